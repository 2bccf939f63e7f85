//! The tick-health line: once a minute, tick lateness and tick-to-command quantiles at INFO.

use std::time::Duration;

use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

use super::Health;

/// How often the line is logged.
pub(crate) const EVERY: Duration = Duration::from_secs(60);

/// Logs tick health every [`EVERY`] until `cancel` fires.
pub(crate) async fn run(health: Health, cancel: CancellationToken) {
    let mut every = tokio::time::interval_at(Instant::now() + EVERY, EVERY);
    // One wait for the cancellation, polled again on every pass (not a new one per pass).
    let cancelled = cancel.cancelled();
    tokio::pin!(cancelled);
    loop {
        tokio::select! {
            _ = &mut cancelled => break,
            _ = every.tick() => {
                let f = health.figures();
                let (lat, cmd) = (f.lateness, f.tick_to_command);
                tracing::info!(
                    timer = health.timer.name(), fired = f.ticks_fired, skipped = f.ticks_skipped,
                    lateness_p50_us = lat.p50_us, lateness_p99_us = lat.p99_us, lateness_max_us = lat.max_us,
                    tick_to_command_p50_us = cmd.p50_us, tick_to_command_p99_us = cmd.p99_us, tick_to_command_max_us = cmd.max_us,
                    "tick health"
                );
            }
        }
    }
}

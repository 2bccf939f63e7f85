//! The sensor ingest actor: robot bytes in, the newest observation out on every tick.
//!
//! It reads the link continuously and feeds the core's [`StreamParser`], which resynchronises after garbage
//! and only commits frames whose checksum holds. It keeps just the newest frame (it never works through a
//! backlog) but sums the odometry packets (distance 19, angle 20) over every frame, because the robot resets
//! them each time it reports them. On each tick it sends learning an [`Observation`] with the frame's age.

use std::time::Duration;

use pavlov::oi::SensorValues;
use pavlov::oi::packets::id;
use pavlov::oi::parser::{ParserStats, StreamParser};
use tokio::io::AsyncReadExt;
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

use crate::link::LinkReader;
use crate::ticker::Tick;

/// The robot's state as seen at one tick.
#[derive(Debug, Clone)]
pub struct Observation {
    /// The tick this observation belongs to.
    pub tick: Tick,
    /// The newest complete frame's values (`None` before the first frame).
    pub values: Option<SensorValues>,
    /// Age of that frame in whole ticks at the tick's deadline.
    pub age_ticks: Option<u32>,
    /// Distance (mm) summed over every frame since the previous tick.
    pub distance_mm: i32,
    /// Angle (degrees) summed over every frame since the previous tick.
    pub angle_deg: i32,
    /// Parser counters so far.
    pub parser: ParserStats,
    /// False once the link has reached end-of-file or failed.
    pub link_up: bool,
}

/// Runs until `cancel` fires or the tick channel closes.
pub async fn run(
    mut link: LinkReader,
    mut parser: StreamParser,
    period: Duration,
    mut ticks: watch::Receiver<Option<Tick>>,
    out: mpsc::Sender<Observation>,
    cancel: CancellationToken,
) {
    let mut buf = vec![0u8; 4096];
    let mut newest: Option<(SensorValues, Instant)> = None;
    let (mut distance, mut angle) = (0i32, 0i32);
    let mut link_up = true;
    loop {
        tokio::select! {
            biased;
            _ = cancel.cancelled() => break,
            changed = ticks.changed() => {
                if changed.is_err() {
                    break;
                }
                let Some(tick) = *ticks.borrow_and_update() else { continue };
                let age_ticks = newest.as_ref().map(|(_, at)| {
                    let age = tick.deadline.saturating_duration_since(*at);
                    (age.as_micros() / period.as_micros().max(1)) as u32
                });
                let obs = Observation {
                    tick,
                    values: newest.as_ref().map(|(v, _)| v.clone()),
                    age_ticks,
                    distance_mm: std::mem::take(&mut distance),
                    angle_deg: std::mem::take(&mut angle),
                    parser: parser.stats(),
                    link_up,
                };
                if out.try_send(obs).is_err() {
                    tracing::debug!("learning is behind; observation for tick {} dropped", tick.seq);
                }
            }
            n = link.read(&mut buf), if link_up => match n {
                Ok(0) => {
                    tracing::warn!("robot link closed (end of file)");
                    link_up = false;
                }
                Err(e) => {
                    tracing::warn!("robot link read failed: {e}");
                    link_up = false;
                }
                Ok(n) => {
                    let now = Instant::now();
                    parser.feed(&buf[..n], |frame| {
                        distance = distance.saturating_add(frame.get_or_zero(id::DISTANCE));
                        angle = angle.saturating_add(frame.get_or_zero(id::ANGLE));
                        newest = Some((frame, now));
                    });
                }
            }
        }
    }
}

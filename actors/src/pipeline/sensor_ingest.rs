//! The sensor ingest actor: robot bytes in, the newest observation out on every tick.
//!
//! It reads the link continuously and feeds the core's [`StreamParser`], which resynchronises after garbage
//! and only commits frames whose checksum holds. It keeps just the newest frame (it never works through a
//! backlog) but sums the odometry packets (distance 19, angle 20) over every frame, because the robot resets
//! them each time it reports them, and ORs the event bits (over-currents, bumps, wheel drops, cliffs) over
//! every frame into the tick's snapshot ([`EventLatch`]), so a flag in a frame that was never the newest is
//! not lost. On each tick it sends learning an [`Observation`] with the frame's age
//! and the link's state. It hosts link supervision ([`Supervisor`]): every frame and tick goes to it, and
//! a reopened port's reader replaces the old one here. Taking a tick is the tick loop's heartbeat, which
//! `/healthz` judges: the timer thread fires on its own, so only the runtime's side shows a stuck loop.

use std::time::Duration;

use pavlov::oi::SensorValues;
use pavlov::oi::events::EventLatch;
use pavlov::oi::packets::id;
use pavlov::oi::parser::StreamParser;
use pavlov::record::LinkStatus;
use tokio::io::AsyncReadExt;
use tokio::sync::{mpsc, watch};
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

use super::ticker::Tick;
use crate::command::{Inbox, LinkCommand};
use crate::link::LinkReader;
use crate::link::supervisor::Supervisor;
use crate::telemetry::counters::SharedTickStats;

/// The robot's state as seen at one tick.
#[derive(Debug, Clone)]
pub(crate) struct Observation {
    /// The tick this observation belongs to.
    pub(crate) tick: Tick,
    /// The newest complete frame's values (`None` before the first frame).
    pub(crate) values: Option<SensorValues>,
    /// Age of that frame in whole ticks at the tick's deadline.
    pub(crate) age_ticks: Option<u32>,
    /// Distance (mm) summed over every frame since the previous tick.
    pub(crate) distance_mm: i32,
    /// Angle (degrees) summed over every frame since the previous tick.
    pub(crate) angle_deg: i32,
    /// The link's state, mode, counters.
    pub(crate) link: LinkStatus,
}

/// The channels and link parts the ingest works with.
pub(crate) struct IngestLink {
    /// The robot-to-host half of the link.
    pub(crate) reader: LinkReader,
    /// The stream parser for the requested packets.
    pub(crate) parser: StreamParser,
    /// Link supervision (re-sync, reopen, trips).
    pub(crate) supervisor: Supervisor,
}

/// The channels sensor ingest reads and writes.
pub(crate) struct IngestChannels {
    /// The ticker.
    pub(crate) ticks: watch::Receiver<Option<Tick>>,
    /// Link commands from the router.
    pub(crate) commands: Inbox<LinkCommand>,
    /// Where observations go (to learning).
    pub(crate) out: mpsc::Sender<Observation>,
    /// Where the tick loop's heartbeat goes: the time each tick is taken here, on the async runtime.
    pub(crate) heartbeat: SharedTickStats,
}

/// What the ingest keeps between ticks: the newest frame and what is summed or latched over every frame
/// since the previous tick. The actor and the stepped virtual-time driver
/// ([`crate::experiment::stepped`]) both run the ingest through it, so there is one per-tick path.
pub(crate) struct IngestState {
    newest: Option<(SensorValues, Instant)>,
    distance: i32,
    angle: i32,
    events: EventLatch,
    period: Duration,
}

impl IngestState {
    /// Nothing seen yet, for ticks of `period`.
    pub(crate) fn new(period: Duration) -> Self {
        IngestState {
            newest: None,
            distance: 0,
            angle: 0,
            events: EventLatch::new(),
            period,
        }
    }

    /// Feeds `bytes` read from the link `at` through the parser; every complete frame goes to supervision.
    pub(crate) fn on_bytes(
        &mut self,
        bytes: &[u8],
        at: Instant,
        parser: &mut StreamParser,
        supervisor: &mut Supervisor,
    ) {
        let bad_before = parser.stats().bad_frames;
        let newest = &mut self.newest;
        let (distance, angle, events) = (&mut self.distance, &mut self.angle, &mut self.events);
        parser.feed(bytes, |frame| {
            *distance = distance.saturating_add(frame.get_or_zero(id::DISTANCE));
            *angle = angle.saturating_add(frame.get_or_zero(id::ANGLE));
            supervisor.on_frame(&frame, at);
            events.fold(&frame);
            *newest = Some((frame, at));
        });
        let stats = parser.stats();
        if stats.bad_frames > bad_before {
            tracing::debug!(
                bad_frames = stats.bad_frames,
                skipped_bytes = stats.skipped_bytes,
                "rejected a damaged sensor frame"
            );
        }
    }

    /// Tick `tick`, taken `at`: supervision sees it, and the observation of everything since the previous
    /// tick is returned.
    pub(crate) fn on_tick(
        &mut self,
        tick: Tick,
        at: Instant,
        parser: &StreamParser,
        supervisor: &mut Supervisor,
    ) -> Observation {
        supervisor.on_tick(tick.seq, at);
        let period = self.period;
        let age_ticks = self.newest.as_ref().map(|(_, at)| {
            let age = tick.deadline.saturating_duration_since(*at);
            (age.as_micros() / period.as_micros().max(1)) as u32
        });
        let events = &mut self.events;
        let values = self.newest.as_ref().map(|(v, _)| {
            let mut v = v.clone();
            events.apply_and_clear(&mut v);
            v
        });
        Observation {
            tick,
            values,
            age_ticks,
            distance_mm: std::mem::take(&mut self.distance),
            angle_deg: std::mem::take(&mut self.angle),
            link: supervisor.status(parser.stats()),
        }
    }
}

/// Runs until `cancel` fires or the tick channel closes.
pub(crate) async fn run(
    link: IngestLink,
    period: Duration,
    channels: IngestChannels,
    cancel: CancellationToken,
) {
    let IngestLink {
        reader,
        mut parser,
        mut supervisor,
    } = link;
    let IngestChannels {
        mut ticks,
        mut commands,
        out,
        heartbeat,
    } = channels;
    let mut reader = Some(reader);
    let mut buf = vec![0u8; 4096];
    let mut state = IngestState::new(period);
    let mut commands_open = true;
    // One wait for the cancellation, polled again on every pass (not a new one per pass).
    let cancelled = cancel.cancelled();
    tokio::pin!(cancelled);
    loop {
        tokio::select! {
            biased;
            _ = &mut cancelled => break,
            changed = ticks.changed() => {
                if changed.is_err() {
                    break;
                }
                let Some(tick) = *ticks.borrow_and_update() else { continue };
                let now = Instant::now();
                if let Ok(mut stats) = heartbeat.lock() {
                    stats.last_taken = Some(now);
                }
                let obs = state.on_tick(tick, now, &parser, &mut supervisor);
                if supervisor.reopening() {
                    // The old port is being closed and reopened; its reader goes with it.
                    reader = None;
                }
                if out.try_send(obs).is_err() {
                    tracing::debug!("learning is behind; observation for tick {} dropped", tick.seq);
                }
            }
            command = commands.recv(), if commands_open => match command {
                Some(c) => supervisor.command(c),
                None => commands_open = false,
            },
            fresh = supervisor.reopen_finished(), if supervisor.reopening() => {
                if let Some(fresh) = fresh {
                    // Bytes of a frame cut by the reconnect must not join the new port's first frame.
                    parser.reset();
                    reader = Some(fresh);
                }
            }
            n = read_link(&mut reader, &mut buf), if reader.is_some() => match n {
                Ok(0) => {
                    tracing::warn!("robot link closed (end of file)");
                    reader = None;
                    supervisor.on_lost();
                }
                Err(e) => {
                    tracing::warn!("robot link read failed: {e}");
                    reader = None;
                    supervisor.on_lost();
                }
                Ok(n) => state.on_bytes(&buf[..n], Instant::now(), &mut parser, &mut supervisor),
            }
        }
    }
}

async fn read_link(reader: &mut Option<LinkReader>, buf: &mut [u8]) -> std::io::Result<usize> {
    match reader {
        Some(r) => r.read(buf).await,
        None => std::future::pending().await,
    }
}

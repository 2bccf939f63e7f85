//! The Horde, off the control path: `[horde]`'s predictions learned on a thread of their own.
//!
//! Learning's task acts first (the control predictions go to gating), learns the control predictions,
//! and then *offers* the tick's signals to the Horde: a `try_send` into a queue of `QUEUE` ticks.
//! When the Horde is still busy and the queue is full, the tick is not learned from by the Horde; it is
//! counted (`skipped_busy`), and the Horde breaks its chain of ticks there rather than learn a
//! transition it did not see. Nothing the Horde does can delay gating or actuation: the tick path never
//! waits on it.
//!
//! Checkpoints are copied a few rows at a time in the time a tick leaves over (copy-on-write a row at a
//! time, [`pavlov::learn::group`]) and written on another thread ([`crate::storage::horde_file`]), so
//! a checkpoint of 10⁸ weights skips no tick either.
//!
//! - `worker`: the thread's loop; [`status`]: what it reports; `cpu_time`: the thread's CPU time, which
//!   its step is measured in beside the wall time.

mod background;
mod cpu_time;
pub mod status;
mod worker;

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::Ordering;
use std::sync::mpsc::{Receiver, SyncSender, TrySendError, sync_channel};
use std::thread::JoinHandle;
use std::time::Duration;

use pavlov::config::{Config, Precision, Scheduling};
use pavlov::learn::group::Weight;
use pavlov::learn::{Horde, LearnError, TickSignals};
use tokio::sync::watch;

use crate::storage::horde_file;
use status::{HordeStatus, OfferCounters};
use worker::{Target, Worker};

/// Ticks that may wait for the Horde before learning's offers are refused: one being learned and one
/// waiting, so a step that runs long once costs nothing, and a Horde that is too slow is seen at once.
pub(crate) const QUEUE: usize = 1;

/// The most tick buffers in use at once: one being learned, [`QUEUE`] waiting.
const BUFFERS: usize = QUEUE + 1;

/// One tick's signals, as the Horde reads them. The buffers go round: learning fills one, the Horde
/// learns from it and sends it back, so an offer allocates nothing once [`BUFFERS`] exist.
#[derive(Debug, Clone, Default)]
pub(crate) struct HordeTick {
    pub(crate) seq: u64,
    pub(crate) obs: Vec<f64>,
    pub(crate) raw: Vec<f64>,
    pub(crate) extra: Vec<f64>,
    pub(crate) stimuli: Vec<bool>,
}

/// Every prediction's value after a tick (published ten times a second).
#[derive(Debug, Clone, Default, PartialEq)]
pub struct HordeValues {
    /// The tick.
    pub seq: u64,
    /// One per prediction, in the Horde's order.
    pub values: Vec<f32>,
}

/// What the dashboard, `/metrics` and the bench read of the Horde.
#[derive(Clone)]
pub struct HordeView {
    /// Its figures, twice a second.
    pub status: watch::Receiver<HordeStatus>,
    /// Every prediction's value, ten times a second.
    pub values: watch::Receiver<std::sync::Arc<HordeValues>>,
    /// The predictions' names, in the order of the values.
    pub names: std::sync::Arc<Vec<String>>,
}

pub(crate) enum HordeCommand {
    /// Every weight back to its initial value (`reset_weights`).
    Reset,
    /// Copy a checkpoint (while learning) and write it into `dir`, keeping `keep`.
    Checkpoint { dir: PathBuf, keep: usize },
    /// Announce checkpoint failures on this event log from now on (the log exists only once the
    /// pipeline is wired, after the Horde has started).
    Events(crate::bus::events::EventLog),
    /// Stop: write a last checkpoint if asked, then say so.
    Finish {
        checkpoint: Option<Target>,
        done: std::sync::mpsc::Sender<()>,
    },
}

/// Why the Horde could not start.
#[derive(Debug, thiserror::Error)]
pub enum HordeError {
    #[error("[horde]: {0}")]
    Learn(#[from] LearnError),
    #[error("cannot resume the Horde from {path}: {error}")]
    Resume { path: String, error: String },
    #[error("cannot start the Horde thread: {0}")]
    Thread(std::io::Error),
}

/// The running Horde.
pub(crate) struct HordeHandle {
    ticks: SyncSender<HordeTick>,
    /// Buffers the Horde has learned from, back for the next offers.
    returned: Receiver<HordeTick>,
    /// Buffers here, ready to fill.
    spare: Vec<HordeTick>,
    /// Buffers allocated so far (at most [`BUFFERS`]).
    allocated: usize,
    commands: SyncSender<HordeCommand>,
    offers: Arc<OfferCounters>,
    status: watch::Receiver<HordeStatus>,
    values: watch::Receiver<Arc<HordeValues>>,
    names: Arc<Vec<String>>,
    thread: Option<JoinHandle<()>>,
    /// The Horde's threads under `SCHED_IDLE`, put back under the normal policy to finish.
    idle_threads: Arc<background::IdleThreads>,
}

impl HordeHandle {
    /// Builds `config`'s Horde (`None` without `[horde]` families), restores it from `resume` if given,
    /// and starts its thread. `tick_offset` is the lifelong tick of this run's tick 0.
    pub(crate) fn spawn(
        config: &Config,
        resume: Option<&Path>,
        tick_offset: u64,
    ) -> Result<Option<Self>, HordeError> {
        if !config.horde.is_enabled() {
            return Ok(None);
        }
        let period = Duration::from_millis(config.tick.period_ms.max(1));
        let handle = match config.horde.precision {
            Precision::F32 => Self::start::<f32>(config, resume, tick_offset, period)?,
            Precision::F64 => Self::start::<f64>(config, resume, tick_offset, period)?,
        };
        Ok(Some(handle))
    }

    fn start<W: Weight>(
        config: &Config,
        resume: Option<&Path>,
        tick_offset: u64,
        period: Duration,
    ) -> Result<Self, HordeError> {
        let mut horde: Horde<W> =
            Horde::new(config.horde.families.clone(), &config.signal_names())?;
        let mut resumed_tick = 0;
        if let Some(path) = resume {
            let fail = |error: String| HordeError::Resume {
                path: path.display().to_string(),
                error,
            };
            let (tick, snapshot) = horde_file::read::<W>(path).map_err(|e| fail(e.to_string()))?;
            horde
                .restore_snapshot(&snapshot)
                .map_err(|e| fail(e.to_string()))?;
            tracing::info!(path = %path.display(), tick, "resumed the Horde from a checkpoint");
            resumed_tick = tick;
        }
        // The memory checkpoints are copied into, mapped before the first tick (see
        // `Horde::prepare_snapshot_buffers`): copying a checkpoint then allocates nothing.
        horde.prepare_snapshot_buffers();
        let shape = horde.shape();
        tracing::info!(
            predictions = shape.predictions,
            groups = shape.groups,
            weights = shape.weights,
            precision = W::NAME,
            "the Horde learns on its own thread"
        );
        let names = Arc::new(horde.predictions().iter().map(|p| p.name.clone()).collect());
        let (tick_tx, tick_rx) = sync_channel(QUEUE);
        let (return_tx, return_rx) = sync_channel(BUFFERS);
        let (command_tx, command_rx) = sync_channel(16);
        let (status_tx, status_rx) = watch::channel(HordeStatus {
            predictions: shape.predictions,
            groups: shape.groups,
            weights: shape.weights,
            precision: W::NAME,
            ..HordeStatus::default()
        });
        let (values_tx, values_rx) = watch::channel(Arc::new(HordeValues::default()));
        let offers = Arc::new(OfferCounters::default());
        let idle = config.horde.scheduling == Scheduling::Idle;
        let idle_threads = Arc::new(background::IdleThreads::default());
        let worker = Worker {
            idle,
            idle_threads: idle_threads.clone(),
            horde,
            ticks: tick_rx,
            returns: return_tx,
            commands: command_rx,
            offers: offers.clone(),
            status: status_tx,
            values: values_tx,
            spare_values: Vec::new(),
            period,
            tick_offset,
            resumed_tick,
        };
        let thread = std::thread::Builder::new()
            .name("pavlov-horde".into())
            .spawn(move || {
                if idle {
                    worker.idle_threads.learner_gives_way();
                }
                worker.run()
            })
            .map_err(HordeError::Thread)?;
        Ok(HordeHandle {
            ticks: tick_tx,
            returned: return_rx,
            spare: Vec::with_capacity(BUFFERS),
            allocated: 0,
            commands: command_tx,
            offers,
            status: status_rx,
            values: values_rx,
            names,
            thread: Some(thread),
            idle_threads,
        })
    }

    /// Hands tick `seq`'s signals over without waiting: refused (and counted) while the Horde is busy.
    /// Allocates nothing once its buffers exist: while the Horde holds every buffer it is busy, and the
    /// tick is refused without being copied.
    pub(crate) fn offer(&mut self, seq: u64, signals: &TickSignals) {
        self.offers.offered.fetch_add(1, Ordering::Relaxed);
        self.spare.extend(self.returned.try_iter());
        let mut tick = match self.spare.pop() {
            Some(tick) => tick,
            None if self.allocated < BUFFERS => {
                self.allocated += 1;
                HordeTick::default()
            }
            None => {
                self.offers.skipped_busy.fetch_add(1, Ordering::Relaxed);
                return;
            }
        };
        tick.seq = seq;
        fill(&mut tick.obs, signals.obs);
        fill(&mut tick.raw, signals.raw);
        fill(&mut tick.extra, signals.extra);
        fill(&mut tick.stimuli, signals.stimuli);
        match self.ticks.try_send(tick) {
            Ok(()) => self.wake(),
            Err(TrySendError::Full(tick)) => {
                self.spare.push(tick);
                self.offers.skipped_busy.fetch_add(1, Ordering::Relaxed);
            }
            Err(TrySendError::Disconnected(_)) => {
                tracing::debug!("the Horde thread has stopped");
            }
        }
    }

    /// How many tick buffers exist (for tests: never more than [`BUFFERS`]).
    #[cfg(test)]
    pub(crate) fn buffers(&self) -> usize {
        self.allocated
    }

    fn command(&self, command: HordeCommand) {
        if self.commands.try_send(command).is_err() {
            tracing::warn!("the Horde's command queue is full; a command was dropped");
        }
        self.wake();
    }

    /// Unparks the Horde's thread (it parks between ticks rather than block in a channel: see
    /// `Worker::next_tick`); takes no lock.
    fn wake(&self) {
        if let Some(thread) = &self.thread {
            thread.thread().unpark();
        }
    }

    /// Announces the Horde's failed checkpoint writes on `events` (`checkpoint_failed`, counted in
    /// `/metrics` as every checkpoint failure).
    pub(crate) fn attach_events(&self, events: crate::bus::events::EventLog) {
        self.command(HordeCommand::Events(events));
    }

    /// Every weight back to its initial value.
    pub(crate) fn reset(&self) {
        self.command(HordeCommand::Reset);
    }

    /// Copies a checkpoint while learning goes on, and writes it into `dir` (keeping `keep`).
    pub(crate) fn checkpoint(&self, dir: &Path, keep: usize) {
        self.command(HordeCommand::Checkpoint {
            dir: dir.to_path_buf(),
            keep,
        });
    }

    /// The Horde's figures.
    pub(crate) fn status(&self) -> watch::Receiver<HordeStatus> {
        self.status.clone()
    }

    /// Every prediction's value, ten times a second.
    pub(crate) fn values(&self) -> watch::Receiver<Arc<HordeValues>> {
        self.values.clone()
    }

    /// The predictions' names, in the order of [`HordeValues::values`].
    pub(crate) fn names(&self) -> Arc<Vec<String>> {
        self.names.clone()
    }

    /// Stops the thread after writing a last checkpoint into `checkpoint`'s folder if given; blocks
    /// until it is written (call from a blocking context).
    pub(crate) fn finish(mut self, checkpoint: Option<(&Path, usize)>) {
        let (done_tx, done_rx) = std::sync::mpsc::channel();
        let target = checkpoint.map(|(dir, keep)| Target {
            dir: dir.to_path_buf(),
            keep,
        });
        // Control has stopped: the Horde's threads need not give way any more, and under `SCHED_IDLE`
        // on a busy machine the thread would not even see the command for minutes.
        self.idle_threads.all_back_to_normal();
        // The command queue is small and nearly always empty; a blocking send waits for one command.
        let _ = self.commands.send(HordeCommand::Finish {
            checkpoint: target,
            done: done_tx,
        });
        self.wake();
        let _ = done_rx.recv();
        if let Some(t) = self.thread.take() {
            let _ = t.join();
        }
    }
}

/// `to` becomes a copy of `from`, in the memory `to` has (no allocation once it is large enough).
fn fill<T: Copy>(to: &mut Vec<T>, from: &[T]) {
    to.clear();
    to.extend_from_slice(from);
}

#[cfg(test)]
mod tests {
    use pavlov::config::Config;

    use super::*;

    #[test]
    fn offers_reuse_two_buffers_and_a_tick_refused_while_busy_is_counted() {
        let text = format!(
            "{}\n[horde]\nscheduling = \"normal\"\n[[horde.families]]\nname = \"p\"\n\
             cumulants = [\"obs/*\"]\ntaus = [2.0]\nlambda = 0.5\nalpha = 0.01\n\
             features = {{ kind = \"one_dim\", all_obs = true, tiles = 4 }}\n",
            include_str!("../../../config/stall.toml")
        );
        let cfg = Config::from_toml(&text).unwrap();
        let mut handle = HordeHandle::spawn(&cfg, None, 0).unwrap().unwrap();
        let obs = vec![0.5; cfg.signal_names().obs.len()];
        let signals = TickSignals {
            obs: &obs,
            raw: &obs,
            extra: &[],
            stimuli: &[false],
        };
        // Offered back to back, faster than the Horde learns: some are refused as busy.
        for seq in 0..2000 {
            handle.offer(seq, &signals);
            if seq % 100 == 0 {
                std::thread::sleep(Duration::from_millis(5));
            }
        }
        assert!(handle.buffers() <= BUFFERS, "{} buffers", handle.buffers());
        let status = handle.status();
        handle.finish(None);
        let s = status.borrow().clone();
        assert!(s.ticks_learned > 0, "{s:?}");
        // Every offer is learned or counted as refused, but those still queued when it was finished.
        let seen = s.ticks_learned + s.skipped_busy;
        assert!((2000 - BUFFERS as u64..=2000).contains(&seen), "{s:?}");
        assert!(s.skipped_busy > 0, "offered faster than it learns: {s:?}");
    }
}

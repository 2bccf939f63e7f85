//! The Horde thread's loop: learn every tick handed over, copy a checkpoint in the time left over, and
//! write it on yet another thread, so that neither a large step nor a checkpoint ever reaches the tick.

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::mpsc::{Receiver, RecvTimeoutError, TryRecvError};
use std::thread::JoinHandle;
use std::time::{Duration, Instant};

use pavlov::learn::group::Weight;
use pavlov::learn::{Horde, HordeSnapshot, TickSignals};
use tokio::sync::watch;

use super::status::{HordeStatus, OfferCounters};
use super::{HordeCommand, HordeTick, HordeValues};
use crate::storage::horde_file;
use crate::telemetry::histogram::LatencyHistogram;

/// Rows copied between two checks of the time budget.
const COPY_CHUNK: usize = 16;
/// Status published every this many ticks (twice a second at 50 Hz).
const STATUS_EVERY: u64 = 25;
/// Values published every this many ticks (10 Hz).
const VALUES_EVERY: u64 = 5;

/// Where a checkpoint goes.
#[derive(Debug, Clone)]
pub(crate) struct Target {
    pub(crate) dir: PathBuf,
    pub(crate) keep: usize,
}

/// Everything the thread owns.
pub(crate) struct Worker<W> {
    pub(crate) horde: Horde<W>,
    /// Whether the checkpoint writer runs under `SCHED_IDLE` (`[horde] scheduling = "idle"`).
    pub(crate) idle: bool,
    /// The threads under `SCHED_IDLE`, registered there (see [`super::background::IdleThreads`]).
    pub(crate) idle_threads: Arc<super::background::IdleThreads>,
    pub(crate) ticks: Receiver<HordeTick>,
    /// Where a tick's buffer goes back once learned.
    pub(crate) returns: std::sync::mpsc::SyncSender<HordeTick>,
    pub(crate) commands: Receiver<HordeCommand>,
    pub(crate) offers: Arc<OfferCounters>,
    pub(crate) status: watch::Sender<HordeStatus>,
    pub(crate) values: watch::Sender<Arc<HordeValues>>,
    /// The memory of the next values published.
    pub(crate) spare_values: Vec<f32>,
    /// The tick period: a step and the copying after it stay within half of it.
    pub(crate) period: Duration,
    /// Lifelong tick of this run's tick 0 (checkpoints are named by lifelong ticks).
    pub(crate) tick_offset: u64,
    /// The tick of the checkpoint this Horde resumed from (0 when fresh): its own checkpoints are never
    /// named below it, even when it stops before learning a tick of this run.
    pub(crate) resumed_tick: u64,
}

/// A checkpoint being written: the file's path or why not, and the snapshot back (its memory is the next
/// one's).
type Writer<W> = JoinHandle<(Result<PathBuf, (String, String)>, HordeSnapshot<W>)>;

struct Progress<W> {
    last_seq: Option<u64>,
    steps: LatencyHistogram,
    /// The steps' CPU time (the thread's).
    steps_cpu: LatencyHistogram,
    learned: u64,
    breaks: u64,
    /// The checkpoint being copied: where it goes, and the tick it is of.
    copying: Option<(Target, u64)>,
    writer: Option<Writer<W>>,
    written: u64,
    errors: u64,
    last_file: Option<String>,
    /// Where a failed checkpoint write is announced (once the pipeline has attached it).
    events: Option<crate::bus::events::EventLog>,
}

impl<W: Weight> Worker<W> {
    /// Runs until learning stops handing ticks over, or a `Finish` arrives.
    pub(crate) fn run(mut self) {
        let mut p = Progress {
            last_seq: None,
            steps: LatencyHistogram::new(),
            steps_cpu: LatencyHistogram::new(),
            learned: 0,
            breaks: 0,
            copying: None,
            writer: None,
            written: 0,
            errors: 0,
            last_file: None,
            events: None,
        };
        let mut finish = None;
        loop {
            while let Ok(command) = self.commands.try_recv() {
                match command {
                    HordeCommand::Reset => self.horde.reset(),
                    HordeCommand::Events(events) => p.events = Some(events),
                    HordeCommand::Checkpoint { dir, keep } => {
                        self.begin_checkpoint(&mut p, Target { dir, keep });
                    }
                    HordeCommand::Finish { checkpoint, done } => {
                        finish = Some((checkpoint, done));
                    }
                }
            }
            if finish.is_some() {
                break;
            }
            match self.next_tick(Duration::from_millis(100)) {
                Ok(tick) => {
                    let started = Instant::now();
                    self.learn(&mut p, &tick);
                    let seq = tick.seq;
                    // Back to learning for another tick (a full queue cannot be: it holds every buffer).
                    let _ = self.returns.try_send(tick);
                    self.copy_for(&mut p, started + self.period / 2);
                    if p.learned % VALUES_EVERY == 0 {
                        self.publish_values(seq);
                    }
                    if p.learned % STATUS_EVERY == 0 {
                        self.publish_status(&p);
                    }
                }
                Err(RecvTimeoutError::Timeout) => {
                    self.copy_for(&mut p, Instant::now() + self.period / 2);
                }
                Err(RecvTimeoutError::Disconnected) => break,
            }
        }
        // Shutting down: the last checkpoint is completed at once (nothing is learned any more), at the
        // normal policy: control has stopped, and under `SCHED_IDLE` on a busy machine the copy and the
        // write of hundreds of megabytes would wait minutes for a core.
        if self.idle {
            super::background::back_to_normal_policy();
            // A writer under way is waited for below.
            self.idle_threads.all_back_to_normal();
            self.idle = false;
        }
        let (target, done) = finish.unzip();
        if let Some(target) = target.flatten() {
            if p.copying.is_none() {
                self.begin_checkpoint(&mut p, target);
            }
            self.copy_for(&mut p, Instant::now() + Duration::from_secs(3600));
        }
        if let Some(writer) = p.writer.take() {
            self.collect(&mut p, writer);
        }
        self.publish_status(&p);
        if let Some(done) = done {
            let _ = done.send(());
        }
    }

    /// The next tick learning hands over, waiting at most `wait`. The thread parks rather than block
    /// in the channel: a receiver blocked in a channel registers under the channel's lock, and a thread
    /// under `SCHED_IDLE` that is preempted while it holds that lock (which a busy machine does at any
    /// instruction) would hold up learning's next offer until the scheduler gets round to it again.
    /// Learning unparks it after each offer ([`super::HordeHandle::offer`]); parking and unparking
    /// take no lock, and an unpark before the park is not lost.
    fn next_tick(&self, wait: Duration) -> Result<HordeTick, RecvTimeoutError> {
        let deadline = Instant::now() + wait;
        loop {
            match self.ticks.try_recv() {
                Ok(tick) => return Ok(tick),
                Err(TryRecvError::Disconnected) => return Err(RecvTimeoutError::Disconnected),
                Err(TryRecvError::Empty) => {}
            }
            let now = Instant::now();
            if now >= deadline {
                return Err(RecvTimeoutError::Timeout);
            }
            std::thread::park_timeout(deadline - now);
        }
    }

    fn learn(&mut self, p: &mut Progress<W>, tick: &HordeTick) {
        if p.last_seq.is_some_and(|s| tick.seq != s + 1) {
            self.horde.break_chain();
            p.breaks += 1;
        }
        let started = Instant::now();
        let cpu_started = super::cpu_time::thread_cpu_time();
        self.horde.step(&TickSignals {
            obs: &tick.obs,
            raw: &tick.raw,
            extra: &tick.extra,
            stimuli: &tick.stimuli,
        });
        p.steps.record(started.elapsed());
        if let (Some(a), Some(b)) = (cpu_started, super::cpu_time::thread_cpu_time()) {
            p.steps_cpu.record(b.saturating_sub(a));
        }
        p.last_seq = Some(tick.seq);
        p.learned += 1;
    }

    fn begin_checkpoint(&mut self, p: &mut Progress<W>, target: Target) {
        // A write that has finished gives its memory back for this copy.
        if p.writer.as_ref().is_some_and(JoinHandle::is_finished)
            && let Some(writer) = p.writer.take()
        {
            self.collect(p, writer);
        }
        if p.copying.is_some() || !self.horde.begin_snapshot() {
            tracing::debug!("a Horde checkpoint is already being copied; this one is skipped");
            return;
        }
        let tick = (self.tick_offset + p.last_seq.map_or(0, |s| s + 1)).max(self.resumed_tick);
        p.copying = Some((target, tick));
    }

    /// Copies checkpoint rows until `until`, and at least [`COPY_CHUNK`] of them (a step that takes
    /// more than half a tick would otherwise leave a checkpoint uncopied as long as ticks keep coming);
    /// hands a completed checkpoint to a writer thread.
    fn copy_for(&mut self, p: &mut Progress<W>, until: Instant) {
        if p.copying.is_none() {
            return;
        }
        let mut complete = self.horde.advance_snapshot(COPY_CHUNK);
        while !complete && Instant::now() < until {
            complete = self.horde.advance_snapshot(COPY_CHUNK);
        }
        if !complete {
            return;
        }
        let (Some(snapshot), Some((target, tick))) = (self.horde.take_snapshot(), p.copying.take())
        else {
            return;
        };
        if let Some(previous) = p.writer.take() {
            // One write at a time: the previous one has had the whole copy's time to finish.
            self.collect(p, previous);
        }
        let idle = self.idle.then(|| self.idle_threads.clone());
        match spawn_write(target, tick, snapshot, idle) {
            Ok(writer) => p.writer = Some(writer),
            Err(e) => {
                p.errors += 1;
                tracing::error!("Horde checkpoint not written: cannot start its writer: {e}");
            }
        }
    }

    fn collect(&mut self, p: &mut Progress<W>, writer: Writer<W>) {
        match writer.join() {
            Ok((written, snapshot)) => {
                self.horde.keep_snapshot_buffers(snapshot);
                match written {
                    Ok(path) => {
                        p.written += 1;
                        p.last_file = Some(path.display().to_string());
                    }
                    Err((path, reason)) => {
                        p.errors += 1;
                        tracing::error!("Horde checkpoint {path} not written: {reason}");
                        if let Some(events) = &p.events {
                            events.emit(
                                p.last_seq,
                                pavlov::event::EventKind::CheckpointFailed { path, reason },
                            );
                        }
                    }
                }
            }
            Err(_) => {
                p.errors += 1;
                tracing::error!("the Horde checkpoint writer panicked");
            }
        }
    }

    /// Publishes every value, in the memory of the publication before when no one holds that any more
    /// (so the thread allocates nothing per tick but the small `Arc`).
    fn publish_values(&mut self, seq: u64) {
        let mut values = std::mem::take(&mut self.spare_values);
        self.horde.values_into(&mut values);
        let old = self
            .values
            .send_replace(Arc::new(HordeValues { seq, values }));
        if let Ok(old) = Arc::try_unwrap(old) {
            self.spare_values = old.values;
        }
    }

    fn publish_status(&self, p: &Progress<W>) {
        let shape = self.horde.shape();
        let _ = self.status.send(HordeStatus {
            predictions: shape.predictions,
            groups: shape.groups,
            weights: shape.weights,
            precision: W::NAME,
            ticks_learned: p.learned,
            skipped_busy: self.offers.skipped(),
            chain_breaks: p.breaks,
            step: p.steps.quantiles(),
            step_cpu: p.steps_cpu.quantiles(),
            stopped: self.horde.stopped(),
            snapshot_rows_left: self.horde.snapshot_rows_left(),
            checkpoints_written: p.written,
            checkpoint_errors: p.errors,
            last_checkpoint: p.last_file.clone(),
        });
    }
}

/// Writes `snapshot` on a thread of its own (a large Horde takes a second or more to write).
fn spawn_write<W: Weight>(
    target: Target,
    tick: u64,
    snapshot: HordeSnapshot<W>,
    idle: Option<Arc<super::background::IdleThreads>>,
) -> std::io::Result<Writer<W>> {
    std::thread::Builder::new()
        .name("pavlov-horde-write".into())
        .spawn(move || {
            if let Some(threads) = &idle {
                threads.writer_gives_way();
            }
            let written = horde_file::write_atomic(&target.dir, tick, &snapshot).map_err(|e| {
                (
                    target
                        .dir
                        .join(horde_file::file_name(tick))
                        .display()
                        .to_string(),
                    e.to_string(),
                )
            });
            if written.is_ok()
                && let Err(e) = horde_file::prune(&target.dir, target.keep)
            {
                tracing::warn!("could not prune old Horde checkpoints: {e}");
            }
            if let Some(threads) = &idle {
                threads.writer_done();
            }
            (written, snapshot)
        })
}

#[cfg(test)]
mod tests {
    use std::sync::mpsc::sync_channel;

    use pavlov::config::Config;

    use super::*;

    type Rig = (
        Worker<f32>,
        std::sync::mpsc::SyncSender<HordeTick>,
        std::sync::mpsc::SyncSender<HordeCommand>,
        watch::Receiver<HordeStatus>,
        Config,
    );

    /// A small Horde's worker over the stall study's observations, and the ends that drive it.
    fn rig(period: Duration, tick_offset: u64, resumed_tick: u64) -> Rig {
        let text = format!(
            "{}\n[horde]\n[[horde.families]]\nname = \"p\"\ncumulants = [\"obs/*\"]\ntaus = [2.0]\n\
             lambda = 0.5\nalpha = 0.01\nfeatures = {{ kind = \"one_dim\", all_obs = true, tiles = 4 }}\n",
            include_str!("../../../config/stall.toml")
        );
        let cfg = Config::from_toml(&text).unwrap();
        let horde: Horde<f32> =
            Horde::new(cfg.horde.families.clone(), &cfg.signal_names()).unwrap();
        let (tick_tx, tick_rx) = sync_channel(1);
        let (command_tx, command_rx) = sync_channel(4);
        let (status_tx, status_rx) = watch::channel(HordeStatus::default());
        let (values_tx, _values_rx) = watch::channel(Arc::new(HordeValues::default()));
        let worker = Worker {
            horde,
            idle: false,
            idle_threads: Arc::default(),
            ticks: tick_rx,
            // The tests hand ticks in themselves: the buffers need not come back.
            returns: sync_channel(super::super::BUFFERS).0,
            commands: command_rx,
            offers: Arc::new(OfferCounters::default()),
            status: status_tx,
            values: values_tx,
            spare_values: Vec::new(),
            period,
            tick_offset,
            resumed_tick,
        };
        (worker, tick_tx, command_tx, status_rx, cfg)
    }

    /// A resumed Horde that stops before it learns a tick of this run names its last checkpoint by
    /// the tick it resumed from, never below it (this run's tick 0 is the resumed control checkpoint's
    /// tick, which can be one behind the Horde's).
    #[test]
    fn a_resumed_horde_never_names_a_checkpoint_below_the_one_it_resumed_from() {
        let (worker, tick_tx, command_tx, status_rx, _) = rig(Duration::from_millis(20), 249, 250);
        let dir = std::env::temp_dir().join(format!("pavlov-horde-resumed-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        let thread = std::thread::spawn(move || worker.run());
        // Shut down before any tick of this run: the last checkpoint, as the server writes it.
        let (done_tx, done_rx) = std::sync::mpsc::channel();
        command_tx
            .send(HordeCommand::Finish {
                checkpoint: Some(Target {
                    dir: dir.clone(),
                    keep: 5,
                }),
                done: done_tx,
            })
            .unwrap();
        let _ = done_rx.recv();
        drop(tick_tx);
        thread.join().unwrap();
        assert_eq!(status_rx.borrow().checkpoints_written, 1);
        assert!(
            dir.join("horde-250.bin").exists(),
            "{:?}",
            std::fs::read_dir(&dir).unwrap().collect::<Vec<_>>()
        );
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A Horde whose step leaves no time over (a period of zero) still completes a checkpoint while
    /// ticks keep coming: a chunk of rows is copied after every step.
    #[test]
    fn a_checkpoint_is_copied_even_when_steps_leave_no_time() {
        let (worker, tick_tx, command_tx, status_rx, cfg) = rig(Duration::ZERO, 0, 0);
        let dir = std::env::temp_dir().join(format!("pavlov-horde-worker-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).unwrap();
        command_tx
            .send(HordeCommand::Checkpoint {
                dir: dir.clone(),
                keep: 5,
            })
            .unwrap();
        let thread = std::thread::spawn(move || worker.run());
        let obs = vec![0.5; cfg.signal_names().obs.len()];
        // 176 rows in chunks of 16: done within a dozen ticks; 100 leave no doubt.
        for seq in 0..100 {
            tick_tx
                .send(HordeTick {
                    seq,
                    obs: obs.clone(),
                    raw: obs.clone(),
                    extra: vec![],
                    stimuli: vec![false],
                })
                .unwrap();
            // As learning does after an offer: the thread parks between ticks.
            thread.thread().unpark();
        }
        drop(tick_tx);
        thread.join().unwrap();
        let status = status_rx.borrow().clone();
        assert_eq!(status.ticks_learned, 100);
        assert_eq!(status.checkpoints_written, 1, "{status:?}");
        assert_eq!(status.checkpoint_errors, 0);
        assert!(dir.join("horde-0.bin").exists());
        let _ = std::fs::remove_dir_all(&dir);
    }

    /// A checkpoint the disk refuses (here: its folder is a file) is announced as `checkpoint_failed`
    /// on the attached event log, naming the file and the OS's reason, and counted.
    #[test]
    fn a_failed_checkpoint_is_announced_on_the_event_log() {
        let (worker, tick_tx, command_tx, status_rx, _) = rig(Duration::from_millis(20), 0, 0);
        let not_a_dir =
            std::env::temp_dir().join(format!("pavlov-horde-notdir-{}", std::process::id()));
        std::fs::write(&not_a_dir, b"a file where the folder should be").unwrap();
        let events = crate::bus::events::EventLog::new();
        let mut seen = events.subscribe();
        command_tx.send(HordeCommand::Events(events)).unwrap();
        let thread = std::thread::spawn(move || worker.run());
        let (done_tx, done_rx) = std::sync::mpsc::channel();
        command_tx
            .send(HordeCommand::Finish {
                checkpoint: Some(Target {
                    dir: not_a_dir.clone(),
                    keep: 5,
                }),
                done: done_tx,
            })
            .unwrap();
        let _ = done_rx.recv();
        drop(tick_tx);
        thread.join().unwrap();
        let _ = std::fs::remove_file(&not_a_dir);
        assert_eq!(status_rx.borrow().checkpoint_errors, 1);
        let event = seen.try_recv().expect("an event was announced");
        match &event.kind {
            pavlov::event::EventKind::CheckpointFailed { path, reason } => {
                assert!(path.ends_with("horde-0.bin"), "{path}");
                assert!(!reason.is_empty());
            }
            other => panic!("{other:?}"),
        }
    }
}

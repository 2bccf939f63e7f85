//! The one way an experiment runs: the server's stages on the simulated Create under tokio's paused clock,
//! and one scheduler that spreads the runs over OS threads.
//!
//! [`run_paused`] gives each run its own single-threaded runtime with the clock paused, so a 6-minute run
//! takes as long as the computation does and the same seed always gives the same ticks. It starts the
//! server (with the recorder when the run is recorded), lets a [`Collect`] see every tick record as it is
//! published, and shuts the server down in order. A run whose collector sends the server nothing, on a
//! line without faults, is instead stepped by one loop ([`crate::experiment::stepped`], [`Driver`]) that
//! calls the same per-tick functions without the actors' channels and wakes; both drivers record the same
//! ticks bit for bit. [`run_all`] runs a list of runs on `threads` threads;
//! each run's outcome depends only on its own seed, never on the scheduling. An experiment is a folder
//! that plans its runs, supplies a [`Collect`], and analyses what comes back.

use std::path::PathBuf;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::sync::{Arc, Mutex};

use pavlov::config::Config;
use pavlov::record::TickRecord;
use tokio::sync::broadcast::error::RecvError;

use crate::server::{RobotTarget, Server};
use crate::storage::recorder::Recorder;
use crate::storage::recording::RecordingHeader;

/// Why a run failed.
#[derive(Debug, thiserror::Error)]
pub enum RunError {
    /// The runtime could not be built.
    #[error("cannot build the runtime: {0}")]
    Runtime(std::io::Error),
    /// The recorder could not start.
    #[error("cannot start the recorder: {0}")]
    Recorder(std::io::Error),
    /// The server could not start.
    #[error("cannot start the server: {0}")]
    Server(String),
    /// The stepped driver could not go on.
    #[error("stepped run: {0}")]
    Stepped(#[from] crate::experiment::stepped::SteppedError),
    /// The feed closed before the run was complete.
    #[error("the tick feed closed after {0} records")]
    FeedClosed(u64),
    /// Something the experiment ran beside the server failed.
    #[error("{0}")]
    Collector(String),
    /// A run's thread panicked.
    #[error("a run panicked")]
    Panicked,
}

/// One run to make.
#[derive(Debug, Clone)]
pub(crate) struct RunRequest {
    /// The configuration (mode and seeds already set for this run).
    pub(crate) config: Config,
    /// Ticks to collect.
    pub(crate) ticks: u64,
    /// Record every tick into this directory, with this label in the recording's header.
    pub(crate) record: Option<(PathBuf, String)>,
}

/// What an experiment does with a run's ticks.
pub(crate) trait Collect {
    /// What it makes of them.
    type Output;
    /// Whether [`Collect::start`] uses the server (sends it commands or poses): such a run is driven by
    /// the actors, the others by the stepped driver ([`crate::experiment::stepped`]).
    const DRIVES_THE_SERVER: bool = false;
    /// Called once the server runs, before the first record (e.g. to start a simulated operator).
    fn start(&mut self, _server: &Server) {}
    /// Called with every tick record, in order.
    fn record(&mut self, record: Arc<TickRecord>);
    /// Called after the last record, before the server shuts down.
    fn finish(self) -> impl std::future::Future<Output = Result<Self::Output, RunError>>;
}

/// A finished run.
#[derive(Debug, Clone)]
pub(crate) struct Finished<T> {
    /// What the collector made of it.
    pub(crate) output: T,
    /// The recording, if one was written.
    pub(crate) recording: Option<PathBuf>,
    /// Records the recorder wrote.
    pub(crate) recorded: u64,
    /// Records the feed could not hand to the recorder (queue full).
    pub(crate) recorder_dropped: u64,
    /// Records the collector's subscription missed (should be 0).
    pub(crate) lagged: u64,
    /// Wall-clock time the run took, s.
    pub(crate) wall_s: f64,
}

/// How a run's tick graph is driven under the paused clock.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Driver {
    /// The server's actors, each its own task.
    Actors,
    /// One loop stepping the same stages in order ([`crate::experiment::stepped`]).
    Stepped,
}

/// Runs `request` under a paused clock and hands every record to `collector`: stepped when the
/// configuration and the collector allow it ([`Driver`]), on the actors otherwise. Both give the same
/// records.
pub(crate) fn run_paused<C: Collect>(
    request: RunRequest,
    collector: C,
) -> Result<Finished<C::Output>, RunError> {
    let driver = if !C::DRIVES_THE_SERVER && crate::experiment::stepped::steppable(&request.config)
    {
        Driver::Stepped
    } else {
        Driver::Actors
    };
    run_paused_on(driver, request, collector)
}

/// Runs `request` under a paused clock on `driver` and hands every record to `collector`.
pub(crate) fn run_paused_on<C: Collect>(
    driver: Driver,
    request: RunRequest,
    collector: C,
) -> Result<Finished<C::Output>, RunError> {
    let wall = std::time::Instant::now();
    let RunRequest {
        config,
        ticks,
        record,
    } = request;
    let recorder = match record {
        Some((dir, label)) => {
            let header = RecordingHeader::new(&config, label);
            // The queue holds the whole run, so the recording is complete however the threads are scheduled.
            let capacity = usize::try_from(ticks)
                .unwrap_or(usize::MAX)
                .saturating_add(64);
            // A folder that holds a recording already (an earlier study's, or a user's) is left alone.
            let dir = super::results::beside::recording_dir(&dir);
            Some(
                Recorder::spawn_new(header, Some(dir.clone()), dir, capacity)
                    .map_err(RunError::Recorder)?,
            )
        }
        None => None,
    };
    // The time driver only: a run touches no socket (the simulated robot is an in-process stream, the
    // skeleton ingest is off), and without the I/O driver each advance of the paused clock parks
    // without a system call (with it, every advance is an `epoll_wait`).
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_time()
        .start_paused(true)
        .build()
        .map_err(RunError::Runtime)?;
    let link = recorder.as_ref().map(|r| r.link.clone());
    let outcome = match driver {
        Driver::Actors => rt.block_on(collect(config, ticks, link, collector)),
        Driver::Stepped => rt.block_on(collect_stepped(config, ticks, link, collector)),
    };
    drop(rt);
    let report = recorder.map(Recorder::join).unwrap_or_default();
    let (output, dropped, lagged) = outcome?;
    Ok(Finished {
        output,
        recording: report.files.first().cloned(),
        recorded: report.written,
        recorder_dropped: dropped,
        lagged,
        wall_s: wall.elapsed().as_secs_f64(),
    })
}

async fn collect<C: Collect>(
    config: Config,
    ticks: u64,
    recorder: Option<crate::storage::recorder::RecorderLink>,
    mut collector: C,
) -> Result<(C::Output, u64, u64), RunError> {
    let mut builder = Server::builder(config, RobotTarget::Simulated);
    if let Some(r) = recorder {
        builder = builder.recorder(r);
    }
    let server = builder
        .start()
        .await
        .map_err(|e| RunError::Server(e.to_string()))?;
    let mut rx = server.feed().subscribe();
    collector.start(&server);
    let (mut seen, mut lagged) = (0u64, 0u64);
    while seen < ticks {
        match rx.recv().await {
            Ok(r) => {
                seen += 1;
                collector.record(r);
            }
            Err(RecvError::Lagged(n)) => lagged += n,
            Err(RecvError::Closed) => return Err(RunError::FeedClosed(seen)),
        }
    }
    let output = collector.finish().await;
    let dropped = server.feed().recorder_dropped();
    server.shutdown().await;
    Ok((output?, dropped, lagged))
}

async fn collect_stepped<C: Collect>(
    config: Config,
    ticks: u64,
    recorder: Option<crate::storage::recorder::RecorderLink>,
    mut collector: C,
) -> Result<(C::Output, u64, u64), RunError> {
    let mut stepper =
        crate::experiment::stepped::Stepper::start(&config, recorder.as_ref()).await?;
    // The recorder's queue is held by the feed and the event log from here on.
    drop(recorder);
    for _ in 0..ticks {
        collector.record(stepper.tick()?);
    }
    let output = collector.finish().await;
    let dropped = stepper.feed().recorder_dropped();
    stepper.finish().await;
    Ok((output?, dropped, 0))
}

/// Runs `run` on every spec, on `threads` OS threads, and returns the results in spec order.
/// `progress` is called as runs finish; the first failure stops further runs from starting.
pub(crate) fn run_all<S: Sync, R: Send>(
    specs: &[S],
    threads: usize,
    run: &(dyn Fn(&S) -> Result<R, RunError> + Sync),
    progress: &(dyn Fn(&R) + Sync),
) -> Result<Vec<R>, RunError> {
    let next = AtomicUsize::new(0);
    let results: Mutex<Vec<Option<Result<R, RunError>>>> =
        Mutex::new((0..specs.len()).map(|_| None).collect());
    std::thread::scope(|s| {
        for _ in 0..threads.clamp(1, specs.len().max(1)) {
            s.spawn(|| {
                loop {
                    let i = next.fetch_add(1, Ordering::Relaxed);
                    let Some(spec) = specs.get(i) else { break };
                    // The servers' own logs (start-up, tick health) would drown the progress bar.
                    let outcome = tracing::subscriber::with_default(
                        tracing::subscriber::NoSubscriber::default(),
                        || run(spec),
                    );
                    if let Ok(r) = &outcome {
                        progress(r);
                    }
                    let failed = outcome.is_err();
                    if let Ok(mut all) = results.lock()
                        && let Some(slot) = all.get_mut(i)
                    {
                        *slot = Some(outcome);
                    }
                    if failed {
                        next.store(specs.len(), Ordering::Relaxed);
                    }
                }
            });
        }
    });
    let all = results.into_inner().map_err(|_| RunError::Panicked)?;
    let mut out = Vec::with_capacity(all.len());
    for r in all {
        match r {
            Some(Ok(r)) => out.push(r),
            Some(Err(e)) => return Err(e),
            None => {}
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::super::drivers_agree::Hash;
    use super::*;

    /// The ticks of a short Pavlovian stall run, pinned: a change to how the actors are driven under the
    /// paused clock (batching, stepping, buffers) must not change one bit of what a run records. The hash
    /// is that of the protobuf messages of the first 1500 ticks of run 1 of `experiment stall --runs 2
    /// --minutes 1 --seed 1`, the bytes its recording holds, as the code before the virtual-time work
    /// (issue 26) and before the stochastic gate wrote them (checked on that code with this test).
    #[test]
    fn a_short_run_records_exactly_the_pinned_ticks() {
        let mut config =
            Config::from_toml(include_str!("../../../config/stall.toml")).expect("stall config");
        config.control.mode = pavlov::control::Mode::Pavlovian;
        config.sim.seed = super::super::stall::run_seed(1, 1);
        let request = RunRequest {
            config,
            ticks: 1500,
            record: None,
        };
        let done = run_paused(request, Hash::default()).expect("run");
        let (hash, n) = done.output;
        assert_eq!(n, 1500);
        assert_eq!(done.lagged, 0);
        assert_eq!(
            hash, "f088f22c495f9aeb81a8a01c0a92214ba34d49c4260f03e2458203e35b5383f3",
            "the run's ticks changed"
        );
    }

    /// Whole 6-minute runs (18 000 ticks) of the default stall study, pinned: runs 0 (reactive) and 1
    /// (Pavlovian) of study seed 1, run 1 of seeds 2 and 3. The simulated Create, the OI bytes, learning and
    /// the recorder's encoding were made cheaper per tick (issue 26) on the promise that no recorded bit
    /// moves. Each hash is that of the tick messages of the run's recording as the code before that work
    /// (4582006) wrote it in `experiment stall --seed S` (`runs/00-reactive`, `runs/01-pavlovian`).
    #[test]
    fn whole_stall_runs_record_exactly_the_pinned_ticks() {
        use pavlov::control::Mode::{Pavlovian, Reactive};
        let pinned = [
            (
                1,
                0,
                Reactive,
                "b0fee02d929dad5ddd34cbaf3dd1dc1ae30b33c5825fdeb465373a3dee45afbf",
            ),
            (
                1,
                1,
                Pavlovian,
                "26235f3ee0973aafc043838644460cae2da3b509d62d800c3966990a978877a6",
            ),
            (
                2,
                1,
                Pavlovian,
                "2ac4780c10ad10ec637c3e0d2e786d0fdaba30040a63d6620caa0a3a50b8ab89",
            ),
            (
                3,
                1,
                Pavlovian,
                "288fd2b360f2d66d36a96a4be82d7eedfab513dcc66bf3ac46419301e07fa125",
            ),
        ];
        let mut changed = Vec::new();
        for (seed, index, mode, want) in pinned {
            let mut config = Config::from_toml(include_str!("../../../config/stall.toml"))
                .expect("stall config");
            config.control.mode = mode;
            config.sim.seed = super::super::stall::run_seed(seed, index);
            let request = RunRequest {
                config,
                ticks: 18_000,
                record: None,
            };
            let done = run_paused(request, Hash::default()).expect("run");
            let (hash, n) = done.output;
            assert_eq!(n, 18_000);
            if hash != want {
                changed.push(format!("seed {seed} run {index} ({mode:?}): {hash}"));
            }
        }
        assert!(changed.is_empty(), "the runs' ticks changed: {changed:#?}");
    }
}

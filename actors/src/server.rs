//! One server run: the robot link, the tick pipeline, the recorder and the skeleton ingest, started by one
//! builder and stopped in an order that leaves the robot safe.
//!
//! Start-up ([`ServerBuilder::start`]): the configuration and learning (with any checkpoint to resume) are
//! checked first; then every listening socket (the skeleton's UDP port) is bound; only then is the robot
//! touched — the link opened (or the simulator started), the start-up sequence sent, the link writer and
//! the [`crate::pipeline`] started. A failure after the robot was touched shuts everything down in order.
//!
//! Shut-down ([`Server::shutdown`]): the actors are cancelled; actuation writes a stop and drops the
//! writer's queue; the writer then sends stop, pause-stream and Start (→ Passive) and closes the link;
//! only then does the server return.

use std::path::{Path, PathBuf};
use std::time::Duration;

use pavlov::checkpoint::Checkpoint;
use pavlov::config::Config;
use pavlov::oi::handshake;
use pavlov::oi::parser::StreamParser;
use pavlov::sim::faults::FaultInjector;
use pavlov::sim::robot::SimRobot;
use pavlov::skeleton::PoseTracker;
use tokio::io::AsyncWriteExt;
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

use crate::bus::{EventLog, TickFeed};
use crate::command::ControlRequest;
use crate::horde::{HordeError, HordeHandle, HordeView};
use crate::link::opener::LinkOpener;
use crate::link::serial::{SerialOpener, open_serial};
use crate::link::supervisor::Supervisor;
use crate::link::{LinkError, OpenLink, writer};
use crate::pipeline::learning::Learning;
use crate::pipeline::sensor_ingest::IngestLink;
use crate::pipeline::skeleton_ingest::{self, SkeletonIngest};
use crate::pipeline::{self, PipelineParts};
use crate::simulated::{SimStatus, robot};
use crate::storage::checkpoint_files::{self, Resumed};
use crate::storage::horde_file;
use crate::storage::recorder::{RecorderInput, RecorderLink};
use crate::telemetry::Health;
use crate::telemetry::counters::SharedWriterStats;

/// Where the robot is.
pub enum RobotTarget {
    /// The simulated Create, in process.
    Simulated,
    /// A serial device (a real Create, or `pavlov sim --pty`).
    Serial(String),
    /// A link opened by the caller (tests); `sim` is the simulator task behind it, if any.
    Link {
        /// The open link.
        link: OpenLink,
        /// The simulator task, returned by [`Server::shutdown`].
        sim: Option<JoinHandle<SimRobot>>,
    },
}

impl std::fmt::Debug for RobotTarget {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            RobotTarget::Simulated => write!(f, "Simulated"),
            RobotTarget::Serial(path) => write!(f, "Serial({path})"),
            RobotTarget::Link { .. } => write!(f, "Link"),
        }
    }
}

/// Which robot a server drives, as the dashboard's header shows it.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RobotLinkKind {
    /// The simulated Create, in process (or behind a link a test opened for one).
    Simulated,
    /// A serial device at this path.
    Serial(String),
    /// A link opened by the caller, with no simulator behind it that the server knows of.
    External,
}

impl RobotTarget {
    /// What the dashboard says of this target.
    fn kind(&self) -> RobotLinkKind {
        match self {
            RobotTarget::Simulated => RobotLinkKind::Simulated,
            RobotTarget::Serial(path) => RobotLinkKind::Serial(path.clone()),
            RobotTarget::Link { sim: Some(_), .. } => RobotLinkKind::Simulated,
            RobotTarget::Link { sim: None, .. } => RobotLinkKind::External,
        }
    }
}

/// Errors starting the server.
#[derive(Debug, thiserror::Error)]
pub enum ServerError {
    /// The robot link failed.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// The skeleton ingest could not start (`[skeleton] listen` taken or invalid).
    #[error("skeleton ingest: {0}; stop whatever holds the port or change [skeleton] listen")]
    Skeleton(skeleton_ingest::IngestError),
    /// The configuration is invalid.
    #[error("configuration: {0}")]
    Config(#[from] pavlov::config::ConfigError),
    /// Learning could not be set up from the configuration.
    #[error("learning: {0}")]
    Learning(String),
}

/// Builds a server: [`Server::builder`], then options, then [`ServerBuilder::start`].
pub struct ServerBuilder {
    config: Config,
    target: RobotTarget,
    recorder: Option<RecorderLink>,
}

impl ServerBuilder {
    /// Also hands every tick record to `recorder`, and routes recording commands to it.
    pub fn recorder(mut self, recorder: RecorderLink) -> Self {
        self.recorder = Some(recorder);
        self
    }

    /// Checks everything, binds the listening sockets, opens the robot link, sends the start-up sequence
    /// and starts every actor.
    pub async fn start(self) -> Result<Server, ServerError> {
        let ServerBuilder {
            config,
            target,
            recorder,
        } = self;
        config.validate()?;
        // Learning (and any checkpoint to resume) is checked before the robot is touched.
        let (learning, checkpoints) = build_learning(&config)?;
        let stream = config.robot.stream_ids();
        let model = config.robot.model;
        let startup = handshake::startup_bytes(model, config.robot.oi_mode, &stream)
            .map_err(LinkError::from)?;
        let shutdown = handshake::shutdown_bytes(model).map_err(LinkError::from)?;
        let parser = StreamParser::new(&stream)
            .map_err(LinkError::from)?
            .with_model(model);
        let cancel = CancellationToken::new();
        let period = Duration::from_millis(config.tick.period_ms);
        let started = Instant::now() + period;
        // Every listening socket is bound before a byte goes to the robot.
        let skeleton = skeleton_ingest::bind_for(&config)
            .await
            .map_err(ServerError::Skeleton)?;

        let sim_cancel = CancellationToken::new();
        let robot = target.kind();
        let (link, sim, sim_status) = open_robot(&config, target, &sim_cancel)?;
        let OpenLink {
            reader,
            writer: mut link_writer,
            opener,
        } = link;
        let mut stopper = Stopper {
            sim_cancel: sim_cancel.clone(),
            sim,
        };
        // Frames no Create could send (values out of range) are rejected like a bad checksum.
        let sent = async {
            link_writer.write_all(&startup).await?;
            link_writer.flush().await
        }
        .await;
        if let Err(e) = sent {
            stopper.stop().await;
            return Err(LinkError::Io(e).into());
        }
        let link_up_at = Instant::now();
        tracing::info!(%model, ?stream, "robot link up: start-up sequence sent");

        let (write_tx, write_rx) = mpsc::channel(16);
        let (control_tx, control_rx) = mpsc::channel(8);
        let writer_stats = SharedWriterStats::default();
        let writer = tokio::spawn(writer::run(
            link_writer,
            write_rx,
            control_rx,
            shutdown,
            writer_stats.clone(),
        ));
        let obs_names = learning.obs_names();
        let horde = learning.horde_view();
        let params_at_start = learning.params_in_force();
        let (feed, events) = feed_and_events(recorder.as_ref());
        let recorder_commands = recorder.as_ref().map(|r| r.commands.clone());
        let ingest = IngestLink {
            reader,
            parser,
            supervisor: Supervisor::new(&config, opener, control_tx, link_up_at)
                .with_events(events.clone()),
        };
        let initial = Box::new(learning.initial_start_state(&events));
        let pipeline = pipeline::spawn(
            &config,
            PipelineParts {
                learning,
                ingest,
                writer: write_tx,
                feed: feed.clone(),
                recorder: recorder_commands,
                started,
                events: events.clone(),
            },
            &cancel,
        );
        if let Some(r) = &recorder {
            // The recorder may now ask for the learner's state, and begin a recording waiting for it.
            let attach = RecorderInput::Attach {
                snapshots: pipeline.snapshots.clone(),
                events: events.clone(),
                initial,
            };
            if r.input.send(attach).await.is_err() {
                tracing::error!("the recorder has stopped: nothing will be recorded");
            }
        }
        let mut actors = pipeline.tasks;
        let pose = pipeline.pose;
        // The bound skeleton socket starts publishing into the pipeline's pose channel.
        let skeleton = skeleton.map(|bound| {
            let (ingest, task) = bound.spawn(pose.clone(), started, cancel.clone());
            actors.push(task);
            ingest
        });
        let health = Health {
            ticks: pipeline.ticks,
            timer: pipeline.timer,
            writer: writer_stats,
            actuation: pipeline.actuation,
            sim: sim_status,
            recorder: feed.recorder_gauge(),
            link: feed.latest_link(),
            foxglove: Default::default(),
            zenoh: Default::default(),
            horde: horde.as_ref().map(|h| h.status.clone()),
            storage: events.storage_failures(),
        };
        actors.push(tokio::spawn(crate::telemetry::health_log::run(
            health.clone(),
            cancel.clone(),
        )));
        Ok(Server {
            feed,
            events,
            commands: pipeline.commands,
            estop: pipeline.estop,
            pose,
            started,
            config,
            checkpoints,
            obs_names,
            params_at_start,
            robot,
            skeleton,
            horde,
            health,
            _cancel_on_drop: cancel.clone().drop_guard(),
            cancel,
            actors,
            writer,
            stopper,
        })
    }
}

/// The tick feed and the event log, both handing what they publish to `recorder` too when there is one.
pub(crate) fn feed_and_events(recorder: Option<&RecorderLink>) -> (TickFeed, EventLog) {
    match recorder {
        Some(r) => {
            let feed = TickFeed::new().with_recorder(r.input.clone());
            let dropped = feed.recorder_dropped_counter();
            let events = EventLog::new().with_recorder(r.input.clone(), dropped);
            (feed, events)
        }
        None => (TickFeed::new(), EventLog::new()),
    }
}

/// An opened robot: the link, the simulator task behind it and its status (when simulated).
type OpenedRobot = (
    OpenLink,
    Option<JoinHandle<SimRobot>>,
    Option<watch::Receiver<SimStatus>>,
);

/// Opens the robot link for `target`: the simulator (with its faults) or a serial port.
fn open_robot(
    config: &Config,
    target: RobotTarget,
    sim_cancel: &CancellationToken,
) -> Result<OpenedRobot, ServerError> {
    let model = config.robot.model;
    Ok(match target {
        RobotTarget::Simulated => {
            let robot = SimRobot::new(model, config.sim.robot_params(model), config.sim.seed);
            let faults = config.sim.fault_spec()?;
            // The injector forks its own streams from the seed, apart from the robot's.
            let injector = FaultInjector::new(faults, config.sim.seed);
            let l = robot::spawn_sim_with_faults(robot, injector, sim_cancel.clone());
            let opener: Box<dyn LinkOpener> = Box::new(l.device);
            let link = OpenLink {
                reader: l.reader,
                writer: l.writer,
                opener: Some(opener),
            };
            (link, Some(l.robot), Some(l.status))
        }
        RobotTarget::Serial(path) => {
            let (reader, writer) = open_serial(&path, model)?;
            let opener: Box<dyn LinkOpener> = Box::new(SerialOpener::new(path, model));
            let link = OpenLink {
                reader,
                writer,
                opener: Some(opener),
            };
            (link, None, None)
        }
        RobotTarget::Link { link, sim } => (link, sim, None),
    })
}

/// Stops the simulator behind the link (if any) once the link is closed.
struct Stopper {
    sim_cancel: CancellationToken,
    sim: Option<JoinHandle<SimRobot>>,
}

impl Stopper {
    /// Waits up to a second for the simulator to see the link closed, then cancels it.
    async fn stop(&mut self) -> Option<SimRobot> {
        let handle = self.sim.take()?;
        // The writer closed the link after the shut-down sequence; the simulator stops at end-of-file.
        let cancel = self.sim_cancel.clone();
        let guard = tokio::spawn(async move {
            tokio::time::sleep(Duration::from_secs(1)).await;
            cancel.cancel();
        });
        let robot = handle.await.ok();
        guard.abort();
        robot
    }
}

/// A running server.
pub struct Server {
    /// Every tick's record.
    feed: TickFeed,
    /// Every change made at run time.
    events: EventLog,
    /// Inject commands here.
    commands: mpsc::Sender<ControlRequest>,
    /// The e-stop latch itself, for a client that must latch it ahead of its own earlier commands (an
    /// operator's websocket connection); every other e-stop goes through `commands`.
    estop: crate::pipeline::latch::EstopLatch,
    /// Publish skeleton poses here (the skeleton ingest actor, or a test).
    pose: watch::Sender<PoseTracker>,
    /// The time the first tick was due.
    started: Instant,
    /// The configuration in force at start-up.
    config: Config,
    /// What start-up did with checkpoints: what was resumed, where this run's checkpoints go.
    checkpoints: CheckpointStart,
    /// The skeleton ingest, when `[skeleton]` is enabled and its socket opened.
    skeleton: Option<SkeletonIngest>,
    /// Names of the observation vector's dimensions, in record order.
    obs_names: Vec<String>,
    /// The Horde's figures and values, when `[horde]` has families.
    horde: Option<HordeView>,
    /// Every prediction's learning parameters at the first tick (a resumed checkpoint's, where it has
    /// them), in configuration order; later changes are `params_set` events.
    pub(crate) params_at_start: Vec<pavlov::agent::learning::ParamsInForce>,
    /// Which robot this server drives.
    pub(crate) robot: RobotLinkKind,
    health: Health,
    cancel: CancellationToken,
    actors: Vec<JoinHandle<()>>,
    writer: JoinHandle<()>,
    stopper: Stopper,
    // A server dropped without `shutdown` still stops its actors (actuation then stops the wheels).
    _cancel_on_drop: tokio_util::sync::DropGuard,
}

/// What is left after a shut-down.
pub struct ShutdownReport {
    /// The simulated robot, when the server ran one: its state after the shut-down sequence.
    pub sim_robot: Option<SimRobot>,
}

impl Server {
    /// A builder for a server of `config` driving `target`.
    pub fn builder(config: Config, target: RobotTarget) -> ServerBuilder {
        ServerBuilder {
            config,
            target,
            recorder: None,
        }
    }

    /// Every health figure of this server (tick timing, latency, counters).
    pub fn health(&self) -> Health {
        self.health.clone()
    }

    /// Every tick's record.
    pub fn feed(&self) -> &TickFeed {
        &self.feed
    }

    /// Every change made at run time.
    pub fn events(&self) -> &EventLog {
        &self.events
    }

    /// Where commands go in (the router hands each to its owner).
    pub fn commands(&self) -> &mpsc::Sender<ControlRequest> {
        &self.commands
    }

    /// The e-stop latch itself, for a client that must latch it ahead of its own earlier commands.
    pub fn estop(&self) -> &crate::pipeline::latch::EstopLatch {
        &self.estop
    }

    /// Where skeleton poses go in: the skeleton ingest publishes here, and so may a test or the simulated
    /// operator of the interaction experiment.
    pub fn pose(&self) -> &watch::Sender<PoseTracker> {
        &self.pose
    }

    /// The time the first tick was due.
    pub fn started(&self) -> Instant {
        self.started
    }

    /// The configuration in force at start-up.
    pub fn config(&self) -> &Config {
        &self.config
    }

    /// What start-up did with checkpoints: what was resumed, where this run's checkpoints go.
    pub fn checkpoints(&self) -> &CheckpointStart {
        &self.checkpoints
    }

    /// The skeleton ingest, when `[skeleton]` is enabled and its socket opened.
    pub fn skeleton(&self) -> Option<&SkeletonIngest> {
        self.skeleton.as_ref()
    }

    /// Names of the observation vector's dimensions, in record order.
    pub fn obs_names(&self) -> &[String] {
        &self.obs_names
    }

    /// The Horde's figures and values, when `[horde]` has families.
    pub fn horde(&self) -> Option<&HordeView> {
        self.horde.as_ref()
    }

    /// Stops every actor, sends the shut-down sequence to the robot and waits for it to be written.
    pub async fn shutdown(mut self) -> ShutdownReport {
        self.cancel.cancel();
        for a in std::mem::take(&mut self.actors) {
            if let Err(e) = a.await {
                tracing::error!("an actor panicked: {e}");
            }
        }
        if let Err(e) = (&mut self.writer).await {
            tracing::error!("the link writer panicked: {e}");
        }
        ShutdownReport {
            sim_robot: self.stopper.stop().await,
        }
    }
}

/// What start-up did with checkpoints.
#[derive(Debug, Default)]
pub struct CheckpointStart {
    /// The checkpoint resumed from, the newer ones skipped and why, and the learning parameters it
    /// carries that differ from the configuration's (the checkpoint's are in force).
    pub resumed: Option<Resumed>,
    /// This run's folder of automatic checkpoints, `[checkpoint] dir/runs/<run id>/` (with autosave).
    pub run_dir: Option<PathBuf>,
}

/// Learning for `config`: resumed from `[checkpoint] resume_from`, or from the newest valid checkpoint
/// if `[checkpoint] resume`, and checkpointing into a new run folder if `[checkpoint] autosave`. What
/// was resumed, skipped and overridden is logged.
pub(crate) fn build_learning(config: &Config) -> Result<(Learning, CheckpointStart), ServerError> {
    let mut learning = Learning::new(config).map_err(|e| ServerError::Learning(e.to_string()))?;
    let c = &config.checkpoint;
    let mut restore = |cp: &Checkpoint| learning.resume(cp).map_err(|e| e.to_string());
    let resumed = if let Some(file) = &c.resume_from {
        let r = checkpoint_files::resume_file(config, Path::new(file), &mut restore)
            .map_err(|e| ServerError::Learning(format!("--resume-from: {e}")))?;
        Some(r)
    } else if c.resume {
        let r = checkpoint_files::resume_newest(config, &mut restore)
            .map_err(|e| ServerError::Learning(format!("--resume: {e}")))?;
        Some(r)
    } else {
        None
    };
    if let Some(r) = &resumed {
        tracing::info!(path = %r.path.display(), tick = r.tick, "resumed learning from a checkpoint");
        for s in &r.skipped {
            tracing::warn!(path = %s.path.display(), "skipped a newer checkpoint: {}", s.reason);
        }
        for o in &r.overrides {
            tracing::info!(
                prediction = %o.prediction,
                parameter = o.parameter,
                checkpoint = o.checkpoint,
                configuration = o.configuration,
                "resumed {o}"
            );
        }
    }
    let horde_resume = resumed
        .as_ref()
        .and_then(|r| r.path.parent())
        .and_then(horde_file::newest_in);
    let horde = match HordeHandle::spawn(config, horde_resume.as_deref(), learning.tick_offset()) {
        Ok(h) => h,
        // A Horde checkpoint of other families (edited since) or damaged: the Horde starts afresh;
        // the control predictions, which were resumed, are what the robot depends on.
        Err(e @ HordeError::Resume { .. }) => {
            tracing::warn!("{e}; the Horde starts from its initial weights");
            HordeHandle::spawn(config, None, learning.tick_offset())
                .map_err(|e| ServerError::Learning(e.to_string()))?
        }
        Err(e) => return Err(ServerError::Learning(e.to_string())),
    };
    learning = learning.with_horde(horde);
    if c.autosave {
        learning = learning.with_autosave().map_err(|e| {
            ServerError::Learning(format!("cannot start the checkpoint writer: {e}"))
        })?;
    }
    let run_dir = learning.run_dir().map(Path::to_path_buf);
    if let Some(dir) = &run_dir {
        tracing::info!(dir = %dir.display(), "this run's checkpoints go into its own folder");
    }
    Ok((learning, CheckpointStart { resumed, run_dir }))
}

//! Wiring: starts every actor of one server run, and stops them in an order that leaves the robot safe.
//!
//! ```text
//! ticker ─Tick─► sensor ingest ─Observation─► learning ─Prediction─► gating ─Decision─► actuation ─bytes─► writer ─► robot
//!    │                                   ▲ pose (skeleton ingest)        ▲ mode/teleop        ▲ e-stop latch
//!    └────────────── Tick (watchdog) ─────┼─────────────────────────────────┼────────────────────┘
//! commands ─► router ─────────────────────┴─ params/reset/save/request ───┘          TickRecord ─► feed (dashboard, recorder)
//! ```
//!
//! Shut-down: the actors are cancelled; actuation writes a stop and drops the writer's queue; the writer then
//! sends stop, pause-stream and Start (→ Passive) and closes the link; only then does the server return.

use std::sync::Arc;
use std::time::Duration;

use pavlov::config::Config;
use pavlov::oi::parser::StreamParser;
use pavlov::sim::params::SimParams;
use pavlov::sim::robot::SimRobot;
use pavlov::skeleton::PoseTracker;
use tokio::io::AsyncWriteExt;
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

use crate::actuation::{self, Actuation, ActuationStats};
use crate::command::{self, CommandRoutes, ControlRequest};
use crate::feed::TickFeed;
use crate::gating;
use crate::learning::{self, Learning};
use crate::link::opener::{LinkOpener, SerialOpener};
use crate::link::supervisor::Supervisor;
use crate::link::{LinkError, LinkReader, LinkWriter, OpenLink, handshake, transport, writer};
use crate::ticker::{self, SharedTickStats};
use pavlov::agent::GatingStage;
use pavlov::sim::faults::FaultInjector;

/// Where the robot is.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum RobotTarget {
    /// The simulated Create, in process.
    Simulated,
    /// A serial device (a real Create, or `pavlov sim --pty`).
    Serial(String),
}

/// Errors starting the server.
#[derive(Debug, thiserror::Error)]
pub enum ServerError {
    /// The robot link failed.
    #[error(transparent)]
    Link(#[from] LinkError),
    /// The skeleton ingest could not start (`[skeleton] listen` taken or invalid).
    #[error("skeleton ingest: {0}; stop whatever holds the port or change [skeleton] listen")]
    Skeleton(crate::skeleton_ingest::IngestError),
    /// The configuration is invalid.
    #[error("configuration: {0}")]
    Config(#[from] pavlov::config::ConfigError),
    /// Learning could not be set up from the configuration.
    #[error("learning: {0}")]
    Learning(String),
}

/// A running server.
pub struct Server {
    /// Every tick's record.
    pub feed: TickFeed,
    /// Inject commands here.
    pub commands: mpsc::Sender<ControlRequest>,
    /// Tick lateness and skips.
    pub tick_stats: SharedTickStats,
    /// Tick-to-command latency and write errors.
    pub writer_stats: writer::SharedWriterStats,
    /// Actuation's counters.
    pub actuation_stats: watch::Receiver<ActuationStats>,
    /// Publish skeleton poses here (the skeleton ingest actor, or a test).
    pub pose: watch::Sender<PoseTracker>,
    /// The time the first tick was due.
    pub started: Instant,
    /// The configuration in force at start-up.
    pub config: Config,
    /// The skeleton ingest, when `[skeleton]` is enabled and its socket opened.
    pub skeleton: Option<crate::skeleton_ingest::SkeletonIngest>,
    /// Names of the observation vector's dimensions, in record order.
    pub obs_names: Vec<String>,
    /// The in-process simulated robot's state after each step (and the faults injected), when simulated.
    pub sim_status: Option<watch::Receiver<transport::SimStatus>>,
    cancel: CancellationToken,
    sim_cancel: CancellationToken,
    actors: Vec<JoinHandle<()>>,
    writer: JoinHandle<()>,
    sim: Option<JoinHandle<SimRobot>>,
    // A server dropped without `shutdown` still stops its actors (actuation then stops the wheels).
    _cancel_on_drop: tokio_util::sync::DropGuard,
}

/// What is left after a shut-down.
pub struct ShutdownReport {
    /// The simulated robot, when the server ran one: its state after the shut-down sequence.
    pub sim_robot: Option<SimRobot>,
}

impl Server {
    /// Opens the robot link, sends the start-up sequence and starts every actor.
    pub async fn start(config: Config, target: RobotTarget) -> Result<Server, ServerError> {
        Self::start_with_recorder(config, target, None).await
    }

    /// Like [`Server::start`], with every tick record also queued to `recorder` (and the router's
    /// start/stop-recording commands sent to it).
    pub async fn start_with_recorder(
        config: Config,
        target: RobotTarget,
        recorder: Option<crate::recorder::RecorderLink>,
    ) -> Result<Server, ServerError> {
        let model = config.robot.model;
        let sim_cancel = CancellationToken::new();
        // A checkpoint that cannot be resumed is refused before the robot (or the simulator) is touched.
        if config.checkpoint.resume {
            crate::checkpoint::load_for_resume(&config)
                .map_err(|e| ServerError::Learning(format!("--resume: {e}")))?;
        }
        let mut sim_status = None;
        let (link, sim) = match &target {
            RobotTarget::Simulated => {
                let robot = SimRobot::new(model, SimParams::for_model(model), config.sim.seed);
                let faults = config.sim.fault_spec()?;
                // The injector forks its own streams from the seed, apart from the robot's.
                let injector = FaultInjector::new(faults, config.sim.seed);
                let l = transport::spawn_sim_with_faults(robot, injector, sim_cancel.clone());
                let opener: Box<dyn LinkOpener> = Box::new(l.device);
                sim_status = Some(l.status);
                let link = OpenLink {
                    reader: l.reader,
                    writer: l.writer,
                    opener: Some(opener),
                };
                (link, Some(l.robot))
            }
            RobotTarget::Serial(path) => {
                let (r, w) = transport::open_serial(path, model)?;
                let opener: Box<dyn LinkOpener> = Box::new(SerialOpener::new(path.clone(), model));
                let link = OpenLink {
                    reader: r,
                    writer: w,
                    opener: Some(opener),
                };
                (link, None)
            }
        };
        let mut server =
            Self::start_on_link_with_recorder(config, link, sim, sim_cancel, recorder).await?;
        server.sim_status = sim_status;
        Ok(server)
    }

    /// Starts the server on an already open link (`sim`: the simulator task behind it, if any). The link
    /// cannot be reopened: a dead stream is re-synced with backoff instead.
    pub async fn start_on_link(
        config: Config,
        reader: LinkReader,
        link_writer: LinkWriter,
        sim: Option<JoinHandle<SimRobot>>,
        sim_cancel: CancellationToken,
    ) -> Result<Server, ServerError> {
        Self::start_on_link_with_recorder(
            config,
            OpenLink {
                reader,
                writer: link_writer,
                opener: None,
            },
            sim,
            sim_cancel,
            None,
        )
        .await
    }

    /// [`Server::start_on_link`] with a way to reopen the link and an optional recorder.
    pub async fn start_on_link_with_recorder(
        config: Config,
        link: OpenLink,
        sim: Option<JoinHandle<SimRobot>>,
        sim_cancel: CancellationToken,
        recorder: Option<crate::recorder::RecorderLink>,
    ) -> Result<Server, ServerError> {
        let OpenLink {
            reader,
            writer: mut link_writer,
            opener,
        } = link;
        let model = config.robot.model;
        let stream = config.robot.stream_ids();
        let period = Duration::from_millis(config.tick.period_ms);
        let cancel = CancellationToken::new();
        // Learning (and any checkpoint to resume) is checked before a byte goes to the robot.
        let learning = build_learning(&config)?;
        let startup = handshake::startup_bytes(model, config.robot.oi_mode, &stream)
            .map_err(LinkError::from)?;
        link_writer
            .write_all(&startup)
            .await
            .map_err(LinkError::Io)?;
        link_writer.flush().await.map_err(LinkError::Io)?;
        let link_up_at = Instant::now();
        tracing::info!(%model, ?stream, "robot link up: start-up sequence sent");
        // Frames no Create could send (values out of range) are rejected like a bad checksum.
        let parser = StreamParser::new(&stream)
            .map_err(LinkError::from)?
            .with_model(model);

        let obs_names = learning.obs_names();
        let gating = GatingStage::new(
            config.control.mode,
            config.control.default_policy,
            config.control.response,
        );
        let actuation = Actuation::new(model, config.safety.clone());

        let (tick_tx, tick_rx) = watch::channel(None);
        let (obs_tx, obs_rx) = mpsc::channel(4);
        let (pred_tx, pred_rx) = mpsc::channel(4);
        let (dec_tx, dec_rx) = mpsc::channel(4);
        let (write_tx, write_rx) = mpsc::channel(16);
        let (control_tx, control_rx) = mpsc::channel(8);
        let (link_cmd_tx, link_cmd_rx) = mpsc::channel(4);
        let (cmd_tx, cmd_rx) = mpsc::channel(64);
        let (gating_cmd_tx, gating_cmd_rx) = mpsc::channel(16);
        let (learning_cmd_tx, learning_cmd_rx) = mpsc::channel(16);
        let (estop_tx, estop_rx) = watch::channel(false);
        let (act_stats_tx, act_stats_rx) = watch::channel(ActuationStats::default());
        let (pose_tx, pose_rx) = watch::channel(PoseTracker::new(config.skeleton.max_joint_age_ms));
        let (feed, recorder_commands) = match recorder {
            Some(r) => (TickFeed::new().with_recorder(r.records), Some(r.commands)),
            None => (TickFeed::new(), None),
        };
        let tick_stats = SharedTickStats::default();
        let writer_stats = writer::SharedWriterStats::default();

        let shutdown = handshake::shutdown_bytes(model).map_err(LinkError::from)?;
        let writer = tokio::spawn(writer::run(
            link_writer,
            write_rx,
            control_rx,
            shutdown,
            writer_stats.clone(),
        ));
        let started = Instant::now() + period;
        let mut actors = vec![
            tokio::spawn(ticker::run(
                started,
                period,
                tick_tx,
                tick_stats.clone(),
                cancel.clone(),
            )),
            tokio::spawn(crate::sensor_ingest::run(
                crate::sensor_ingest::IngestLink {
                    reader,
                    parser,
                    supervisor: Supervisor::new(&config, opener, control_tx, link_up_at),
                    commands: link_cmd_rx,
                },
                period,
                tick_rx.clone(),
                obs_tx,
                cancel.clone(),
            )),
            tokio::spawn(learning::run(
                learning,
                started,
                obs_rx,
                pose_rx,
                learning_cmd_rx,
                pred_tx,
                cancel.clone(),
            )),
            tokio::spawn(gating::run(
                gating,
                pred_rx,
                gating_cmd_rx,
                dec_tx,
                cancel.clone(),
            )),
            tokio::spawn(actuation::run(
                actuation,
                actuation::ActuationChannels {
                    decisions: dec_rx,
                    ticks: tick_rx,
                    estop: estop_rx,
                    writer: write_tx,
                    feed: feed.clone(),
                    stats: act_stats_tx,
                },
                cancel.clone(),
            )),
            tokio::spawn(command::route(
                cmd_rx,
                CommandRoutes {
                    gating: gating_cmd_tx,
                    learning: learning_cmd_tx,
                    link: link_cmd_tx,
                    estop: estop_tx,
                    recorder: recorder_commands,
                },
                cancel.clone(),
            )),
            tokio::spawn(log_health(
                (tick_stats.clone(), writer_stats.clone()),
                cancel.clone(),
            )),
        ];
        // A skeleton port that cannot be opened stops the start-up: the gesture experiment would run blind.
        let (skeleton, skeleton_error) = match crate::skeleton_ingest::start_for(
            &config,
            pose_tx.clone(),
            started,
            cancel.clone(),
        )
        .await
        {
            Ok(Some((ingest, handle))) => {
                actors.push(handle);
                (Some(ingest), None)
            }
            Ok(None) => (None, None),
            Err(e) => (None, Some(e)),
        };
        let server = Server {
            feed,
            commands: cmd_tx,
            tick_stats,
            writer_stats,
            actuation_stats: act_stats_rx,
            pose: pose_tx,
            started,
            config,
            obs_names,
            sim_status: None,
            skeleton,
            _cancel_on_drop: cancel.clone().drop_guard(),
            cancel,
            sim_cancel,
            actors,
            writer,
            sim,
        };
        if let Some(e) = skeleton_error {
            // Everything already started is stopped in order (the robot is left stopped, in Passive).
            server.shutdown().await;
            return Err(ServerError::Skeleton(e));
        }
        Ok(server)
    }

    /// A token that, when cancelled, stops the server's actors (the caller still awaits [`Server::shutdown`]).
    pub fn cancel_token(&self) -> CancellationToken {
        self.cancel.clone()
    }

    /// Stops every actor, sends the shut-down sequence to the robot and waits for it to be written.
    pub async fn shutdown(self) -> ShutdownReport {
        self.cancel.cancel();
        for a in self.actors {
            if let Err(e) = a.await {
                tracing::error!("an actor panicked: {e}");
            }
        }
        if let Err(e) = self.writer.await {
            tracing::error!("the link writer panicked: {e}");
        }
        let sim_robot = match self.sim {
            Some(handle) => {
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
            None => None,
        };
        ShutdownReport { sim_robot }
    }
}

/// Learning for `config`: resumed from the newest checkpoint if `[checkpoint] resume`, checkpointing
/// if `[checkpoint] autosave`.
fn build_learning(config: &Config) -> Result<Learning, ServerError> {
    let mut learning = Learning::new(config).map_err(|e| ServerError::Learning(e.to_string()))?;
    if config.checkpoint.resume {
        let (path, checkpoint) = crate::checkpoint::load_for_resume(config)
            .map_err(|e| ServerError::Learning(format!("--resume: {e}")))?;
        learning
            .resume(&checkpoint)
            .map_err(|e| ServerError::Learning(format!("--resume: {}: {e}", path.display())))?;
        tracing::info!(path = %path.display(), tick = checkpoint.created_tick, "resumed learning from a checkpoint");
    }
    if config.checkpoint.autosave {
        learning = learning.with_autosave(config).map_err(|e| {
            ServerError::Learning(format!("cannot start the checkpoint writer: {e}"))
        })?;
    }
    Ok(learning)
}

/// Logs tick health once a minute until `cancel` fires.
pub async fn log_health(
    server_stats: (SharedTickStats, writer::SharedWriterStats),
    cancel: CancellationToken,
) {
    let (ticks, writes) = server_stats;
    let mut every = tokio::time::interval_at(
        Instant::now() + Duration::from_secs(60),
        Duration::from_secs(60),
    );
    loop {
        tokio::select! {
            _ = cancel.cancelled() => break,
            _ = every.tick() => {
                let (lat, fired, skipped) = match ticks.lock() {
                    Ok(s) => (s.lateness.summary(), s.fired, s.skipped),
                    Err(_) => continue,
                };
                let cmd = match writes.lock() {
                    Ok(s) => s.tick_to_command.summary(),
                    Err(_) => continue,
                };
                tracing::info!(
                    fired, skipped,
                    lateness_p50_us = lat.p50_us, lateness_p99_us = lat.p99_us, lateness_max_us = lat.max_us,
                    tick_to_command_p50_us = cmd.p50_us, tick_to_command_p99_us = cmd.p99_us, tick_to_command_max_us = cmd.max_us,
                    "tick health"
                );
            }
        }
    }
}

/// Shared pointer alias used by subscribers.
pub type Record = Arc<pavlov::record::TickRecord>;

//! The tick graph: the actors that run once per 20 ms tick, and every channel between them, wired here
//! in one place.
//!
//! ```text
//!            ┌────────── Tick (watch) ─────────────────────────────────────────────┐
//! ticker ────┤                                                                      ▼ watchdog
//!            └─► sensor ingest ─Observation─► learning ─Learned─► gating ─Decision─► actuation ─► link writer
//!                  ▲ link commands             ▲ pose  ▲ cmds       ▲ cmds ▲ e-stop    ▲ e-stop      │
//! router ──────────┴───────────────────────────┴───────┘────────────┘──────┴───────────┘      TickRecord ─► feed
//! ```
//!
//! - `ticker`: the only clock that drives control (its own timer thread in real time).
//! - `sensor_ingest`: robot bytes → the newest observation on every tick (hosts link supervision).
//! - [`skeleton_ingest`]: OSC skeletons over UDP → the newest pose.
//! - `learning`, `gating`, `actuation`: thin shells over the core's stages; actuation assembles
//!   each tick's record.
//! - `router`: every command to its owner's inbox without waiting (the e-stop latch it applies itself).
//! - the feed (`crate::bus::feed`, on the bus): every tick record out to the dashboard, the recorder and
//!   the tests, without blocking.
//!
//! In virtual time (experiments, tests) the same stages can instead be stepped in order by one loop,
//! `crate::experiment::stepped`, which calls the per-tick functions these actors call, without their channels and wakes.
//!
//! Every channel on the tick path is bounded and written with `try_send`: a stage that falls behind loses
//! its oldest input (and actuation's watchdog stops the wheels), it never makes an earlier stage wait.

pub(crate) mod actuation;
pub(crate) mod gating;
pub mod latch;
pub(crate) mod learning;
pub(crate) mod router;
pub(crate) mod sensor_ingest;
pub mod skeleton_ingest;
pub(crate) mod ticker;

use std::time::Duration;

use pavlov::agent::GatingStage;
use pavlov::config::{Config, TickTimer};
use pavlov::skeleton::PoseTracker;
use tokio::sync::{mpsc, oneshot, watch};
use tokio::task::JoinHandle;
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

use crate::bus::{EventLog, StartState, TickFeed};
use crate::command::{ControlRequest, Envelope, INBOX_CAPACITY, RecorderCommand};
use crate::link::writer::WriteRequest;
use crate::telemetry::counters::{ActuationStats, SharedTickStats};

use actuation::{Actuation, ActuationChannels};
use gating::GatingChannels;
use learning::{Learning, LearningChannels};
use router::Routes;
use sensor_ingest::{IngestChannels, IngestLink};

/// Capacity of the stage-to-stage channels, in ticks.
const STAGE_CAPACITY: usize = 4;

/// Capacity of the server's command inbox.
const COMMAND_CAPACITY: usize = 64;

/// What the pipeline is built from.
pub(crate) struct PipelineParts {
    /// Learning, ready to run (resumed and autosaving as configured).
    pub(crate) learning: Learning,
    /// The link's reading side with its parser and supervisor.
    pub(crate) ingest: IngestLink,
    /// The link writer's command queue.
    pub(crate) writer: mpsc::Sender<WriteRequest>,
    /// Where tick records go.
    pub(crate) feed: TickFeed,
    /// The recorder's inbox, when the server records.
    pub(crate) recorder: Option<mpsc::Sender<Envelope<RecorderCommand>>>,
    /// When the first tick is due.
    pub(crate) started: Instant,
    /// Where changes made at run time are announced.
    pub(crate) events: EventLog,
}

/// The running pipeline.
pub(crate) struct Pipeline {
    /// The command inbox (the router's).
    pub(crate) commands: mpsc::Sender<ControlRequest>,
    /// The e-stop latch, for the clients that set it ahead of their other commands.
    pub(crate) estop: latch::EstopLatch,
    /// Publish skeleton poses here.
    pub(crate) pose: watch::Sender<PoseTracker>,
    /// The ticker's figures.
    pub(crate) ticks: SharedTickStats,
    /// The timer that drives the tick.
    pub(crate) timer: TickTimer,
    /// Actuation's counters.
    pub(crate) actuation: watch::Receiver<ActuationStats>,
    /// The actor tasks, in start order.
    pub(crate) tasks: Vec<JoinHandle<()>>,
    /// Asks learning for the learner's state between two ticks (for a recording that begins).
    pub(crate) snapshots: mpsc::Sender<oneshot::Sender<StartState>>,
}

/// Gating and actuation for `config`, as the tick graph runs them (the actors or `crate::experiment::stepped`).
pub(crate) fn stages(config: &Config) -> (GatingStage, Actuation) {
    let gating = GatingStage::new(
        config.control.mode,
        config.control.default_policy,
        config.control.response,
        config.rule_table(),
    )
    .with_stochastic_gate(pavlov::agent::StochasticGate::from_config(config));
    (
        gating,
        Actuation::new(config.robot.model, config.safety.clone()),
    )
}

/// Starts every actor of the tick graph for `config`; they stop when `cancel` fires.
pub(crate) fn spawn(config: &Config, parts: PipelineParts, cancel: &CancellationToken) -> Pipeline {
    let PipelineParts {
        learning,
        ingest,
        writer,
        feed,
        recorder,
        started,
        events,
    } = parts;
    let period = Duration::from_millis(config.tick.period_ms);
    let (gating, actuation) = stages(config);

    let (tick_tx, tick_rx) = watch::channel(None);
    let (obs_tx, obs_rx) = mpsc::channel(STAGE_CAPACITY);
    let (learned_tx, learned_rx) = mpsc::channel(STAGE_CAPACITY);
    let (decision_tx, decision_rx) = mpsc::channel(STAGE_CAPACITY);
    let (command_tx, command_rx) = mpsc::channel(COMMAND_CAPACITY);
    let (gating_cmd_tx, gating_cmd_rx) = mpsc::channel(INBOX_CAPACITY);
    let (learning_cmd_tx, learning_cmd_rx) = mpsc::channel(INBOX_CAPACITY);
    let (link_cmd_tx, link_cmd_rx) = mpsc::channel(INBOX_CAPACITY);
    let (estop_tx, estop_rx) = watch::channel(false);
    let estop = latch::EstopLatch::new(estop_tx, Some((events.clone(), feed.clone())));
    let (stats_tx, stats_rx) = watch::channel(ActuationStats::default());
    let (pose_tx, pose_rx) = watch::channel(PoseTracker::new(config.skeleton.max_joint_age_ms));
    let ticks = SharedTickStats::default();
    let (snapshots_tx, snapshots_rx) = mpsc::channel(2);
    let (followed_tx, followed_rx) = watch::channel(None);

    let ticker = ticker::spawn(
        &config.tick,
        started,
        tick_tx,
        ticks.clone(),
        cancel.clone(),
    );
    let tasks = vec![
        ticker.task,
        tokio::spawn(sensor_ingest::run(
            ingest,
            period,
            IngestChannels {
                ticks: tick_rx.clone(),
                commands: link_cmd_rx,
                out: obs_tx,
                heartbeat: ticks.clone(),
            },
            cancel.clone(),
        )),
        tokio::spawn(learning::run(
            learning,
            started,
            LearningChannels {
                observations: obs_rx,
                pose: pose_rx,
                commands: learning_cmd_rx,
                out: learned_tx,
                events: events.clone(),
                snapshots: snapshots_rx,
                followed: followed_rx,
            },
            cancel.clone(),
        )),
        tokio::spawn(gating::run(
            gating,
            config.robot.model,
            GatingChannels {
                learned: learned_rx,
                commands: gating_cmd_rx,
                estop: estop_rx.clone(),
                out: decision_tx,
                events: events.clone(),
            },
            cancel.clone(),
        )),
        tokio::spawn(actuation::run(
            actuation,
            ActuationChannels {
                decisions: decision_rx,
                ticks: tick_rx,
                estop: estop_rx,
                writer,
                feed: feed.clone(),
                stats: stats_tx,
                events: events.clone(),
                followed: followed_tx,
            },
            cancel.clone(),
        )),
        tokio::spawn(router::route(
            command_rx,
            Routes {
                estop: estop.clone(),
                gating: gating_cmd_tx,
                learning: learning_cmd_tx,
                link: link_cmd_tx,
                recorder,
            },
            cancel.clone(),
        )),
    ];
    Pipeline {
        commands: command_tx,
        estop,
        pose: pose_tx,
        ticks,
        timer: ticker.timer,
        actuation: stats_rx,
        tasks,
        snapshots: snapshots_tx,
    }
}

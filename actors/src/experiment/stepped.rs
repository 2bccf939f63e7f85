//! The tick graph stepped in order, for virtual time: one loop that runs, per simulated tick, what the
//! actors run in their separate tasks, without their channels, wakes and timers.
//!
//! Under tokio's paused clock (experiments, tests) a tick costs the actors about a dozen task wakes, a
//! timer-wheel pass and the in-process stream's buffers, and the clock moves only when every task waits.
//! [`Stepper`] instead keeps the simulated Create, the OI parser, link supervision, learning, gating and
//! actuation in one struct and steps them itself, calling the same per-tick functions the actors call:
//! [`step_robot`] and [`host_to_robot`] (the simulator task's step and read), [`IngestState`] (sensor
//! ingest), [`Learning::act`] and [`Learning::learn`], [`gating::decide`], [`Actuation::watchdog`] and
//! [`Actuation::on_decision`] (which assembles the record), and the feed. The bytes on the simulated line
//! are the same: the start-up sequence, every stream frame and every Drive Direct go through the same
//! encoder, fault injector and parser.
//!
//! The order is the order the actors reach under the paused clock, so every record is the same bit for
//! bit (a test compares both drivers): at an instant with both a robot step and a tick, the robot steps
//! first, the tick is then handled without the frame of that step (sensor ingest takes a tick before
//! bytes when both are ready), the tick's command reaches the robot, and the step's frame is parsed
//! last, stamped with that instant. Time is not kept by tokio: every instant is computed from the start
//! (`t0 + n × period`, `t0 + k × 15 ms`) and handed to the stages, which is what they would have read
//! from the paused clock.
//!
//! It runs what an experiment runs and nothing more: the simulated Create without link faults (an
//! unplugged line needs a reconnect the actors make), no skeleton ingest, no commands from clients (no
//! router, no e-stop: a run whose collector drives the server uses the actors). Link supervision runs and
//! its re-syncs go to the robot as the link writer would send them; a reopen it cannot make is refused
//! with [`SteppedError::Reopen`] rather than diverging silently. The lab (`pavlov serve`) always runs on
//! the actors.

use std::sync::Arc;
use std::time::Duration;

use futures_util::future::BoxFuture;
use pavlov::agent::GatingStage;
use pavlov::config::Config;
use pavlov::oi::handshake;
use pavlov::oi::parser::StreamParser;
use pavlov::record::TickRecord;
use pavlov::sim::faults::{FaultInjector, FaultSpec};
use pavlov::sim::robot::SimRobot;
use pavlov::skeleton::PoseTracker;
use tokio::sync::{mpsc, oneshot, watch};
use tokio::time::Instant;

use crate::bus::{EventLog, StartState, TickFeed};
use crate::link::opener::LinkOpener;
use crate::link::supervisor::Supervisor;
use crate::link::writer::WriterControl;
use crate::link::{LinkError, LinkReader, LinkWriter};
use crate::pipeline::actuation::{Actuation, CommandQueue, followed_of};
use crate::pipeline::gating;
use crate::pipeline::learning::Learning;
use crate::pipeline::sensor_ingest::IngestState;
use crate::pipeline::ticker::Tick;
use crate::server::{ServerError, build_learning, feed_and_events};
use crate::simulated::robot::{SIM_STEP, host_to_robot, step_robot};
use crate::storage::recorder::{RecorderInput, RecorderLink};

/// Why a stepped run stopped.
#[derive(Debug, thiserror::Error)]
pub enum SteppedError {
    /// Setting the run up failed as the server's start-up would have.
    #[error("{0}")]
    Start(#[from] ServerError),
    /// Link supervision asked to close and reopen the link, which only the actors can do.
    #[error(
        "link supervision asked for a reopen at tick {0}; the stepped driver cannot reopen a link"
    )]
    Reopen(u64),
}

/// Whether `config` can be stepped: the simulated Create without link faults and without skeleton
/// ingest. (Whether clients send commands is the caller's to know.)
pub(crate) fn steppable(config: &Config) -> bool {
    config
        .sim
        .fault_spec()
        .is_ok_and(|f| f == FaultSpec::none())
        && !config.skeleton.is_enabled(&config.control.stimulus)
}

/// The simulated Create and its line, host side included.
struct Wire {
    robot: SimRobot,
    faults: FaultInjector,
    /// The host side's rate (the in-process line runs at the model's).
    host_baud: Option<u32>,
    /// Whether bytes flowed on the line at the last step.
    flowing: bool,
}

impl Wire {
    /// Bytes the host writes reach the robot at once, as the link writer's write does in process.
    fn send(&mut self, bytes: &[u8]) {
        host_to_robot(
            &mut self.robot,
            &mut self.faults,
            self.host_baud,
            self.flowing,
            bytes,
        );
    }
}

impl CommandQueue for Wire {
    fn offer(&mut self, bytes: &[u8], _tick_deadline: Option<Instant>) -> bool {
        self.send(bytes);
        true
    }
}

/// The stepped run's stand-in for the simulator's plug. Supervision is built with it, as the server's is
/// with [`crate::simulated::device::SimDevice`], so it decides exactly as it would on the actors; but a
/// reopen (which reconnects a running simulator task) cannot be made here: the stepper stops the run at
/// the close that begins one ([`SteppedError::Reopen`]).
struct NoReopen;

impl LinkOpener for NoReopen {
    fn open(&mut self) -> BoxFuture<'static, Result<(LinkReader, LinkWriter), LinkError>> {
        Box::pin(async {
            Err(LinkError::Io(std::io::Error::new(
                std::io::ErrorKind::Unsupported,
                "a stepped run cannot reopen its link",
            )))
        })
    }

    fn describe(&self) -> String {
        "the stepped simulated Create".into()
    }

    fn rescue_baud(&mut self, _rates: Vec<u32>) -> BoxFuture<'static, ()> {
        Box::pin(async {})
    }
}

/// A run of the tick graph stepped by the caller, one tick per [`Stepper::tick`].
pub(crate) struct Stepper {
    wire: Wire,
    parser: StreamParser,
    supervisor: Supervisor,
    ingest: IngestState,
    learning: Learning,
    gating: GatingStage,
    engaged: bool,
    actuation: Actuation,
    /// Actuation's last record, as learning reads it on the next tick.
    followed: Option<(u64, bool, f64)>,
    feed: TickFeed,
    events: EventLog,
    /// Supervision's requests to the link writer.
    control: mpsc::Receiver<WriterControl>,
    /// The recorder's requests for the learner's state between two ticks.
    snapshots: mpsc::Receiver<oneshot::Sender<StartState>>,
    /// Nobody publishes poses in a stepped run; learning reads the empty tracker.
    pose: watch::Receiver<PoseTracker>,
    _pose_tx: watch::Sender<PoseTracker>,
    /// When the robot was started (its first step), the origin of every instant.
    t0: Instant,
    /// When tick 0 is due.
    started: Instant,
    period: Duration,
    /// The next robot step, since `t0`.
    next_step: Duration,
    /// The next tick's sequence number.
    next_seq: u64,
    /// When the next tick is due, since `t0`.
    next_due: Duration,
    /// Robot bytes of a step at the tick's own instant, parsed after the tick.
    pending: Vec<u8>,
    /// The buffer the robot sends its next step's bytes into.
    spare: Vec<u8>,
}

impl Stepper {
    /// Sets a run of `config` up as the server's start-up does (the learning, the robot with the start-up
    /// sequence sent, supervision, the feed and the event log, the recorder attached), at the current
    /// instant of tokio's clock.
    pub(crate) async fn start(
        config: &Config,
        recorder: Option<&RecorderLink>,
    ) -> Result<Stepper, SteppedError> {
        config.validate().map_err(ServerError::from)?;
        let (mut learning, _) = build_learning(config)?;
        let stream = config.robot.stream_ids();
        let model = config.robot.model;
        let link = |e: pavlov::oi::OiError| ServerError::from(LinkError::from(e));
        let startup =
            handshake::startup_bytes(model, config.robot.oi_mode, &stream).map_err(link)?;
        let parser = StreamParser::new(&stream).map_err(link)?.with_model(model);
        let period = Duration::from_millis(config.tick.period_ms);
        let t0 = Instant::now();
        let started = t0 + period;

        let mut robot = SimRobot::new(model, config.sim.robot_params(model), config.sim.seed);
        let faults = FaultInjector::new(
            config.sim.fault_spec().map_err(ServerError::from)?,
            config.sim.seed,
        );
        faults.configure(&mut robot);
        let mut wire = Wire {
            robot,
            faults,
            host_baud: Some(model.baud()),
            flowing: true,
        };
        // The simulator reads the start-up sequence before its first step, both at `t0`.
        wire.send(&startup);

        let (feed, events) = feed_and_events(recorder);
        let (control_tx, control) = mpsc::channel(8);
        let opener: Box<dyn LinkOpener> = Box::new(NoReopen);
        let supervisor =
            Supervisor::new(config, Some(opener), control_tx, t0).with_events(events.clone());
        let initial = Box::new(learning.initial_start_state(&events));
        learning.attach_events(events.clone());
        let (gating, actuation) = crate::pipeline::stages(config);
        let (snapshots_tx, snapshots) = mpsc::channel(2);
        if let Some(r) = recorder {
            let attach = RecorderInput::Attach {
                snapshots: snapshots_tx,
                events: events.clone(),
                initial,
            };
            if r.input.send(attach).await.is_err() {
                tracing::error!("the recorder has stopped: nothing will be recorded");
            }
        }
        let (pose_tx, pose) = watch::channel(PoseTracker::new(config.skeleton.max_joint_age_ms));
        let mut stepper = Stepper {
            wire,
            parser,
            supervisor,
            ingest: IngestState::new(period),
            learning,
            gating,
            engaged: false,
            actuation,
            followed: None,
            feed,
            events,
            control,
            snapshots,
            pose,
            _pose_tx: pose_tx,
            t0,
            started,
            period,
            next_step: Duration::ZERO,
            next_seq: 0,
            next_due: period,
            pending: Vec::with_capacity(256),
            spare: Vec::with_capacity(256),
        };
        stepper.step_robot_now(false);
        Ok(stepper)
    }

    /// The feed every record is published on (the recorder's queue among them).
    pub(crate) fn feed(&self) -> &TickFeed {
        &self.feed
    }

    /// Steps the robot at `next_step`; its bytes are parsed now, or kept for after the tick (`hold`).
    fn step_robot_now(&mut self, hold: bool) {
        let at = self.t0 + self.next_step;
        self.next_step += SIM_STEP;
        let stepped = step_robot(
            &mut self.wire.robot,
            &mut self.wire.faults,
            self.wire.host_baud,
            &mut self.spare,
        );
        self.wire.flowing = stepped.flowing;
        if let Some(bytes) = stepped.to_host() {
            if hold {
                self.pending.extend_from_slice(bytes);
            } else {
                self.ingest
                    .on_bytes(bytes, at, &mut self.parser, &mut self.supervisor);
            }
        }
        stepped.recycle(&mut self.spare);
    }

    /// Runs the robot up to the next tick, and the tick through every stage; returns its record.
    pub(crate) fn tick(&mut self) -> Result<Arc<TickRecord>, SteppedError> {
        let seq = self.next_seq;
        self.next_seq += 1;
        let due = self.next_due;
        self.next_due += self.period;
        while self.next_step < due {
            self.step_robot_now(false);
        }
        if self.next_step == due {
            self.step_robot_now(true);
        }
        let at = self.t0 + due;
        let tick = Tick {
            seq,
            deadline: at,
            fired: at,
        };
        let obs = self
            .ingest
            .on_tick(tick, at, &self.parser, &mut self.supervisor);
        while let Ok(request) = self.control.try_recv() {
            match request {
                WriterControl::Send(bytes) => self.wire.send(&bytes),
                WriterControl::Close(_) | WriterControl::Replace { .. } => {
                    return Err(SteppedError::Reopen(seq));
                }
            }
        }
        self.actuation.watchdog(&tick, &mut self.wire, &self.events);
        let (learned, fresh) = self
            .learning
            .act(obs, self.started, &self.pose, self.followed);
        self.learning.learn(seq, fresh);
        let decision = gating::decide(&mut self.gating, learned, &mut self.engaged);
        let record = self.actuation.on_decision(decision, false, &mut self.wire);
        self.followed = Some(followed_of(&record));
        let record = Arc::new(record);
        self.feed.publish(record.clone());
        if !self.pending.is_empty() {
            self.ingest
                .on_bytes(&self.pending, at, &mut self.parser, &mut self.supervisor);
            self.pending.clear();
        }
        while let Ok(request) = self.snapshots.try_recv() {
            let _ = request.send(self.learning.start_state());
        }
        Ok(record)
    }

    /// Ends the run as the server's shut-down does for learning: the final checkpoint (with autosave)
    /// and the Horde's are written.
    pub(crate) async fn finish(self) {
        let last = self.next_seq.saturating_sub(1);
        self.learning.finish(last).await;
    }
}

/// What the allocation test (`tests/alloc_per_tick.rs`) drives: a stepped run, tick by tick.
#[doc(hidden)]
pub mod bench_support {
    use std::sync::Arc;

    use pavlov::config::Config;
    use pavlov::record::TickRecord;

    use super::{SteppedError, Stepper};

    /// A stepped run of a configuration, without a recorder.
    pub struct SteppedRun(Stepper);

    impl SteppedRun {
        /// Starts a run of `config` (inside a runtime with tokio's clock paused).
        pub async fn start(config: &Config) -> Result<SteppedRun, SteppedError> {
            Stepper::start(config, None).await.map(SteppedRun)
        }

        /// Runs the next tick and returns its record.
        pub fn tick(&mut self) -> Result<Arc<TickRecord>, SteppedError> {
            self.0.tick()
        }
    }
}

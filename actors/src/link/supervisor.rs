//! The async side of link supervision: it feeds the core's [`LinkMonitor`] with frames, ticks and link
//! failures, and carries out what it asks — re-sending Start and Stream through the writer's priority
//! queue, reopening the port in a background task (so a slow `open` never holds the tick), and handing the
//! reopened port's halves to the sensor ingest and the writer.
//!
//! It lives inside the sensor ingest actor, which sees every frame and every tick.

use pavlov::config::{Config, DriveMode};
use pavlov::oi::parser::ParserStats;
use pavlov::oi::{Model, SensorValues};
use pavlov::record::LinkStatus;
use pavlov::supervision::LinkState;
use pavlov::supervision::monitor::{LinkAction, LinkMonitor};
use tokio::sync::mpsc;
use tokio::task::JoinHandle;
use tokio::time::Instant;

use super::opener::LinkOpener;
use super::writer::WriterControl;
use super::{LinkError, LinkReader, LinkWriter};
use crate::bus::EventLog;
use crate::command::{Applied, CommandError, Envelope, LinkCommand};
use pavlov::event::EventKind;
use pavlov::oi::handshake;

/// How long a reopen waits for the writer to close the old port.
const CLOSE_WAIT: std::time::Duration = std::time::Duration::from_millis(500);

type Reopen = JoinHandle<Result<(LinkReader, LinkWriter), LinkError>>;

/// Link supervision for one server run.
pub(crate) struct Supervisor {
    monitor: LinkMonitor,
    opener: Option<Box<dyn LinkOpener>>,
    control: mpsc::Sender<WriterControl>,
    model: Model,
    mode: DriveMode,
    stream: Vec<u8>,
    base: Instant,
    reopening: Option<Reopen>,
    baud_rescues: u64,
    /// The newest tick (`None` before the first).
    last_tick: Option<u64>,
    /// Where link changes and re-arms are announced.
    events: Option<EventLog>,
}

impl Supervisor {
    /// Supervision per `config`; the start-up sequence went out at `base`. Without an `opener` the port
    /// cannot be reopened, and a dead link is re-synced with backoff instead.
    pub(crate) fn new(
        config: &Config,
        opener: Option<Box<dyn LinkOpener>>,
        control: mpsc::Sender<WriterControl>,
        base: Instant,
    ) -> Self {
        let mode = config.robot.oi_mode;
        Supervisor {
            monitor: LinkMonitor::new(
                config.link.monitor(),
                mode.code(),
                config.link.mode_quirk,
                0,
            ),
            opener,
            control,
            model: config.robot.model,
            mode,
            stream: config.robot.stream_ids(),
            base,
            reopening: None,
            baud_rescues: 0,
            last_tick: None,
            events: None,
        }
    }

    fn now_ms(&self) -> u64 {
        self.ms_at(Instant::now())
    }

    /// Milliseconds from the start-up sequence to `at`.
    fn ms_at(&self, at: Instant) -> u64 {
        at.saturating_duration_since(self.base)
            .as_millis()
            .min(u128::from(u64::MAX)) as u64
    }

    /// A valid frame arrived `at` (the time its bytes were read).
    pub(crate) fn on_frame(&mut self, values: &SensorValues, at: Instant) {
        let before = (self.monitor.state(), self.monitor.trip());
        self.monitor.on_frame(self.ms_at(at), values);
        self.log_change(before);
    }

    /// The link reached end-of-file or failed.
    pub(crate) fn on_lost(&mut self) {
        let before = (self.monitor.state(), self.monitor.trip());
        self.monitor.on_link_lost(self.now_ms());
        self.log_change(before);
    }

    /// Announces link changes and re-arms on `events` from now on.
    pub(crate) fn with_events(mut self, events: EventLog) -> Self {
        self.events = Some(events);
        self
    }

    /// Once per tick (`seq`, taken `at`): acts on what the monitor asks.
    pub(crate) fn on_tick(&mut self, seq: u64, at: Instant) {
        self.last_tick = Some(seq);
        let before = (self.monitor.state(), self.monitor.trip());
        let now = self.ms_at(at);
        match self.monitor.on_tick(now) {
            None => {}
            Some(LinkAction::Resync { with_mode }) => {
                let mode = with_mode.then_some(self.mode);
                match handshake::resync_bytes(self.model, mode, &self.stream) {
                    Ok(bytes) => self.send(WriterControl::Send(bytes)),
                    Err(e) => tracing::error!("cannot encode the re-sync: {e}"),
                }
            }
            Some(LinkAction::Reopen) => match self.opener.as_mut() {
                Some(opener) => {
                    tracing::info!("reopening {}", opener.describe());
                    // Every other reopen that brought no frame, first try to bring a robot back from
                    // another baud rate (a damaged byte can form a Baud command).
                    let attempt = self.monitor.reopen_attempt();
                    let rescue = self.monitor.rescue_due().map(|index| {
                        self.baud_rescues += 1;
                        let rates = handshake::baud_rescue_batch(self.model, index);
                        tracing::warn!(
                            rescues = self.baud_rescues,
                            ?rates,
                            "no frame after {attempt} reopens: sending Baud at other rates"
                        );
                        opener.rescue_baud(rates)
                    });
                    // Close the old port first: a serial device is held exclusively.
                    let (closed_tx, closed) = tokio::sync::oneshot::channel();
                    let open = opener.open();
                    let close = WriterControl::Close(closed_tx);
                    self.send(close);
                    self.reopening = Some(tokio::spawn(async move {
                        let _ = tokio::time::timeout(CLOSE_WAIT, closed).await;
                        if let Some(rescue) = rescue {
                            rescue.await;
                        }
                        open.await
                    }));
                }
                None => {
                    // Nothing to reopen: send the whole start-up sequence again, with backoff.
                    self.monitor.reopen_failed(now);
                    match handshake::startup_bytes(self.model, self.mode, &self.stream) {
                        Ok(bytes) => self.send(WriterControl::Send(bytes)),
                        Err(e) => tracing::error!("cannot encode the start-up sequence: {e}"),
                    }
                }
            },
            Some(LinkAction::SendMode) => self.send_mode(),
        }
        self.log_change(before);
    }

    /// True while a reopen runs.
    pub(crate) fn reopening(&self) -> bool {
        self.reopening.is_some()
    }

    /// Waits for the running reopen (the caller has dropped the old reader); on success hands the new port's writer (with the start-up sequence)
    /// to the writer and returns the reader. Pending forever when no reopen runs.
    pub(crate) async fn reopen_finished(&mut self) -> Option<LinkReader> {
        let Some(task) = self.reopening.as_mut() else {
            return std::future::pending().await;
        };
        let result = task.await;
        self.reopening = None;
        let now = self.now_ms();
        match result {
            Ok(Ok((reader, writer))) => {
                match handshake::startup_bytes(self.model, self.mode, &self.stream) {
                    Ok(startup) => {
                        self.monitor.reopened(now);
                        tracing::info!(
                            reconnects = self.monitor.counters().reconnects,
                            "robot link reopened; start-up sequence sent"
                        );
                        self.send(WriterControl::Replace {
                            link: writer,
                            startup,
                        });
                        Some(reader)
                    }
                    Err(e) => {
                        tracing::error!("cannot encode the start-up sequence: {e}");
                        self.monitor.reopen_failed(now);
                        None
                    }
                }
            }
            Ok(Err(e)) => {
                self.monitor.reopen_failed(now);
                let c = self.monitor.counters();
                if c.reopen_failures <= 3 || c.reopen_failures.is_power_of_two() {
                    tracing::warn!(
                        failures = c.reopen_failures,
                        "cannot reopen the robot link: {e}"
                    );
                }
                None
            }
            Err(e) => {
                tracing::error!("the reopen task failed: {e}");
                self.monitor.reopen_failed(now);
                None
            }
        }
    }

    /// Applies a link command.
    pub(crate) fn command(&mut self, envelope: Envelope<LinkCommand>) {
        let Envelope { command, reply } = envelope;
        match command {
            LinkCommand::Rearm {} => {
                let result = match self.monitor.trip() {
                    None => Err(CommandError::Rejected(format!(
                        "the robot has not tripped (link {}); nothing to re-arm",
                        self.monitor.state().name()
                    ))),
                    Some(cause) => {
                        if self.monitor.rearm(self.now_ms()).is_some() {
                            self.send_mode();
                        }
                        tracing::warn!(
                            "operator re-armed after a trip ({}): {:?} sent",
                            cause.describe(),
                            self.mode
                        );
                        if let Some(events) = &self.events {
                            events.emit(
                                self.last_tick,
                                EventKind::Rearm {
                                    cause,
                                    mode: self.mode,
                                },
                            );
                        }
                        Ok(Applied::Rearmed {
                            rearmed: cause,
                            mode: self.mode,
                        })
                    }
                };
                let _ = reply.send(result);
            }
        }
    }

    fn send_mode(&mut self) {
        match handshake::mode_bytes(self.model, self.mode) {
            Ok(bytes) => self.send(WriterControl::Send(bytes)),
            Err(e) => tracing::error!("cannot encode the mode command: {e}"),
        }
    }

    fn send(&mut self, c: WriterControl) {
        if self.control.try_send(c).is_err() {
            tracing::warn!(
                "the link writer's control queue is full; a supervision write was dropped"
            );
        }
    }

    fn log_change(&self, before: (LinkState, Option<pavlov::supervision::TripCause>)) {
        let (state, trip) = (self.monitor.state(), self.monitor.trip());
        if (state, trip) == before {
            return;
        }
        if let Some(events) = &self.events {
            let reconnects = self.monitor.counters().reconnects;
            events.emit(
                self.last_tick,
                EventKind::Link {
                    state,
                    trip,
                    reconnects,
                },
            );
        }
        let c = self.monitor.counters();
        match state {
            LinkState::Up => tracing::info!(
                outage_ms = c.last_outage_ms,
                "robot link up (was {})",
                before.0.name()
            ),
            LinkState::Stale => tracing::warn!("robot stream stale: re-sending Start and Stream"),
            LinkState::Reconnecting => tracing::warn!("robot link lost: reconnecting"),
            LinkState::Tripped => tracing::error!(
                "the robot left {:?} for Passive by itself ({}); send `rearm` to resume control",
                self.mode,
                trip.map_or("unknown cause", |t| t.describe())
            ),
            LinkState::Down => tracing::warn!("robot link down"),
        }
    }

    /// The link's state for the tick record.
    pub(crate) fn status(&self, parser: ParserStats) -> LinkStatus {
        let c = self.monitor.counters();
        LinkStatus {
            up: self.monitor.state() == LinkState::Up,
            good_frames: parser.good_frames,
            bad_frames: parser.bad_frames,
            skipped_bytes: parser.skipped_bytes,
            state: self.monitor.state(),
            mode: self.monitor.mode(),
            trip: self.monitor.trip(),
            reconnects: c.reconnects,
            stale_events: c.stale_events,
        }
    }
}

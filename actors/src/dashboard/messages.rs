//! The server's telemetry messages of the dashboard protocol (`web/PROTOCOL.md`): `hello`, `tick` and
//! `status`, serialised straight from the records and counters they describe.

use pavlov::analysis::interaction::live::LiveInteractionFigures;
use pavlov::analysis::interaction::live_aligned::AlignedFigures;
use pavlov::analysis::run_counters::RunTotals;
use pavlov::control::{Action, Mode};
use pavlov::record::{
    ElbowAngles, LinkStatus, PredictionValue, SafetyStop, SensorReadings, TickRecord,
};
use serde::Serialize;
use serde_json::Value;

use super::history::InForce;
use super::protocol::{PROTOCOL_VERSION, STATUS_EVERY_TICKS, known_commands};
use crate::telemetry::HealthFigures;
use crate::telemetry::counters::ActuationStats;

/// Left and right wheel speeds, mm/s.
#[derive(Debug, Clone, Copy, Serialize)]
pub(crate) struct Wheels {
    /// Left wheel.
    pub(crate) left: i16,
    /// Right wheel.
    pub(crate) right: i16,
}

impl From<Action> for Wheels {
    fn from(a: Action) -> Self {
        Wheels {
            left: a.left_mm_s,
            right: a.right_mm_s,
        }
    }
}

/// A `tick` message, borrowed from the record it describes.
#[derive(Serialize)]
pub(crate) struct TickMessage<'a> {
    #[serde(rename = "type")]
    kind: &'static str,
    seq: u64,
    t: f64,
    mode: Mode,
    obs_age_ticks: Option<u32>,
    obs: &'a [f32],
    predictions: &'a [PredictionValue],
    stimulus: bool,
    gate: bool,
    /// What engaged the gate: a rule's name or `stimulus`; `null` when it did not engage.
    rule: Option<&'a str>,
    command: Wheels,
    default: Wheels,
    estop: bool,
    safety_stop: Option<SafetyStop>,
    sensors: &'a SensorReadings,
    elbow: Option<&'a ElbowAngles>,
    link: &'a LinkStatus,
    lateness_us: u32,
}

impl<'a> TickMessage<'a> {
    /// The message for one record.
    pub(crate) fn new(r: &'a TickRecord) -> Self {
        TickMessage {
            kind: "tick",
            seq: r.seq,
            t: r.t_ms / 1000.0,
            mode: r.mode,
            obs_age_ticks: r.obs_age_ticks,
            obs: &r.obs,
            predictions: &r.predictions,
            stimulus: r.stimulus,
            gate: r.gate,
            rule: r.rule.as_deref(),
            command: r.command.into(),
            default: r.default_action.into(),
            estop: r.estop,
            safety_stop: r.safety_stop,
            sensors: &r.sensors,
            elbow: r.elbow.as_ref(),
            link: &r.link,
            lateness_us: r.lateness_us,
        }
    }

    /// The JSON text.
    pub(crate) fn to_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}

/// Tick health in a `status` message.
#[derive(Debug, Clone, Default, Serialize)]
pub(crate) struct StatusHealth {
    /// Median tick lateness since start, µs.
    pub(crate) lateness_p50_us: u64,
    /// 99th percentile of tick lateness since start, µs.
    pub(crate) lateness_p99_us: u64,
    /// Worst tick lateness since start, µs.
    pub(crate) lateness_max_us: u64,
    /// Ticks fired.
    pub(crate) ticks_fired: u64,
    /// Ticks skipped because the ticker woke too late.
    pub(crate) ticks_skipped: u64,
    /// 99th percentile of tick deadline → motor command written, µs.
    pub(crate) tick_to_command_p99_us: u64,
    /// Serial write errors.
    pub(crate) write_errors: u64,
    /// Actuation's counters (forced stops, full writer queue).
    pub(crate) actuation: ActuationStats,
}

impl From<&HealthFigures> for StatusHealth {
    fn from(f: &HealthFigures) -> Self {
        StatusHealth {
            lateness_p50_us: f.lateness.p50_us,
            lateness_p99_us: f.lateness.p99_us,
            lateness_max_us: f.lateness.max_us,
            ticks_fired: f.ticks_fired,
            ticks_skipped: f.ticks_skipped,
            tick_to_command_p99_us: f.tick_to_command.p99_us,
            write_errors: f.write_errors,
            actuation: f.actuation,
        }
    }
}

/// A `status` message: health, run counters, the number of connected clients and, in the gesture-command
/// experiment, the live interaction metrics.
#[derive(Serialize)]
pub(crate) struct StatusMessage<'a> {
    #[serde(rename = "type")]
    kind: &'static str,
    seq: u64,
    health: &'a StatusHealth,
    counters: &'a RunTotals,
    clients: usize,
    #[serde(skip_serializing_if = "Option::is_none")]
    interaction: Option<InteractionStatus<'a>>,
}

/// The `interaction` object: the live metrics and, on some statuses, the aligned averages.
#[derive(Serialize)]
struct InteractionStatus<'a> {
    #[serde(flatten)]
    summary: &'a LiveInteractionFigures,
    #[serde(skip_serializing_if = "Option::is_none")]
    aligned: Option<&'a AlignedFigures>,
}

impl<'a> StatusMessage<'a> {
    /// The status as of tick `seq`.
    pub(crate) fn new(
        seq: u64,
        health: &'a StatusHealth,
        counters: &'a RunTotals,
        clients: usize,
    ) -> Self {
        StatusMessage {
            kind: "status",
            seq,
            health,
            counters,
            clients,
            interaction: None,
        }
    }

    /// Adds the live interaction metrics (absent from the JSON when `None`).
    pub(crate) fn with_interaction(
        mut self,
        interaction: Option<&'a LiveInteractionFigures>,
    ) -> Self {
        self.interaction = interaction.map(|summary| InteractionStatus {
            summary,
            aligned: None,
        });
        self
    }

    /// Adds the aligned averages to `interaction` (no effect without it; absent from the JSON when `None`).
    pub(crate) fn with_aligned(mut self, aligned: Option<&'a AlignedFigures>) -> Self {
        if let Some(i) = &mut self.interaction {
            i.aligned = aligned;
        }
        self
    }

    /// The JSON text.
    pub(crate) fn to_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}

/// The signals a client can plot, announced in `hello`.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct Signals {
    /// Names of the `obs` array's entries, in order.
    pub(crate) obs: Vec<String>,
    /// Names of the predictions, in the `predictions` array's order.
    pub(crate) predictions: Vec<String>,
    /// The prediction that drives the Pavlovian gate.
    pub(crate) gate_prediction: String,
    /// What `set_params` and `human_request` accept, for a client's form.
    pub(crate) bounds: LearningBounds,
    /// Predictions in the Horde (`[horde]`; 0 without one): what `horde_watch` serves.
    pub(crate) horde_predictions: usize,
}

/// The bounds of the learning commands, announced in `hello` (`signals.bounds`): the same bounds the
/// server checks (`pavlov::learn::bounds`, `pavlov::agent::learning::MAX_REQUEST_MS`).
#[derive(Debug, Clone, Default, Serialize)]
pub(crate) struct LearningBounds {
    /// Each prediction's bounds, in the order of `signals.predictions`.
    pub(crate) predictions: Vec<PredictionBounds>,
    /// The longest `human_request` `duration_ms`.
    pub(crate) max_request_ms: u64,
}

/// One prediction's bounds of `set_params`: 0 < α ≤ `max_alpha`, `min_lambda` ≤ λ ≤ `max_lambda`, θ finite.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct PredictionBounds {
    /// The prediction's name.
    pub(crate) name: String,
    /// Active features for a fully valid input (‖x‖²).
    pub(crate) active_features: usize,
    /// The length of its weight vector.
    pub(crate) features: usize,
    /// The largest α: 1 / `active_features` (α·‖x‖² ≤ 1).
    pub(crate) max_alpha: f64,
    /// The smallest λ.
    pub(crate) min_lambda: f64,
    /// The largest λ.
    pub(crate) max_lambda: f64,
}

impl LearningBounds {
    /// The bounds of `config`'s predictions (an already validated configuration).
    pub(crate) fn for_config(config: &pavlov::config::Config) -> Self {
        let predictions = config
            .prediction_bounds()
            .unwrap_or_default()
            .into_iter()
            .map(|(name, b)| PredictionBounds {
                name,
                active_features: b.active_features,
                features: b.features,
                max_alpha: b.max_alpha,
                min_lambda: 0.0,
                max_lambda: 1.0,
            })
            .collect();
        LearningBounds {
            predictions,
            max_request_ms: pavlov::agent::learning::MAX_REQUEST_MS,
        }
    }
}

/// The `hello` message.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct Hello {
    #[serde(rename = "type")]
    kind: &'static str,
    /// [`PROTOCOL_VERSION`].
    pub(crate) protocol: u32,
    /// Server name and version.
    pub(crate) server: String,
    /// The tick period, ms.
    pub(crate) tick_period_ms: u64,
    /// Ticks per second the client receives (the tick rate until it asks for less).
    pub(crate) rate_hz: f64,
    /// `status` messages come every this many ticks.
    pub(crate) status_every_ticks: u64,
    /// Whether this connection may send control commands (it presented the token, or none is needed).
    pub(crate) can_command: bool,
    /// What the `tick` arrays hold.
    pub(crate) signals: Signals,
    /// Every command name.
    pub(crate) commands: Vec<&'static str>,
    /// Message size limit and per-client queue, as configured.
    pub(crate) limits: Limits,
    /// What of the configuration this connection may see ([`super::hello_config`]): all of it with the
    /// token redacted for an operator, what the page draws for a watcher.
    pub(crate) config: Value,
    /// This server run (a page that reconnects to another run starts afresh).
    pub(crate) run: String,
    /// The robot this server drives.
    pub(crate) robot: RobotInfo,
    /// Seconds of history sent after `hello` (at most; `[dashboard] history_s`).
    pub(crate) history_s: u64,
    /// What is in force as of the history that follows (mode, learning parameters, recording).
    pub(crate) in_force: Option<InForce>,
}

/// `hello.robot`: which robot, and how it is reached.
#[derive(Debug, Clone, Serialize)]
pub(crate) struct RobotInfo {
    /// `create1` or `create2`.
    pub(crate) model: pavlov::oi::model::Model,
    /// `simulated`, `serial` or `external` (a link a test opened).
    pub(crate) link: &'static str,
    /// The serial device, for `serial`.
    pub(crate) port: Option<String>,
}

impl RobotInfo {
    /// What the dashboard shows of `kind`.
    pub(crate) fn new(
        model: pavlov::oi::model::Model,
        kind: &crate::server::RobotLinkKind,
    ) -> Self {
        use crate::server::RobotLinkKind;
        let (link, port) = match kind {
            RobotLinkKind::Simulated => ("simulated", None),
            RobotLinkKind::Serial(path) => ("serial", Some(path.clone())),
            RobotLinkKind::External => ("external", None),
        };
        RobotInfo { model, link, port }
    }
}

/// What every `hello` of one server run says of the run.
#[derive(Debug, Clone)]
pub(crate) struct HelloRun {
    /// An id of this run.
    pub(crate) run: String,
    /// The robot.
    pub(crate) robot: RobotInfo,
    /// `[dashboard] history_s`.
    pub(crate) history_s: u64,
}

/// Limits announced in `hello`.
#[derive(Debug, Clone, Copy, Serialize)]
pub(crate) struct Limits {
    /// Largest message the server accepts, bytes.
    pub(crate) max_message_bytes: usize,
    /// Ticks queued for this client before the oldest are dropped.
    pub(crate) client_queue: usize,
    /// The message rate limit (`{"burst":…,"per_second":…}`); messages beyond it get `rate_limited`.
    pub(crate) rate: super::rate::RateLimit,
}

impl Hello {
    /// A hello for a connection (its run, robot and history are set apart, see [`HelloRun`]).
    pub(crate) fn new(
        tick_period_ms: u64,
        can_command: bool,
        signals: Signals,
        limits: Limits,
        config: Value,
        run: &HelloRun,
    ) -> Self {
        Hello {
            kind: "hello",
            protocol: PROTOCOL_VERSION,
            server: crate::provenance::BUILD.program(),
            tick_period_ms,
            rate_hz: 1000.0 / tick_period_ms.max(1) as f64,
            status_every_ticks: STATUS_EVERY_TICKS,
            can_command,
            signals,
            commands: known_commands(),
            limits,
            config,
            run: run.run.clone(),
            robot: run.robot.clone(),
            history_s: run.history_s,
            in_force: None,
        }
    }

    /// The same hello with what is in force now.
    pub(crate) fn with_in_force(mut self, in_force: InForce) -> Self {
        self.in_force = Some(in_force);
        self
    }

    /// The JSON text.
    pub(crate) fn to_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn tick_messages_carry_the_record() {
        let record = TickRecord {
            seq: 12,
            t_ms: 240.0,
            mode: Mode::Pavlovian,
            obs_age_ticks: Some(1),
            sensors: SensorReadings {
                overcurrent_left: true,
                battery_current_ma: Some(-700),
                ..Default::default()
            },
            obs: vec![0.5, 1.0],
            elbow: None,
            stimulus: true,
            predictions: vec![PredictionValue {
                name: "stall".into(),
                value: 0.25,
                threshold: 0.5,
            }],
            gate: true,
            rule: Some("stall_ahead".into()),
            default_action: Action {
                left_mm_s: 100,
                right_mm_s: 100,
            },
            command: Action::STOP,
            safety_stop: Some(SafetyStop::EStop),
            estop: true,
            lateness_us: 80,
            link: LinkStatus {
                up: true,
                good_frames: 9,
                bad_frames: 1,
                skipped_bytes: 3,
                ..Default::default()
            },
            ..TickRecord::at_rest(12, 240.0, Mode::Pavlovian)
        };
        let v: Value = serde_json::from_str(&TickMessage::new(&record).to_json()).unwrap();
        assert_eq!(v["type"], "tick");
        assert_eq!(v["seq"], 12);
        assert_eq!(v["t"], 0.24);
        assert_eq!(v["mode"], "pavlovian");
        assert_eq!(v["obs"], json!([0.5, 1.0]));
        assert_eq!(
            v["predictions"][0],
            json!({"name":"stall","value":0.25,"threshold":0.5})
        );
        assert_eq!(v["command"], json!({"left":0,"right":0}));
        assert_eq!(v["default"], json!({"left":100,"right":100}));
        assert_eq!(v["safety_stop"], "e_stop");
        assert_eq!(v["sensors"]["overcurrent_left"], true);
        assert_eq!(v["sensors"]["battery_current_ma"], -700);
        assert_eq!(v["link"]["bad_frames"], 1);
        assert_eq!(v["elbow"], Value::Null);
        assert_eq!(
            (v["stimulus"].clone(), v["gate"].clone(), v["estop"].clone()),
            (json!(true), json!(true), json!(true))
        );
        assert_eq!(v["rule"], "stall_ahead");
        let idle = TickRecord {
            gate: false,
            rule: None,
            ..record
        };
        let v: Value = serde_json::from_str(&TickMessage::new(&idle).to_json()).unwrap();
        assert_eq!(
            v["rule"],
            Value::Null,
            "present, null, when the gate is off"
        );
    }

    #[test]
    fn hello_announces_the_learning_bounds() {
        let config =
            pavlov::config::Config::from_toml(include_str!("../../../config/stall.toml")).unwrap();
        let bounds = LearningBounds::for_config(&config);
        let v = serde_json::to_value(&bounds).unwrap();
        assert_eq!(
            v,
            json!({"predictions":[{"name":"stall","active_features":44,"features":440,
                   "max_alpha":1.0 / 44.0,"min_lambda":0.0,"max_lambda":1.0}],
                   "max_request_ms":10000})
        );
    }

    #[test]
    fn the_elbow_carries_the_angles_their_averages_and_the_skeleton_status() {
        let record = TickRecord {
            elbow: Some(pavlov::record::ElbowAngles {
                left: Some(80.5),
                left_avg: Some(120.0),
                right: None,
                right_avg: Some(160.0),
                skeleton: pavlov::skeleton::SkeletonStatus::Stale,
            }),
            ..TickRecord::at_rest(3, 60.0, Mode::Pavlovian)
        };
        let v: Value = serde_json::from_str(&TickMessage::new(&record).to_json()).unwrap();
        assert_eq!(
            v["elbow"],
            json!({"left":80.5,"left_avg":120.0,"right":null,"right_avg":160.0,"skeleton":"stale"})
        );
        let none = pavlov::record::ElbowAngles::default();
        assert_eq!(serde_json::to_value(&none).unwrap()["skeleton"], "none");
        // Recordings made before the field read as `none`.
        let old: pavlov::record::ElbowAngles =
            serde_json::from_str(r#"{"left":1.0,"left_avg":null,"right":null,"right_avg":null}"#)
                .unwrap();
        assert_eq!(old.skeleton, pavlov::skeleton::SkeletonStatus::Absent);
    }
}

//! The dashboard's wire protocol (documented for clients in `web/PROTOCOL.md`): JSON text frames.
//!
//! Server → client: `hello` once, then `tick` (every tick, or fewer if the client asked for a lower rate)
//! and `status` (health and run counters every [`STATUS_EVERY_TICKS`] ticks), and one `ack` or `error` per
//! client message. Client → server: JSON objects with a `cmd` field and an optional `id` that the reply
//! echoes. This module parses client messages with precise errors and builds the server's messages; it
//! does no I/O.

use pavlov::control::{Action, Mode};
use pavlov::metrics::MetricsSummary;
use pavlov::record::{
    ElbowSummary, LinkSummary, PredictionValue, SafetyStop, SensorSummary, TickRecord,
};
use serde::Serialize;
use serde_json::{Map, Value};

use crate::actuation::ActuationStats;
use crate::command::ControlCommand;

/// Version of this protocol, announced in `hello`.
pub const PROTOCOL_VERSION: u32 = 1;
/// The websocket subprotocol the server selects when a client offers it.
pub const SUBPROTOCOL: &str = "pavlov.v1";
/// Prefix of a subprotocol entry that carries the access token (`token.<token>`).
pub const TOKEN_PROTOCOL_PREFIX: &str = "token.";
/// A `status` message goes out on every tick whose sequence number is a multiple of this (5 Hz at 50 Hz).
pub const STATUS_EVERY_TICKS: u64 = 10;

/// Commands that change the robot or the learner, forwarded to the server's command router.
pub const CONTROL_COMMANDS: [&str; 10] = [
    "set_mode",
    "estop",
    "release",
    "teleop",
    "human_request",
    "set_params",
    "reset_weights",
    "save_weights",
    "start_recording",
    "stop_recording",
];
/// Commands about the connection itself, answered by the websocket actor (allowed without the token).
pub const SESSION_COMMANDS: [&str; 2] = ["set_rate", "ping"];

/// A command about the connection itself.
#[derive(Debug, Clone, PartialEq)]
pub enum SessionCommand {
    /// Receive at most `hz` ticks per second.
    SetRate {
        /// Requested rate, Hz.
        hz: f64,
    },
    /// Answered with an ack; a liveness check.
    Ping,
}

/// What a client asked for.
#[derive(Debug, Clone, PartialEq)]
pub enum ClientCommand {
    /// Handled by the websocket actor.
    Session(SessionCommand),
    /// Forwarded to the server.
    Control(ControlCommand),
}

/// A parsed client message.
#[derive(Debug, Clone, PartialEq)]
pub struct ClientRequest {
    /// The client's `id`, echoed in the reply (a string or a number).
    pub id: Option<Value>,
    /// The `cmd` name.
    pub cmd: String,
    /// The command.
    pub command: ClientCommand,
}

/// Why a client message was refused. The `code` goes out in the error reply.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ProtocolError {
    /// Not JSON.
    #[error("malformed JSON: {0}")]
    BadJson(String),
    /// JSON, but not an object.
    #[error("a message must be a JSON object with a \"cmd\" field, got {0}")]
    NotAnObject(&'static str),
    /// `id` of the wrong type.
    #[error("\"id\" must be a string or a number, got {0}")]
    BadId(&'static str),
    /// No `cmd`, or not a string.
    #[error("missing \"cmd\": a message must have a string field \"cmd\"")]
    MissingCmd,
    /// A `cmd` nobody handles.
    #[error("unknown command `{0}`; known commands: {known}", known = known_commands().join(", "))]
    UnknownCommand(String),
    /// A known `cmd` with bad or missing arguments.
    #[error("bad arguments for `{cmd}`: {message}")]
    BadArguments {
        /// The command.
        cmd: String,
        /// What is wrong.
        message: String,
    },
    /// A binary frame.
    #[error("binary frames are not supported; send JSON text frames")]
    Binary,
}

impl ProtocolError {
    /// The machine-readable error code.
    pub fn code(&self) -> &'static str {
        match self {
            ProtocolError::BadJson(_) => "bad_json",
            ProtocolError::NotAnObject(_) => "bad_message",
            ProtocolError::BadId(_) => "bad_id",
            ProtocolError::MissingCmd => "missing_cmd",
            ProtocolError::UnknownCommand(_) => "unknown_command",
            ProtocolError::BadArguments { .. } => "bad_arguments",
            ProtocolError::Binary => "binary_unsupported",
        }
    }
}

/// A refused message: the error and whatever `id` could be recovered for the reply.
#[derive(Debug, Clone, PartialEq)]
pub struct Rejection {
    /// The client's `id`, if the message had a usable one.
    pub id: Option<Value>,
    /// Why.
    pub error: ProtocolError,
}

/// Every command name, session commands last.
pub fn known_commands() -> Vec<&'static str> {
    CONTROL_COMMANDS
        .iter()
        .chain(SESSION_COMMANDS.iter())
        .copied()
        .collect()
}

fn json_kind(v: &Value) -> &'static str {
    match v {
        Value::Null => "null",
        Value::Bool(_) => "a boolean",
        Value::Number(_) => "a number",
        Value::String(_) => "a string",
        Value::Array(_) => "an array",
        Value::Object(_) => "an object",
    }
}

/// Parses one text frame from a client.
pub fn parse_request(text: &str) -> Result<ClientRequest, Rejection> {
    let reject = |id: Option<Value>, error| Rejection { id, error };
    let value: Value = serde_json::from_str(text)
        .map_err(|e| reject(None, ProtocolError::BadJson(e.to_string())))?;
    let Value::Object(mut fields) = value else {
        return Err(reject(None, ProtocolError::NotAnObject(json_kind(&value))));
    };
    let id = match fields.remove("id") {
        None | Some(Value::Null) => None,
        Some(v @ (Value::String(_) | Value::Number(_))) => Some(v),
        Some(other) => return Err(reject(None, ProtocolError::BadId(json_kind(&other)))),
    };
    let cmd = match fields.get("cmd") {
        Some(Value::String(s)) => s.clone(),
        _ => return Err(reject(id, ProtocolError::MissingCmd)),
    };
    let command = if SESSION_COMMANDS.contains(&cmd.as_str()) {
        parse_session(&cmd, fields).map(ClientCommand::Session)
    } else if CONTROL_COMMANDS.contains(&cmd.as_str()) {
        parse_control(&cmd, fields).map(ClientCommand::Control)
    } else {
        Err(ProtocolError::UnknownCommand(cmd.clone()))
    };
    match command {
        Ok(command) => Ok(ClientRequest { id, cmd, command }),
        Err(error) => Err(reject(id, error)),
    }
}

/// Parses a control command. serde ignores `deny_unknown_fields` for the unit variants of an internally
/// tagged enum (`{"cmd":"estop","force":true}` would pass), so every field given must also appear when
/// the parsed command is serialised back.
fn parse_control(cmd: &str, fields: Map<String, Value>) -> Result<ControlCommand, ProtocolError> {
    let bad = |message: String| ProtocolError::BadArguments {
        cmd: cmd.to_string(),
        message,
    };
    let given: Vec<String> = fields.keys().cloned().collect();
    let command = serde_json::from_value::<ControlCommand>(Value::Object(fields))
        .map_err(|e| bad(e.to_string()))?;
    let known = match serde_json::to_value(&command) {
        Ok(Value::Object(known)) => known,
        _ => return Err(bad("the command cannot be represented".into())),
    };
    match given.iter().find(|k| !known.contains_key(k.as_str())) {
        Some(extra) => Err(bad(format!("unknown field `{extra}`"))),
        None => Ok(command),
    }
}

fn parse_session(
    cmd: &str,
    mut fields: Map<String, Value>,
) -> Result<SessionCommand, ProtocolError> {
    fields.remove("cmd");
    let bad = |message: String| ProtocolError::BadArguments {
        cmd: cmd.to_string(),
        message,
    };
    let command = match cmd {
        "set_rate" => {
            let hz = match fields.remove("hz") {
                Some(Value::Number(n)) => n.as_f64().unwrap_or(f64::NAN),
                Some(other) => {
                    return Err(bad(format!(
                        "`hz` must be a number, got {}",
                        json_kind(&other)
                    )));
                }
                None => return Err(bad("missing field `hz`".into())),
            };
            if !(hz > 0.0 && hz.is_finite()) {
                return Err(bad(format!("`hz` must be a positive number, got {hz}")));
            }
            SessionCommand::SetRate { hz }
        }
        _ => SessionCommand::Ping,
    };
    match fields.keys().next() {
        Some(extra) => Err(bad(format!("unknown field `{extra}`"))),
        None => Ok(command),
    }
}

#[derive(Serialize)]
struct Ack<'a> {
    #[serde(rename = "type")]
    kind: &'static str,
    id: &'a Option<Value>,
    cmd: &'a str,
    result: &'a Value,
}

#[derive(Serialize)]
struct ErrorReply<'a> {
    #[serde(rename = "type")]
    kind: &'static str,
    id: &'a Option<Value>,
    code: &'a str,
    message: &'a str,
}

/// `{"type":"ack","id":…,"cmd":…,"result":…}`.
pub fn ack_json(id: &Option<Value>, cmd: &str, result: &Value) -> String {
    let ack = Ack {
        kind: "ack",
        id,
        cmd,
        result,
    };
    serde_json::to_string(&ack).unwrap_or_default()
}

/// `{"type":"error","id":…,"code":…,"message":…}`.
pub fn error_json(id: &Option<Value>, code: &str, message: &str) -> String {
    let reply = ErrorReply {
        kind: "error",
        id,
        code,
        message,
    };
    serde_json::to_string(&reply).unwrap_or_default()
}

/// Left and right wheel speeds, mm/s.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Wheels {
    /// Left wheel.
    pub left: i16,
    /// Right wheel.
    pub right: i16,
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
pub struct TickMessage<'a> {
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
    command: Wheels,
    default: Wheels,
    estop: bool,
    safety_stop: Option<SafetyStop>,
    sensors: &'a SensorSummary,
    elbow: Option<&'a ElbowSummary>,
    link: &'a LinkSummary,
    lateness_us: u32,
}

impl<'a> TickMessage<'a> {
    /// The message for one record.
    pub fn new(r: &'a TickRecord) -> Self {
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
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}

/// Tick health in a `status` message.
#[derive(Debug, Clone, Default, Serialize)]
pub struct Health {
    /// Median tick lateness since start, µs.
    pub lateness_p50_us: u64,
    /// 99th percentile of tick lateness since start, µs.
    pub lateness_p99_us: u64,
    /// Worst tick lateness since start, µs.
    pub lateness_max_us: u64,
    /// Ticks fired.
    pub ticks_fired: u64,
    /// Ticks skipped because the ticker woke too late.
    pub ticks_skipped: u64,
    /// 99th percentile of tick deadline → motor command written, µs.
    pub tick_to_command_p99_us: u64,
    /// Serial write errors.
    pub write_errors: u64,
    /// Actuation's counters (forced stops, full writer queue).
    pub actuation: ActuationStats,
}

/// A `status` message: health, run counters and the number of connected clients.
#[derive(Serialize)]
pub struct StatusMessage<'a> {
    #[serde(rename = "type")]
    kind: &'static str,
    seq: u64,
    health: &'a Health,
    counters: &'a MetricsSummary,
    clients: usize,
}

impl<'a> StatusMessage<'a> {
    /// The status as of tick `seq`.
    pub fn new(seq: u64, health: &'a Health, counters: &'a MetricsSummary, clients: usize) -> Self {
        StatusMessage {
            kind: "status",
            seq,
            health,
            counters,
            clients,
        }
    }

    /// The JSON text.
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}

/// The signals a client can plot, announced in `hello`.
#[derive(Debug, Clone, Serialize)]
pub struct Signals {
    /// Names of the `obs` array's entries, in order.
    pub obs: Vec<String>,
    /// Names of the predictions, in the `predictions` array's order.
    pub predictions: Vec<String>,
    /// The prediction that drives the Pavlovian gate.
    pub gate_prediction: String,
}

/// The `hello` message.
#[derive(Debug, Clone, Serialize)]
pub struct Hello {
    #[serde(rename = "type")]
    kind: &'static str,
    /// [`PROTOCOL_VERSION`].
    pub protocol: u32,
    /// Server name and version.
    pub server: String,
    /// The tick period, ms.
    pub tick_period_ms: u64,
    /// Ticks per second the client receives (the tick rate until it asks for less).
    pub rate_hz: f64,
    /// `status` messages come every this many ticks.
    pub status_every_ticks: u64,
    /// Whether this connection may send control commands (it presented the token, or none is needed).
    pub can_command: bool,
    /// What the `tick` arrays hold.
    pub signals: Signals,
    /// Every command name.
    pub commands: Vec<&'static str>,
    /// Message size limit and per-client queue, as configured.
    pub limits: Limits,
    /// The configuration in force (the token redacted).
    pub config: Value,
}

/// Limits announced in `hello`.
#[derive(Debug, Clone, Copy, Serialize)]
pub struct Limits {
    /// Largest message the server accepts, bytes.
    pub max_message_bytes: usize,
    /// Ticks queued for this client before the oldest are dropped.
    pub client_queue: usize,
}

impl Hello {
    /// A hello for a connection.
    pub fn new(
        tick_period_ms: u64,
        can_command: bool,
        signals: Signals,
        limits: Limits,
        config: Value,
    ) -> Self {
        Hello {
            kind: "hello",
            protocol: PROTOCOL_VERSION,
            server: format!("pavlov {}", env!("CARGO_PKG_VERSION")),
            tick_period_ms,
            rate_hz: 1000.0 / tick_period_ms.max(1) as f64,
            status_every_ticks: STATUS_EVERY_TICKS,
            can_command,
            signals,
            commands: known_commands(),
            limits,
            config,
        }
    }

    /// The JSON text.
    pub fn to_json(&self) -> String {
        serde_json::to_string(self).unwrap_or_default()
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    fn rejected(text: &str) -> Rejection {
        parse_request(text).unwrap_err()
    }

    #[test]
    fn control_commands_parse_with_their_id_stripped() {
        let r = parse_request(r#"{"cmd":"set_mode","mode":"manual","id":7}"#).unwrap();
        assert_eq!(r.id, Some(json!(7)));
        assert_eq!(r.cmd, "set_mode");
        assert_eq!(
            r.command,
            ClientCommand::Control(ControlCommand::SetMode { mode: Mode::Manual })
        );
        let r = parse_request(r#"{"id":"a","cmd":"estop"}"#).unwrap();
        assert_eq!(r.id, Some(json!("a")));
        assert_eq!(r.command, ClientCommand::Control(ControlCommand::Estop {}));
        let r = parse_request(r#"{"cmd":"release","id":null}"#).unwrap();
        assert_eq!(r.id, None);
    }

    #[test]
    fn every_listed_control_command_is_a_real_one() {
        let samples = [
            json!({"cmd":"set_mode","mode":"reactive"}),
            json!({"cmd":"estop"}),
            json!({"cmd":"release"}),
            json!({"cmd":"teleop","left_mm_s":100,"right_mm_s":-100}),
            json!({"cmd":"human_request"}),
            json!({"cmd":"set_params","alpha":0.1,"lambda":0.9,"threshold":0.4}),
            json!({"cmd":"reset_weights"}),
            json!({"cmd":"save_weights"}),
            json!({"cmd":"start_recording"}),
            json!({"cmd":"stop_recording"}),
        ];
        assert_eq!(samples.len(), CONTROL_COMMANDS.len());
        for (name, sample) in CONTROL_COMMANDS.iter().zip(samples) {
            let r = parse_request(&sample.to_string()).unwrap();
            assert_eq!(r.cmd, *name);
            assert!(matches!(r.command, ClientCommand::Control(_)), "{name}");
        }
    }

    #[test]
    fn session_commands_parse_and_check_their_arguments() {
        let r = parse_request(r#"{"cmd":"set_rate","hz":10}"#).unwrap();
        assert_eq!(
            r.command,
            ClientCommand::Session(SessionCommand::SetRate { hz: 10.0 })
        );
        let r = parse_request(r#"{"cmd":"ping","id":1}"#).unwrap();
        assert_eq!(r.command, ClientCommand::Session(SessionCommand::Ping));
        for bad in [
            r#"{"cmd":"set_rate"}"#,
            r#"{"cmd":"set_rate","hz":"fast"}"#,
            r#"{"cmd":"set_rate","hz":0}"#,
            r#"{"cmd":"set_rate","hz":-3}"#,
            r#"{"cmd":"set_rate","hz":5,"extra":1}"#,
            r#"{"cmd":"ping","x":true}"#,
        ] {
            assert_eq!(rejected(bad).error.code(), "bad_arguments", "{bad}");
        }
    }

    #[test]
    fn malformed_json_is_bad_json_without_an_id() {
        let r = rejected(r#"{"cmd":"estop","id":3"#);
        assert_eq!(r.id, None);
        assert_eq!(r.error.code(), "bad_json");
        assert!(r.error.to_string().contains("EOF"), "{}", r.error);
    }

    #[test]
    fn non_objects_are_refused_by_kind() {
        for (text, kind) in [
            ("[1,2]", "an array"),
            ("3", "a number"),
            ("\"estop\"", "a string"),
            ("null", "null"),
        ] {
            let r = rejected(text);
            assert_eq!(r.error, ProtocolError::NotAnObject(kind));
        }
    }

    #[test]
    fn bad_ids_and_missing_cmd_are_named() {
        assert_eq!(
            rejected(r#"{"cmd":"estop","id":[1]}"#).error,
            ProtocolError::BadId("an array")
        );
        let r = rejected(r#"{"id":5}"#);
        assert_eq!((r.id, r.error), (Some(json!(5)), ProtocolError::MissingCmd));
        assert_eq!(rejected(r#"{"cmd":42}"#).error, ProtocolError::MissingCmd);
    }

    #[test]
    fn unknown_commands_list_the_known_ones_and_keep_the_id() {
        let r = rejected(r#"{"cmd":"fly","id":"x"}"#);
        assert_eq!(r.id, Some(json!("x")));
        assert_eq!(r.error.code(), "unknown_command");
        let msg = r.error.to_string();
        assert!(
            msg.contains("`fly`") && msg.contains("set_mode") && msg.contains("set_rate"),
            "{msg}"
        );
    }

    #[test]
    fn bad_arguments_carry_serde_detail() {
        let cases = [
            (r#"{"cmd":"set_mode","mode":"fly"}"#, "fly"),
            (r#"{"cmd":"set_mode"}"#, "mode"),
            (r#"{"cmd":"estop","force":true}"#, "force"),
            (
                r#"{"cmd":"teleop","left_mm_s":40000,"right_mm_s":0}"#,
                "40000",
            ),
            (r#"{"cmd":"set_params","alpha":"big"}"#, "big"),
        ];
        for (text, detail) in cases {
            let r = rejected(text);
            assert_eq!(r.error.code(), "bad_arguments", "{text}");
            assert!(r.error.to_string().contains(detail), "{text}: {}", r.error);
        }
    }

    #[test]
    fn replies_are_well_formed_json() {
        let ack: Value =
            serde_json::from_str(&ack_json(&Some(json!(3)), "estop", &json!({"estop":true})))
                .unwrap();
        assert_eq!(
            ack,
            json!({"type":"ack","id":3,"cmd":"estop","result":{"estop":true}})
        );
        let err: Value =
            serde_json::from_str(&error_json(&None, "bad_json", "x \"quoted\"")).unwrap();
        assert_eq!(
            err,
            json!({"type":"error","id":null,"code":"bad_json","message":"x \"quoted\""})
        );
    }

    #[test]
    fn tick_messages_carry_the_record() {
        let record = TickRecord {
            seq: 12,
            t_ms: 240.0,
            mode: Mode::Pavlovian,
            obs_age_ticks: Some(1),
            sensors: SensorSummary {
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
            default_action: Action {
                left_mm_s: 100,
                right_mm_s: 100,
            },
            command: Action::STOP,
            safety_stop: Some(SafetyStop::EStop),
            estop: true,
            lateness_us: 80,
            link: LinkSummary {
                up: true,
                good_frames: 9,
                bad_frames: 1,
                skipped_bytes: 3,
            },
            inputs: None,
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
    }
}

//! The dashboard's wire protocol (documented for clients in `web/PROTOCOL.md`): JSON text frames. This
//! module holds the client side (commands) and the replies; the telemetry is in [`super::messages`].
//!
//! Server → client: `hello` once, then `tick` (every tick, or fewer if the client asked for a lower rate)
//! and `status` (health and run counters every [`STATUS_EVERY_TICKS`] ticks), and one `ack` or `error` per
//! client message. Client → server: JSON objects with a `cmd` field and an optional `id` that the reply
//! echoes. This module parses client messages with precise errors and builds the replies; it
//! does no I/O.

use serde::Serialize;
use serde_json::{Map, Value};

use super::strict_json::StrictJsonError;
use crate::command::ControlCommand;

/// Version of this protocol, announced in `hello`.
pub(crate) const PROTOCOL_VERSION: u32 = 1;
/// The websocket subprotocol the server selects when a client offers it.
pub(crate) const SUBPROTOCOL: &str = "pavlov.v1";
/// Prefix of a subprotocol entry that carries the access token (`token.<token>`).
pub(crate) const TOKEN_PROTOCOL_PREFIX: &str = "token.";
/// A `status` message goes out on every tick whose sequence number is a multiple of this (5 Hz at 50 Hz).
pub(crate) const STATUS_EVERY_TICKS: u64 = 10;

/// Commands about the connection itself, answered by the websocket actor (allowed without the token).
pub(crate) const SESSION_COMMANDS: [&str; 4] = ["set_rate", "ping", "horde_watch", "horde_unwatch"];

/// A command about the connection itself.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum SessionCommand {
    /// Receive at most `hz` ticks per second.
    SetRate {
        /// Requested rate, Hz.
        hz: f64,
    },
    /// Answered with an ack; a liveness check.
    Ping,
    /// Receive the Horde's names once, then `count` of its values from `from` (all that fit in one
    /// message when `None`), `hz` times a second.
    HordeWatch {
        /// Messages a second, in `[MIN_HZ, MAX_HZ]`.
        hz: f64,
        /// The first prediction.
        from: usize,
        /// How many, at most `MAX_VALUES`.
        count: Option<usize>,
    },
    /// Stop receiving the Horde's values.
    HordeUnwatch,
}

/// What a client asked for.
#[derive(Debug, Clone, PartialEq)]
pub(crate) enum ClientCommand {
    /// Handled by the websocket actor.
    Session(SessionCommand),
    /// Forwarded to the server.
    Control(ControlCommand),
}

/// A parsed client message.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ClientRequest {
    /// The client's `id`, echoed in the reply (a string or a number).
    pub(crate) id: Option<Value>,
    /// The `cmd` name.
    pub(crate) cmd: String,
    /// The command.
    pub(crate) command: ClientCommand,
}

/// Why a client message was refused. The `code` goes out in the error reply.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub(crate) enum ProtocolError {
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
    /// An object has the same key twice (`{"cmd":"ping","cmd":"estop"}`): refused rather than guessed.
    #[error("{0}; every key may appear once per object")]
    DuplicateKey(String),
}

impl ProtocolError {
    /// The machine-readable error code.
    pub(crate) fn code(&self) -> &'static str {
        match self {
            ProtocolError::BadJson(_) => "bad_json",
            ProtocolError::NotAnObject(_) => "bad_message",
            ProtocolError::BadId(_) => "bad_id",
            ProtocolError::MissingCmd => "missing_cmd",
            ProtocolError::UnknownCommand(_) => "unknown_command",
            ProtocolError::BadArguments { .. } => "bad_arguments",
            ProtocolError::Binary => "binary_unsupported",
            ProtocolError::DuplicateKey(_) => "duplicate_key",
        }
    }
}

/// A refused message: the error and whatever `id` could be recovered for the reply.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Rejection {
    /// The client's `id`, if the message had a usable one.
    pub(crate) id: Option<Value>,
    /// Why.
    pub(crate) error: ProtocolError,
}

/// Every command name: the server's ([`ControlCommand::names`]), then the session's.
pub(crate) fn known_commands() -> Vec<&'static str> {
    ControlCommand::names()
        .chain(SESSION_COMMANDS.iter().copied())
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
pub(crate) fn parse_request(text: &str) -> Result<ClientRequest, Rejection> {
    let reject = |id: Option<Value>, error| Rejection { id, error };
    let value = match super::strict_json::parse(text) {
        Ok(v) => v,
        Err(e @ StrictJsonError::DuplicateKey { .. }) => {
            // The id is kept when it is given once (a duplicate `id` is not an id).
            return Err(reject(
                peek_id(text),
                ProtocolError::DuplicateKey(e.to_string()),
            ));
        }
        Err(StrictJsonError::Syntax(e)) => return Err(reject(None, ProtocolError::BadJson(e))),
    };
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
    } else if ControlCommand::is_name(&cmd) {
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
        "horde_watch" => parse_horde_watch(&mut fields).map_err(bad)?,
        "horde_unwatch" => SessionCommand::HordeUnwatch,
        _ => SessionCommand::Ping,
    };
    match fields.keys().next() {
        Some(extra) => Err(bad(format!("unknown field `{extra}`"))),
        None => Ok(command),
    }
}

/// `horde_watch`'s arguments, each optional and bounded.
fn parse_horde_watch(fields: &mut Map<String, Value>) -> Result<SessionCommand, String> {
    use super::horde_feed::{DEFAULT_HZ, MAX_HZ, MAX_VALUES, MIN_HZ};
    let hz = match fields.remove("hz") {
        None => DEFAULT_HZ,
        Some(Value::Number(n)) => n.as_f64().unwrap_or(f64::NAN),
        Some(other) => return Err(format!("`hz` must be a number, got {}", json_kind(&other))),
    };
    if !(MIN_HZ..=MAX_HZ).contains(&hz) {
        return Err(format!(
            "`hz` must be in [{MIN_HZ}, {MAX_HZ}] messages a second, got {hz}"
        ));
    }
    let index = |fields: &mut Map<String, Value>, key: &str| match fields.remove(key) {
        None => Ok(None),
        Some(Value::Number(n)) if n.as_u64().is_some() => {
            Ok(n.as_u64().map(|v| usize::try_from(v).unwrap_or(usize::MAX)))
        }
        Some(other) => Err(format!(
            "`{key}` must be a non-negative integer, got {}",
            match &other {
                Value::Number(n) => n.to_string(),
                v => json_kind(v).to_string(),
            }
        )),
    };
    let from = index(fields, "from")?.unwrap_or(0);
    let count = index(fields, "count")?;
    if let Some(c) = count
        && !(1..=MAX_VALUES).contains(&c)
    {
        return Err(format!(
            "`count` must be in [1, {MAX_VALUES}] values a message, got {c}"
        ));
    }
    Ok(SessionCommand::HordeWatch { hz, from, count })
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

/// The `id` of a message that will not be processed (over the rate limit), if it is a JSON object with a
/// string or number `id`; nothing else of the message is kept.
pub(crate) fn peek_id(text: &str) -> Option<Value> {
    #[derive(serde::Deserialize)]
    struct IdOnly {
        #[serde(default)]
        id: Option<Value>,
    }
    // A derived struct would also accept an array (its first element as the id).
    if !text.trim_start().starts_with('{') {
        return None;
    }
    match serde_json::from_str::<IdOnly>(text) {
        Ok(IdOnly {
            id: Some(id @ (Value::String(_) | Value::Number(_))),
        }) => Some(id),
        _ => None,
    }
}

/// `{"type":"ack","id":…,"cmd":…,"result":…}`.
pub(crate) fn ack_json(id: &Option<Value>, cmd: &str, result: &Value) -> String {
    let ack = Ack {
        kind: "ack",
        id,
        cmd,
        result,
    };
    serde_json::to_string(&ack).unwrap_or_default()
}

/// `{"type":"error","id":…,"code":…,"message":…}`.
pub(crate) fn error_json(id: &Option<Value>, code: &str, message: &str) -> String {
    let reply = ErrorReply {
        kind: "error",
        id,
        code,
        message,
    };
    serde_json::to_string(&reply).unwrap_or_default()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::command::{GatingCommand, LatchCommand};
    use pavlov::control::Mode;
    use serde_json::json;

    #[test]
    fn the_id_of_an_unprocessed_message_is_recovered_when_it_can_be() {
        assert_eq!(peek_id(r#"{"cmd":"ping","id":7}"#), Some(json!(7)));
        assert_eq!(peek_id(r#" {"id":"a","x":[1,{"y":2}]}"#), Some(json!("a")));
        assert_eq!(peek_id(r#"{"id":{"a":1}}"#), None);
        assert_eq!(peek_id(r#"{"cmd":"ping"}"#), None);
        assert_eq!(peek_id("[7]"), None);
        assert_eq!(peek_id("{not json"), None);
    }

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
            ClientCommand::Control(GatingCommand::SetMode { mode: Mode::Manual }.into())
        );
        let r = parse_request(r#"{"id":"a","cmd":"estop"}"#).unwrap();
        assert_eq!(r.id, Some(json!("a")));
        assert_eq!(
            r.command,
            ClientCommand::Control(LatchCommand::Estop {}.into())
        );
        let r = parse_request(r#"{"cmd":"release","id":null}"#).unwrap();
        assert_eq!(r.id, None);
    }

    /// A message for command `name`: its required arguments where it has some, else none.
    fn sample(name: &str) -> Value {
        match name {
            "set_mode" => json!({"cmd":name,"mode":"reactive"}),
            "teleop" => json!({"cmd":name,"left_mm_s":100,"right_mm_s":-100}),
            "set_params" => json!({"cmd":name,"alpha":0.1,"lambda":0.9,"threshold":0.4}),
            _ => json!({"cmd":name}),
        }
    }

    #[test]
    fn every_control_command_parses_into_the_variant_of_its_name() {
        // The names come from the owners' enums, so a new command is covered here without a list to extend.
        let names: Vec<&str> = ControlCommand::names().collect();
        assert!(names.len() >= 11, "{names:?}");
        for name in names {
            let r = parse_request(&sample(name).to_string())
                .unwrap_or_else(|e| panic!("{name}: {}", e.error));
            assert_eq!(r.cmd, name);
            let ClientCommand::Control(command) = r.command else {
                panic!("{name} is not a control command");
            };
            assert_eq!(serde_json::to_value(&command).unwrap()["cmd"], name);
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
    fn a_key_given_twice_is_refused_not_guessed() {
        let r = rejected(r#"{"cmd":"ping","cmd":"estop","id":4}"#);
        assert_eq!(r.error.code(), "duplicate_key");
        assert_eq!(r.id, Some(json!(4)));
        assert!(r.error.to_string().contains(r#""cmd""#), "{}", r.error);
        let r = rejected(r#"{"cmd":"set_params","alpha":0.1,"alpha":0.9}"#);
        assert_eq!(r.error.code(), "duplicate_key");
        // A duplicated id is no id.
        let r = rejected(r#"{"cmd":"ping","id":1,"id":2}"#);
        assert_eq!((r.id, r.error.code()), (None, "duplicate_key"));
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
    fn horde_watch_takes_bounded_optional_arguments() {
        let ok = |text: &str| parse_request(text).unwrap().command;
        assert_eq!(
            ok(r#"{"cmd":"horde_watch"}"#),
            ClientCommand::Session(SessionCommand::HordeWatch {
                hz: 2.0,
                from: 0,
                count: None
            })
        );
        assert_eq!(
            ok(r#"{"cmd":"horde_watch","hz":10,"from":5,"count":16384}"#),
            ClientCommand::Session(SessionCommand::HordeWatch {
                hz: 10.0,
                from: 5,
                count: Some(16384)
            })
        );
        assert_eq!(
            ok(r#"{"cmd":"horde_unwatch"}"#),
            ClientCommand::Session(SessionCommand::HordeUnwatch)
        );
        for (text, says) in [
            (
                r#"{"cmd":"horde_watch","hz":11}"#,
                "`hz` must be in [0.1, 10]",
            ),
            (r#"{"cmd":"horde_watch","hz":0}"#, "got 0"),
            (r#"{"cmd":"horde_watch","hz":"fast"}"#, "a string"),
            (
                r#"{"cmd":"horde_watch","count":0}"#,
                "`count` must be in [1, 16384]",
            ),
            (r#"{"cmd":"horde_watch","count":16385}"#, "got 16385"),
            (
                r#"{"cmd":"horde_watch","from":-1}"#,
                "`from` must be a non-negative integer, got -1",
            ),
            (r#"{"cmd":"horde_watch","from":1.5}"#, "got 1.5"),
            (
                r#"{"cmd":"horde_watch","names":true}"#,
                "unknown field `names`",
            ),
            (r#"{"cmd":"horde_unwatch","hz":1}"#, "unknown field `hz`"),
        ] {
            let r = rejected(text);
            assert_eq!(r.error.code(), "bad_arguments", "{text}");
            assert!(r.error.to_string().contains(says), "{text}: {}", r.error);
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
}

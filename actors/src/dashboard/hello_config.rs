//! What of the configuration a client sees in its `hello` (`web/PROTOCOL.md`, "What a watcher sees").
//!
//! An operator (who presented the token, or every client when none is configured) gets the whole
//! configuration in force with the token redacted: it may change most of it anyway. A watcher has
//! proved nothing, so it gets only what the page needs to draw: the robot model, the tick period, the
//! control mode, stimulus and gate prediction, and each prediction's name and threshold. Nothing of
//! `[dashboard]` (the bind address, the token, the limits), `[checkpoint]` (file paths), `[sim]`
//! (the seed and fault plan), `[link]`, `[safety]`, `[skeleton]` (its listening address) or the learning
//! parameters.

use pavlov::config::Config;
use serde_json::{Value, json};

/// The configuration an operator sees: all of it, the token shown as `<redacted>`.
pub(crate) fn for_operator(config: &Config) -> Value {
    serde_json::to_value(config.redacted()).unwrap_or(Value::Null)
}

/// The configuration a watcher sees: only what the page needs to draw.
pub(crate) fn for_watcher(config: &Config) -> Value {
    let predictions: Vec<Value> = config
        .predictions
        .iter()
        .map(|p| json!({"name": p.name, "threshold": p.threshold_value()}))
        .collect();
    json!({
        "robot": {"model": config.robot.model},
        "tick": {"period_ms": config.tick.period_ms},
        "control": {
            "mode": config.control.mode,
            "stimulus": config.control.stimulus,
            "gate_prediction": config.control.gate_prediction,
        },
        "predictions": predictions,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    const STALL: &str = include_str!("../../../config/stall.toml");

    fn config() -> Config {
        let mut c = Config::from_toml(STALL).unwrap();
        c.dashboard.token = Some("a-secret-token-of-some-length".into());
        c.checkpoint.dir = "/home/lab/weights".into();
        c
    }

    #[test]
    fn a_watcher_sees_only_what_the_page_draws() {
        let v = for_watcher(&config());
        let text = v.to_string();
        for hidden in [
            "a-secret-token",
            "redacted",
            "/home/lab",
            "dashboard",
            "checkpoint",
            "sim",
            "skeleton",
            "link",
            "safety",
            "alpha",
            "127.0.0.1",
        ] {
            assert!(!text.contains(hidden), "{hidden} in {text}");
        }
        let keys: Vec<&String> = v.as_object().unwrap().keys().collect();
        assert_eq!(keys, ["control", "predictions", "robot", "tick"]);
        assert_eq!(v["robot"]["model"], "create1");
        assert_eq!(v["tick"]["period_ms"], 20);
        assert_eq!(v["control"]["mode"], "pavlovian");
        assert_eq!(v["control"]["stimulus"]["kind"], "stall");
        assert_eq!(
            v["predictions"],
            json!([{"name": "stall", "threshold": 0.5}])
        );
    }

    #[test]
    fn an_operator_sees_everything_but_the_token() {
        let v = for_operator(&config());
        assert_eq!(v["dashboard"]["token"], "<redacted>");
        assert_eq!(v["checkpoint"]["dir"], "/home/lab/weights");
        assert!(!v.to_string().contains("a-secret-token"));
    }
}

//! `[zenoh]`: how this robot appears on Zenoh when `pavlov serve --zenoh` is given: its name (the
//! `<robot>` of every key `pavlov/v1/<robot>/…`), whether commands are taken over Zenoh, how often the status
//! is published and the URL of its own dashboard. How Zenoh connects (peer or client, endpoints,
//! scouting) is Zenoh's own configuration file, given to `--zenoh`.

use serde::{Deserialize, Serialize};

use super::{ConfigError, invalid};

/// The longest robot name, in bytes.
pub const MAX_ROBOT_NAME: usize = 64;

/// `[zenoh]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct ZenohConfig {
    /// This robot's name in key expressions: 1 to 64 of `A-Z a-z 0-9 - _`.
    pub robot: String,
    /// Take commands on `pavlov/v1/<robot>/command` (each must carry the dashboard's token); off: every
    /// command query is answered with a refusal.
    pub commands: bool,
    /// Milliseconds between status messages on `pavlov/v1/<robot>/status` (100 to 60000).
    pub status_every_ms: u64,
    /// The URL of this robot's dashboard as others reach it (published in the status, linked from the
    /// fleet page); empty: `http://` + `[dashboard] bind`.
    pub dashboard_url: String,
}

impl Default for ZenohConfig {
    fn default() -> Self {
        ZenohConfig {
            robot: "pavlov".into(),
            commands: false,
            status_every_ms: 1000,
            dashboard_url: String::new(),
        }
    }
}

impl ZenohConfig {
    /// The defaults: nothing to write into a configuration.
    pub fn is_default(&self) -> bool {
        *self == ZenohConfig::default()
    }

    /// Checks the name (safe in a key expression: no `/`, `*`, `$`, `?`, `#`, spaces) and the bounds.
    pub(super) fn validate(&self) -> Result<(), ConfigError> {
        check_robot_name(&self.robot).map_err(|why| invalid("zenoh.robot", why))?;
        if !(100..=60_000).contains(&self.status_every_ms) {
            return Err(invalid(
                "zenoh.status_every_ms",
                format!(
                    "must be between 100 and 60000, got {}",
                    self.status_every_ms
                ),
            ));
        }
        let url = &self.dashboard_url;
        if !(url.is_empty() || url.starts_with("http://") || url.starts_with("https://")) {
            return Err(invalid(
                "zenoh.dashboard_url",
                format!(
                    "must start with http:// or https://, got {:?}",
                    self.dashboard_url
                ),
            ));
        }
        Ok(())
    }
}

/// Why `name` cannot be a robot's name in a key expression, if it cannot.
pub fn check_robot_name(name: &str) -> Result<(), String> {
    if name.is_empty() || name.len() > MAX_ROBOT_NAME {
        return Err(format!(
            "must be 1 to {MAX_ROBOT_NAME} characters, got {}",
            name.len()
        ));
    }
    if let Some(c) = name
        .chars()
        .find(|c| !(c.is_ascii_alphanumeric() || *c == '-' || *c == '_'))
    {
        return Err(format!(
            "{name:?} has {c:?}: only A-Z a-z 0-9 - _ are allowed (it is one chunk of the key \
             expression pavlov/v1/<robot>/…)"
        ));
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn robot_names_are_single_safe_chunks() {
        assert!(check_robot_name("create-1_b").is_ok());
        for bad in ["", "a/b", "a*", "$x", "robot 1", "a?b", "é"] {
            assert!(check_robot_name(bad).is_err(), "{bad:?}");
        }
        assert!(check_robot_name(&"x".repeat(65)).is_err());
        let c = ZenohConfig {
            status_every_ms: 50,
            ..ZenohConfig::default()
        };
        let e = c.validate().unwrap_err().to_string();
        assert!(e.contains("zenoh.status_every_ms"), "{e}");
    }
}

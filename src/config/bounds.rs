//! The bounds of the configuration values that could make the robot unsafe or the process crash, each
//! refused at start-up with its key and its bound (never clamped, never left to abort the process):
//!
//! - **Policy speeds** within ±500 mm/s, the Open Interface's Drive Direct range
//!   ([`crate::control::Policy::validate`]): a faster speed is refused, not silently clamped.
//! - **Safety timeouts** `[safety] max_obs_age_ticks` and `max_action_age_ticks`: at least 1 tick and
//!   at most [`MAX_SAFETY_TIMEOUT_MS`] (1 s: 50 ticks at the paper's 20 ms). They are what stops the
//!   wheels when the sensor stream dies or the pipeline stalls; at the Drive Direct limit of 500 mm/s the
//!   robot covers 0.5 m in that second, half a leg of the paper's 1 m enclosure. A longer timeout (4·10⁹
//!   ticks is 2.5 years) disables the stop in all but name.
//! - **Predictions**: every parameter and size through [`crate::learn::bounds`] (the step size
//!   α·‖x‖² ≤ 1 with ‖x‖² the prediction's active features on this robot model, λ, τ, the initial
//!   weight, θ, tiles per dimension, pair offsets, features per prediction and in all, the number of
//!   predictions), all before anything is allocated: `tiles = 100000000` is an error naming the key,
//!   not an allocation failure.
//!
//! The other keys' bounds sit with their tables (`[tick]`, `[link]`, `[skeleton]`, the rest of
//! `[dashboard]`, `[checkpoint]`).

use super::{Config, ConfigError, invalid};
use crate::learn::bounds::{MAX_PREDICTIONS, check_set_size};
use crate::learn::{LearnError, ParamBounds, PredictionSpec};
use crate::obs::ObsLayout;

/// The longest a safety timeout may last, ms (see the module documentation).
pub const MAX_SAFETY_TIMEOUT_MS: u64 = 1000;

/// Checks every bound of this module; `[tick] period_ms` must already be valid.
pub(super) fn check(cfg: &Config) -> Result<(), ConfigError> {
    check_safety(cfg)?;
    check_policies(cfg)?;
    cfg.prediction_bounds()?;
    Ok(())
}

fn check_safety(cfg: &Config) -> Result<(), ConfigError> {
    let period_ms = cfg.tick.period_ms.max(1);
    let max_ticks = (MAX_SAFETY_TIMEOUT_MS / period_ms).max(1);
    let timeouts = [
        (
            "safety.max_action_age_ticks",
            cfg.safety.max_action_age_ticks,
        ),
        ("safety.max_obs_age_ticks", cfg.safety.max_obs_age_ticks),
    ];
    for (key, ticks) in timeouts {
        if ticks == 0 || u64::from(ticks) > max_ticks {
            return Err(invalid(
                key,
                format!(
                    "{ticks} ticks is outside 1..={max_ticks} (at most {MAX_SAFETY_TIMEOUT_MS} ms at \
                     period_ms = {period_ms}: the wheels must stop within a second)"
                ),
            ));
        }
    }
    Ok(())
}

fn check_policies(cfg: &Config) -> Result<(), ConfigError> {
    for (key, policy) in [
        ("control.default_policy", &cfg.control.default_policy),
        ("control.response", &cfg.control.response),
    ] {
        super::rules::check_policy(key, policy)?;
    }
    Ok(())
}

/// The configuration key of a prediction's error: `predictions[0] (stall).alpha`.
fn prediction_error(i: usize, spec: &PredictionSpec, e: LearnError) -> ConfigError {
    let name = &spec.name;
    match e {
        LearnError::OutOfBounds {
            field,
            value,
            bound,
            ..
        } => invalid(
            format!("predictions[{i}] ({name}).{field}"),
            format!("{value} {bound}"),
        ),
        LearnError::EmptyName => invalid(format!("predictions[{i}].name"), e.to_string()),
        LearnError::NoTilings => {
            invalid(format!("predictions[{i}] ({name}).features"), e.to_string())
        }
        other => invalid(format!("predictions[{i}] ({name})"), other.to_string()),
    }
}

impl Config {
    /// Every prediction checked against its bounds on this robot model (see the module
    /// documentation), and each one's bounds for runtime changes, in order.
    pub fn prediction_bounds(&self) -> Result<Vec<(String, ParamBounds)>, ConfigError> {
        if self.predictions.len() > MAX_PREDICTIONS {
            return Err(invalid(
                "predictions",
                format!(
                    "{} predictions are more than the {MAX_PREDICTIONS} allowed",
                    self.predictions.len()
                ),
            ));
        }
        let obs_dims = ObsLayout::for_model(self.robot.model).len();
        let mut all = Vec::with_capacity(self.predictions.len());
        for (i, p) in self.predictions.iter().enumerate() {
            let bounds = p.bounds(obs_dims).map_err(|e| prediction_error(i, p, e))?;
            all.push((p.name.clone(), bounds));
        }
        let sizes: Vec<usize> = all.iter().map(|(_, b)| b.features).collect();
        check_set_size(&sizes).map_err(|e| invalid("predictions", e.to_string()))?;
        Ok(all)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const STALL: &str = include_str!("../../config/stall.toml");
    const INTERACTION: &str = include_str!("../../config/interaction.toml");

    /// The key and message `text` is refused with.
    fn refusal(text: &str) -> (String, String) {
        match Config::from_toml(text) {
            Err(ConfigError::Invalid { key, message }) => (key, message),
            other => panic!("expected a refusal, got {other:?}"),
        }
    }

    /// The refusal of `base` with `from` replaced by `to`.
    fn refused(base: &str, from: &str, to: &str) -> (String, String) {
        let text = base.replace(from, to);
        assert_ne!(text, base, "{from} not found");
        refusal(&text)
    }

    #[test]
    fn policy_speeds_beyond_drive_direct_are_refused_not_clamped() {
        let (key, message) = refused(
            STALL,
            "default_policy = { kind = \"stall_cycle\" }",
            "default_policy = { kind = \"stall_cycle\", drive_mm_s = 2000 }",
        );
        assert_eq!(key, "control.default_policy.drive_mm_s");
        assert!(
            message.contains("2000") && message.contains("-500..=500"),
            "{message}"
        );
        let (key, _) = refused(
            INTERACTION,
            "response = { kind = \"spin_left\" }",
            "response = { kind = \"spin_left\", speed_mm_s = -501 }",
        );
        assert_eq!(key, "control.response.speed_mm_s");
        let edge = STALL.replace(
            "response = { kind = \"stop\" }",
            "response = { kind = \"constant\", left_mm_s = 500, right_mm_s = -500 }",
        );
        Config::from_toml(&edge).unwrap();
    }

    #[test]
    fn safety_timeouts_must_stop_the_wheels_within_a_second() {
        let (key, message) = refused(
            STALL,
            "max_obs_age_ticks = 5",
            "max_obs_age_ticks = 4000000000",
        );
        assert_eq!(key, "safety.max_obs_age_ticks");
        assert!(message.contains("1..=50"), "{message}");
        let (key, _) = refused(
            STALL,
            "max_action_age_ticks = 3",
            "max_action_age_ticks = 51",
        );
        assert_eq!(key, "safety.max_action_age_ticks");
        let (key, _) = refused(STALL, "max_obs_age_ticks = 5", "max_obs_age_ticks = 0");
        assert_eq!(key, "safety.max_obs_age_ticks");
        Config::from_toml(&STALL.replace("max_obs_age_ticks = 5", "max_obs_age_ticks = 50"))
            .unwrap();
        // The bound is a time: at 100 ms ticks, 10 ticks.
        let slow = STALL.replace("period_ms = 20", "period_ms = 100");
        let (key, message) = refused(&slow, "max_obs_age_ticks = 5", "max_obs_age_ticks = 11");
        assert_eq!(key, "safety.max_obs_age_ticks");
        assert!(message.contains("1..=10"), "{message}");
    }

    #[test]
    fn a_divergent_step_size_is_refused_with_its_bound() {
        let alpha = "alpha = 0.022727272727272728";
        let (key, message) = refused(STALL, alpha, "alpha = 1.0");
        assert_eq!(key, "predictions[0] (stall).alpha");
        assert_eq!(
            message,
            "1.0 exceeds 1/44 = 0.0227 (α·‖x‖² ≤ 1 with 44 active features)"
        );
        let (_, message) = refused(STALL, alpha, "alpha = 1e308");
        assert!(
            message.contains("1e308") && message.contains("1/44"),
            "{message}"
        );
        let (key, message) = refused(INTERACTION, "alpha = 0.02", "alpha = 0.5");
        assert_eq!(key, "predictions[0] (command).alpha");
        assert!(message.contains("1/5 = 0.2"), "{message}");
        Config::from_toml(&INTERACTION.replace("alpha = 0.02", "alpha = 0.2")).unwrap();
        for (from, to, field) in [
            ("lambda = 0.5", "lambda = 1.5", "lambda"),
            ("tau = 25.0", "tau = 1.0", "tau"),
            ("tau = 25.0", "tau = inf", "tau"),
            (
                "initial_weight = 0.0",
                "initial_weight = nan",
                "initial_weight",
            ),
            (
                "threshold = { fixed = 0.5 }",
                "threshold = { fixed = inf }",
                "threshold",
            ),
        ] {
            let (key, _) = refused(STALL, from, to);
            assert_eq!(key, format!("predictions[0] (stall).{field}"), "{to}");
        }
    }

    #[test]
    fn feature_sizes_are_refused_before_any_allocation() {
        let (key, message) = refused(STALL, "tiles = 10", "tiles = 100000000");
        assert_eq!(key, "predictions[0] (stall).features.tiles");
        assert!(message.contains("1..=1000"), "{message}");
        let (key, message) = refused(INTERACTION, "tiles = 10 ", "tiles = 1000 ");
        assert_eq!(key, "predictions[0] (command).features");
        assert!(message.contains("1000000"), "{message}");
        let (key, _) = refused(
            INTERACTION,
            "{ x = \"left_elbow\", y = \"right_elbow\", offset = 0.0 }",
            "{ x = \"left_elbow\", y = \"right_elbow\", offset = 1.5 }",
        );
        assert_eq!(key, "predictions[0] (command).features.pairs[4].offset");
    }

    #[test]
    fn the_number_of_predictions_and_their_features_in_all_are_bounded() {
        let start = STALL.find("[[predictions]]").unwrap();
        let end = STALL.find("[sim]").unwrap();
        let table = &STALL[start..end];
        let many: String = (0..=MAX_PREDICTIONS)
            .map(|k| table.replace("name = \"stall\"", &format!("name = \"p{k}\"")))
            .collect();
        let text = STALL
            .replace(table, &many)
            .replace("gate_prediction = \"stall\"", "gate_prediction = \"p0\"");
        let (key, message) = refusal(&text);
        assert_eq!(key, "predictions");
        assert!(message.contains("33 predictions"), "{message}");
        // 23 predictions of 44 × 1000 features: each fits, together they do not.
        let big = table.replace("tiles = 10", "tiles = 1000");
        let heavy: String = (0..23)
            .map(|k| big.replace("name = \"stall\"", &format!("name = \"p{k}\"")))
            .collect();
        let text = STALL
            .replace(table, &heavy)
            .replace("gate_prediction = \"stall\"", "gate_prediction = \"p0\"");
        let (key, message) = refusal(&text);
        assert_eq!(key, "predictions");
        assert!(message.contains("1012000 features"), "{message}");
    }

    #[test]
    fn the_client_queue_is_bounded() {
        let text = format!("{STALL}\n[dashboard]\nclient_queue = 1000000000\n");
        match Config::from_toml(&text) {
            Err(ConfigError::Invalid { key, message }) => {
                assert_eq!(key, "dashboard.client_queue");
                assert!(message.contains("10000"), "{message}");
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn the_bounds_follow_the_robot_model() {
        let c = Config::from_toml(STALL).unwrap();
        let b = c.prediction_bounds().unwrap();
        assert_eq!(b[0].0, "stall");
        assert_eq!((b[0].1.active_features, b[0].1.features), (44, 440));
        let i = Config::from_toml(INTERACTION).unwrap();
        assert_eq!(i.prediction_bounds().unwrap()[0].1.max_alpha, 0.2);
    }
}

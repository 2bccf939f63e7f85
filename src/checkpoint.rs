//! Lifelong checkpoints: the learned state of every prediction together with the configuration it
//! belongs to, and the check that refuses to resume a checkpoint into a configuration that differs.
//!
//! The fingerprint is FNV-1a (64 bit) over the canonical TOML encoding of the robot model, the stimulus
//! and the prediction specs: everything that decides what a weight means. A checkpoint never holds a
//! non-finite number ([`Checkpoint::new`] refuses one, naming the prediction): JSON cannot carry NaN or
//! infinity, and a learner restored from one would only predict NaN. [`Checkpoint::param_overrides`]
//! names the learning parameters (α, λ, θ) a checkpoint carries that differ from the configuration's
//! (changed at run time with `set_params`); restoring the checkpoint puts its values in force. Pure code:
//! writing files atomically is the server's job.

use serde::{Deserialize, Serialize};
use thiserror::Error;

use crate::config::{Config, StimulusSpec};
use crate::learn::snapshot::SetSnapshot;
use crate::learn::spec::PredictionSpec;
use crate::oi::Model;

/// The `format` of checkpoints this code writes and reads.
pub const CHECKPOINT_FORMAT: &str = "pavlov-checkpoint/1";

/// A checkpoint file's contents.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Checkpoint {
    /// Always [`CHECKPOINT_FORMAT`].
    pub format: String,
    /// The tick after whose learning step the state was taken.
    pub created_tick: u64,
    /// The robot model (it decides the observation layout).
    pub robot_model: Model,
    /// The stimulus (it is one of the learning inputs).
    pub stimulus: StimulusSpec,
    /// The prediction specs the weights belong to.
    pub predictions_config: Vec<PredictionSpec>,
    /// [`fingerprint`] of the three fields above.
    pub config_fingerprint: String,
    /// Weights, traces and the previous step of every prediction.
    pub state: SetSnapshot,
}

/// Why a checkpoint cannot be built or resumed.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CheckpointError {
    /// Not a checkpoint of this format.
    #[error("the checkpoint's format is `{got}`, expected `{CHECKPOINT_FORMAT}`")]
    Format { got: String },
    /// The file's fingerprint does not match its own contents.
    #[error(
        "the checkpoint's fingerprint {stored} does not match its contents ({computed}): the file was edited or damaged"
    )]
    Damaged { stored: String, computed: String },
    /// The checkpoint belongs to another configuration.
    #[error("the checkpoint does not match the configuration: {}", .differences.join("; "))]
    Mismatch { differences: Vec<String> },
    /// The configuration could not be encoded for the fingerprint.
    #[error("cannot encode the configuration for its fingerprint: {0}")]
    Encode(String),
    /// A weight, trace or parameter is NaN or infinite: such a state is never checkpointed.
    #[error(
        "prediction `{prediction}`: {field} is {value}; a checkpoint never holds a non-finite number"
    )]
    NonFinite {
        /// The prediction whose state is not finite.
        prediction: String,
        /// Which value (`weights[12]`, `traces[3]`, `alpha`, …).
        field: String,
        /// The value (`NaN`, `inf`, `-inf`).
        value: f64,
    },
}

/// A learning parameter a checkpoint carries that differs from the configuration's.
#[derive(Debug, Clone, PartialEq)]
pub struct ParamOverride {
    /// The prediction.
    pub prediction: String,
    /// `alpha`, `lambda` or `threshold`.
    pub parameter: &'static str,
    /// The checkpoint's value (the one in force after restoring it).
    pub checkpoint: f64,
    /// The configuration's value.
    pub configuration: f64,
}

impl std::fmt::Display for ParamOverride {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(
            f,
            "prediction `{}`: {} is {} in the checkpoint, {} in the configuration; the checkpoint's {} is in force",
            self.prediction, self.parameter, self.checkpoint, self.configuration, self.checkpoint
        )
    }
}

/// Checks that every number in `state` is finite; the error names the first one that is not.
pub fn check_finite(state: &SetSnapshot) -> Result<(), CheckpointError> {
    for p in &state.predictions {
        let non_finite = |field: String, value: f64| CheckpointError::NonFinite {
            prediction: p.name.clone(),
            field,
            value,
        };
        let secondary = p.secondary.as_deref().unwrap_or(&[]);
        for (what, values) in [
            ("weights", &p.weights[..]),
            ("traces", &p.traces[..]),
            ("secondary", secondary),
        ] {
            if let Some((i, &v)) = values.iter().enumerate().find(|(_, v)| !v.is_finite()) {
                return Err(non_finite(format!("{what}[{i}]"), v));
            }
        }
        let threshold = match p.threshold {
            crate::learn::spec::Threshold::Fixed(t) => t,
            crate::learn::spec::Threshold::Steps(_) => 0.0,
        };
        let gamma = p.previous.as_ref().map_or(0.0, |prev| prev.gamma);
        for (field, v) in [
            ("alpha", p.alpha),
            ("lambda", p.lambda),
            ("threshold", threshold),
            ("previous.gamma", gamma),
            ("beta", p.beta.unwrap_or(0.0)),
        ] {
            if !v.is_finite() {
                return Err(non_finite(field.to_string(), v));
            }
        }
    }
    Ok(())
}

/// What the fingerprint covers, in a fixed order.
#[derive(Serialize)]
struct Fingerprinted<'a> {
    robot_model: Model,
    stimulus: &'a StimulusSpec,
    predictions: &'a [PredictionSpec],
}

/// FNV-1a, 64 bit.
fn fnv1a64(bytes: &[u8]) -> u64 {
    bytes.iter().fold(0xcbf2_9ce4_8422_2325, |h, &b| {
        (h ^ u64::from(b)).wrapping_mul(0x0000_0100_0000_01b3)
    })
}

/// The fingerprint of a model, stimulus and prediction specs, as `fnv1a64:<16 hex digits>`.
pub fn fingerprint(
    robot_model: Model,
    stimulus: &StimulusSpec,
    predictions: &[PredictionSpec],
) -> Result<String, CheckpointError> {
    let canonical = toml::to_string(&Fingerprinted {
        robot_model,
        stimulus,
        predictions,
    })
    .map_err(|e| CheckpointError::Encode(e.to_string()))?;
    Ok(format!("fnv1a64:{:016x}", fnv1a64(canonical.as_bytes())))
}

/// The fingerprint of `config`'s learning-relevant part.
pub fn config_fingerprint(config: &Config) -> Result<String, CheckpointError> {
    fingerprint(
        config.robot.model,
        &config.control.stimulus,
        &config.predictions,
    )
}

impl Checkpoint {
    /// A checkpoint of `state`, taken at `tick`, for `config`. Refused when any number in `state` is
    /// not finite ([`CheckpointError::NonFinite`] names the prediction).
    pub fn new(config: &Config, tick: u64, state: SetSnapshot) -> Result<Self, CheckpointError> {
        check_finite(&state)?;
        Ok(Checkpoint {
            format: CHECKPOINT_FORMAT.to_string(),
            created_tick: tick,
            robot_model: config.robot.model,
            stimulus: config.control.stimulus.clone(),
            predictions_config: config.predictions.clone(),
            config_fingerprint: config_fingerprint(config)?,
            state,
        })
    }

    /// Checks that this checkpoint may be resumed under `config`; the error names every difference.
    pub fn check_against(&self, config: &Config) -> Result<(), CheckpointError> {
        if self.format != CHECKPOINT_FORMAT {
            return Err(CheckpointError::Format {
                got: self.format.clone(),
            });
        }
        let computed = fingerprint(self.robot_model, &self.stimulus, &self.predictions_config)?;
        if computed != self.config_fingerprint {
            return Err(CheckpointError::Damaged {
                stored: self.config_fingerprint.clone(),
                computed,
            });
        }
        if computed == config_fingerprint(config)? {
            return Ok(());
        }
        let mut differences = Vec::new();
        if self.robot_model != config.robot.model {
            differences.push(format!(
                "robot.model is {} in the checkpoint, {} in the configuration",
                self.robot_model, config.robot.model
            ));
        }
        diff_values(
            "control.stimulus",
            &encode(&self.stimulus)?,
            &encode(&config.control.stimulus)?,
            &mut differences,
        );
        diff_predictions(
            &self.predictions_config,
            &config.predictions,
            &mut differences,
        )?;
        if differences.is_empty() {
            differences.push(format!(
                "fingerprint {} differs from the configuration's",
                self.config_fingerprint
            ));
        }
        Err(CheckpointError::Mismatch { differences })
    }

    /// The learning parameters (α, λ, θ) of this checkpoint's state that differ from `config`'s, matched
    /// by prediction name. Restoring the checkpoint puts the checkpoint's values in force.
    pub fn param_overrides(&self, config: &Config) -> Vec<ParamOverride> {
        let mut out = Vec::new();
        for saved in &self.state.predictions {
            let Some(spec) = config.predictions.iter().find(|p| p.name == saved.name) else {
                continue;
            };
            let saved_threshold = PredictionSpec {
                threshold: saved.threshold,
                ..spec.clone()
            }
            .threshold_value();
            for (parameter, checkpoint, configuration) in [
                ("alpha", saved.alpha, spec.alpha),
                ("lambda", saved.lambda, spec.lambda),
                ("threshold", saved_threshold, spec.threshold_value()),
            ] {
                if checkpoint.to_bits() != configuration.to_bits() {
                    out.push(ParamOverride {
                        prediction: saved.name.clone(),
                        parameter,
                        checkpoint,
                        configuration,
                    });
                }
            }
        }
        out
    }
}

fn encode<T: Serialize>(value: &T) -> Result<toml::Value, CheckpointError> {
    toml::Value::try_from(value).map_err(|e| CheckpointError::Encode(e.to_string()))
}

fn diff_predictions(
    saved: &[PredictionSpec],
    configured: &[PredictionSpec],
    out: &mut Vec<String>,
) -> Result<(), CheckpointError> {
    let names = |s: &[PredictionSpec]| {
        s.iter()
            .map(|p| p.name.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    };
    if saved.len() != configured.len() {
        out.push(format!(
            "the checkpoint has {} predictions [{}], the configuration {} [{}]",
            saved.len(),
            names(saved),
            configured.len(),
            names(configured)
        ));
        return Ok(());
    }
    for (i, (s, c)) in saved.iter().zip(configured).enumerate() {
        let path = format!("predictions[{i}] ({})", c.name);
        diff_values(&path, &encode(s)?, &encode(c)?, out);
    }
    Ok(())
}

/// Appends a sentence for every leaf where `saved` and `configured` differ.
fn diff_values(path: &str, saved: &toml::Value, configured: &toml::Value, out: &mut Vec<String>) {
    use toml::Value;
    match (saved, configured) {
        (Value::Table(a), Value::Table(b)) => {
            let mut keys: Vec<&String> = a.keys().chain(b.keys()).collect();
            keys.sort();
            keys.dedup();
            for k in keys {
                let p = format!("{path}.{k}");
                match (a.get(k), b.get(k)) {
                    (Some(x), Some(y)) => diff_values(&p, x, y, out),
                    (Some(x), None) => {
                        out.push(format!("{p} is {x} in the checkpoint but not configured"))
                    }
                    (None, Some(y)) => out.push(format!(
                        "{p} is {y} in the configuration but not in the checkpoint"
                    )),
                    (None, None) => {}
                }
            }
        }
        (Value::Array(a), Value::Array(b)) if a.len() == b.len() => {
            for (i, (x, y)) in a.iter().zip(b).enumerate() {
                diff_values(&format!("{path}[{i}]"), x, y, out);
            }
        }
        (a, b) if a != b => out.push(format!(
            "{path} is {a} in the checkpoint, {b} in the configuration"
        )),
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn stall() -> Config {
        Config::from_toml(include_str!("../config/stall.toml")).unwrap()
    }

    fn learned_state(cfg: &Config) -> SetSnapshot {
        crate::agent::LearningStage::new(cfg).unwrap().snapshot()
    }

    fn empty_state() -> SetSnapshot {
        SetSnapshot {
            predictions: Vec::new(),
        }
    }

    #[test]
    fn fingerprint_is_deterministic_and_sensitive_to_the_specs() {
        let a = stall();
        let f = config_fingerprint(&a).unwrap();
        assert_eq!(f, config_fingerprint(&stall()).unwrap());
        assert!(f.starts_with("fnv1a64:") && f.len() == 8 + 16, "{f}");
        let mut b = stall();
        b.predictions[0].alpha *= 0.5;
        assert_ne!(f, config_fingerprint(&b).unwrap());
        // Settings that do not change what a weight means leave it alone.
        let mut c = stall();
        c.sim.seed += 1;
        c.checkpoint.dir = "elsewhere".into();
        assert_eq!(f, config_fingerprint(&c).unwrap());
    }

    #[test]
    fn fnv1a64_matches_reference_values() {
        assert_eq!(fnv1a64(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(fnv1a64(b"a"), 0xaf63_dc4c_8601_ec8c);
    }

    #[test]
    fn a_checkpoint_matches_its_own_configuration_and_round_trips() {
        let cfg = stall();
        let cp = Checkpoint::new(&cfg, 42, empty_state()).unwrap();
        assert_eq!(cp.check_against(&cfg), Ok(()));
        let text = toml::to_string(&cp).unwrap();
        let back: Checkpoint = toml::from_str(&text).unwrap();
        assert_eq!(back, cp);
    }

    /// Issue 14: an off-policy prediction's secondary weights and β go through a checkpoint (TOML) and
    /// restore exactly; a non-finite secondary weight is never checkpointed.
    #[test]
    fn off_policy_secondary_weights_round_trip_and_must_be_finite() {
        let text = format!(
            "{}\n{}",
            include_str!("../config/stall.toml"),
            r#"
[[predictions]]
name = "stall_pi"
tau = 25.0
lambda = 0.5
alpha = 0.022727272727272728
sigma = "identity"
threshold = { fixed = 0.5 }
cumulant = { stimulus = "stall" }
features = { kind = "one_dim", all_obs = true, tiles = 10 }
learner = "gtd"
target_policy = "default"
beta = 0.0022727272727272726
"#
        );
        let cfg = Config::from_toml(&text).unwrap();
        let mut stage = crate::agent::LearningStage::new(&cfg).unwrap();
        let mut state = stage.snapshot();
        let p = &mut state.predictions[1];
        p.weights[3] = 0.25;
        p.secondary.as_mut().unwrap()[3] = -0.125;
        stage.restore(&state).unwrap();
        let cp = Checkpoint::new(&cfg, 7, stage.snapshot()).unwrap();
        let back: Checkpoint = toml::from_str(&toml::to_string(&cp).unwrap()).unwrap();
        assert_eq!(back, cp);
        let mut restored = crate::agent::LearningStage::new(&cfg).unwrap();
        restored.restore(&back.state).unwrap();
        let gtd = restored
            .predictions()
            .off_policy_learner("stall_pi")
            .unwrap();
        assert_eq!((gtd.weights()[3], gtd.secondary()[3]), (0.25, -0.125));
        state.predictions[1].secondary.as_mut().unwrap()[5] = f64::NAN;
        match check_finite(&state) {
            Err(CheckpointError::NonFinite {
                prediction, field, ..
            }) => {
                assert_eq!(
                    (prediction.as_str(), field.as_str()),
                    ("stall_pi", "secondary[5]")
                );
            }
            other => panic!("{other:?}"),
        }
    }

    #[test]
    fn a_different_lambda_is_refused_naming_the_field() {
        let cp = Checkpoint::new(&stall(), 1, empty_state()).unwrap();
        let mut other = stall();
        other.predictions[0].lambda = 0.25;
        let err = cp.check_against(&other).unwrap_err();
        let msg = err.to_string();
        let name = &other.predictions[0].name;
        assert!(
            msg.contains(&format!("predictions[0] ({name}).lambda")),
            "{msg}"
        );
        assert!(msg.contains("0.25"), "{msg}");
    }

    #[test]
    fn a_different_model_or_prediction_count_is_named() {
        let cp = Checkpoint::new(&stall(), 1, empty_state()).unwrap();
        let mut other = stall();
        other.robot.model = match other.robot.model {
            Model::Create1 => Model::Create2,
            Model::Create2 => Model::Create1,
        };
        other.predictions.push(other.predictions[0].clone());
        other.predictions.last_mut().unwrap().name = "extra".into();
        let msg = cp.check_against(&other).unwrap_err().to_string();
        assert!(msg.contains("robot.model"), "{msg}");
        assert!(msg.contains("extra"), "{msg}");
    }

    #[test]
    fn an_edited_checkpoint_or_another_format_is_refused() {
        let cfg = stall();
        let mut cp = Checkpoint::new(&cfg, 1, empty_state()).unwrap();
        cp.predictions_config[0].alpha += 1.0;
        assert!(matches!(
            cp.check_against(&cfg),
            Err(CheckpointError::Damaged { .. })
        ));
        let mut cp = Checkpoint::new(&cfg, 1, empty_state()).unwrap();
        cp.format = "pavlov-checkpoint/0".into();
        assert!(matches!(
            cp.check_against(&cfg),
            Err(CheckpointError::Format { .. })
        ));
    }

    #[test]
    fn a_non_finite_weight_trace_or_parameter_is_never_checkpointed() {
        let cfg = stall();
        let name = cfg.predictions[0].name.clone();
        assert!(Checkpoint::new(&cfg, 1, learned_state(&cfg)).is_ok());
        let mut nan_weight = learned_state(&cfg);
        nan_weight.predictions[0].weights[7] = f64::NAN;
        let err = Checkpoint::new(&cfg, 1, nan_weight).unwrap_err();
        assert!(
            matches!(&err, CheckpointError::NonFinite { prediction, field, value }
                if *prediction == name && field == "weights[7]" && value.is_nan()),
            "{err:?}"
        );
        let msg = err.to_string();
        assert!(msg.contains(&format!("`{name}`")), "{msg}");
        assert!(msg.contains("weights[7] is NaN"), "{msg}");
        let mut inf_trace = learned_state(&cfg);
        inf_trace.predictions[0].traces[0] = f64::INFINITY;
        let msg = Checkpoint::new(&cfg, 1, inf_trace).unwrap_err().to_string();
        assert!(msg.contains("traces[0] is inf"), "{msg}");
        let mut nan_alpha = learned_state(&cfg);
        nan_alpha.predictions[0].alpha = f64::NAN;
        let msg = Checkpoint::new(&cfg, 1, nan_alpha).unwrap_err().to_string();
        assert!(msg.contains("alpha is NaN"), "{msg}");
    }

    #[test]
    fn parameters_changed_at_run_time_are_named_as_overrides() {
        let cfg = stall();
        let cp = Checkpoint::new(&cfg, 1, learned_state(&cfg)).unwrap();
        assert!(cp.param_overrides(&cfg).is_empty());
        let mut state = learned_state(&cfg);
        state.predictions[0].alpha = 0.01;
        state.predictions[0].threshold = crate::learn::spec::Threshold::Fixed(0.3);
        let cp = Checkpoint::new(&cfg, 1, state).unwrap();
        let overrides = cp.param_overrides(&cfg);
        let what: Vec<_> = overrides.iter().map(|o| o.parameter).collect();
        assert_eq!(what, ["alpha", "threshold"]);
        assert_eq!(overrides[0].checkpoint, 0.01);
        assert_eq!(overrides[0].configuration, cfg.predictions[0].alpha);
        let line = overrides[1].to_string();
        assert!(
            line.contains("threshold is 0.3 in the checkpoint, 0.5 in the configuration"),
            "{line}"
        );
        assert!(line.contains("the checkpoint's 0.3 is in force"), "{line}");
    }
}

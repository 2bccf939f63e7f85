//! The server's configuration: one TOML file, validated at start-up.
//!
//! Every table rejects unknown keys (`deny_unknown_fields`), and [`Config::validate`] checks values, so a
//! typo or a bad number stops the server at start-up with a message that names the key. Every key is
//! documented in `config/README.md`.

use serde::{Deserialize, Serialize};

use crate::control::{GateKind, Mode, Policy};
use crate::learn::PredictionSpec;
use crate::oi::Model;

mod bounds;
mod dashboard;
pub mod gate;
mod horde;
mod link;
mod rules;
mod sim_params;
mod tick;
mod zenoh;
pub use bounds::MAX_SAFETY_TIMEOUT_MS;
pub use dashboard::{
    DashboardConfig, MAX_CLIENT_QUEUE, MIN_PUBLIC_TOKEN_BITS, MIN_PUBLIC_TOKEN_CHARS,
    public_token_problem, token_strength_bits,
};
pub use horde::{HordeConfig, Precision, Scheduling};
pub use link::LinkConfig;
pub use rules::{MAX_RULES, RuleSpec};
pub use sim_params::SimParamsOverrides;
pub use tick::{MAX_SPIN_US, TickConfig, TickTimer};
pub use zenoh::{ZenohConfig, check_robot_name};

/// A configuration error, naming the offending key.
#[derive(Debug, thiserror::Error, PartialEq)]
pub enum ConfigError {
    /// The file is not valid TOML, has an unknown key, or a value of the wrong type.
    #[error("{0}")]
    Parse(String),
    /// A value is out of range; the first field is the key path.
    #[error("{key}: {message}")]
    Invalid {
        /// Dotted key path, e.g. `predictions[0].tau`.
        key: String,
        /// What is wrong.
        message: String,
    },
}

fn invalid(key: impl Into<String>, message: impl Into<String>) -> ConfigError {
    ConfigError::Invalid {
        key: key.into(),
        message: message.into(),
    }
}

pub use crate::oi::mode::DriveMode;

/// `[robot]`: which robot and how to talk to it.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct RobotConfig {
    /// `create1` or `create2`.
    pub model: Model,
    /// `safe` or `full`.
    pub oi_mode: DriveMode,
    /// Packet ids to stream; empty = the model's all-sensors group (6 or 100).
    pub stream: Vec<u8>,
}

impl Default for RobotConfig {
    fn default() -> Self {
        RobotConfig {
            model: Model::Create1,
            oi_mode: DriveMode::Safe,
            stream: Vec::new(),
        }
    }
}

impl RobotConfig {
    /// The packet ids to stream.
    pub fn stream_ids(&self) -> Vec<u8> {
        if self.stream.is_empty() {
            vec![self.model.all_sensors_group()]
        } else {
            self.stream.clone()
        }
    }
}

/// `[safety]`: when actuation stops the wheels on its own.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SafetyConfig {
    /// Stop when no fresh action has arrived for this many ticks (1 tick to 1 s; see `bounds`).
    pub max_action_age_ticks: u32,
    /// Stop when the newest observation is older than this many ticks (1 tick to 1 s; see `bounds`).
    pub max_obs_age_ticks: u32,
}

impl Default for SafetyConfig {
    fn default() -> Self {
        SafetyConfig {
            max_action_age_ticks: 3,
            max_obs_age_ticks: 5,
        }
    }
}

/// The stimulus event E.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum StimulusSpec {
    /// A motor stall: a leaky integrator of the wheels' over-current flags (+1 on, −1 off, clamped to
    /// `[0, max]`) exceeds `above` (the paper: 3 and 5).
    Stall {
        /// E when the integrator is strictly above this level.
        above: u8,
        /// The integrator's upper clamp.
        max: u8,
    },
    /// A command gesture: the left elbow's interior angle is valid and below `below_deg` (the paper: 90).
    LeftElbow {
        /// Threshold angle, degrees.
        below_deg: f64,
    },
}

impl StimulusSpec {
    /// The stimulus's name, as predictions and the Horde refer to it.
    pub fn name(&self) -> &'static str {
        match self {
            StimulusSpec::Stall { .. } => "stall",
            StimulusSpec::LeftElbow { .. } => "left_elbow_command",
        }
    }
}

/// Names of the extra (non-observation) inputs every learner may read, scaled to `[0, 1]` as
/// angle / 180°: the elbow angles and their moving averages (NaN without a skeleton).
pub const ELBOW_INPUTS: [&str; 4] = [
    "left_elbow",
    "left_elbow_avg",
    "right_elbow",
    "right_elbow_avg",
];

/// `[control]`: the gate.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ControlConfig {
    /// `reactive`, `pavlovian` or `manual` at start-up; changeable while running.
    pub mode: Mode,
    /// The stimulus E.
    pub stimulus: StimulusSpec,
    /// The default policy π.
    pub default_policy: Policy,
    /// The fixed response ϱ.
    pub response: Policy,
    /// The prediction (by name) that drives the Pavlovian gate.
    pub gate_prediction: String,
    /// `deterministic` (the paper's, the default) or `stochastic` (π's action with probability
    /// `epsilon` where a rule fires; see [`crate::config::gate`]).
    #[serde(default, skip_serializing_if = "GateKind::is_deterministic")]
    pub gate: GateKind,
    /// The stochastic gate's ε in (0, 1): the probability of π's action where a rule fires. Required
    /// with `gate = "stochastic"`, refused otherwise.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub epsilon: Option<f64>,
}

/// The random stream the lab variation draws from (forked from `[sim] seed`).
const LAB_VARIATION_STREAM: u64 = 0x1AB;

/// `[sim]`: the simulated robot and human.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimConfig {
    /// Seed of every random draw in the simulation.
    pub seed: u64,
    /// Faults the simulated Create injects (see `pavlov::sim::faults::FaultSpec`), e.g. `none`, `soak`, or
    /// `drop=1e-4,flip=1e-4,hang=2e-5`.
    pub faults: String,
    /// Draw the start charge, start pose and floor friction from the seed (`pavlov::sim::variation`), as
    /// runs in a lab differ; off: every run starts the same.
    pub lab_variation: bool,
    /// `[sim.params]`: changes to the robot's physical parameters (robustness studies); empty by default.
    #[serde(default, skip_serializing_if = "SimParamsOverrides::is_empty")]
    pub params: SimParamsOverrides,
}

impl Default for SimConfig {
    fn default() -> Self {
        SimConfig {
            seed: 1,
            faults: "none".into(),
            lab_variation: false,
            params: SimParamsOverrides::default(),
        }
    }
}

impl SimConfig {
    /// The simulated robot's parameters for `model`: the model's, changed by `[sim.params]`, with this run's lab variation drawn from
    /// the seed when `lab_variation` is on.
    pub fn robot_params(&self, model: crate::oi::Model) -> crate::sim::params::SimParams {
        let params = self
            .params
            .apply(&crate::sim::params::SimParams::for_model(model));
        if self.lab_variation {
            // Its own stream, apart from everything else the seed drives.
            let mut rng = crate::rng::Rng::new(self.seed).fork(LAB_VARIATION_STREAM);
            crate::sim::variation::draw(&params, &mut rng)
        } else {
            params
        }
    }

    /// The parsed fault specification.
    pub fn fault_spec(&self) -> Result<crate::sim::faults::FaultSpec, ConfigError> {
        self.faults
            .parse()
            .map_err(|e: crate::sim::faults::FaultSpecError| invalid("sim.faults", e.to_string()))
    }
}

/// `[skeleton]`: the body-skeleton stream (OSC over UDP) of the gesture-command experiment.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SkeletonConfig {
    /// Whether `pavlov serve` listens for skeletons; unset means "when the stimulus is `left_elbow`".
    pub enabled: Option<bool>,
    /// UDP address to listen on (OSCeleton's default target is 127.0.0.1:7110).
    pub listen: String,
    /// What the streamer sends (see [`SkeletonFormat`]).
    pub format: SkeletonFormat,
    /// Swap left and right joint labels (mirrored streamers).
    pub swap_lr: bool,
    /// A joint older than this counts as missing, ms.
    pub max_joint_age_ms: u64,
}

/// The skeleton wire format and its coordinates.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum SkeletonFormat {
    /// OSCeleton `/joint ,sifff` in raw millimetres (`-xr`).
    #[default]
    OsceletonMm,
    /// OSCeleton `/joint ,sifff` in its default normalized coordinates, transformed back to millimetres.
    OsceletonNormalized,
    /// KinectV2-OSC `/bodies/<id>/joints/<JointType> ,fffs` in metres.
    KinectV2,
}

impl Default for SkeletonConfig {
    fn default() -> Self {
        SkeletonConfig {
            enabled: None,
            listen: "127.0.0.1:7110".into(),
            format: SkeletonFormat::OsceletonMm,
            swap_lr: false,
            max_joint_age_ms: 100,
        }
    }
}

impl SkeletonConfig {
    /// Whether the skeleton ingest runs under `stimulus`: `enabled` when set, else only for `left_elbow`.
    pub fn is_enabled(&self, stimulus: &StimulusSpec) -> bool {
        self.enabled
            .unwrap_or(matches!(stimulus, StimulusSpec::LeftElbow { .. }))
    }

    fn validate(&self) -> Result<(), ConfigError> {
        if self.listen.parse::<std::net::SocketAddr>().is_err() {
            return Err(invalid(
                "skeleton.listen",
                format!("`{}` is not an address like 127.0.0.1:7110", self.listen),
            ));
        }
        if !(1..=10_000).contains(&self.max_joint_age_ms) {
            return Err(invalid(
                "skeleton.max_joint_age_ms",
                "must be between 1 and 10000",
            ));
        }
        Ok(())
    }
}

/// `[checkpoint]`: where learned weights are saved.
///
/// Layout of `dir`: every server run writes its automatic checkpoints into `runs/<run id>/` (pruned to
/// `keep`), `save_weights` writes into `saved/` (never pruned, never overwritten, limited by `max_saves`
/// and `max_saves_mb`), and `--resume` searches every run (and the flat `checkpoint-<tick>.json` files
/// of earlier versions).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct CheckpointConfig {
    /// Directory that holds `runs/` (automatic checkpoints) and `saved/` (`save_weights`).
    pub dir: String,
    /// Seconds of ticks between periodic checkpoints (0: only at shutdown).
    pub every_s: u64,
    /// How many of this run's automatic checkpoints to keep (the oldest are deleted).
    pub keep: usize,
    /// Restore the newest valid checkpoint in `dir` before the first tick (`pavlov serve --resume`).
    pub resume: bool,
    /// Restore this checkpoint file instead of searching (`pavlov serve --resume-from FILE`).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub resume_from: Option<String>,
    /// Write periodic and shut-down checkpoints (`pavlov serve` turns this on; experiments leave it off).
    pub autosave: bool,
    /// The most files `saved/` may hold before `save_weights` is refused.
    pub max_saves: usize,
    /// The most MiB `saved/` may hold, the new save included, before `save_weights` is refused.
    pub max_saves_mb: u64,
}

impl Default for CheckpointConfig {
    fn default() -> Self {
        CheckpointConfig {
            dir: "weights".into(),
            every_s: 60,
            keep: 5,
            resume: false,
            resume_from: None,
            autosave: false,
            max_saves: 100,
            max_saves_mb: 256,
        }
    }
}

/// The whole configuration file.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Config {
    /// `[robot]`.
    #[serde(default)]
    pub robot: RobotConfig,
    /// `[tick]`.
    #[serde(default)]
    pub tick: TickConfig,
    /// `[safety]`.
    #[serde(default)]
    pub safety: SafetyConfig,
    /// `[link]`.
    #[serde(default)]
    pub link: LinkConfig,
    /// `[control]`.
    pub control: ControlConfig,
    /// `[[predictions]]`, learned side by side.
    pub predictions: Vec<PredictionSpec>,
    /// `[[rules]]`: the rule table of Pavlovian control (empty: the paper's single rule, see
    /// [`Config::rule_table`]).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub rules: Vec<RuleSpec>,
    /// `[sim]`.
    #[serde(default)]
    pub sim: SimConfig,
    /// `[dashboard]`.
    #[serde(default)]
    pub dashboard: DashboardConfig,
    /// `[checkpoint]`.
    #[serde(default)]
    pub checkpoint: CheckpointConfig,
    /// `[skeleton]`.
    #[serde(default)]
    pub skeleton: SkeletonConfig,
    /// `[horde]`.
    #[serde(default, skip_serializing_if = "HordeConfig::is_off")]
    pub horde: HordeConfig,
    /// `[zenoh]` (used by `pavlov serve --zenoh`).
    #[serde(default, skip_serializing_if = "ZenohConfig::is_default")]
    pub zenoh: ZenohConfig,
}

/// What every artifact (a recording, a summary, a log line, what a client without the token receives)
/// shows in place of a secret.
pub const REDACTED: &str = "<redacted>";

impl Config {
    /// This configuration with its secrets replaced by [`REDACTED`]: what may leave the process (a
    /// recording, a Foxglove or Zenoh client, an operator's `hello`). The dashboard's token is the only
    /// secret a configuration holds; an absent or empty token stays as it is (there is nothing to hide,
    /// and a reader can still tell that none was set).
    pub fn redacted(&self) -> Config {
        let mut config = self.clone();
        if config.dashboard.token().is_some() {
            config.dashboard.token = Some(REDACTED.to_string());
        }
        config
    }

    /// Validates a configuration read back from an artifact (a recording): everything [`Config::validate`]
    /// checks but `[dashboard]`, which only a running server uses and whose token an artifact holds
    /// redacted (`<redacted>` is shorter than a public bind's minimum).
    pub fn validate_recorded(&self) -> Result<(), ConfigError> {
        let mut config = self.clone();
        config.dashboard = DashboardConfig::default();
        config.validate()
    }

    /// The signals predictions and the Horde may read: this robot model's observation dimensions,
    /// [`ELBOW_INPUTS`], and the configured stimulus.
    pub fn signal_names(&self) -> crate::learn::SignalNames {
        crate::learn::SignalNames::for_layout(
            &crate::obs::ObsLayout::for_model(self.robot.model),
            &ELBOW_INPUTS,
            &[self.control.stimulus.name()],
        )
    }

    /// Parses and validates a TOML document.
    pub fn from_toml(text: &str) -> Result<Config, ConfigError> {
        let cfg: Config = toml::from_str(text).map_err(|e| ConfigError::Parse(e.to_string()))?;
        cfg.validate()?;
        Ok(cfg)
    }

    /// Checks every value that types alone cannot.
    pub fn validate(&self) -> Result<(), ConfigError> {
        self.tick.validate()?;
        // Safety timeouts, policy speeds, every prediction's bounds, the client queue.
        bounds::check(self)?;
        let model = self.robot.model;
        for (i, &id) in self.robot.stream.iter().enumerate() {
            if !crate::oi::packets::available_on(id, model) {
                return Err(invalid(
                    format!("robot.stream[{i}]"),
                    format!("packet {id} does not exist on the {model}"),
                ));
            }
        }
        crate::oi::frame::check_stream_budget(&self.robot.stream_ids(), model.baud())
            .map_err(|e| invalid("robot.stream", e.to_string()))?;
        match self.control.stimulus {
            StimulusSpec::Stall { above, max } => {
                if max == 0 || above >= max {
                    return Err(invalid(
                        "control.stimulus",
                        format!("need 0 <= above < max, got above = {above}, max = {max}"),
                    ));
                }
            }
            StimulusSpec::LeftElbow { below_deg } => {
                if !(below_deg > 0.0 && below_deg < 180.0) {
                    return Err(invalid(
                        "control.stimulus.below_deg",
                        "must be between 0 and 180 degrees",
                    ));
                }
            }
        }
        self.skeleton.validate()?;
        self.horde.validate(&self.signal_names())?;
        self.link.validate()?;
        self.zenoh.validate()?;
        self.sim.fault_spec()?;
        self.sim.params.validate()?;
        if self.checkpoint.dir.trim().is_empty() {
            return Err(invalid("checkpoint.dir", "must name a directory"));
        }
        if self.checkpoint.keep == 0 {
            return Err(invalid(
                "checkpoint.keep",
                "must keep at least 1 checkpoint",
            ));
        }
        if self.checkpoint.max_saves == 0 {
            return Err(invalid("checkpoint.max_saves", "must be at least 1"));
        }
        if !(1..=1_048_576).contains(&self.checkpoint.max_saves_mb) {
            return Err(invalid(
                "checkpoint.max_saves_mb",
                "must be between 1 and 1048576 (1 TiB)",
            ));
        }
        if self
            .checkpoint
            .resume_from
            .as_deref()
            .is_some_and(|f| f.trim().is_empty())
        {
            return Err(invalid("checkpoint.resume_from", "must name a file"));
        }
        self.dashboard.validate()?;
        if self.predictions.is_empty() {
            return Err(invalid("predictions", "at least one prediction is needed"));
        }
        for (i, p) in self.predictions.iter().enumerate() {
            if self.predictions[..i].iter().any(|q| q.name == p.name) {
                return Err(invalid(
                    format!("predictions[{i}].name"),
                    format!("`{}` is used twice", p.name),
                ));
            }
        }
        if !self
            .predictions
            .iter()
            .any(|p| p.name == self.control.gate_prediction)
        {
            return Err(invalid(
                "control.gate_prediction",
                format!("no prediction is named `{}`", self.control.gate_prediction),
            ));
        }
        self.check_rules()?;
        self.check_gate()?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    #[test]
    fn lab_variation_draws_the_robot_from_the_seed_only_when_asked() {
        let mut sim = SimConfig::default();
        let m = crate::oi::Model::Create1;
        assert_eq!(
            sim.robot_params(m),
            crate::sim::params::SimParams::for_model(m)
        );
        sim.lab_variation = true;
        let a = sim.robot_params(m);
        assert_ne!(a, crate::sim::params::SimParams::for_model(m));
        assert_eq!(a, sim.robot_params(m), "the same seed draws the same run");
        sim.seed = 2;
        assert_ne!(a, sim.robot_params(m), "another seed, another run");
        let stall = include_str!("../../config/stall.toml");
        assert!(Config::from_toml(stall).unwrap().sim.lab_variation);
        let bad = stall.replace("lab_variation = true", "lab_variation = 3");
        assert!(Config::from_toml(&bad).is_err());
    }

    use super::*;

    const STALL: &str = include_str!("../../config/stall.toml");
    const INTERACTION: &str = include_str!("../../config/interaction.toml");

    #[test]
    fn shipped_configurations_load_with_the_papers_parameters() {
        let s = Config::from_toml(STALL).unwrap();
        assert_eq!(s.robot.model, Model::Create1);
        assert_eq!(s.predictions[0].lambda, 0.5);
        assert!((s.predictions[0].alpha - 1.0 / 44.0).abs() < 1e-12);
        assert_eq!(s.predictions[0].threshold_value(), 0.5);
        let i = Config::from_toml(INTERACTION).unwrap();
        let p = &i.predictions[0];
        assert_eq!((p.lambda, p.initial_weight, p.tau), (0.8, -1.0, 25.0));
        assert!((p.threshold_value() - 0.96f64.powi(15)).abs() < 1e-12);
    }

    #[test]
    fn every_example_configuration_loads() {
        let dir = concat!(env!("CARGO_MANIFEST_DIR"), "/config");
        let mut loaded = Vec::new();
        for entry in std::fs::read_dir(dir).unwrap() {
            let path = entry.unwrap().path();
            if path.extension().is_some_and(|e| e == "toml") {
                let text = std::fs::read_to_string(&path).unwrap();
                if let Err(e) = Config::from_toml(&text) {
                    panic!("{}: {e}", path.display());
                }
                loaded.push(path.file_name().unwrap().to_string_lossy().into_owned());
            }
        }
        loaded.sort();
        for name in ["rules.toml", "stall.toml", "interaction.toml", "horde.toml"] {
            assert!(
                loaded.iter().any(|l| l == name),
                "{name} not among {loaded:?}"
            );
        }
    }

    #[test]
    fn an_unknown_key_is_named() {
        let text = STALL.replace("period_ms = 20", "period_ms = 20\nperoid = 3");
        let e = Config::from_toml(&text).unwrap_err().to_string();
        assert!(e.contains("peroid"), "{e}");
    }

    #[test]
    fn bad_values_name_their_key() {
        let cases = [
            ("period_ms = 20", "period_ms = 0", "tick.period_ms"),
            ("tau = 25.0", "tau = 0.5", "predictions[0]"),
            (
                "gate_prediction = \"stall\"",
                "gate_prediction = \"nope\"",
                "control.gate_prediction",
            ),
            ("stream = [6]", "stream = [6, 6]", "robot.stream"),
            ("stream = [6]", "stream = [50]", "robot.stream[0]"),
            (
                "above = 3, max = 5",
                "above = 5, max = 5",
                "control.stimulus",
            ),
        ];
        for (from, to, key) in cases {
            let text = STALL.replace(from, to);
            assert_ne!(text, STALL, "{from} not found");
            match Config::from_toml(&text) {
                Err(ConfigError::Invalid { key: k, .. }) => {
                    assert!(k.starts_with(key), "{k} vs {key}")
                }
                other => panic!("{to}: expected an invalid {key}, got {other:?}"),
            }
        }
    }

    #[test]
    fn a_public_bind_needs_a_token() {
        let text = format!("{STALL}\n[dashboard]\nbind = \"0.0.0.0:8080\"\n");
        match Config::from_toml(&text) {
            Err(ConfigError::Invalid { key, .. }) => assert_eq!(key, "dashboard.token"),
            other => panic!("{other:?}"),
        }
        let ok = format!(
            "{STALL}\n[dashboard]\nbind = \"0.0.0.0:8080\"\ntoken = \"0123456789abcdef\"\n"
        );
        assert!(Config::from_toml(&ok).is_ok());
    }

    #[test]
    fn careless_names_and_timescales_are_refused_by_key() {
        let long = "r".repeat(1 << 20);
        let text = format!(
            "{STALL}\n[[rules]]\nname = \"{long}\"\nprediction = \"stall\"\nresponse = {{ kind = \"stop\" }}\npriority = 1\n"
        );
        match Config::from_toml(&text) {
            Err(ConfigError::Invalid { key, message }) => {
                assert_eq!(key, "rules[0].name");
                assert!(message.contains("at most 64"), "{message}");
            }
            other => panic!("{other:?}"),
        }
        let tau = STALL.replace("tau = 25.0", "tau = 1e300");
        assert!(
            Config::from_toml(&tau).is_err_and(|e| e.to_string().contains("at most 1e6")),
            "tau = 1e300 is refused"
        );
    }

    #[test]
    fn redacted_hides_the_token_and_nothing_else() {
        let with = format!(
            "{STALL}\n[dashboard]\nbind = \"0.0.0.0:8080\"\ntoken = \"0123456789abcdef\"\n"
        );
        let config = Config::from_toml(&with).expect("valid");
        let redacted = config.redacted();
        assert_eq!(redacted.dashboard.token.as_deref(), Some(REDACTED));
        let mut back = redacted.clone();
        back.dashboard.token = config.dashboard.token.clone();
        assert_eq!(back, config, "only the token differs");
        let without = Config::from_toml(STALL).expect("valid");
        assert_eq!(without.redacted(), without, "no token: nothing to hide");
        // A public bind's redacted token is too short for a server, but a recording of it still reads.
        assert!(redacted.validate().is_err());
        assert_eq!(redacted.validate_recorded(), Ok(()));
    }
}

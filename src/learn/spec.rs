//! [`PredictionSpec`]: everything that defines one prediction (the question, the features, the learning
//! parameters), as plain data that deserialises from TOML.
//!
//! The question follows the paper: the cumulant is the indicator of a stimulus event E, `R_t = I{E}`,
//! and the discount is `γ_t = (1 − I{E})(1 − 1/τ)`, so the prediction terminates on E or after τ steps
//! in expectation. Example (the interaction experiment):
//!
//! ```toml
//! name = "command"
//! tau = 25.0
//! lambda = 0.8
//! alpha = 0.02
//! sigma = "logistic"
//! initial_weight = -1.0
//! threshold = { steps = 15 }
//! cumulant = { stimulus = "left_elbow_command" }
//! [features]
//! kind = "pairs"
//! tiles = 10
//! pairs = [
//!   { x = "left_elbow", y = "left_elbow_avg", offset = 0.0 },
//!   { x = "left_elbow", y = "left_elbow_avg", offset = 0.5 },
//!   { x = "right_elbow", y = "right_elbow_avg", offset = 0.0 },
//!   { x = "right_elbow", y = "right_elbow_avg", offset = 0.5 },
//!   { x = "left_elbow", y = "right_elbow", offset = 0.0 },
//! ]
//! ```

use serde::{Deserialize, Serialize};

use super::bounds::{
    MAX_FEATURES, MAX_TILES_PER_DIMENSION, MAX_TILINGS_PER_DIMENSION, ParamBounds,
    check_initial_value, check_tau, out_of_bounds,
};
use super::td::TdParams;
use super::{LearnError, Sigma};

/// The threshold θ of the mixing function `f_E(v) = I{E ∨ v > θ}`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Threshold {
    /// A fixed θ (the stall experiment used 0.5).
    Fixed(f64),
    /// θ = (1 − 1/τ)^K for a response that takes K steps (the interaction experiment used K = 15).
    Steps(u32),
}

/// Which learning algorithm updates a prediction.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum LearnerKind {
    /// The paper's on-policy TD(λ) ([`super::td`]): the prediction is about the behaviour actually run
    /// (`learner = "paper"`, or `"td"`).
    #[default]
    #[serde(alias = "paper")]
    Td,
    /// Off-policy GTD(λ) ([`super::gtd`]): the prediction is about the declared `target_policy`,
    /// learned from the behaviour actually run with importance sampling ratios.
    Gtd,
    /// The cross-entropy gradient of the logistic output: the paper's update without σ′ in the trace
    /// ([`super::named::xent`]).
    Xent,
    /// The paper's TD(λ) with σ = identity ([`super::named::linear`]).
    Linear,
    /// True online TD(λ) with dutch traces, linear ([`super::named::true_online`]).
    TrueOnline,
    /// Autostep step sizes per weight on the `xent` update ([`super::named::autostep`]).
    Autostep,
}

impl LearnerKind {
    pub(crate) fn is_td(&self) -> bool {
        *self == LearnerKind::Td
    }

    /// Every learner, in the order the tables list them.
    pub const ALL: [LearnerKind; 6] = [
        LearnerKind::Td,
        LearnerKind::Xent,
        LearnerKind::Linear,
        LearnerKind::TrueOnline,
        LearnerKind::Autostep,
        LearnerKind::Gtd,
    ];

    /// The learner's name as the configuration, the tables and the dashboard show it (`"paper"` for the
    /// paper's TD(λ)).
    pub fn name(self) -> &'static str {
        match self {
            LearnerKind::Td => "paper",
            LearnerKind::Gtd => "gtd",
            LearnerKind::Xent => "xent",
            LearnerKind::Linear => "linear",
            LearnerKind::TrueOnline => "true_online",
            LearnerKind::Autostep => "autostep",
        }
    }

    /// The learner named `name` (as in the configuration: `"paper"` or `"td"`, `"xent"`, …).
    pub fn from_name(name: &str) -> Option<Self> {
        match name {
            "td" => Some(LearnerKind::Td),
            _ => Self::ALL.into_iter().find(|k| k.name() == name),
        }
    }
}

/// The policy an off-policy prediction is about.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum TargetPolicy {
    /// "The default policy π continues": the prediction of the cumulant were π followed from now on,
    /// whatever response actually runs. With the deterministic policies here, ρ_t = 1 on a tick whose
    /// command was π's and 0 otherwise (see `crate::agent::learning`).
    Default,
}

/// Which signal the prediction is about.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Cumulant {
    /// The indicator of the named stimulus event: R = I{E}, and E terminates the prediction.
    Stimulus(String),
}

/// Which tile coder, over which named input signals.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum FeatureSpec {
    /// `tilings` tilings (default 1) of `tiles` tiles per input, evenly offset: every observation
    /// dimension (if `all_obs`), then the named `inputs` (stall experiment: `all_obs = true, tiles = 10`).
    OneDim {
        #[serde(default)]
        all_obs: bool,
        #[serde(default)]
        inputs: Vec<String>,
        tiles: usize,
        #[serde(default = "one_tiling", skip_serializing_if = "is_one")]
        tilings: usize,
    },
    /// One `tiles × tiles` tiling per pair of named inputs, each with its own offset.
    Pairs { pairs: Vec<PairSpec>, tiles: usize },
}

fn one_tiling() -> usize {
    1
}

fn is_one(n: &usize) -> bool {
    *n == 1
}

/// One 2-D tiling over inputs `x` and `y`, shifted by `offset` (a fraction of a tile, in `[0, 1)`).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PairSpec {
    pub x: String,
    pub y: String,
    #[serde(default)]
    pub offset: f64,
}

/// One prediction: question (cumulant, τ), features, and learning parameters.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PredictionSpec {
    /// A unique name (used in records, the dashboard and runtime commands).
    pub name: String,
    /// The timescale in ticks (> 1): γ = 1 − 1/τ while the stimulus is absent.
    pub tau: f64,
    /// Bootstrapping parameter λ in `[0, 1]`.
    pub lambda: f64,
    /// Step size α > 0.
    pub alpha: f64,
    /// The output nonlinearity.
    pub sigma: Sigma,
    /// The initial value of every weight (default 0).
    #[serde(default)]
    pub initial_weight: f64,
    /// The threshold of the Pavlovian mixing function.
    pub threshold: Threshold,
    /// The tile coder and its inputs.
    pub features: FeatureSpec,
    /// The signal being predicted.
    pub cumulant: Cumulant,
    /// The learning algorithm (default: the paper's TD(λ)).
    #[serde(default, skip_serializing_if = "LearnerKind::is_td")]
    pub learner: LearnerKind,
    /// The target policy of an off-policy (`learner = "gtd"`) prediction; required there, refused
    /// elsewhere.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub target_policy: Option<TargetPolicy>,
    /// GTD(λ)'s secondary step size β (> 0, β·‖x‖² ≤ 1); required with `learner = "gtd"`, refused
    /// elsewhere.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub beta: Option<f64>,
}

impl PredictionSpec {
    /// `1 − 1/τ`, the discount while the stimulus is absent.
    pub fn continuation(&self) -> f64 {
        1.0 - 1.0 / self.tau
    }

    /// γ_t = (1 − I{E})(1 − 1/τ).
    pub fn gamma(&self, stimulus: bool) -> f64 {
        if stimulus { 0.0 } else { self.continuation() }
    }

    /// R_t = I{E}.
    pub fn reward(&self, stimulus: bool) -> f64 {
        if stimulus { 1.0 } else { 0.0 }
    }

    /// θ: the fixed value, or (1 − 1/τ)^K.
    pub fn threshold_value(&self) -> f64 {
        match self.threshold {
            Threshold::Fixed(theta) => theta,
            Threshold::Steps(k) => self.continuation().powf(f64::from(k)),
        }
    }

    /// The TD(λ) parameters.
    pub fn td_params(&self) -> TdParams {
        TdParams {
            alpha: self.alpha,
            lambda: self.lambda,
            sigma: self.sigma,
            initial_weight: self.initial_weight,
        }
    }

    /// Checks the scalar fields (name, τ, α > 0, λ, initial weight, threshold) that need no feature
    /// count; [`PredictionSpec::bounds`] checks everything.
    pub fn validate(&self) -> Result<(), LearnError> {
        let name = self.name.as_str();
        if name.is_empty() {
            return Err(LearnError::EmptyName);
        }
        super::bounds::check_name_length(name)?;
        check_tau(name, self.tau)?;
        self.td_params().validate(name)?;
        check_threshold(name, self.threshold)?;
        self.check_learner()
    }

    /// The learner's keys: `learner = "gtd"` needs `target_policy` and `beta` (> 0) and σ = identity
    /// (only linear GTD(λ) is implemented, [`super::gtd`]); `"linear"` and `"true_online"` need σ =
    /// identity; the on-policy learners take neither off-policy key.
    fn check_learner(&self) -> Result<(), LearnError> {
        let name = self.name.as_str();
        let refuse = |field: &str, value: String, bound: &str| LearnError::OutOfBounds {
            name: name.to_string(),
            field: field.to_string(),
            value,
            bound: bound.to_string(),
        };
        match self.learner {
            LearnerKind::Linear | LearnerKind::TrueOnline => {
                super::named::linear::check_identity(name, self.learner.name(), self.sigma)?;
                self.check_on_policy()
            }
            LearnerKind::Td | LearnerKind::Xent | LearnerKind::Autostep => self.check_on_policy(),
            LearnerKind::Gtd => {
                if self.target_policy.is_none() {
                    return Err(refuse(
                        "target_policy",
                        "(absent)".into(),
                        "is required with learner = \"gtd\" (e.g. target_policy = \"default\")",
                    ));
                }
                let Some(beta) = self.beta else {
                    return Err(refuse(
                        "beta",
                        "(absent)".into(),
                        "is required with learner = \"gtd\" (the secondary step size, > 0 and β·‖x‖² ≤ 1)",
                    ));
                };
                super::gtd::check_beta_positive(name, beta)?;
                if self.sigma != Sigma::Identity {
                    return Err(refuse(
                        "sigma",
                        "\"logistic\"".into(),
                        "is not supported with learner = \"gtd\" (only linear GTD(λ) is implemented; \
                         the convergent nonlinear form needs a Hessian term): use sigma = \"identity\"",
                    ));
                }
                Ok(())
            }
        }
    }

    /// An on-policy learner takes neither `target_policy` nor `beta`.
    fn check_on_policy(&self) -> Result<(), LearnError> {
        let refuse = |field: &str, value: String, bound: &str| LearnError::OutOfBounds {
            name: self.name.clone(),
            field: field.to_string(),
            value,
            bound: bound.to_string(),
        };
        if let Some(t) = self.target_policy {
            return Err(refuse(
                "target_policy",
                format!("{t:?}").to_lowercase(),
                "is only for learner = \"gtd\" (an on-policy TD(λ) prediction is about the behaviour run)",
            ));
        }
        if let Some(b) = self.beta {
            return Err(refuse(
                "beta",
                format!("{b:?}"),
                "is only for learner = \"gtd\" (TD(λ) has no secondary weights)",
            ));
        }
        Ok(())
    }

    /// The GTD(λ) parameters, for a `learner = "gtd"` prediction.
    pub fn gtd_params(&self) -> Option<super::gtd::GtdParams> {
        (self.learner == LearnerKind::Gtd).then(|| super::gtd::GtdParams {
            alpha: self.alpha,
            beta: self.beta.unwrap_or(f64::NAN),
            lambda: self.lambda,
            initial_weight: self.initial_weight,
        })
    }

    /// Checks every field against its bound (`super::bounds`) for a robot with `obs_dims` observation
    /// dimensions, without allocating anything: the scalars, the tile count and the feature count, the
    /// step size α·‖x‖² ≤ 1 with ‖x‖² the number of tilings, and a finite initial prediction w₀·‖x‖².
    /// Returns the bounds for runtime changes.
    pub fn bounds(&self, obs_dims: usize) -> Result<ParamBounds, LearnError> {
        self.validate()?;
        let bounds = feature_bounds(&self.name, &self.features, obs_dims)?;
        bounds.check_alpha(&self.name, self.alpha)?;
        if let Some(beta) = self.beta {
            super::gtd::check_beta(&self.name, beta, bounds.active_features)?;
        }
        check_initial_value(&self.name, self.initial_weight, bounds.active_features)?;
        Ok(bounds)
    }
}

/// A fixed threshold θ finite (a bound of [`super::bounds`], kept beside the type it checks) (a number of steps K always gives a finite θ).
pub fn check_threshold(name: &str, threshold: Threshold) -> Result<(), LearnError> {
    match threshold {
        Threshold::Fixed(value) if !value.is_finite() => Err(out_of_bounds(
            name,
            "threshold",
            value,
            "is not finite".into(),
        )),
        _ => Ok(()),
    }
}

/// The sizes of `features` over `obs_dims` observation dimensions, checked against the size bounds
/// without allocating anything: tiles in `1..=MAX_TILES_PER_DIMENSION`, at least one tiling, and at most
/// [`MAX_FEATURES`] features.
pub fn feature_bounds(
    name: &str,
    features: &FeatureSpec,
    obs_dims: usize,
) -> Result<ParamBounds, LearnError> {
    let (tiles, tilings, per_tiling) = match features {
        FeatureSpec::OneDim {
            all_obs,
            inputs,
            tiles,
            tilings,
        } => {
            if !(1..=MAX_TILINGS_PER_DIMENSION).contains(tilings) {
                return Err(LearnError::OutOfBounds {
                    name: name.to_string(),
                    field: "features.tilings".into(),
                    value: tilings.to_string(),
                    bound: format!("is outside 1..={MAX_TILINGS_PER_DIMENSION} per dimension"),
                });
            }
            let dims = if *all_obs { obs_dims } else { 0 };
            (
                *tiles,
                dims.saturating_add(inputs.len()).saturating_mul(*tilings),
                Some(*tiles),
            )
        }
        FeatureSpec::Pairs { pairs, tiles } => {
            if let Some((k, p)) = pairs
                .iter()
                .enumerate()
                .find(|(_, p)| !(0.0..1.0).contains(&p.offset))
            {
                return Err(out_of_bounds(
                    name,
                    &format!("features.pairs[{k}].offset"),
                    p.offset,
                    "is outside [0, 1) of a tile width".into(),
                ));
            }
            (*tiles, pairs.len(), tiles.checked_mul(*tiles))
        }
    };
    if !(1..=MAX_TILES_PER_DIMENSION).contains(&tiles) {
        return Err(LearnError::OutOfBounds {
            name: name.to_string(),
            field: "features.tiles".into(),
            value: tiles.to_string(),
            bound: format!("is outside 1..={MAX_TILES_PER_DIMENSION} tiles per dimension"),
        });
    }
    if tilings == 0 {
        return Err(LearnError::NoTilings);
    }
    let total = per_tiling.and_then(|b| b.checked_mul(tilings));
    match total {
        Some(n) if n <= MAX_FEATURES => Ok(ParamBounds::new(tilings, n)),
        _ => Err(LearnError::OutOfBounds {
            name: name.to_string(),
            field: "features".into(),
            value: format!(
                "{tilings} tilings of {} tiles",
                per_tiling.map_or_else(|| "too many".to_string(), |b| b.to_string())
            ),
            bound: format!(
                "exceed {MAX_FEATURES} features (the weights and traces are dense f64 vectors, \
                 walked on every tick)"
            ),
        }),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const COMMAND: &str = r#"
        name = "command"
        tau = 25.0
        lambda = 0.8
        alpha = 0.02
        sigma = "logistic"
        initial_weight = -1.0
        threshold = { steps = 15 }
        cumulant = { stimulus = "left_elbow_command" }
        [features]
        kind = "pairs"
        tiles = 10
        pairs = [
          { x = "left_elbow", y = "left_elbow_avg", offset = 0.0 },
          { x = "left_elbow", y = "left_elbow_avg", offset = 0.5 },
          { x = "right_elbow", y = "right_elbow_avg" },
          { x = "right_elbow", y = "right_elbow_avg", offset = 0.5 },
          { x = "left_elbow", y = "right_elbow", offset = 0.0 },
        ]
    "#;

    const STALL: &str = r#"
        name = "stall"
        tau = 25.0
        lambda = 0.5
        alpha = 0.022727272727272728
        sigma = "identity"
        threshold = { fixed = 0.5 }
        cumulant = { stimulus = "stall" }
        features = { kind = "one_dim", all_obs = true, tiles = 10 }
    "#;

    #[test]
    fn the_papers_two_predictions_parse_from_toml() {
        let command: PredictionSpec = toml::from_str(COMMAND).unwrap();
        command.validate().unwrap();
        assert_eq!(command.sigma, Sigma::Logistic);
        assert_eq!(command.initial_weight, -1.0);
        match &command.features {
            FeatureSpec::Pairs { pairs, tiles } => {
                assert_eq!((pairs.len(), *tiles), (5, 10));
                assert_eq!(pairs[2].offset, 0.0);
                assert_eq!(pairs[3].offset, 0.5);
            }
            other => panic!("{other:?}"),
        }
        // (1 - 1/25)^15 = 0.96^15
        assert!((command.threshold_value() - 0.542_086_379_860_908_8).abs() < 1e-12);

        let stall: PredictionSpec = toml::from_str(STALL).unwrap();
        stall.validate().unwrap();
        assert_eq!(stall.initial_weight, 0.0);
        assert_eq!(stall.threshold_value(), 0.5);
        assert_eq!(stall.cumulant, Cumulant::Stimulus("stall".into()));
    }

    #[test]
    fn unknown_keys_are_rejected() {
        let typo = STALL.replace("lambda", "lamda");
        assert!(toml::from_str::<PredictionSpec>(&typo).is_err());
        let extra = STALL.replace("tiles = 10", "tiles = 10, hashing = true");
        assert!(toml::from_str::<PredictionSpec>(&extra).is_err());
        let kind = STALL.replace("one_dim", "three_dim");
        assert!(toml::from_str::<PredictionSpec>(&kind).is_err());
    }

    #[test]
    fn gamma_and_reward_follow_the_stimulus() {
        let stall: PredictionSpec = toml::from_str(STALL).unwrap();
        assert_eq!(stall.gamma(false), 0.96);
        assert_eq!(stall.gamma(true), 0.0);
        assert_eq!(stall.reward(true), 1.0);
        assert_eq!(stall.reward(false), 0.0);
    }

    #[test]
    fn invalid_scalars_are_named() {
        let base: PredictionSpec = toml::from_str(STALL).unwrap();
        let with = |f: &dyn Fn(&mut PredictionSpec)| {
            let mut s = base.clone();
            f(&mut s);
            s.validate()
        };
        let field = |r: Result<(), LearnError>| match r {
            Err(LearnError::OutOfBounds { field, .. }) => field,
            other => panic!("{other:?}"),
        };
        assert_eq!(field(with(&|s| s.tau = 1.0)), "tau");
        assert_eq!(field(with(&|s| s.tau = f64::INFINITY)), "tau");
        assert_eq!(field(with(&|s| s.alpha = 0.0)), "alpha");
        assert_eq!(field(with(&|s| s.alpha = f64::NAN)), "alpha");
        assert_eq!(field(with(&|s| s.lambda = 1.01)), "lambda");
        assert_eq!(field(with(&|s| s.lambda = -0.1)), "lambda");
        assert_eq!(
            field(with(&|s| s.initial_weight = f64::NAN)),
            "initial_weight"
        );
        assert_eq!(
            field(with(&|s| s.threshold = Threshold::Fixed(f64::NAN))),
            "threshold"
        );
        assert_eq!(with(&|s| s.name.clear()), Err(LearnError::EmptyName));
        let message = with(&|s| s.tau = 0.5).unwrap_err().to_string();
        assert!(
            message.contains("stall") && message.contains("tau"),
            "{message}"
        );
    }

    #[test]
    fn off_policy_keys_are_checked_with_their_names() {
        let gtd =
            format!("{STALL}\nlearner = \"gtd\"\ntarget_policy = \"default\"\nbeta = 0.002\n");
        let spec: PredictionSpec = toml::from_str(&gtd).unwrap();
        spec.bounds(44).unwrap();
        assert_eq!(spec.learner, LearnerKind::Gtd);
        assert_eq!(spec.target_policy, Some(TargetPolicy::Default));
        assert_eq!(spec.gtd_params().unwrap().beta, 0.002);
        let field = |text: &str| match toml::from_str::<PredictionSpec>(text).unwrap().bounds(44) {
            Err(LearnError::OutOfBounds { field, .. }) => field,
            other => panic!("{other:?}"),
        };
        assert_eq!(
            field(&gtd.replace("target_policy = \"default\"\n", "")),
            "target_policy"
        );
        assert_eq!(field(&gtd.replace("beta = 0.002\n", "")), "beta");
        assert_eq!(field(&gtd.replace("beta = 0.002", "beta = 0.0")), "beta");
        assert_eq!(field(&gtd.replace("beta = 0.002", "beta = 0.5")), "beta");
        assert_eq!(field(&gtd.replace("\"identity\"", "\"logistic\"")), "sigma");
        let td_with_beta = format!("{STALL}\nbeta = 0.002\n");
        assert_eq!(field(&td_with_beta), "beta");
        let td_with_target = format!("{STALL}\ntarget_policy = \"default\"\n");
        assert_eq!(field(&td_with_target), "target_policy");
        let e = toml::from_str::<PredictionSpec>(&gtd.replace("beta = 0.002", "beta = 0.5"))
            .unwrap()
            .bounds(44)
            .unwrap_err()
            .to_string();
        assert_eq!(
            e,
            "prediction `stall`: beta = 0.5 exceeds 1/44 = 0.0227 (β·‖x‖² ≤ 1 with 44 active features)"
        );
        assert!(
            toml::from_str::<PredictionSpec>(&gtd.replace("\"default\"", "\"greedy\"")).is_err()
        );
        assert!(toml::from_str::<PredictionSpec>(&gtd.replace("\"gtd\"", "\"q\"")).is_err());
        // An on-policy spec serialises without the new keys (older readers keep working).
        let on: PredictionSpec = toml::from_str(STALL).unwrap();
        let text = toml::to_string(&on).unwrap();
        assert!(
            !text.contains("learner") && !text.contains("beta"),
            "{text}"
        );
    }

    #[test]
    fn the_step_size_is_bounded_by_the_feature_construction() {
        let stall: PredictionSpec = toml::from_str(STALL).unwrap();
        assert_eq!(stall.bounds(44).unwrap().active_features, 44);
        let mut fast = stall.clone();
        fast.alpha = 1.0;
        fast.validate().unwrap();
        let e = fast.bounds(44).unwrap_err().to_string();
        assert!(e.contains("exceeds 1/44"), "{e}");
        // The same α fits a construction with fewer active features.
        fast.alpha = 0.1;
        assert!(fast.bounds(44).is_err());
        assert!(fast.bounds(10).is_ok());
        let command: PredictionSpec = toml::from_str(COMMAND).unwrap();
        assert_eq!(command.bounds(44).unwrap().max_alpha, 0.2);
        // A finite initial weight whose prediction over 44 features overflows.
        let mut huge = stall;
        huge.initial_weight = 1e307;
        match huge.bounds(44) {
            Err(LearnError::OutOfBounds { field, bound, .. }) => {
                assert_eq!(field, "initial_weight");
                assert!(bound.contains("44 active features"), "{bound}");
            }
            other => panic!("{other:?}"),
        }
        huge.initial_weight = -1e300;
        huge.bounds(44).unwrap();
    }

    #[test]
    fn a_threshold_must_be_finite() {
        match check_threshold("p", Threshold::Fixed(f64::INFINITY)) {
            Err(LearnError::OutOfBounds { field, .. }) => assert_eq!(field, "threshold"),
            other => panic!("{other:?}"),
        }
        check_threshold("p", Threshold::Steps(u32::MAX)).unwrap();
    }

    #[test]
    fn feature_sizes_are_bounded_before_allocation() {
        let one_dim = |tiles| FeatureSpec::OneDim {
            all_obs: true,
            inputs: vec!["left_elbow".into()],
            tiles,
            tilings: 1,
        };
        assert_eq!(
            feature_bounds("stall", &one_dim(10), 44).unwrap(),
            ParamBounds::new(45, 450)
        );
        for tiles in [0, 1001, 100_000_000, usize::MAX] {
            match feature_bounds("stall", &one_dim(tiles), 44) {
                Err(LearnError::OutOfBounds { field, bound, .. }) => {
                    assert_eq!(field, "features.tiles");
                    assert!(bound.contains("1..=1000"), "{bound}");
                }
                other => panic!("{tiles}: {other:?}"),
            }
        }
        let pair = PairSpec {
            x: "a".into(),
            y: "b".into(),
            offset: 0.0,
        };
        let pairs = |n, tiles| FeatureSpec::Pairs {
            pairs: vec![pair.clone(); n],
            tiles,
        };
        assert_eq!(
            feature_bounds("command", &pairs(5, 10), 44).unwrap(),
            ParamBounds::new(5, 500)
        );
        assert!(feature_bounds("command", &pairs(1, 1000), 44).is_ok());
        match feature_bounds("command", &pairs(2, 1000), 44) {
            Err(e @ LearnError::OutOfBounds { .. }) => {
                let text = e.to_string();
                assert!(
                    text.contains("features = 2 tilings") && text.contains("1000000"),
                    "{text}"
                )
            }
            other => panic!("{other:?}"),
        }
        let mut shifted = pairs(3, 10);
        if let FeatureSpec::Pairs { pairs, .. } = &mut shifted {
            pairs[2].offset = 1.0;
        }
        match feature_bounds("command", &shifted, 44) {
            Err(LearnError::OutOfBounds { field, .. }) => {
                assert_eq!(field, "features.pairs[2].offset")
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(
            feature_bounds("p", &pairs(0, 10), 44),
            Err(LearnError::NoTilings)
        );
    }
}

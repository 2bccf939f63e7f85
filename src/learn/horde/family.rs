//! [`FamilySpec`]: many general predictions (GVFs) declared at once, every cumulant at every timescale
//! over one feature construction, as plain data that deserialises from TOML (`[[horde.families]]`).
//!
//! A prediction of cumulant `C` at timescale τ learns `E[Σ_k γ^k C_{t+k+1}]` with `γ = 1 − 1/τ`, the
//! discounted sum over about the next τ ticks; with `terminate_on = "<stimulus>"` the sum also ends when
//! that stimulus comes on (γ = 0 there), as the paper's predictions end at their event. Nexting
//! predicted every sensor at several timescales this way \[nexting\]:
//!
//! ```toml
//! [[horde.families]]
//! name = "nexting"
//! cumulants = ["obs/*"]          # every observation dimension (see `signals` for the selectors)
//! taus = [2.0, 10.0, 50.0]       # 40 ms, 200 ms and 1 s at 20 ms a tick
//! lambda = 0.9
//! alpha = 0.0002                 # α·‖x‖² ≤ 1 with 484 active features: at most 1/484
//! features = { kind = "one_dim", all_obs = true, tiles = 12, tilings = 11 }
//! ```
//!
//! Its predictions are named `<family>/<cumulant>@<τ>`: `nexting/obs/current@10`.

use serde::{Deserialize, Serialize};

use super::super::bounds::{
    ParamBounds, check_alpha_positive, check_initial_value, check_initial_weight, check_lambda,
    check_tau,
};
use super::super::spec::{LearnerKind, feature_bounds};
use super::super::{FeatureSpec, LearnError, Sigma};

/// `[[horde.families]]`: see the module documentation.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct FamilySpec {
    /// A unique name, the prefix of its predictions' names.
    pub name: String,
    /// Cumulant selectors ([`super::signals`]).
    pub cumulants: Vec<String>,
    /// Timescales τ in ticks (> 1 each): one prediction per cumulant per τ.
    pub taus: Vec<f64>,
    /// Bootstrapping parameter λ in `[0, 1]`.
    pub lambda: f64,
    /// Step size α > 0, with α·‖x‖² ≤ 1.
    pub alpha: f64,
    /// The output nonlinearity (default identity; a logistic prediction keeps a trace of its own).
    #[serde(default = "identity")]
    pub sigma: Sigma,
    /// The value every weight starts from (default 0).
    #[serde(default)]
    pub initial_weight: f64,
    /// A stimulus that ends every prediction of the family when it comes on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub terminate_on: Option<String>,
    /// The features every prediction of the family learns from (built once per tick for all).
    pub features: FeatureSpec,
    /// The learner (default `"paper"`): `"paper"`, `"xent"` (the log-loss gradient, no σ′ in the trace),
    /// `"linear"` (σ = identity), `"true_online"` (dutch traces, σ = identity; its predictions share a
    /// trace only with predictions of the same α) or `"autostep"` (a step size, h and v per weight: four
    /// numbers per weight); off-policy `"gtd"` is refused (a Horde's predictions are about the behaviour
    /// run, and its trace would hold each prediction's importance sampling ratio).
    #[serde(default, skip_serializing_if = "LearnerKind::is_td")]
    pub learner: LearnerKind,
}

fn identity() -> Sigma {
    Sigma::Identity
}

/// The most timescales one family may have.
pub const MAX_TAUS: usize = 64;

impl FamilySpec {
    /// Checks every scalar and size against its bound for a robot with `obs_dims` observation
    /// dimensions, without allocating weights; returns the bounds of its features.
    pub fn bounds(&self, obs_dims: usize) -> Result<ParamBounds, LearnError> {
        let name = self.name.as_str();
        if name.is_empty() || name.contains(['@', '/']) {
            return Err(LearnError::BadFamilyName(self.name.clone()));
        }
        crate::learn::bounds::check_name_length(name)?;
        if self.cumulants.is_empty() || self.taus.is_empty() {
            return Err(LearnError::EmptyFamily(self.name.clone()));
        }
        if self.taus.len() > MAX_TAUS {
            return Err(LearnError::OutOfBounds {
                name: name.to_string(),
                field: "taus".into(),
                value: self.taus.len().to_string(),
                bound: format!("timescales are more than {MAX_TAUS}"),
            });
        }
        for &tau in &self.taus {
            check_tau(name, tau)?;
        }
        check_lambda(name, self.lambda)?;
        check_alpha_positive(name, self.alpha)?;
        check_initial_weight(name, self.initial_weight)?;
        match self.learner {
            LearnerKind::Td | LearnerKind::Xent | LearnerKind::Autostep => {}
            LearnerKind::Linear | LearnerKind::TrueOnline => {
                crate::learn::named::linear::check_identity(name, self.learner.name(), self.sigma)?
            }
            LearnerKind::Gtd => {
                return Err(LearnError::OutOfBounds {
                    name: name.to_string(),
                    field: "learner".into(),
                    value: "\"gtd\"".into(),
                    bound: "is not available in the Horde (its predictions are about the behaviour run; \
                            it runs \"paper\", \"xent\", \"linear\", \"true_online\" and \"autostep\")"
                        .into(),
                });
            }
        }
        let bounds = feature_bounds(name, &self.features, obs_dims)?;
        bounds.check_alpha(name, self.alpha)?;
        check_initial_value(name, self.initial_weight, bounds.active_features)?;
        Ok(bounds)
    }

    /// The name of its prediction of `cumulant` (a canonical selector) at `tau`.
    pub fn prediction_name(&self, cumulant: &str, tau: f64) -> String {
        format!("{}/{cumulant}@{tau}", self.name)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const NEXTING: &str = r#"
        name = "nexting"
        cumulants = ["obs/*", "bias"]
        taus = [2.0, 10.0, 50.0]
        lambda = 0.9
        alpha = 0.0002
        terminate_on = "stall"
        features = { kind = "one_dim", all_obs = true, tiles = 12, tilings = 11 }
    "#;

    #[test]
    fn a_family_parses_and_names_its_predictions() {
        let f: FamilySpec = toml::from_str(NEXTING).unwrap();
        assert_eq!(f.sigma, Sigma::Identity);
        assert_eq!(f.terminate_on.as_deref(), Some("stall"));
        let b = f.bounds(44).unwrap();
        assert_eq!((b.active_features, b.features), (484, 5808));
        assert_eq!(
            f.prediction_name("obs/current", 10.0),
            "nexting/obs/current@10"
        );
        assert_eq!(f.prediction_name("bias", 2.5), "nexting/bias@2.5");
    }

    #[test]
    fn bad_families_are_refused_naming_the_key() {
        let base: FamilySpec = toml::from_str(NEXTING).unwrap();
        let refuse = |edit: &dyn Fn(&mut FamilySpec)| {
            let mut f = base.clone();
            edit(&mut f);
            f.bounds(44).unwrap_err().to_string()
        };
        assert!(refuse(&|f| f.alpha = 0.01).contains("exceeds 1/484"));
        assert!(refuse(&|f| f.taus = vec![10.0, 1.0]).contains("tau"));
        assert!(refuse(&|f| f.lambda = 2.0).contains("lambda"));
        assert!(refuse(&|f| f.taus.clear()).contains("nexting"));
        assert!(refuse(&|f| f.name = "a/b".into()).contains("a/b"));
        assert!(refuse(&|f| f.taus = vec![2.0; 65]).contains("taus"));
        assert!(toml::from_str::<FamilySpec>(&NEXTING.replace("taus", "tau")).is_err());
    }

    #[test]
    fn a_family_names_its_learner_and_the_horde_refuses_only_gtd() {
        let with = |learner: &str, sigma: &str| {
            toml::from_str::<FamilySpec>(&format!(
                "{NEXTING}\nlearner = \"{learner}\"\nsigma = \"{sigma}\"\n"
            ))
            .unwrap()
        };
        assert_eq!(with("xent", "logistic").learner, LearnerKind::Xent);
        with("xent", "logistic").bounds(44).unwrap();
        with("paper", "logistic").bounds(44).unwrap();
        with("linear", "identity").bounds(44).unwrap();
        with("true_online", "identity").bounds(44).unwrap();
        with("autostep", "identity").bounds(44).unwrap();
        with("autostep", "logistic").bounds(44).unwrap();
        for linear_only in ["linear", "true_online"] {
            let e = with(linear_only, "logistic")
                .bounds(44)
                .unwrap_err()
                .to_string();
            assert!(e.contains("sigma"), "{e}");
        }
        for sigma in ["identity", "logistic"] {
            let e = with("gtd", sigma).bounds(44).unwrap_err().to_string();
            assert!(e.contains("learner") && e.contains("gtd"), "{e}");
        }
        // The default is not written (older readers keep working).
        let text = toml::to_string(&with("paper", "identity")).unwrap();
        assert!(!text.contains("learner"), "{text}");
    }
}

//! `[control] gate` and `epsilon`: the stochastic gate's settings and the step-size bound it implies
//! for off-policy predictions.
//!
//! With `gate = "stochastic"` the behaviour takes π's action with probability ε where a rule fires, so an
//! off-policy prediction about π (`learner = "gtd"`, `target_policy = "default"`) sees importance
//! sampling ratios up to ρ_max = 1/ε (`crate::agent::stochastic_gate`). Its trace, and so its step,
//! grows by ρ, and the bound α·‖x‖² ≤ 1 of every prediction becomes **α·ρ_max·‖x‖² ≤ 1**, i.e.
//! α ≤ ε/‖x‖². A configuration beyond it is refused at load with the largest α allowed (never scaled
//! behind the operator's back: the α in force is the α written). The same bound holds for runtime
//! changes ([`Config::max_alpha`]).

use super::{Config, ConfigError, invalid};
use crate::control::GateKind;
use crate::learn::PredictionSpec;
use crate::learn::spec::TargetPolicy;

/// Whether `spec` learns off-policy about the default policy π, so that its ratios reach ρ_max.
pub fn learns_about_default(spec: &PredictionSpec) -> bool {
    spec.gtd_params().is_some() && spec.target_policy == Some(TargetPolicy::Default)
}

impl Config {
    /// The largest importance sampling ratio the behaviour can produce: 1/ε with the stochastic
    /// gate, 1 otherwise (a deterministic behaviour gives ρ ∈ {0, 1}).
    pub fn rho_max(&self) -> f64 {
        match (self.control.gate, self.control.epsilon) {
            (GateKind::Stochastic, Some(eps)) if eps > 0.0 => 1.0 / eps,
            _ => 1.0,
        }
    }

    /// The largest α prediction `spec` may use with `active` active features: 1/‖x‖², divided by
    /// ρ_max for an off-policy prediction about π.
    pub fn max_alpha(&self, spec: &PredictionSpec, active: usize) -> f64 {
        let base = 1.0 / active.max(1) as f64;
        if learns_about_default(spec) {
            base / self.rho_max()
        } else {
            base
        }
    }

    /// `[control] gate` and `epsilon`, and α·ρ_max·‖x‖² ≤ 1 for every off-policy prediction about π.
    pub(super) fn check_gate(&self) -> Result<(), ConfigError> {
        match (self.control.gate, self.control.epsilon) {
            (GateKind::Deterministic, None) => return Ok(()),
            (GateKind::Deterministic, Some(_)) => {
                return Err(invalid(
                    "control.epsilon",
                    "is only used with gate = \"stochastic\"",
                ));
            }
            (GateKind::Stochastic, None) => {
                return Err(invalid(
                    "control.epsilon",
                    "is required with gate = \"stochastic\" (the probability of π's action where a rule fires)",
                ));
            }
            (GateKind::Stochastic, Some(eps)) => {
                if !(eps > 0.0 && eps < 1.0) {
                    return Err(invalid(
                        "control.epsilon",
                        format!(
                            "{eps} is outside (0, 1) (0 is the deterministic gate; 1 never responds)"
                        ),
                    ));
                }
            }
        }
        let rho_max = self.rho_max();
        for ((i, spec), (_, bounds)) in self
            .predictions
            .iter()
            .enumerate()
            .zip(self.prediction_bounds()?)
        {
            if !learns_about_default(spec) {
                continue;
            }
            let max = self.max_alpha(spec, bounds.active_features);
            // The bound written in decimal (ε/44) may differ from it in its last digit.
            if spec.alpha > max * (1.0 + 1e-12) {
                let n = bounds.active_features;
                return Err(invalid(
                    format!("predictions[{i}] ({}).alpha", spec.name),
                    format!(
                        "{:?} exceeds ε/{n} = {max:.6} (α·ρ_max·‖x‖² ≤ 1 with ρ_max = 1/ε = {rho_max} under \
                         control.gate = \"stochastic\", epsilon = {}, and {n} active features)",
                        spec.alpha,
                        self.rho_max().recip()
                    ),
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const STALL: &str = include_str!("../../config/stall.toml");

    /// The stall configuration with an off-policy prediction about π of step size `alpha`, and the
    /// `[control]` lines `gate`.
    fn stall_with(gate: &str, alpha: f64) -> String {
        let pi = format!(
            "\n[[predictions]]\nname = \"stall_pi\"\ntau = 25.0\nlambda = 0.5\nalpha = {alpha:?}\n\
             sigma = \"identity\"\nthreshold = {{ fixed = 0.5 }}\ncumulant = {{ stimulus = \"stall\" }}\n\
             features = {{ kind = \"one_dim\", all_obs = true, tiles = 10 }}\nlearner = \"gtd\"\n\
             target_policy = \"default\"\nbeta = 0.001\n"
        );
        STALL.replace(
            "response = { kind = \"stop\" }",
            &format!("response = {{ kind = \"stop\" }}\n{gate}"),
        ) + &pi
    }

    #[test]
    fn the_step_size_bound_divides_by_rho_max_at_load() {
        // Deterministic: ρ ≤ 1, the paper's α = 1/44 is the bound.
        Config::from_toml(&stall_with("", 1.0 / 44.0)).unwrap();
        // ε = 0.5: ρ_max = 2, so α ≤ 0.5/44.
        let half = "gate = \"stochastic\"\nepsilon = 0.5";
        let e = Config::from_toml(&stall_with(half, 1.0 / 44.0)).unwrap_err();
        assert_eq!(
            e.to_string(),
            "predictions[1] (stall_pi).alpha: 0.022727272727272728 exceeds ε/44 = 0.011364 (α·ρ_max·‖x‖² ≤ 1 \
             with ρ_max = 1/ε = 2 under control.gate = \"stochastic\", epsilon = 0.5, and 44 active features)"
        );
        let ok = Config::from_toml(&stall_with(half, 0.5 / 44.0)).unwrap();
        assert_eq!(ok.rho_max(), 2.0);
        assert_eq!(ok.max_alpha(&ok.predictions[1], 44), 0.5 / 44.0);
        // The on-policy prediction keeps its own bound, 1/44: ρ never reaches it.
        assert_eq!(ok.max_alpha(&ok.predictions[0], 44), 1.0 / 44.0);
        // Just above the bound: refused; ε = 0.2 needs α ≤ 0.2/44.
        assert!(Config::from_toml(&stall_with(half, 0.5 / 44.0 * 1.001)).is_err());
        let fifth = "gate = \"stochastic\"\nepsilon = 0.2";
        assert!(Config::from_toml(&stall_with(fifth, 0.5 / 44.0)).is_err());
        Config::from_toml(&stall_with(fifth, 0.2 / 44.0)).unwrap();
    }

    #[test]
    fn epsilon_is_required_with_the_stochastic_gate_and_within_zero_and_one() {
        let refusal = |gate: &str| match Config::from_toml(&stall_with(gate, 0.001)) {
            Err(ConfigError::Invalid { key, message }) => format!("{key}: {message}"),
            other => panic!("{gate}: expected a refusal, got {other:?}"),
        };
        assert!(refusal("gate = \"stochastic\"").starts_with("control.epsilon: is required"));
        assert!(refusal("epsilon = 0.5").starts_with("control.epsilon: is only used"));
        for bad in ["0.0", "1.0", "-0.1", "nan", "inf"] {
            let r = refusal(&format!("gate = \"stochastic\"\nepsilon = {bad}"));
            assert!(r.contains("outside (0, 1)"), "{bad}: {r}");
        }
        assert!(Config::from_toml(&stall_with("gate = \"random\"\nepsilon = 0.5", 0.001)).is_err());
        // The default is written as before: no `gate` or `epsilon` key.
        let det = Config::from_toml(STALL).unwrap();
        assert_eq!(det.control.gate, GateKind::Deterministic);
        let text = toml::to_string(&det).unwrap();
        assert!(
            !text.contains("gate =") && !text.contains("epsilon"),
            "{text}"
        );
    }
}

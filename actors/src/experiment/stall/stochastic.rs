//! The stall study's stochastic-gate arms (`--policies …,offpolicy-stochastic --epsilon 0.2,0.5`): how
//! a run's configuration gets the stochastic gate, and the behaviour's coverage of π in the gate region.
//!
//! An `offpolicy-stochastic` run is an `offpolicy` run (Pavlovian control on the GTD(λ) prediction
//! `stall_pi` about π) whose mixing function takes π's action with probability ε where `stall_pi` is above
//! θ and the stimulus is off (`[control] gate = "stochastic"`, `pavlov::agent::stochastic_gate`). The
//! ratio on π's action there is ρ = 1/ε, so the step-size bound becomes α·ρ_max·‖x‖² ≤ 1
//! (`pavlov::config::gate`): the off-policy prediction's α, the paper's 1/‖x‖², is multiplied by ε, which
//! makes it that bound, and β keeps its rule β = α/10 (multiplied by ε too). Nothing else changes, and
//! nothing was chosen by looking at a result.
//!
//! **Coverage** is measured on the *gate region*: the ticks on which a prediction's rule engaged the
//! mixing function while the stimulus was off (the record's `rule` names a rule, not `stimulus`). The
//! coverage is the fraction of those ticks on which π's command went out. The paper's gate gives 0 by
//! construction; a stochastic gate about ε (less where a safety stop intervened).

use pavlov::config::Config;
use pavlov::control::{GateKind, STIMULUS_RULE};
use pavlov::record::TickRecord;
use serde::{Deserialize, Serialize};

use super::policies::PoliciesError;

/// The ε of `offpolicy-stochastic` when `--epsilon` is not given: the independent patch's value,
/// fixed before any run here.
pub const DEFAULT_EPSILON: f64 = 0.5;

/// Parses `--epsilon 0.2,0.35,0.5`: each in (0, 1), none twice.
pub fn parse_epsilons(list: &str) -> Result<Vec<f64>, PoliciesError> {
    let mut out: Vec<f64> = Vec::new();
    for item in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let eps: f64 = item
            .parse()
            .map_err(|_| PoliciesError::Epsilon(format!("`{item}` is not a number")))?;
        if !(eps > 0.0 && eps < 1.0) {
            return Err(PoliciesError::Epsilon(format!("{item} is outside (0, 1)")));
        }
        if out.contains(&eps) {
            return Err(PoliciesError::Epsilon(format!("{item} is named twice")));
        }
        out.push(eps);
    }
    if out.is_empty() {
        return Err(PoliciesError::Epsilon("name at least one ε".into()));
    }
    Ok(out)
}

/// `config` (which carries the off-policy prediction) with the stochastic gate of `epsilon`, and every
/// off-policy prediction about π's α and β multiplied by ε (see the module documentation), checked.
pub fn with_stochastic_gate(config: &Config, epsilon: f64) -> Result<Config, PoliciesError> {
    let mut c = config.clone();
    apply_stochastic_gate(&mut c, epsilon);
    c.validate()
        .map_err(|e| PoliciesError::Config(e.to_string()))?;
    Ok(c)
}

/// What [`with_stochastic_gate`] changes, unchecked (a run's configuration is checked when its server
/// starts).
pub(crate) fn apply_stochastic_gate(c: &mut Config, epsilon: f64) {
    c.control.gate = GateKind::Stochastic;
    c.control.epsilon = Some(epsilon);
    for p in &mut c.predictions {
        if pavlov::config::gate::learns_about_default(p) {
            p.alpha *= epsilon;
            p.beta = p.beta.map(|b| b * epsilon);
        }
    }
}

/// The behaviour's coverage of π in the gate region over one run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Coverage {
    /// Ticks in the run.
    pub ticks: u64,
    /// Ticks in the gate region (a prediction's rule engaged, the stimulus off).
    pub region_ticks: u64,
    /// Of those, ticks whose command was π's.
    pub region_followed: u64,
    /// Σ b(A|S) over the region's ticks (for the mean behaviour probability there).
    pub region_b_sum: f64,
}

impl Coverage {
    /// Counts one tick.
    pub(crate) fn observe(&mut self, r: &TickRecord) {
        self.ticks += 1;
        let region = !r.stimulus && r.rule.as_deref().is_some_and(|n| n != STIMULUS_RULE);
        if region {
            self.region_ticks += 1;
            self.region_b_sum += r.behaviour_prob;
            if pavlov::agent::learning::followed_default(r.command, r.default_action) {
                self.region_followed += 1;
            }
        }
    }

    /// The fraction of the region's ticks on which π's command went out (`None`: no region).
    pub fn coverage(&self) -> Option<f64> {
        (self.region_ticks > 0).then(|| self.region_followed as f64 / self.region_ticks as f64)
    }

    /// The fraction of all ticks in the region.
    pub fn region_fraction(&self) -> f64 {
        self.region_ticks as f64 / self.ticks.max(1) as f64
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pavlov::control::{Action, Mode};

    #[test]
    fn epsilon_lists_are_parsed_with_precise_errors() {
        assert_eq!(
            parse_epsilons("0.2, 0.35,0.5").unwrap(),
            vec![0.2, 0.35, 0.5]
        );
        for (bad, says) in [
            ("0", "outside (0, 1)"),
            ("1", "outside (0, 1)"),
            ("x", "not a number"),
            ("0.5,0.5", "named twice"),
            ("", "at least one"),
        ] {
            let e = parse_epsilons(bad).unwrap_err().to_string();
            assert!(e.contains(says), "{bad}: {e}");
        }
    }

    #[test]
    fn the_stochastic_arm_scales_only_the_off_policy_step_sizes() {
        let base = super::super::policies::with_offpolicy_prediction(
            &Config::from_toml(include_str!("../../../../config/stall.toml")).unwrap(),
        )
        .unwrap();
        let c = with_stochastic_gate(&base, 0.35).unwrap();
        assert_eq!(
            (c.control.gate, c.control.epsilon),
            (GateKind::Stochastic, Some(0.35))
        );
        assert_eq!(
            c.predictions[0], base.predictions[0],
            "the on-policy prediction unchanged"
        );
        assert_eq!(c.predictions[1].alpha, base.predictions[1].alpha * 0.35);
        assert_eq!(
            c.predictions[1].beta,
            base.predictions[1].beta.map(|b| b * 0.35)
        );
        // Exactly the bound α·ρ_max·‖x‖² = 1.
        assert!((c.predictions[1].alpha / 0.35 * 44.0 - 1.0).abs() < 1e-12);
    }

    #[test]
    fn coverage_counts_pis_commands_where_a_rule_fired_without_the_stimulus() {
        let forward = Action::new(100, 100);
        let tick = |rule: Option<&str>, stimulus: bool, command: Action, b: f64| TickRecord {
            rule: rule.map(str::to_string),
            stimulus,
            command,
            default_action: forward,
            behaviour_prob: b,
            ..TickRecord::at_rest(0, 0.0, Mode::Pavlovian)
        };
        let mut c = Coverage::default();
        assert_eq!(c.coverage(), None);
        c.observe(&tick(None, false, forward, 1.0)); // outside
        c.observe(&tick(Some("stimulus"), true, Action::STOP, 1.0)); // the stimulus: outside
        c.observe(&tick(Some("stall_pi"), true, Action::STOP, 1.0)); // rule and stimulus: outside
        c.observe(&tick(Some("stall_pi"), false, forward, 0.5)); // π drawn
        c.observe(&tick(Some("stall_pi"), false, Action::STOP, 0.5)); // ϱ drawn
        c.observe(&tick(Some("stall_pi"), false, Action::STOP, 0.5));
        assert_eq!((c.ticks, c.region_ticks, c.region_followed), (6, 3, 1));
        assert_eq!(c.coverage(), Some(1.0 / 3.0));
        assert_eq!(c.region_fraction(), 0.5);
        assert_eq!(c.region_b_sum, 1.5);
    }
}

//! The mixing function and gate: when the fixed response ϱ takes over from the default policy π.
//!
//! The paper's behaviour policy is `b = f_E(v)·ϱ + (1 − f_E(v))·π` with a binary mixing function, so it
//! reduces to choosing one action:
//! - reactive control: `f = I{E}`;
//! - Pavlovian control: `f_E(v) = I{E ∨ v > θ}`;
//! - manual: a person drives; the response never engages (the operator's commands are the default).
//!
//! The paper lets the mixing function take any value in `[0, 1]`. [`GateKind::Stochastic`] uses that:
//! where a prediction's rule fires (and the stimulus is off) the response acts with probability 1 − ε and
//! π's action is taken with probability ε, so the behaviour keeps taking π's actions where an off-policy
//! prediction about π needs them (`crate::agent::stochastic_gate` draws and logs it).

use serde::{Deserialize, Serialize};

use super::Action;

/// How the action is chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Mode {
    /// The response engages on the stimulus alone.
    Reactive,
    /// The response engages on the stimulus or on a prediction above its threshold.
    Pavlovian,
    /// The response never engages.
    Manual,
}

impl Mode {
    /// Every mode, in the order declared.
    pub const ALL: [Mode; 3] = [Mode::Reactive, Mode::Pavlovian, Mode::Manual];

    /// The mode's name, as serialised and shown (`reactive`, `pavlovian`, `manual`).
    pub fn name(self) -> &'static str {
        match self {
            Mode::Reactive => "reactive",
            Mode::Pavlovian => "pavlovian",
            Mode::Manual => "manual",
        }
    }
}

/// How the mixing function engages a prediction rule's response (`[control] gate`).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum GateKind {
    /// The paper's binary mixing function: the response whenever a rule fires.
    #[default]
    Deterministic,
    /// `f = 1 − ε` where a rule fires and the stimulus is off: π's action with probability ε
    /// (`[control] epsilon`); the stimulus still engages the response with certainty.
    Stochastic,
}

impl GateKind {
    /// True for the paper's gate (the default, left out when a configuration is written).
    pub fn is_deterministic(&self) -> bool {
        *self == GateKind::Deterministic
    }
}

/// The mixing function: true when the fixed response should act on this tick.
///
/// `prediction` is `None` when it cannot be trusted (invalid or missing inputs); Pavlovian control then
/// falls back to the stimulus alone, like reactive control. A NaN prediction or threshold never
/// engages the response on its own (`v > θ` is false).
pub fn gate(mode: Mode, stimulus: bool, prediction: Option<f64>, threshold: f64) -> bool {
    match mode {
        Mode::Reactive => stimulus,
        Mode::Pavlovian => stimulus || prediction.is_some_and(|v| v > threshold),
        Mode::Manual => false,
    }
}

/// `b = f·ϱ + (1 − f)·π` for a binary `f`: the response when engaged, else the default.
pub fn mix(response: Action, default: Action, engaged: bool) -> Action {
    if engaged { response } else { default }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn truth_table() {
        let theta = 0.5;
        // (mode, stimulus, prediction, expected)
        let rows = [
            (Mode::Reactive, false, None, false),
            (Mode::Reactive, true, None, true),
            (Mode::Reactive, false, Some(0.9), false),
            (Mode::Reactive, true, Some(0.1), true),
            (Mode::Pavlovian, false, None, false),
            (Mode::Pavlovian, true, None, true),
            (Mode::Pavlovian, false, Some(0.4), false),
            (Mode::Pavlovian, false, Some(0.5), false),
            (Mode::Pavlovian, false, Some(0.51), true),
            (Mode::Pavlovian, true, Some(0.1), true),
            (Mode::Pavlovian, false, Some(f64::NAN), false),
            (Mode::Pavlovian, true, Some(f64::NAN), true),
            (Mode::Manual, true, Some(0.9), false),
            (Mode::Manual, false, Some(0.9), false),
        ];
        for (mode, e, v, want) in rows {
            assert_eq!(gate(mode, e, v, theta), want, "{mode:?} E={e} v={v:?}");
        }
        assert!(!gate(Mode::Pavlovian, false, Some(1.0), f64::NAN));
    }

    #[test]
    fn mix_selects_one_action() {
        let spin = Action::new(-150, 150);
        let forward = Action::new(200, 200);
        assert_eq!(mix(spin, forward, true), spin);
        assert_eq!(mix(spin, forward, false), forward);
    }

    #[test]
    fn modes_are_lowercase_in_config() {
        #[derive(Deserialize)]
        struct W {
            m: Mode,
        }
        let w: W = toml::from_str("m = \"pavlovian\"").unwrap();
        assert_eq!(w.m, Mode::Pavlovian);
        assert!(toml::from_str::<W>("m = \"Pavlovian\"").is_err());
    }
}

//! [`GatingStage`]: the paper's mixing function, plus manual teleop and the e-stop.
//!
//! In reactive mode the fixed response ϱ replaces the default policy π while the stimulus E is present,
//! `b = I{E}ϱ + (1 − I{E})π`; in Pavlovian mode also while the gating prediction exceeds its threshold,
//! `f(v) = I{E ∨ v > θ}`, generalised to a rule table (several predictions, thresholds and responses,
//! [`crate::control::rules`]) whose highest-priority rule that fired picks the response; in manual mode
//! the wheels follow teleop commands, which expire after [`TELEOP_HOLD_TICKS`] so that an operator who
//! goes away cannot leave the robot driving.
//!
//! With a [`StochasticGate`] (`[control] gate = "stochastic"`) a rule that fires while the stimulus is off
//! takes π's action with probability ε instead of its response; every output carries the behaviour
//! probability b(A|S) of its action (1 for every certain choice).

use std::sync::Arc;

use crate::control::rules::{Fired, GateInput, Rule, STIMULUS_RULE, select};
use crate::control::{Action, Mode, Policy};

use super::stochastic_gate::StochasticGate;

/// How many ticks a teleop command drives the wheels without being refreshed (0.5 s at 50 Hz).
pub const TELEOP_HOLD_TICKS: u64 = 25;

/// What gating decided on one tick.
#[derive(Debug, Clone, PartialEq)]
pub struct GateOutput {
    /// Mode in force.
    pub mode: Mode,
    /// Whether the fixed response was selected (false where a stochastic gate drew π's action).
    pub gate: bool,
    /// The default policy's action π.
    pub default_action: Action,
    /// The action to take (actuation may still override it for safety).
    pub action: Action,
    /// What engaged the mixing function: the name of the rule that fired, or `stimulus` (the stimulus
    /// alone); `None` when it did not engage. Set also where a stochastic gate drew π's action
    /// (`gate` false, `behaviour_prob` = ε).
    pub rule: Option<Arc<str>>,
    /// The behaviour probability b(A|S) of `action`: 1 unless a stochastic gate drew it.
    pub behaviour_prob: f64,
}

/// Gating's state.
#[derive(Debug, Clone)]
pub struct GatingStage {
    mode: Mode,
    default_policy: Policy,
    response: Policy,
    rules: Vec<Rule>,
    stimulus_rule: Arc<str>,
    estop: bool,
    teleop: Option<(Action, u64)>,
    stochastic: Option<StochasticGate>,
}

/// Why a command was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum GateError {
    /// Teleop outside manual mode.
    #[error("teleop needs manual mode; the server is in {0} mode")]
    NotManual(&'static str),
    /// Teleop while the e-stop is latched.
    #[error("the e-stop is latched; release it first")]
    EStopLatched,
}

impl GatingStage {
    /// A gate in `mode` between `default_policy` (π) and the responses: `response` (ϱ) for the stimulus
    /// alone, each rule's own when it fires (`Config::rule_table`: the paper's single rule by default).
    pub fn new(mode: Mode, default_policy: Policy, response: Policy, rules: Vec<Rule>) -> Self {
        GatingStage {
            mode,
            default_policy,
            response,
            rules,
            stimulus_rule: STIMULUS_RULE.into(),
            estop: false,
            teleop: None,
            stochastic: None,
        }
    }

    /// This gate with the stochastic mixing function `gate` (`None`: the paper's).
    pub fn with_stochastic_gate(mut self, gate: Option<StochasticGate>) -> Self {
        self.stochastic = gate;
        self
    }

    /// The mode in force.
    pub fn mode(&self) -> Mode {
        self.mode
    }

    /// Switches mode (and drops any teleop command).
    pub fn set_mode(&mut self, mode: Mode) {
        self.mode = mode;
        self.teleop = None;
    }

    /// Latches or releases the e-stop.
    pub fn set_estop(&mut self, on: bool) {
        self.estop = on;
        self.teleop = None;
    }

    /// Accepts a teleop command on tick `seq` (manual mode only).
    pub fn teleop(&mut self, action: Action, seq: u64) -> Result<(), GateError> {
        if self.mode != Mode::Manual {
            return Err(GateError::NotManual(self.mode.name()));
        }
        if self.estop {
            return Err(GateError::EStopLatched);
        }
        self.teleop = Some((action, seq));
        Ok(())
    }

    /// Decides tick `seq`'s action from the stimulus and every prediction's gate input, in the
    /// prediction set's order (a `None` value = invalid input: that prediction fires no rule).
    pub fn decide(&mut self, seq: u64, stimulus: bool, inputs: &[GateInput]) -> GateOutput {
        let default_action = self.default_policy.action(seq);
        // (what engaged, the action, whether it is the response, b of the action)
        let (rule, action, responded, b) = match self.mode {
            Mode::Manual => {
                let a = match self.teleop {
                    Some((a, at)) if seq.saturating_sub(at) <= TELEOP_HOLD_TICKS => a,
                    _ => Action::STOP,
                };
                (None, a, false, 1.0)
            }
            mode => match select(mode, stimulus, &self.rules, inputs) {
                None => (None, default_action, false, 1.0),
                Some(Fired::Stimulus) => (
                    Some(self.stimulus_rule.clone()),
                    self.response.action(seq),
                    true,
                    1.0,
                ),
                Some(Fired::Rule(i)) => {
                    let rule = &self.rules[i];
                    let response = rule.response.action(seq);
                    match &self.stochastic {
                        Some(g) if !stimulus => {
                            let d = g.choose(seq, response, default_action);
                            let responded = !(d.took_default && response != default_action);
                            (
                                Some(rule.name.clone()),
                                d.action,
                                responded,
                                d.behaviour_prob,
                            )
                        }
                        _ => (Some(rule.name.clone()), response, true, 1.0),
                    }
                }
            },
        };
        GateOutput {
            mode: self.mode,
            gate: responded,
            default_action,
            action: if self.estop { Action::STOP } else { action },
            rule,
            behaviour_prob: if self.estop { 1.0 } else { b },
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FORWARD: Policy = Policy::Constant {
        left_mm_s: 200,
        right_mm_s: 200,
    };

    /// The paper's single rule: prediction 0 at its own threshold, the response `stop`.
    fn stage(mode: Mode) -> GatingStage {
        let rule = Rule {
            name: "p".into(),
            prediction: 0,
            threshold: None,
            response: Policy::Stop {},
            priority: 0,
        };
        GatingStage::new(mode, FORWARD, Policy::Stop {}, vec![rule])
    }

    /// One prediction's input at θ = 0.5.
    fn one(value: Option<f64>) -> [GateInput; 1] {
        [GateInput {
            value,
            threshold: 0.5,
        }]
    }

    #[test]
    fn the_highest_priority_rule_that_fired_acts_and_is_named() {
        let rule = |name: &str, prediction, response, priority| Rule {
            name: name.into(),
            prediction,
            threshold: None,
            response,
            priority,
        };
        let spin = Policy::SpinLeft { speed_mm_s: 100 };
        let back = Policy::Constant {
            left_mm_s: -50,
            right_mm_s: -50,
        };
        let mut g = GatingStage::new(
            Mode::Pavlovian,
            FORWARD,
            Policy::Stop {},
            vec![rule("near", 0, spin, 1), rule("far", 1, back, 5)],
        );
        let inputs = |a: f64, b: f64| {
            [
                GateInput {
                    value: Some(a),
                    threshold: 0.5,
                },
                GateInput {
                    value: Some(b),
                    threshold: 0.5,
                },
            ]
        };
        let quiet = g.decide(0, false, &inputs(0.1, 0.1));
        assert_eq!(
            (quiet.gate, quiet.rule, quiet.action),
            (false, None, Action::new(200, 200))
        );
        let near = g.decide(1, false, &inputs(0.9, 0.1));
        assert_eq!(
            (near.rule.as_deref(), near.action),
            (Some("near"), spin.action(1))
        );
        let both = g.decide(2, true, &inputs(0.9, 0.9));
        assert_eq!(
            (both.rule.as_deref(), both.action),
            (Some("far"), back.action(2))
        );
        let stimulus = g.decide(3, true, &inputs(0.1, 0.1));
        assert!(stimulus.gate);
        assert_eq!(
            (stimulus.rule.as_deref(), stimulus.action),
            (Some("stimulus"), Action::STOP)
        );
        // Reactive control answers the stimulus alone with the configured response.
        g.set_mode(Mode::Reactive);
        assert_eq!(g.decide(4, false, &inputs(0.9, 0.9)).rule, None);
        let reactive = g.decide(5, true, &inputs(0.9, 0.9));
        assert_eq!(
            (reactive.rule.as_deref(), reactive.action),
            (Some("stimulus"), Action::STOP)
        );
    }

    #[test]
    fn reactive_responds_only_to_the_stimulus_pavlovian_also_to_the_prediction() {
        let mut r = stage(Mode::Reactive);
        assert_eq!(
            r.decide(0, false, &one(Some(0.9))).action,
            Action::new(200, 200)
        );
        assert_eq!(r.decide(1, true, &one(Some(0.0))).action, Action::STOP);
        let mut p = stage(Mode::Pavlovian);
        let out = p.decide(0, false, &one(Some(0.9)));
        assert!(out.gate);
        assert_eq!(out.action, Action::STOP);
        assert_eq!(out.default_action, Action::new(200, 200));
        // An invalid prediction falls back to the stimulus alone.
        assert!(!p.decide(1, false, &one(None)).gate);
    }

    #[test]
    fn the_stochastic_gate_logs_b_of_the_action_it_took() {
        let eps = 0.3;
        let g = StochasticGate::new(eps, 11);
        let mut p = stage(Mode::Pavlovian).with_stochastic_gate(Some(g.clone()));
        let forward = Action::new(200, 200);
        let (mut pi, mut response) = (0, 0);
        for seq in 0..200 {
            // The region: the rule fires, the stimulus is off.
            let out = p.decide(seq, false, &one(Some(0.9)));
            assert_eq!(
                out.rule.as_deref(),
                Some("p"),
                "the rule engaged the mixing function"
            );
            if g.draw(seq) < eps {
                pi += 1;
                assert_eq!(
                    (out.action, out.gate, out.behaviour_prob),
                    (forward, false, eps)
                );
            } else {
                response += 1;
                assert_eq!(
                    (out.action, out.gate, out.behaviour_prob),
                    (Action::STOP, true, 1.0 - eps)
                );
            }
            // Outside it every choice is certain: π's action, the stimulus's response (even with the
            // rule firing too), an invalid prediction.
            let quiet = p.decide(seq, false, &one(Some(0.1)));
            assert_eq!(
                (quiet.action, quiet.behaviour_prob, quiet.rule),
                (forward, 1.0, None)
            );
            let both = p.decide(seq, true, &one(Some(0.9)));
            assert_eq!(
                (both.action, both.gate, both.behaviour_prob),
                (Action::STOP, true, 1.0)
            );
            let alone = p.decide(seq, true, &one(Some(0.1)));
            assert_eq!((alone.action, alone.behaviour_prob), (Action::STOP, 1.0));
        }
        assert!(pi > 0 && response > 0, "{pi} π, {response} ϱ");
        // The e-stop is certain too, and reactive mode never reaches the rule.
        p.set_estop(true);
        let stopped = p.decide(3, false, &one(Some(0.9)));
        assert_eq!(
            (stopped.action, stopped.behaviour_prob),
            (Action::STOP, 1.0)
        );
        let mut r = stage(Mode::Reactive).with_stochastic_gate(Some(g));
        assert_eq!(r.decide(3, false, &one(Some(0.9))).behaviour_prob, 1.0);
        // The paper's gate: certain everywhere.
        assert_eq!(
            stage(Mode::Pavlovian)
                .decide(3, false, &one(Some(0.9)))
                .behaviour_prob,
            1.0
        );
    }

    #[test]
    fn estop_overrides_everything_and_teleop_expires() {
        let mut g = stage(Mode::Manual);
        assert_eq!(g.decide(0, false, &one(None)).action, Action::STOP);
        g.teleop(Action::new(100, -100), 10).unwrap();
        assert_eq!(
            g.decide(10 + TELEOP_HOLD_TICKS, false, &one(None)).action,
            Action::new(100, -100)
        );
        assert_eq!(
            g.decide(11 + TELEOP_HOLD_TICKS, false, &one(None)).action,
            Action::STOP
        );
        g.set_estop(true);
        assert_eq!(
            g.teleop(Action::new(1, 1), 50),
            Err(GateError::EStopLatched)
        );
        let mut p = stage(Mode::Pavlovian);
        p.set_estop(true);
        assert_eq!(p.decide(0, false, &one(Some(0.0))).action, Action::STOP);
        assert_eq!(
            stage(Mode::Reactive).teleop(Action::STOP, 0),
            Err(GateError::NotManual("reactive"))
        );
    }
}

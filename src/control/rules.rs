//! The rule table: several fixed responses, each driven by its own prediction (the second extension the
//! paper's Discussion names).
//!
//! The paper's Pavlovian control has one rule, `f_E(v) = I{E ∨ v > θ}` with one response ϱ. A rule table
//! generalises it: rule `i` fires when its prediction `v_i` exceeds its threshold `θ_i`, and the gate
//! engages when the stimulus E is on or any rule fires. The action is the response of the
//! highest-priority rule that fired; when none fired and the stimulus alone engaged the gate, the action
//! is `control.response`, as in the paper. With the single default rule (the gate prediction, its own
//! threshold, `control.response`) this is exactly the paper's gate. Reactive mode ignores the rules
//! (the stimulus alone engages `control.response`); manual mode never engages.
//!
//! Pure: [`select`] decides from values only, so it is tested here and used unchanged by the runtime and
//! by replay.

use std::sync::Arc;

use super::{Mode, Policy};

/// The name recorded when the stimulus alone engaged the gate.
pub const STIMULUS_RULE: &str = "stimulus";

/// One rule, resolved against the prediction set (see `pavlov::config::RuleSpec` for the TOML form).
#[derive(Debug, Clone, PartialEq)]
pub struct Rule {
    /// The rule's name, as the gate records it.
    pub name: Arc<str>,
    /// Index of the rule's prediction in the prediction set (config order).
    pub prediction: usize,
    /// θ of the rule; `None` = the prediction's own threshold in force (which `set_params` may change).
    pub threshold: Option<f64>,
    /// The fixed response the rule selects.
    pub response: Policy,
    /// Larger wins when several rules fire on the same tick.
    pub priority: i64,
}

/// One prediction's input to the gate on a tick.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GateInput {
    /// The prediction's value when it rests on fully valid inputs (`None`: it cannot fire a rule).
    pub value: Option<f64>,
    /// The prediction's own threshold in force.
    pub threshold: f64,
}

/// What engaged the gate on a tick.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Fired {
    /// The stimulus alone (no rule fired): `control.response`.
    Stimulus,
    /// The rule at this index of the table: its response.
    Rule(usize),
}

/// Whether `rule` fires on `inputs`: its prediction is valid and strictly above its threshold. A NaN
/// value or threshold never fires (`v > θ` is false), nor does a prediction index out of range.
pub fn fires(rule: &Rule, inputs: &[GateInput]) -> bool {
    inputs.get(rule.prediction).is_some_and(|input| {
        let theta = rule.threshold.unwrap_or(input.threshold);
        input.value.is_some_and(|v| v > theta)
    })
}

/// What engages the gate in `mode`, if anything: in Pavlovian mode the highest-priority rule that fired
/// (the first of equal priorities, which configuration refuses), else the stimulus; in reactive mode
/// the stimulus; in manual mode nothing.
pub fn select(mode: Mode, stimulus: bool, rules: &[Rule], inputs: &[GateInput]) -> Option<Fired> {
    match mode {
        Mode::Manual => None,
        Mode::Reactive => stimulus.then_some(Fired::Stimulus),
        Mode::Pavlovian => {
            let mut best: Option<usize> = None;
            for (i, rule) in rules.iter().enumerate() {
                if fires(rule, inputs) && best.is_none_or(|b| rule.priority > rules[b].priority) {
                    best = Some(i);
                }
            }
            best.map(Fired::Rule)
                .or_else(|| stimulus.then_some(Fired::Stimulus))
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::gate;

    fn rule(name: &str, prediction: usize, threshold: Option<f64>, priority: i64) -> Rule {
        Rule {
            name: name.into(),
            prediction,
            threshold,
            response: Policy::Stop {},
            priority,
        }
    }

    fn input(value: Option<f64>, threshold: f64) -> GateInput {
        GateInput { value, threshold }
    }

    #[test]
    fn the_single_default_rule_is_the_papers_gate() {
        let rules = [rule("stall", 0, None, 0)];
        for mode in [Mode::Reactive, Mode::Pavlovian, Mode::Manual] {
            for stimulus in [false, true] {
                for v in [None, Some(0.4), Some(0.5), Some(0.51), Some(f64::NAN)] {
                    for theta in [0.5, f64::NAN] {
                        let engaged = select(mode, stimulus, &rules, &[input(v, theta)]).is_some();
                        assert_eq!(
                            engaged,
                            gate(mode, stimulus, v, theta),
                            "{mode:?} E={stimulus} v={v:?} θ={theta}"
                        );
                    }
                }
            }
        }
        // The rule is named when the prediction fired, the stimulus when it alone did.
        let both = select(Mode::Pavlovian, true, &rules, &[input(Some(0.9), 0.5)]);
        assert_eq!(both, Some(Fired::Rule(0)));
        let alone = select(Mode::Pavlovian, true, &rules, &[input(Some(0.1), 0.5)]);
        assert_eq!(alone, Some(Fired::Stimulus));
    }

    #[test]
    fn the_highest_priority_rule_that_fired_wins_in_any_table_order() {
        let rules = [
            rule("low", 0, Some(0.2), -3),
            rule("high", 1, Some(0.6), 7),
            rule("mid", 0, Some(0.4), 1),
        ];
        let at = |v0: f64, v1: f64| {
            select(
                Mode::Pavlovian,
                false,
                &rules,
                &[input(Some(v0), 0.5), input(Some(v1), 0.5)],
            )
        };
        assert_eq!(at(0.1, 0.1), None);
        assert_eq!(at(0.3, 0.1), Some(Fired::Rule(0)));
        assert_eq!(at(0.45, 0.1), Some(Fired::Rule(2)));
        assert_eq!(at(0.45, 0.7), Some(Fired::Rule(1)));
        assert_eq!(at(0.1, 0.7), Some(Fired::Rule(1)));
        // Reactive mode ignores the rules; manual never engages.
        let inputs = [input(Some(0.9), 0.5), input(Some(0.9), 0.5)];
        assert_eq!(select(Mode::Reactive, false, &rules, &inputs), None);
        assert_eq!(
            select(Mode::Reactive, true, &rules, &inputs),
            Some(Fired::Stimulus)
        );
        assert_eq!(select(Mode::Manual, true, &rules, &inputs), None);
    }

    #[test]
    fn a_rule_uses_its_own_threshold_or_its_predictions_and_never_an_invalid_value() {
        let own = rule("own", 0, Some(0.8), 0);
        let inherited = rule("inherited", 0, None, 0);
        let at = |v: Option<f64>| [input(v, 0.5)];
        assert!(!fires(&own, &at(Some(0.7))));
        assert!(fires(&inherited, &at(Some(0.7))));
        assert!(fires(&own, &at(Some(0.81))));
        assert!(!fires(&inherited, &at(None)));
        assert!(!fires(&inherited, &at(Some(f64::NAN))));
        assert!(!fires(&rule("nan", 0, Some(f64::NAN), 0), &at(Some(1.0))));
        assert!(!fires(&rule("missing", 3, None, 0), &at(Some(1.0))));
    }
}

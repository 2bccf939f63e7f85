//! `[[rules]]`: the rule table of Pavlovian control, several fixed responses each driven by its own
//! prediction (see [`crate::control::rules`] for how the gate uses it).
//!
//! Absent, the table is the paper's single rule: the gate prediction (`control.gate_prediction`), its
//! own threshold and `control.response`, so a configuration without `[[rules]]` behaves exactly as
//! before. Each rule is checked at start-up with its key named (`rules[2].prediction`): the prediction
//! must exist, the threshold must be finite and within the prediction's value range (`[0, 1]` for a
//! logistic σ), the response within the Drive Direct range, names unique, priorities distinct, and at
//! most [`MAX_RULES`] rules.

use serde::{Deserialize, Serialize};

use super::{Config, ConfigError, invalid};
use crate::control::rules::{Rule, STIMULUS_RULE};
use crate::control::{ControlError, Policy};
use crate::learn::Sigma;

/// The most rules a table may hold (each one is checked on every tick).
pub const MAX_RULES: usize = 16;

/// One `[[rules]]` table.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct RuleSpec {
    /// The rule's name as the gate records it (default: the prediction's name).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub name: Option<String>,
    /// The `[[predictions]]` name that drives the rule.
    pub prediction: String,
    /// θ: the rule fires when the prediction is strictly above it (default: the prediction's own
    /// threshold in force, which `set_params` may change).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub threshold: Option<f64>,
    /// The fixed response the rule selects, like `control.response`.
    pub response: Policy,
    /// Larger wins when several rules fire on one tick; two rules may not share a priority.
    pub priority: i64,
}

impl RuleSpec {
    /// The rule's name: its own, or its prediction's.
    pub fn name(&self) -> &str {
        self.name.as_deref().unwrap_or(&self.prediction)
    }
}

/// `policy` checked against the Drive Direct range, with `key` named.
pub(super) fn check_policy(key: &str, policy: &Policy) -> Result<(), ConfigError> {
    policy.validate().map_err(|e| match e {
        ControlError::SpeedOutOfRange { field, speed } => invalid(
            format!("{key}.{field}"),
            format!("{speed} mm/s is outside the Drive Direct range -500..=500 mm/s"),
        ),
    })
}

impl Config {
    /// Checks `[[rules]]` (see the module documentation); the predictions must already be valid.
    pub(super) fn check_rules(&self) -> Result<(), ConfigError> {
        if self.rules.len() > MAX_RULES {
            return Err(invalid(
                "rules",
                format!(
                    "{} rules are more than the {MAX_RULES} allowed",
                    self.rules.len()
                ),
            ));
        }
        for (i, r) in self.rules.iter().enumerate() {
            let Some(p) = self.predictions.iter().find(|p| p.name == r.prediction) else {
                return Err(invalid(
                    format!("rules[{i}].prediction"),
                    format!("no prediction is named `{}`", r.prediction),
                ));
            };
            let name = r.name();
            if let Err(e) = crate::learn::bounds::check_name_length(name) {
                return Err(invalid(format!("rules[{i}].name"), e.to_string()));
            }
            if name.is_empty() || name == STIMULUS_RULE {
                return Err(invalid(
                    format!("rules[{i}].name"),
                    format!("`{name}` is empty or reserved for the stimulus alone"),
                ));
            }
            if let Some(theta) = r.threshold {
                let logistic = p.sigma == Sigma::Logistic;
                if !theta.is_finite() || (logistic && !(0.0..=1.0).contains(&theta)) {
                    let range = if logistic {
                        "within 0..=1 (the range of the logistic σ)"
                    } else {
                        "finite"
                    };
                    return Err(invalid(
                        format!("rules[{i}].threshold"),
                        format!("{theta} must be {range} for prediction `{}`", p.name),
                    ));
                }
            }
            check_policy(&format!("rules[{i}].response"), &r.response)?;
            for (j, q) in self.rules[..i].iter().enumerate() {
                if q.name() == name {
                    return Err(invalid(
                        format!("rules[{i}].name"),
                        format!("`{name}` is also the name of rules[{j}]; give each rule a name"),
                    ));
                }
                if q.priority == r.priority {
                    return Err(invalid(
                        format!("rules[{i}].priority"),
                        format!(
                            "rules[{i}] ({name}) and rules[{j}] ({}) both have priority {}; \
                             priorities must differ",
                            q.name(),
                            r.priority
                        ),
                    ));
                }
            }
        }
        Ok(())
    }

    /// The rule table in force, resolved against the predictions: `[[rules]]`, or the paper's single
    /// rule when there are none. Rules whose prediction does not exist (refused by validation) are left
    /// out.
    pub fn rule_table(&self) -> Vec<Rule> {
        let index = |name: &str| self.predictions.iter().position(|p| p.name == name);
        if self.rules.is_empty() {
            return index(&self.control.gate_prediction)
                .map(|prediction| Rule {
                    name: self.control.gate_prediction.as_str().into(),
                    prediction,
                    threshold: None,
                    response: self.control.response,
                    priority: 0,
                })
                .into_iter()
                .collect();
        }
        self.rules
            .iter()
            .filter_map(|r| {
                Some(Rule {
                    name: r.name().into(),
                    prediction: index(&r.prediction)?,
                    threshold: r.threshold,
                    response: r.response,
                    priority: r.priority,
                })
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const STALL: &str = include_str!("../../config/stall.toml");
    const INTERACTION: &str = include_str!("../../config/interaction.toml");
    const RULES: &str = include_str!("../../config/rules.toml");

    fn with_rules(base: &str, rules: &str) -> String {
        format!("{base}\n{rules}")
    }

    fn refusal(text: &str) -> (String, String) {
        match Config::from_toml(text) {
            Err(ConfigError::Invalid { key, message }) => (key, message),
            other => panic!("expected a refusal, got {other:?}"),
        }
    }

    const STOP_RULE: &str = "[[rules]]\nprediction = \"stall\"\nresponse = { kind = \"stop\" }\n";

    #[test]
    fn without_rules_the_table_is_the_papers_single_rule() {
        let c = Config::from_toml(STALL).unwrap();
        assert!(c.rules.is_empty());
        let table = c.rule_table();
        assert_eq!(table.len(), 1);
        assert_eq!(&*table[0].name, "stall");
        assert_eq!(
            (table[0].prediction, table[0].threshold),
            (0, None),
            "the gate prediction at its own threshold"
        );
        assert_eq!(table[0].response, c.control.response);
        // The table is not written back into a configuration that had none.
        assert!(!toml::to_string(&c).unwrap().contains("rules"));
    }

    #[test]
    fn the_example_rule_table_loads_with_its_names_thresholds_and_priorities() {
        let c = Config::from_toml(RULES).unwrap();
        let table = c.rule_table();
        assert_eq!(table.len(), 2);
        assert_eq!((&*table[0].name, table[0].prediction), ("stall", 0));
        assert_eq!((&*table[1].name, table[1].prediction), ("stall_ahead", 1));
        assert!(table[0].priority > table[1].priority);
        assert_ne!(table[0].response, table[1].response);
        assert_eq!((table[0].threshold, table[1].threshold), (Some(0.5), None));
    }

    #[test]
    fn each_bad_rule_is_refused_naming_its_key() {
        let second = |extra: &str| with_rules(STALL, &format!("{STOP_RULE}priority = 0\n{extra}"));
        let cases = [
            (
                second(
                    "[[rules]]\nprediction = \"nope\"\nresponse = { kind = \"stop\" }\npriority = 1\n",
                ),
                "rules[1].prediction",
                "nope",
            ),
            (
                second(
                    "[[rules]]\nname = \"b\"\nprediction = \"stall\"\nthreshold = nan\nresponse = { kind = \"stop\" }\npriority = 1\n",
                ),
                "rules[1].threshold",
                "finite",
            ),
            (
                second(
                    "[[rules]]\nname = \"b\"\nprediction = \"stall\"\nthreshold = inf\nresponse = { kind = \"stop\" }\npriority = 1\n",
                ),
                "rules[1].threshold",
                "finite",
            ),
            (
                second(
                    "[[rules]]\nprediction = \"stall\"\nresponse = { kind = \"stop\" }\npriority = 1\n",
                ),
                "rules[1].name",
                "also the name of rules[0]",
            ),
            (
                second(
                    "[[rules]]\nname = \"b\"\nprediction = \"stall\"\nresponse = { kind = \"stop\" }\npriority = 0\n",
                ),
                "rules[1].priority",
                "rules[1] (b) and rules[0] (stall) both have priority 0",
            ),
            (
                second(
                    "[[rules]]\nname = \"b\"\nprediction = \"stall\"\nresponse = { kind = \"constant\", left_mm_s = 600, right_mm_s = 0 }\npriority = 1\n",
                ),
                "rules[1].response.left_mm_s",
                "-500..=500",
            ),
            (
                second(
                    "[[rules]]\nname = \"stimulus\"\nprediction = \"stall\"\nresponse = { kind = \"stop\" }\npriority = 1\n",
                ),
                "rules[1].name",
                "reserved",
            ),
        ];
        for (text, key, words) in cases {
            let (k, message) = refusal(&text);
            assert_eq!(k, key, "{message}");
            assert!(message.contains(words), "{key}: {message}");
        }
        // A missing priority or an unknown key is a parse error that names it.
        let e = Config::from_toml(&with_rules(STALL, STOP_RULE)).unwrap_err();
        assert!(e.to_string().contains("priority"), "{e}");
        let e = Config::from_toml(&with_rules(
            STALL,
            &format!("{STOP_RULE}priority = 0\nprio = 1\n"),
        ))
        .unwrap_err();
        assert!(e.to_string().contains("prio"), "{e}");
    }

    #[test]
    fn a_logistic_predictions_rule_threshold_must_lie_in_its_range() {
        let rule = |theta: &str| {
            with_rules(
                INTERACTION,
                &format!(
                    "[[rules]]\nprediction = \"command\"\nthreshold = {theta}\n\
                     response = {{ kind = \"stop\" }}\npriority = 0\n"
                ),
            )
        };
        let (key, message) = refusal(&rule("1.5"));
        assert_eq!(key, "rules[0].threshold");
        assert!(message.contains("0..=1"), "{message}");
        Config::from_toml(&rule("0.9")).unwrap();
        // An identity prediction's threshold only has to be finite.
        Config::from_toml(&with_rules(
            STALL,
            &format!("{STOP_RULE}priority = 0\nthreshold = -2.5\n"),
        ))
        .unwrap();
    }

    #[test]
    fn the_number_of_rules_is_bounded() {
        let many: String = (0..=MAX_RULES)
            .map(|k| {
                format!(
                    "[[rules]]\nname = \"r{k}\"\nprediction = \"stall\"\n\
                     response = {{ kind = \"stop\" }}\npriority = {k}\n"
                )
            })
            .collect();
        let (key, message) = refusal(&with_rules(STALL, &many));
        assert_eq!(key, "rules");
        assert!(
            message.contains("17 rules") && message.contains("16"),
            "{message}"
        );
        let fits: String = many
            .split("[[rules]]")
            .skip(2)
            .map(|r| format!("[[rules]]{r}"))
            .collect();
        assert_eq!(
            Config::from_toml(&with_rules(STALL, &fits))
                .unwrap()
                .rules
                .len(),
            MAX_RULES
        );
    }
}

//! `[horde]`: many general predictions learned beside the control predictions, off the control path.
//!
//! The Horde's predictions never drive the gate (`[control] gate_prediction` names one of
//! `[[predictions]]`): they are learned on a thread of their own from the same ticks, and shown on the
//! dashboard. Their families are documented in [`crate::learn::horde::family`].

use serde::{Deserialize, Serialize};

use super::{ConfigError, invalid};
use crate::learn::{FamilySpec, SignalNames};

/// The Horde's weights' type.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Precision {
    /// 4 bytes a weight: twice the predictions in the same memory and time; about 1e-5 from the f64
    /// result over a run (measured in `learn::group`'s tests).
    #[default]
    F32,
    /// 8 bytes a weight, the control predictions' type.
    F64,
}

/// How the Horde's threads are scheduled against the rest of the server's (`[horde] scheduling`).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Scheduling {
    /// Linux's `SCHED_IDLE`: any other thread that wakes preempts the Horde at once, so on a machine with
    /// few cores the Horde never holds up the tick's threads; while the machine is busy with other work
    /// it gets almost no CPU and skips ticks (counted).
    #[default]
    Idle,
    /// The normal policy: the Horde keeps up better on a busy machine, and a tick-path thread woken on
    /// its core may wait up to a scheduler slice (a few ms) for it.
    Normal,
}

/// `[horde]`.
#[derive(Debug, Clone, PartialEq, Default, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct HordeConfig {
    /// The weights' type.
    pub precision: Precision,
    /// `[[horde.families]]`: empty means no Horde.
    pub families: Vec<FamilySpec>,
    /// How the Horde's threads are scheduled.
    pub scheduling: Scheduling,
}

impl HordeConfig {
    /// Whether there is a Horde to run.
    pub fn is_enabled(&self) -> bool {
        !self.families.is_empty()
    }

    /// No Horde and the default precision: nothing to write into a configuration.
    pub fn is_off(&self) -> bool {
        *self == HordeConfig::default()
    }

    /// Checks every family and the Horde's size against its bounds over the signals `names`, without
    /// allocating any weight.
    pub(super) fn validate(&self, names: &SignalNames) -> Result<(), ConfigError> {
        if !self.is_enabled() {
            return Ok(());
        }
        // A name too long to quote whole in a message is named by its position.
        for (i, f) in self.families.iter().enumerate() {
            crate::learn::bounds::check_name_length(&f.name)
                .map_err(|e| invalid(format!("horde.families[{i}]"), e.to_string()))?;
        }
        crate::learn::horde::check(&self.families, names).map_err(|e| {
            // Name the family in the key when the error does.
            let key = self
                .families
                .iter()
                .position(|f| e.to_string().contains(&format!("`{}`", f.name)))
                .map_or_else(
                    || "horde.families".to_string(),
                    |i| format!("horde.families[{i}]"),
                );
            invalid(key, e.to_string())
        })?;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::Config;

    const STALL: &str = include_str!("../../config/stall.toml");

    fn with_horde(family: &str) -> String {
        format!("{STALL}\n[horde]\nprecision = \"f32\"\n[[horde.families]]\n{family}")
    }

    const NEXTING: &str = r#"
        name = "nexting"
        cumulants = ["obs/*", "raw/battery_charge"]
        taus = [2.0, 10.0]
        lambda = 0.9
        alpha = 0.0002
        terminate_on = "stall"
        features = { kind = "one_dim", all_obs = true, tiles = 12, tilings = 11 }
    "#;

    #[test]
    fn a_horde_is_configured_in_a_few_lines() {
        let cfg = Config::from_toml(&with_horde(NEXTING)).unwrap();
        assert!(cfg.horde.is_enabled());
        let shape = crate::learn::horde::check(&cfg.horde.families, &cfg.signal_names()).unwrap();
        assert_eq!(shape.predictions, 90);
        // No [horde] at all: nothing changes, and nothing is written back.
        let plain = Config::from_toml(STALL).unwrap();
        assert!(plain.horde.is_off());
        assert!(!toml::to_string(&plain).unwrap().contains("horde"));
    }

    #[test]
    fn the_shipped_horde_config_is_the_stall_study_plus_a_nexting_horde() {
        let text = include_str!("../../config/horde.toml");
        let cfg = Config::from_toml(text).unwrap();
        let shape = crate::learn::horde::check(&cfg.horde.families, &cfg.signal_names()).unwrap();
        // About 10⁴ predictions over one shared tile coding of ~6,000 features, ≥ 450 active.
        assert_eq!(shape.predictions, 44 * 6 + 2 * 6 + 5808 * 2);
        assert_eq!(shape.feature_sets, 1, "one tile coding per tick for all");
        assert_eq!(shape.active_features, 484);
        assert_eq!(shape.weights, shape.predictions * 5808);
        // Without [horde] it is the stall study, key for key: the Horde changes no control setting.
        let mut control = cfg.clone();
        control.horde = super::HordeConfig::default();
        assert_eq!(control, Config::from_toml(STALL).unwrap());
    }

    #[test]
    fn the_shipped_learners_config_runs_every_horde_learner() {
        use crate::learn::LearnerKind;
        let text = include_str!("../../config/horde-learners.toml");
        let cfg = Config::from_toml(text).unwrap();
        let learners: Vec<LearnerKind> = cfg.horde.families.iter().map(|f| f.learner).collect();
        assert_eq!(
            learners,
            [
                LearnerKind::Td,
                LearnerKind::Xent,
                LearnerKind::TrueOnline,
                LearnerKind::Autostep
            ]
        );
        let shape = crate::learn::horde::check(&cfg.horde.families, &cfg.signal_names()).unwrap();
        assert_eq!((shape.predictions, shape.feature_sets), (272, 1));
        assert_eq!(shape.weights, 272 * 2112);
        // A group per τ for each learner (xent's two logistic predictions: one each).
        assert_eq!(shape.groups, 4 * 2);
    }

    #[test]
    fn a_bad_family_is_refused_with_its_key() {
        for (edit, says) in [
            (
                NEXTING.replace("raw/battery_charge", "raw/nose"),
                "raw/nose",
            ),
            (NEXTING.replace("0.0002", "0.01"), "exceeds 1/484"),
            (NEXTING.replace("\"stall\"", "\"bump\""), "bump"),
            (NEXTING.replace("tilings = 11", "tilings = 0"), "tilings"),
            // Careless values: an endless timescale, a huge name, a cumulant listed twice.
            (NEXTING.replace("10.0]", "1e300]"), "at most 1e6"),
            (
                NEXTING.replace("\"nexting\"", &format!("\"{}\"", "n".repeat(1 << 20))),
                "1048576 characters; at most 64",
            ),
            (
                NEXTING.replace(
                    "\"raw/battery_charge\"",
                    "\"raw/battery_charge\", \"obs/bump_left\"",
                ),
                "lists cumulant `obs/bump_left` twice",
            ),
        ] {
            match Config::from_toml(&with_horde(&edit)) {
                Err(super::ConfigError::Invalid { key, message }) => {
                    assert_eq!(key, "horde.families[0]", "{message}");
                    assert!(message.contains(says), "{message}");
                }
                other => panic!("{other:?}"),
            }
        }
        let typo = with_horde(&NEXTING.replace("taus", "tau"));
        assert!(Config::from_toml(&typo).is_err());
    }
}

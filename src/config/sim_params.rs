//! `[sim.params]`: optional changes to the simulated robot's physical parameters, for robustness studies
//! (`pavlov experiment stall --variations`). Every key is absent by default, and an absent key leaves the
//! model's documented value ([`crate::sim::params::SimParams::for_model`]) untouched, so a configuration
//! without `[sim.params]` simulates exactly what it did before the table existed (the test
//! `defaults_simulate_the_same_bytes_as_before` pins the byte stream of a default run).

use serde::{Deserialize, Serialize};

use super::{ConfigError, invalid};
use crate::sim::params::SimParams;

/// `[sim.params]`: each key, when present, replaces (or, for `friction_scale`, scales) one physical
/// parameter of the simulated robot before any lab variation is drawn. Absent keys change nothing.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct SimParamsOverrides {
    /// The enclosure's short walls, m (default 1.0, the paper's "one meter"); the start position moves
    /// with it to the centroid (L/3, L/3).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub enclosure_leg_m: Option<f64>,
    /// The weight on the robot, kg (default 2.0, the paper's "approximately two kilograms").
    #[serde(skip_serializing_if = "Option::is_none")]
    pub payload_kg: Option<f64>,
    /// A factor on the wheels' kinetic, breakaway and viscous friction (default 1: the model's values).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub friction_scale: Option<f64>,
    /// The current a blocked motor demands at full duty, A (default 1.5); must exceed the over-current
    /// limit.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub stall_current_a: Option<f64>,
    /// The pack's internal resistance, Ω (default 0.35 on the Create 1, 0.25 on the Create 2).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub internal_resistance_ohm: Option<f64>,
    /// Noise of the reported battery current, mA (default 6).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub current_noise_ma: Option<f64>,
    /// Time constant of the firmware's current measurement, s (default 0.03).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub current_sense_tau_s: Option<f64>,
    /// Softness of the over-current flag's threshold, A (default 0.12).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub overcurrent_scale_a: Option<f64>,
    /// Whether the driver limits a wheel's current to the over-current limit (default true: our reading of
    /// [C1 p10, p17]; false: the current is only flagged, never limited).
    #[serde(skip_serializing_if = "Option::is_none")]
    pub limit_wheel_current: Option<bool>,
}

impl SimParamsOverrides {
    /// True when no key is set (the table is then left out of a written configuration).
    pub fn is_empty(&self) -> bool {
        *self == SimParamsOverrides::default()
    }

    /// `params` with every set key applied.
    pub fn apply(&self, params: &SimParams) -> SimParams {
        let mut p = params.clone();
        if let Some(l) = self.enclosure_leg_m {
            p.enclosure_leg_m = l;
            p.start_x_m = l / 3.0;
            p.start_y_m = l / 3.0;
        }
        if let Some(v) = self.payload_kg {
            p.payload_kg = v;
        }
        if let Some(f) = self.friction_scale {
            p.friction_current_a *= f;
            p.breakaway_current_a *= f;
            p.viscous_current_a_per_m_s *= f;
        }
        if let Some(v) = self.stall_current_a {
            p.stall_current_a = v;
        }
        if let Some(v) = self.internal_resistance_ohm {
            p.internal_resistance_ohm = v;
        }
        if let Some(v) = self.current_noise_ma {
            p.current_noise_ma = v;
        }
        if let Some(v) = self.current_sense_tau_s {
            p.current_sense_tau_s = v;
        }
        if let Some(v) = self.overcurrent_scale_a {
            p.overcurrent_scale_a = v;
        }
        if let Some(v) = self.limit_wheel_current {
            p.limit_wheel_current = v;
        }
        p
    }

    /// Refuses values the simulation cannot run with, naming the key.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let checks: [(&str, Option<f64>, f64, f64); 8] = [
            ("enclosure_leg_m", self.enclosure_leg_m, 0.6, 10.0),
            ("payload_kg", self.payload_kg, 0.0, 20.0),
            ("friction_scale", self.friction_scale, 0.1, 10.0),
            ("stall_current_a", self.stall_current_a, 1.05, 20.0),
            (
                "internal_resistance_ohm",
                self.internal_resistance_ohm,
                0.0,
                5.0,
            ),
            ("current_noise_ma", self.current_noise_ma, 0.0, 1000.0),
            ("current_sense_tau_s", self.current_sense_tau_s, 0.0, 1.0),
            ("overcurrent_scale_a", self.overcurrent_scale_a, 0.001, 5.0),
        ];
        for (key, value, lo, hi) in checks {
            if let Some(v) = value
                && !(v.is_finite() && (lo..=hi).contains(&v))
            {
                return Err(invalid(
                    format!("sim.params.{key}"),
                    format!("{v} is outside {lo}..={hi}"),
                ));
            }
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::super::SimConfig;
    use super::*;
    use crate::oi::Model;
    use crate::sim::robot::SimRobot;

    /// FNV-1a over a byte stream.
    fn fnv(bytes: &[u8], mut h: u64) -> u64 {
        for &b in bytes {
            h ^= u64::from(b);
            h = h.wrapping_mul(0x0000_0100_0000_01b3);
        }
        h
    }

    /// The stream bytes of a robot started, streamed and driven through the stall cycle's phases
    /// (straight into a wall and back, turns) for `steps` 15 ms steps, hashed.
    fn digest(sim: &SimConfig, model: Model, steps: usize) -> u64 {
        let mut r = SimRobot::new(model, sim.robot_params(model), sim.seed);
        r.receive(&[128, 131, 148, 1, 6]);
        let mut h = 0xcbf2_9ce4_8422_2325;
        for i in 0..steps {
            let phase = (i / 200) % 4;
            let (l, rr): (i16, i16) = match phase {
                0 => (100, -100),
                1 => (200, 200),
                2 => (100, -100),
                _ => (-200, -200),
            };
            if i % 200 == 0 {
                let mut cmd = vec![145];
                cmd.extend_from_slice(&rr.to_be_bytes());
                cmd.extend_from_slice(&l.to_be_bytes());
                r.receive(&cmd);
            }
            r.step();
            h = fnv(&r.take_output(), h);
        }
        h
    }

    /// The digests of [`digest`] (seed 11, 4000 steps) computed on the code before `[sim.params]` existed
    /// (commit 91e4d16): (lab variation, model, digest).
    const BEFORE: [(bool, Model, u64); 3] = [
        (false, Model::Create1, 0xce06_39cd_f351_6011),
        (true, Model::Create1, 0x83d7_74a6_b90b_f217),
        (true, Model::Create2, 0x558a_59f5_84bc_2307),
    ];

    /// Every key set to the Create 1's documented value.
    fn create1_defaults() -> SimParamsOverrides {
        SimParamsOverrides {
            enclosure_leg_m: Some(1.0),
            payload_kg: Some(2.0),
            friction_scale: Some(1.0),
            stall_current_a: Some(1.5),
            internal_resistance_ohm: Some(0.35),
            current_noise_ma: Some(6.0),
            current_sense_tau_s: Some(0.03),
            overcurrent_scale_a: Some(0.12),
            limit_wheel_current: Some(true),
        }
    }

    #[test]
    fn defaults_simulate_the_same_bytes_as_before() {
        for (lab, model, before) in BEFORE {
            let sim = SimConfig {
                seed: 11,
                lab_variation: lab,
                ..SimConfig::default()
            };
            assert_eq!(digest(&sim, model, 4000), before, "{lab} {model:?}");
        }
        // Every key given its documented value simulates the same bytes too.
        for lab in [false, true] {
            let sim = SimConfig {
                seed: 11,
                lab_variation: lab,
                params: create1_defaults(),
                ..SimConfig::default()
            };
            let before = BEFORE.iter().find(|b| b.0 == lab && b.1 == Model::Create1);
            assert_eq!(
                Some(digest(&sim, Model::Create1, 4000)),
                before.map(|b| b.2)
            );
        }
    }

    #[test]
    fn a_key_changes_what_it_names_and_nothing_else() {
        let base = SimParams::for_model(Model::Create1);
        assert_eq!(SimParamsOverrides::default().apply(&base), base);
        assert_eq!(create1_defaults().apply(&base), base);
        let off = SimParamsOverrides {
            limit_wheel_current: Some(false),
            ..SimParamsOverrides::default()
        };
        assert_eq!(
            off.apply(&base),
            SimParams {
                limit_wheel_current: false,
                ..base.clone()
            }
        );
        let sim = SimConfig {
            seed: 11,
            params: off,
            ..SimConfig::default()
        };
        assert_ne!(digest(&sim, Model::Create1, 4000), BEFORE[0].2);
        let leg = SimParamsOverrides {
            enclosure_leg_m: Some(1.2),
            friction_scale: Some(2.0),
            ..SimParamsOverrides::default()
        }
        .apply(&base);
        assert_eq!((leg.enclosure_leg_m, leg.start_x_m), (1.2, 1.2 / 3.0));
        assert_eq!(leg.breakaway_current_a, 2.0 * base.breakaway_current_a);
    }

    #[test]
    fn the_table_is_left_out_unless_set_and_bad_values_name_their_key() {
        let text = toml::to_string(&SimConfig::default()).unwrap();
        assert!(!text.contains("params"), "{text}");
        let back: SimConfig = toml::from_str("seed = 3\n[params]\nfriction_scale = 1.4\n").unwrap();
        assert_eq!(back.params.friction_scale, Some(1.4));
        let bad = SimParamsOverrides {
            stall_current_a: Some(0.5),
            ..SimParamsOverrides::default()
        };
        let e = bad.validate().unwrap_err().to_string();
        assert!(e.contains("sim.params.stall_current_a"), "{e}");
        assert!(toml::from_str::<SimConfig>("[params]\nnope = 1\n").is_err());
    }
}

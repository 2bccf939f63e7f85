//! [`StochasticGate`]: the mixing function `f = 1 − ε` where a prediction's rule fires (`[control] gate =
//! "stochastic"`), its random draws, and the behaviour probability b(A|S) it logs.
//!
//! Where a rule fires and the stimulus is off, the response ϱ acts with probability 1 − ε and the default
//! policy π's action is taken with probability ε; everywhere else the choice is the paper's (certain). So
//! the behaviour probability of the action taken is
//!
//! ```text
//! b(A|S) = ε       π's action drawn in the gate region
//!          1 − ε   the response drawn in the gate region
//!          1       everywhere else (and wherever ϱ's action equals π's: both draws give it)
//! ```
//!
//! and the importance sampling ratio of an off-policy prediction about π is ρ = π(A|S)/b(A|S): 1/ε on
//! π's action in the region, 1 on π's action elsewhere, 0 on any other action
//! ([`crate::agent::learning::importance_ratio`]). The stimulus stays a certain stop: the stochastic gate
//! explores only where the paper's gate would have acted on a prediction alone, never where the reactive
//! safety response is due.
//!
//! **Replay exact.** Tick `seq`'s draw is a function of the run's seed (`[sim] seed`) and `seq` only:
//! `Rng::new(seed).fork(GATE_STREAM).fork(seq).next_f64()` ([`crate::rng`]). No state carries from one
//! draw to the next, so a recording replays bit for bit wherever it starts, whichever ticks the runtime
//! dropped, and the draws never shift the simulator's own random streams.

use crate::config::Config;
use crate::control::{Action, GateKind};
use crate::rng::Rng;

/// The stream the gate's draws fork from the run's seed ("gate").
pub const GATE_STREAM: u64 = 0x6A7E;

/// The stochastic gate of one run.
#[derive(Debug, Clone, PartialEq)]
pub struct StochasticGate {
    epsilon: f64,
    base: Rng,
}

/// What the stochastic gate chose in its region.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GateDraw {
    /// The action taken.
    pub action: Action,
    /// Whether it is π's (drawn with probability ε), rather than the response's.
    pub took_default: bool,
    /// b(A|S) of the action taken.
    pub behaviour_prob: f64,
}

impl StochasticGate {
    /// A gate that takes π's action with probability `epsilon` (in (0, 1), as the configuration checks),
    /// drawing from `seed`.
    pub fn new(epsilon: f64, seed: u64) -> Self {
        StochasticGate {
            epsilon,
            base: Rng::new(seed).fork(GATE_STREAM),
        }
    }

    /// The configuration's stochastic gate, seeded by `[sim] seed`; `None` for the paper's gate.
    pub fn from_config(config: &Config) -> Option<Self> {
        match (config.control.gate, config.control.epsilon) {
            (GateKind::Stochastic, Some(eps)) => Some(StochasticGate::new(eps, config.sim.seed)),
            _ => None,
        }
    }

    /// ε: the probability of π's action in the gate region.
    pub fn epsilon(&self) -> f64 {
        self.epsilon
    }

    /// Tick `seq`'s uniform draw in `[0, 1)`: a function of the seed and `seq` alone.
    pub fn draw(&self, seq: u64) -> f64 {
        self.base.fork(seq).next_f64()
    }

    /// The choice on tick `seq` in the gate region, between the `response`'s action and π's `default`.
    pub fn choose(&self, seq: u64, response: Action, default: Action) -> GateDraw {
        if response == default {
            return GateDraw {
                action: default,
                took_default: true,
                behaviour_prob: 1.0,
            };
        }
        if self.draw(seq) < self.epsilon {
            GateDraw {
                action: default,
                took_default: true,
                behaviour_prob: self.epsilon,
            }
        } else {
            GateDraw {
                action: response,
                took_default: false,
                behaviour_prob: 1.0 - self.epsilon,
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const FORWARD: Action = Action {
        left_mm_s: 200,
        right_mm_s: 200,
    };

    #[test]
    fn b_is_epsilon_on_pis_action_and_one_minus_epsilon_on_the_response() {
        let g = StochasticGate::new(0.25, 7);
        let (mut pi, n) = (0usize, 20_000u64);
        for seq in 0..n {
            let d = g.choose(seq, Action::STOP, FORWARD);
            if d.took_default {
                pi += 1;
                assert_eq!((d.action, d.behaviour_prob), (FORWARD, 0.25));
            } else {
                assert_eq!((d.action, d.behaviour_prob), (Action::STOP, 0.75));
            }
            // The choice is the draw against ε, and the draw is the seed's and the tick's alone.
            assert_eq!(d.took_default, g.draw(seq) < 0.25);
            assert_eq!(
                d,
                StochasticGate::new(0.25, 7).choose(seq, Action::STOP, FORWARD)
            );
        }
        // π's share is ε within 4 binomial SDs (√(n·ε(1−ε)) ≈ 61 ticks).
        let expected = 0.25 * n as f64;
        assert!((pi as f64 - expected).abs() < 4.0 * 61.3, "{pi} of {n}");
        // Another seed draws otherwise.
        let other = StochasticGate::new(0.25, 8);
        assert!((0..64).any(|s| other.draw(s) != g.draw(s)));
    }

    #[test]
    fn a_response_equal_to_pis_action_is_certain() {
        let g = StochasticGate::new(0.5, 1);
        for seq in 0..100 {
            let d = g.choose(seq, FORWARD, FORWARD);
            assert_eq!((d.action, d.behaviour_prob), (FORWARD, 1.0));
        }
    }

    #[test]
    fn rho_is_one_over_b_on_pis_action_and_zero_off_it() {
        use crate::agent::learning::importance_ratio;
        // (π's command?, b, ρ)
        let cases = [
            (true, 1.0, 1.0),  // π's action outside the region (or the paper's gate)
            (false, 1.0, 0.0), // the response, certain (or a safety stop)
            (true, 0.5, 2.0),  // π's action drawn with ε = 0.5
            (true, 0.2, 5.0),  // … with ε = 0.2
            (false, 0.8, 0.0), // the response drawn with 1 − ε = 0.8
            (true, 0.0, 0.0),  // not a probability of an action taken
            (true, f64::NAN, 0.0),
            (true, 1.5, 0.0),
        ];
        for (followed, b, rho) in cases {
            assert_eq!(
                importance_ratio(followed, b),
                rho,
                "followed {followed}, b {b}"
            );
        }
    }

    /// A stall configuration with an off-policy prediction about π, a stochastic gate of ε = 0.5 and
    /// the largest α it allows (0.5/44).
    fn offpolicy_stochastic() -> Config {
        let text = include_str!("../../config/stall.toml").replace(
            "response = { kind = \"stop\" }",
            "response = { kind = \"stop\" }\ngate = \"stochastic\"\nepsilon = 0.5",
        ) + "\n[[predictions]]\nname = \"stall_pi\"\ntau = 25.0\nlambda = 0.5\nalpha = 0.011363636363636364\n\
             sigma = \"identity\"\nthreshold = { fixed = 0.5 }\ncumulant = { stimulus = \"stall\" }\n\
             features = { kind = \"one_dim\", all_obs = true, tiles = 10 }\nlearner = \"gtd\"\n\
             target_policy = \"default\"\nbeta = 0.0011363636363636363\n";
        Config::from_toml(&text).unwrap()
    }

    /// The GTD prediction's weights after two ticks from scratch, the second one with E on (R = 1) and
    /// reached by a command of ratio `followed`, `b`.
    fn after_one_update(followed: bool, b: f64) -> Vec<f64> {
        use crate::agent::{LearnInput, LearningStage};
        let mut stage = LearningStage::new(&offpolicy_stochastic()).unwrap();
        let mut values = crate::oi::SensorValues::new();
        for id in 7u8..=42 {
            values.set(id, 0);
        }
        for forced in [false, true] {
            stage.act(LearnInput {
                values: Some(&values),
                elbow: None,
                forced_stimulus: forced,
                previous_followed_default: followed,
                previous_behaviour_prob: b,
            });
            stage.learn().unwrap();
        }
        stage.snapshot().predictions[1].weights.clone()
    }

    #[test]
    fn the_learning_stage_hands_gtd_rho_one_over_b() {
        // From θ = w = e = 0, the first update is θ += α δ ρ x_t with δ = R = 1 (the secondary
        // correction is 0): α ρ on each of the 44 active features of x_t.
        let alpha = 0.5 / 44.0;
        let active = |w: &[f64]| {
            w.iter()
                .filter(|&&x| x != 0.0)
                .copied()
                .collect::<Vec<f64>>()
        };
        let certain = active(&after_one_update(true, 1.0));
        assert_eq!(certain.len(), 44);
        assert!(
            certain.iter().all(|&x| (x - alpha).abs() < 1e-15),
            "{certain:?}"
        );
        // π's action drawn with b = ε = 0.5: ρ = 2, twice the step.
        let drawn = active(&after_one_update(true, 0.5));
        assert!(
            drawn.iter().all(|&x| (x - 2.0 * alpha).abs() < 1e-15),
            "{drawn:?}"
        );
        assert_eq!(drawn.len(), 44);
        // The response (b = 1 − ε): ρ = 0, nothing moves.
        assert!(active(&after_one_update(false, 0.5)).is_empty());
    }

    #[test]
    fn runtime_changes_keep_the_step_size_bound() {
        let mut stage = crate::agent::LearningStage::new(&offpolicy_stochastic()).unwrap();
        let e = stage
            .set_params(Some("stall_pi"), Some(1.0 / 44.0), None, None)
            .unwrap_err();
        assert!(e.to_string().contains("α·ρ_max·‖x‖² ≤ 1"), "{e}");
        let p = stage.params(Some("stall_pi")).unwrap();
        assert_eq!((p.alpha, p.bounds.max_alpha), (0.5 / 44.0, 0.5 / 44.0));
        assert_eq!(
            stage.params(Some("stall")).unwrap().bounds.max_alpha,
            1.0 / 44.0
        );
        stage
            .set_params(Some("stall_pi"), Some(0.25 / 44.0), None, None)
            .unwrap();
        // The on-policy prediction keeps 1/44.
        stage
            .set_params(Some("stall"), Some(1.0 / 44.0), None, None)
            .unwrap();
    }

    #[test]
    fn the_configuration_seeds_the_gate_with_the_runs_seed() {
        let text = include_str!("../../config/stall.toml");
        let det = Config::from_toml(text).unwrap();
        assert_eq!(StochasticGate::from_config(&det), None);
        let sto = Config::from_toml(&text.replace(
            "response = { kind = \"stop\" }",
            "response = { kind = \"stop\" }\ngate = \"stochastic\"\nepsilon = 0.35",
        ))
        .unwrap();
        let g = StochasticGate::from_config(&sto).unwrap();
        assert_eq!(g, StochasticGate::new(0.35, sto.sim.seed));
        assert_eq!(g.epsilon(), 0.35);
    }
}

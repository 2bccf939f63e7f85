//! How accurate a stall prediction is against the return the default policy π would have earned,
//! measured where π was actually followed.
//!
//! The prediction at tick t estimates `G_t = Σ_{k≥1} (Π_{j<k} γ_{t+j}) R_{t+k}` with R = I{E} and
//! γ = (1 − I{E})(1 − 1/τ): `G_t = (1 − 1/τ)^{k−1}` where t + k is the first tick after t with the
//! stimulus, or 0 when there is none. That is the return π would have earned only if every command from
//! t to t + k − 1 was π's (the response from t + k on does not matter: the return has ended). So a tick
//! is scored only when π was followed until the next stimulus, or for [`HORIZON_TICKS`] ticks when none
//! came (the return is then below (1 − 1/τ)^HORIZON ≈ 4e−5 for τ = 25, and counted as 0). The last
//! `HORIZON_TICKS` ticks of a run, whose return is not yet known, are not scored.
//!
//! Both predictions are scored on the *same* ticks against the *same* target: a tick counts only when π's
//! return is known there and both predictions have a value, so their errors are comparable tick for tick.
//! What this does not show: in reactive runs π is always followed and both predictions are on-policy in
//! effect, so their difference is TD(λ) against GTD(λ) on identical targets — two algorithms, not on-
//! against off-policy learning; in runs gated by a prediction the scored ticks are those on which the gate
//! stayed off, that is, selected by the gating prediction's own values (its misses), which favours neither
//! prediction knowingly but is not a random sample of the run.

use serde::{Deserialize, Serialize};

/// How far ahead a return is followed (5 s at 50 Hz: 10 τ for the stall prediction).
pub(crate) const HORIZON_TICKS: usize = 250;

/// One tick, as the accuracy needs it.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Step {
    /// The predictions scored, in [`PiReturns::names`] order (NaN when missing).
    pub(crate) values: [f64; 2],
    /// The command was π's.
    pub(crate) followed: bool,
    /// The stimulus E.
    pub(crate) stimulus: bool,
}

/// The error of one prediction against π's return over the scored ticks of one run.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct Scored {
    /// Ticks scored.
    pub n: usize,
    /// Root mean squared error.
    pub rmse: f64,
    /// Mean of prediction − return.
    pub bias: f64,
    /// Mean return over the scored ticks.
    pub mean_return: f64,
    /// RMSE over the scored ticks whose return is above 0.5 (the prediction should cross θ there).
    pub rmse_near: f64,
    /// Ticks with a return above 0.5.
    pub n_near: usize,
}

/// Both predictions' accuracy in one run: the on-policy (`stall`) and the off-policy one.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize, Deserialize)]
pub struct RunAccuracy {
    /// The on-policy TD(λ) prediction.
    pub on_policy: Scored,
    /// The off-policy GTD(λ) prediction about π.
    pub off_policy: Scored,
    /// Ticks on which π was followed, of all ticks.
    pub followed_fraction: f64,
}

/// Collects the ticks of one run.
#[derive(Debug, Clone)]
pub(crate) struct PiReturns {
    /// The names of the two predictions scored: on-policy, off-policy.
    pub(crate) names: [String; 2],
    continuation: f64,
    steps: Vec<Step>,
}

impl PiReturns {
    /// `continuation` is 1 − 1/τ of both predictions.
    pub(crate) fn new(on_policy: &str, off_policy: &str, continuation: f64) -> Self {
        PiReturns {
            names: [on_policy.to_string(), off_policy.to_string()],
            continuation,
            steps: Vec::new(),
        }
    }

    /// One tick's record.
    pub(crate) fn observe(&mut self, r: &pavlov::record::TickRecord) {
        let value = |name: &str| {
            r.predictions
                .iter()
                .find(|p| p.name == name)
                .map_or(f64::NAN, |p| p.value)
        };
        self.steps.push(Step {
            values: [value(&self.names[0]), value(&self.names[1])],
            followed: pavlov::agent::learning::followed_default(r.command, r.default_action),
            stimulus: r.stimulus,
        });
    }

    /// The return π would have earned from tick `t`, when π was followed long enough to know it.
    fn pi_return(&self, t: usize) -> Option<f64> {
        if t + HORIZON_TICKS >= self.steps.len() {
            return None;
        }
        let mut discount = 1.0;
        for j in t..t + HORIZON_TICKS {
            if !self.steps[j].followed {
                return None;
            }
            if self.steps[j + 1].stimulus {
                return Some(discount);
            }
            discount *= self.continuation;
        }
        Some(0.0)
    }

    /// The accuracy over the run.
    pub(crate) fn finish(&self) -> RunAccuracy {
        let mut sums = [[0.0f64; 5]; 2]; // n, Σe², Σe, ΣG, and Σe² near
        let mut near = [0usize; 2];
        for t in 0..self.steps.len() {
            let Some(g) = self.pi_return(t) else {
                continue;
            };
            // The same ticks for both: skip a tick when either prediction has no value.
            if self.steps[t].values.iter().any(|v| !v.is_finite()) {
                continue;
            }
            for (k, s) in sums.iter_mut().enumerate() {
                let v = self.steps[t].values[k];
                let e = v - g;
                s[0] += 1.0;
                s[1] += e * e;
                s[2] += e;
                s[3] += g;
                if g > 0.5 {
                    s[4] += e * e;
                    near[k] += 1;
                }
            }
        }
        let scored = |k: usize| {
            let s = sums[k];
            let n = s[0];
            if n == 0.0 {
                return Scored::default();
            }
            Scored {
                n: n as usize,
                rmse: (s[1] / n).sqrt(),
                bias: s[2] / n,
                mean_return: s[3] / n,
                rmse_near: if near[k] > 0 {
                    (s[4] / near[k] as f64).sqrt()
                } else {
                    f64::NAN
                },
                n_near: near[k],
            }
        };
        let followed = self.steps.iter().filter(|s| s.followed).count();
        RunAccuracy {
            on_policy: scored(0),
            off_policy: scored(1),
            followed_fraction: followed as f64 / self.steps.len().max(1) as f64,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn steps(pattern: &[(bool, bool)], values: [f64; 2]) -> PiReturns {
        let mut p = PiReturns::new("on", "off", 0.5);
        p.steps = pattern
            .iter()
            .map(|&(followed, stimulus)| Step {
                values,
                followed,
                stimulus,
            })
            .collect();
        // Pad with followed, stimulus-free ticks so that every tick's horizon fits.
        p.steps.extend(std::iter::repeat_n(
            Step {
                values,
                followed: true,
                stimulus: false,
            },
            HORIZON_TICKS + 1,
        ));
        p
    }

    #[test]
    fn returns_are_scored_only_where_pi_was_followed_until_the_stimulus() {
        // t0 followed, t1 followed, t2 has E: G0 = 0.5, G1 = 1.
        let p = steps(&[(true, false), (true, false), (false, true)], [0.0, 0.0]);
        assert_eq!(p.pi_return(0), Some(0.5));
        assert_eq!(p.pi_return(1), Some(1.0));
        // From t2 on no stimulus comes: G = 0.
        assert_eq!(p.pi_return(2), None, "t2's own command was not π's");
        assert_eq!(p.pi_return(3), Some(0.0));
        // The response ran at t1: neither t0 nor t1 knows π's return.
        let q = steps(&[(true, false), (false, false), (true, true)], [0.0, 0.0]);
        assert_eq!(q.pi_return(0), None);
        assert_eq!(q.pi_return(1), None);
    }

    #[test]
    fn the_error_is_prediction_minus_return() {
        let p = steps(&[(true, false), (true, false), (false, true)], [1.0, 0.5]);
        let a = p.finish();
        // Scored: t0 (G = 0.5), t1 (G = 1) and the padding (G = 0) until its last horizon.
        let n = a.on_policy.n;
        assert_eq!(n, a.off_policy.n);
        assert_eq!(a.on_policy.n_near, 1);
        assert!((a.on_policy.rmse_near - 0.0).abs() < 1e-12);
        assert!((a.off_policy.rmse_near - 0.5).abs() < 1e-12);
        let mean_g = 1.5 / n as f64;
        assert!((a.on_policy.mean_return - mean_g).abs() < 1e-12);
        assert!((a.on_policy.bias - (1.0 - mean_g)).abs() < 1e-12);
    }

    #[test]
    fn a_tick_one_prediction_lacks_is_scored_for_neither() {
        let mut p = steps(&[(true, false), (true, false), (false, true)], [1.0, 0.5]);
        p.steps[1].values[1] = f64::NAN;
        let a = p.finish();
        assert_eq!(a.on_policy.n, a.off_policy.n);
        assert_eq!((a.on_policy.n_near, a.off_policy.n_near), (0, 0));
        assert!((a.on_policy.mean_return - a.off_policy.mean_return).abs() < 1e-15);
    }
}

//! True online TD(λ) in a [`TraceGroup`] (`learner = "true_online"` in a Horde family): the dutch trace
//! shared, a `V_old` per prediction.
//!
//! The single-prediction learner ([`crate::learn::named::true_online`]) is, for the transition t → t + 1,
//!
//! ```text
//! e_t     = γ_t λ e_{t−1} + (1 − α γ_t λ e_{t−1}ᵀx_t) x_t
//! w_{t+1} = w_t + α (δ_t + V − V_old) e_t − α (V − V_old) x_t,     V = w_tᵀx_t
//! ```
//!
//! # Why the trace can be shared
//!
//! The dutch trace depends on the features, γ_t, λ and α, and on nothing a prediction learns: not its
//! cumulant, not its weights. A group's predictions have the same features, λ and discount sequence
//! (the Horde's groups are keyed by the bank, λ, τ and the terminating stimulus, so γ_t is the group's,
//! never a prediction's); a true-online group is also keyed by α, so every column's trace is the same
//! vector. On binary features it is still "decay every row by γ_t λ, then add a scalar to the active
//! rows", with the scalar `g = 1 − α γ_t λ z` in place of the accumulating trace's 1, so the deferred rows
//! ([`super::rows`], [`super::epochs`]) hold it unchanged. `z = e_{t−1}ᵀx_t` is the group's own `z`: the
//! trace after the last update on this tick's features, which the group keeps anyway.
//!
//! The step `α (δ + V − V_old)` along the trace goes into the deferred `A` as the paper's step does; the
//! correction `− α (V − V_old) x_t` is written into the rows of x_t, which the trace's touch has just
//! brought forward (the same rows, the same cost). Each prediction keeps `V_old` (0 at the start of a
//! chain) and its last correction, from which `V = w_tᵀx_t` follows without reading the rows again:
//! the value predicted for x_t plus the last step times `z`, minus the last correction times the
//! number of rows x_{t−1} and x_t share.
//!
//! Not shared, so refused: a logistic σ (the learner is linear), and one prediction's α changed alone
//! (it is in the trace; [`TraceGroup::set_alpha`] refuses it in a group of more than one).
//!
//! The result is the single learner's up to rounding: the group sums `z` and `V` from its deferred
//! coefficients where the single learner takes dot products of its dense vectors (the tests compare
//! them step by step).

use serde::{Deserialize, Serialize};

use super::weight::Weight;
use super::{LearnError, Sigma, TraceGroup};

/// What a true-online group keeps per prediction beyond the paper's group.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct DutchState {
    /// `V_old` of each prediction: the previous step's `V′` (0 at the start of a chain).
    pub v_old: Vec<f64>,
    /// The last correction `α (V − V_old)` of each prediction, written into the rows of x_{t−1}.
    pub back_prev: Vec<f64>,
    /// How many rows x_{t−1} and x_t share (those the last correction moved under this tick's sum).
    pub overlap: usize,
}

impl DutchState {
    fn new(cols: usize) -> Self {
        DutchState {
            v_old: vec![0.0; cols],
            back_prev: vec![0.0; cols],
            overlap: 0,
        }
    }

    /// The start of a chain: `V_old` = 0, no correction pending.
    pub(super) fn clear(&mut self) {
        self.v_old.fill(0.0);
        self.back_prev.fill(0.0);
        self.overlap = 0;
    }
}

impl<W: Weight> TraceGroup<W> {
    /// The same group learning true online TD(λ) with a shared dutch trace (see the module
    /// documentation). Refused unless σ is the identity and every prediction has the same α.
    pub fn with_dutch_traces(mut self) -> Result<Self, LearnError> {
        if self.sigma != Sigma::Identity {
            return Err(LearnError::SharedDutchTrace(
                "its output is not linear (learner = \"true_online\" needs sigma = \"identity\")"
                    .into(),
            ));
        }
        if let Some(first) = self.columns.first()
            && self.columns.iter().any(|c| c.alpha != first.alpha)
        {
            return Err(LearnError::SharedDutchTrace(
                "its predictions have different step sizes (α is in the dutch trace)".into(),
            ));
        }
        self.dutch = Some(DutchState::new(self.columns.len()));
        Ok(self)
    }

    /// Whether the group learns true online TD(λ).
    pub fn is_dutch(&self) -> bool {
        self.dutch.is_some()
    }

    /// The per-prediction state of a true-online group (`None` for the paper's).
    pub fn dutch_state(&self) -> Option<&DutchState> {
        self.dutch.as_ref()
    }

    /// `state`, checked against this group: present exactly when the group is true online (whose
    /// predictions' step sizes `alphas` are then one), sized for its predictions, finite, its overlap at
    /// most the features.
    pub(super) fn checked_dutch(
        &self,
        name: &str,
        state: Option<&DutchState>,
        alphas: &[f64],
    ) -> Result<Option<DutchState>, LearnError> {
        let bad = |what: &str| LearnError::BadGroupState {
            name: name.to_string(),
            what: what.to_string(),
        };
        match (&self.dutch, state) {
            (None, None) => Ok(None),
            (Some(_), Some(s)) => {
                let cols = self.columns.len();
                if s.v_old.len() != cols || s.back_prev.len() != cols {
                    return Err(bad("is sized for another group"));
                }
                if !s.v_old.iter().chain(&s.back_prev).all(|x| x.is_finite()) {
                    return Err(LearnError::NonFiniteSnapshot(name.to_string()));
                }
                if s.overlap > self.features() {
                    return Err(bad("is inconsistent (overlap beyond the features)"));
                }
                if alphas.windows(2).any(|w| w[0] != w[1]) {
                    return Err(bad(
                        "gives a true online group's predictions different step sizes (α is in the \
                         shared dutch trace)",
                    ));
                }
                Ok(Some(s.clone()))
            }
            (Some(_), None) => Err(bad(
                "has no true online state (v_old) for a learner = \"true_online\" group",
            )),
            (None, Some(_)) => Err(bad(
                "holds a true online state, this group learns another learner",
            )),
        }
    }

    /// [`TraceGroup::learn`] for a true-online group (the caller checked the sizes and `fresh`).
    pub(super) fn learn_dutch(
        &mut self,
        gamma_t: f64,
        cumulants: &[f64],
        deltas: &mut [f64],
    ) -> usize {
        deltas.fill(f64::NAN);
        let Some(mut dutch) = self.dutch.take() else {
            return 0;
        };
        let mut stopped = 0;
        if self.chain.has_prev {
            let cols = self.columns.len();
            let decay = self.chain.gamma_prev * self.lambda;
            // z = e_{t−1}ᵀx_t, before the trace moves on; the dutch trace's scalar for x_t's rows.
            let z = self.chain.z;
            let alpha = self.columns.first().map_or(0.0, |c| c.alpha);
            let g = 1.0 - alpha * decay * z;
            let mut back = vec![0.0; cols];
            for i in 0..cols {
                // V = w_tᵀx_t: as predicted, plus the last step along the trace, minus the last
                // correction on the rows x_{t−1} and x_t share.
                let v = self.chain.y_prev[i] + self.chain.step_prev[i] * z
                    - dutch.back_prev[i] * dutch.overlap as f64;
                self.chain.step_prev[i] = 0.0;
                let v_old = dutch.v_old[i];
                // V_old for the next step: this step's V′, whatever happens to the step.
                dutch.v_old[i] = self.chain.y_now[i];
                if self.diverged[i] || !cumulants[i].is_finite() {
                    continue;
                }
                let delta = cumulants[i] + gamma_t * self.chain.y_now[i] - v;
                if !delta.is_finite() || !gamma_t.is_finite() {
                    self.diverged[i] = true;
                    stopped += 1;
                    continue;
                }
                let a = self.columns[i].alpha;
                let (step, correction) = (a * (delta + v - v_old), a * (v - v_old));
                if !step.is_finite() || !correction.is_finite() {
                    self.diverged[i] = true;
                    stopped += 1;
                    continue;
                }
                deltas[i] = delta;
                self.chain.step_prev[i] = step;
                back[i] = correction;
            }
            self.rows.decay(decay);
            let read_again = self.rows.touch(&self.chain.x_prev, g);
            subtract_on_rows(&mut self.rows, &self.chain.x_prev, &back);
            dutch.back_prev = back;
            dutch.overlap = read_again;
            self.dutch = Some(dutch);
            // The steps into `A`, `eᵀx_t` and the chain moved on, as for every group.
            return self.finish_step(gamma_t, deltas, stopped, g, read_again);
        }
        self.chain.step_prev.fill(0.0);
        self.chain.z = 0.0;
        dutch.clear();
        self.dutch = Some(dutch);
        self.finish_step(gamma_t, deltas, stopped, 0.0, 0)
    }
}

/// `w(f, i) −= back[i]` for every row `f` of `active` (brought forward by the touch just before).
fn subtract_on_rows<W: Weight>(
    rows: &mut super::rows::DeferredRows<W>,
    active: &[usize],
    back: &[f64],
) {
    if back.iter().all(|&b| b == 0.0) {
        return;
    }
    let minus: Vec<W> = back.iter().map(|&b| W::from_f64(-b)).collect();
    let largest = back.iter().fold(0.0f64, |m, b| m.max(b.abs()));
    let cols = rows.cols;
    let mut touched = false;
    for &f in active {
        if f >= rows.features() {
            continue;
        }
        rows.bring_forward(f);
        rows.preserve(f);
        super::weight::accumulate(&mut rows.w0[f * cols..(f + 1) * cols], &minus);
        touched = true;
    }
    if touched {
        rows.w0_bound += largest;
    }
}

#[cfg(test)]
mod tests {
    use super::super::Column;
    use super::*;
    use crate::learn::named::TrueOnlineTd;
    use crate::learn::test_stream::held_stream;
    use crate::learn::{TdParams, TileCoder};

    /// A group of `cols` true-online predictions against as many single learners on the same stream
    /// (the stimulus terminates: γ = 0 there); returns the largest difference of the values and δs
    /// (every tick) and of the weights, traces and `V_old` (at the end).
    fn compare<W: Weight>(cols: usize, lambda: f64, tau: f64, seed: u64) -> (f64, f64) {
        let coder = TileCoder::one_dim(12, 8).unwrap();
        let n = coder.num_features();
        let alpha = 0.5 / coder.num_tilings() as f64;
        let columns: Vec<Column> = (0..cols)
            .map(|_| Column {
                alpha,
                initial_weight: 0.0,
            })
            .collect();
        let mut group: TraceGroup<W> = TraceGroup::new(n, lambda, Sigma::Identity, columns)
            .unwrap()
            .with_dutch_traces()
            .unwrap();
        let params = TdParams {
            alpha,
            lambda,
            sigma: Sigma::Identity,
            initial_weight: 0.0,
        };
        let mut single: Vec<TrueOnlineTd> =
            (0..cols).map(|_| TrueOnlineTd::new(n, params)).collect();
        let (mut x_prev, mut x_now, mut gamma_prev) = (Vec::new(), Vec::new(), 0.0);
        let mut deltas = vec![0.0; cols];
        let mut worst_value: f64 = 0.0;
        for (t, (x, stim)) in held_stream(1500, 12, 0.05, seed).into_iter().enumerate() {
            coder.active(&x, &mut x_now);
            let gamma = if stim { 0.0 } else { 1.0 - 1.0 / tau };
            let r: Vec<f64> = (0..cols)
                .map(|i| {
                    if i == 0 {
                        f64::from(u8::from(stim))
                    } else {
                        x[i % 12] * i as f64
                    }
                })
                .collect();
            let values = group.predict(&x_now).to_vec();
            for (i, s) in single.iter().enumerate() {
                worst_value = worst_value.max((s.predict(&x_now) - values[i]).abs());
            }
            group.learn(gamma, &r, &mut deltas).unwrap();
            for (i, s) in single.iter_mut().enumerate() {
                if t > 0 {
                    let d = s
                        .try_update(&x_prev, gamma_prev, r[i], gamma, &x_now)
                        .unwrap();
                    worst_value = worst_value.max((d - deltas[i]).abs());
                }
            }
            std::mem::swap(&mut x_prev, &mut x_now);
            gamma_prev = gamma;
        }
        let mut worst_state: f64 = 0.0;
        let dutch = group.dutch_state().unwrap().clone();
        for (i, s) in single.iter().enumerate() {
            for (a, b) in group.weights(i).iter().zip(s.weights()) {
                worst_state = worst_state.max((a - b).abs());
            }
            for (a, b) in group.traces().iter().zip(s.traces()) {
                worst_state = worst_state.max((a - b).abs());
            }
            worst_state = worst_state.max((dutch.v_old[i] - s.v_old()).abs());
        }
        (worst_value, worst_state)
    }

    #[test]
    fn a_group_learns_what_its_single_learners_learn() {
        for (cols, lambda, tau, seed) in [
            (1, 0.9, 25.0, 1),
            (5, 0.9, 25.0, 2),
            (7, 0.5, 5.0, 3),
            (3, 0.0, 10.0, 4),
        ] {
            let (v, s) = compare::<f64>(cols, lambda, tau, seed);
            // Values reach about 100 (x·i at τ = 25); measured up to 7e-11: rounding, relative 1e-12.
            assert!(
                v < 1e-9 && s < 1e-9,
                "{cols} columns, λ = {lambda}: {v}, {s}"
            );
        }
        // f32 weights: the weights' own rounding (the values reach a few units).
        let (v, s) = compare::<f32>(4, 0.9, 25.0, 5);
        assert!(v < 1e-3 && s < 1e-3, "f32: {v}, {s}");
    }

    #[test]
    fn a_dutch_group_needs_one_alpha_and_a_linear_output() {
        let col = |alpha| Column {
            alpha,
            initial_weight: 0.0,
        };
        let mixed =
            TraceGroup::<f64>::new(4, 0.9, Sigma::Identity, vec![col(0.1), col(0.2)]).unwrap();
        let e = mixed.with_dutch_traces().unwrap_err().to_string();
        assert!(e.contains("step sizes"), "{e}");
        let logistic = TraceGroup::<f64>::new(4, 0.9, Sigma::Logistic, vec![col(0.1)]).unwrap();
        assert!(
            logistic
                .with_dutch_traces()
                .unwrap_err()
                .to_string()
                .contains("identity")
        );
        let mut two = TraceGroup::<f64>::new(4, 0.9, Sigma::Identity, vec![col(0.1), col(0.1)])
            .unwrap()
            .with_dutch_traces()
            .unwrap();
        assert!(
            two.set_alpha(0, 0.05)
                .unwrap_err()
                .to_string()
                .contains("dutch")
        );
        // Nor through a state: one restored with two step sizes is refused, and one without its
        // V_old, and the paper's group refuses a true online state.
        let mut mixed_state = two.state();
        mixed_state.alphas[1] = 0.05;
        let e = two
            .restore_state("two", &mixed_state)
            .unwrap_err()
            .to_string();
        assert!(e.contains("different step sizes"), "{e}");
        let mut no_v_old = two.state();
        no_v_old.dutch = None;
        let e = two.restore_state("two", &no_v_old).unwrap_err().to_string();
        assert!(e.contains("v_old"), "{e}");
        let mut paper =
            TraceGroup::<f64>::new(4, 0.9, Sigma::Identity, vec![col(0.1), col(0.1)]).unwrap();
        assert!(paper.restore_state("paper", &two.state()).is_err());
        two.restore_state("two", &two.state()).unwrap();
    }
}

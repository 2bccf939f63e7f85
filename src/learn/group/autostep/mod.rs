//! [`AutostepGroup`]: Autostep TD(λ) (`learner = "autostep"` in a Horde family) for predictions that
//! share one trace, each with its own step size, h and v per weight.
//!
//! The single-prediction learner and its equations are [`crate::learn::named::autostep`]. Its trace is
//! the log-loss gradient's, `e_t = γ_t λ e_{t−1} + x_t`: no α (the step sizes act on the weights, never on
//! the trace) and no σ′, so predictions over the same features with the same λ and discount sequence
//! share it, whatever their cumulant, σ or step sizes. Everything else is per prediction and per weight:
//! the weights, the step sizes α_i, h_i and v_i, four numbers per weight, held a prediction at a time
//! (`features` values each).
//!
//! Autostep's update is not deferrable as the paper's is ([`super::epochs`]): every weight with a
//! non-zero trace changes its own step size every tick, and a step normalised by `M > 1` divides every
//! step size of the prediction. So a tick costs, per prediction, the rows whose trace is not zero (a
//! trace decays geometrically but is exactly zero only after γ = 0, λ = 0 or an underflow: in practice
//! every feature seen since the last termination), plus every row on a tick with `M > 1`. A row whose
//! trace is zero is skipped: for it every step of the update is the identity (g = 0, v and α unchanged,
//! `w + α·δ·0 = w`), so the group computes exactly the single learner's numbers, in the same order, for
//! `f64` weights (the tests compare them bit for bit).
//!
//! A step that would make a number of a prediction non-finite changes nothing of that prediction, and
//! stops it, as the single learner's does. A prediction whose cumulant is missing (NaN) on a tick learns
//! nothing then, while the shared trace moves on (the single learner would not move its own).

mod state;

use super::super::named::autostep::{META_STEP, TAU_V};
use super::weight::Weight;
use super::{Column, GroupState, LearnError, Sigma};

/// Autostep predictions sharing one trace (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct AutostepGroup<W> {
    features: usize,
    lambda: f64,
    sigma: Sigma,
    columns: Vec<Column>,
    /// The weights, step sizes, h and v: `features` values per prediction, prediction after prediction.
    weights: Vec<W>,
    alphas: Vec<W>,
    h: Vec<W>,
    v: Vec<W>,
    /// The shared trace.
    trace: Vec<f64>,
    /// The rows whose trace is not zero (each once), and which they are.
    live: Vec<usize>,
    is_live: Vec<bool>,
    /// The rows of the previous tick's features.
    in_prev: Vec<bool>,
    diverged: Vec<bool>,
    x_prev: Vec<usize>,
    x_now: Vec<usize>,
    /// `wᵀx` of this tick's features (before its update), and of the previous tick's.
    y_now: Vec<f64>,
    y_prev: Vec<f64>,
    gamma_prev: f64,
    has_prev: bool,
    fresh: bool,
    /// One prediction's new step sizes, v, weights and h of its live rows (scratch, by row).
    new_alpha: Vec<f64>,
    new_v: Vec<f64>,
    new_w: Vec<f64>,
    new_h: Vec<f64>,
    /// A snapshot taken whole ([`AutostepGroup::begin_snapshot_into`]).
    pending: Option<(GroupState, Vec<W>)>,
}

impl<W: Weight> AutostepGroup<W> {
    /// A group of `columns` over `features` binary features: every weight at its column's initial
    /// weight, every step size at its α, h and v at 0, μ = [`META_STEP`] and τ_v = [`TAU_V`].
    pub fn new(
        features: usize,
        lambda: f64,
        sigma: Sigma,
        columns: Vec<Column>,
    ) -> Result<Self, LearnError> {
        super::super::bounds::check_lambda("group", lambda)?;
        for c in &columns {
            super::super::bounds::check_alpha_positive("group", c.alpha)?;
            super::super::bounds::check_initial_weight("group", c.initial_weight)?;
        }
        let cols = columns.len();
        let per_column = |value: fn(&Column) -> f64| -> Vec<W> {
            let mut out = super::huge::weight_vec(features * cols);
            for c in &columns {
                out.extend(std::iter::repeat_n(W::from_f64(value(c)), features));
            }
            out
        };
        let weights = per_column(|c| c.initial_weight);
        let alphas = per_column(|c| c.alpha);
        let h = per_column(|_| 0.0);
        let v = per_column(|_| 0.0);
        Ok(AutostepGroup {
            features,
            lambda,
            sigma,
            weights,
            alphas,
            h,
            v,
            trace: vec![0.0; features],
            live: Vec::new(),
            is_live: vec![false; features],
            in_prev: vec![false; features],
            diverged: vec![false; cols],
            x_prev: Vec::new(),
            x_now: Vec::new(),
            y_now: vec![0.0; cols],
            y_prev: vec![0.0; cols],
            gamma_prev: 0.0,
            has_prev: false,
            fresh: false,
            new_alpha: vec![0.0; features],
            new_v: vec![0.0; features],
            new_w: vec![0.0; features],
            new_h: vec![0.0; features],
            pending: None,
            columns,
        })
    }

    /// The number of predictions.
    pub fn len(&self) -> usize {
        self.columns.len()
    }

    /// True without predictions.
    pub fn is_empty(&self) -> bool {
        self.columns.is_empty()
    }

    /// The number of features.
    pub fn features(&self) -> usize {
        self.features
    }

    /// The number of values a snapshot holds: four per weight (weights, step sizes, h, v).
    pub fn value_count(&self) -> usize {
        4 * self.weights.len()
    }

    /// σ.
    pub fn sigma(&self) -> Sigma {
        self.sigma
    }

    /// The predictions' configured step sizes (where their step sizes start) and initial weights.
    pub fn columns(&self) -> &[Column] {
        &self.columns
    }

    fn range(&self, col: usize) -> std::ops::Range<usize> {
        col * self.features..(col + 1) * self.features
    }

    /// The weights of prediction `col`, one per feature.
    pub fn weights(&self, col: usize) -> Vec<f64> {
        self.weights[self.range(col)]
            .iter()
            .map(|w| w.to_f64())
            .collect()
    }

    /// The step sizes of prediction `col`, one per feature.
    pub fn alphas(&self, col: usize) -> Vec<f64> {
        self.alphas[self.range(col)]
            .iter()
            .map(|w| w.to_f64())
            .collect()
    }

    /// The shared trace, one per feature.
    pub fn traces(&self) -> &[f64] {
        &self.trace
    }

    /// Whether prediction `col` stopped learning because a step was not finite.
    pub fn diverged(&self, col: usize) -> bool {
        self.diverged.get(col).copied().unwrap_or(false)
    }

    /// `wᵀx` of prediction `col`'s weights for the binary `active` (an index beyond the features is
    /// ignored), summed in the order of `active` as the single learner sums it.
    fn dot(&self, col: usize, active: &[usize]) -> f64 {
        let w = &self.weights[self.range(col)];
        active
            .iter()
            .filter_map(|&f| w.get(f))
            .map(|w| w.to_f64())
            .sum()
    }

    /// Step 1 of a tick: `wᵀx_t` of every prediction for the features `active`. Predicting twice
    /// without a `learn` breaks the chain.
    pub fn predict(&mut self, active: &[usize]) -> &[f64] {
        if self.fresh {
            self.break_chain();
        }
        for i in 0..self.columns.len() {
            self.y_now[i] = self.dot(i, active);
        }
        self.x_now.clear();
        self.x_now.extend_from_slice(active);
        self.fresh = true;
        &self.y_now
    }

    /// `wᵀx_t` of the last `predict` (before or after its `learn`).
    pub fn values(&self) -> &[f64] {
        if self.fresh {
            &self.y_now
        } else {
            &self.y_prev
        }
    }

    /// Step 2 of a tick: the update for the transition from the previous tick into this one, with this
    /// tick's cumulants (one per prediction) and discount `γ_t`; each prediction's δ into `deltas` (NaN
    /// where nothing was learned). Returns how many predictions stopped on this step.
    pub fn learn(
        &mut self,
        gamma_t: f64,
        cumulants: &[f64],
        deltas: &mut [f64],
    ) -> Result<usize, LearnError> {
        if !self.fresh {
            return Err(LearnError::LearnWithoutPredict);
        }
        let cols = self.columns.len();
        if cumulants.len() != cols || deltas.len() != cols {
            return Err(LearnError::CumulantCountMismatch {
                expected: cols,
                got: cumulants.len().min(deltas.len()),
            });
        }
        deltas.fill(f64::NAN);
        let mut stopped = 0;
        if self.has_prev {
            let sigma = self.sigma;
            for i in 0..cols {
                if self.diverged[i] || !cumulants[i].is_finite() {
                    continue;
                }
                let delta = cumulants[i] + gamma_t * sigma.value(self.y_now[i])
                    - sigma.value(self.dot(i, &self.x_prev));
                if !delta.is_finite() || !self.gamma_prev.is_finite() {
                    self.diverged[i] = true;
                    stopped += 1;
                    continue;
                }
                deltas[i] = delta;
            }
            self.move_trace();
            for (i, delta) in deltas.iter_mut().enumerate() {
                if delta.is_nan() {
                    continue;
                }
                if !self.step(i, *delta) {
                    *delta = f64::NAN;
                    self.diverged[i] = true;
                    stopped += 1;
                }
            }
        }
        std::mem::swap(&mut self.x_prev, &mut self.x_now);
        std::mem::swap(&mut self.y_prev, &mut self.y_now);
        for &f in &self.x_now {
            if let Some(p) = self.in_prev.get_mut(f) {
                *p = false;
            }
        }
        for &f in &self.x_prev {
            if let Some(p) = self.in_prev.get_mut(f) {
                *p = true;
            }
        }
        self.gamma_prev = gamma_t;
        self.has_prev = true;
        self.fresh = false;
        Ok(stopped)
    }

    /// `e ← γ_t λ e + x_t` for the previous tick's features x_t, keeping the live rows.
    fn move_trace(&mut self) {
        let decay = self.gamma_prev * self.lambda;
        let trace = &mut self.trace;
        let is_live = &mut self.is_live;
        self.live.retain(|&f| {
            trace[f] *= decay;
            let keep = trace[f] != 0.0;
            is_live[f] = keep;
            keep
        });
        for &f in &self.x_prev {
            if f >= self.features {
                continue;
            }
            self.trace[f] += 1.0;
            if !self.is_live[f] {
                self.is_live[f] = true;
                self.live.push(f);
            }
        }
    }

    /// Autostep's step of prediction `col` with δ `delta` over the moved trace; false (and nothing
    /// changed) when a number would not be finite.
    fn step(&mut self, col: usize, delta: f64) -> bool {
        let (mu, tau) = (META_STEP, TAU_V);
        let base = col * self.features;
        // Step sizes and v of the live rows (a row of zero trace keeps both).
        for &f in &self.live {
            let e = self.trace[f];
            let x = if self.in_prev[f] { 1.0 } else { 0.0 };
            let alpha = self.alphas[base + f].to_f64();
            let g = delta * e * self.h[base + f].to_f64();
            let v = g.abs().max(
                self.v[base + f].to_f64()
                    + alpha * e * x * (g.abs() - self.v[base + f].to_f64()) / tau,
            );
            self.new_v[f] = v;
            self.new_alpha[f] = if e != 0.0 && v > 0.0 {
                alpha * (mu * g / v).exp()
            } else {
                alpha
            };
        }
        let m = self
            .x_prev
            .iter()
            .filter(|&&f| f < self.features)
            .map(|&f| self.new_alpha[f] * self.trace[f])
            .sum::<f64>()
            .max(1.0);
        let mut finite = true;
        for &f in &self.live {
            let e = self.trace[f];
            let x = if self.in_prev[f] { 1.0 } else { 0.0 };
            let a = self.new_alpha[f] / m;
            self.new_alpha[f] = a;
            self.new_w[f] = self.weights[base + f].to_f64() + a * delta * e;
            let h = self.h[base + f].to_f64();
            self.new_h[f] = h * (1.0 - a * e * x) + a * delta * e;
            finite &= [a, self.new_v[f], self.new_w[f], self.new_h[f]]
                .iter()
                .all(|v| v.is_finite() && W::from_f64(*v).finite());
        }
        if !finite {
            return false;
        }
        for &f in &self.live {
            self.alphas[base + f] = W::from_f64(self.new_alpha[f]);
            self.v[base + f] = W::from_f64(self.new_v[f]);
            self.weights[base + f] = W::from_f64(self.new_w[f]);
            self.h[base + f] = W::from_f64(self.new_h[f]);
        }
        if m > 1.0 {
            // The normaliser divides every step size, the rows of zero trace too.
            for f in 0..self.features {
                if !self.is_live[f] {
                    let a = &mut self.alphas[base + f];
                    *a = W::from_f64(a.to_f64() / m);
                }
            }
        }
        true
    }

    /// Forgets a `predict` that has not been learned from.
    pub fn clear_pending(&mut self) {
        self.fresh = false;
    }

    /// Forgets the previous tick and ends the trace; weights, step sizes, h and v are kept.
    pub fn break_chain(&mut self) {
        self.has_prev = false;
        self.fresh = false;
        for &f in &self.live {
            self.trace[f] = 0.0;
            self.is_live[f] = false;
        }
        self.live.clear();
    }

    /// Back to the initial state; stopped predictions learn again.
    pub fn reset(&mut self) {
        self.break_chain();
        for (i, c) in self.columns.iter().enumerate() {
            let r = i * self.features..(i + 1) * self.features;
            self.weights[r.clone()].fill(W::from_f64(c.initial_weight));
            self.alphas[r.clone()].fill(W::from_f64(c.alpha));
            self.h[r.clone()].fill(W::default());
            self.v[r].fill(W::default());
        }
        self.diverged.fill(false);
    }

    /// Changes α of prediction `col`: its step sizes restart from it (as the single learner's).
    pub fn set_alpha(&mut self, col: usize, alpha: f64) -> Result<(), LearnError> {
        super::super::bounds::check_alpha_positive("group", alpha)?;
        if col < self.columns.len() {
            self.columns[col].alpha = alpha;
            let r = self.range(col);
            self.alphas[r].fill(W::from_f64(alpha));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests;

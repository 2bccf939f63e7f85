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

    /// The exact state, between two ticks (see [`GroupState::autostep`]).
    pub fn state(&self) -> GroupState {
        let mut s = self.state_without_values();
        s.w0 = self.values_now().iter().map(|w| w.to_f64()).collect();
        s
    }

    fn values_now(&self) -> Vec<W> {
        let mut out = Vec::with_capacity(self.value_count());
        for part in [&self.weights, &self.alphas, &self.h, &self.v] {
            out.extend_from_slice(part);
        }
        out
    }

    fn state_without_values(&self) -> GroupState {
        let cols = self.columns.len();
        GroupState {
            precision: W::NAME.into(),
            w0: Vec::new(),
            coef: self.trace.clone(),
            row_epoch: vec![0; self.features],
            epoch: 0,
            p: 1.0,
            a: vec![0.0; cols],
            a_w: vec![0.0; cols],
            members: Vec::new(),
            ring: Vec::new(),
            lambda: self.lambda,
            alphas: self.columns.iter().map(|c| c.alpha).collect(),
            diverged: self.diverged.clone(),
            x_prev: self.has_prev.then(|| self.x_prev.clone()),
            gamma_prev: self.gamma_prev,
            y_prev: self.y_prev.clone(),
            step_prev: vec![0.0; cols],
            z: 0.0,
            dutch: None,
            autostep: true,
        }
    }

    /// Takes a snapshot of the whole state at once, its values into `buffer` when it has the size (the
    /// values of an earlier snapshot, or [`super::snapshot_buffer`]). Unlike the paper's group it is not
    /// copied a few rows a tick: one copy of four times the weights on this tick. False when one is
    /// waiting to be taken.
    pub fn begin_snapshot_into(&mut self, buffer: Option<Vec<W>>) -> bool {
        if self.pending.is_some() {
            return false;
        }
        let mut values = match buffer {
            Some(b) if b.len() == self.value_count() => b,
            _ => vec![W::default(); self.value_count()],
        };
        let mut at = 0;
        for part in [&self.weights, &self.alphas, &self.h, &self.v] {
            values[at..at + part.len()].copy_from_slice(part);
            at += part.len();
        }
        self.pending = Some((self.state_without_values(), values));
        true
    }

    /// The snapshot taken by [`AutostepGroup::begin_snapshot_into`], if one is waiting.
    pub fn take_snapshot(&mut self) -> Option<(GroupState, Vec<W>)> {
        self.pending.take()
    }

    /// Restores a snapshot of [`AutostepGroup::take_snapshot`]'s form.
    pub fn restore_snapshot(
        &mut self,
        name: &str,
        state: &GroupState,
        values: &[W],
    ) -> Result<(), LearnError> {
        let mut full = state.clone();
        full.w0 = values.iter().map(|w| w.to_f64()).collect();
        self.restore_state(name, &full)
    }

    /// Restores `s`, taken from an Autostep group of the same shape; everything is checked before
    /// anything changes.
    pub fn restore_state(&mut self, name: &str, s: &GroupState) -> Result<(), LearnError> {
        let n = self.features;
        let cols = self.columns.len();
        let bad = |what: &str| LearnError::BadGroupState {
            name: name.to_string(),
            what: what.to_string(),
        };
        if s.precision != W::NAME {
            return Err(bad(&format!(
                "holds {} weights, this learner {}",
                s.precision,
                W::NAME
            )));
        }
        if !s.autostep || s.dutch.is_some() {
            return Err(bad(
                "is not an Autostep group's, this group learns learner = \"autostep\"",
            ));
        }
        let sizes_ok = s.w0.len() == 4 * n * cols
            && s.coef.len() == n
            && s.alphas.len() == cols
            && s.y_prev.len() == cols
            && s.diverged.len() == cols;
        if !sizes_ok {
            return Err(bad("is sized for another group"));
        }
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if !finite(&s.w0)
            || !finite(&s.coef)
            || !finite(&s.y_prev)
            || ![s.gamma_prev, s.lambda].iter().all(|x| x.is_finite())
        {
            return Err(LearnError::NonFiniteSnapshot(name.to_string()));
        }
        let block = n * cols;
        let (step_sizes, v) = (&s.w0[block..2 * block], &s.w0[3 * block..]);
        if step_sizes.iter().any(|&a| a < 0.0) || v.iter().any(|&x| x < 0.0) {
            return Err(bad("has a negative step size or normaliser v"));
        }
        if s.x_prev
            .as_deref()
            .is_some_and(|x| x.iter().any(|&f| f >= n))
        {
            return Err(bad("is inconsistent (feature index)"));
        }
        for &a in &s.alphas {
            super::super::bounds::check_alpha_positive(name, a)?;
        }
        super::super::bounds::check_lambda(name, s.lambda)?;

        self.pending = None;
        let to_w = |v: &[f64]| -> Vec<W> { v.iter().map(|&x| W::from_f64(x)).collect() };
        self.weights = to_w(&s.w0[..block]);
        self.alphas = to_w(step_sizes);
        self.h = to_w(&s.w0[2 * block..3 * block]);
        self.v = to_w(v);
        self.trace.clone_from(&s.coef);
        self.live = (0..n).filter(|&f| self.trace[f] != 0.0).collect();
        self.is_live = self.trace.iter().map(|&e| e != 0.0).collect();
        self.lambda = s.lambda;
        for (c, &a) in self.columns.iter_mut().zip(&s.alphas) {
            c.alpha = a;
        }
        self.diverged.clone_from(&s.diverged);
        self.in_prev.fill(false);
        self.x_prev = s.x_prev.clone().unwrap_or_default();
        for &f in &self.x_prev {
            self.in_prev[f] = true;
        }
        self.x_now.clear();
        self.has_prev = s.x_prev.is_some();
        self.gamma_prev = s.gamma_prev;
        self.y_prev.clone_from(&s.y_prev);
        self.fresh = false;
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::named::AutostepTd;
    use crate::learn::test_stream::held_stream;
    use crate::learn::{TdParams, TileCoder};

    fn group<W: Weight>(cols: usize, lambda: f64, sigma: Sigma, n: usize) -> AutostepGroup<W> {
        let columns = (0..cols)
            .map(|i| Column {
                alpha: 0.02 + 0.01 * (i % 3) as f64,
                initial_weight: if sigma == Sigma::Logistic { -1.0 } else { 0.0 },
            })
            .collect();
        AutostepGroup::new(n, lambda, sigma, columns).unwrap()
    }

    /// The cumulant of column `i`: the stimulus for column 0, a scaled input for the others.
    fn cumulants(cols: usize, x: &[f64], stim: bool) -> Vec<f64> {
        (0..cols)
            .map(|i| {
                if i == 0 {
                    f64::from(u8::from(stim))
                } else {
                    x[i % x.len()]
                }
            })
            .collect()
    }

    /// A group of `cols` Autostep predictions against as many single learners over the same stream
    /// (the stimulus terminates: γ = 0 there): every value and δ, and at the end every weight, step
    /// size and trace, bit for bit.
    /// Returns on how many steps a learner's step was normalised (M > 1).
    fn same_as_single(cols: usize, lambda: f64, sigma: Sigma, seed: u64) -> usize {
        let coder = TileCoder::one_dim(12, 8).unwrap();
        let n = coder.num_features();
        let mut g: AutostepGroup<f64> = group(cols, lambda, sigma, n);
        let mut single: Vec<AutostepTd> = g
            .columns()
            .iter()
            .map(|c| {
                AutostepTd::new(
                    n,
                    TdParams {
                        alpha: c.alpha,
                        lambda,
                        sigma,
                        initial_weight: c.initial_weight,
                    },
                )
            })
            .collect();
        let (mut x_prev, mut x_now, mut gamma_prev) = (Vec::new(), Vec::new(), 0.0);
        let mut deltas = vec![0.0; cols];
        let mut normalised = 0;
        for (t, (x, stim)) in held_stream(1200, 12, 0.05, seed).into_iter().enumerate() {
            coder.active(&x, &mut x_now);
            let gamma = if stim { 0.0 } else { 0.95 };
            let r = cumulants(cols, &x, stim);
            let values = g.predict(&x_now).to_vec();
            for (i, s) in single.iter().enumerate() {
                assert_eq!(
                    s.predict(&x_now),
                    sigma.value(values[i]),
                    "value {i} at {t}"
                );
            }
            g.learn(gamma, &r, &mut deltas).unwrap();
            if t > 0 {
                for (i, s) in single.iter_mut().enumerate() {
                    let d = s
                        .try_update(&x_prev, gamma_prev, r[i], gamma, &x_now)
                        .unwrap();
                    assert_eq!(d.to_bits(), deltas[i].to_bits(), "δ {i} at {t}");
                    // After a normalised step Σ α_i e_i x_i is 1; below 1 otherwise.
                    let m: f64 = x_prev.iter().map(|&f| s.alphas()[f] * s.traces()[f]).sum();
                    normalised += usize::from((m - 1.0).abs() < 1e-9);
                }
            }
            std::mem::swap(&mut x_prev, &mut x_now);
            gamma_prev = gamma;
        }
        for (i, s) in single.iter().enumerate() {
            assert_eq!(g.alphas(i), s.alphas(), "step sizes of {i}");
            assert_eq!(g.weights(i), s.weights(), "weights of {i}");
            assert_eq!(g.traces(), s.traces(), "trace of {i}");
        }
        normalised
    }

    #[test]
    fn a_group_is_its_single_learners_bit_for_bit() {
        // With λ = 0.9 the trace reaches ~7: Σ α_i e_i x_i > 1 and the normaliser M acts, on every step
        // of the prediction, the rows of zero trace too.
        assert!(same_as_single(1, 0.9, Sigma::Identity, 1) > 0);
        assert!(same_as_single(4, 0.9, Sigma::Identity, 2) > 0);
        same_as_single(3, 0.0, Sigma::Identity, 3);
        // The trace holds no σ′: logistic predictions share it too.
        same_as_single(3, 0.7, Sigma::Logistic, 4);
    }

    #[test]
    fn a_state_restores_exactly_and_a_foreign_one_is_refused() {
        let coder = TileCoder::one_dim(12, 4).unwrap();
        let n = coder.num_features();
        let mut a: AutostepGroup<f32> = group(3, 0.9, Sigma::Identity, n);
        let s = held_stream(600, 12, 0.05, 7);
        let mut active = Vec::new();
        let mut deltas = vec![0.0; 3];
        let mut tick = |g: &mut AutostepGroup<f32>, (x, stim): &(Vec<f64>, bool)| {
            coder.active(x, &mut active);
            g.predict(&active);
            g.learn(0.9, &cumulants(3, x, *stim), &mut deltas).unwrap();
            g.values().to_vec()
        };
        for t in &s[..300] {
            tick(&mut a, t);
        }
        assert!(a.begin_snapshot_into(None));
        let (state, values) = a.take_snapshot().unwrap();
        assert_eq!(values.len(), a.value_count());
        assert_eq!(state.value_count(), a.value_count());
        let mut b: AutostepGroup<f32> = group(3, 0.9, Sigma::Identity, n);
        b.restore_snapshot("b", &state, &values).unwrap();
        assert_eq!(b.state(), a.state());
        for t in &s[300..] {
            assert_eq!(tick(&mut a, t), tick(&mut b, t));
        }
        let mut other: AutostepGroup<f32> = group(2, 0.9, Sigma::Identity, n);
        assert!(other.restore_state("o", &a.state()).is_err());
        let mut not_autostep = a.state();
        not_autostep.autostep = false;
        let e = b.restore_state("b", &not_autostep).unwrap_err().to_string();
        assert!(e.contains("Autostep"), "{e}");
    }
}

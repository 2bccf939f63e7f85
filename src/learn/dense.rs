//! [`DenseTd`]: one prediction's TD(λ) with its weights and trace stored densely, what a
//! [`super::PredictionSet`] runs for each on-policy prediction.
//!
//! A control prediction has a few hundred to a few thousand features (the paper's: 440 and 500). At that
//! size one pass over every weight and trace, `e ← γλe; w ← w + αδe`, is a few hundred multiply-adds
//! that the compiler vectorizes, and it costs less than the bookkeeping that lets a
//! [`super::TraceGroup`] touch only the active rows (measured with `cargo bench --bench learn`). The
//! group stays the learner of the Horde, whose predictions share traces over thousands of rows.
//!
//! The update is the paper's, the same steps in the same order as the dense reference
//! [`super::TdLambda`] and the group (the tests compare all three over long runs):
//! `δ = R_t + γ_t σ(wᵀx_t) − σ(wᵀx_{t−1})`, `e ← γ_{t−1}λ e + σ′(wᵀx_{t−1}) x_{t−1}`, `w ← w + αδ e`,
//! with `wᵀx_{t−1}` under the current weights. Two differences, neither visible in a result:
//! - a trace entry that decays below [`TRACE_FLOOR`] is set to 0, so that a long run never computes with
//!   subnormal numbers (hundreds of times slower); it would move a weight by less than 1e-100 of a step;
//! - a step is checked for staying finite against running bounds on `max|w|` and `max|e|`, and only when
//!   those cannot rule out an overflow, weight by weight (as the group does): a prediction whose step
//!   would make a weight non-finite, or larger than 1e300, **stops learning** and keeps its weights.
//!
//! Its weights and trace *are* its exact state: a snapshot of them continues bit for bit.

use super::bounds::{check_alpha_positive, check_dense_state, check_initial_weight, check_lambda};
use super::group::{Column, GroupState, TraceGroup};
use super::{LearnError, Sigma};

/// A trace entry below this (in absolute value) after decaying is set to 0.
pub const TRACE_FLOOR: f64 = 1e-100;

/// Weights are kept below this; a step that would pass it stops the prediction.
const SAFE: f64 = 1e300;

/// One prediction over `features` binary features (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct DenseTd {
    weights: Vec<f64>,
    traces: Vec<f64>,
    column: Column,
    lambda: f64,
    sigma: Sigma,
    diverged: bool,
    x_prev: Vec<usize>,
    x_now: Vec<usize>,
    /// `wᵀx_t` of the last `predict`, and σ of it.
    y_now: f64,
    v_now: f64,
    gamma_prev: f64,
    has_prev: bool,
    fresh: bool,
    /// At least the largest `|w|` and `|e|`.
    w_bound: f64,
    e_bound: f64,
    /// Whether the pass skips blocks of zero traces ([`DenseTd::skipping_zero_blocks`]).
    skip_zero_blocks: bool,
}

impl DenseTd {
    /// A prediction whose weights all start at `column.initial_weight`, with a zero trace.
    pub fn new(
        features: usize,
        lambda: f64,
        sigma: Sigma,
        column: Column,
    ) -> Result<Self, LearnError> {
        check_lambda("prediction", lambda)?;
        check_alpha_positive("prediction", column.alpha)?;
        check_initial_weight("prediction", column.initial_weight)?;
        Ok(DenseTd {
            weights: vec![column.initial_weight; features],
            traces: vec![0.0; features],
            column,
            lambda,
            sigma,
            diverged: false,
            x_prev: Vec::new(),
            x_now: Vec::new(),
            y_now: 0.0,
            v_now: 0.0,
            gamma_prev: 0.0,
            has_prev: false,
            fresh: false,
            w_bound: column.initial_weight.abs(),
            e_bound: 0.0,
            skip_zero_blocks: false,
        })
    }

    /// The same learner, whose pass skips blocks of eight zero traces: for a prediction with few active
    /// features whose trace ends at its stimulus, where most blocks are zero (the paper's command
    /// prediction: 148 against 165 ns a step), not for one with many (its stall prediction: 323 against
    /// 261 ns). The results are the same.
    pub fn skipping_zero_blocks(mut self, skip: bool) -> Self {
        self.skip_zero_blocks = skip;
        self
    }

    /// The number of features.
    pub fn features(&self) -> usize {
        self.weights.len()
    }

    /// Step size α.
    pub fn alpha(&self) -> f64 {
        self.column.alpha
    }

    /// λ.
    pub fn lambda(&self) -> f64 {
        self.lambda
    }

    /// The weights, one per feature.
    pub fn weights(&self) -> &[f64] {
        &self.weights
    }

    /// The trace, one per feature.
    pub fn traces(&self) -> &[f64] {
        &self.traces
    }

    /// Whether the prediction stopped learning because a step was not finite.
    pub fn diverged(&self) -> bool {
        self.diverged
    }

    /// The previous tick's features and discount, if the chain has one.
    pub fn previous(&self) -> Option<(&[usize], f64)> {
        self.has_prev.then_some((&self.x_prev[..], self.gamma_prev))
    }

    fn dot(&self, active: &[usize]) -> f64 {
        // In order from 0.0, skipping a feature beyond the weights: the same sum as a fold over
        // `filter_map(get)`, with one test per feature.
        let weights = &self.weights[..];
        let mut sum = 0.0;
        for &f in active {
            if f < weights.len() {
                sum += weights[f];
            }
        }
        sum
    }

    /// Step 1 of a tick: `wᵀx_t` for the features `active` (distinct indices; one beyond the features is
    /// ignored). Predicting twice without a `learn` breaks the chain.
    pub fn predict(&mut self, active: &[usize]) -> f64 {
        if self.fresh {
            self.break_chain();
        }
        self.y_now = self.dot(active);
        self.v_now = self.sigma.value(self.y_now);
        self.x_now.clear();
        self.x_now.extend_from_slice(active);
        self.fresh = true;
        self.y_now
    }

    /// σ(wᵀx_t) of the last `predict`: the prediction's value.
    pub fn value(&self) -> f64 {
        self.v_now
    }

    /// Step 2 of a tick: the update for the transition from the previous tick into this one, with this
    /// tick's cumulant `R_t` and discount `γ_t`. Returns δ, or NaN when nothing was learned (the first
    /// tick of a chain, a non-finite cumulant, a stopped prediction, or the step that stopped it).
    pub fn learn(&mut self, gamma_t: f64, cumulant: f64) -> Result<f64, LearnError> {
        if !self.fresh {
            return Err(LearnError::LearnWithoutPredict);
        }
        let mut delta = f64::NAN;
        if self.has_prev {
            let y_prev = self.dot(&self.x_prev);
            // σ(y) and σ′(y) from one evaluation of σ (σ′ = σ(1 − σ) for the logistic, as
            // `Sigma::derivative` computes it).
            let v_prev = self.sigma.value(y_prev);
            let grad = match self.sigma {
                Sigma::Identity => 1.0,
                Sigma::Logistic => v_prev * (1.0 - v_prev),
            };
            let mut step = 0.0;
            if !self.diverged && cumulant.is_finite() {
                let d = cumulant + gamma_t * self.v_now - v_prev;
                if d.is_finite() && gamma_t.is_finite() {
                    delta = d;
                    step = self.column.alpha * d;
                } else {
                    self.diverged = true;
                }
            }
            let decay = self.gamma_prev * self.lambda;
            if !self.apply(decay, grad, step) {
                delta = f64::NAN;
                self.diverged = true;
            }
        }
        std::mem::swap(&mut self.x_prev, &mut self.x_now);
        self.gamma_prev = gamma_t;
        self.has_prev = true;
        self.fresh = false;
        Ok(delta)
    }

    /// `e ← decay·e + grad·x_{t−1}`, then `w ← w + step·e` unless that would make a weight non-finite
    /// or larger than [`SAFE`]; returns whether the weights took the step (the trace always moves).
    fn apply(&mut self, decay: f64, grad: f64, step: f64) -> bool {
        let e_bound = decay.abs() * self.e_bound + grad.abs();
        let w_bound = self.w_bound + step.abs() * e_bound;
        let surely_safe = w_bound < SAFE; // false for a NaN bound too
        let take = step != 0.0 && (surely_safe || self.step_stays_safe(decay, grad, step));
        if take {
            decay_and_step(
                &mut self.traces,
                &mut self.weights,
                decay,
                step,
                self.skip_zero_blocks,
            );
            // Both vectors cut to one length, so one test per feature covers both.
            let n = self.traces.len().min(self.weights.len());
            let (traces, weights) = (&mut self.traces[..n], &mut self.weights[..n]);
            for &f in &self.x_prev {
                if f < n {
                    traces[f] += grad;
                    weights[f] += step * grad;
                }
            }
        } else {
            decay_only(&mut self.traces, decay);
            for &f in &self.x_prev {
                if let Some(e) = self.traces.get_mut(f) {
                    *e += grad;
                }
            }
        }
        if take && surely_safe {
            self.e_bound = e_bound;
            self.w_bound = w_bound;
        } else {
            self.rescan_bounds();
        }
        take || step == 0.0
    }

    /// Whether the step keeps every weight finite and below [`SAFE`]: the step's arithmetic, unwritten.
    fn step_stays_safe(&self, decay: f64, grad: f64, step: f64) -> bool {
        let mut on = vec![false; self.features()];
        for &f in &self.x_prev {
            if let Some(o) = on.get_mut(f) {
                *o = true;
            }
        }
        self.weights
            .iter()
            .zip(&self.traces)
            .zip(&on)
            .all(|((&w, &e), &on)| {
                let mut e = floored(e * decay);
                let mut w = w + step * e;
                if on {
                    e += grad;
                    w += step * grad;
                }
                e.is_finite() && w.is_finite() && w.abs() < SAFE
            })
    }

    fn rescan_bounds(&mut self) {
        self.w_bound = self.weights.iter().fold(0.0f64, |m, w| m.max(w.abs()));
        self.e_bound = self.traces.iter().fold(0.0f64, |m, e| m.max(e.abs()));
    }

    /// Forgets a `predict` that has not been learned from.
    pub fn clear_pending(&mut self) {
        self.fresh = false;
    }

    /// Forgets the previous tick and ends every trace; weights are kept.
    pub fn break_chain(&mut self) {
        self.has_prev = false;
        self.fresh = false;
        self.traces.fill(0.0);
        self.e_bound = 0.0;
    }

    /// Back to the initial weights, zero traces, no previous tick; a stopped prediction learns again.
    pub fn reset(&mut self) {
        self.break_chain();
        self.weights.fill(self.column.initial_weight);
        self.w_bound = self.column.initial_weight.abs();
        self.diverged = false;
    }

    /// Changes α from the next update on (bounds are the caller's).
    pub fn set_alpha(&mut self, alpha: f64) -> Result<(), LearnError> {
        check_alpha_positive("prediction", alpha)?;
        self.column.alpha = alpha;
        Ok(())
    }

    /// Changes λ from the next update on.
    pub fn set_lambda(&mut self, lambda: f64) -> Result<(), LearnError> {
        check_lambda("prediction", lambda)?;
        self.lambda = lambda;
        Ok(())
    }

    /// Replaces the weights, the trace and the previous tick (a checkpoint); both vectors must have one
    /// finite entry per feature. A stopped prediction learns again.
    pub fn set_dense(
        &mut self,
        weights: &[f64],
        traces: &[f64],
        previous: Option<(&[usize], f64)>,
    ) -> Result<(), LearnError> {
        check_dense_state("prediction", self.features(), weights, traces)?;
        self.weights.copy_from_slice(weights);
        self.traces.copy_from_slice(traces);
        self.diverged = false;
        self.fresh = false;
        self.x_prev.clear();
        match previous {
            Some((x, gamma)) => {
                self.x_prev.extend_from_slice(x);
                self.gamma_prev = gamma;
                self.has_prev = true;
            }
            None => self.has_prev = false,
        }
        self.rescan_bounds();
        Ok(())
    }

    /// Restores the exact state a [`TraceGroup`] of one prediction wrote (checkpoints of earlier
    /// versions): its weights, trace, previous tick and whether it had stopped, checked as the group
    /// checks them. α and λ are the caller's to set.
    pub fn restore_group_state(
        &mut self,
        name: &str,
        state: &GroupState,
    ) -> Result<(), LearnError> {
        let mut group: TraceGroup<f64> =
            TraceGroup::new(self.features(), self.lambda, self.sigma, vec![self.column])?;
        group.restore_state(name, state)?;
        let (weights, traces) = (group.weights(0), group.traces());
        self.set_dense(&weights, &traces, group.previous())
            .map_err(|_| LearnError::NonFiniteSnapshot(name.to_string()))?;
        self.diverged = group.diverged(0);
        Ok(())
    }
}

#[inline(always)]
fn floored(e: f64) -> f64 {
    if e.abs() < TRACE_FLOOR { 0.0 } else { e }
}

/// `e ← floored(decay·e); w ← w + step·e` over every feature: the one pass a tick makes over them all.
/// With `skip`, a block of [`CHUNK`] zero traces is passed over (it stays zero and moves no weight): worth
/// it for a sparse prediction whose trace ends at its stimulus, a cost for a dense one. On a CPU with AVX2
/// the same loop is compiled for it (four weights an instruction instead of two); the results are the
/// same bits, as each element is computed by the same IEEE operations (Rust never fuses a multiply and an
/// add on its own).
fn decay_and_step(traces: &mut [f64], weights: &mut [f64], decay: f64, step: f64, skip: bool) {
    #[cfg(target_arch = "x86_64")]
    if std::arch::is_x86_feature_detected!("avx2") {
        // SAFETY: the CPU has AVX2 (just checked), the only requirement of a `target_feature` function.
        unsafe { decay_and_step_avx2(traces, weights, decay, step, skip) };
        return;
    }
    decay_and_step_portable(traces, weights, decay, step, skip);
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn decay_and_step_avx2(traces: &mut [f64], weights: &mut [f64], decay: f64, step: f64, skip: bool) {
    decay_and_step_portable(traces, weights, decay, step, skip);
}

// The element update is written out in each loop rather than shared through a closure: with a closure
// the passes measured 315 against 295 ns (stall) and 186 against 148 ns (command) a step.
#[inline(always)]
fn decay_and_step_portable(
    traces: &mut [f64],
    weights: &mut [f64],
    decay: f64,
    step: f64,
    skip: bool,
) {
    if !skip {
        for (e, w) in traces.iter_mut().zip(weights.iter_mut()) {
            let d = floored(*e * decay);
            *e = d;
            *w += step * d;
        }
        return;
    }
    let mut ec = traces.chunks_exact_mut(CHUNK);
    let mut wc = weights.chunks_exact_mut(CHUNK);
    for (e8, w8) in (&mut ec).zip(&mut wc) {
        if all_zero(e8) {
            continue;
        }
        for (e, w) in e8.iter_mut().zip(w8.iter_mut()) {
            let d = floored(*e * decay);
            *e = d;
            *w += step * d;
        }
    }
    for (e, w) in ec.into_remainder().iter_mut().zip(wc.into_remainder()) {
        let d = floored(*e * decay);
        *e = d;
        *w += step * d;
    }
}

/// The block of traces a sparse prediction's pass skips when all are zero.
const CHUNK: usize = 8;

/// Whether every entry of a block is ±0, without a branch per entry.
#[inline(always)]
fn all_zero(block: &[f64]) -> bool {
    block.iter().fold(0u64, |acc, e| acc | (e.to_bits() << 1)) == 0
}

fn decay_only(traces: &mut [f64], decay: f64) {
    for e in traces.iter_mut() {
        *e = floored(*e * decay);
    }
}

#[cfg(test)]
mod tests;

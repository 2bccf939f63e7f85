//! [`TraceGroup`]: TD(λ) for predictions that share one eligibility trace, at a cost per tick in
//! proportion to the active features, not to all features.
//!
//! Predictions over the same features with the same λ and the same discount sequence γ_t, and a linear
//! output (σ = identity), have the same accumulating trace whatever their cumulant or step size: the
//! trace `e_t = γ_t λ e_{t−1} + x_t` depends only on the features and the discounts. A group stores their
//! weights feature-major (the weights of all its predictions for one feature are one contiguous row,
//! [`weight`]) and defers the trace's updates (`epochs`), so a tick reads the rows of the active
//! features and touches the rows of the previous tick's, and nothing else. With the logistic σ the trace
//! holds σ′(wᵀx), which is each prediction's own: such a group has one prediction.
//!
//! The update is the paper's (see [`crate::learn::td`]), step by step the same as the dense reference
//! [`crate::learn::TdLambda`] up to rounding (the tests compare them). One more saving: the value of the
//! previous tick's features under the current weights, which δ needs, is last tick's prediction plus the
//! last step times the trace on those features (`wᵀx_{t−1} = y_{t−1} + αδ·eᵀx_{t−1}`), so each tick
//! computes one sparse product per prediction, not two.
//!
//! The bookkeeping matches [`crate::learn::set`]: [`TraceGroup::predict`] with this tick's features,
//! then [`TraceGroup::learn`] with this tick's cumulants and discount.

mod autostep;
mod copy;
mod dutch;
mod epochs;
mod fused;
mod huge;
mod rows;
mod state;
pub mod weight;

pub use autostep::AutostepGroup;
pub use copy::snapshot_buffer;
pub use dutch::DutchState;
pub use state::GroupState;
pub use weight::Weight;

use super::{LearnError, Sigma};
use rows::DeferredRows;

/// One prediction of a group: its step size and initial weight.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Column {
    /// Step size α.
    pub alpha: f64,
    /// The value every weight starts from.
    pub initial_weight: f64,
}

/// Predictions sharing one trace (see the module documentation).
#[derive(Debug, Clone, PartialEq)]
pub struct TraceGroup<W> {
    rows: DeferredRows<W>,
    lambda: f64,
    sigma: Sigma,
    /// The trace takes x instead of σ′(wᵀx)·x (`learner = "xent"`, the log-loss gradient; only a logistic
    /// group differs).
    unit_gradient: bool,
    columns: Vec<Column>,
    diverged: Vec<bool>,
    chain: Chain,
    /// Sums of the active rows (scratch).
    acc: Vec<W>,
    /// The state of a snapshot whose weights are being copied ([`TraceGroup::begin_snapshot`]).
    pending: Option<Box<GroupState>>,
    /// True online TD(λ) with a shared dutch trace (`learner = "true_online"`, [`dutch`]).
    dutch: Option<DutchState>,
}

/// What links one tick to the next.
#[derive(Debug, Clone, PartialEq)]
struct Chain {
    x_prev: Vec<usize>,
    x_now: Vec<usize>,
    /// `wᵀx` of the previous tick's features when they were predicted.
    y_prev: Vec<f64>,
    /// `wᵀx` of this tick's features.
    y_now: Vec<f64>,
    /// The last step `αδ` of each prediction (0 when none was taken).
    step_prev: Vec<f64>,
    /// `eᵀx_t` after the last update: with `step_prev`, turns `y_prev` into its current value.
    z: f64,
    /// The trace coefficients summed over this tick's features when they were read, and the epoch
    /// they were read in: with the rows touched since, they give `z` without reading the rows again.
    coef_sum_now: f64,
    epoch_now: u32,
    gamma_prev: f64,
    has_prev: bool,
    fresh: bool,
}

impl<W: Weight> TraceGroup<W> {
    /// A group of `columns` over `features` binary features. A logistic group has exactly one column.
    pub fn new(
        features: usize,
        lambda: f64,
        sigma: Sigma,
        columns: Vec<Column>,
    ) -> Result<Self, LearnError> {
        super::bounds::check_lambda("group", lambda)?;
        for c in &columns {
            super::bounds::check_alpha_positive("group", c.alpha)?;
            super::bounds::check_initial_weight("group", c.initial_weight)?;
        }
        if sigma == Sigma::Logistic && columns.len() != 1 {
            return Err(LearnError::SharedLogisticTrace(columns.len()));
        }
        let initial: Vec<f64> = columns.iter().map(|c| c.initial_weight).collect();
        let cols = columns.len();
        Ok(TraceGroup {
            rows: DeferredRows::new(features, &initial),
            lambda,
            sigma,
            unit_gradient: false,
            diverged: vec![false; cols],
            columns,
            chain: Chain {
                x_prev: Vec::new(),
                x_now: Vec::new(),
                y_prev: vec![0.0; cols],
                y_now: vec![0.0; cols],
                step_prev: vec![0.0; cols],
                z: 0.0,
                coef_sum_now: 0.0,
                epoch_now: 0,
                gamma_prev: 0.0,
                has_prev: false,
                fresh: false,
            },
            acc: vec![W::default(); cols],
            pending: None,
            dutch: None,
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
        self.rows.features()
    }

    /// The number of weights (features × predictions).
    pub fn weight_count(&self) -> usize {
        self.rows.w0.len()
    }

    /// λ.
    pub fn lambda(&self) -> f64 {
        self.lambda
    }

    /// σ.
    pub fn sigma(&self) -> Sigma {
        self.sigma
    }

    /// The same group with the trace of the log-loss gradient, x instead of σ′(wᵀx)·x, when `on`
    /// (`learner = "xent"`, [`crate::learn::named::xent`]); a linear group is the same either way.
    pub fn with_unit_gradient(mut self, on: bool) -> Self {
        self.unit_gradient = on;
        self
    }

    /// The predictions' step sizes and initial weights.
    pub fn columns(&self) -> &[Column] {
        &self.columns
    }

    /// Step 1 of a tick: `wᵀx_t` of every prediction for the features `active` (distinct indices; one
    /// beyond the features is ignored). Predicting twice without a `learn` breaks the chain.
    pub fn predict(&mut self, active: &[usize]) -> &[f64] {
        if self.chain.fresh {
            self.break_chain();
        }
        let coef_sum = self.rows.gather(active, &mut self.acc);
        for (i, y) in self.chain.y_now.iter_mut().enumerate() {
            *y = self.acc[i].to_f64() + coef_sum * self.rows.a(i);
        }
        self.chain.coef_sum_now = coef_sum;
        self.chain.epoch_now = self.rows.epoch();
        self.chain.x_now.clear();
        self.chain.x_now.extend_from_slice(active);
        self.chain.fresh = true;
        &self.chain.y_now
    }

    /// `wᵀx_t` of the last `predict` (before or after its `learn`).
    pub fn values(&self) -> &[f64] {
        if self.chain.fresh {
            &self.chain.y_now
        } else {
            &self.chain.y_prev
        }
    }

    /// Whether prediction `col` stopped learning because a step was not finite.
    pub fn diverged(&self, col: usize) -> bool {
        self.diverged.get(col).copied().unwrap_or(false)
    }

    /// Step 2 of a tick: the update for the transition from the previous tick into this one, with this
    /// tick's cumulants `R_t` (one per prediction) and discount `γ_t`. Writes each prediction's δ into
    /// `deltas` (NaN where nothing was learned: the first tick of a chain, a non-finite cumulant, a
    /// stopped prediction) and returns how many predictions stopped on this step.
    pub fn learn(
        &mut self,
        gamma_t: f64,
        cumulants: &[f64],
        deltas: &mut [f64],
    ) -> Result<usize, LearnError> {
        if !self.chain.fresh {
            return Err(LearnError::LearnWithoutPredict);
        }
        let cols = self.columns.len();
        if cumulants.len() != cols || deltas.len() != cols {
            return Err(LearnError::CumulantCountMismatch {
                expected: cols,
                got: cumulants.len().min(deltas.len()),
            });
        }
        if self.dutch.is_some() {
            return Ok(self.learn_dutch(gamma_t, cumulants, deltas));
        }
        deltas.fill(f64::NAN);
        if self.chain.has_prev {
            let (stopped, grad) = self.deltas(gamma_t, cumulants, deltas);
            self.rows.decay(self.chain.gamma_prev * self.lambda);
            let read_again = self.rows.touch(&self.chain.x_prev, grad);
            Ok(self.finish_step(gamma_t, deltas, stopped, grad, read_again))
        } else {
            self.chain.step_prev.fill(0.0);
            self.chain.z = 0.0;
            Ok(self.finish_step(gamma_t, deltas, 0, 1.0, 0))
        }
    }

    /// The δ of every prediction for the transition into this tick (`deltas`, NaN where none is
    /// learned) and its step `αδ` (`step_prev`, applied by [`TraceGroup::finish_step`]); returns how
    /// many predictions stopped, and the trace's gradient factor (σ′ for a logistic group, else 1).
    fn deltas(&mut self, gamma_t: f64, cumulants: &[f64], deltas: &mut [f64]) -> (usize, f64) {
        let sigma = self.sigma;
        let mut grad = 1.0;
        let mut stopped = 0;
        for i in 0..self.columns.len() {
            let step = &mut self.chain.step_prev[i];
            let y_prev = self.chain.y_prev[i] + *step * self.chain.z;
            *step = 0.0;
            if self.diverged[i] {
                continue;
            }
            if sigma == Sigma::Logistic && !self.unit_gradient {
                grad = sigma.derivative(y_prev);
            }
            let r = cumulants[i];
            if !r.is_finite() {
                continue;
            }
            let delta = r + gamma_t * sigma.value(self.chain.y_now[i]) - sigma.value(y_prev);
            if !delta.is_finite() || !gamma_t.is_finite() {
                self.diverged[i] = true;
                stopped += 1;
                continue;
            }
            deltas[i] = delta;
            *step = self.columns[i].alpha * delta;
        }
        (stopped, grad)
    }

    /// The end of a tick's update, once the trace is decayed and touched: the steps into `A` (refused
    /// ones stop their prediction), `eᵀx_t` for the next tick, and the chain moved on. Returns the
    /// predictions stopped in all (`stopped` before the steps).
    fn finish_step(
        &mut self,
        gamma_t: f64,
        deltas: &mut [f64],
        mut stopped: usize,
        grad: f64,
        read_again: usize,
    ) -> usize {
        if self.chain.has_prev {
            for (i, delta) in deltas.iter_mut().enumerate() {
                let step = self.chain.step_prev[i];
                if step != 0.0 && !self.rows.step(i, step) {
                    self.chain.step_prev[i] = 0.0;
                    *delta = f64::NAN;
                    self.diverged[i] = true;
                    stopped += 1;
                }
            }
            // eᵀx_t: this tick's rows as read, carried into the current epoch, plus g for each of
            // them the touch just added to.
            let carry = self.rows.carry_since(self.chain.epoch_now);
            self.chain.z =
                self.chain.coef_sum_now * carry * self.rows.p() + grad * read_again as f64;
        }
        let chain = &mut self.chain;
        std::mem::swap(&mut chain.x_prev, &mut chain.x_now);
        std::mem::swap(&mut chain.y_prev, &mut chain.y_now);
        chain.gamma_prev = gamma_t;
        chain.has_prev = true;
        chain.fresh = false;
        stopped
    }

    /// Forgets a `predict` that has not been learned from.
    pub fn clear_pending(&mut self) {
        self.chain.fresh = false;
    }

    /// Forgets the previous tick and ends every trace; weights are kept.
    pub fn break_chain(&mut self) {
        self.chain.has_prev = false;
        self.chain.fresh = false;
        self.chain.step_prev.fill(0.0);
        self.chain.z = 0.0;
        self.rows.clear_traces();
        if let Some(d) = &mut self.dutch {
            d.clear();
        }
    }

    /// Back to the initial weights, zero traces, no previous tick; stopped predictions learn again.
    pub fn reset(&mut self) {
        self.break_chain();
        let initial: Vec<f64> = self.columns.iter().map(|c| c.initial_weight).collect();
        self.rows.reset(&initial);
        self.diverged.fill(false);
    }

    /// Changes α of prediction `col` from the next update on (bounds are the caller's).
    pub fn set_alpha(&mut self, col: usize, alpha: f64) -> Result<(), LearnError> {
        super::bounds::check_alpha_positive("group", alpha)?;
        if self.dutch.is_some() && self.columns.len() > 1 {
            return Err(LearnError::SharedDutchTrace(
                "the step size of one of its predictions cannot change alone (α is in the dutch trace)"
                    .into(),
            ));
        }
        if let Some(c) = self.columns.get_mut(col) {
            c.alpha = alpha;
        }
        Ok(())
    }

    /// Changes λ of the whole group from the next update on.
    pub fn set_lambda(&mut self, lambda: f64) -> Result<(), LearnError> {
        super::bounds::check_lambda("group", lambda)?;
        self.lambda = lambda;
        Ok(())
    }

    /// The weights of prediction `col`, one per feature (computed: the group stores them deferred).
    pub fn weights(&self, col: usize) -> Vec<f64> {
        (0..self.features())
            .map(|f| self.rows.weight(f, col))
            .collect()
    }

    /// The shared trace, one per feature.
    pub fn traces(&self) -> Vec<f64> {
        (0..self.features()).map(|f| self.rows.trace(f)).collect()
    }

    /// The previous tick's features and discount, if the chain has one.
    pub fn previous(&self) -> Option<(&[usize], f64)> {
        self.chain
            .has_prev
            .then_some((&self.chain.x_prev[..], self.chain.gamma_prev))
    }

    /// Replaces prediction `col`'s weights and the trace with dense vectors (a checkpoint of the dense
    /// form) and the previous tick with `previous`; both must have one finite entry per feature.
    pub fn set_dense(
        &mut self,
        col: usize,
        weights: &[f64],
        traces: &[f64],
        previous: Option<(&[usize], f64)>,
    ) -> Result<(), LearnError> {
        super::bounds::check_dense_state("group", self.features(), weights, traces)?;
        if col >= self.columns.len() {
            return Err(LearnError::UnknownPrediction(format!("column {col}")));
        }
        self.rows.set_dense(col, weights, traces);
        self.diverged[col] = false;
        self.set_previous(previous);
        if let Some(d) = &mut self.dutch {
            // The dense form holds no correction pending: V is the restored weights' value of x_{t−1}.
            d.back_prev.fill(0.0);
            d.overlap = 0;
        }
        // The previous prediction under the restored weights, so that the next δ uses it exactly.
        if let Some((x_prev, _)) = previous {
            let coef_sum = self.rows.gather(x_prev, &mut self.acc);
            for (i, y) in self.chain.y_prev.iter_mut().enumerate() {
                *y = self.acc[i].to_f64() + coef_sum * self.rows.a(i);
            }
        }
        Ok(())
    }

    fn set_previous(&mut self, previous: Option<(&[usize], f64)>) {
        let chain = &mut self.chain;
        chain.step_prev.fill(0.0);
        chain.z = 0.0;
        chain.fresh = false;
        match previous {
            Some((x, gamma)) => {
                chain.x_prev.clear();
                chain.x_prev.extend_from_slice(x);
                chain.gamma_prev = gamma;
                chain.has_prev = true;
            }
            None => {
                chain.x_prev.clear();
                chain.has_prev = false;
            }
        }
    }
}

#[cfg(test)]
mod tests;

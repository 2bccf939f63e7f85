//! [`DeferredRows`]: the weight matrix of a [`super::TraceGroup`], feature-major (one row of one weight per
//! prediction for each feature), with its shared trace's updates deferred as described in
//! [`super::epochs`]. Every operation costs the rows it names, times the number of predictions.

use super::epochs::{ClosedEpoch, Epochs};
use super::weight::{Weight, accumulate, add_scaled};

/// The weights and the shared trace of a group of predictions over `features` binary features.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct DeferredRows<W> {
    /// Predictions (columns).
    pub cols: usize,
    /// `W0`, row-major by feature: row `f` is `w0[f·cols .. (f+1)·cols]`.
    pub w0: Vec<W>,
    /// The trace coefficient of each row, in the units of its epoch.
    pub coef: Vec<f64>,
    /// The epoch each row's `W0` and `coef` are relative to.
    pub row_epoch: Vec<u32>,
    /// The epochs.
    pub epochs: Epochs<W>,
}

impl<W: Weight> DeferredRows<W> {
    /// `features` rows whose weights start at `initial[i]` for prediction `i`, with a zero trace.
    pub fn new(features: usize, initial: &[f64]) -> Self {
        let cols = initial.len();
        let row: Vec<W> = initial.iter().map(|&w| W::from_f64(w)).collect();
        let mut w0 = Vec::with_capacity(features * cols);
        for _ in 0..features {
            w0.extend_from_slice(&row);
        }
        DeferredRows {
            cols,
            w0,
            coef: vec![0.0; features],
            row_epoch: vec![0; features],
            epochs: Epochs::new(cols),
        }
    }

    /// The number of feature rows.
    pub fn features(&self) -> usize {
        self.coef.len()
    }

    fn row_mut(&mut self, f: usize) -> &mut [W] {
        let c = self.cols;
        &mut self.w0[f * c..(f + 1) * c]
    }

    /// Brings row `f` into the current epoch: applies the closed epochs' updates it has not seen.
    #[inline]
    pub fn bring_forward(&mut self, f: usize) {
        let from = self.row_epoch[f];
        if from == self.epochs.id {
            return;
        }
        self.row_epoch[f] = self.epochs.id;
        let mut c = self.coef[f];
        if c == 0.0 {
            return;
        }
        let cols = self.cols;
        let (w0, epochs) = (&mut self.w0, &self.epochs);
        let row = &mut w0[f * cols..(f + 1) * cols];
        let mut seen = false;
        for closed in epochs.since(from) {
            seen = true;
            add_scaled(row, W::from_f64(c), &closed.a_end);
            c *= closed.carry;
            if c == 0.0 {
                break;
            }
        }
        // Not in the ring: it cannot be (rows leave with their epoch), but a trace that old is gone.
        debug_assert!(seen, "row {f} of epoch {from} outside the ring");
        self.coef[f] = if seen { c } else { 0.0 };
        if self.coef[f] != 0.0 {
            self.epochs.members.push(f);
        }
    }

    /// Adds rows `active` into `acc` (one sum per prediction) and returns the sum of their
    /// coefficients, after bringing them forward: `wᵀx = acc + Σcoef · A`.
    pub fn gather(&mut self, active: &[usize], acc: &mut [W]) -> f64 {
        acc.fill(W::default());
        let mut coef_sum = 0.0;
        for &f in active {
            if f >= self.coef.len() {
                continue;
            }
            self.bring_forward(f);
            let c = self.cols;
            accumulate(acc, &self.w0[f * c..(f + 1) * c]);
            coef_sum += self.coef[f];
        }
        coef_sum
    }

    /// Decays the trace by `decay` (γ_t λ), closing the epoch when the product would fall below the
    /// floor (always when `decay` is 0).
    pub fn decay(&mut self, decay: f64) {
        let p = self.epochs.p * decay;
        if p >= W::EPOCH_FLOOR {
            self.epochs.p = p;
        } else {
            self.close(p);
        }
    }

    /// Ends every trace (the next update starts a fresh chain of credit). Weights are kept.
    pub fn clear_traces(&mut self) {
        self.close(0.0);
    }

    fn close(&mut self, carry: f64) {
        if let Some(old) = self.epochs.close(carry) {
            self.retire(&old);
        }
    }

    /// The rows still in `old`, an epoch leaving the ring: brought forward through the ring, their
    /// negligible remaining trace dropped.
    fn retire(&mut self, old: &ClosedEpoch<W>) {
        let cols = self.cols;
        for &f in &old.members {
            if self.row_epoch[f] != old.id {
                continue;
            }
            self.row_epoch[f] = self.epochs.id;
            let mut c = self.coef[f];
            self.coef[f] = 0.0;
            let row = &mut self.w0[f * cols..(f + 1) * cols];
            for closed in std::iter::once(old).chain(self.epochs.ring.iter()) {
                if c == 0.0 {
                    break;
                }
                add_scaled(row, W::from_f64(c), &closed.a_end);
                c *= closed.carry;
            }
        }
    }

    /// Adds `g` to the trace of rows `active` (e ← e + g·x), keeping their weights.
    pub fn touch(&mut self, active: &[usize], g: f64) {
        let d = g / self.epochs.p;
        let minus_d = W::from_f64(-d);
        for &f in active {
            if f >= self.coef.len() {
                continue;
            }
            self.bring_forward(f);
            if self.coef[f] == 0.0 {
                self.epochs.members.push(f);
            }
            self.coef[f] += d;
            let cols = self.cols;
            let (w0, a_w) = (&mut self.w0, &self.epochs.a_w);
            add_scaled(&mut w0[f * cols..(f + 1) * cols], minus_d, a_w);
        }
    }

    /// Applies `w ← w + step · e` for prediction `col`. Refused (nothing changes, `false`) when it
    /// would make the deferred sum non-finite.
    pub fn step(&mut self, col: usize, step: f64) -> bool {
        let a = self.epochs.a[col] + step * self.epochs.p;
        let a_w = W::from_f64(a);
        if !a.is_finite() || !a_w.finite() {
            return false;
        }
        self.epochs.a[col] = a;
        self.epochs.a_w[col] = a_w;
        true
    }

    /// `A` of prediction `col` in the current epoch.
    pub fn a(&self, col: usize) -> f64 {
        self.epochs.a[col]
    }

    /// The coefficient of row `f` in the current epoch's units, without changing anything.
    fn coef_now(&self, f: usize) -> f64 {
        let mut c = self.coef[f];
        if c != 0.0 && self.row_epoch[f] != self.epochs.id {
            let mut seen = false;
            for closed in self.epochs.since(self.row_epoch[f]) {
                seen = true;
                c *= closed.carry;
            }
            if !seen {
                c = 0.0;
            }
        }
        c
    }

    /// The trace summed over rows `active`: `eᵀx`.
    pub fn trace_dot(&self, active: &[usize]) -> f64 {
        let sum: f64 = active
            .iter()
            .filter(|&&f| f < self.coef.len())
            .map(|&f| self.coef_now(f))
            .sum();
        sum * self.epochs.p
    }

    /// The trace of row `f`, e(f).
    pub fn trace(&self, f: usize) -> f64 {
        self.coef_now(f) * self.epochs.p
    }

    /// The weight of prediction `col` at row `f`, without changing anything.
    pub fn weight(&self, f: usize, col: usize) -> f64 {
        let mut w = self.w0[f * self.cols + col].to_f64();
        let mut c = self.coef[f];
        if self.row_epoch[f] != self.epochs.id && c != 0.0 {
            let mut seen = false;
            for closed in self.epochs.since(self.row_epoch[f]) {
                seen = true;
                w += (W::from_f64(c) * closed.a_end[col]).to_f64();
                c *= closed.carry;
            }
            if !seen {
                c = 0.0;
            }
        }
        w + c * self.epochs.a[col]
    }

    /// Every row back to `initial[i]` for prediction `i`, with a zero trace.
    pub fn reset(&mut self, initial: &[f64]) {
        let row: Vec<W> = initial.iter().map(|&w| W::from_f64(w)).collect();
        for f in 0..self.features() {
            self.row_mut(f).copy_from_slice(&row);
        }
        self.coef.fill(0.0);
        self.epochs.restart();
        self.row_epoch.fill(self.epochs.id);
    }

    /// Sets prediction `col`'s weights to `weights` and every row's trace to `traces` (one per row),
    /// in a fresh epoch.
    pub fn set_dense(&mut self, col: usize, weights: &[f64], traces: &[f64]) {
        let cols = self.cols;
        // Bring every row into a fresh epoch with A = 0, so that W0 holds the weight itself.
        let materialized: Vec<Vec<f64>> = (0..cols)
            .map(|i| (0..self.features()).map(|f| self.weight(f, i)).collect())
            .collect();
        self.epochs.restart();
        for f in 0..self.features() {
            for (i, column) in materialized.iter().enumerate() {
                let w = if i == col { weights[f] } else { column[f] };
                self.w0[f * cols + i] = W::from_f64(w);
            }
            self.coef[f] = traces[f];
            self.row_epoch[f] = self.epochs.id;
            if traces[f] != 0.0 {
                self.epochs.members.push(f);
            }
        }
    }
}

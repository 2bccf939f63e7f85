//! [`DeferredRows`]: the weight matrix of a [`super::TraceGroup`], feature-major (one row of one weight per
//! prediction for each feature), with its shared trace's updates deferred as described in
//! [`super::epochs`]. Every operation costs the rows it names, times the number of predictions.

use super::copy::RowCopy;
use super::epochs::{ClosedEpoch, Epochs};
use super::weight::{Weight, accumulate_wide as accumulate, add_scaled_wide as add_scaled};

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
    /// At least the largest `|W0|` (raised by every write, exact after a rescan).
    pub w0_bound: f64,
    /// At least the largest `|coef|`.
    pub coef_bound: f64,
    /// The rows the last `gather` read carry its mark.
    pub marks: Vec<u32>,
    pub mark: u32,
    /// The rows a one-pass tick touches (`super::fused`) carry that tick's `mark` here.
    pub touched: Vec<u32>,
    /// The write that brings a row forward, left by [`DeferredRows::bring_forward_later`] for a
    /// one-pass tick to make after it has read the row (empty between ticks).
    pub forward: Vec<Option<W>>,
    /// A copy of `W0` in progress: every write preserves the row first.
    pub copy: Option<RowCopy<W>>,
}

impl<W: Weight> DeferredRows<W> {
    /// `features` rows whose weights start at `initial[i]` for prediction `i`, with a zero trace.
    pub fn new(features: usize, initial: &[f64]) -> Self {
        let cols = initial.len();
        let row: Vec<W> = initial.iter().map(|&w| W::from_f64(w)).collect();
        let mut w0 = super::huge::weight_vec(features * cols);
        for _ in 0..features {
            w0.extend_from_slice(&row);
        }
        DeferredRows {
            cols,
            w0,
            coef: vec![0.0; features],
            row_epoch: vec![0; features],
            epochs: Epochs::new(cols),
            w0_bound: initial.iter().fold(0.0f64, |m, w| m.max(w.abs())),
            coef_bound: 0.0,
            marks: vec![0; features],
            mark: 0,
            touched: vec![0; features],
            forward: vec![None; features],
            copy: None,
        }
    }

    /// Starts a copy of `W0` as it is now (see [`RowCopy`]), into `buffer` if it has the size; false
    /// (and `buffer` dropped) when one is in progress.
    pub fn begin_copy(&mut self, buffer: Option<Vec<W>>) -> bool {
        if self.copy.is_some() {
            return false;
        }
        self.copy = Some(RowCopy::new(self.features(), self.cols, buffer));
        true
    }

    /// Copies up to `rows` more rows; returns whether the copy is complete (false without a copy).
    pub fn copy_some(&mut self, rows: usize) -> bool {
        match self.copy.as_mut() {
            Some(c) => c.copy_some(&self.w0, rows),
            None => false,
        }
    }

    /// The copy's rows still to copy (0 without a copy).
    pub fn copy_left(&self) -> usize {
        self.copy.as_ref().map_or(0, RowCopy::left)
    }

    /// The completed copy, taken out; `None` while incomplete or without one.
    pub fn take_copy(&mut self) -> Option<Vec<W>> {
        if self.copy.as_ref().is_some_and(RowCopy::is_complete) {
            self.copy.take().map(RowCopy::into_weights)
        } else {
            None
        }
    }

    /// Completes a copy in progress at once (before `W0` is rewritten whole).
    pub fn complete_copy(&mut self) {
        let rows = self.features();
        self.copy_some(rows);
    }

    #[inline]
    pub(super) fn preserve(&mut self, f: usize) {
        if let Some(c) = self.copy.as_mut() {
            c.preserve(f, &self.w0);
        }
    }

    /// Starts a new tick's marks ([`DeferredRows::marks`], [`DeferredRows::touched`]). The mark never
    /// comes back to 0, the mark of no tick: when the counter wraps, the old marks are cleared.
    pub fn next_mark(&mut self) {
        self.mark = self.mark.wrapping_add(1);
        if self.mark == 0 {
            self.marks.fill(0);
            self.touched.fill(0);
            self.mark = 1;
        }
    }

    /// Recomputes the bounds on `|W0|` and `|coef|` exactly.
    pub fn rescan_bounds(&mut self) {
        self.w0_bound = self.w0.iter().fold(0.0f64, |m, w| m.max(w.to_f64().abs()));
        self.coef_bound = self.coef.iter().fold(0.0f64, |m, c| m.max(c.abs()));
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
        if self.row_epoch[f] != self.epochs.id {
            self.bring_forward_from_old_epoch(f);
        }
    }

    #[inline(never)]
    fn bring_forward_from_old_epoch(&mut self, f: usize) {
        let from = self.row_epoch[f];
        self.row_epoch[f] = self.epochs.id;
        let mut c = self.coef[f];
        if c == 0.0 {
            return;
        }
        self.preserve(f);
        let cols = self.cols;
        let (w0, epochs) = (&mut self.w0, &self.epochs);
        let row = &mut w0[f * cols..(f + 1) * cols];
        let mut seen = false;
        let mut raise = 0.0;
        for closed in epochs.since(from) {
            seen = true;
            add_scaled(row, W::from_f64(c), &closed.a_end);
            raise += c.abs() * closed.a_end_max;
            c *= closed.carry;
            if c == 0.0 {
                break;
            }
        }
        self.w0_bound += raise;
        // Not in the ring: it cannot be (rows leave with their epoch), but a trace that old is gone.
        debug_assert!(seen, "row {f} of epoch {from} outside the ring");
        self.coef[f] = if seen { c } else { 0.0 };
        if self.coef[f] != 0.0 {
            self.epochs.members.push(f);
        }
    }

    /// [`DeferredRows::bring_forward`] of row `f`, one epoch behind, but for its write: returns the
    /// factor `k` of the write `W0(f) += k · A_end` of the newest closed epoch for the caller to make
    /// (`None` when there is none to make), so that the row can still be read as it was before.
    /// A row further behind is brought forward at once (and `None` returned).
    pub fn bring_forward_later(&mut self, f: usize) -> Option<W> {
        let from = self.row_epoch[f];
        if from == self.epochs.id {
            return None;
        }
        let Some(newest) = self.epochs.ring.back().filter(|c| c.id == from) else {
            self.bring_forward_from_old_epoch(f);
            return None;
        };
        self.row_epoch[f] = self.epochs.id;
        let c = self.coef[f];
        if c == 0.0 {
            return None;
        }
        let (k, raise, carry) = (W::from_f64(c), c.abs() * newest.a_end_max, newest.carry);
        self.preserve(f);
        self.w0_bound += raise;
        self.coef[f] = c * carry;
        if self.coef[f] != 0.0 {
            self.epochs.members.push(f);
        }
        Some(k)
    }

    /// Adds rows `active` into `acc` (one sum per prediction) and returns the sum of their
    /// coefficients, after bringing them forward: `wᵀx = acc + Σcoef · A`. Marks the rows, so that
    /// the next [`DeferredRows::touch`] can count how many of its rows are among them.
    pub fn gather(&mut self, active: &[usize], acc: &mut [W]) -> f64 {
        acc.fill(W::default());
        self.next_mark();
        let mut coef_sum = 0.0;
        let cols = self.cols;
        for &f in active {
            if f >= self.coef.len() {
                continue;
            }
            self.bring_forward(f);
            self.marks[f] = self.mark;
            if cols == 1 {
                acc[0] = acc[0] + self.w0[f];
            } else {
                accumulate(acc, &self.w0[f * cols..(f + 1) * cols]);
            }
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
            if let Some(copy) = self.copy.as_mut() {
                copy.preserve(f, &self.w0);
            }
            let row = &mut self.w0[f * cols..(f + 1) * cols];
            for closed in std::iter::once(old).chain(self.epochs.ring.iter()) {
                if c == 0.0 {
                    break;
                }
                add_scaled(row, W::from_f64(c), &closed.a_end);
                self.w0_bound += c.abs() * closed.a_end_max;
                c *= closed.carry;
            }
        }
    }

    /// Adds `g` to the trace of rows `active` (e ← e + g·x), keeping their weights. Returns how many of
    /// them the last [`DeferredRows::gather`] read.
    pub fn touch(&mut self, active: &[usize], g: f64) -> usize {
        let d = g / self.epochs.p;
        let minus_d = W::from_f64(-d);
        let a_max = self.epochs.a.iter().fold(0.0f64, |m, a| m.max(a.abs()));
        let cols = self.cols;
        let mut touched = false;
        let mut read = 0;
        for &f in active {
            if f >= self.coef.len() {
                continue;
            }
            self.bring_forward(f);
            if self.coef[f] == 0.0 {
                self.epochs.members.push(f);
            }
            self.coef[f] += d;
            self.coef_bound = self.coef_bound.max(self.coef[f].abs());
            touched = true;
            read += usize::from(self.marks[f] == self.mark);
            self.preserve(f);
            if cols == 1 {
                self.w0[f] = self.w0[f] + minus_d * self.epochs.a_w[0];
            } else {
                let (w0, a_w) = (&mut self.w0, &self.epochs.a_w);
                add_scaled(&mut w0[f * cols..(f + 1) * cols], minus_d, a_w);
            }
        }
        if touched {
            // Each touched row moved by at most |d|·max|A|: so did the largest.
            self.w0_bound += d.abs() * a_max;
        }
        read
    }

    /// The carry of the epoch closed since epoch `id`, or 1 when `id` is still the current one: what
    /// turns a coefficient read in epoch `id` into the current epoch's units (at most one epoch closes
    /// between a `gather` and the `touch` after it).
    pub fn carry_since(&self, id: u32) -> f64 {
        if id == self.epochs.id {
            1.0
        } else {
            self.epochs.since(id).map(|c| c.carry).product()
        }
    }

    /// The current epoch's number.
    pub fn epoch(&self) -> u32 {
        self.epochs.id
    }

    /// `P`, the trace's scale in the current epoch.
    pub fn p(&self) -> f64 {
        self.epochs.p
    }

    /// Applies `w ← w + step · e` for prediction `col`. Refused (nothing changes, `false`) when it
    /// would make a weight non-finite.
    ///
    /// Every weight is `W0 + coef·A` plus the closed epochs' `coef·A_end`, so it is at most
    /// `max|W0| + max|coef| · (Σ max|A_end| + |A|)` in size: while that bound is below
    /// [`Weight::SAFE`] the step is safe without looking at a row. Above it (a diverging learner, or
    /// extreme weights restored), every row of the prediction is checked.
    pub fn step(&mut self, col: usize, step: f64) -> bool {
        let a = self.epochs.a[col] + step * self.epochs.p;
        let a_w = W::from_f64(a);
        if !a.is_finite() || !a_w.finite() {
            return false;
        }
        let bound = self.w0_bound + self.coef_bound * (self.epochs.ring_a_max() + a.abs().max(1.0));
        let surely_safe = bound < W::SAFE; // false for a NaN bound too
        if !surely_safe && !self.step_stays_finite(col, step) {
            return false;
        }
        self.epochs.a[col] = a;
        self.epochs.a_w[col] = a_w;
        true
    }

    /// Whether every weight of prediction `col` stays finite, and below [`Weight::SAFE`], after `step`.
    fn step_stays_finite(&self, col: usize, step: f64) -> bool {
        let change = step * self.epochs.p;
        (0..self.features()).all(|f| {
            let w = self.weight(f, col) + self.coef_now(f) * change;
            w.is_finite() && w.abs() < W::SAFE
        })
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
        self.complete_copy();
        let row: Vec<W> = initial.iter().map(|&w| W::from_f64(w)).collect();
        for f in 0..self.features() {
            self.row_mut(f).copy_from_slice(&row);
        }
        self.coef.fill(0.0);
        self.epochs.restart();
        self.row_epoch.fill(self.epochs.id);
        self.rescan_bounds();
    }

    /// Sets prediction `col`'s weights to `weights` and every row's trace to `traces` (one per row),
    /// in a fresh epoch.
    pub fn set_dense(&mut self, col: usize, weights: &[f64], traces: &[f64]) {
        self.complete_copy();
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
        self.rescan_bounds();
    }
}

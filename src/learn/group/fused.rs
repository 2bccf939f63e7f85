//! [`TraceGroup::predict_and_learn`]: a tick's prediction and update in one pass over the weights, for
//! a group too wide for its active rows to stay in the cache between the two.
//!
//! A tick of [`TraceGroup::predict`] then [`TraceGroup::learn`] reads this tick's active rows (the sums
//! `wᵀx`) and then reads and writes the previous tick's (the trace's touch, `W0 −= d·A`). Features
//! persist from tick to tick, so these are mostly the same rows, but at Horde scale a group's active
//! rows are megabytes (484 rows × 5,854 predictions × 4 bytes = 11 MB) and are gone from the cache by
//! the time the touch comes back to them: every row is brought from memory twice.
//!
//! Both passes are column by column: a sum for column `i` reads column `i` of each row, the touch of
//! column `i` writes column `i` with `A_i`. What ties the columns together is the bookkeeping of the
//! rows (their trace coefficients and epochs) and the step into `A`, which needs the sums. So the
//! bookkeeping of both passes is done first (the same calls, in the same order, as `predict` and
//! `learn` make), then one pass ([`Pass`]) runs over a block of [`CHUNK`] columns at a time: each of
//! this tick's rows is added into the sums and, when the previous tick had it too, touched in the same
//! loop, its block read once; then the previous tick's other rows are touched; and then the steps.
//! The next row's block is prefetched while one is summed (the rows are scattered over the matrix, and
//! the hardware's prefetcher only finds a row after its first lines have missed), and on a CPU with
//! AVX2 the pass uses it. Every weight sees the same operations on the same values in the same order:
//! the result is bit for bit that of `predict` then `learn` (the tests compare them).
//!
//! When the decay closes the epoch, the previous tick's rows are brought into the new epoch
//! (`W0 += coef · A_end`) by the touch, after this tick's sums have read them: for the rows both ticks
//! have, the bookkeeping leaves that write to the pass
//! ([`super::rows::DeferredRows::bring_forward_later`]), which makes it after the row's sum, and the
//! values' part from `A` is taken before the close restarts `A`. A logistic group (one column), a first
//! tick or a predict left without its learn run `predict` and `learn` as they are.

use super::weight::{
    Weight, accumulate, accumulate_and_add_scaled, accumulate_forward_and_add_scaled, add_scaled,
};
use super::{LearnError, Sigma, TraceGroup};

/// Columns per block: 512 `f32` are 2 KiB a row, so a block of a Horde's 484 active rows is 1 MB and
/// stays in a 2 MB L2 cache between the two passes.
pub(crate) const CHUNK: usize = 512;

impl<W: Weight> TraceGroup<W> {
    /// [`TraceGroup::predict`] with `active`, then [`TraceGroup::learn`] with `gamma_t` and
    /// `cumulants`, with the same result bit for bit, reading each weight row once (see the module
    /// documentation). Returns the predictions stopped on this step.
    pub fn predict_and_learn(
        &mut self,
        active: &[usize],
        gamma_t: f64,
        cumulants: &[f64],
        deltas: &mut [f64],
    ) -> Result<usize, LearnError> {
        let decay = self.chain.gamma_prev * self.lambda;
        let cols = self.columns.len();
        // A true-online group (`super::dutch`) has its own update, in two passes.
        let fusable = self.dutch.is_none()
            && self.chain.has_prev
            && !self.chain.fresh
            && self.sigma == Sigma::Identity
            && cumulants.len() == cols
            && deltas.len() == cols;
        if !fusable {
            self.predict(active);
            return self.learn(gamma_t, cumulants, deltas);
        }
        // `predict`'s bookkeeping: rows brought forward and marked, their coefficients summed.
        let coef_sum = self.gather_rows(active);
        self.chain.coef_sum_now = coef_sum;
        self.chain.epoch_now = self.rows.epoch();
        self.chain.x_now.clear();
        self.chain.x_now.extend_from_slice(active);
        // The values' part from `A`, which a closing epoch would restart.
        for (i, y) in self.chain.y_now.iter_mut().enumerate() {
            *y = coef_sum * self.rows.a(i);
        }
        // `learn`'s: the decay (which may close the epoch), then the touch of the previous tick's rows.
        self.rows.decay(decay);
        let (minus_d, read_again) = self.touch_rows();
        // Both passes over the weights, a block of columns at a time.
        self.sum_and_touch(minus_d);
        for (y, acc) in self.chain.y_now.iter_mut().zip(&self.acc) {
            *y += acc.to_f64();
        }
        deltas.fill(f64::NAN);
        let (stopped, grad) = self.deltas(gamma_t, cumulants, deltas);
        Ok(self.finish_step(gamma_t, deltas, stopped, grad, read_again))
    }

    /// What [`super::rows::DeferredRows::gather`] does but the sums: brings rows `active` forward,
    /// marks them and returns the sum of their coefficients.
    fn gather_rows(&mut self, active: &[usize]) -> f64 {
        let rows = &mut self.rows;
        rows.next_mark();
        let mut coef_sum = 0.0;
        for &f in active {
            if f >= rows.coef.len() {
                continue;
            }
            rows.bring_forward(f);
            rows.marks[f] = rows.mark;
            coef_sum += rows.coef[f];
        }
        coef_sum
    }

    /// What [`super::rows::DeferredRows::touch`] does with `g = 1` but the rows' weights: the previous
    /// tick's rows brought forward (none is also read this tick: without an epoch closing, those were
    /// brought forward by [`TraceGroup::gather_rows`]), their coefficients raised, each row preserved for a
    /// copy in progress before it is written. Returns `−d` as a weight (the touch's factor on `A`) and
    /// how many of the rows this tick reads.
    fn touch_rows(&mut self) -> (W, usize) {
        let rows = &mut self.rows;
        let d = 1.0 / rows.epochs.p;
        let minus_d = W::from_f64(-d);
        let a_max = rows.epochs.a.iter().fold(0.0f64, |m, a| m.max(a.abs()));
        let mut touched = false;
        let mut read = 0;
        for &f in &self.chain.x_prev {
            if f >= rows.coef.len() {
                continue;
            }
            if rows.marks[f] == rows.mark {
                // Read this tick: its write waits for the pass.
                rows.forward[f] = rows.bring_forward_later(f);
            } else {
                rows.bring_forward(f);
            }
            if rows.coef[f] == 0.0 {
                rows.epochs.members.push(f);
            }
            rows.coef[f] += d;
            rows.coef_bound = rows.coef_bound.max(rows.coef[f].abs());
            touched = true;
            read += usize::from(rows.marks[f] == rows.mark);
            rows.touched[f] = rows.mark;
            rows.preserve(f);
        }
        if touched {
            rows.w0_bound += d.abs() * a_max;
        }
        (minus_d, read)
    }

    /// The sums of this tick's rows into `acc`, and the touch `W0 += minus_d·A` of the previous tick's,
    /// a block of [`CHUNK`] columns at a time (see [`Pass`]).
    fn sum_and_touch(&mut self, minus_d: W) {
        self.acc.fill(W::default());
        let rows = &mut self.rows;
        let pass = Pass {
            cols: self.columns.len(),
            x_now: &self.chain.x_now,
            x_prev: &self.chain.x_prev,
            marks: &rows.marks,
            touched: &rows.touched,
            mark: rows.mark,
            forward: &rows.forward,
            a_end: rows.epochs.ring.back().map_or(&[][..], |c| &c.a_end[..]),
            a_w: &rows.epochs.a_w,
            minus_d,
        };
        pass.run(&mut rows.w0, &mut self.acc);
        for &f in &self.chain.x_now {
            if let Some(k) = rows.forward.get_mut(f) {
                *k = None;
            }
        }
    }
}

/// One tick's pass over a group's active rows. For each block of [`CHUNK`] columns: this tick's rows
/// in their order, each added into the sums and, if the previous tick's features include it (most
/// do: features persist), touched in the same loop, so that its block is read once; then the
/// previous tick's rows that this tick does not read, touched. A row's sum reads its weights before
/// its touch writes them, the sums add the rows in the same order, and a row's touch is the same
/// operation whenever it comes (no row is in `x_prev` twice): the result is bit for bit that of
/// summing every row and then touching every row.
struct Pass<'a, W> {
    cols: usize,
    x_now: &'a [usize],
    x_prev: &'a [usize],
    /// `marks[f] == mark`: row `f` is among this tick's.
    marks: &'a [u32],
    /// `touched[f] == mark`: row `f` is among the previous tick's.
    touched: &'a [u32],
    mark: u32,
    /// `forward[f] = Some(k)`: row `f`, one of this tick's, is brought forward after its sum reads
    /// it, `W0(f) += k · a_end` (`a_end`: `A` at the close of the epoch this tick closed).
    forward: &'a [Option<W>],
    a_end: &'a [W],
    a_w: &'a [W],
    minus_d: W,
}

impl<W: Weight> Pass<'_, W> {
    /// Runs the pass, with the instructions of the widest vectors the CPU has where it is known to
    /// have them: the same operations element by element (Rust never fuses a multiply and an add on
    /// its own), so the same bits.
    fn run(&self, w0: &mut [W], acc: &mut [W]) {
        #[cfg(target_arch = "x86_64")]
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2 (just checked), the only requirement of a `target_feature`
            // function.
            unsafe { self.run_avx2(w0, acc) };
            return;
        }
        self.run_portable(w0, acc);
    }

    #[cfg(target_arch = "x86_64")]
    #[target_feature(enable = "avx2")]
    fn run_avx2(&self, w0: &mut [W], acc: &mut [W]) {
        self.run_portable(w0, acc);
    }

    #[inline(always)]
    fn run_portable(&self, w0: &mut [W], acc: &mut [W]) {
        let (cols, features) = (self.cols, self.marks.len());
        let mut start = 0;
        while start < cols {
            let end = (start + CHUNK).min(cols);
            let acc = &mut acc[start..end];
            let a = &self.a_w[start..end];
            let a_end = self.a_end.get(start..end).unwrap_or(&[]);
            let block = |f: usize| f * cols + start..f * cols + end;
            for (k, &f) in self.x_now.iter().enumerate() {
                if f >= features {
                    continue;
                }
                if let Some(&next) = self.x_now.get(k + 1) {
                    prefetch(w0, block(next.min(features - 1)));
                }
                if let Some(k) = self.forward[f] {
                    accumulate_forward_and_add_scaled(
                        acc,
                        &mut w0[block(f)],
                        k,
                        a_end,
                        self.minus_d,
                        a,
                    );
                } else if self.touched[f] == self.mark {
                    accumulate_and_add_scaled(acc, &mut w0[block(f)], self.minus_d, a);
                } else {
                    accumulate(acc, &w0[block(f)]);
                }
            }
            for &f in self.x_prev {
                if f < features && self.marks[f] != self.mark {
                    add_scaled(&mut w0[block(f)], self.minus_d, a);
                }
            }
            start = end;
        }
    }
}

/// Asks for the cache lines of `w[range]` ahead of their use (the rows of a tick are scattered over the
/// matrix: the hardware's prefetcher finds each row only after its first lines have missed).
#[inline(always)]
fn prefetch<W>(w: &[W], range: std::ops::Range<usize>) {
    #[cfg(target_arch = "x86_64")]
    {
        use std::arch::x86_64::{_MM_HINT_T0, _mm_prefetch};
        let row = &w[range];
        let bytes = std::mem::size_of_val(row);
        let base = row.as_ptr().cast::<i8>();
        for line in (0..bytes).step_by(64) {
            // SAFETY: `base + line` lies within `row` (line < its size in bytes); a prefetch only
            // hints the cache and never faults, reads into a register or writes.
            unsafe { _mm_prefetch::<_MM_HINT_T0>(base.add(line)) };
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::learn::group::Column;
    use crate::learn::test_stream::held_stream;
    use crate::learn::tiles::TileCoder;

    /// Runs two groups of `cols` predictions over the same stream, one with `predict` then `learn`, the
    /// other with `predict_and_learn`, and asserts that every value, every δ and, at the end, the whole
    /// state are the same bit for bit. A copy of the weights is taken while they learn (from tick 50),
    /// and the stimulus ends the traces now and then (γ = 0: an epoch closes).
    fn same_bits<W: Weight>(cols: usize, lambda: f64, tau: f64, seed: u64) {
        let coder = TileCoder::one_dim(12, 8).unwrap();
        let n = coder.num_features();
        let columns: Vec<Column> = (0..cols)
            .map(|i| Column {
                alpha: 0.01 + 0.002 * (i % 7) as f64,
                initial_weight: 0.1 * (i % 3) as f64,
            })
            .collect();
        let mut two: TraceGroup<W> = TraceGroup::new(n, lambda, Sigma::Identity, columns).unwrap();
        let mut one = two.clone();
        let (mut d2, mut d1) = (vec![0.0; cols], vec![0.0; cols]);
        let mut active = Vec::new();
        let (mut fused_ticks, mut closing_ticks) = (0, 0);
        for (t, (x, stim)) in held_stream(600, 12, 0.03, seed).into_iter().enumerate() {
            coder.active(&x, &mut active);
            if t % 97 == 40 {
                // Now and then a feature beyond the matrix, which both ignore.
                active.push(n + 3);
            }
            let gamma = if stim { 0.0 } else { 1.0 - 1.0 / tau };
            let r: Vec<f64> = (0..cols)
                .map(|i| {
                    if i == 0 {
                        f64::from(u8::from(stim))
                    } else {
                        x[i % 12]
                    }
                })
                .collect();
            let p = one.rows.epochs.p * one.chain.gamma_prev * lambda;
            fused_ticks += usize::from(one.chain.has_prev);
            closing_ticks += usize::from(one.chain.has_prev && p < W::EPOCH_FLOOR);
            if t == 50 {
                assert!(two.begin_snapshot() && one.begin_snapshot());
            }
            two.predict(&active);
            let s2 = two.learn(gamma, &r, &mut d2).unwrap();
            let s1 = one.predict_and_learn(&active, gamma, &r, &mut d1).unwrap();
            assert_eq!(s1, s2);
            let bits = |v: &[f64]| v.iter().map(|y| y.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(one.values()), bits(two.values()), "values at tick {t}");
            assert_eq!(bits(&d1), bits(&d2), "deltas at tick {t}");
            if t > 50 {
                assert_eq!(one.advance_snapshot(3), two.advance_snapshot(3));
            }
        }
        // Every tick after the first is one pass, those that close an epoch too (every tick for λ = 0,
        // and wherever the stimulus ends the traces).
        assert_eq!(fused_ticks, 599);
        assert!(
            closing_ticks >= 5,
            "ticks closing an epoch: {closing_ticks}"
        );
        assert_eq!(one.state(), two.state());
        assert_eq!(one.take_snapshot(), two.take_snapshot());
    }

    #[test]
    fn one_pass_is_bit_for_bit_two_passes() {
        same_bits::<f32>(1, 0.9, 25.0, 1);
        same_bits::<f32>(3, 0.5, 5.0, 2);
        same_bits::<f32>(2 * CHUNK + 37, 0.9, 25.0, 3);
        same_bits::<f64>(CHUNK + 1, 0.9, 10.0, 4);
        same_bits::<f64>(5, 0.0, 10.0, 5);
    }
}

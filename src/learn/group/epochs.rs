//! The epochs of a [`super::rows::DeferredRows`]: the bookkeeping that lets a trace's weight updates be
//! applied to a row only when the row is next read or touched.
//!
//! # The deferred update
//!
//! With accumulating traces over binary features, every feature row `f` of a group shares one trace
//! `e_t(f)`, and the update `w(f, i) += α_i δ_i(t) e_t(f)` of prediction `i` touches every row with a
//! non-zero trace, which is every row seen in the last few hundred ticks. Between two touches of a row its
//! trace only decays, `e_t(f) = coef_f · P_t`, where `P_t` is the product of the decays `γλ` since the
//! epoch began and `coef_f` is constant. So the row's weights follow
//!
//! ```text
//! w_t(f, i) = W0(f, i) + coef_f · A_i(t),     A_i(t) = Σ_{s ≤ t} α_i δ_i(s) · P_s
//! ```
//!
//! with `A_i` one number per prediction for the whole group. A step adds `α_i δ_i P_t` to `A_i` (cost:
//! one number per prediction); touching a row (its feature is active, so `coef_f += g/P_t`) moves the
//! change into `W0` so that `w` stays the same (`W0(f, ·) −= (g/P_t) · A`, one row). A tick costs the
//! active rows, never all rows.
//!
//! # Epochs
//!
//! `P_t` shrinks every tick, so `coef_f` grows like `1/P_t`; before `P_t` falls below
//! [`super::weight::Weight::EPOCH_FLOOR`] the epoch is **closed**: its final `A` is kept, `P` restarts at
//! 1 and `A` at 0, and a row still in the closed epoch is brought forward when next used
//! (`W0 += coef · A_end`, `coef *= carry`, where `carry` is `P` at the close: the factor from the old
//! epoch's units to the new one's). A decay of 0 (a termination γ = 0, or λ = 0) closes the epoch with
//! carry 0: every trace ends there.
//!
//! The last [`RING_EPOCHS`] closed epochs are kept. When one leaves the ring, the rows still in it are
//! brought forward and their trace is dropped: it has decayed by at least `EPOCH_FLOOR^RING_EPOCHS`
//! (1e-16 of its value for f64 weights, 1e-8 for f32), below what the weights can hold.
//!
//! Derived for this project; checked against the dense reference [`crate::learn::TdLambda`] by the tests
//! of [`super::TraceGroup`].

use std::collections::VecDeque;

use super::weight::Weight;

/// How many closed epochs are kept.
pub(crate) const RING_EPOCHS: usize = 4;

/// A closed epoch.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct ClosedEpoch<W> {
    /// Its number.
    pub id: u32,
    /// The trace decay product at its close: multiplies a coefficient of this epoch into the next one's.
    pub carry: f64,
    /// `A` at its close, one per prediction.
    pub a_end: Vec<W>,
    /// The largest `|A|` at its close.
    pub a_end_max: f64,
    /// The rows that entered it with a non-zero trace (some may have moved on since).
    pub members: Vec<usize>,
}

/// The epoch in progress and the ring of closed ones.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Epochs<W> {
    /// The current epoch's number.
    pub id: u32,
    /// `P`: the product of the decays since the current epoch began (1 at its start).
    pub p: f64,
    /// `A`, one per prediction, exact.
    pub a: Vec<f64>,
    /// `A` as weights, for the row kernels.
    pub a_w: Vec<W>,
    /// Rows that entered the current epoch with a non-zero trace.
    pub members: Vec<usize>,
    /// The closed epochs, oldest first, at most [`RING_EPOCHS`], numbered consecutively up to `id − 1`.
    pub ring: VecDeque<ClosedEpoch<W>>,
}

impl<W: Weight> Epochs<W> {
    /// A first epoch for `cols` predictions.
    pub fn new(cols: usize) -> Self {
        Epochs {
            id: 0,
            p: 1.0,
            a: vec![0.0; cols],
            a_w: vec![W::default(); cols],
            members: Vec::new(),
            ring: VecDeque::with_capacity(RING_EPOCHS + 1),
        }
    }

    /// Closes the current epoch with `carry` and starts the next; returns the epoch that left the
    /// ring, if one did (its rows must be brought forward by the caller).
    pub fn close(&mut self, carry: f64) -> Option<ClosedEpoch<W>> {
        let cols = self.a.len();
        let evicted = (self.ring.len() == RING_EPOCHS)
            .then(|| self.ring.pop_front())
            .flatten();
        let a_end = std::mem::replace(&mut self.a_w, vec![W::default(); cols]);
        let a_end_max = self.a.iter().fold(0.0f64, |m, a| m.max(a.abs()));
        self.ring.push_back(ClosedEpoch {
            id: self.id,
            carry,
            a_end,
            a_end_max,
            members: std::mem::take(&mut self.members),
        });
        self.id = self.id.wrapping_add(1);
        self.p = 1.0;
        self.a.fill(0.0);
        evicted
    }

    /// The closed epochs from `id` on, oldest first; empty when `id` is not in the ring.
    pub fn since(&self, id: u32) -> impl Iterator<Item = &ClosedEpoch<W>> + '_ {
        let start = self
            .ring
            .front()
            .map_or(usize::MAX, |front| id.wrapping_sub(front.id) as usize);
        self.ring.iter().skip(start.min(self.ring.len()))
    }

    /// The sum of the closed epochs' largest `|A|`.
    pub fn ring_a_max(&self) -> f64 {
        self.ring.iter().map(|c| c.a_end_max).sum()
    }

    /// Back to a first epoch with `A = 0` and no closed epochs (the numbering continues).
    pub fn restart(&mut self) {
        self.ring.clear();
        self.members.clear();
        self.id = self.id.wrapping_add(1);
        self.p = 1.0;
        self.a.fill(0.0);
        self.a_w.fill(W::default());
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_ring_keeps_the_last_closed_epochs_in_order() {
        let mut e: Epochs<f64> = Epochs::new(2);
        for k in 0..RING_EPOCHS {
            e.a = vec![k as f64, 0.0];
            e.a_w = vec![k as f64, 0.0];
            e.members.push(k);
            assert!(e.close(0.5).is_none());
        }
        assert_eq!(e.id, RING_EPOCHS as u32);
        assert_eq!(e.since(1).map(|c| c.id).collect::<Vec<_>>(), vec![1, 2, 3]);
        assert_eq!(e.since(9).count(), 0, "an id not in the ring");
        let out = e.close(0.5).expect("the oldest leaves");
        assert_eq!(
            (out.id, out.members.clone(), out.a_end[0]),
            (0, vec![0], 0.0)
        );
        assert_eq!(e.ring.front().map(|c| c.id), Some(1));
        assert_eq!((e.p, e.a.clone()), (1.0, vec![0.0, 0.0]));
    }
}

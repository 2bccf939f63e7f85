//! What a prediction's values turned out to be worth: the realised return each value was predicting,
//! known some ticks later, the error between them, and the one-step TD error of the values as recorded.
//!
//! A prediction with cumulant `R` and discount `γ` learned by TD (see [`crate::learn::group`]) at tick `t`
//! predicts the return `G_t = R_{t+1} + γ_{t+1} R_{t+2} + γ_{t+1} γ_{t+2} R_{t+3} + …`. For the paper's
//! predictions (`R = I{E}`, `γ = (1 − I{E})(1 − 1/τ)`, see [`crate::learn::PredictionSpec`]) the sum ends
//! on the stimulus. [`ReturnTracker`] adds each tick's `R_t` into the return of every earlier tick still
//! waiting, and hands a value and its return back as a [`Realised`] pair as soon as the return is known:
//! exactly when the prediction terminates (`γ = 0`), or truncated at the horizon `H`, the first `k` with
//! `(1 − 1/τ)^k < tolerance`. A truncated return misses at most `(1 − 1/τ)^H` times the largest return
//! that could follow (for a stimulus indicator, at most 1): with the default tolerance the bias is below
//! 0.01. `H` is capped at [`MAX_HORIZON`] ticks so an enormous τ cannot make the tracker hold an enormous
//! backlog; [`ReturnTracker::tail_bound`] says what the truncation may then miss.
//!
//! It runs beside learning, not inside it (the dashboard's hub runs it on every tick record, off the tick
//! path), so its TD error is the one of the *recorded* values: `δ_t = R_t + γ_t v_t − v_{t−1}`, with `v`
//! as each tick predicted it before its own update. The learner's internal δ differs from it by the
//! previous update's own effect on `v(x_{t−1})` (α·δ·eᵀx), small once learning has settled.
//!
//! A gap in the sequence numbers (ticks the caller never saw) makes every waiting return unknowable: they
//! are dropped and counted, and the chain restarts.

use std::collections::VecDeque;

/// The default truncation tolerance: the horizon is where the discount falls below it.
pub const DEFAULT_TOLERANCE: f64 = 0.01;
/// The longest horizon kept, in ticks (5 minutes at 50 Hz): bounds the tracker's backlog and its work per
/// tick whatever τ is.
pub const MAX_HORIZON: u32 = 15_000;
/// Matched pairs over which the running error averages (an exponential window; 10 s at 50 Hz). Until
/// that many pairs have been seen it is the plain mean of all of them.
pub const ERROR_WINDOW: f64 = 500.0;

/// Why a tracker cannot be made.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ReturnTrackerError {
    /// The continuation `1 − 1/τ` is not in `[0, 1)`.
    #[error("the continuation γ = {0} must be a finite number in [0, 1)")]
    Continuation(f64),
    /// The tolerance is not in `(0, 1)`.
    #[error("the truncation tolerance {0} must be in (0, 1)")]
    Tolerance(f64),
}

/// A value paired with the return it was predicting.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Realised {
    /// The tick whose value it was.
    pub seq: u64,
    /// The value predicted on that tick.
    pub value: f64,
    /// The return that followed (truncated at the horizon unless `complete`).
    pub ret: f64,
    /// Whether the prediction terminated within the horizon, so `ret` is exact.
    pub complete: bool,
}

impl Realised {
    /// `value − return`.
    pub fn error(&self) -> f64 {
        self.value - self.ret
    }
}

/// The running error of the values against their returns.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ErrorFigures {
    /// Pairs matched since the start.
    pub pairs: u64,
    /// Exponentially weighted root mean squared error (NaN before the first pair).
    pub rmse: f64,
    /// Exponentially weighted mean absolute error.
    pub mean_abs: f64,
    /// Exponentially weighted mean of `value − return` (positive: the prediction runs high).
    pub bias: f64,
}

#[derive(Debug, Clone, Copy)]
struct Waiting {
    seq: u64,
    value: f64,
    ret: f64,
    discount: f64,
    age: u32,
}

#[derive(Debug, Clone, Copy, Default)]
struct RunningError {
    pairs: u64,
    sq: f64,
    abs: f64,
    signed: f64,
}

impl RunningError {
    fn add(&mut self, error: f64) {
        self.pairs += 1;
        let beta = (1.0 / self.pairs as f64).max(1.0 / ERROR_WINDOW);
        self.sq += beta * (error * error - self.sq);
        self.abs += beta * (error.abs() - self.abs);
        self.signed += beta * (error - self.signed);
    }

    fn figures(&self) -> ErrorFigures {
        if self.pairs == 0 {
            return ErrorFigures {
                pairs: 0,
                rmse: f64::NAN,
                mean_abs: f64::NAN,
                bias: f64::NAN,
            };
        }
        ErrorFigures {
            pairs: self.pairs,
            rmse: self.sq.sqrt(),
            mean_abs: self.abs,
            bias: self.signed,
        }
    }
}

/// Tracks one prediction's realised returns, running error and TD error (see the module documentation).
#[derive(Debug, Clone)]
pub struct ReturnTracker {
    horizon: u32,
    tail_bound: f64,
    waiting: VecDeque<Waiting>,
    last: Option<(u64, f64)>,
    error: RunningError,
    dropped: u64,
}

impl ReturnTracker {
    /// A tracker for a prediction whose discount is at most `continuation` (`1 − 1/τ`), truncating returns
    /// where the discount falls below `tolerance`.
    pub fn new(continuation: f64, tolerance: f64) -> Result<Self, ReturnTrackerError> {
        if !(continuation.is_finite() && (0.0..1.0).contains(&continuation)) {
            return Err(ReturnTrackerError::Continuation(continuation));
        }
        if !(tolerance > 0.0 && tolerance < 1.0) {
            return Err(ReturnTrackerError::Tolerance(tolerance));
        }
        let horizon = horizon_for(continuation, tolerance);
        Ok(ReturnTracker {
            horizon,
            tail_bound: continuation.powi(horizon as i32),
            waiting: VecDeque::new(),
            last: None,
            error: RunningError::default(),
            dropped: 0,
        })
    }

    /// The horizon `H`, in ticks.
    pub fn horizon(&self) -> u32 {
        self.horizon
    }

    /// `γ^H`: how much of the rest of the return a truncated return may miss, as a fraction of the
    /// largest return that could follow.
    pub fn tail_bound(&self) -> f64 {
        self.tail_bound
    }

    /// Values whose returns became unknowable (a gap in the ticks), since the start.
    pub fn dropped(&self) -> u64 {
        self.dropped
    }

    /// The running error now.
    pub fn error(&self) -> ErrorFigures {
        self.error.figures()
    }

    /// One tick: its sequence number, the value predicted on it (before its update), and its cumulant
    /// `R_t` and discount `γ_t`. Pushes every pair whose return became known into `realised` (oldest
    /// first) and returns the TD error `δ_t` (`None` on the first tick of a chain or when a value is not
    /// finite).
    pub fn observe(
        &mut self,
        seq: u64,
        value: f64,
        cumulant: f64,
        gamma: f64,
        realised: &mut Vec<Realised>,
    ) -> Option<f64> {
        let contiguous = self
            .last
            .is_some_and(|(last, _)| last.checked_add(1) == Some(seq));
        if !contiguous {
            self.dropped += self.waiting.len() as u64;
            self.waiting.clear();
        }
        let td = self
            .last
            .filter(|_| contiguous)
            .map(|(_, prev)| cumulant + gamma * value - prev)
            .filter(|d| d.is_finite());
        self.last = Some((seq, value));
        if cumulant.is_finite() && gamma.is_finite() {
            for w in &mut self.waiting {
                w.ret += w.discount * cumulant;
                w.discount *= gamma;
                w.age += 1;
            }
        } else {
            // A return with an unknown term is unknowable.
            self.dropped += self.waiting.len() as u64;
            self.waiting.clear();
        }
        while let Some(w) = self.waiting.front().copied() {
            let complete = w.discount == 0.0;
            if !complete && w.age < self.horizon {
                break;
            }
            self.waiting.pop_front();
            let pair = Realised {
                seq: w.seq,
                value: w.value,
                ret: w.ret,
                complete,
            };
            self.error.add(pair.error());
            realised.push(pair);
        }
        if value.is_finite() {
            self.waiting.push_back(Waiting {
                seq,
                value,
                ret: 0.0,
                discount: 1.0,
                age: 0,
            });
        }
        td
    }
}

/// The first `k ≥ 1` with `continuation^k < tolerance`, at most [`MAX_HORIZON`].
pub fn horizon_for(continuation: f64, tolerance: f64) -> u32 {
    if continuation <= 0.0 {
        return 1;
    }
    let k = (tolerance.ln() / continuation.ln()).floor() + 1.0;
    let mut k = if k.is_finite() {
        k.clamp(1.0, f64::from(MAX_HORIZON)) as u32
    } else {
        MAX_HORIZON
    };
    // Guard the floating-point edge: step to the exact first k.
    while k > 1 && continuation.powi(k as i32 - 1) < tolerance {
        k -= 1;
    }
    while k < MAX_HORIZON && continuation.powi(k as i32) >= tolerance {
        k += 1;
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Feeds the stimulus indicator `stimuli` (the paper's question: R = I{E}, γ = (1 − I{E})·c) with
    /// `values`, returning the pairs and the TD errors.
    fn feed(
        t: &mut ReturnTracker,
        c: f64,
        values: &[f64],
        stimuli: &[bool],
    ) -> (Vec<Realised>, Vec<Option<f64>>) {
        let mut out = Vec::new();
        let mut tds = Vec::new();
        for (i, (&v, &e)) in values.iter().zip(stimuli).enumerate() {
            let (r, g) = if e { (1.0, 0.0) } else { (0.0, c) };
            tds.push(t.observe(i as u64, v, r, g, &mut out));
        }
        (out, tds)
    }

    #[test]
    fn the_horizon_is_where_the_discount_falls_below_the_tolerance() {
        // 0.5^6 = 0.0156, 0.5^7 = 0.0078.
        assert_eq!(horizon_for(0.5, 0.01), 7);
        // τ = 25: 0.96^112 = 0.01034, 0.96^113 = 0.00992.
        assert_eq!(horizon_for(0.96, 0.01), 113);
        assert_eq!(horizon_for(0.0, 0.01), 1);
        assert_eq!(horizon_for(1.0 - 1e-9, 0.01), MAX_HORIZON);
        let t = ReturnTracker::new(0.96, 0.01).unwrap();
        assert!(t.tail_bound() < 0.01 && t.tail_bound() > 0.0099);
        assert!(ReturnTracker::new(1.0, 0.01).is_err());
        assert!(ReturnTracker::new(f64::NAN, 0.01).is_err());
        assert!(ReturnTracker::new(0.5, 0.0).is_err());
        assert!(ReturnTracker::new(0.5, 1.0).is_err());
    }

    #[test]
    fn a_stimulus_completes_every_waiting_return_exactly() {
        // γ = 0.5; the stimulus on tick 3. G_0 = 0 + 0.5·0 + 0.25·1 = 0.25, G_1 = 0.5, G_2 = 1.
        let mut t = ReturnTracker::new(0.5, 0.01).unwrap();
        let values = [0.2, 0.4, 0.9, 0.1];
        let (out, tds) = feed(&mut t, 0.5, &values, &[false, false, false, true]);
        let got: Vec<(u64, f64, f64, bool)> = out
            .iter()
            .map(|p| (p.seq, p.value, p.ret, p.complete))
            .collect();
        assert_eq!(
            got,
            [
                (0, 0.2, 0.25, true),
                (1, 0.4, 0.5, true),
                (2, 0.9, 1.0, true)
            ]
        );
        // δ_1 = 0 + 0.5·0.4 − 0.2 = 0; δ_2 = 0.45 − 0.4 = 0.05; δ_3 = 1 + 0·0.1 − 0.9 = 0.1.
        assert_eq!(tds[0], None);
        assert!((tds[1].unwrap() - 0.0).abs() < 1e-12);
        assert!((tds[2].unwrap() - 0.05).abs() < 1e-12);
        assert!((tds[3].unwrap() - 0.1).abs() < 1e-12);
        // Errors −0.05, −0.1, −0.1: mean |e| = 0.25/3, RMSE = sqrt(0.0225/3), bias = −0.25/3.
        let e = t.error();
        assert_eq!(e.pairs, 3);
        assert!((e.mean_abs - 0.25 / 3.0).abs() < 1e-12, "{e:?}");
        assert!((e.rmse - (0.0225f64 / 3.0).sqrt()).abs() < 1e-12, "{e:?}");
        assert!((e.bias + 0.25 / 3.0).abs() < 1e-12, "{e:?}");
    }

    #[test]
    fn a_return_with_no_stimulus_is_truncated_at_the_horizon() {
        // γ = 0.5, H = 7: tick 0's return is known on tick 7: the stimulus on tick 6 makes it 0.5^5.
        let mut t = ReturnTracker::new(0.5, 0.01).unwrap();
        let mut stimuli = [false; 20];
        stimuli[6] = true;
        let (out, _) = feed(&mut t, 0.5, &[0.0; 20], &stimuli);
        assert_eq!(out[0].seq, 0);
        assert!((out[0].ret - 0.5f64.powi(5)).abs() < 1e-15);
        assert!(out[0].complete);
        // After the stimulus: tick 6's return waits 7 ticks (to tick 13) and, with no stimulus, is 0 and
        // truncated; tick 12's is the last one known by tick 19.
        let after: Vec<&Realised> = out.iter().filter(|p| p.seq >= 6).collect();
        assert_eq!(after.first().unwrap().seq, 6);
        assert_eq!(after.last().unwrap().seq, 12);
        assert!(after.iter().all(|p| p.ret == 0.0 && !p.complete));
        assert_eq!(out.len(), 13);
    }

    #[test]
    fn a_gap_drops_the_waiting_returns_and_restarts_the_chain() {
        let mut t = ReturnTracker::new(0.5, 0.01).unwrap();
        let mut out = Vec::new();
        for seq in 0..3 {
            t.observe(seq, 0.3, 0.0, 0.5, &mut out);
        }
        // Ticks 3 and 4 never seen.
        let td = t.observe(5, 0.3, 1.0, 0.0, &mut out);
        assert_eq!(td, None);
        assert!(out.is_empty(), "{out:?}");
        assert_eq!(t.dropped(), 3);
        assert!(t.error().rmse.is_nan());
        // Tick 6 ends tick 5's return: G_5 = 1.
        assert!(t.observe(6, 0.3, 1.0, 0.0, &mut out).is_some());
        assert_eq!(out.len(), 1);
        assert_eq!((out[0].seq, out[0].ret), (5, 1.0));
    }

    #[test]
    fn a_value_that_is_not_finite_is_not_paired_and_gives_no_td_error() {
        let mut t = ReturnTracker::new(0.5, 0.01).unwrap();
        let mut out = Vec::new();
        t.observe(0, f64::NAN, 0.0, 0.5, &mut out);
        assert_eq!(t.observe(1, 0.5, 1.0, 0.0, &mut out), None);
        assert!(out.is_empty());
        t.observe(2, 0.2, 1.0, 0.0, &mut out);
        assert_eq!(out.len(), 1);
        assert_eq!(out[0].seq, 1);
    }

    #[test]
    fn the_running_error_forgets_over_its_window() {
        let mut e = RunningError::default();
        for _ in 0..5_000 {
            e.add(1.0);
        }
        for _ in 0..5_000 {
            e.add(0.0);
        }
        // After 10 windows of zero error, (1 − 1/500)^5000 ≈ 4.5e-5 of the old error is left.
        let f = e.figures();
        assert!(f.mean_abs < 1e-4 && f.mean_abs > 1e-5, "{f:?}");
        assert_eq!(f.pairs, 10_000);
    }

    #[test]
    fn a_long_run_matches_the_returns_computed_backwards() {
        // Backwards: G_t = R_{t+1} + γ_{t+1} G_{t+1}, over a run of stimuli every 37 ticks, γ = 0.96.
        let c = 0.96;
        let n = 400;
        let stimuli: Vec<bool> = (0..n).map(|i| i % 37 == 36).collect();
        let mut g = vec![0.0; n];
        for i in (0..n - 1).rev() {
            let (r, gamma) = if stimuli[i + 1] { (1.0, 0.0) } else { (0.0, c) };
            g[i] = r + gamma * g[i + 1];
        }
        let mut t = ReturnTracker::new(c, 0.01).unwrap();
        let (out, _) = feed(&mut t, c, &vec![0.5; n], &stimuli);
        // The stimuli come well within the horizon (113): every return is complete and exact.
        assert!(out.len() > 350);
        for p in &out {
            assert!(p.complete);
            assert!((p.ret - g[p.seq as usize]).abs() < 1e-12, "{p:?}");
        }
    }
}

//! [`Transitions`]: the online bookkeeping of a learner that acts first and learns after ("predict with
//! this tick's features, then learn the step from the previous tick into this one"), shared by the
//! chains of the off-policy learner ([`super::gtd::GtdChain`]) and the named learners
//! ([`super::named::NamedChain`]).
//!
//! It keeps the previous tick's active features and discount, whether a prediction is waiting to be
//! learned from, and whether the learner has stopped because a step would have made a number non-finite.

use super::UpdateRefused;

/// The link from one tick to the next.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct Transitions {
    x_prev: Vec<usize>,
    x_now: Vec<usize>,
    gamma_prev: f64,
    has_prev: bool,
    fresh: bool,
    diverged: bool,
}

impl Transitions {
    /// No previous tick.
    pub fn new() -> Self {
        Self::default()
    }

    /// Keeps this tick's features for the next [`Transitions::learn`].
    pub fn observe(&mut self, active: &[usize]) {
        self.x_now.clear();
        self.x_now.extend_from_slice(active);
        self.fresh = true;
    }

    /// Runs `step(x_prev, γ_prev, x_now)` for the transition from the previous tick into this one, then
    /// makes this tick the previous one. `None` when there was no previous tick, no
    /// [`Transitions::observe`] since the last `learn`, or the learner has diverged (now or before); a
    /// step refused because it would diverge stops the learner, one refused for a non-finite input only
    /// skips the tick.
    pub fn learn(
        &mut self,
        gamma: f64,
        step: impl FnOnce(&[usize], f64, &[usize]) -> Result<f64, UpdateRefused>,
    ) -> Option<f64> {
        if !self.fresh {
            return None;
        }
        self.fresh = false;
        let delta = if self.has_prev && !self.diverged {
            match step(&self.x_prev, self.gamma_prev, &self.x_now) {
                Ok(d) => Some(d),
                Err(UpdateRefused::WouldDiverge { .. }) => {
                    self.diverged = true;
                    None
                }
                Err(UpdateRefused::NonFiniteInput { .. }) => None,
            }
        } else {
            None
        };
        std::mem::swap(&mut self.x_prev, &mut self.x_now);
        self.gamma_prev = gamma;
        self.has_prev = true;
        delta
    }

    /// Whether the learner stopped because a step would have made a number non-finite.
    pub fn diverged(&self) -> bool {
        self.diverged
    }

    /// Forgets an observation that has not been learned from.
    pub fn clear_pending(&mut self) {
        self.fresh = false;
    }

    /// Forgets the previous tick (the learner clears its traces).
    pub fn break_chain(&mut self) {
        self.fresh = false;
        self.has_prev = false;
    }

    /// No previous tick, and learning again after a divergence (the learner resets its state).
    pub fn reset(&mut self) {
        self.fresh = false;
        self.has_prev = false;
        self.diverged = false;
    }

    /// The previous tick's features and discount, if there is one.
    pub fn previous(&self) -> Option<(&[usize], f64)> {
        self.has_prev.then_some((&self.x_prev[..], self.gamma_prev))
    }

    /// Replaces the previous tick (restoring a checkpoint); learns again after a divergence.
    pub fn restore(&mut self, previous: Option<(&[usize], f64)>) {
        match previous {
            Some((x, gamma)) => {
                self.x_prev.clear();
                self.x_prev.extend_from_slice(x);
                self.gamma_prev = gamma;
                self.has_prev = true;
            }
            None => self.has_prev = false,
        }
        self.fresh = false;
        self.diverged = false;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_step_needs_a_previous_tick_and_a_fresh_observation() {
        let mut t = Transitions::new();
        t.observe(&[1, 2]);
        assert_eq!(t.learn(0.9, |_, _, _| Ok(1.0)), None, "no previous tick");
        assert_eq!(t.previous(), Some((&[1, 2][..], 0.9)));
        assert_eq!(t.learn(0.8, |_, _, _| Ok(1.0)), None, "nothing observed");
        t.observe(&[3]);
        let seen = t.learn(0.7, |x_prev, gamma_prev, x_now| {
            assert_eq!((x_prev, gamma_prev, x_now), (&[1, 2][..], 0.9, &[3][..]));
            Ok(0.5)
        });
        assert_eq!(seen, Some(0.5));
        t.observe(&[4]);
        t.clear_pending();
        assert_eq!(
            t.learn(0.7, |_, _, _| Ok(1.0)),
            None,
            "a cleared observation"
        );
    }

    #[test]
    fn a_diverging_step_stops_learning_until_reset_and_a_bad_input_skips_one_tick() {
        let mut t = Transitions::new();
        t.restore(Some((&[0], 1.0)));
        t.observe(&[1]);
        let bad = UpdateRefused::NonFiniteInput { delta: f64::NAN };
        assert_eq!(t.learn(1.0, |_, _, _| Err(bad)), None);
        assert!(!t.diverged());
        t.observe(&[1]);
        let diverge = UpdateRefused::WouldDiverge { delta: 1e308 };
        assert_eq!(t.learn(1.0, |_, _, _| Err(diverge)), None);
        assert!(t.diverged());
        t.observe(&[1]);
        assert_eq!(t.learn(1.0, |_, _, _| Ok(2.0)), None, "stopped");
        t.reset();
        t.observe(&[1]);
        t.learn(1.0, |_, _, _| Ok(2.0));
        t.observe(&[2]);
        assert_eq!(t.learn(1.0, |_, _, _| Ok(2.0)), Some(2.0));
    }
}

//! [`GtdChain`]: a [`Gtd`] learner with the online bookkeeping of [`crate::learn::set`] ("act first,
//! then learn"): [`GtdChain::predict`] with this tick's features, then [`GtdChain::learn`] with this
//! tick's cumulant and discount and the importance sampling ratio ρ of the *previous* tick's action,
//! which is what took the agent from the previous tick to this one.

use super::Gtd;
use crate::learn::transitions::Transitions;

/// A GTD(λ) learner and the link from one tick to the next.
#[derive(Debug, Clone, PartialEq)]
pub struct GtdChain {
    gtd: Gtd,
    chain: Transitions,
}

impl GtdChain {
    /// A chain without a previous tick.
    pub fn new(gtd: Gtd) -> Self {
        GtdChain {
            gtd,
            chain: Transitions::new(),
        }
    }

    /// The learner.
    pub fn gtd(&self) -> &Gtd {
        &self.gtd
    }

    /// The learner, to change its parameters.
    pub fn gtd_mut(&mut self) -> &mut Gtd {
        &mut self.gtd
    }

    /// `θᵀx_t` for this tick's features, kept for the next [`GtdChain::learn`].
    pub fn predict(&mut self, active: &[usize]) -> f64 {
        self.chain.observe(active);
        self.gtd.predict(active)
    }

    /// The GTD(λ) step for the transition from the previous tick into this one, whose action had the
    /// ratio `rho_prev`; then this tick becomes the previous one. `None` when there was no previous tick,
    /// no `predict` since the last `learn`, or the learner has diverged (now or before); a step that
    /// would make a number non-finite stops the learner (it keeps its last finite state).
    pub fn learn(&mut self, gamma: f64, reward: f64, rho_prev: f64) -> Option<f64> {
        let gtd = &mut self.gtd;
        self.chain.learn(gamma, |x_prev, gamma_prev, x_now| {
            gtd.try_update(x_prev, gamma_prev, rho_prev, reward, gamma, x_now)
        })
    }

    /// Whether the learner stopped because a step would have made a number non-finite.
    pub fn diverged(&self) -> bool {
        self.chain.diverged()
    }

    /// Forgets a `predict` that has not been learned from.
    pub fn clear_pending(&mut self) {
        self.chain.clear_pending();
    }

    /// Forgets the previous tick and clears the trace.
    pub fn break_chain(&mut self) {
        self.chain.break_chain();
        self.gtd.clear_traces();
    }

    /// Back to the initial weights, no previous tick; learns again after a divergence.
    pub fn reset(&mut self) {
        self.gtd.reset();
        self.chain.reset();
    }

    /// The previous tick's features and discount, if there is one.
    pub fn previous(&self) -> Option<(&[usize], f64)> {
        self.chain.previous()
    }

    /// Replaces the learned state and the previous tick (restoring a checkpoint; the caller checked the
    /// indices); learns again after a divergence. On error nothing changes.
    pub fn restore(
        &mut self,
        name: &str,
        theta: &[f64],
        secondary: &[f64],
        traces: &[f64],
        previous: Option<(&[usize], f64)>,
    ) -> Result<(), crate::learn::LearnError> {
        self.gtd.set_state(name, theta, secondary, traces)?;
        self.chain.restore(previous);
        Ok(())
    }
}

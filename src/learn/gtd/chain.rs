//! [`GtdChain`]: a [`Gtd`] learner with the online bookkeeping of [`crate::learn::set`] ("act first,
//! then learn"): [`GtdChain::predict`] with this tick's features, then [`GtdChain::learn`] with this
//! tick's cumulant and discount and the importance sampling ratio ρ of the *previous* tick's action,
//! which is what took the agent from the previous tick to this one.

use super::Gtd;
use crate::learn::UpdateRefused;

/// A GTD(λ) learner and the link from one tick to the next.
#[derive(Debug, Clone, PartialEq)]
pub struct GtdChain {
    gtd: Gtd,
    x_prev: Vec<usize>,
    x_now: Vec<usize>,
    gamma_prev: f64,
    has_prev: bool,
    fresh: bool,
    diverged: bool,
}

impl GtdChain {
    /// A chain without a previous tick.
    pub fn new(gtd: Gtd) -> Self {
        GtdChain {
            gtd,
            x_prev: Vec::new(),
            x_now: Vec::new(),
            gamma_prev: 0.0,
            has_prev: false,
            fresh: false,
            diverged: false,
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
        self.x_now.clear();
        self.x_now.extend_from_slice(active);
        self.fresh = true;
        self.gtd.predict(active)
    }

    /// The GTD(λ) step for the transition from the previous tick into this one, whose action had the
    /// ratio `rho_prev`; then this tick becomes the previous one. `None` when there was no previous tick,
    /// no `predict` since the last `learn`, or the learner has diverged (now or before); a step that
    /// would make a number non-finite stops the learner (it keeps its last finite state).
    pub fn learn(&mut self, gamma: f64, reward: f64, rho_prev: f64) -> Option<f64> {
        if !self.fresh {
            return None;
        }
        self.fresh = false;
        let delta = if self.has_prev && !self.diverged {
            match self.gtd.try_update(
                &self.x_prev,
                self.gamma_prev,
                rho_prev,
                reward,
                gamma,
                &self.x_now,
            ) {
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

    /// Forgets a `predict` that has not been learned from.
    pub fn clear_pending(&mut self) {
        self.fresh = false;
    }

    /// Forgets the previous tick and clears the trace.
    pub fn break_chain(&mut self) {
        self.fresh = false;
        self.has_prev = false;
        self.gtd.clear_traces();
    }

    /// Back to the initial weights, no previous tick; learns again after a divergence.
    pub fn reset(&mut self) {
        self.gtd.reset();
        self.fresh = false;
        self.has_prev = false;
        self.diverged = false;
    }

    /// The previous tick's features and discount, if there is one.
    pub fn previous(&self) -> Option<(&[usize], f64)> {
        self.has_prev.then_some((&self.x_prev[..], self.gamma_prev))
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
        Ok(())
    }
}

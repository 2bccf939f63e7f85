//! The named learners beyond the paper's, selectable per prediction with `learner = "…"` (config/README.md):
//!
//! | `learner` | what | file |
//! |---|---|---|
//! | `"paper"` (default; also `"td"`) | the paper's TD(λ), σ′ in the trace | [`super::td`] (reference), run by [`super::set::TdLearner`] |
//! | `"xent"` | the cross-entropy (log-loss) gradient of the logistic output: the paper's update without σ′ in the trace | [`xent`] |
//! | `"linear"` | the paper's TD(λ) with σ = identity | [`linear`] |
//! | `"true_online"` | true online TD(λ) with dutch traces (van Seijen & Sutton 2014), linear | [`true_online`] |
//! | `"autostep"` | Autostep step sizes per weight (Mahmood et al. 2012) on the `xent` update | [`autostep`] |
//! | `"gtd"` | off-policy GTD(λ) (Maei 2011) | [`super::gtd`] |
//!
//! [`NamedChain`] gives `xent`, `true_online` and `autostep` the online bookkeeping of
//! [`super::set`] ("act first, then learn"), as [`super::gtd::GtdChain`] does for GTD(λ); `paper` and
//! `linear` run on the set's own engine, unchanged.

pub mod autostep;
pub mod linear;
pub mod true_online;
pub mod xent;

pub use autostep::AutostepTd;
pub use true_online::TrueOnlineTd;
pub use xent::XentTd;

use super::bounds::{check_alpha_positive, check_lambda};
use super::transitions::Transitions;
use super::{LearnError, TdParams, UpdateRefused};

/// `wᵀx` for the binary x whose active indices are `active` (an index beyond the weights is ignored).
#[inline]
pub(crate) fn dot(weights: &[f64], active: &[usize]) -> f64 {
    active.iter().filter_map(|&i| weights.get(i)).sum()
}

/// One of the named learners that keep their own state.
#[derive(Debug, Clone, PartialEq)]
pub enum Named {
    /// [`xent`].
    Xent(XentTd),
    /// [`true_online`].
    TrueOnline(TrueOnlineTd),
    /// [`autostep`].
    Autostep(AutostepTd),
}

impl Named {
    fn params_mut(&mut self) -> &mut TdParams {
        match self {
            Named::Xent(l) => &mut l.params,
            Named::TrueOnline(l) => &mut l.params,
            Named::Autostep(l) => &mut l.params,
        }
    }

    /// The learning parameters.
    pub fn params(&self) -> TdParams {
        match self {
            Named::Xent(l) => l.params,
            Named::TrueOnline(l) => l.params,
            Named::Autostep(l) => l.params,
        }
    }

    /// The prediction for features `active`.
    pub fn predict(&self, active: &[usize]) -> f64 {
        match self {
            Named::Xent(l) => l.predict(active),
            Named::TrueOnline(l) => l.predict(active),
            Named::Autostep(l) => l.predict(active),
        }
    }

    fn try_update(
        &mut self,
        x_t: &[usize],
        gamma_t: f64,
        reward_next: f64,
        gamma_next: f64,
        x_next: &[usize],
    ) -> Result<f64, UpdateRefused> {
        match self {
            Named::Xent(l) => l.try_update(x_t, gamma_t, reward_next, gamma_next, x_next),
            Named::TrueOnline(l) => l.try_update(x_t, gamma_t, reward_next, gamma_next, x_next),
            Named::Autostep(l) => l.try_update(x_t, gamma_t, reward_next, gamma_next, x_next),
        }
    }

    /// The weights.
    pub fn weights(&self) -> &[f64] {
        match self {
            Named::Xent(l) => &l.weights,
            Named::TrueOnline(l) => &l.weights,
            Named::Autostep(l) => &l.weights,
        }
    }

    /// The eligibility trace.
    pub fn traces(&self) -> &[f64] {
        match self {
            Named::Xent(l) => &l.traces,
            Named::TrueOnline(l) => &l.traces,
            Named::Autostep(l) => &l.traces,
        }
    }

    /// The state beyond weights and trace, for a checkpoint: true online `[V_old]`; Autostep the step
    /// sizes, h and v, one after the other; nothing for `xent`.
    pub fn aux(&self) -> Option<Vec<f64>> {
        match self {
            Named::Xent(_) => None,
            Named::TrueOnline(l) => Some(vec![l.v_old]),
            Named::Autostep(l) => Some([&l.alphas[..], &l.h, &l.v].concat()),
        }
    }

    fn clear_traces(&mut self) {
        match self {
            Named::Xent(l) => l.traces.fill(0.0),
            Named::TrueOnline(l) => {
                l.traces.fill(0.0);
                l.v_old = 0.0;
            }
            Named::Autostep(l) => l.traces.fill(0.0),
        }
    }

    fn reset(&mut self) {
        let p = self.params();
        let n = self.weights().len();
        *self = match self {
            Named::Xent(_) => Named::Xent(XentTd::new(n, p)),
            Named::TrueOnline(_) => Named::TrueOnline(TrueOnlineTd::new(n, p)),
            Named::Autostep(_) => Named::Autostep(AutostepTd::new(n, p)),
        };
    }

    /// Replaces the state (checked: lengths and finiteness); on error nothing changes.
    fn set_state(
        &mut self,
        name: &str,
        weights: &[f64],
        traces: &[f64],
        aux: Option<&[f64]>,
    ) -> Result<(), LearnError> {
        let n = self.weights().len();
        let bad = |what: &str| LearnError::BadGroupState {
            name: name.to_string(),
            what: what.to_string(),
        };
        if weights.len() != n || traces.len() != n {
            return Err(LearnError::FeatureCountMismatch {
                name: name.to_string(),
                expected: n,
                got: if weights.len() != n {
                    weights.len()
                } else {
                    traces.len()
                },
            });
        }
        let all_finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if !all_finite(weights) || !all_finite(traces) || !aux.is_none_or(all_finite) {
            return Err(LearnError::NonFiniteSnapshot(name.to_string()));
        }
        match (&mut *self, aux) {
            (Named::Xent(_), None) => {}
            (Named::TrueOnline(l), Some([v_old])) => l.v_old = *v_old,
            (Named::Autostep(l), Some(a)) if a.len() == 3 * n => {
                if a[..n].iter().any(|&x| x <= 0.0) {
                    return Err(bad(
                        "has a step size that is not above 0 (learner = \"autostep\")",
                    ));
                }
                l.alphas.copy_from_slice(&a[..n]);
                l.h.copy_from_slice(&a[n..2 * n]);
                l.v.copy_from_slice(&a[2 * n..]);
            }
            _ => {
                return Err(bad(
                    "has no learner state (`aux`) of the configured learner's shape",
                ));
            }
        }
        match self {
            Named::Xent(l) => (
                l.weights.copy_from_slice(weights),
                l.traces.copy_from_slice(traces),
            ),
            Named::TrueOnline(l) => (
                l.weights.copy_from_slice(weights),
                l.traces.copy_from_slice(traces),
            ),
            Named::Autostep(l) => (
                l.weights.copy_from_slice(weights),
                l.traces.copy_from_slice(traces),
            ),
        };
        Ok(())
    }
}

/// A [`Named`] learner and the link from one tick to the next (as [`super::gtd::GtdChain`]).
#[derive(Debug, Clone, PartialEq)]
pub struct NamedChain {
    learner: Named,
    chain: Transitions,
}

impl NamedChain {
    /// A chain without a previous tick.
    pub fn new(learner: Named) -> Self {
        NamedChain {
            learner,
            chain: Transitions::new(),
        }
    }

    /// The learner.
    pub fn learner(&self) -> &Named {
        &self.learner
    }

    /// The prediction for this tick's features, kept for the next [`NamedChain::learn`].
    pub fn predict(&mut self, active: &[usize]) -> f64 {
        self.chain.observe(active);
        self.learner.predict(active)
    }

    /// The step for the transition from the previous tick into this one; then this tick becomes the
    /// previous one. `None` when there was no previous tick or `predict`, or the learner has diverged.
    pub fn learn(&mut self, gamma: f64, reward: f64) -> Option<f64> {
        let learner = &mut self.learner;
        self.chain.learn(gamma, |x_prev, gamma_prev, x_now| {
            learner.try_update(x_prev, gamma_prev, reward, gamma, x_now)
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
        self.learner.clear_traces();
    }

    /// Back to the initial state, no previous tick; learns again after a divergence.
    pub fn reset(&mut self) {
        self.learner.reset();
        self.chain.reset();
    }

    /// Changes α (Autostep: the step sizes restart from it).
    pub fn set_alpha(&mut self, alpha: f64) -> Result<(), LearnError> {
        check_alpha_positive("named", alpha)?;
        self.learner.params_mut().alpha = alpha;
        if let Named::Autostep(l) = &mut self.learner {
            l.alphas.fill(alpha);
        }
        Ok(())
    }

    /// Changes λ.
    pub fn set_lambda(&mut self, lambda: f64) -> Result<(), LearnError> {
        check_lambda("named", lambda)?;
        self.learner.params_mut().lambda = lambda;
        Ok(())
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
        weights: &[f64],
        traces: &[f64],
        aux: Option<&[f64]>,
        previous: Option<(&[usize], f64)>,
    ) -> Result<(), LearnError> {
        self.learner.set_state(name, weights, traces, aux)?;
        self.chain.restore(previous);
        Ok(())
    }
}

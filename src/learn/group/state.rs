//! [`GroupState`]: the exact state of a [`TraceGroup`], deferred parts included, as plain data.
//!
//! A group's weights and trace can be written out densely ([`TraceGroup::weights`],
//! [`TraceGroup::traces`]), but continuing from the dense form rounds differently from continuing
//! from the deferred one, so a run restored from it drifts from the original in the last bits. A
//! replay that must reproduce every tick bit for bit restores this state instead: the deferred rows,
//! the epochs, and the previous tick as the group will use it.

use serde::{Deserialize, Serialize};

use super::epochs::{ClosedEpoch, Epochs, RING_EPOCHS};
use super::rows::DeferredRows;
use super::{Chain, DutchState, TraceGroup, Weight};
use crate::learn::LearnError;

/// A closed epoch of a [`GroupState`].
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ClosedEpochState {
    pub id: u32,
    pub carry: f64,
    pub a_end: Vec<f64>,
    pub members: Vec<usize>,
}

/// The exact state of a [`TraceGroup`] (see the module documentation). Weights are stored as `f64`,
/// which holds an `f32` exactly.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct GroupState {
    /// `"f32"` or `"f64"`: the weights' type.
    pub precision: String,
    /// Deferred weights, feature-major.
    pub w0: Vec<f64>,
    pub coef: Vec<f64>,
    pub row_epoch: Vec<u32>,
    pub epoch: u32,
    pub p: f64,
    pub a: Vec<f64>,
    pub a_w: Vec<f64>,
    pub members: Vec<usize>,
    pub ring: Vec<ClosedEpochState>,
    pub lambda: f64,
    pub alphas: Vec<f64>,
    pub diverged: Vec<bool>,
    /// The previous tick's features, `None` at the start of a chain.
    pub x_prev: Option<Vec<usize>>,
    pub gamma_prev: f64,
    pub y_prev: Vec<f64>,
    pub step_prev: Vec<f64>,
    pub z: f64,
    /// A true-online group's state per prediction (`learner = "true_online"`, `super::dutch`).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub dutch: Option<DutchState>,
    /// An Autostep group's (`learner = "autostep"`, [`crate::learn::horde`]'s `AutostepGroup`): `coef`
    /// is its trace (`p` = 1, no epochs) and its values are four blocks of `features × predictions`, each
    /// prediction's features contiguous: the weights, the step sizes, h and v.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub autostep: bool,
}

impl GroupState {
    /// How many values (weights, and an Autostep group's per-weight state) the state's weights hold
    /// (`w0`'s length, or that of the weights beside a snapshot's state).
    pub fn value_count(&self) -> usize {
        let weights = self.coef.len().saturating_mul(self.a.len());
        if self.autostep {
            weights.saturating_mul(4)
        } else {
            weights
        }
    }
}

fn to_f64s<W: Weight>(v: &[W]) -> Vec<f64> {
    v.iter().map(|w| w.to_f64()).collect()
}

fn to_ws<W: Weight>(v: &[f64]) -> Vec<W> {
    v.iter().map(|&w| W::from_f64(w)).collect()
}

impl<W: Weight> TraceGroup<W> {
    /// The exact state, between two ticks.
    pub fn state(&self) -> GroupState {
        let mut s = self.state_without_weights();
        s.w0 = to_f64s(&self.rows.w0);
        s
    }

    /// Starts a snapshot taken a few rows at a time (`super::copy`): the state as it is now, whose
    /// weights [`TraceGroup::advance_snapshot`] copies between ticks while the group keeps learning.
    /// False when one is in progress.
    pub fn begin_snapshot(&mut self) -> bool {
        self.begin_snapshot_into(None)
    }

    /// [`TraceGroup::begin_snapshot`] into `buffer` (the weights of an earlier snapshot, or
    /// [`super::snapshot_buffer`]) when it has the size: no memory is allocated or mapped while copying.
    pub fn begin_snapshot_into(&mut self, buffer: Option<Vec<W>>) -> bool {
        if !self.rows.begin_copy(buffer) {
            return false;
        }
        self.pending = Some(Box::new(self.state_without_weights()));
        true
    }

    /// Copies up to `rows` more rows of the snapshot in progress; returns whether it is complete.
    pub fn advance_snapshot(&mut self, rows: usize) -> bool {
        self.rows.copy_some(rows)
    }

    /// Rows the snapshot in progress has still to copy.
    pub fn snapshot_rows_left(&self) -> usize {
        self.rows.copy_left()
    }

    /// The completed snapshot: the state without its weights (`w0` empty) and the weights as they were.
    pub fn take_snapshot(&mut self) -> Option<(GroupState, Vec<W>)> {
        let weights = self.rows.take_copy()?;
        let state = self.pending.take()?;
        Some((*state, weights))
    }

    /// Restores a snapshot of [`TraceGroup::take_snapshot`]'s form.
    pub fn restore_snapshot(
        &mut self,
        name: &str,
        state: &GroupState,
        weights: &[W],
    ) -> Result<(), LearnError> {
        let mut full = state.clone();
        full.w0 = to_f64s(weights);
        self.restore_state(name, &full)
    }

    fn state_without_weights(&self) -> GroupState {
        let r = &self.rows;
        let e = &r.epochs;
        GroupState {
            precision: W::NAME.into(),
            w0: Vec::new(),
            coef: r.coef.clone(),
            row_epoch: r.row_epoch.clone(),
            epoch: e.id,
            p: e.p,
            a: e.a.clone(),
            a_w: to_f64s(&e.a_w),
            members: e.members.clone(),
            ring: e
                .ring
                .iter()
                .map(|c| ClosedEpochState {
                    id: c.id,
                    carry: c.carry,
                    a_end: to_f64s(&c.a_end),
                    members: c.members.clone(),
                })
                .collect(),
            lambda: self.lambda,
            alphas: self.columns.iter().map(|c| c.alpha).collect(),
            diverged: self.diverged.clone(),
            x_prev: self.chain.has_prev.then(|| self.chain.x_prev.clone()),
            gamma_prev: self.chain.gamma_prev,
            y_prev: self.chain.y_prev.clone(),
            step_prev: self.chain.step_prev.clone(),
            z: self.chain.z,
            dutch: self.dutch.clone(),
            autostep: false,
        }
    }

    /// Restores `state`, taken from a group of the same shape; everything is checked before anything
    /// changes. `name` labels the errors.
    pub fn restore_state(&mut self, name: &str, s: &GroupState) -> Result<(), LearnError> {
        let n = self.features();
        let cols = self.columns.len();
        let bad = |what: &str| LearnError::BadGroupState {
            name: name.to_string(),
            what: what.to_string(),
        };
        if s.precision != W::NAME {
            return Err(bad(&format!(
                "holds {} weights, this learner {}",
                s.precision,
                W::NAME
            )));
        }
        let sizes_ok = s.w0.len() == n * cols
            && s.coef.len() == n
            && s.row_epoch.len() == n
            && [&s.a, &s.a_w, &s.alphas, &s.y_prev, &s.step_prev]
                .iter()
                .all(|v| v.len() == cols)
            && s.diverged.len() == cols
            && s.ring.len() <= RING_EPOCHS
            && s.ring.iter().all(|c| c.a_end.len() == cols);
        if s.autostep {
            return Err(bad(
                "holds an Autostep group's state, this group learns another learner",
            ));
        }
        if !sizes_ok {
            return Err(bad("is sized for another group"));
        }
        let dutch = self.checked_dutch(name, s.dutch.as_ref(), &s.alphas)?;
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        let all_finite = [&s.w0, &s.coef, &s.a, &s.a_w, &s.y_prev, &s.step_prev]
            .iter()
            .all(|v| finite(v))
            && s.ring
                .iter()
                .all(|c| finite(&c.a_end) && c.carry.is_finite())
            && [s.p, s.z, s.gamma_prev, s.lambda]
                .iter()
                .all(|x| x.is_finite());
        if !all_finite {
            return Err(LearnError::NonFiniteSnapshot(name.to_string()));
        }
        let in_range = |v: &[usize]| v.iter().all(|&f| f < n);
        let consecutive = s
            .ring
            .iter()
            .enumerate()
            .all(|(k, c)| c.id == s.epoch.wrapping_sub((s.ring.len() - k) as u32));
        let consistent = in_range(&s.members)
            && s.ring.iter().all(|c| in_range(&c.members))
            && s.x_prev.as_deref().is_none_or(in_range)
            && consecutive
            && s.p > 0.0
            && s.p <= 1.0;
        if !consistent {
            return Err(bad(
                "is inconsistent (feature index, epoch numbers or trace product)",
            ));
        }
        for &a in &s.alphas {
            super::super::bounds::check_alpha_positive(name, a)?;
        }
        super::super::bounds::check_lambda(name, s.lambda)?;

        // A snapshot in progress is abandoned: its rows would be of the state replaced.
        self.pending = None;
        self.rows = DeferredRows {
            cols,
            w0: {
                let mut w0 = super::huge::weight_vec(s.w0.len());
                w0.extend(s.w0.iter().map(|&w| W::from_f64(w)));
                w0
            },
            coef: s.coef.clone(),
            row_epoch: s.row_epoch.clone(),
            epochs: Epochs {
                id: s.epoch,
                p: s.p,
                a: s.a.clone(),
                a_w: to_ws(&s.a_w),
                members: s.members.clone(),
                ring: s
                    .ring
                    .iter()
                    .map(|c| ClosedEpoch {
                        id: c.id,
                        carry: c.carry,
                        a_end: to_ws(&c.a_end),
                        a_end_max: c.a_end.iter().fold(0.0f64, |m, a| m.max(a.abs())),
                        members: c.members.clone(),
                    })
                    .collect(),
            },
            w0_bound: 0.0,
            coef_bound: 0.0,
            marks: vec![0; n],
            mark: 0,
            touched: vec![0; n],
            forward: vec![None; n],
            copy: None,
        };
        self.rows.rescan_bounds();
        self.lambda = s.lambda;
        for (c, &a) in self.columns.iter_mut().zip(&s.alphas) {
            c.alpha = a;
        }
        self.diverged.clone_from(&s.diverged);
        self.chain = Chain {
            x_prev: s.x_prev.clone().unwrap_or_default(),
            x_now: Vec::new(),
            y_prev: s.y_prev.clone(),
            y_now: vec![0.0; cols],
            step_prev: s.step_prev.clone(),
            z: s.z,
            coef_sum_now: 0.0,
            epoch_now: s.epoch,
            gamma_prev: s.gamma_prev,
            has_prev: s.x_prev.is_some(),
            fresh: false,
        };
        self.dutch = dutch;
        Ok(())
    }
}

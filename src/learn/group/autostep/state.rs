//! An [`AutostepGroup`]'s state as a [`GroupState`] (see [`GroupState::autostep`]): taken whole, for a
//! checkpoint, and restored, everything checked before anything changes.

use super::super::weight::Weight;
use super::super::{GroupState, LearnError};
use super::AutostepGroup;

impl<W: Weight> AutostepGroup<W> {
    /// The exact state, between two ticks (see [`GroupState::autostep`]).
    pub fn state(&self) -> GroupState {
        let mut s = self.state_without_values();
        s.w0 = self.values_now().iter().map(|w| w.to_f64()).collect();
        s
    }

    fn values_now(&self) -> Vec<W> {
        let mut out = Vec::with_capacity(self.value_count());
        for part in [&self.weights, &self.alphas, &self.h, &self.v] {
            out.extend_from_slice(part);
        }
        out
    }

    fn state_without_values(&self) -> GroupState {
        let cols = self.columns.len();
        GroupState {
            precision: W::NAME.into(),
            w0: Vec::new(),
            coef: self.trace.clone(),
            row_epoch: vec![0; self.features],
            epoch: 0,
            p: 1.0,
            a: vec![0.0; cols],
            a_w: vec![0.0; cols],
            members: Vec::new(),
            ring: Vec::new(),
            lambda: self.lambda,
            alphas: self.columns.iter().map(|c| c.alpha).collect(),
            diverged: self.diverged.clone(),
            x_prev: self.has_prev.then(|| self.x_prev.clone()),
            gamma_prev: self.gamma_prev,
            y_prev: self.y_prev.clone(),
            step_prev: vec![0.0; cols],
            z: 0.0,
            dutch: None,
            autostep: true,
        }
    }

    /// Takes a snapshot of the whole state at once, its values into `buffer` when it has the size (the
    /// values of an earlier snapshot, or [`crate::learn::group::snapshot_buffer`]). Unlike the paper's
    /// group it is not copied a few rows a tick: one copy of four times the weights on this tick. False
    /// when one is waiting to be taken.
    pub fn begin_snapshot_into(&mut self, buffer: Option<Vec<W>>) -> bool {
        if self.pending.is_some() {
            return false;
        }
        let mut values = match buffer {
            Some(b) if b.len() == self.value_count() => b,
            _ => vec![W::default(); self.value_count()],
        };
        let mut at = 0;
        for part in [&self.weights, &self.alphas, &self.h, &self.v] {
            values[at..at + part.len()].copy_from_slice(part);
            at += part.len();
        }
        self.pending = Some((self.state_without_values(), values));
        true
    }

    /// The snapshot taken by [`AutostepGroup::begin_snapshot_into`], if one is waiting.
    pub fn take_snapshot(&mut self) -> Option<(GroupState, Vec<W>)> {
        self.pending.take()
    }

    /// Restores a snapshot of [`AutostepGroup::take_snapshot`]'s form.
    pub fn restore_snapshot(
        &mut self,
        name: &str,
        state: &GroupState,
        values: &[W],
    ) -> Result<(), LearnError> {
        let mut full = state.clone();
        full.w0 = values.iter().map(|w| w.to_f64()).collect();
        self.restore_state(name, &full)
    }

    /// Restores `s`, taken from an Autostep group of the same shape; everything is checked before
    /// anything changes.
    pub fn restore_state(&mut self, name: &str, s: &GroupState) -> Result<(), LearnError> {
        let n = self.features;
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
        if !s.autostep || s.dutch.is_some() {
            return Err(bad(
                "is not an Autostep group's, this group learns learner = \"autostep\"",
            ));
        }
        let sizes_ok = s.w0.len() == 4 * n * cols
            && s.coef.len() == n
            && s.alphas.len() == cols
            && s.y_prev.len() == cols
            && s.diverged.len() == cols;
        if !sizes_ok {
            return Err(bad("is sized for another group"));
        }
        let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
        if !finite(&s.w0)
            || !finite(&s.coef)
            || !finite(&s.y_prev)
            || ![s.gamma_prev, s.lambda].iter().all(|x| x.is_finite())
        {
            return Err(LearnError::NonFiniteSnapshot(name.to_string()));
        }
        let block = n * cols;
        let (step_sizes, v) = (&s.w0[block..2 * block], &s.w0[3 * block..]);
        if step_sizes.iter().any(|&a| a < 0.0) || v.iter().any(|&x| x < 0.0) {
            return Err(bad("has a negative step size or normaliser v"));
        }
        if s.x_prev
            .as_deref()
            .is_some_and(|x| x.iter().any(|&f| f >= n))
        {
            return Err(bad("is inconsistent (feature index)"));
        }
        for &a in &s.alphas {
            crate::learn::bounds::check_alpha_positive(name, a)?;
        }
        crate::learn::bounds::check_lambda(name, s.lambda)?;

        self.pending = None;
        let to_w = |v: &[f64]| -> Vec<W> { v.iter().map(|&x| W::from_f64(x)).collect() };
        self.weights = to_w(&s.w0[..block]);
        self.alphas = to_w(step_sizes);
        self.h = to_w(&s.w0[2 * block..3 * block]);
        self.v = to_w(v);
        self.trace.clone_from(&s.coef);
        self.live = (0..n).filter(|&f| self.trace[f] != 0.0).collect();
        self.is_live = self.trace.iter().map(|&e| e != 0.0).collect();
        self.lambda = s.lambda;
        for (c, &a) in self.columns.iter_mut().zip(&s.alphas) {
            c.alpha = a;
        }
        self.diverged.clone_from(&s.diverged);
        self.in_prev.fill(false);
        self.x_prev = s.x_prev.clone().unwrap_or_default();
        for &f in &self.x_prev {
            self.in_prev[f] = true;
        }
        self.x_now.clear();
        self.has_prev = s.x_prev.is_some();
        self.gamma_prev = s.gamma_prev;
        self.y_prev.clone_from(&s.y_prev);
        self.fresh = false;
        Ok(())
    }
}

//! Building a [`Horde`]: families checked against their bounds and the Horde's size bounds, feature
//! constructions shared, predictions expanded and put into trace groups, and only then the weights
//! allocated.

use super::super::group::{AutostepGroup, Column, TraceGroup, Weight};
use super::super::inputs::{SignalNames, resolve};
use super::super::spec::LearnerKind;
use super::super::{LearnError, ParamBounds, Sigma};
use super::groups::SlotGroup;
use super::{
    Bank, FamilySpec, Horde, HordeShape, MAX_HORDE_PREDICTIONS, MAX_HORDE_WEIGHTS, PredictionInfo,
    Slot, Source, signals,
};

/// What puts predictions into one trace group: the same features, λ and discount (τ and its
/// terminating stimulus), the same kind of group (`learner`) and the same σ (a logistic prediction of
/// the paper's learner, whose trace holds its own σ′, is `own` group; Autostep's trace holds no σ′, so
/// its logistic predictions share one); for true online TD(λ) also the same α, which is in its dutch
/// trace.
#[derive(Debug, Clone, Copy, PartialEq)]
struct GroupKey {
    bank: usize,
    lambda: u64,
    tau: u64,
    terminate: Option<usize>,
    own: Option<usize>,
    kind: GroupKind,
    /// α's bits for a true-online group, else 0.
    alpha: u64,
    /// A group has one σ.
    logistic: bool,
}

/// Which group a family's learner runs in.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum GroupKind {
    /// The paper's deferred group: `paper`, `linear` (σ′ in the trace when logistic).
    Paper,
    /// The paper's group with the log-loss gradient's trace: `xent`.
    Xent,
    /// The deferred group with a dutch trace: `true_online`.
    Dutch,
    /// [`AutostepGroup`]: `autostep`.
    Autostep,
}

impl GroupKind {
    fn of(learner: LearnerKind, sigma: Sigma) -> Self {
        match learner {
            // With σ = identity the log-loss gradient is the paper's: the same group.
            LearnerKind::Xent if sigma == Sigma::Identity => GroupKind::Paper,
            LearnerKind::Xent => GroupKind::Xent,
            LearnerKind::TrueOnline => GroupKind::Dutch,
            LearnerKind::Autostep => GroupKind::Autostep,
            // `gtd` is refused by `FamilySpec::bounds` before any group is planned.
            LearnerKind::Td | LearnerKind::Linear | LearnerKind::Gtd => GroupKind::Paper,
        }
    }
}

/// A trace group's predictions, gathered before it is built.
#[derive(Debug, Default)]
struct GroupPlan {
    columns: Vec<Column>,
    sources: Vec<Source>,
    predictions: Vec<usize>,
}

/// A Horde checked and laid out, before its weights are allocated.
struct Blueprint {
    family_bounds: Vec<ParamBounds>,
    banks: Vec<Bank>,
    keys: Vec<GroupKey>,
    plans: Vec<GroupPlan>,
    predictions: Vec<PredictionInfo>,
}

impl Blueprint {
    fn shape(&self) -> HordeShape {
        HordeShape {
            predictions: self.predictions.len(),
            feature_sets: self.banks.len(),
            groups: self.keys.len(),
            weights: self
                .keys
                .iter()
                .zip(&self.plans)
                .map(|(k, p)| self.banks[k.bank].coder.num_features() * p.columns.len())
                .sum(),
            active_features: self.banks.iter().map(|b| b.coder.num_tilings()).sum(),
        }
    }
}

/// Checks `families` over `names` against every bound and lays the Horde out, allocating no weight.
pub fn check(families: &[FamilySpec], names: &SignalNames) -> Result<HordeShape, LearnError> {
    Ok(blueprint(families, names)?.shape())
}

impl<W: Weight> Horde<W> {
    /// Checks every family against its bounds and the Horde's size bounds, then builds it over the
    /// signals `names` (allocating only once everything is known to fit).
    pub fn new(families: Vec<FamilySpec>, names: &SignalNames) -> Result<Self, LearnError> {
        let Blueprint {
            family_bounds,
            banks,
            keys,
            plans,
            predictions,
        } = blueprint(&families, names)?;
        let mut place = vec![(0, 0); predictions.len()];
        let mut slots = Vec::with_capacity(plans.len());
        for (s, (key, plan)) in keys.into_iter().zip(plans).enumerate() {
            let first = &families[predictions[plan.predictions[0]].family];
            let features = banks[key.bank].coder.num_features();
            for (c, &i) in plan.predictions.iter().enumerate() {
                place[i] = (s, c);
            }
            let cols = plan.columns.len();
            let (lambda, sigma, columns) = (first.lambda, first.sigma, plan.columns);
            let group = match key.kind {
                GroupKind::Paper | GroupKind::Xent => SlotGroup::Trace(
                    TraceGroup::new(features, lambda, sigma, columns)?
                        .with_unit_gradient(key.kind == GroupKind::Xent),
                ),
                GroupKind::Dutch => SlotGroup::Trace(
                    TraceGroup::new(features, lambda, sigma, columns)?.with_dutch_traces()?,
                ),
                GroupKind::Autostep => {
                    SlotGroup::Autostep(AutostepGroup::new(features, lambda, sigma, columns)?)
                }
            };
            slots.push(Slot {
                bank: key.bank,
                continuation: 1.0 - 1.0 / f64::from_bits(key.tau),
                terminate: key.terminate,
                group,
                sources: plan.sources,
                predictions: plan.predictions,
                cumulants: vec![0.0; cols],
                deltas: vec![f64::NAN; cols],
                spare: None,
            });
        }
        Ok(Horde {
            families,
            family_bounds,
            banks,
            slots,
            predictions,
            place,
            stopped: 0,
            snapshot_stopped: None,
        })
    }
}

fn blueprint(families: &[FamilySpec], names: &SignalNames) -> Result<Blueprint, LearnError> {
    names.check_unique()?;
    let mut banks: Vec<Bank> = Vec::new();
    let mut predictions = Vec::new();
    let mut keys: Vec<GroupKey> = Vec::new();
    let mut plans: Vec<GroupPlan> = Vec::new();
    let mut weights = 0usize;
    // Autostep's step sizes, h and v (three per Autostep weight).
    let mut values = 0usize;
    let mut family_bounds = Vec::with_capacity(families.len());
    for (fi, f) in families.iter().enumerate() {
        if families[..fi].iter().any(|g| g.name == f.name) {
            return Err(LearnError::DuplicatePrediction(f.name.clone()));
        }
        let bounds = f.bounds(names.obs.len())?;
        family_bounds.push(bounds);
        let terminate = f
            .terminate_on
            .as_deref()
            .map(|s| names.resolve_stimulus(&f.name, s))
            .transpose()?;
        let bank = match banks.iter().position(|b| b.spec == f.features) {
            Some(b) => b,
            None => {
                let r = resolve(&f.name, &f.features, names)?;
                banks.push(Bank {
                    spec: f.features.clone(),
                    scratch: Vec::with_capacity(r.gather.len()),
                    active: Vec::with_capacity(r.coder.num_tilings()),
                    gather: r.gather,
                    coder: r.coder,
                    on: None,
                });
                banks.len() - 1
            }
        };
        let mut cumulants = Vec::new();
        // A set, not a scan: `feature/*` expands to every feature (hundreds of thousands in a large bank).
        let mut seen = std::collections::HashSet::new();
        for selector in &f.cumulants {
            for (canonical, source) in signals::expand(&f.name, selector, names, bounds.features)? {
                if !seen.insert(canonical.clone()) {
                    return Err(LearnError::DuplicateCumulant {
                        family: f.name.clone(),
                        cumulant: canonical,
                    });
                }
                cumulants.push((canonical, source));
            }
        }
        let count = predictions.len() + cumulants.len() * f.taus.len();
        if count > MAX_HORDE_PREDICTIONS {
            return Err(LearnError::TooManyPredictions {
                count,
                max: MAX_HORDE_PREDICTIONS,
            });
        }
        let family_weights = bounds
            .features
            .saturating_mul(cumulants.len() * f.taus.len());
        weights = weights.saturating_add(family_weights);
        if weights > MAX_HORDE_WEIGHTS {
            return Err(LearnError::TooManyFeaturesInAll {
                total: weights,
                max: MAX_HORDE_WEIGHTS,
            });
        }
        // Autostep holds a step size, h and v beside each weight: in the same bound.
        let kind = GroupKind::of(f.learner, f.sigma);
        if kind == GroupKind::Autostep {
            values = values.saturating_add(family_weights.saturating_mul(3));
        }
        if weights.saturating_add(values) > MAX_HORDE_WEIGHTS {
            return Err(LearnError::AutostepStateTooLarge {
                values: weights.saturating_add(values),
                max: MAX_HORDE_WEIGHTS,
            });
        }
        if cumulants
            .iter()
            .any(|(_, s)| matches!(s, Source::Feature(_)))
        {
            banks[bank].on = Some(vec![false; bounds.features]);
        }
        for (selector, source) in cumulants {
            for &tau in &f.taus {
                let index = predictions.len();
                let name = f.prediction_name(&selector, tau);
                let key = GroupKey {
                    bank,
                    lambda: f.lambda.to_bits(),
                    tau: tau.to_bits(),
                    terminate,
                    own: (f.sigma == Sigma::Logistic && kind != GroupKind::Autostep)
                        .then_some(index),
                    kind,
                    alpha: if kind == GroupKind::Dutch {
                        f.alpha.to_bits()
                    } else {
                        0
                    },
                    logistic: f.sigma == Sigma::Logistic,
                };
                let slot = match keys.iter().position(|k| *k == key) {
                    Some(s) => s,
                    None => {
                        keys.push(key);
                        plans.push(GroupPlan::default());
                        keys.len() - 1
                    }
                };
                let plan = &mut plans[slot];
                plan.columns.push(Column {
                    alpha: f.alpha,
                    initial_weight: f.initial_weight,
                });
                plan.sources.push(source);
                plan.predictions.push(index);
                predictions.push(PredictionInfo {
                    name,
                    family: fi,
                    source,
                    tau,
                });
            }
        }
    }
    Ok(Blueprint {
        family_bounds,
        banks,
        keys,
        plans,
        predictions,
    })
}

//! Building a [`Horde`]: families checked against their bounds and the Horde's size bounds, feature
//! constructions shared, predictions expanded and put into trace groups, and only then the weights
//! allocated.

use super::super::group::{Column, TraceGroup, Weight};
use super::super::inputs::{SignalNames, resolve};
use super::super::spec::LearnerKind;
use super::super::{LearnError, ParamBounds, Sigma};
use super::{
    Bank, FamilySpec, Horde, HordeShape, MAX_HORDE_PREDICTIONS, MAX_HORDE_WEIGHTS, PredictionInfo,
    Slot, Source, signals,
};

/// What puts predictions into one trace group: the same features, λ and discount (τ and its
/// terminating stimulus), and a linear output (a logistic prediction is `own` group).
#[derive(Debug, Clone, Copy, PartialEq)]
struct GroupKey {
    bank: usize,
    lambda: u64,
    tau: u64,
    terminate: Option<usize>,
    own: Option<usize>,
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
            slots.push(Slot {
                bank: key.bank,
                continuation: 1.0 - 1.0 / f64::from_bits(key.tau),
                terminate: key.terminate,
                group: TraceGroup::new(features, first.lambda, first.sigma, plan.columns)?
                    .with_unit_gradient(first.learner == LearnerKind::Xent),
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
        weights = weights.saturating_add(
            bounds
                .features
                .saturating_mul(cumulants.len() * f.taus.len()),
        );
        if weights > MAX_HORDE_WEIGHTS {
            return Err(LearnError::TooManyFeaturesInAll {
                total: weights,
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
                    own: (f.sigma == Sigma::Logistic).then_some(index),
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

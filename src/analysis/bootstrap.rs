//! A difference of two means with a percentile-bootstrap confidence interval (Efron & Tibshirani, *An
//! Introduction to the Bootstrap*, 1993, ch. 13): each sample is resampled with replacement on its own, the
//! difference of the resampled means is taken `resamples` times, and the interval is the 2.5th and 97.5th
//! percentiles of those differences. It makes no assumption about the shape of the latencies (which are
//! quantised to 20 ms ticks and skewed), and it is deterministic for a seed.
//!
//! [`mean_difference_clustered`] resamples in two stages (Davison & Hinkley, *Bootstrap Methods and their
//! Application*, 1997, §3.8): first the clusters (runs) with replacement, then the values within each drawn
//! cluster. Commands of one run share its robot (its own friction, charge, lags) and its operator, so they
//! are not independent; resampling runs lets the interval carry the run-to-run spread. With one run per
//! side it reduces to [`mean_difference`] and cannot see that spread.

use serde::{Deserialize, Serialize};

use crate::rng::Rng;

/// How many resamples the experiments draw.
pub const RESAMPLES: usize = 2000;

/// `mean(minuend) − mean(subtrahend)` and its 95 % percentile-bootstrap interval.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct MeanDifference {
    /// The difference of the sample means.
    pub difference: f64,
    /// Lower end of the 95 % interval.
    pub lo: f64,
    /// Upper end of the 95 % interval.
    pub hi: f64,
    /// Size of the minuend's sample.
    pub n_minuend: usize,
    /// Size of the subtrahend's sample.
    pub n_subtrahend: usize,
}

impl MeanDifference {
    /// Whether the whole interval lies above 0.
    pub fn above_zero(&self) -> bool {
        self.lo > 0.0
    }

    /// Whether the whole interval lies below 0.
    pub fn below_zero(&self) -> bool {
        self.hi < 0.0
    }
}

fn mean(xs: &[f64]) -> f64 {
    xs.iter().sum::<f64>() / xs.len() as f64
}

fn resampled_mean(xs: &[f64], rng: &mut Rng) -> f64 {
    let n = xs.len() as u64;
    let sum: f64 = (0..xs.len())
        .map(|_| xs.get(rng.below(n) as usize).copied().unwrap_or(0.0))
        .sum();
    sum / xs.len() as f64
}

/// The difference `mean(minuend) − mean(subtrahend)` with its 95 % bootstrap interval from `resamples`
/// resamples drawn with `seed`; `None` when either sample is empty or holds a non-finite value.
pub fn mean_difference(
    minuend: &[f64],
    subtrahend: &[f64],
    resamples: usize,
    seed: u64,
) -> Option<MeanDifference> {
    let finite = |xs: &[f64]| !xs.is_empty() && xs.iter().all(|x| x.is_finite());
    if !finite(minuend) || !finite(subtrahend) {
        return None;
    }
    let mut rng = Rng::new(seed);
    let mut diffs: Vec<f64> = (0..resamples.max(1))
        .map(|_| resampled_mean(minuend, &mut rng) - resampled_mean(subtrahend, &mut rng))
        .collect();
    diffs.sort_by(f64::total_cmp);
    let at = |q: f64| {
        let i = ((diffs.len() - 1) as f64 * q).round() as usize;
        diffs.get(i).copied().unwrap_or(f64::NAN)
    };
    Some(MeanDifference {
        difference: mean(minuend) - mean(subtrahend),
        lo: at(0.025),
        hi: at(0.975),
        n_minuend: minuend.len(),
        n_subtrahend: subtrahend.len(),
    })
}

/// Pools the clusters' values.
fn pooled(clusters: &[Vec<f64>]) -> Vec<f64> {
    clusters.iter().flatten().copied().collect()
}

/// The mean of one two-stage resample of `clusters` (empty clusters are skipped).
fn resampled_clustered_mean(clusters: &[&Vec<f64>], rng: &mut Rng) -> f64 {
    let n = clusters.len() as u64;
    let (mut sum, mut count) = (0.0, 0usize);
    for _ in 0..clusters.len() {
        if let Some(c) = clusters.get(rng.below(n) as usize) {
            let m = c.len() as u64;
            for _ in 0..c.len() {
                sum += c.get(rng.below(m) as usize).copied().unwrap_or(0.0);
            }
            count += c.len();
        }
    }
    if count == 0 {
        f64::NAN
    } else {
        sum / count as f64
    }
}

/// `mean(minuend) − mean(subtrahend)` over the pooled values of clusters, with a 95 % two-stage bootstrap
/// interval (clusters, then values within them); `None` when a side has no value or a non-finite one.
pub fn mean_difference_clustered(
    minuend: &[Vec<f64>],
    subtrahend: &[Vec<f64>],
    resamples: usize,
    seed: u64,
) -> Option<MeanDifference> {
    let (a, b) = (pooled(minuend), pooled(subtrahend));
    let finite = |xs: &[f64]| !xs.is_empty() && xs.iter().all(|x| x.is_finite());
    if !finite(&a) || !finite(&b) {
        return None;
    }
    let ca: Vec<&Vec<f64>> = minuend.iter().filter(|c| !c.is_empty()).collect();
    let cb: Vec<&Vec<f64>> = subtrahend.iter().filter(|c| !c.is_empty()).collect();
    let mut rng = Rng::new(seed);
    let mut diffs: Vec<f64> = (0..resamples.max(1))
        .map(|_| resampled_clustered_mean(&ca, &mut rng) - resampled_clustered_mean(&cb, &mut rng))
        .filter(|d| d.is_finite())
        .collect();
    diffs.sort_by(f64::total_cmp);
    let at = |q: f64| {
        let i = ((diffs.len().max(1) - 1) as f64 * q).round() as usize;
        diffs.get(i).copied().unwrap_or(f64::NAN)
    };
    Some(MeanDifference {
        difference: mean(&a) - mean(&b),
        lo: at(0.025),
        hi: at(0.975),
        n_minuend: a.len(),
        n_subtrahend: b.len(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_clear_shift_has_an_interval_around_it_that_excludes_zero() {
        let mut rng = Rng::new(3);
        let a: Vec<f64> = (0..200).map(|_| rng.normal(100.0, 20.0)).collect();
        let b: Vec<f64> = (0..200).map(|_| rng.normal(80.0, 20.0)).collect();
        let d = mean_difference(&b, &a, RESAMPLES, 1).unwrap();
        assert!((d.difference + 20.0).abs() < 5.0, "{d:?}");
        assert!(d.lo < d.difference && d.difference < d.hi);
        assert!(d.below_zero() && !d.above_zero());
        // About ±1.96 standard errors: SE of the difference is 20·√(2/200) = 2.
        assert!((d.hi - d.lo - 4.0 * 1.96).abs() < 2.0, "{d:?}");
    }

    #[test]
    fn run_level_offsets_widen_the_clustered_interval_until_it_spans_them() {
        // Three runs a side; each run carries its own offset (a robot's lag) of ±30 ms, and the policies do
        // not differ at all. Per command the difference looks "significant"; per run it is not.
        let mut rng = Rng::new(11);
        let runs = |offsets: [f64; 3], rng: &mut Rng| -> Vec<Vec<f64>> {
            offsets
                .iter()
                .map(|o| {
                    (0..100)
                        .map(|_| 150.0 + o + rng.normal(0.0, 10.0))
                        .collect()
                })
                .collect()
        };
        let a = runs([30.0, -25.0, 5.0], &mut rng);
        let b = runs([20.0, -30.0, 0.0], &mut rng);
        let flat = mean_difference(&pooled(&a), &pooled(&b), RESAMPLES, 3).unwrap();
        assert!(flat.above_zero(), "commands alone: {flat:?}");
        let clustered = mean_difference_clustered(&a, &b, RESAMPLES, 3).unwrap();
        assert_eq!(clustered.difference, flat.difference);
        assert!(clustered.lo < 0.0 && clustered.hi > 0.0, "{clustered:?}");
        // One cluster a side: the same as the plain bootstrap's width, roughly.
        let one = mean_difference_clustered(&a[..1], &b[..1], RESAMPLES, 3).unwrap();
        let plain = mean_difference(&a[0], &b[0], RESAMPLES, 3).unwrap();
        assert!(
            ((one.hi - one.lo) - (plain.hi - plain.lo)).abs() < 1.0,
            "{one:?} {plain:?}"
        );
        assert_eq!(mean_difference_clustered(&[vec![]], &b, 10, 1), None);
    }

    #[test]
    fn no_shift_straddles_zero_and_empty_or_bad_samples_give_none() {
        let mut rng = Rng::new(4);
        let a: Vec<f64> = (0..100).map(|_| rng.normal(0.0, 1.0)).collect();
        let b: Vec<f64> = (0..100).map(|_| rng.normal(0.0, 1.0)).collect();
        let d = mean_difference(&a, &b, RESAMPLES, 2).unwrap();
        assert!(d.lo < 0.0 && d.hi > 0.0, "{d:?}");
        assert_eq!(mean_difference(&[], &b, 10, 1), None);
        assert_eq!(mean_difference(&[f64::NAN], &b, 10, 1), None);
        // Same seed, same interval.
        assert_eq!(
            mean_difference(&a, &b, 500, 9),
            mean_difference(&a, &b, 500, 9)
        );
    }
}

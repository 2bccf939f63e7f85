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
//!
//! [`paired_mean_difference`] is for paired designs (the interaction study: both runs of a pair see the same
//! operator): the differences are taken within each pair first, and only the pairs are resampled. With few
//! pairs a percentile interval is too narrow (with k pairs it has at most C(2k − 1, k) distinct means, 10
//! for k = 3); [`FEW_PAIRS`] is where the tables say so.
//!
//! [`ratio_of_means`] is the interval of a relative change `mean(b) / mean(a) − 1`: each sample is resampled
//! on its own and the *ratio* of the resampled means is taken, so for a non-negative quantity no bound can
//! fall below −100 % (dividing the difference's interval by the fixed baseline mean could, and did).

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

/// Below this many pairs (or runs a side) a percentile-bootstrap interval is printed with a warning that
/// it is unreliable: it has too few distinct resamples and is too narrow.
pub const FEW_PAIRS: usize = 8;

/// The percentile `q` of sorted `xs` (the nearest rank, `(len − 1)·q` rounded).
fn percentile(sorted: &[f64], q: f64) -> f64 {
    let i = ((sorted.len().max(1) - 1) as f64 * q).round() as usize;
    sorted.get(i).copied().unwrap_or(f64::NAN)
}

/// The mean of within-pair differences with its 95 % percentile-bootstrap interval over the pairs. `None`
/// when there is no difference or one is not finite; with a single pair the interval is NaN (no spread).
pub fn paired_mean_difference(
    differences: &[f64],
    resamples: usize,
    seed: u64,
) -> Option<MeanDifference> {
    if differences.is_empty() || differences.iter().any(|d| !d.is_finite()) {
        return None;
    }
    let difference = mean(differences);
    let n = differences.len();
    let (lo, hi) = if n < 2 {
        (f64::NAN, f64::NAN)
    } else {
        let mut rng = Rng::new(seed);
        let mut means: Vec<f64> = (0..resamples.max(1))
            .map(|_| resampled_mean(differences, &mut rng))
            .collect();
        means.sort_by(f64::total_cmp);
        (percentile(&means, 0.025), percentile(&means, 0.975))
    };
    Some(MeanDifference {
        difference,
        lo,
        hi,
        n_minuend: n,
        n_subtrahend: n,
    })
}

/// A relative change `mean(other) / mean(baseline) − 1` with its 95 % percentile-bootstrap interval.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct RelativeChange {
    /// `mean(other) / mean(baseline) − 1` (−0.41 is −41 %).
    pub change: f64,
    /// Lower end of the 95 % interval (NaN when a sample has fewer than two values: no spread).
    pub lo: f64,
    /// Upper end of the 95 % interval (NaN likewise).
    pub hi: f64,
    /// Resamples dropped because the resampled baseline mean was 0.
    pub dropped: usize,
}

impl RelativeChange {
    /// Whether an interval was computed (both samples had two values or more).
    pub fn has_interval(&self) -> bool {
        self.lo.is_finite() && self.hi.is_finite()
    }
}

/// The relative change of the mean of `other` against the mean of `baseline`, with the 95 % percentile
/// interval of the ratio of independently resampled means. For non-negative data every bound is ≥ −1.
/// `None` when a sample is empty, holds a non-finite value, or the baseline mean is not positive.
pub fn ratio_of_means(
    other: &[f64],
    baseline: &[f64],
    resamples: usize,
    seed: u64,
) -> Option<RelativeChange> {
    let finite = |xs: &[f64]| !xs.is_empty() && xs.iter().all(|x| x.is_finite());
    if !finite(other) || !finite(baseline) || mean(baseline) <= 0.0 {
        return None;
    }
    let change = mean(other) / mean(baseline) - 1.0;
    if other.len() < 2 || baseline.len() < 2 {
        return Some(RelativeChange {
            change,
            lo: f64::NAN,
            hi: f64::NAN,
            dropped: 0,
        });
    }
    let mut rng = Rng::new(seed);
    let mut dropped = 0;
    let mut ratios = Vec::with_capacity(resamples.max(1));
    for _ in 0..resamples.max(1) {
        let o = resampled_mean(other, &mut rng);
        let b = resampled_mean(baseline, &mut rng);
        if b > 0.0 {
            ratios.push(o / b - 1.0);
        } else {
            dropped += 1;
        }
    }
    ratios.sort_by(f64::total_cmp);
    Some(RelativeChange {
        change,
        lo: percentile(&ratios, 0.025),
        hi: percentile(&ratios, 0.975),
        dropped,
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
    fn percentile_bootstrap_of_a_tiny_sample_matches_its_exact_bootstrap_distribution() {
        // Independent computation: for x = (0, 1, 2, 3) the bootstrap distribution of the mean is exact over
        // all 4⁴ = 256 equally likely resamples; enumerate them and take the same nearest-rank percentiles.
        // By hand: the sum s of four draws from {0..3} has counts 1, 4, 10, 20, 31, 40, 44, 40, 31, 20, 10,
        // 4, 1 for s = 0..12; the cumulative share reaches 0.025 at s = 2 (15/256 = 0.059 ≥ 0.025, while
        // 5/256 = 0.020 < 0.025) and 0.975 at s = 10 (251/256 = 0.980), so the interval is (0.5, 2.5).
        let x = [0.0, 1.0, 2.0, 3.0];
        let mut exact = Vec::new();
        for a in x {
            for b in x {
                for c in x {
                    for d in x {
                        exact.push((a + b + c + d) / 4.0);
                    }
                }
            }
        }
        exact.sort_by(f64::total_cmp);
        let (elo, ehi) = (percentile(&exact, 0.025), percentile(&exact, 0.975));
        assert_eq!((elo, ehi), (0.5, 2.5));
        // The paired bootstrap of these "differences", fixed seed, 20 000 resamples: the same quantiles.
        let d = paired_mean_difference(&x, 20_000, 7).unwrap();
        assert_eq!(d.difference, 1.5);
        assert_eq!((d.lo, d.hi), (elo, ehi), "{d:?}");
        // One pair: an estimate, no spread.
        let one = paired_mean_difference(&[4.0], 100, 1).unwrap();
        assert_eq!(one.difference, 4.0);
        assert!(one.lo.is_nan() && one.hi.is_nan());
        assert_eq!(paired_mean_difference(&[], 100, 1), None);
    }

    #[test]
    fn pairing_removes_the_shared_operator_from_the_interval() {
        // Five pairs whose two runs share a large pair effect (the operator) and differ by exactly 10: the
        // unpaired interval spans the operators' spread, the paired one is the single value 10.
        let pair_effect = [0.0, 80.0, -60.0, 40.0, -20.0];
        let reactive: Vec<f64> = pair_effect.iter().map(|e| 150.0 + e).collect();
        let pavlovian: Vec<f64> = reactive.iter().map(|r| r - 10.0).collect();
        let lead: Vec<f64> = reactive
            .iter()
            .zip(&pavlovian)
            .map(|(r, p)| r - p)
            .collect();
        let paired = paired_mean_difference(&lead, RESAMPLES, 1).unwrap();
        assert_eq!(
            (paired.difference, paired.lo, paired.hi),
            (10.0, 10.0, 10.0)
        );
        let unpaired = mean_difference(&reactive, &pavlovian, RESAMPLES, 1).unwrap();
        assert!(unpaired.lo < 0.0 && unpaired.hi > 20.0, "{unpaired:?}");
    }

    #[test]
    fn ratio_interval_never_falls_below_minus_100_percent_on_offpolicy_shaped_data() {
        // Shaped like the three-policy table's off-policy rows: a reactive baseline of tens of over-current
        // observations per run, an off-policy policy with mostly none and an occasional burst. Dividing the
        // difference's interval by the fixed reactive mean gave −101.5 % and the like for such data.
        let reactive = [42.0, 35.0, 51.0, 38.0, 47.0, 29.0, 44.0, 40.0, 55.0, 33.0];
        let offpolicy = [0.0, 0.0, 3.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0];
        let r = ratio_of_means(&offpolicy, &reactive, RESAMPLES, 1).unwrap();
        assert!((r.change - (0.4 / 41.4 - 1.0)).abs() < 1e-12, "{r:?}");
        assert!(
            r.lo >= -1.0 && r.lo <= r.change && r.change <= r.hi,
            "{r:?}"
        );
        // The old construction on the same data does go below −100 %.
        let d = mean_difference(&offpolicy, &reactive, RESAMPLES, 1).unwrap();
        assert!(d.lo / 41.4 < -1.0, "{d:?}");
        // Every off-policy run at 0: the change is exactly −100 %, and so is the whole interval.
        let z = ratio_of_means(&[0.0; 5], &reactive, RESAMPLES, 2).unwrap();
        assert_eq!((z.change, z.lo, z.hi), (-1.0, -1.0, -1.0));
        // A known ratio: b = 2a exactly in every value gives +100 % with an interval around it.
        let a = [1.0, 2.0, 3.0, 4.0];
        let b = [2.0, 4.0, 6.0, 8.0];
        let r = ratio_of_means(&b, &a, RESAMPLES, 3).unwrap();
        assert!(
            (r.change - 1.0).abs() < 1e-12 && r.lo < 1.0 && r.hi > 1.0,
            "{r:?}"
        );
        // One run a side: the change, no interval; a zero baseline: nothing.
        let one = ratio_of_means(&[3.0], &[4.0], RESAMPLES, 1).unwrap();
        assert!((one.change + 0.25).abs() < 1e-12 && !one.has_interval());
        assert_eq!(ratio_of_means(&[1.0], &[0.0, 0.0], 10, 1), None);
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

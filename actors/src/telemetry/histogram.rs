//! A fixed-size latency histogram with logarithmic buckets, for tick lateness and tick-to-command time.
//!
//! Recording is O(1) and allocation-free so it can sit on the tick path. Buckets are 1 µs wide up to 64 µs
//! and then grow by 1/16 of an octave, so quantiles are exact to about ±4 %; values above ~67 s share the last bucket.

use serde::Serialize;
use std::time::Duration;

const LINEAR: u64 = 64;
const SUB: u64 = 16; // sub-buckets per octave above LINEAR
const OCTAVES: u64 = 20;
const BUCKETS: usize = (LINEAR + SUB * OCTAVES) as usize;

/// Counts of durations in logarithmic buckets.
#[derive(Clone)]
pub(crate) struct LatencyHistogram {
    counts: Box<[u64; BUCKETS]>,
    total: u64,
    max_us: u64,
    sum_us: u128,
}

/// Quantiles of a histogram, µs.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct LatencyQuantiles {
    /// Number of samples.
    pub(crate) count: u64,
    /// Median.
    pub(crate) p50_us: u64,
    /// 99th percentile.
    pub p99_us: u64,
    /// Largest sample.
    pub(crate) max_us: u64,
    /// Mean.
    pub(crate) mean_us: f64,
}

impl Default for LatencyHistogram {
    fn default() -> Self {
        Self::new()
    }
}

fn bucket_of(us: u64) -> usize {
    if us < LINEAR {
        return us as usize;
    }
    let octave = 63 - us.leading_zeros() as u64 - 6; // 0 for 64..127
    let base = 64u64 << octave;
    let sub = ((us - base) * SUB) / base;
    let idx =
        LINEAR + octave.min(OCTAVES - 1) * SUB + if octave >= OCTAVES { SUB - 1 } else { sub };
    (idx as usize).min(BUCKETS - 1)
}

fn bucket_upper(idx: usize) -> u64 {
    let idx = idx as u64;
    if idx < LINEAR {
        return idx;
    }
    let octave = (idx - LINEAR) / SUB;
    let sub = (idx - LINEAR) % SUB;
    let base = 64u64 << octave;
    base + (base * (sub + 1)) / SUB - 1
}

impl LatencyHistogram {
    /// An empty histogram.
    pub(crate) fn new() -> Self {
        LatencyHistogram {
            counts: Box::new([0; BUCKETS]),
            total: 0,
            max_us: 0,
            sum_us: 0,
        }
    }

    /// Adds one sample.
    pub(crate) fn record(&mut self, d: Duration) {
        let us = d.as_micros().min(u64::MAX as u128) as u64;
        self.counts[bucket_of(us)] += 1;
        self.total += 1;
        self.max_us = self.max_us.max(us);
        self.sum_us += us as u128;
    }

    /// The smallest bucket bound below which a fraction `q` of the samples lie (0 when empty).
    pub(crate) fn quantile_us(&self, q: f64) -> u64 {
        if self.total == 0 {
            return 0;
        }
        let rank = ((q.clamp(0.0, 1.0) * self.total as f64).ceil() as u64).max(1);
        let mut seen = 0;
        for (i, c) in self.counts.iter().enumerate() {
            seen += c;
            if seen >= rank {
                return bucket_upper(i).min(self.max_us);
            }
        }
        self.max_us
    }

    /// p50, p99, max and mean.
    pub(crate) fn quantiles(&self) -> LatencyQuantiles {
        LatencyQuantiles {
            count: self.total,
            p50_us: self.quantile_us(0.5),
            p99_us: self.quantile_us(0.99),
            max_us: self.max_us,
            mean_us: if self.total == 0 {
                0.0
            } else {
                self.sum_us as f64 / self.total as f64
            },
        }
    }

    /// Cumulative counts at the given upper bounds (µs), for a Prometheus histogram.
    pub(crate) fn cumulative_at(&self, bounds_us: &[u64]) -> Vec<u64> {
        bounds_us
            .iter()
            .map(|&b| {
                self.counts
                    .iter()
                    .enumerate()
                    .filter(|(i, _)| bucket_upper(*i) <= b)
                    .map(|(_, c)| c)
                    .sum()
            })
            .collect()
    }

    /// Adds every sample of `other` (two runs measured apart, reported as one).
    pub(crate) fn merge(&mut self, other: &LatencyHistogram) {
        for (mine, theirs) in self.counts.iter_mut().zip(other.counts.iter()) {
            *mine += theirs;
        }
        self.total += other.total;
        self.max_us = self.max_us.max(other.max_us);
        self.sum_us += other.sum_us;
    }

    /// The samples recorded since `earlier`, a snapshot of this same histogram (a measurement that
    /// leaves out a warm-up). The largest is the larger bound of its bucket, at most the largest overall.
    /// Used by `bench --zenoh` only, so built with that feature (and in tests).
    #[cfg(any(test, feature = "zenoh"))]
    pub(crate) fn since(&self, earlier: &LatencyHistogram) -> LatencyHistogram {
        let mut out = LatencyHistogram::new();
        for (i, (now, then)) in self.counts.iter().zip(earlier.counts.iter()).enumerate() {
            let c = now.saturating_sub(*then);
            out.counts[i] = c;
            out.total += c;
            if c > 0 {
                out.max_us = bucket_upper(i).min(self.max_us);
            }
        }
        out.sum_us = self.sum_us.saturating_sub(earlier.sum_us);
        out
    }

    /// Sum of all samples, µs.
    pub(crate) fn sum_us(&self) -> u128 {
        self.sum_us
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn since_keeps_only_the_later_samples() {
        let mut h = LatencyHistogram::new();
        for us in [10, 20, 5000] {
            h.record(Duration::from_micros(us));
        }
        let snapshot = h.clone();
        for us in [30, 40, 200] {
            h.record(Duration::from_micros(us));
        }
        let later = h.since(&snapshot);
        let q = later.quantiles();
        assert_eq!(q.count, 3);
        assert_eq!(later.sum_us(), 270);
        assert!((200..=211).contains(&q.max_us), "max {}", q.max_us);
        assert_eq!(later.quantile_us(0.5), 40);
        assert_eq!(h.since(&h).quantiles().count, 0);
    }

    #[test]
    fn buckets_are_monotonic_and_cover_their_values() {
        let mut last = 0;
        for us in [
            0u64, 1, 63, 64, 65, 100, 127, 128, 1000, 20_000, 1_000_000, 60_000_000,
        ] {
            let b = bucket_of(us);
            assert!(b >= last, "bucket order at {us}");
            last = b;
            assert!(
                bucket_upper(b) >= us || b == BUCKETS - 1,
                "upper bound of {us}"
            );
        }
    }

    #[test]
    fn quantiles_are_within_the_bucket_resolution() {
        let mut h = LatencyHistogram::new();
        for us in 1..=1000u64 {
            h.record(Duration::from_micros(us));
        }
        let s = h.quantiles();
        assert_eq!(s.count, 1000);
        assert!((480..=530).contains(&s.p50_us), "p50 {}", s.p50_us);
        assert!((960..=1000).contains(&s.p99_us), "p99 {}", s.p99_us);
        assert_eq!(s.max_us, 1000);
        assert!((s.mean_us - 500.5).abs() < 1e-9);
        assert_eq!(h.cumulative_at(&[63, 2000]), vec![63, 1000]);
    }

    #[test]
    fn a_merge_is_the_histogram_of_both_sample_sets() {
        let (mut a, mut b, mut both) = (
            LatencyHistogram::new(),
            LatencyHistogram::new(),
            LatencyHistogram::new(),
        );
        for us in 1..=500u64 {
            a.record(Duration::from_micros(us));
            both.record(Duration::from_micros(us));
        }
        for us in [2000u64, 3000, 90_000] {
            b.record(Duration::from_micros(us));
            both.record(Duration::from_micros(us));
        }
        a.merge(&b);
        assert_eq!(a.quantiles(), both.quantiles());
        assert_eq!(a.quantiles().max_us, 90_000);
        assert_eq!(
            a.cumulative_at(&[100, 2500]),
            both.cumulative_at(&[100, 2500])
        );
    }

    #[test]
    fn empty_histogram_reports_zero() {
        assert_eq!(
            LatencyHistogram::new().quantiles(),
            LatencyQuantiles::default()
        );
    }
}

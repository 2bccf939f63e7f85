//! A writer of the Prometheus text exposition format (0.0.4): metric families with their `# HELP` and
//! `# TYPE` lines, samples with escaped labels, and histograms whose buckets are cumulative and end at
//! `+Inf`. [`super::prometheus`] uses it to render `/metrics`; [`super::prometheus_check`] is the matching reader.

use std::fmt::Write as _;

use super::histogram::LatencyHistogram;

/// Builds the text, one metric family at a time.
#[derive(Default)]
pub(crate) struct Exposition {
    out: String,
}

impl Exposition {
    /// The text written so far.
    pub(crate) fn into_text(self) -> String {
        self.out
    }

    /// Starts a family: its `# HELP` and `# TYPE` lines.
    pub(crate) fn family(&mut self, name: &str, kind: &str, help: &str) {
        let help = help.replace('\\', "\\\\").replace('\n', "\\n");
        let _ = writeln!(self.out, "# HELP {name} {help}");
        let _ = writeln!(self.out, "# TYPE {name} {kind}");
    }

    /// One sample line (label values escaped).
    pub(crate) fn sample(&mut self, name: &str, labels: &[(&str, &str)], value: f64) {
        self.out.push_str(name);
        if !labels.is_empty() {
            self.out.push('{');
            for (i, (k, v)) in labels.iter().enumerate() {
                if i > 0 {
                    self.out.push(',');
                }
                let v = v
                    .replace('\\', "\\\\")
                    .replace('"', "\\\"")
                    .replace('\n', "\\n");
                let _ = write!(self.out, "{k}=\"{v}\"");
            }
            self.out.push('}');
        }
        let _ = writeln!(self.out, " {}", format_value(value));
    }

    /// A counter family with one unlabelled sample.
    pub(crate) fn counter(&mut self, name: &str, help: &str, value: u64) {
        self.family(name, "counter", help);
        self.sample(name, &[], value as f64);
    }

    /// A gauge family with one unlabelled sample.
    pub(crate) fn gauge(&mut self, name: &str, help: &str, value: f64) {
        self.family(name, "gauge", help);
        self.sample(name, &[], value);
    }

    /// A histogram family: cumulative `_bucket`s ending at `+Inf`, `_sum` and `_count`.
    pub(crate) fn histogram(&mut self, name: &str, help: &str, h: &HistogramSample) {
        self.family(name, "histogram", help);
        let bucket = format!("{name}_bucket");
        let mut running = 0;
        for &(le, count) in &h.buckets {
            // Cumulative counts never decrease and never exceed the total.
            running = count.max(running).min(h.count);
            self.sample(&bucket, &[("le", &format_value(le))], running as f64);
        }
        self.sample(&bucket, &[("le", "+Inf")], h.count as f64);
        self.sample(&format!("{name}_sum"), &[], h.sum_seconds);
        self.sample(&format!("{name}_count"), &[], h.count as f64);
    }
}

/// A sample value as the format writes it (`+Inf`, `-Inf`, `NaN` for the special values).
pub(crate) fn format_value(v: f64) -> String {
    if v.is_nan() {
        "NaN".into()
    } else if v == f64::INFINITY {
        "+Inf".into()
    } else if v == f64::NEG_INFINITY {
        "-Inf".into()
    } else {
        format!("{v}")
    }
}

/// Counter sets declared with `counter_set!` write their families here.
impl crate::bus::counter_set::MetricSink for Exposition {
    fn family(&mut self, name: &str, kind: &str, help: &str) {
        Exposition::family(self, name, kind, help);
    }

    fn sample(&mut self, name: &str, labels: &[(&str, &str)], value: f64) {
        Exposition::sample(self, name, labels, value);
    }
}

/// A histogram as Prometheus sees it: cumulative counts at increasing bounds, plus `+Inf`.
#[derive(Debug, Clone, Default, PartialEq)]
pub(crate) struct HistogramSample {
    /// `(upper bound in seconds, samples ≤ bound)`, bounds increasing.
    pub(crate) buckets: Vec<(f64, u64)>,
    /// Every sample (the `+Inf` bucket and `_count`).
    pub(crate) count: u64,
    /// Sum of the samples, seconds.
    pub(crate) sum_seconds: f64,
}

impl HistogramSample {
    /// Reads `h` at `bounds_us` (increasing). A sample lies in the bucket of its histogram bin's upper edge,
    /// so a count may lag the exact one by the bin width (about 4 %) near a bound, never exceed it.
    pub(crate) fn from_histogram(h: &LatencyHistogram, bounds_us: &[u64]) -> Self {
        let counts = h.cumulative_at(bounds_us);
        HistogramSample {
            buckets: bounds_us
                .iter()
                .map(|&us| us as f64 / 1e6)
                .zip(counts)
                .collect(),
            count: h.quantiles().count,
            sum_seconds: h.sum_us() as f64 / 1e6,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::prometheus_check::parse;
    use super::*;

    #[test]
    fn special_values_and_label_escapes_follow_the_format() {
        assert_eq!(format_value(f64::NAN), "NaN");
        assert_eq!(format_value(f64::INFINITY), "+Inf");
        assert_eq!(format_value(0.25), "0.25");
        assert_eq!(format_value(3.0), "3");
        let mut e = Exposition::default();
        e.family("x_total", "counter", "a\nb");
        e.sample("x_total", &[("l", "q\"\\\n")], 1.0);
        assert_eq!(
            e.out.as_str(),
            "# HELP x_total a\\nb\n# TYPE x_total counter\nx_total{l=\"q\\\"\\\\\\n\"} 1\n"
        );
        let text = e.into_text();
        assert!(parse(&text).is_ok(), "{text}");
    }
}

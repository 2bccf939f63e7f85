//! Every table a study prints, also written beside its figures as `table.md` (for reading and for a paper's
//! source) and `table.csv` (every number at full precision, for a spreadsheet or a plotting script). The
//! numbers are the study's own: nothing here computes a statistic.

use std::fmt::Write as _;
use std::path::Path;

use pavlov::analysis::stats::{Describe, WelchTest};

use super::interaction::InteractionStudy;
use super::stall::policies::PoliciesStudy;
use super::stall::report::StallStudy;

/// A table: a header and rows of cells, the same for Markdown and CSV.
struct Table {
    header: Vec<String>,
    rows: Vec<Vec<String>>,
}

impl Table {
    fn new(header: &[&str]) -> Self {
        Self {
            header: header.iter().map(|h| (*h).to_string()).collect(),
            rows: Vec::new(),
        }
    }

    fn push(&mut self, row: Vec<String>) {
        self.rows.push(row);
    }

    fn markdown(&self) -> String {
        let mut s = String::new();
        let cell = |c: &str| c.replace('|', "\\|");
        let _ = writeln!(
            s,
            "| {} |",
            self.header
                .iter()
                .map(|h| cell(h))
                .collect::<Vec<_>>()
                .join(" | ")
        );
        let _ = writeln!(s, "|{}", "---|".repeat(self.header.len()));
        for r in &self.rows {
            let _ = writeln!(
                s,
                "| {} |",
                r.iter().map(|c| cell(c)).collect::<Vec<_>>().join(" | ")
            );
        }
        s
    }

    fn csv(&self) -> String {
        let cell = |c: &str| {
            if c.contains([',', '"', '\n']) {
                format!("\"{}\"", c.replace('"', "\"\""))
            } else {
                c.to_string()
            }
        };
        let mut s = String::new();
        for r in std::iter::once(&self.header).chain(&self.rows) {
            let _ = writeln!(
                s,
                "{}",
                r.iter().map(|c| cell(c)).collect::<Vec<_>>().join(",")
            );
        }
        s
    }
}

/// A number with about three significant digits (as the printed tables show it): the one formatter of
/// every study's tables.
pub(crate) fn num(x: f64) -> String {
    let a = x.abs();
    if !x.is_finite() {
        "–".into()
    } else if a >= 100.0 {
        format!("{x:.0}")
    } else if a >= 10.0 {
        format!("{x:.1}")
    } else if a >= 1.0 {
        format!("{x:.2}")
    } else {
        format!("{x:.3}")
    }
}

/// A number at full precision for CSV; empty when there is none.
fn full(x: f64) -> String {
    if x.is_finite() {
        format!("{x}")
    } else {
        String::new()
    }
}

fn full_opt(x: Option<f64>) -> String {
    x.map_or(String::new(), full)
}

fn pm(d: &Describe) -> String {
    format!("{} ± {}", num(d.mean), num(d.se))
}

fn pct(x: Option<f64>) -> String {
    x.map_or("–".into(), |v| format!("{:+.1} %", v * 100.0))
}

fn ci_pct(x: Option<(f64, f64)>) -> String {
    x.map_or("–".into(), |(lo, hi)| {
        format!("{:+.1}, {:+.1} %", lo * 100.0, hi * 100.0)
    })
}

fn welch_md(w: Option<WelchTest>) -> [String; 3] {
    w.map_or(["–".into(), "–".into(), "–".into()], |w| {
        [format!("{:.2}", w.t), format!("{:.1}", w.df), w.p_text()]
    })
}

fn welch_csv(w: Option<WelchTest>) -> [String; 3] {
    w.map_or([String::new(), String::new(), String::new()], |w| {
        [full(w.t), full(w.df), full(w.p)]
    })
}

/// Writes `table.md` (a heading line, then the table) and `table.csv` into `dir`.
fn write(dir: &Path, heading: &str, md: &Table, csv: &Table) -> std::io::Result<()> {
    std::fs::write(
        dir.join("table.md"),
        format!("{}\n\n{}", heading.trim_end(), md.markdown()),
    )?;
    std::fs::write(dir.join("table.csv"), csv.csv())
}

/// The stall study's comparison table (means, intervals, t, p), as printed.
pub(crate) fn write_stall(dir: &Path, study: &StallStudy) -> std::io::Result<()> {
    let printed = super::stall::report::table(study);
    let heading = printed.lines().next().unwrap_or_default();
    let mut md = Table::new(&[
        "metric",
        "reactive",
        "Pavlovian",
        "change",
        "95 % CI",
        "t",
        "df",
        "p",
    ]);
    let mut csv = Table::new(&[
        "metric",
        "label",
        "unit",
        "reactive_n",
        "reactive_mean",
        "reactive_se",
        "reactive_sd",
        "pavlovian_n",
        "pavlovian_mean",
        "pavlovian_se",
        "pavlovian_sd",
        "relative_change",
        "relative_change_lo",
        "relative_change_hi",
        "t",
        "df",
        "p",
    ]);
    for c in &study.analysis.comparisons {
        let [t, df, p] = welch_md(c.welch);
        md.push(vec![
            format!("{} ({})", c.label, c.unit),
            pm(&c.reactive),
            pm(&c.pavlovian),
            pct(c.relative_change),
            ci_pct(c.relative_change_ci),
            t,
            df,
            p,
        ]);
        let [t, df, p] = welch_csv(c.welch);
        csv.push(vec![
            c.metric.clone(),
            c.label.clone(),
            c.unit.clone(),
            c.reactive.n.to_string(),
            full(c.reactive.mean),
            full(c.reactive.se),
            full(c.reactive.sd),
            c.pavlovian.n.to_string(),
            full(c.pavlovian.mean),
            full(c.pavlovian.se),
            full(c.pavlovian.sd),
            full_opt(c.relative_change),
            full_opt(c.relative_change_ci.map(|r| r.0)),
            full_opt(c.relative_change_ci.map(|r| r.1)),
            t,
            df,
            p,
        ]);
    }
    write(dir, heading, &md, &csv)
}

/// The interaction study's per-policy timing table, as printed.
pub(crate) fn write_interaction(dir: &Path, s: &InteractionStudy) -> std::io::Result<()> {
    let printed = super::interaction::report::table(s);
    let heading = printed.lines().next().unwrap_or_default();
    let mut md = Table::new(&[
        "policy",
        "commands",
        "latency ms (± SE)",
        "current ms (± SE, n)",
        "motion ms (± SE, n)",
        "anticipated",
        "missed",
        "false starts/min",
        "responding outside s/min",
    ]);
    let mut csv = Table::new(&[
        "policy",
        "commands",
        "latency_ms_mean",
        "latency_ms_se",
        "current_latency_ms_n",
        "current_latency_ms_mean",
        "current_latency_ms_se",
        "motion_latency_ms_n",
        "motion_latency_ms_mean",
        "motion_latency_ms_se",
        "anticipated",
        "anticipated_fraction",
        "missed",
        "false_starts_per_minute",
        "responding_outside_s_per_minute",
    ]);
    let ms = |d: &Describe| format!("{:.0} ± {:.0}", d.mean, d.se);
    for p in &s.timing {
        md.push(vec![
            p.policy.clone(),
            p.commands.to_string(),
            ms(&p.latency_ms),
            format!("{} ({})", ms(&p.current_latency_ms), p.current_latency_ms.n),
            format!("{} ({})", ms(&p.motion_latency_ms), p.motion_latency_ms.n),
            p.anticipated.to_string(),
            p.missed.to_string(),
            format!("{:.2}", p.false_starts_per_minute + 0.0),
            format!("{:.2}", p.responding_outside_s_per_minute + 0.0),
        ]);
        csv.push(vec![
            p.policy.clone(),
            p.commands.to_string(),
            full(p.latency_ms.mean),
            full(p.latency_ms.se),
            p.current_latency_ms.n.to_string(),
            full(p.current_latency_ms.mean),
            full(p.current_latency_ms.se),
            p.motion_latency_ms.n.to_string(),
            full(p.motion_latency_ms.mean),
            full(p.motion_latency_ms.se),
            p.anticipated.to_string(),
            full(p.anticipated_fraction),
            p.missed.to_string(),
            full(p.false_starts_per_minute),
            full(p.responding_outside_s_per_minute),
        ]);
    }
    write(dir, heading, &md, &csv)
}

/// The three-policy study's metrics table: `table.md` is the printed Markdown, `table.csv` one row per
/// metric and policy and one per metric and pair of policies.
pub(crate) fn write_policies(
    dir: &Path,
    study: &PoliciesStudy,
    printed: &str,
) -> std::io::Result<()> {
    std::fs::write(dir.join("table.md"), printed)?;
    let mut csv = Table::new(&[
        "metric",
        "label",
        "policy",
        "against",
        "n",
        "mean",
        "se",
        "sd",
        "min",
        "max",
        "relative_change",
        "relative_change_lo",
        "relative_change_hi",
        "t",
        "df",
        "p",
    ]);
    for row in &study.metrics {
        for p in &row.policies {
            csv.push(vec![
                row.metric.clone(),
                row.label.clone(),
                p.policy.clone(),
                String::new(),
                p.describe.n.to_string(),
                full(p.describe.mean),
                full(p.describe.se),
                full(p.describe.sd),
                full_opt(p.range.map(|r| r.0)),
                full_opt(p.range.map(|r| r.1)),
                String::new(),
                String::new(),
                String::new(),
                String::new(),
                String::new(),
                String::new(),
            ]);
        }
        for c in &row.changes {
            let [t, df, p] = welch_csv(c.welch);
            let mut r = vec![
                row.metric.clone(),
                row.label.clone(),
                c.b.clone(),
                c.a.clone(),
            ];
            r.extend(std::iter::repeat_n(String::new(), 6));
            r.extend([
                full_opt(c.relative_change),
                full_opt(c.relative_change_ci.map(|x| x.0)),
                full_opt(c.relative_change_ci.map(|x| x.1)),
                t,
                df,
                p,
            ]);
            csv.push(r);
        }
    }
    std::fs::write(dir.join("table.csv"), csv.csv())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn markdown_and_csv_hold_the_same_cells_escaped() {
        let mut t = Table::new(&["a", "b"]);
        t.push(vec!["1, 2".into(), "x|y".into()]);
        t.push(vec!["say \"hi\"".into(), "3".into()]);
        assert_eq!(
            t.markdown(),
            "| a | b |\n|---|---|\n| 1, 2 | x\\|y |\n| say \"hi\" | 3 |\n"
        );
        assert_eq!(t.csv(), "a,b\n\"1, 2\",x|y\n\"say \"\"hi\"\"\",3\n");
        assert_eq!(full(f64::NAN), "");
        assert_eq!(num(12.345), "12.3");
    }
}

//! The stall experiment's outputs: `summary.json`, CSV tables, the figures, and the terminal table.

use std::fmt::Write as _;
use std::path::Path;

use pavlov::control::Mode;
use serde::{Deserialize, Serialize};

use super::analysis::{Analysis, TOTALS, total};
use super::run::RunResult;
use super::{StallOptions, WINDOW_S, plots};
use crate::experiment::tables::num;
use crate::provenance::Provenance;

/// Everything `summary.json` holds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StallStudy {
    /// Always "stall".
    pub(crate) experiment: String,
    /// The settings.
    pub(crate) options: StallOptions,
    /// How each run's simulator seed is derived.
    pub(crate) seed_derivation: String,
    /// Every run, in interleaved order.
    pub runs: Vec<RunResult>,
    /// The statistics.
    pub analysis: Analysis,
    /// Wall-clock time of the whole study, s.
    pub(crate) wall_s: f64,
    /// Simulated time over every run, s.
    pub(crate) simulated_s: f64,
    /// Simulated time per second of wall time.
    pub(crate) speedup: f64,
    /// The build and invocation that made the study, and the hash of its configuration.
    #[serde(default)]
    pub provenance: Option<Provenance>,
}

/// Writes `summary.json`, the CSV tables, the printed table as `table.md` and `table.csv`, and the figures
/// (SVG and 300-dpi PNG) into `dir`.
pub fn write_all(dir: &Path, study: &StallStudy) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    let json = serde_json::to_string_pretty(study).map_err(std::io::Error::other)?;
    std::fs::write(dir.join("summary.json"), json)?;
    std::fs::write(dir.join("runs.csv"), runs_csv(&study.runs))?;
    std::fs::write(dir.join("windows.csv"), windows_csv(&study.runs))?;
    std::fs::write(dir.join("learning_curve.csv"), curve_csv(&study.analysis))?;
    let excerpts: Vec<(Mode, &[pavlov::record::TickRecord])> = [Mode::Reactive, Mode::Pavlovian]
        .into_iter()
        .filter_map(|m| {
            study
                .runs
                .iter()
                .find(|r| r.mode == m && !r.excerpt.is_empty())
                .map(|r| (m, plots::push_window(&r.excerpt, 500)))
        })
        .collect();
    std::fs::write(dir.join("fig1_signals.csv"), signals_csv(&excerpts))?;
    plots::fig1_push(dir, &excerpts)?;
    plots::fig2_bars(dir, &study.analysis)?;
    plots::learning_curve(dir, &study.analysis)?;
    crate::experiment::tables::write_stall(dir, study)?;
    Ok(())
}

/// The run's policy as every output names it: the study's own label (`offpolicy` in the three-policy study,
/// whose off-policy runs share the Pavlovian mode), the mode's name when the run has none.
pub(crate) fn policy_label(r: &RunResult) -> &str {
    if r.policy.is_empty() {
        r.mode.name()
    } else {
        &r.policy
    }
}

fn opt(v: Option<f64>) -> String {
    v.map_or_else(String::new, |x| format!("{x}"))
}

/// One row per run.
pub(crate) fn runs_csv(runs: &[RunResult]) -> String {
    let mut s = String::from("run,policy,seed");
    for (key, _, _) in TOTALS {
        s.push(',');
        s.push_str(key);
    }
    s.push('\n');
    for r in runs {
        let _ = write!(s, "{},{},{}", r.index, policy_label(r), r.seed);
        for (key, _, _) in TOTALS {
            let _ = write!(s, ",{}", opt(total(r, key)));
        }
        s.push('\n');
    }
    s
}

/// One row per run and window.
pub(crate) fn windows_csv(runs: &[RunResult]) -> String {
    let mut s = String::from(
        "run,policy,window,start_s,overcurrent_observations,stall_events,distance_m,energy_j\n",
    );
    for r in runs {
        for (w, c) in r.windows.iter().enumerate() {
            let _ = writeln!(
                s,
                "{},{},{w},{},{},{},{},{}",
                r.index,
                policy_label(r),
                w as f64 * WINDOW_S,
                c.overcurrent_observations,
                c.stall_events,
                c.distance_m,
                c.energy_j
            );
        }
    }
    s
}

/// The learning curve.
pub(crate) fn curve_csv(a: &Analysis) -> String {
    let mut s =
        String::from("window,start_s,reactive_mean,reactive_se,pavlovian_mean,pavlovian_se\n");
    for p in &a.learning_curve {
        let _ = writeln!(
            s,
            "{},{},{},{},{},{}",
            p.window, p.start_s, p.reactive.mean, p.reactive.se, p.pavlovian.mean, p.pavlovian.se
        );
    }
    s
}

/// The Figure 1 signals.
pub(crate) fn signals_csv(excerpts: &[(Mode, &[pavlov::record::TickRecord])]) -> String {
    let mut s = String::from(
        "policy,seq,t_s,prediction,threshold,overcurrent,stimulus,gate,command_left_mm_s,command_right_mm_s\n",
    );
    for (mode, recs) in excerpts {
        for r in recs.iter() {
            let (v, th) = r
                .predictions
                .first()
                .map_or((f64::NAN, f64::NAN), |p| (p.value, p.threshold));
            let _ = writeln!(
                s,
                "{},{},{},{v},{th},{},{},{},{},{}",
                mode.name(),
                r.seq,
                r.t_ms / 1000.0,
                u8::from(r.sensors.overcurrent_left || r.sensors.overcurrent_right),
                u8::from(r.stimulus),
                u8::from(r.gate),
                r.command.left_mm_s,
                r.command.right_mm_s
            );
        }
    }
    s
}

fn sd(d: &pavlov::analysis::stats::Describe) -> String {
    if d.n < 2 {
        "n = 1: no spread".into()
    } else {
        num(d.sd)
    }
}

fn pm(d: &pavlov::analysis::stats::Describe) -> String {
    match d.n {
        0 => "–".into(),
        1 => format!("{} (n = 1: no spread)", num(d.mean)),
        _ => format!("{} ± {}", num(d.mean), num(d.se)),
    }
}

/// The table printed at the end of a study.
pub fn table(study: &StallStudy) -> String {
    let o = &study.options;
    let mut s = String::new();
    let _ = writeln!(
        s,
        "Stall experiment: seed {}, {} runs per policy × {} min, interleaved (reactive first); mean ± SE over runs; \
         change = Pavlovian mean / reactive mean − 1, its 95 % interval the percentile bootstrap of that ratio \
         (runs resampled within each policy; 2000 resamples); Welch's t-test of the difference",
        o.seed, o.runs_per_policy, o.minutes
    );
    // The metric column is as wide as its longest label, so every row's numbers line up.
    let labels: Vec<String> = study
        .analysis
        .comparisons
        .iter()
        .map(|c| format!("{} ({})", c.label, c.unit))
        .collect();
    let w = labels
        .iter()
        .map(|l| l.chars().count())
        .max()
        .unwrap_or(0)
        .max(6);
    let _ = writeln!(
        s,
        "{:<w$} {:>24} {:>24} {:>9} {:>18} {:>8} {:>6} {:>8}",
        "metric", "reactive", "Pavlovian", "change", "95 % CI", "t", "df", "p"
    );
    for (c, label) in study.analysis.comparisons.iter().zip(&labels) {
        let (t, df, p) = c.welch.map_or(("–".into(), "–".into(), "–".into()), |w| {
            (format!("{:.2}", w.t), format!("{:.1}", w.df), w.p_text())
        });
        let change = c
            .relative_change
            .map_or("–".into(), |r| format!("{:+.1}%", r * 100.0));
        let ci = match c.relative_change_ci {
            Some((lo, hi)) if lo.is_finite() && hi.is_finite() => {
                format!("{:+.1}, {:+.1}%", lo * 100.0, hi * 100.0)
            }
            _ if c.reactive.n < 2 || c.pavlovian.n < 2 => "no spread".into(),
            _ => "–".into(),
        };
        let _ = writeln!(
            s,
            "{:<w$} {:>24} {:>24} {:>9} {:>18} {:>8} {:>6} {:>8}",
            label,
            pm(&c.reactive),
            pm(&c.pavlovian),
            change,
            ci,
            t,
            df,
            p
        );
    }
    let _ = writeln!(
        s,
        "spread across runs, SD [min – max]: reactive / Pavlovian"
    );
    let range =
        |r: Option<(f64, f64)>| r.map_or("–".into(), |(l, h)| format!("{} – {}", num(l), num(h)));
    for c in &study.analysis.comparisons {
        let _ = writeln!(
            s,
            "  {:<28} {} [{}] / {} [{}]",
            c.label,
            sd(&c.reactive),
            range(c.reactive_range),
            sd(&c.pavlovian),
            range(c.pavlovian_range)
        );
    }
    if o.runs_per_policy < pavlov::analysis::bootstrap::FEW_PAIRS && o.runs_per_policy >= 2 {
        let _ = writeln!(
            s,
            "note: {} runs per policy are too few for a reliable bootstrap interval (it comes out too narrow); \
             read the intervals as rough",
            o.runs_per_policy
        );
    }
    let _ = writeln!(
        s,
        "learning curve (over-current observations per {WINDOW_S} s window, reactive / Pavlovian mean):"
    );
    let mut line = String::new();
    for p in &study.analysis.learning_curve {
        let _ = write!(
            line,
            " {}s: {:.1}/{:.1}",
            p.start_s, p.reactive.mean, p.pavlovian.mean
        );
    }
    let _ = writeln!(s, "{}", line.trim_start());
    match study.analysis.first_below_window {
        Some(w) => {
            let _ = writeln!(
                s,
                "first window with the Pavlovian mean below the reactive one: {}–{} s",
                w as f64 * WINDOW_S,
                (w + 1) as f64 * WINDOW_S
            );
        }
        None => {
            let _ = writeln!(s, "no window has the Pavlovian mean below the reactive one");
        }
    }
    match study.analysis.benefit_from_window {
        Some(w) => {
            let _ = writeln!(
                s,
                "Pavlovian below reactive in every window from {} s on",
                w as f64 * WINDOW_S
            );
        }
        None => {
            let _ = writeln!(s, "Pavlovian is not below reactive in every later window");
        }
    }
    let f = &study.analysis.first_predictive_stop_s;
    let _ = writeln!(
        s,
        "first stop on the prediction alone (gate on, stimulus off): {} s into the run ({} Pavlovian runs)",
        pm(f),
        f.n
    );
    let _ = writeln!(
        s,
        "seeds (run: policy seed): {}",
        study
            .runs
            .iter()
            .map(|r| format!("{}:{} {}", r.index, &r.mode.name()[..1], r.seed))
            .collect::<Vec<_>>()
            .join(", ")
    );
    let _ = writeln!(
        s,
        "{:.0} s simulated in {:.1} s of wall time ({:.0}× real time)",
        study.simulated_s, study.wall_s, study.speedup
    );
    let _ = writeln!(s, "{}", crate::experiment::design_notes::stall());
    s
}

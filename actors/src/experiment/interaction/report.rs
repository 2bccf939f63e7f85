//! `pavlov experiment interaction`'s outputs: `summary.json`, `commands.csv`, `aligned.csv`, `curve.csv`,
//! the Figure 3 / Figure 4 analogues, the time course (`fig_curve.svg`), and the terminal table.

use std::fmt::Write as _;
use std::path::Path;

use pavlov::analysis::bootstrap::{FEW_PAIRS, MeanDifference};
use pavlov::analysis::stats::Describe;

use super::{InteractionStudy, plots};

fn num(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.0}")
    } else {
        "–".into()
    }
}

fn pm(d: &Describe) -> String {
    match d.n {
        0 => "–".into(),
        1 => format!("{} (n = 1: no spread)", num(d.mean)),
        _ => format!("{} ± {}", num(d.mean), num(d.se)),
    }
}

fn diff(d: Option<MeanDifference>, scale: f64, unit: &str) -> String {
    match d {
        Some(d) if !(d.lo.is_finite() && d.hi.is_finite()) => {
            format!("{:+.1}{unit} [n = 1: no spread]", d.difference * scale)
        }
        Some(d) => format!(
            "{:+.1}{unit} [95 % CI {:+.1}, {:+.1}]",
            d.difference * scale,
            d.lo * scale,
            d.hi * scale
        ),
        None => "–".into(),
    }
}

/// The terminal table.
pub fn table(s: &InteractionStudy) -> String {
    let o = &s.options;
    let mut t = String::new();
    let _ = writeln!(
        t,
        "Interaction experiment: seed {}, {} run(s) per policy × {} min; response onset relative to the operator's \
         true command onset (latency; negative = anticipated); per-policy means ± SE over commands",
        o.seed, o.runs_per_policy, o.minutes
    );
    let _ = writeln!(
        t,
        "{:<10} {:>8} {:>20} {:>20} {:>20} {:>11} {:>7} {:>15} {:>18}",
        "policy",
        "commands",
        "latency ms (±SE)",
        "current ms (±SE)",
        "motion ms (±SE)",
        "anticipated",
        "missed",
        "false starts/min",
        "resp. outside s/min"
    );
    for p in &s.timing {
        let _ = writeln!(
            t,
            "{:<10} {:>8} {:>20} {:>20} {:>20} {:>11} {:>7} {:>15.2} {:>18.2}",
            p.policy,
            p.commands,
            pm(&p.latency_ms),
            format!("{} ({})", pm(&p.current_latency_ms), p.current_latency_ms.n),
            format!("{} ({})", pm(&p.motion_latency_ms), p.motion_latency_ms.n),
            p.anticipated,
            p.missed,
            p.false_starts_per_minute + 0.0,
            p.responding_outside_s_per_minute + 0.0
        );
    }
    let sh = &s.shifts;
    let _ = writeln!(
        t,
        "leads = reactive − Pavlovian onset (positive = the Pavlovian response came earlier), taken within each of \
         the {} pairs of runs that saw the same operator, then over pairs; 95 % percentile bootstrap over pairs:\n  \
         battery current onset lead {}\n  motion onset lead {}\n  decision (debounced gate) onset lead {}",
        sh.pairs,
        diff(sh.current_lead_ms, 1.0, " ms"),
        diff(sh.motion_lead_ms, 1.0, " ms"),
        diff(sh.decision_lead_ms, 1.0, " ms"),
    );
    if sh.pairs < 2 {
        let _ = writeln!(
            t,
            "  (n = 1 pair: no spread, so no interval; the physical leads also hold the two robots' own differences \
             in friction and charge; the decision lead does not depend on the robot)"
        );
    } else if sh.pairs < FEW_PAIRS {
        let _ = writeln!(
            t,
            "  (only {} pairs: a bootstrap interval over so few clusters is unreliable — too narrow — read it as \
             rough; run more pairs with --runs)",
            sh.pairs
        );
    }
    let frac = |p: &str| {
        s.timing
            .iter()
            .find(|x| x.policy == p)
            .map_or(f64::NAN, |x| x.anticipated_fraction * 100.0)
    };
    let _ = writeln!(
        t,
        "  anticipated (decision before the true onset): reactive {:.1} %, Pavlovian {:.1} %, excess (Pavlovian − \
         reactive, within pairs) {}",
        frac("reactive"),
        frac("pavlovian"),
        diff(sh.anticipated_excess, 100.0, " pp"),
    );
    if let Some(w) = sh.decision_lead_t {
        let _ = writeln!(
            t,
            "  decision lead, paired t over pairs = {:.2}, df = {:.0}, p {}",
            w.t,
            w.df,
            p_phrase(&w)
        );
    }
    let _ = writeln!(
        t,
        "time course ({}-min windows; leads = reactive − Pavlovian onset, ms, positive = Pavlovian earlier, 95 % \
         two-stage bootstrap (runs, then commands) and, for the decision lead, paired over pairs; anticipated excess \
         over the reactive baseline, pp; Pavlovian false starts per minute):",
        s.options.window_min
    );
    for p in &s.curve {
        let _ = writeln!(
            t,
            "  {:>5.1}–{:<5.1} min: decision lead {:<33} paired {:<33} current lead {:<33} excess {:<34} false starts {:.2}",
            p.from_min,
            p.to_min,
            diff(p.decision_lead, 1.0, " ms"),
            diff(p.decision_lead_paired, 1.0, " ms"),
            diff(p.current_lead, 1.0, " ms"),
            diff(p.anticipated_difference, 100.0, " pp"),
            p.false_starts_pavlovian.per_minute
        );
    }
    let from = |w: Option<usize>| {
        w.and_then(|w| s.curve.get(w))
            .map_or("never in this study".to_string(), |p| {
                format!("from {:.1} min", p.from_min)
            })
    };
    let holds = if s.holds_from_window == s.holds_from_window_paired {
        format!(
            "{} (the same with either interval method)",
            from(s.holds_from_window)
        )
    } else {
        format!(
            "{} by the two-stage interval, {} by the paired one (the window depends on the method)",
            from(s.holds_from_window),
            from(s.holds_from_window_paired)
        )
    };
    let _ = writeln!(
        t,
        "anticipation holds {holds}\n  rule: the first window from which the decision lead's 95 % interval lies \
         wholly above 0 in that and every later window; Figure 3 analogue at {:.1} min (the middle of the two-stage \
         window, or the end of the run)",
        s.fig3_at_min
    );
    let _ = writeln!(
        t,
        "aligned on the observed onset (last {} per run), every 100 ms (aligned.csv: every tick):\n  \
         {:>7} {:>17} {:>8} {:>8} {:>19} {:>8}",
        s.options.aligned_commands,
        "offset",
        "current mA R / P",
        "Δ mA",
        "p",
        "rotation °/tick R/P",
        "p"
    );
    for p in s.aligned.iter().filter(|p| p.offset % 5 == 0) {
        let _ = writeln!(
            t,
            "  {:>+5} ms {:>8}/{:<8} {:>+8.1} {:>8} {:>9.2}/{:<9.2} {:>8}",
            p.offset * 20,
            num(p.current_reactive.mean),
            num(p.current_pavlovian.mean),
            p.current_pavlovian.mean - p.current_reactive.mean,
            p.current_welch.map_or("–".into(), |w| w.p_text()),
            p.angle_reactive.mean,
            p.angle_pavlovian.mean,
            p.angle_welch.map_or("–".into(), |w| w.p_text()),
        );
    }
    let _ = writeln!(
        t,
        "seeds: {}; {:.1} s wall",
        s.runs
            .iter()
            .map(|r| format!(
                "{}:{} robot {} operator {}",
                r.index,
                &r.mode.name()[..1],
                r.robot_seed,
                r.human_seed
            ))
            .collect::<Vec<_>>()
            .join(", "),
        s.wall_s
    );
    let _ = writeln!(t, "{}", crate::experiment::design_notes::interaction());
    t
}

fn d(x: &Describe) -> String {
    format!("{},{}", x.mean, x.se)
}

/// Writes `summary.json`, `commands.csv`, `aligned.csv`, the per-policy table as `table.md` and `table.csv`,
/// and the figures (SVG and 300-dpi PNG).
pub fn write_all(dir: &Path, s: &InteractionStudy) -> std::io::Result<()> {
    std::fs::create_dir_all(dir)?;
    let json = serde_json::to_string_pretty(s).map_err(std::io::Error::other)?;
    std::fs::write(dir.join("summary.json"), json)?;
    let mut c = String::from(
        "run,policy,command,onset_ms,end_ms,outcome,current_latency_ms,motion_latency_ms\n",
    );
    let opt = |x: Option<f64>| x.map_or(String::new(), |v| v.to_string());
    for r in &s.runs {
        for (k, (w, out)) in r.commands.iter().zip(&r.metrics.outcomes).enumerate() {
            let phys = r.physical.get(k).copied().unwrap_or_default();
            let out = serde_json::to_string(out)
                .unwrap_or_default()
                .replace(',', ";");
            let _ = writeln!(
                c,
                "{},{},{k},{},{},{out},{},{}",
                r.index,
                r.mode.name(),
                w.onset_ms,
                w.end_ms,
                opt(phys.current_ms),
                opt(phys.motion_ms)
            );
        }
    }
    std::fs::write(dir.join("commands.csv"), c)?;
    let mut a = String::from(
        "offset_ticks,offset_ms,current_reactive_mean,current_reactive_se,current_pavlovian_mean,current_pavlovian_se,\
         current_p,angle_reactive_mean,angle_reactive_se,angle_pavlovian_mean,angle_pavlovian_se,angle_p\n",
    );
    for p in &s.aligned {
        let _ = writeln!(
            a,
            "{},{},{},{},{},{},{},{}",
            p.offset,
            p.offset * 20,
            d(&p.current_reactive),
            d(&p.current_pavlovian),
            p.current_welch.map_or(f64::NAN, |w| w.p),
            d(&p.angle_reactive),
            d(&p.angle_pavlovian),
            p.angle_welch.map_or(f64::NAN, |w| w.p),
        );
    }
    std::fs::write(dir.join("aligned.csv"), a)?;
    std::fs::write(dir.join("curve.csv"), curve_csv(s))?;
    plots::fig3(dir, s)?;
    plots::fig4(dir, s)?;
    plots::fig_curve(dir, s)?;
    crate::experiment::tables::write_interaction(dir, s)?;
    Ok(())
}

/// The time course, one row per window.
pub(crate) fn curve_csv(s: &InteractionStudy) -> String {
    let mut c = String::from(
        "from_min,to_min,commands_reactive,commands_pavlovian,\
         decision_lead_ms,decision_lead_lo,decision_lead_hi,decision_lead_paired_ms,decision_lead_paired_lo,decision_lead_paired_hi,current_lead_ms,current_lead_lo,current_lead_hi,motion_lead_ms,motion_lead_lo,motion_lead_hi,\
         anticipated_reactive,anticipated_pavlovian,anticipated_excess,anticipated_excess_lo,anticipated_excess_hi,\
         false_starts_per_min_reactive,false_starts_per_min_pavlovian,false_starts_pavlovian_lo,false_starts_pavlovian_hi\n",
    );
    let d = |x: Option<MeanDifference>| {
        x.map_or(",,".to_string(), |x| {
            format!("{},{},{}", x.difference, x.lo, x.hi)
        })
    };
    for p in &s.curve {
        let _ = writeln!(
            c,
            "{},{},{},{},{},{},{},{},{},{},{},{},{},{},{}",
            p.from_min,
            p.to_min,
            p.commands_reactive,
            p.commands_pavlovian,
            d(p.decision_lead),
            d(p.decision_lead_paired),
            d(p.current_lead),
            d(p.motion_lead),
            p.anticipated_reactive,
            p.anticipated_pavlovian,
            d(p.anticipated_difference),
            p.false_starts_reactive.per_minute,
            p.false_starts_pavlovian.per_minute,
            p.false_starts_pavlovian.lo,
            p.false_starts_pavlovian.hi,
        );
    }
    c
}

/// `= 0.012` or `< 0.001`, to follow a "p" in a sentence.
fn p_phrase(w: &pavlov::analysis::stats::WelchTest) -> String {
    let p = w.p_text();
    if p.starts_with('<') {
        p
    } else {
        format!("= {p}")
    }
}

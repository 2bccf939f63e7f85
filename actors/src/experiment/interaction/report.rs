//! `pavlov experiment interaction`'s outputs: `summary.json`, `commands.csv`, `aligned.csv`, the Figure 3 /
//! Figure 4 analogues, and the terminal table.

use std::fmt::Write as _;
use std::path::Path;

use pavlov::analysis::stats::Describe;

use super::{InteractionStudy, plots};
use crate::experiment::mode_name;

fn num(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.0}")
    } else {
        "–".into()
    }
}

/// The terminal table.
pub fn table(s: &InteractionStudy) -> String {
    let o = &s.options;
    let mut t = String::new();
    let _ = writeln!(
        t,
        "Interaction experiment: seed {}, {} run(s) per policy × {} min; response onset relative to the operator's \
         true command onset (negative = anticipated)",
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
            format!("{} ± {}", num(p.latency_ms.mean), num(p.latency_ms.se)),
            format!(
                "{} ± {} ({})",
                num(p.current_latency_ms.mean),
                num(p.current_latency_ms.se),
                p.current_latency_ms.n
            ),
            format!(
                "{} ± {} ({})",
                num(p.motion_latency_ms.mean),
                num(p.motion_latency_ms.se),
                p.motion_latency_ms.n
            ),
            p.anticipated,
            p.missed,
            p.false_starts_per_minute + 0.0,
            p.responding_outside_s_per_minute + 0.0
        );
    }
    if let Some(w) = s.latency_welch {
        let _ = writeln!(
            t,
            "latency, Pavlovian vs reactive: Welch t = {:.2}, df = {:.1}, p = {:.3}",
            w.t, w.df, w.p
        );
    }
    let _ = writeln!(
        t,
        "aligned on the observed onset (last {} per run): battery current mA, reactive / Pavlovian",
        s.options.aligned_commands
    );
    let mut line = String::new();
    for p in s
        .aligned
        .iter()
        .filter(|p| [-10, 0, 5, 10, 15, 25].contains(&p.offset))
    {
        let _ = write!(
            line,
            " {:+} ms: {}/{}{}",
            p.offset * 20,
            num(p.current_reactive.mean),
            num(p.current_pavlovian.mean),
            p.current_welch
                .map_or("", |w| if w.p < 0.05 { "*" } else { "" })
        );
    }
    let _ = writeln!(t, "{}  (* p < 0.05)", line.trim_start());
    let _ = writeln!(
        t,
        "seeds: {}; {:.1} s wall",
        s.runs
            .iter()
            .map(|r| format!(
                "{}:{} robot {} operator {}",
                r.index,
                &mode_name(r.mode)[..1],
                r.robot_seed,
                r.human_seed
            ))
            .collect::<Vec<_>>()
            .join(", "),
        s.wall_s
    );
    t
}

fn d(x: &Describe) -> String {
    format!("{},{}", x.mean, x.se)
}

/// Writes `summary.json`, `commands.csv`, `aligned.csv` and the figures.
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
                mode_name(r.mode),
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
    plots::fig3(&dir.join("fig3_timing.svg"), s)?;
    plots::fig4(&dir.join("fig4_aligned.svg"), s)?;
    Ok(())
}

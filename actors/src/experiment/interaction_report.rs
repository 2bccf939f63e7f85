//! `pavlov experiment interaction`: runs the interaction study, writes `summary.json`, CSV tables and the
//! Figure 3 / Figure 4 analogues, and returns the terminal table.

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use pavlov::config::Config;
use pavlov::control::Mode;
use pavlov::stats::{Describe, WelchTest};
use serde::Serialize;

use super::interaction::{
    self, AlignedPoint, InteractionRun, PolicyTiming, aligned, latency_test, timing,
};
use super::mode_name;
use super::run::RunError;

/// The study's settings.
#[derive(Debug, Clone, Serialize)]
pub struct InteractionOptions {
    /// Runs per policy (the paper: 1).
    pub runs_per_policy: usize,
    /// Minutes per run (the paper: under 10).
    pub minutes: f64,
    /// How many of each run's last observed commands the aligned averages use (the paper: 40).
    pub aligned_commands: usize,
    /// The experiment's seed.
    pub seed: u64,
    /// Record every run.
    pub record: bool,
    /// OS threads.
    pub threads: usize,
    /// Results directory.
    pub out: PathBuf,
}

/// Everything `summary.json` holds.
#[derive(Debug, Clone, Serialize)]
pub struct InteractionSummary {
    /// The settings.
    pub options: InteractionOptions,
    /// How the seeds are derived.
    pub seed_derivation: String,
    /// Every run.
    pub runs: Vec<InteractionRun>,
    /// Per-policy response timing.
    pub timing: Vec<PolicyTiming>,
    /// Welch's test of the latencies, Pavlovian vs reactive.
    pub latency_welch: Option<WelchTest>,
    /// Aligned averages around the observed command onsets.
    pub aligned: Vec<AlignedPoint>,
    /// Wall time, s.
    pub wall_s: f64,
}

/// Runs every run (alternating reactive / Pavlovian) on `threads` threads, with no progress bar.
pub fn run_study(base: &Config, o: &InteractionOptions) -> Result<InteractionSummary, RunError> {
    run_study_with_progress(base, o, false)
}

/// [`run_study`], with a progress bar on stderr when `progress`.
pub fn run_study_with_progress(
    base: &Config,
    o: &InteractionOptions,
    progress: bool,
) -> Result<InteractionSummary, RunError> {
    let wall = std::time::Instant::now();
    let period_s = base.tick.period_ms.max(1) as f64 / 1000.0;
    let ticks = (o.minutes * 60.0 / period_s).round().max(1.0) as usize;
    let specs: Vec<(usize, Mode)> = (0..2 * o.runs_per_policy)
        .map(|i| {
            let m = if i % 2 == 0 {
                Mode::Reactive
            } else {
                Mode::Pavlovian
            };
            (i, m)
        })
        .collect();
    let bar = super::progress_bar(specs.len(), progress);
    bar.set_message(format!("{} min each", o.minutes));
    bar.tick();
    let mut runs = Vec::with_capacity(specs.len());
    for chunk in specs.chunks(o.threads.max(1)) {
        let outcomes: Vec<Result<InteractionRun, RunError>> = std::thread::scope(|s| {
            let handles: Vec<_> = chunk
                .iter()
                .map(|&(i, m)| {
                    let dir = o
                        .record
                        .then(|| o.out.join("runs").join(format!("{i:02}-{}", mode_name(m))));
                    s.spawn(move || {
                        tracing::subscriber::with_default(
                            tracing::subscriber::NoSubscriber::default(),
                            || interaction::run(base, i, m, o.seed, ticks, o.aligned_commands, dir),
                        )
                    })
                })
                .collect();
            handles
                .into_iter()
                .map(|h| {
                    h.join()
                        .unwrap_or_else(|_| Err(RunError::Server("a run panicked".into())))
                })
                .collect()
        });
        for r in outcomes {
            let r = r?;
            bar.inc(1);
            bar.set_message(format!(
                "run {} {}: mean latency {} ms, {:.1} s wall",
                r.index,
                mode_name(r.mode),
                r.metrics.mean_latency_ms().map_or("–".into(), num),
                r.wall_s
            ));
            runs.push(r);
        }
    }
    bar.finish_and_clear();
    Ok(InteractionSummary {
        options: o.clone(),
        seed_derivation: "run i (even = reactive, odd = Pavlovian): robot seed \
                          Rng::new(seed).fork(i).next_u64(), operator seed Rng::new(seed).fork(i).fork(1).next_u64()"
            .into(),
        timing: vec![timing(&runs, Mode::Reactive), timing(&runs, Mode::Pavlovian)],
        latency_welch: latency_test(&runs),
        aligned: aligned(&runs),
        runs,
        wall_s: wall.elapsed().as_secs_f64(),
    })
}

fn num(x: f64) -> String {
    if x.is_finite() {
        format!("{x:.0}")
    } else {
        "–".into()
    }
}

/// The terminal table.
pub fn table(s: &InteractionSummary) -> String {
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
pub fn write_all(dir: &Path, s: &InteractionSummary) -> std::io::Result<()> {
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
    super::interaction_plots::fig3(&dir.join("fig3_timing.svg"), s)?;
    super::interaction_plots::fig4(&dir.join("fig4_aligned.svg"), s)?;
    Ok(())
}

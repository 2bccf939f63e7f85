//! `pavlov experiment stall`: plans the runs, runs them with a progress bar, analyses and writes the results.

use std::time::Instant;

use pavlov::config::Config;

use super::report::{self, Summary};
use super::{StallOptions, WINDOW_S, analyse, plan, run_all};

/// Runs the whole study with `base` as the configuration; `progress` shows a progress bar on stderr.
pub fn run_study(base: &Config, opts: &StallOptions, progress: bool) -> anyhow::Result<Summary> {
    let wall = Instant::now();
    let specs = plan(base, opts);
    let bar = super::progress_bar(specs.len(), progress);
    let on_done = |_done: usize, _total: usize, r: &super::RunResult| {
        bar.inc(1);
        bar.set_message(format!(
            "run {} {}: {} over-current, {:.1} s wall",
            r.index,
            super::mode_name(r.mode),
            r.metrics.overcurrent_observations,
            r.wall_s
        ));
    };
    let runs = run_all(base, &specs, opts.threads, &on_done)?;
    bar.finish_and_clear();
    let analysis = analyse(&runs, WINDOW_S);
    let simulated_s: f64 = runs.iter().map(|r| r.metrics.elapsed_s).sum();
    let wall_s = wall.elapsed().as_secs_f64();
    Ok(Summary {
        experiment: "stall".into(),
        options: opts.clone(),
        seed_derivation: "run i (0-based, even = reactive, odd = Pavlovian) uses simulator seed \
                          Rng::new(seed).fork(i).next_u64() (pavlov::rng: SplitMix64 seeding, xoshiro256++)"
            .into(),
        runs,
        analysis,
        wall_s,
        simulated_s,
        speedup: if wall_s > 0.0 { simulated_s / wall_s } else { 0.0 },
    })
}

/// Runs the study, writes every output into `opts.out` and returns the terminal table.
pub fn run_and_report(
    base: &Config,
    opts: &StallOptions,
    progress: bool,
) -> anyhow::Result<String> {
    let summary = run_study(base, opts, progress)?;
    report::write_all(&opts.out, &summary)?;
    let mut table = report::table(&summary);
    table.push_str(&format!("results: {}\n", opts.out.display()));
    for r in &summary.runs {
        if r.recorder_dropped > 0 || r.lagged > 0 {
            table.push_str(&format!(
                "warning: run {}: {} records dropped by the recorder queue, {} missed by the analysis\n",
                r.index, r.recorder_dropped, r.lagged
            ));
        }
    }
    Ok(table)
}

//! `pavlov experiment stall|interaction`: the paper's experiments on the simulated Create, through the
//! real runtime under virtual time.

use std::path::PathBuf;

use anyhow::{Context, Result};
use pavlov::config::Config;

use pavlov_actors::experiment::results::{Folder, Placement};
use pavlov_actors::experiment::shard::{self, Shard};
use pavlov_actors::experiment::{interaction, stall};

/// The stall experiment's configuration, built in.
const STALL_CONFIG: &str = include_str!("../../../config/stall.toml");

/// The interaction experiment's configuration, built in.
const INTERACTION_CONFIG: &str = include_str!("../../../config/interaction.toml");

/// `pavlov experiment`.
#[derive(clap::Args, Debug, Clone)]
pub struct ExperimentArgs {
    /// Which experiment.
    #[command(subcommand)]
    pub which: Experiment,
}

/// The experiments.
#[derive(clap::Subcommand, Debug, Clone)]
pub enum Experiment {
    /// The paper's stall experiment: interleaved reactive / Pavlovian runs on the simulated Create, through
    /// the real runtime under virtual time; writes summary.json, CSV tables, recordings and SVG figures.
    Stall(StallArgs),
    /// The paper's interaction experiment: a simulated operator commands a left spin with the left elbow;
    /// reactive vs Pavlovian response timing, and current / rotation aligned on the command (Figs 3, 4).
    Interaction(InteractionArgs),
    /// Merge the shard files (shard-I-of-N.json) that `stall|interaction --shard I/N` runs wrote into the
    /// study's summary, tables and figures, the same as the unsharded study's; refuses missing, repeated or
    /// mismatched shards (different experiment, configuration, options or shard count), runs that are not
    /// the ones the options plan (index, policy, seeds), and anything but regular files of at most 1 GiB.
    Merge(MergeArgs),
}

/// `pavlov experiment merge`.
#[derive(clap::Args, Debug, Clone)]
pub struct MergeArgs {
    /// Shard files, or directories holding them (every shard-*-of-*.json in each).
    #[arg(required = true, value_name = "DIR")]
    pub dirs: Vec<PathBuf>,
    /// Results directory: absent or empty, or any with --force (default: a new
    /// results/<experiment>-<UTC time>-seed<S>/, and results/<experiment>-latest points to it).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Write into a non-empty --out: the merge replaces only the files it writes, and deletes nothing.
    #[arg(long)]
    pub force: bool,
}

/// `pavlov experiment interaction`.
#[derive(clap::Args, Debug, Clone)]
pub struct InteractionArgs {
    /// The time course: several pairs for an hour (defaults --runs 10 --minutes 60, no recordings); writes
    /// curve.csv and fig_curve.svg (every study writes them; this sets the defaults for a long one). Ten
    /// pairs: the paired intervals are over pairs, and a bootstrap over fewer than 8 is too narrow.
    #[arg(long)]
    pub curve: bool,
    /// The sensitivity table: the whole study (defaults --runs 3 --minutes 60: eleven variants, so fewer
    /// pairs than --curve; its intervals over 3 pairs are rough) for each operator and learner variant,
    /// each labelled paper or non-paper; writes sensitivity.md and sensitivity.csv.
    #[arg(long, conflicts_with = "curve")]
    pub sensitivity: bool,
    /// Runs per policy, each pair with its own operator (default 1, the paper; 10 with --curve, 3 with
    /// --sensitivity).
    #[arg(long, value_name = "N")]
    pub runs: Option<usize>,
    /// Minutes per run (default 10, the paper's "under 10"; 60 with --curve or --sensitivity).
    #[arg(long, value_name = "MIN")]
    pub minutes: Option<f64>,
    /// Length of a window of the time course, minutes (5: about 80 commands per policy per window over 3
    /// seeds, a 95 % interval of about ±10 ms on the decision lead).
    #[arg(long, default_value_t = 5.0, value_name = "MIN")]
    pub window: f64,
    /// How many of each run's last observed commands the aligned averages (Figure 4) use (the paper: 40).
    #[arg(long, default_value_t = 40, value_name = "N")]
    pub commands: usize,
    /// The experiment's seed.
    #[arg(long, default_value_t = 1, value_name = "S")]
    pub seed: u64,
    /// Results directory: absent or empty, or any with --force (default: a new
    /// results/interaction[-curve|-sensitivity]-<UTC time>-seed<S>/, and
    /// results/interaction[-curve|-sensitivity]-latest points to it). With --shard: the folder the study's
    /// shards share (default results/interaction[-curve]-seed<S>-shards/).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Write into a non-empty --out (with --shard: replace this shard's file): the study replaces only the
    /// files it writes, deletes nothing, and records a run beside a folder that holds a recording already.
    #[arg(long)]
    pub force: bool,
    /// Configuration (TOML); default: the built-in config/interaction.toml.
    #[arg(long, short = 'c', value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Do not write per-tick recordings of the runs (always off with --curve).
    #[arg(long)]
    pub no_record: bool,
    /// Run only the I-th (0-based) of N disjoint slices of the planned runs and write
    /// shard-I-of-N.json into the results directory; `pavlov experiment merge` puts the shards together.
    #[arg(long, value_name = "I/N", conflicts_with = "sensitivity")]
    pub shard: Option<Shard>,
}

/// `pavlov experiment stall`.
#[derive(clap::Args, Debug, Clone)]
pub struct StallArgs {
    /// Runs per policy (the paper: 10).
    #[arg(long, default_value_t = 10, value_name = "N")]
    pub runs: usize,
    /// Minutes per run (the paper: 6).
    #[arg(long, default_value_t = 6.0, value_name = "MIN")]
    pub minutes: f64,
    /// The experiment's seed; each run's simulator seed is derived from it.
    #[arg(long, default_value_t = 1, value_name = "S")]
    pub seed: u64,
    /// Results directory: absent or empty, or any with --force (default: a new
    /// results/stall-<UTC time>-seed<S>/, or results/stall-policies-…/ with --policies, and
    /// results/stall-latest or stall-policies-latest points to it). With --shard: the folder the study's
    /// shards share (default results/stall-seed<S>-shards/).
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Write into a non-empty --out (with --shard: replace this shard's file): the study replaces only the
    /// files it writes, deletes nothing, and records a run beside a folder that holds a recording already.
    #[arg(long)]
    pub force: bool,
    /// Configuration (TOML); default: the built-in config/stall.toml. Mode and seed are set per run.
    #[arg(long, short = 'c', value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Do not write per-tick recordings of the runs.
    #[arg(long)]
    pub no_record: bool,
    /// OS threads to run on (default: the number of CPUs, at most 2).
    #[arg(long, value_name = "N")]
    pub threads: Option<usize>,
    /// Compare these policies instead (interleaved in this order): reactive, pavlovian, offpolicy
    /// (Pavlovian control on an off-policy GTD(λ) prediction of the stall under π), offpolicy-stochastic
    /// (the same with a stochastic gate: π's action with probability ε where it fires); writes
    /// policies.json, policies.md and runs.csv.
    #[arg(long, value_name = "LIST")]
    pub policies: Option<String>,
    /// With --policies …,offpolicy-stochastic: the stochastic gate's ε, the probability of π's action where
    /// the prediction fires; a list runs one arm per ε (the sweep). Default 0.5.
    #[arg(long, value_name = "LIST", requires = "policies")]
    pub epsilon: Option<String>,
    /// Run only the I-th (0-based) of N disjoint slices of the planned runs and write
    /// shard-I-of-N.json into the results directory; `pavlov experiment merge` puts the shards together.
    #[arg(long, value_name = "I/N")]
    pub shard: Option<Shard>,
    /// The robustness study: the whole study (--runs, --minutes, same seeds) once per variation of the
    /// world, robot, sensing, default-policy speed, link and the 1.0 A current-limit reading, each with
    /// its source or marked an estimate (`stall::variations`); never recorded. Writes variations.md,
    /// variations.csv, variations.json and fig_variations.svg.
    #[arg(long, conflicts_with_all = ["policies", "shard"])]
    pub variations: bool,
}

fn load_config(path: Option<&PathBuf>, builtin: &str) -> Result<Config> {
    let text = match path {
        Some(p) => std::fs::read_to_string(p)
            .with_context(|| format!("cannot read configuration {}", p.display()))?,
        None => builtin.to_string(),
    };
    Config::from_toml(&text).context("invalid configuration")
}

/// Runs `pavlov experiment …`; prints the table on stdout.
pub fn run(args: ExperimentArgs) -> Result<()> {
    match args.which {
        Experiment::Merge(a) => merge(a),
        Experiment::Stall(a) => {
            check_study(a.runs, a.minutes, MAX_STALL_RUNS)?;
            let config = load_config(a.config.as_ref(), STALL_CONFIG)?;
            let threads = a.threads.unwrap_or_else(default_threads);
            let place = Placement::new(a.out.clone(), a.force);
            let mut opts = stall::StallOptions {
                runs_per_policy: a.runs,
                minutes: a.minutes,
                seed: a.seed,
                record: !a.no_record,
                threads,
                out: PathBuf::new(),
            };
            if let Some(shard) = a.shard {
                anyhow::ensure!(
                    a.policies.is_none(),
                    "--shard slices the reactive/Pavlovian study; it does not take --policies yet"
                );
                opts.out = place.shard("stall", a.seed, shard)?;
                let (path, line) = stall::sharded::run_shard(&config, &opts, shard, true)?;
                say!("{line}");
                say!("wrote {}", path.display());
                return Ok(());
            }
            if a.variations {
                let folder = place.study("stall-variations", a.seed)?;
                opts.out = folder.path.clone();
                let table = stall::variations::run_and_report(&config, &opts, true)?;
                say!("{}", table.trim_end());
                say_latest(&folder);
                return Ok(());
            }
            let policies = match &a.policies {
                Some(list) => Some(stall::policies::parse_policies(list)?),
                None => None,
            };
            let name = if policies.is_some() {
                "stall-policies"
            } else {
                "stall"
            };
            let folder = place.study(name, a.seed)?;
            opts.out = folder.path.clone();
            let epsilons = match &a.epsilon {
                Some(list) => stall::stochastic::parse_epsilons(list)?,
                None => vec![stall::stochastic::DEFAULT_EPSILON],
            };
            let table = match &policies {
                Some(policies) => {
                    stall::policies::run_and_report(&config, &opts, policies, &epsilons, true)?
                }
                None => stall::run_and_report(&config, &opts, true)?,
            };
            say!("{}", table.trim_end());
            say_latest(&folder);
            Ok(())
        }
        Experiment::Interaction(a) => {
            let config = load_config(a.config.as_ref(), INTERACTION_CONFIG)?;
            let long = a.curve || a.sensitivity;
            let (runs, minutes) = if a.curve {
                (CURVE_PAIRS, 60.0)
            } else if a.sensitivity {
                (SENSITIVITY_PAIRS, 60.0)
            } else {
                (1, 10.0)
            };
            let name = if a.sensitivity {
                "interaction-sensitivity"
            } else if a.curve {
                "interaction-curve"
            } else {
                "interaction"
            };
            let mut opts = interaction::InteractionOptions::new(
                a.seed,
                a.runs.unwrap_or(runs),
                a.minutes.unwrap_or(minutes),
                PathBuf::new(),
            );
            check_study(opts.runs_per_policy, opts.minutes, MAX_INTERACTION_RUNS)?;
            anyhow::ensure!(
                a.commands >= 1,
                "--commands must be at least 1 (the aligned averages need a command), got 0"
            );
            opts.aligned_commands = a.commands;
            opts.record = !a.no_record && !long;
            opts.threads = default_threads();
            opts.window_min = a.window;
            anyhow::ensure!(
                opts.window_min > 0.0 && opts.window_min.is_finite(),
                "--window must be a positive number of minutes"
            );
            let place = Placement::new(a.out.clone(), a.force);
            if let Some(shard) = a.shard {
                opts.out = place.shard(name, a.seed, shard)?;
                let (path, line) = interaction::sharded::run_shard(&config, &opts, shard, true)?;
                say!("{line}");
                say!("wrote {}", path.display());
                return Ok(());
            }
            let folder = place.study(name, a.seed)?;
            opts.out = folder.path.clone();
            if a.sensitivity {
                let wall = std::time::Instant::now();
                let rows = interaction::sensitivity::run_sensitivity(&config, &opts, true)?;
                let table = interaction::sensitivity::table(&rows, &opts);
                std::fs::create_dir_all(&opts.out)
                    .with_context(|| format!("cannot create {}", opts.out.display()))?;
                std::fs::write(opts.out.join("sensitivity.md"), &table)?;
                std::fs::write(
                    opts.out.join("sensitivity.csv"),
                    interaction::sensitivity::csv(&rows),
                )?;
                say!("{}", table.trim_end());
                say!(
                    "results: {} ({:.0} s wall)",
                    opts.out.display(),
                    wall.elapsed().as_secs_f64()
                );
                say_latest(&folder);
                return Ok(());
            }
            let summary = interaction::run_study_with_progress(&config, &opts, true)?;
            interaction::report::write_all(&opts.out, &summary)?;
            say!("{}", interaction::report::table(&summary).trim_end());
            say!("results: {}", opts.out.display());
            say_latest(&folder);
            Ok(())
        }
    }
}

/// Pairs of runs of the time course (`--curve`) by default: its paired intervals resample pairs, and a
/// percentile bootstrap over fewer than [`pavlov::analysis::bootstrap::FEW_PAIRS`] is too narrow.
const CURVE_PAIRS: usize = 10;
/// Pairs of runs per variant of the sensitivity table by default (eleven variants of an hour each).
const SENSITIVITY_PAIRS: usize = 3;

/// The most runs per policy a stall study takes from the command line (each is a few seconds of CPU).
const MAX_STALL_RUNS: usize = 1000;
/// The most run pairs an interaction study takes from the command line.
const MAX_INTERACTION_RUNS: usize = 100;
/// The longest run, minutes (a day).
const MAX_MINUTES: f64 = 24.0 * 60.0;

/// Refuses a study that would run nothing or forever: `--runs` from 1 to `max_runs`, `--minutes` above
/// 0 and at most a day.
fn check_study(runs: usize, minutes: f64, max_runs: usize) -> Result<()> {
    anyhow::ensure!(
        (1..=max_runs).contains(&runs),
        "--runs must be from 1 to {max_runs}, got {runs}"
    );
    anyhow::ensure!(
        minutes.is_finite() && minutes > 0.0 && minutes <= MAX_MINUTES,
        "--minutes must be above 0 and at most {MAX_MINUTES} (a day), got {minutes}"
    );
    Ok(())
}

/// `pavlov experiment merge`: finds the shard files, picks the experiment they belong to, merges.
fn merge(a: MergeArgs) -> Result<()> {
    let files = shard::shard_files(&a.dirs)?;
    let experiment = shard::experiment_of_all(&files)?;
    let place = Placement::new(a.out, a.force);
    let table = match experiment.as_str() {
        stall::sharded::EXPERIMENT => stall::sharded::merge(&files, &place)?,
        interaction::sharded::EXPERIMENT => interaction::sharded::merge(&files, &place)?,
        other => anyhow::bail!(
            "{}: shards of experiment {other:?} cannot be merged (known: {}, {})",
            files
                .first()
                .map_or_else(String::new, |f| f.display().to_string()),
            stall::sharded::EXPERIMENT,
            interaction::sharded::EXPERIMENT
        ),
    };
    say!("{}", table.trim_end());
    Ok(())
}

/// Marks a default folder as the latest of its kind, once the study is written, and says so.
fn say_latest(folder: &Folder) {
    let note = folder.finish_note();
    if !note.is_empty() {
        say!("{}", note.trim_end());
    }
}

fn default_threads() -> usize {
    std::thread::available_parallelism()
        .map_or(1, |n| n.get())
        .min(2)
}

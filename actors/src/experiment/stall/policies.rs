//! `pavlov experiment stall --policies reactive,pavlovian,offpolicy,offpolicy-stochastic`: the experiment
//! the paper's Discussion proposes — the stall study with a policy whose gate is driven by an
//! **off-policy** prediction of the stall under the default policy π (GTD(λ), `crate`'s
//! `pavlov::learn::gtd`), next to reactive control and the paper's on-policy Pavlovian control; and the
//! same with a stochastic gate that keeps taking π's action with probability ε where the prediction
//! fires ([`super::stochastic`]; `--epsilon 0.2,0.5` runs one arm per ε).
//!
//! Runs are interleaved in the order given (run i uses arm i mod k, an arm being a policy with its ε) with the stall study's seed
//! derivation ([`super::run_seed`]). Every run, whatever its policy, carries both predictions — the
//! paper's on-policy `stall` and the off-policy [`OFFPOLICY_PREDICTION`] — and only the gate's prediction
//! differs (`pavlovian`: `stall`, `offpolicy`: `stall_pi`; reactive ignores both), so each run also
//! scores both against the return π would have earned where π was followed (`super::accuracy`).
//!
//! The off-policy prediction copies the paper's stall prediction (τ, λ, α, features, θ) and adds
//! GTD(λ)'s β = α/10, a usual choice for the secondary step size, fixed before any run and not tuned.

use std::fmt::Write as _;
use std::time::Instant;

use pavlov::analysis::bootstrap::{FEW_PAIRS, RESAMPLES, ratio_of_means};
use pavlov::analysis::stats::{Describe, WelchTest, describe, relative_change, welch};
use pavlov::config::Config;
use pavlov::control::Mode;
use pavlov::learn::PredictionSpec;
use serde::{Deserialize, Serialize};

use super::analysis::{TOTALS, total};
use super::run::{self, RunResult, RunSpec};
use super::{StallOptions, WINDOW_S, run_seed};
use crate::experiment::run_all;

/// The off-policy prediction's name.
pub const OFFPOLICY_PREDICTION: &str = "stall_pi";

/// The off-policy prediction added when the configuration has none of that name: the paper's stall
/// prediction learned with GTD(λ) about "π continues" (β = α/10).
pub const OFFPOLICY_SPEC: &str = r#"
name = "stall_pi"
tau = 25.0
lambda = 0.5
alpha = 0.022727272727272728
sigma = "identity"
initial_weight = 0.0
threshold = { fixed = 0.5 }
cumulant = { stimulus = "stall" }
features = { kind = "one_dim", all_obs = true, tiles = 10 }
learner = "gtd"
target_policy = "default"
beta = 0.0022727272727272726
"#;

/// The on-policy prediction's name (the paper's).
const ONPOLICY_PREDICTION: &str = "stall";

/// A policy of the study.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum StallPolicy {
    /// The response on the stimulus alone.
    Reactive,
    /// The paper's Pavlovian control on the on-policy prediction `stall`.
    Pavlovian,
    /// Pavlovian control on the off-policy prediction `stall_pi`.
    Offpolicy,
    /// The same with the stochastic gate: π's action with probability ε where `stall_pi` fires.
    #[serde(rename = "offpolicy-stochastic")]
    OffpolicyStochastic,
}

impl StallPolicy {
    /// The name in tables and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            StallPolicy::Reactive => "reactive",
            StallPolicy::Pavlovian => "pavlovian",
            StallPolicy::Offpolicy => "offpolicy",
            StallPolicy::OffpolicyStochastic => "offpolicy-stochastic",
        }
    }

    fn mode(self) -> Mode {
        match self {
            StallPolicy::Reactive => Mode::Reactive,
            _ => Mode::Pavlovian,
        }
    }

    fn gate_prediction(self) -> &'static str {
        match self {
            StallPolicy::Offpolicy | StallPolicy::OffpolicyStochastic => OFFPOLICY_PREDICTION,
            _ => ONPOLICY_PREDICTION,
        }
    }
}

/// A bad `--policies` list.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum PoliciesError {
    /// A name that is not a policy.
    #[error(
        "--policies: unknown policy `{0}` (expected reactive, pavlovian, offpolicy or offpolicy-stochastic)"
    )]
    Unknown(String),
    /// A bad `--epsilon` list.
    #[error("--epsilon: {0}")]
    Epsilon(String),
    /// A policy named twice.
    #[error("--policies: `{0}` is named twice")]
    Twice(String),
    /// Fewer than two policies.
    #[error("--policies: name at least two policies to compare, got {0}")]
    TooFew(usize),
    /// The configuration cannot take the off-policy prediction.
    #[error("--policies: the configuration with the off-policy prediction `stall_pi`: {0}")]
    Config(String),
}

/// Parses `reactive,pavlovian,offpolicy`.
pub fn parse_policies(list: &str) -> Result<Vec<StallPolicy>, PoliciesError> {
    let mut out = Vec::new();
    for name in list.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let p = match name {
            "reactive" => StallPolicy::Reactive,
            "pavlovian" => StallPolicy::Pavlovian,
            "offpolicy" => StallPolicy::Offpolicy,
            "offpolicy-stochastic" => StallPolicy::OffpolicyStochastic,
            other => return Err(PoliciesError::Unknown(other.to_string())),
        };
        if out.contains(&p) {
            return Err(PoliciesError::Twice(name.to_string()));
        }
        out.push(p);
    }
    if out.len() < 2 {
        return Err(PoliciesError::TooFew(out.len()));
    }
    Ok(out)
}

/// One arm of the study: a policy, with its ε for `offpolicy-stochastic`.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Arm {
    /// The policy.
    pub policy: StallPolicy,
    /// The stochastic gate's ε (`offpolicy-stochastic` only).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub epsilon: Option<f64>,
}

impl Arm {
    /// The name in tables: the policy's, with `ε=…` for a stochastic gate.
    pub fn name(&self) -> String {
        match self.epsilon {
            Some(e) => format!("{} ε={e}", self.policy.name()),
            None => self.policy.name().to_string(),
        }
    }

    /// The name in a run's folder (no spaces, ASCII).
    fn folder(&self) -> String {
        match self.epsilon {
            Some(e) => format!("{}-eps{e}", self.policy.name()),
            None => self.policy.name().to_string(),
        }
    }
}

/// The arms of `policies`: one per policy, and one per ε of `epsilons` for `offpolicy-stochastic`.
pub fn arms(policies: &[StallPolicy], epsilons: &[f64]) -> Vec<Arm> {
    let mut out = Vec::new();
    for &policy in policies {
        if policy == StallPolicy::OffpolicyStochastic {
            out.extend(epsilons.iter().map(|&e| Arm {
                policy,
                epsilon: Some(e),
            }));
        } else {
            out.push(Arm {
                policy,
                epsilon: None,
            });
        }
    }
    out
}

/// `base` with the off-policy prediction added (when it has none of that name), checked.
pub fn with_offpolicy_prediction(base: &Config) -> Result<Config, PoliciesError> {
    let mut config = base.clone();
    if !config
        .predictions
        .iter()
        .any(|p| p.name == OFFPOLICY_PREDICTION)
    {
        let spec: PredictionSpec =
            toml::from_str(OFFPOLICY_SPEC).map_err(|e| PoliciesError::Config(e.to_string()))?;
        config.predictions.push(spec);
    }
    config
        .validate()
        .map_err(|e| PoliciesError::Config(e.to_string()))?;
    Ok(config)
}

/// The interleaved run list: run i uses `arms[i mod k]` and the stall study's seed for index i.
pub(crate) fn plan(config: &Config, opts: &StallOptions, arms: &[Arm]) -> Vec<(Arm, RunSpec)> {
    let period_s = config.tick.period_ms.max(1) as f64 / 1000.0;
    let ticks = (opts.minutes * 60.0 / period_s).round().max(1.0) as u64;
    let window_ticks = (WINDOW_S / period_s).round().max(1.0) as u64;
    let k = arms.len().max(1);
    (0..k * opts.runs_per_policy)
        .map(|index| {
            let arm = arms[index % k];
            let policy = arm.policy;
            let name = format!("{index:02}-{}", arm.folder());
            (
                arm,
                RunSpec {
                    index,
                    mode: policy.mode(),
                    seed: run_seed(opts.seed, index),
                    ticks,
                    window_ticks,
                    excerpt_from_tick: None,
                    excerpt_len: 0,
                    record_dir: opts.record.then(|| opts.out.join("runs").join(name)),
                    policy: arm.name(),
                    gate_prediction: Some(policy.gate_prediction().to_string()),
                    score: Some((
                        ONPOLICY_PREDICTION.to_string(),
                        OFFPOLICY_PREDICTION.to_string(),
                    )),
                    epsilon: arm.epsilon,
                },
            )
        })
        .collect()
}

/// One metric over one policy's runs.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PolicyMetric {
    /// The policy.
    pub policy: String,
    /// Mean, SD and SE over its runs.
    pub describe: Describe,
    /// Smallest and largest value.
    pub range: Option<(f64, f64)>,
}

/// One metric compared between two policies: `b` against `a`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct PairChange {
    /// The baseline policy.
    pub a: String,
    /// The policy compared with it.
    pub b: String,
    /// (mean_b − mean_a) / mean_a.
    pub relative_change: Option<f64>,
    /// 95 % bootstrap interval of the relative change.
    pub relative_change_ci: Option<(f64, f64)>,
    /// Welch's t-test of b against a.
    pub welch: Option<WelchTest>,
}

/// One metric over every policy.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct MetricRow {
    /// The metric's key ([`TOTALS`]).
    pub metric: String,
    /// Label and unit.
    pub label: String,
    /// Per policy, in the order given.
    pub policies: Vec<PolicyMetric>,
    /// Every pair (later policy against earlier one).
    pub changes: Vec<PairChange>,
}

/// The predictions' accuracy over one policy's runs (each figure: over runs).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct AccuracyRow {
    /// The policy.
    pub policy: String,
    /// Fraction of ticks on which π's command was sent.
    pub followed_fraction: Describe,
    /// Ticks scored per run (π followed until the return was known).
    pub scored_ticks: Describe,
    /// Ticks scored whose return was above 0.5, per run.
    pub near_ticks: Describe,
    /// RMSE of the on-policy prediction.
    pub on_rmse: Describe,
    /// RMSE of the off-policy prediction.
    pub off_rmse: Describe,
    /// RMSE where the return was above 0.5 (on-policy).
    pub on_rmse_near: Describe,
    /// The same for the off-policy prediction.
    pub off_rmse_near: Describe,
    /// Mean error (prediction − return), on-policy.
    pub on_bias: Describe,
    /// The same, off-policy.
    pub off_bias: Describe,
}

/// The behaviour's coverage of π in the gate region over one arm's runs (each figure: over runs; see
/// [`super::stochastic`]).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct CoverageRow {
    /// The arm.
    pub policy: String,
    /// Fraction of all ticks in the gate region.
    pub region_fraction: Describe,
    /// Fraction of the region's ticks on which π's command went out (runs with a region).
    pub coverage: Describe,
    /// Mean behaviour probability b(A|S) over the region's ticks (runs with a region).
    pub mean_b: Describe,
}

/// Everything `policies.json` holds.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct PoliciesStudy {
    /// The settings.
    pub options: StallOptions,
    /// The policies in interleaved order.
    pub policies: Vec<StallPolicy>,
    /// The arms in interleaved order (a policy with its ε).
    #[serde(default)]
    pub arms: Vec<Arm>,
    /// The behaviour's coverage of π in the gate region, per arm.
    #[serde(default)]
    pub coverage: Vec<CoverageRow>,
    /// The off-policy prediction as configured.
    pub offpolicy_prediction: Option<PredictionSpec>,
    /// Every run.
    pub runs: Vec<RunResult>,
    /// The run metrics.
    pub metrics: Vec<MetricRow>,
    /// The predictions' accuracy.
    pub accuracy: Vec<AccuracyRow>,
    /// When the response first engaged on the prediction alone, s, per policy (runs that did).
    pub first_predictive_stop_s: Vec<(String, Describe)>,
    /// Wall-clock time, s.
    pub wall_s: f64,
    /// The build and invocation that made the study, and the hash of its configuration.
    #[serde(default)]
    pub provenance: Option<crate::provenance::Provenance>,
}

fn range(xs: &[f64]) -> Option<(f64, f64)> {
    (!xs.is_empty()).then(|| {
        xs.iter()
            .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), &x| {
                (l.min(x), h.max(x))
            })
    })
}

/// The statistics of `runs` over `arms`.
pub(crate) fn analyse(
    runs: &[RunResult],
    arms: &[Arm],
) -> (Vec<MetricRow>, Vec<AccuracyRow>, Vec<(String, Describe)>) {
    let names: Vec<String> = arms.iter().map(Arm::name).collect();
    let policies = &names;
    let of = |p: &String| {
        let p = p.clone();
        runs.iter().filter(move |r| r.policy == p)
    };
    let metrics = TOTALS
        .iter()
        .map(|(key, label, unit)| {
            let values: Vec<Vec<f64>> = policies
                .iter()
                .map(|p| of(p).filter_map(|r| total(r, key)).collect())
                .collect();
            let mut changes = Vec::new();
            for i in 0..policies.len() {
                for j in i + 1..policies.len() {
                    let (a, b) = (&values[i], &values[j]);
                    let da = describe(a);
                    changes.push(PairChange {
                        a: policies[i].clone(),
                        b: policies[j].clone(),
                        relative_change: relative_change(da.mean, describe(b).mean),
                        relative_change_ci: ratio_of_means(b, a, RESAMPLES, 1)
                            .map(|r| (r.lo, r.hi)),
                        welch: welch(a, b),
                    });
                }
            }
            MetricRow {
                metric: (*key).to_string(),
                label: format!("{label} ({unit})"),
                policies: policies
                    .iter()
                    .zip(&values)
                    .map(|(p, xs)| PolicyMetric {
                        policy: p.clone(),
                        describe: describe(xs),
                        range: range(xs),
                    })
                    .collect(),
                changes,
            }
        })
        .collect();
    let accuracy = policies
        .iter()
        .map(|p| {
            let acc: Vec<_> = of(p).filter_map(|r| r.accuracy).collect();
            let d = |f: &dyn Fn(&super::accuracy::RunAccuracy) -> f64| {
                describe(
                    &acc.iter()
                        .map(f)
                        .filter(|x| x.is_finite())
                        .collect::<Vec<_>>(),
                )
            };
            let on = |a: &super::accuracy::RunAccuracy| a.on_policy;
            let off = |a: &super::accuracy::RunAccuracy| a.off_policy;
            AccuracyRow {
                policy: p.clone(),
                followed_fraction: d(&|a| a.followed_fraction),
                scored_ticks: d(&|a| a.off_policy.n as f64),
                near_ticks: d(&|a| a.off_policy.n_near as f64),
                on_rmse: d(&|a| on(a).rmse),
                off_rmse: d(&|a| off(a).rmse),
                on_rmse_near: d(&|a| on(a).rmse_near),
                off_rmse_near: d(&|a| off(a).rmse_near),
                on_bias: d(&|a| on(a).bias),
                off_bias: d(&|a| off(a).bias),
            }
        })
        .collect();
    let firsts = policies
        .iter()
        .map(|p| {
            let xs: Vec<f64> = of(p).filter_map(|r| r.first_predictive_stop_s).collect();
            (p.clone(), describe(&xs))
        })
        .collect();
    (metrics, accuracy, firsts)
}

/// The coverage of π in the gate region over each arm's runs.
pub(crate) fn coverage(runs: &[RunResult], arms: &[Arm]) -> Vec<CoverageRow> {
    arms.iter()
        .map(|arm| {
            let name = arm.name();
            let cov: Vec<_> = runs
                .iter()
                .filter(|r| r.policy == name)
                .filter_map(|r| r.coverage)
                .collect();
            let with_region: Vec<_> = cov.iter().filter(|c| c.region_ticks > 0).collect();
            CoverageRow {
                policy: name,
                region_fraction: describe(
                    &cov.iter().map(|c| c.region_fraction()).collect::<Vec<_>>(),
                ),
                coverage: describe(
                    &with_region
                        .iter()
                        .filter_map(|c| c.coverage())
                        .collect::<Vec<_>>(),
                ),
                mean_b: describe(
                    &with_region
                        .iter()
                        .map(|c| c.region_b_sum / c.region_ticks as f64)
                        .collect::<Vec<_>>(),
                ),
            }
        })
        .collect()
}

/// Runs the study and returns it.
pub fn run_study(
    base: &Config,
    opts: &StallOptions,
    policies: &[StallPolicy],
    epsilons: &[f64],
    progress: bool,
) -> anyhow::Result<PoliciesStudy> {
    let wall = Instant::now();
    let config = with_offpolicy_prediction(base)?;
    let arms = arms(policies, epsilons);
    // Every stochastic arm's configuration is checked before any run (the step-size bound at load).
    for arm in &arms {
        if let Some(eps) = arm.epsilon {
            super::stochastic::with_stochastic_gate(&config, eps)?;
        }
    }
    let planned = plan(&config, opts, &arms);
    let specs: Vec<RunSpec> = planned.iter().map(|(_, s)| s.clone()).collect();
    let bar = crate::experiment::progress_bar(specs.len(), progress);
    let on_done = |r: &RunResult| {
        bar.inc(1);
        bar.set_message(format!(
            "run {} {}: {} over-current",
            r.index, r.policy, r.metrics.overcurrent_observations
        ));
    };
    let runs = run_all(
        &specs,
        opts.threads,
        &|spec| run::run(&config, spec),
        &on_done,
    )?;
    bar.finish_and_clear();
    let (metrics, accuracy, first_predictive_stop_s) = analyse(&runs, &arms);
    let coverage = coverage(&runs, &arms);
    Ok(PoliciesStudy {
        options: opts.clone(),
        policies: policies.to_vec(),
        arms,
        coverage,
        offpolicy_prediction: config
            .predictions
            .iter()
            .find(|p| p.name == OFFPOLICY_PREDICTION)
            .cloned(),
        runs,
        metrics,
        accuracy,
        first_predictive_stop_s,
        wall_s: wall.elapsed().as_secs_f64(),
        provenance: Some(crate::provenance::Provenance::of(&config)),
    })
}

fn fmt(x: f64) -> String {
    crate::experiment::tables::num(x)
}

fn pct(x: Option<f64>) -> String {
    x.map_or("–".into(), |v| format!("{:+.1} %", 100.0 * v))
}

fn p_value(w: Option<WelchTest>) -> String {
    w.map_or("–".into(), |w| {
        if w.p < 1e-3 {
            format!("p = {:.0e}", w.p)
        } else {
            format!("p = {:.3}", w.p)
        }
    })
}

/// A mean ± SE, or the value with "n = 1: no spread".
fn mean_se(d: Describe) -> String {
    match d.n {
        0 => "–".into(),
        1 => format!("{} (n = 1: no spread)", fmt(d.mean)),
        _ => format!("{} ± {}", fmt(d.mean), fmt(d.se)),
    }
}

/// The Markdown tables: the metrics (mean ± SE, spread SD [min – max], every pair's change with its 95 %
/// bootstrap interval and Welch's p) and the predictions' accuracy.
pub fn table(study: &PoliciesStudy) -> String {
    let mut s = String::new();
    let names: Vec<String> = if study.arms.is_empty() {
        study
            .policies
            .iter()
            .map(|p| p.name().to_string())
            .collect()
    } else {
        study.arms.iter().map(Arm::name).collect()
    };
    // More than four arms (an ε sweep): the Markdown shows the changes against Pavlovian control only;
    // table.csv and policies.json hold every pair.
    let shown = |c: &PairChange| names.len() <= 4 || c.a == StallPolicy::Pavlovian.name();
    let _ = writeln!(
        s,
        "{} policies × {} runs × {} min, seed {}; mean ± SE over runs; spread = SD [min – max]; \
         change = mean(b) / mean(a) − 1 with the 95 % percentile bootstrap of that ratio (runs resampled within each \
         policy), then Welch's p; {:.1} s of wall time\n",
        names.len(),
        study.options.runs_per_policy,
        study.options.minutes,
        study.options.seed,
        study.wall_s
    );
    let _ = write!(s, "| metric |");
    for n in &names {
        let _ = write!(s, " {n} |");
    }
    if let Some(row) = study.metrics.first() {
        for c in row.changes.iter().filter(|c| shown(c)) {
            let _ = write!(s, " {} vs {} |", c.b, c.a);
        }
    }
    let _ = writeln!(s);
    let cols = names.len()
        + study
            .metrics
            .first()
            .map_or(0, |r| r.changes.iter().filter(|c| shown(c)).count());
    let _ = writeln!(s, "|---|{}", "---|".repeat(cols));
    for row in &study.metrics {
        let _ = write!(s, "| {} |", row.label);
        for p in &row.policies {
            let _ = write!(
                s,
                " {} <br>SD {} [{} – {}] |",
                mean_se(p.describe),
                fmt(p.describe.sd),
                p.range.map_or("–".into(), |r| fmt(r.0)),
                p.range.map_or("–".into(), |r| fmt(r.1)),
            );
        }
        for c in row.changes.iter().filter(|c| shown(c)) {
            let ci = match c.relative_change_ci {
                Some((lo, hi)) if lo.is_finite() && hi.is_finite() => {
                    format!("({:+.1}, {:+.1})", 100.0 * lo, 100.0 * hi)
                }
                Some(_) => "(n = 1: no spread)".into(),
                None => "–".into(),
            };
            let _ = write!(
                s,
                " {} {ci}, {} |",
                pct(c.relative_change),
                p_value(c.welch)
            );
        }
        let _ = writeln!(s);
    }
    if (2..FEW_PAIRS).contains(&study.options.runs_per_policy) {
        let _ = writeln!(
            s,
            "\n{} runs per policy are too few for a reliable bootstrap interval (it comes out too narrow).",
            study.options.runs_per_policy
        );
    }
    let _ = writeln!(
        s,
        "\nAccuracy of both predictions on the same ticks against the same target: the return π would have earned, \
         on ticks where π was followed until that return was known and both predictions had a value (mean ± SE over \
         runs). What it shows: how far each prediction is from π's return on those ticks. What it does not show: in \
         reactive runs both predictions are on-policy in effect, so their difference is TD(λ) against GTD(λ) on \
         identical targets (two algorithms, not on- against off-policy learning); in gated runs the scored ticks are \
         those the gating prediction left ungated, selected by its own values, not a random sample.\n"
    );
    let _ = writeln!(
        s,
        "| policy | ticks with π's command | ticks scored / with G > 0.5 | RMSE on-policy `stall` | RMSE off-policy `stall_pi` | RMSE where G > 0.5: on / off | bias (v − G): on / off |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|");
    let pm = mean_se;
    for a in &study.accuracy {
        let _ = writeln!(
            s,
            "| {} | {:.1} % | {} / {} | {} | {} | {} / {} | {} / {} |",
            a.policy,
            100.0 * a.followed_fraction.mean,
            fmt(a.scored_ticks.mean),
            fmt(a.near_ticks.mean),
            pm(a.on_rmse),
            pm(a.off_rmse),
            pm(a.on_rmse_near),
            pm(a.off_rmse_near),
            pm(a.on_bias),
            pm(a.off_bias),
        );
    }
    let _ = writeln!(s);
    coverage_table(&mut s, study);
    sweep_table(&mut s, study);
    for (p, d) in &study.first_predictive_stop_s {
        if d.n > 0 {
            let _ = writeln!(
                s,
                "first stop on the prediction alone, {p}: {} s ({} runs)",
                mean_se(*d),
                d.n
            );
        }
    }
    let _ = writeln!(s, "\n{}", crate::experiment::design_notes::stall());
    s
}

/// The behaviour's coverage of π in the gate region, per arm.
fn coverage_table(s: &mut String, study: &PoliciesStudy) {
    if study.coverage.is_empty() {
        return;
    }
    let _ = writeln!(
        s,
        "Coverage of π in the gate region: the ticks on which a prediction's rule engaged the mixing function \
         while the stimulus was off; coverage = the fraction of them on which π's command went out; b = the \
         behaviour probability of the command there (mean ± SE over runs; runs without such ticks are left out \
         of the last two columns).\n"
    );
    let _ = writeln!(
        s,
        "| policy | ticks in the gate region | coverage of π there | mean b there |"
    );
    let _ = writeln!(s, "|---|---|---|---|");
    let pc = |d: Describe| match d.n {
        0 => "–".to_string(),
        _ => format!("{:.1} ± {:.1} %", 100.0 * d.mean, 100.0 * d.se),
    };
    for c in &study.coverage {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} |",
            c.policy,
            pc(c.region_fraction),
            pc(c.coverage),
            match c.mean_b.n {
                0 => "–".to_string(),
                _ => format!("{:.3}", c.mean_b.mean),
            },
        );
    }
    let _ = writeln!(s);
}

/// The change of `metric` of arm `b` against arm `a`, as `+x % (lo, hi)`.
fn change_cell(study: &PoliciesStudy, metric: &str, a: &str, b: &str) -> String {
    study
        .metrics
        .iter()
        .find(|r| r.metric == metric)
        .and_then(|r| r.changes.iter().find(|c| c.a == a && c.b == b))
        .map_or("–".into(), |c| match c.relative_change_ci {
            Some((lo, hi)) if lo.is_finite() && hi.is_finite() => format!(
                "{} ({:+.1}, {:+.1})",
                pct(c.relative_change),
                100.0 * lo,
                100.0 * hi
            ),
            _ => pct(c.relative_change),
        })
}

/// The ε sweep, when the study has more than one stochastic arm: the main metrics of each against
/// Pavlovian control, with its coverage.
fn sweep_table(s: &mut String, study: &PoliciesStudy) {
    let stochastic: Vec<String> = study
        .arms
        .iter()
        .filter(|a| a.epsilon.is_some())
        .map(Arm::name)
        .collect();
    let base = StallPolicy::Pavlovian.name();
    if stochastic.len() < 2
        || !study
            .arms
            .iter()
            .any(|a| a.policy == StallPolicy::Pavlovian)
    {
        return;
    }
    let _ = writeln!(
        s,
        "The ε sweep against Pavlovian control (change = mean(arm) / mean(pavlovian) − 1 with its 95 % \
         bootstrap interval):\n"
    );
    let _ = writeln!(
        s,
        "| arm | over-current observations | vs pavlovian | stall events vs pavlovian | distance (m) | \
         efficiency (m/kJ) | vs pavlovian | coverage of π in the gate region |"
    );
    let _ = writeln!(s, "|---|---|---|---|---|---|---|---|");
    let mean = |metric: &str, arm: &str| {
        study
            .metrics
            .iter()
            .find(|r| r.metric == metric)
            .and_then(|r| r.policies.iter().find(|p| p.policy == arm))
            .map_or("–".into(), |p| mean_se(p.describe))
    };
    let mut rows = vec![base.to_string()];
    if study
        .arms
        .iter()
        .any(|a| a.policy == StallPolicy::Offpolicy)
    {
        rows.push(StallPolicy::Offpolicy.name().to_string());
    }
    rows.extend(stochastic);
    for arm in &rows {
        let cov = study
            .coverage
            .iter()
            .find(|c| &c.policy == arm)
            .map_or("–".into(), |c| match c.coverage.n {
                0 => "–".to_string(),
                _ => format!("{:.1} %", 100.0 * c.coverage.mean),
            });
        let vs = |metric: &str| {
            if arm == base {
                "–".to_string()
            } else {
                change_cell(study, metric, base, arm)
            }
        };
        let _ = writeln!(
            s,
            "| {arm} | {} | {} | {} | {} | {} | {} | {cov} |",
            mean("overcurrent_observations", arm),
            vs("overcurrent_observations"),
            vs("stall_events"),
            mean("distance_m", arm),
            mean("efficiency_m_per_kj", arm),
            vs("efficiency_m_per_kj"),
        );
    }
    let _ = writeln!(s);
}

/// Runs the study, writes `policies.{json,md}`, `table.{md,csv}` and `runs.csv` into `opts.out`, and returns the
/// tables.
pub fn run_and_report(
    base: &Config,
    opts: &StallOptions,
    policies: &[StallPolicy],
    epsilons: &[f64],
    progress: bool,
) -> anyhow::Result<String> {
    let study = run_study(base, opts, policies, epsilons, progress)?;
    std::fs::create_dir_all(&opts.out)?;
    std::fs::write(
        opts.out.join("policies.json"),
        serde_json::to_string_pretty(&study)?,
    )?;
    let mut t = table(&study);
    std::fs::write(opts.out.join("policies.md"), &t)?;
    crate::experiment::tables::write_policies(&opts.out, &study, &t)?;
    std::fs::write(
        opts.out.join("runs.csv"),
        super::report::runs_csv(&study.runs),
    )?;
    t.push_str(&format!("results: {}\n", opts.out.display()));
    Ok(t)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn policy_lists_are_parsed_with_precise_errors() {
        assert_eq!(
            parse_policies("reactive,pavlovian,offpolicy").unwrap(),
            vec![
                StallPolicy::Reactive,
                StallPolicy::Pavlovian,
                StallPolicy::Offpolicy
            ]
        );
        assert_eq!(
            parse_policies("reactive, greedy").unwrap_err().to_string(),
            "--policies: unknown policy `greedy` (expected reactive, pavlovian, offpolicy or offpolicy-stochastic)"
        );
        assert_eq!(
            parse_policies("pavlovian,offpolicy-stochastic").unwrap(),
            vec![StallPolicy::Pavlovian, StallPolicy::OffpolicyStochastic]
        );
        assert_eq!(
            parse_policies("offpolicy,offpolicy"),
            Err(PoliciesError::Twice("offpolicy".into()))
        );
        assert_eq!(parse_policies("offpolicy"), Err(PoliciesError::TooFew(1)));
    }

    #[test]
    fn each_policy_gates_on_its_own_prediction_even_with_a_rule_table() {
        let base = Config::from_toml(include_str!("../../../../config/rules.toml")).unwrap();
        let config = with_offpolicy_prediction(&base).unwrap();
        let opts = StallOptions {
            runs_per_policy: 1,
            minutes: 0.1,
            seed: 1,
            record: false,
            threads: 1,
            out: "x".into(),
        };
        let p = plan(
            &config,
            &opts,
            &arms(&[StallPolicy::Pavlovian, StallPolicy::Offpolicy], &[]),
        );
        let off = super::super::run::config_for(&config, &p[1].1);
        let table = off.rule_table();
        assert_eq!(table.len(), 1, "the base's two rules are replaced");
        assert_eq!(off.predictions[table[0].prediction].name, "stall_pi");
        assert_eq!(table[0].response, off.control.response);
        // Without a named prediction the base's rule table stands.
        let mut spec = p[0].1.clone();
        spec.gate_prediction = None;
        assert_eq!(
            super::super::run::config_for(&config, &spec)
                .rule_table()
                .len(),
            2
        );
    }

    #[test]
    fn the_plan_interleaves_and_only_the_gate_prediction_differs() {
        let config = with_offpolicy_prediction(
            &Config::from_toml(include_str!("../../../../config/stall.toml")).unwrap(),
        )
        .unwrap();
        assert_eq!(config.predictions.len(), 2);
        let again = with_offpolicy_prediction(&config).unwrap();
        assert_eq!(again.predictions.len(), 2, "not added twice");
        let opts = StallOptions {
            runs_per_policy: 2,
            minutes: 0.1,
            seed: 1,
            record: false,
            threads: 1,
            out: "x".into(),
        };
        let all = [
            StallPolicy::Reactive,
            StallPolicy::Pavlovian,
            StallPolicy::Offpolicy,
        ];
        let p = plan(&config, &opts, &arms(&all, &[]));
        let names: Vec<&str> = p.iter().map(|(p, _)| p.policy.name()).collect();
        assert_eq!(
            names,
            [
                "reactive",
                "pavlovian",
                "offpolicy",
                "reactive",
                "pavlovian",
                "offpolicy"
            ]
        );
        assert_eq!(p[2].1.gate_prediction.as_deref(), Some("stall_pi"));
        assert_eq!(p[1].1.gate_prediction.as_deref(), Some("stall"));
        assert_eq!(
            (p[2].1.mode, p[0].1.mode),
            (Mode::Pavlovian, Mode::Reactive)
        );
        // The stall study's seed derivation.
        assert_eq!(p[4].1.seed, run_seed(1, 4));
    }

    #[test]
    fn an_epsilon_sweep_gives_one_stochastic_arm_per_epsilon() {
        let all = [
            StallPolicy::Reactive,
            StallPolicy::OffpolicyStochastic,
            StallPolicy::Pavlovian,
        ];
        let a = arms(&all, &[0.2, 0.5]);
        let names: Vec<String> = a.iter().map(Arm::name).collect();
        assert_eq!(
            names,
            [
                "reactive",
                "offpolicy-stochastic ε=0.2",
                "offpolicy-stochastic ε=0.5",
                "pavlovian"
            ]
        );
        let config = with_offpolicy_prediction(
            &Config::from_toml(include_str!("../../../../config/stall.toml")).unwrap(),
        )
        .unwrap();
        let opts = StallOptions {
            runs_per_policy: 2,
            minutes: 0.1,
            seed: 1,
            record: true,
            threads: 1,
            out: "x".into(),
        };
        let p = plan(&config, &opts, &a);
        assert_eq!(p.len(), 8);
        assert_eq!(
            (p[1].1.epsilon, p[2].1.epsilon, p[3].1.epsilon),
            (Some(0.2), Some(0.5), None)
        );
        assert_eq!(p[5].1.policy, "offpolicy-stochastic ε=0.2");
        assert_eq!(p[2].1.gate_prediction.as_deref(), Some("stall_pi"));
        assert_eq!(
            p[1].1.record_dir.as_deref(),
            Some(std::path::Path::new(
                "x/runs/01-offpolicy-stochastic-eps0.2"
            ))
        );
        // The run's configuration has the gate and the bound's α; it loads.
        let c = super::super::run::config_for(&config, &p[1].1);
        assert_eq!(c.control.epsilon, Some(0.2));
        assert_eq!(c.predictions[1].alpha, 0.2 * config.predictions[1].alpha);
        c.validate().unwrap();
    }
}

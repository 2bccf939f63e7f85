//! `pavlov experiment interaction --learners paper,xent,linear,true_online,autostep`: the interaction study
//! once per named learner (`pavlov::learn::named`), every learner on the same operators — the same seeds, so
//! pair k of every learner answers the same simulated operator, in both its reactive and its Pavlovian run —
//! and the operator model untouched. Only the prediction's learner changes ([`variant`]): `paper` is the
//! configuration as given (config/interaction.toml), `xent` and `autostep` keep its σ, initial weight, α and
//! features, `linear` and `true_online` take σ = identity and initial weights 0 (config/interaction-linear.toml).
//!
//! Each run is lean (`InteractionOptions::lean`): its ticks are reduced to response and physical samples as
//! they arrive and to the run's timeline when it ends, so memory is one run's samples per thread plus the
//! timelines (a few hundred commands a run), whatever the number of learners.
//!
//! [`metrics`] reduces each learner's runs to its row (what the row's figures are, and the rule for
//! "anticipation holds", are stated there), [`table`] writes the tables, `plot` the figure of the lead
//! against commands.

pub mod metrics;
pub(crate) mod plot;
pub mod table;

use pavlov::analysis::interaction::curve::RunTimeline;
use pavlov::config::Config;
use pavlov::learn::{LearnerKind, Sigma};

use super::{InteractionOptions, plan, run_runs};
use crate::experiment::runner::RunError;
pub use metrics::LearnerRow;

/// The learners `--learners` runs when given `all`.
pub const DEFAULT_LEARNERS: [LearnerKind; 5] = [
    LearnerKind::Td,
    LearnerKind::Xent,
    LearnerKind::Linear,
    LearnerKind::TrueOnline,
    LearnerKind::Autostep,
];

/// Parses `paper,xent,…` (or `all`): on-policy learners only, each once.
pub fn parse_learners(text: &str) -> Result<Vec<LearnerKind>, String> {
    if text.trim() == "all" {
        return Ok(DEFAULT_LEARNERS.to_vec());
    }
    let mut out: Vec<LearnerKind> = Vec::new();
    for name in text.split(',').map(str::trim).filter(|s| !s.is_empty()) {
        let kind = LearnerKind::from_name(name)
            .filter(|k| DEFAULT_LEARNERS.contains(k))
            .ok_or_else(|| {
                format!(
                    "unknown learner `{name}` (one of {}, or all)",
                    DEFAULT_LEARNERS.map(LearnerKind::name).join(", ")
                )
            })?;
        if out.contains(&kind) {
            return Err(format!("learner `{name}` is listed twice"));
        }
        out.push(kind);
    }
    if out.is_empty() {
        return Err("--learners needs at least one learner".into());
    }
    Ok(out)
}

/// `base` with every prediction's learner set to `kind` (see the module documentation).
pub fn variant(base: &Config, kind: LearnerKind) -> Config {
    let mut config = base.clone();
    for p in &mut config.predictions {
        if kind == LearnerKind::Td {
            continue;
        }
        p.learner = kind;
        if matches!(kind, LearnerKind::Linear | LearnerKind::TrueOnline) {
            p.sigma = Sigma::Identity;
            p.initial_weight = 0.0;
        }
    }
    config
}

/// One learner's runs, reduced to their timelines (in planned order: pair k is runs 2k, 2k + 1).
#[derive(Debug, Clone)]
pub struct LearnerRuns {
    /// The learner.
    pub learner: LearnerKind,
    /// Every run's timeline.
    pub timelines: Vec<RunTimeline>,
}

/// Runs the study for every learner of `learners` with `o`'s pairs, minutes and seed.
pub fn run_learners(
    base: &Config,
    o: &InteractionOptions,
    learners: &[LearnerKind],
    progress: bool,
) -> Result<Vec<LearnerRuns>, RunError> {
    let mut opts = o.clone();
    opts.lean = true;
    opts.record = false;
    let mut out = Vec::with_capacity(learners.len());
    for &kind in learners {
        let config = variant(base, kind);
        config
            .validate()
            .map_err(|e| RunError::Collector(format!("learner {}: {e}", kind.name())))?;
        if progress {
            eprintln!("learner: {}", kind.name());
        }
        let runs = run_runs(&config, &opts, plan(&opts), progress)?;
        out.push(LearnerRuns {
            learner: kind,
            timelines: runs.into_iter().map(|r| r.timeline).collect(),
        });
    }
    Ok(out)
}

/// Runs every learner of `learners`, then writes `learners.md`, `learners.csv`, `learners.json` and
/// `fig_learners.{svg,png}` into `o.out`; returns the rows.
pub fn run_and_report(
    base: &Config,
    o: &InteractionOptions,
    learners: &[LearnerKind],
    progress: bool,
) -> Result<Vec<LearnerRow>, ReportError> {
    let runs = run_learners(base, o, learners, progress)?;
    let rows: Vec<LearnerRow> = runs
        .iter()
        .map(|r| metrics::row(r.learner.name(), &r.timelines, o.seed))
        .collect();
    std::fs::create_dir_all(&o.out)?;
    std::fs::write(o.out.join("learners.md"), table::markdown(&rows, o))?;
    std::fs::write(o.out.join("learners.csv"), table::csv(&rows))?;
    let json = serde_json::to_string_pretty(&rows).map_err(std::io::Error::other)?;
    std::fs::write(o.out.join("learners.json"), json)?;
    plot::fig_learners(&o.out, &rows, o.runs_per_policy, o.minutes)?;
    Ok(rows)
}

/// Why `--learners` failed.
#[derive(Debug, thiserror::Error)]
pub enum ReportError {
    /// A run failed.
    #[error(transparent)]
    Run(#[from] RunError),
    /// A file could not be written.
    #[error("cannot write the learners' results: {0}")]
    Io(#[from] std::io::Error),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn learners_parse_by_name_and_variants_change_only_the_learner() {
        assert_eq!(parse_learners("all").unwrap(), DEFAULT_LEARNERS.to_vec());
        assert_eq!(
            parse_learners("paper, xent").unwrap(),
            vec![LearnerKind::Td, LearnerKind::Xent]
        );
        assert!(parse_learners("paper,paper").is_err());
        assert!(
            parse_learners("gtd").is_err(),
            "off-policy is not a learner here"
        );
        assert!(parse_learners("").is_err());
        let base =
            Config::from_toml(include_str!("../../../../../config/interaction.toml")).unwrap();
        let linear_file = Config::from_toml(include_str!(
            "../../../../../config/interaction-linear.toml"
        ))
        .unwrap();
        assert_eq!(variant(&base, LearnerKind::Td), base);
        for kind in DEFAULT_LEARNERS {
            let v = variant(&base, kind);
            v.validate().unwrap();
            let (p, b) = (&v.predictions[0], &base.predictions[0]);
            assert_eq!(p.learner, kind);
            assert_eq!(
                (p.alpha, p.lambda, &p.features),
                (b.alpha, b.lambda, &b.features)
            );
            assert_eq!(v.control, base.control);
        }
        let linear = &variant(&base, LearnerKind::Linear).predictions[0];
        let file = &linear_file.predictions[0];
        assert_eq!(
            (linear.sigma, linear.initial_weight),
            (file.sigma, file.initial_weight)
        );
        let xent = &variant(&base, LearnerKind::Xent).predictions[0];
        assert_eq!(
            (xent.sigma, xent.initial_weight),
            (Sigma::Logistic, -1.0),
            "xent keeps σ and w₀"
        );
    }
}

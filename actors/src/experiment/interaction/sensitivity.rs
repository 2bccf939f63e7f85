//! `pavlov experiment interaction --sensitivity`: how the time course depends on the operator (commands per
//! minute, how long the arm is held, how cleanly it is tracked) and on the learner (α, the initial weight,
//! σ), one whole study per variant, every variant on the same seeds. Each row says whether its learner is the
//! paper's: the operator is not described in the paper, so operator variants keep the paper's learner, while
//! every learner change is labelled non-paper.
//!
//! Per variant: the commands per minute the operator actually gave, the first 3 minutes (the paper's
//! "less than 3 minutes": decision lead and anticipated excess over the reactive baseline), when anticipation
//! holds ([`pavlov::analysis::interaction::curve::holds_from`]), the last window's decision and current leads,
//! and the Pavlovian false starts per minute.

use std::fmt::Write as _;

use pavlov::analysis::bootstrap::MeanDifference;
use pavlov::analysis::interaction::curve::curve;
use pavlov::config::Config;
use pavlov::learn::Sigma;
use pavlov::sim::human::HumanParams;
use serde::Serialize;

use super::{InteractionOptions, run_study_with_progress};
use crate::experiment::runner::RunError;

/// One variant of the study.
#[derive(Debug, Clone)]
pub(crate) struct Variant {
    /// What changes.
    pub(crate) name: String,
    /// Whether the learner is the paper's.
    pub(crate) paper_learner: bool,
    /// The configuration.
    pub(crate) config: Config,
    /// The operator.
    pub(crate) human: HumanParams,
}

/// The variants over `base` (the paper's configuration).
pub(crate) fn variants(base: &Config) -> Vec<Variant> {
    let operator = |name: &str, f: fn(&mut HumanParams)| {
        let mut human = HumanParams::default();
        f(&mut human);
        Variant {
            name: name.into(),
            paper_learner: true,
            config: base.clone(),
            human,
        }
    };
    let learner = |name: &str, f: fn(&mut pavlov::learn::PredictionSpec)| {
        let mut config = base.clone();
        config.predictions.iter_mut().for_each(f);
        Variant {
            name: name.into(),
            paper_learner: false,
            config,
            human: HumanParams::default(),
        }
    };
    vec![
        operator("paper learner, default operator", |_| {}),
        operator("operator: frequent commands (gaps 1 s + 0.5 s mean)", |h| {
            h.gap_min_s = 1.0;
            h.gap_extra_mean_s = 0.5;
        }),
        operator("operator: rare commands (gaps 2.5 s + 10 s mean)", |h| {
            h.gap_extra_mean_s = 10.0;
        }),
        operator("operator: long hold (2–3 s)", |h| h.hold_s = [2.0, 3.0]),
        operator("operator: short hold (0.2–0.4 s)", |h| {
            h.hold_s = [0.2, 0.4]
        }),
        operator("operator: clean tracking (no noise, no dropouts)", |h| {
            h.noise_sd_mm = [0.0; 3];
            h.arm_drop_rate = 0.0;
            h.body_drop_rate = 0.0;
        }),
        operator("operator: noisy tracking (2× noise, 2× dropouts)", |h| {
            h.noise_sd_mm = h.noise_sd_mm.map(|x| 2.0 * x);
            h.arm_drop_rate *= 2.0;
            h.body_drop_rate *= 2.0;
        }),
        learner("α × 5 (0.1)", |p| p.alpha *= 5.0),
        learner("initial weight −0.5 (σ(−2.5) ≈ 0.08)", |p| {
            p.initial_weight = -0.5
        }),
        learner("initial weight 0 (σ(0) = 0.5)", |p| p.initial_weight = 0.0),
        learner("σ identity, initial weight 0 (linear TD)", |p| {
            p.sigma = Sigma::Identity;
            p.initial_weight = 0.0;
        }),
    ]
}

/// One variant's outcome.
#[derive(Debug, Clone, Serialize)]
pub struct SensitivityRow {
    /// What changes.
    pub name: String,
    /// "paper" or "non-paper" (the learner).
    pub learner: String,
    /// Commands per minute the operator gave (over the Pavlovian runs).
    pub commands_per_minute: f64,
    /// Decision lead over the first 3 minutes, ms (reactive − Pavlovian).
    pub first_3_min_decision_lead: Option<MeanDifference>,
    /// Anticipated excess over the first 3 minutes.
    pub first_3_min_anticipated_excess: Option<MeanDifference>,
    /// Minutes from which anticipation holds (`None`: never in the runs).
    pub holds_from_min: Option<f64>,
    /// Decision lead in the last window, ms.
    pub last_decision_lead: Option<MeanDifference>,
    /// Current lead in the last window, ms.
    pub last_current_lead: Option<MeanDifference>,
    /// Pavlovian false starts per minute over the whole runs.
    pub false_starts_per_minute: f64,
}

/// Runs every variant with `o`'s runs, minutes and seed.
pub fn run_sensitivity(
    base: &Config,
    o: &InteractionOptions,
    progress: bool,
) -> Result<Vec<SensitivityRow>, RunError> {
    let mut rows = Vec::new();
    for v in variants(base) {
        if let Err(e) = v.human.validate() {
            return Err(RunError::Collector(format!("variant {}: {e}", v.name)));
        }
        if progress {
            eprintln!("variant: {}", v.name);
        }
        let mut opts = o.clone();
        opts.human = v.human.clone();
        opts.record = false;
        let study = run_study_with_progress(&v.config, &opts, progress)?;
        let timelines: Vec<_> = study.runs.iter().map(|r| r.timeline.clone()).collect();
        let first = curve(&timelines, 3.0, o.seed).into_iter().next();
        let last = study.curve.last();
        let pav = study.timing.iter().find(|t| t.policy == "pavlovian");
        let minutes = o.minutes * o.runs_per_policy as f64;
        rows.push(SensitivityRow {
            name: v.name,
            learner: if v.paper_learner {
                "paper"
            } else {
                "non-paper"
            }
            .into(),
            commands_per_minute: pav.map_or(f64::NAN, |t| t.commands as f64 / minutes.max(1e-9)),
            first_3_min_decision_lead: first.as_ref().and_then(|p| p.decision_lead),
            first_3_min_anticipated_excess: first.as_ref().and_then(|p| p.anticipated_difference),
            holds_from_min: study
                .holds_from_window
                .and_then(|w| study.curve.get(w))
                .map(|p| p.from_min),
            last_decision_lead: last.and_then(|p| p.decision_lead),
            last_current_lead: last.and_then(|p| p.current_lead),
            false_starts_per_minute: pav.map_or(f64::NAN, |t| t.false_starts_per_minute),
        });
    }
    Ok(rows)
}

fn ci(d: Option<MeanDifference>, scale: f64) -> String {
    d.map_or("–".into(), |d| {
        format!(
            "{:+.0} [{:+.0}, {:+.0}]",
            d.difference * scale,
            d.lo * scale,
            d.hi * scale
        )
    })
}

/// The sensitivity table (Markdown, as `docs/src/results.md` shows it).
pub fn table(rows: &[SensitivityRow], o: &InteractionOptions) -> String {
    let mut t = String::new();
    let _ = writeln!(
        t,
        "Sensitivity: {} run(s) per policy × {} min per variant, seed {}; leads = reactive − Pavlovian onset, ms \
         [95 % CI]; excess = Pavlovian − reactive anticipated fraction, pp; holds = first minute from which the \
         decision lead stays above 0 ({}-min windows)\n",
        o.runs_per_policy, o.minutes, o.seed, o.window_min
    );
    let _ = writeln!(
        t,
        "| variant | learner | commands/min | 0–3 min: decision lead | 0–3 min: excess | holds from | last window: decision lead | last window: current lead | false starts/min |"
    );
    let _ = writeln!(t, "|---|---|---|---|---|---|---|---|---|");
    for r in rows {
        let _ = writeln!(
            t,
            "| {} | {} | {:.1} | {} | {} | {} | {} | {} | {:.2} |",
            r.name,
            r.learner,
            r.commands_per_minute,
            ci(r.first_3_min_decision_lead, 1.0),
            ci(r.first_3_min_anticipated_excess, 100.0),
            r.holds_from_min
                .map_or("never".into(), |m| format!("{m:.0} min")),
            ci(r.last_decision_lead, 1.0),
            ci(r.last_current_lead, 1.0),
            r.false_starts_per_minute
        );
    }
    t
}

/// `sensitivity.csv`.
pub fn csv(rows: &[SensitivityRow]) -> String {
    let d = |x: Option<MeanDifference>| {
        x.map_or(",,".to_string(), |x| {
            format!("{},{},{}", x.difference, x.lo, x.hi)
        })
    };
    let mut c = String::from(
        "variant,learner,commands_per_minute,first3_decision_lead_ms,lo,hi,first3_excess,lo,hi,holds_from_min,\
         last_decision_lead_ms,lo,hi,last_current_lead_ms,lo,hi,false_starts_per_minute\n",
    );
    for r in rows {
        let _ = writeln!(
            c,
            "\"{}\",{},{},{},{},{},{},{},{}",
            r.name.replace('"', "'"),
            r.learner,
            r.commands_per_minute,
            d(r.first_3_min_decision_lead),
            d(r.first_3_min_anticipated_excess),
            r.holds_from_min.map_or(String::new(), |m| m.to_string()),
            d(r.last_decision_lead),
            d(r.last_current_lead),
            r.false_starts_per_minute
        );
    }
    c
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_learner_change_is_labelled_non_paper_and_every_operator_is_valid() {
        let base = Config::from_toml(include_str!("../../../../config/interaction.toml")).unwrap();
        let vs = variants(&base);
        assert!(vs.len() >= 10);
        for v in &vs {
            assert_eq!(v.human.validate(), Ok(()), "{}", v.name);
            let p = &v.config.predictions[0];
            let b = &base.predictions[0];
            let same_learner =
                p.alpha == b.alpha && p.initial_weight == b.initial_weight && p.sigma == b.sigma;
            assert_eq!(v.paper_learner, same_learner, "{}", v.name);
        }
        assert_eq!(vs[0].human, HumanParams::default());
    }
}

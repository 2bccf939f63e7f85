//! `pavlov replay DIR`: runs a recording back through the core's learning, gating and safety stages and
//! checks that they reproduce the recorded stimulus, predictions, gate, safety stop and command exactly.
//!
//! Each record carries the learning stage's exact inputs ([`pavlov::record::TickInputs`]: the raw sensor
//! snapshot and the forced-stimulus flag; the elbow features are the record's `elbow` angles). Mode
//! changes and the e-stop are taken from the records. The safety stop and the command are checked on
//! every tick with the same predicate actuation used ([`pavlov::agent::safety`]); only a manual-mode
//! command that no safety stop overrode is not compared (teleop is not in the record). What replay cannot
//! reproduce yet: learning-parameter commands and weight resets during the run, and ticks the runtime
//! dropped between learning and actuation (the first such gap shows up as a mismatch, and is reported as
//! a gap in `seq`).

use pavlov::agent::{GatingStage, LearnInput, LearningStage, safety};
use pavlov::control::{Action, Mode};
use pavlov::skeleton::ElbowFeatures;
use serde::Serialize;

use crate::storage::recording::Recording;

/// One difference between the recording and the replay.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Mismatch {
    /// The tick.
    pub seq: u64,
    /// Which field.
    pub field: String,
    /// What the recording says.
    pub(crate) recorded: String,
    /// What replay computed.
    pub(crate) replayed: String,
}

/// The outcome of a replay.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct ReplayReport {
    /// Records replayed.
    pub ticks: usize,
    /// Prediction values compared.
    pub(crate) predictions_compared: usize,
    /// Safety stops compared (every tick).
    pub stops_compared: usize,
    /// Commands compared (every tick but manual-mode ticks without a safety stop).
    pub commands_compared: usize,
    /// Ticks where `seq` jumped (records missing from the recording).
    pub(crate) seq_gaps: usize,
    /// Total mismatching fields.
    pub mismatch_count: usize,
    /// The first few mismatches.
    pub mismatches: Vec<Mismatch>,
}

impl ReplayReport {
    /// True when everything compared was identical.
    pub fn exact(&self) -> bool {
        self.mismatch_count == 0
    }
}

/// Why replay could not run.
#[derive(Debug, thiserror::Error)]
pub enum ReplayError {
    /// The recorded configuration does not build a learning stage.
    #[error("the recording's configuration: {0}")]
    Config(String),
    /// A record lacks the inputs replay needs (recorded by an older version).
    #[error("record {0} has no replay inputs (recorded by an older version?)")]
    NoInputs(u64),
}

/// How many mismatches are kept in the report.
pub(crate) const KEEP_MISMATCHES: usize = 20;

impl ReplayReport {
    fn note(&mut self, seq: u64, field: &str, recorded: String, replayed: String) {
        self.mismatch_count += 1;
        if self.mismatches.len() < KEEP_MISMATCHES {
            self.mismatches.push(Mismatch {
                seq,
                field: field.to_string(),
                recorded,
                replayed,
            });
        }
    }
}

/// Replays `rec`.
pub fn replay(rec: &Recording) -> Result<ReplayReport, ReplayError> {
    let config = &rec.header.config;
    let mut learning =
        LearningStage::new(config).map_err(|e| ReplayError::Config(e.to_string()))?;
    let mut gating = GatingStage::new(
        config.control.mode,
        config.control.default_policy,
        config.control.response,
    );
    let mut estop = false;
    let mut report = ReplayReport::default();
    let mut last_seq: Option<u64> = None;
    for r in &rec.records {
        let inputs = r.inputs.as_ref().ok_or(ReplayError::NoInputs(r.seq))?;
        if last_seq.is_some_and(|s| r.seq != s + 1) {
            report.seq_gaps += 1;
        }
        last_seq = Some(r.seq);
        if gating.mode() != r.mode {
            gating.set_mode(r.mode);
        }
        if estop != r.estop {
            estop = r.estop;
            gating.set_estop(estop);
        }
        let elbow = r.elbow.as_ref().map(|e| ElbowFeatures {
            left: e.left,
            left_avg: e.left_avg,
            right: e.right,
            right_avg: e.right_avg,
            command: false,
            skeleton: e.skeleton,
        });
        let out = learning.act(LearnInput {
            values: inputs.values.as_ref(),
            elbow,
            forced_stimulus: inputs.forced_stimulus,
        });
        // The same rule as the learning actor: a stale observation is acted on but not learned from.
        if safety::observation_is_fresh(
            r.link.state,
            r.obs_age_ticks,
            config.safety.max_obs_age_ticks,
        ) && let Err(e) = learning.learn()
        {
            return Err(ReplayError::Config(e.to_string()));
        }
        report.ticks += 1;
        if out.stimulus != r.stimulus {
            report.note(
                r.seq,
                "stimulus",
                r.stimulus.to_string(),
                out.stimulus.to_string(),
            );
        }
        if out.predictions.len() != r.predictions.len() {
            report.note(
                r.seq,
                "predictions",
                format!("{} predictions", r.predictions.len()),
                format!("{} predictions", out.predictions.len()),
            );
        }
        for (a, b) in r.predictions.iter().zip(&out.predictions) {
            report.predictions_compared += 1;
            if a.value.to_bits() != b.value.to_bits()
                || a.threshold.to_bits() != b.threshold.to_bits()
            {
                report.note(
                    r.seq,
                    &format!("prediction {}", a.name),
                    format!("{} (θ {})", a.value, a.threshold),
                    format!("{} (θ {})", b.value, b.threshold),
                );
            }
        }
        let g = gating.decide(r.seq, out.stimulus, out.gate_value, out.gate_threshold);
        if g.gate != r.gate {
            report.note(r.seq, "gate", r.gate.to_string(), g.gate.to_string());
        }
        if g.default_action != r.default_action {
            report.note(
                r.seq,
                "default_action",
                fmt_action(r.default_action),
                fmt_action(g.default_action),
            );
        }
        let stop = safety::stop_reason(
            r.estop,
            r.link.state,
            r.obs_age_ticks,
            config.safety.max_obs_age_ticks,
        );
        report.stops_compared += 1;
        if stop != r.safety_stop {
            report.note(
                r.seq,
                "safety_stop",
                format!("{:?}", r.safety_stop),
                format!("{stop:?}"),
            );
        }
        let command = if stop.is_some() {
            Action::STOP
        } else {
            g.action
        };
        if stop.is_some() || r.mode != Mode::Manual {
            report.commands_compared += 1;
            if command != r.command {
                report.note(r.seq, "command", fmt_action(r.command), fmt_action(command));
            }
        }
    }
    Ok(report)
}

fn fmt_action(a: Action) -> String {
    format!("({}, {})", a.left_mm_s, a.right_mm_s)
}

/// The report as text for the terminal.
pub fn describe(report: &ReplayReport) -> String {
    let mut s = format!(
        "replayed {} ticks: {} prediction values, {} safety stops and {} commands compared, {} seq gaps: ",
        report.ticks,
        report.predictions_compared,
        report.stops_compared,
        report.commands_compared,
        report.seq_gaps
    );
    if report.exact() {
        s.push_str("identical");
    } else {
        s.push_str(&format!("{} mismatches", report.mismatch_count));
        for m in &report.mismatches {
            s.push_str(&format!(
                "\n  tick {}: {}: recorded {}, replayed {}",
                m.seq, m.field, m.recorded, m.replayed
            ));
        }
    }
    s
}

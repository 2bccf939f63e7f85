//! `pavlov replay DIR`: runs a recording back through the core's learning, gating and safety stages and
//! checks that they reproduce the recorded stimulus, predictions, gate, the rule that engaged it, safety
//! stop, command and behaviour probability b exactly (a stochastic gate's draws come from the recorded
//! configuration's seed and the tick, `pavlov::agent::stochastic_gate`).
//!
//! The learner starts from the state the recording began with (its header's [`StartState`]: weights,
//! traces, parameters in force, the stall detector — so a recording made after `--resume` or started from
//! the dashboard mid-run replays too). Each record carries the learning stage's exact inputs
//! ([`pavlov::record::TickInputs`]: the raw sensor snapshot and the forced-stimulus flag; the elbow features
//! are the record's `elbow` angles). The recording's events are applied where they took effect: learning
//! parameters and weight resets before the learning step after their tick, mode changes and teleop before
//! the gating step after theirs. The e-stop and the mode are also taken from the records. The safety stop
//! and the command are checked on every tick with the same predicate actuation used
//! ([`pavlov::agent::safety`]), as is the rule that engaged the gate (`[[rules]]`; except in recordings
//! made before the rule table, which engaged the gate without naming one); a manual-mode command is compared once the teleop state is known (from the
//! start of the run, or half a second into the recording, when any teleop from before it has expired).
//! What replay cannot reproduce: ticks the runtime dropped between learning and actuation (the first such
//! gap shows up as a mismatch, and is reported as a gap in `seq`).

use std::collections::VecDeque;

use pavlov::agent::gating::TELEOP_HOLD_TICKS;
use pavlov::agent::{GatingStage, LearnInput, LearningStage, safety};
use pavlov::control::{Action, Mode};
use pavlov::event::{Event, EventKind, GatingChange, LearningChange};
use pavlov::skeleton::ElbowFeatures;
use serde::Serialize;

use crate::storage::recording::{Recording, StartState};

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
    /// Ticks whose `rule` (what engaged the gate) was compared: every tick, unless the recording
    /// predates the rule table (it engaged the gate on some tick but names no rule anywhere).
    pub rules_compared: usize,
    /// Behaviour probabilities b(A|S) compared (every tick; the stochastic gate's draws are the run's
    /// seed's and the tick's, so they replay exactly).
    pub behaviour_compared: usize,
    /// Ticks where `seq` jumped (records missing from the recording).
    pub seq_gaps: usize,
    /// Every event the recording holds (what `pavlov convert` counts too).
    pub events: usize,
    /// Of those, the events applied to learning or gating (the others, e.g. a recording started, change
    /// nothing replay computes).
    pub events_applied: usize,
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
        config.rule_table(),
    )
    .with_stochastic_gate(pavlov::agent::StochasticGate::from_config(config));
    let start: Option<&StartState> = rec.header.start.as_ref();
    if let Some(start) = start {
        learning
            .restore_stage(&start.learner)
            .map_err(|e| ReplayError::Config(format!("the recording's start state: {e}")))?;
    }
    let mut learning_events = queue(&rec.events, EventKind::changes_learning);
    let mut gating_events = queue(&rec.events, EventKind::changes_gating);
    // Manual commands follow teleop, which expires; before the recording it is unknown.
    let manual_known_from = match (start.map(|s| s.after), rec.records.first()) {
        (Some(Some(_)), Some(first)) => first.seq + TELEOP_HOLD_TICKS + 1,
        _ => 0,
    };
    // A recording made before the rule table engaged the gate without naming a rule.
    let compare_rules =
        rec.records.iter().any(|r| r.rule.is_some()) || !rec.records.iter().any(|r| r.gate);
    let mut estop = false;
    let mut report = ReplayReport {
        events: rec.events.len(),
        ..ReplayReport::default()
    };
    let mut last_seq: Option<u64> = None;
    for r in &rec.records {
        let inputs = r.inputs.as_ref().ok_or(ReplayError::NoInputs(r.seq))?;
        if last_seq.is_some_and(|s| r.seq != s + 1) {
            report.seq_gaps += 1;
        }
        last_seq = Some(r.seq);
        for e in due(&mut learning_events, r.seq) {
            report.events_applied += 1;
            apply_to_learning(&mut learning, &e.kind)?;
        }
        for e in due(&mut gating_events, r.seq) {
            report.events_applied += 1;
            apply_to_gating(&mut gating, e);
        }
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
            previous_followed_default: inputs.previous_followed_default,
            previous_behaviour_prob: inputs.previous_behaviour_prob,
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
        let g = gating.decide(r.seq, out.stimulus, &out.gate_inputs);
        if g.gate != r.gate {
            report.note(r.seq, "gate", r.gate.to_string(), g.gate.to_string());
        }
        if compare_rules {
            report.rules_compared += 1;
        }
        if compare_rules && g.rule.as_deref() != r.rule.as_deref() {
            report.note(
                r.seq,
                "rule",
                format!("{:?}", r.rule),
                format!("{:?}", g.rule.as_deref()),
            );
        }
        // b of the command: a safety stop overrides the gate with certainty (as actuation records it).
        let behaviour_prob = if r.safety_stop.is_some() {
            1.0
        } else {
            g.behaviour_prob
        };
        report.behaviour_compared += 1;
        if behaviour_prob.to_bits() != r.behaviour_prob.to_bits() {
            report.note(
                r.seq,
                "behaviour_prob",
                r.behaviour_prob.to_string(),
                behaviour_prob.to_string(),
            );
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
        if stop.is_some() || r.mode != Mode::Manual || r.seq >= manual_known_from {
            report.commands_compared += 1;
            if command != r.command {
                report.note(r.seq, "command", fmt_action(r.command), fmt_action(command));
            }
        }
    }
    Ok(report)
}

/// The events `wanted` keeps, in the order they were made.
fn queue(events: &[Event], wanted: fn(&EventKind) -> bool) -> VecDeque<&Event> {
    let mut q: Vec<&Event> = events.iter().filter(|e| wanted(&e.kind)).collect();
    q.sort_by_key(|e| e.id);
    q.into()
}

/// The queued events that took effect before tick `seq` (after an earlier tick, or before the first).
fn due<'a>(q: &mut VecDeque<&'a Event>, seq: u64) -> Vec<&'a Event> {
    let mut out = Vec::new();
    while let Some(e) = q.front().copied() {
        if e.after.is_some_and(|a| a >= seq) {
            break;
        }
        out.push(e);
        q.pop_front();
    }
    out
}

/// Applies what `kind` changes in learning (see [`EventKind::effects`]; nothing for other kinds).
fn apply_to_learning(learning: &mut LearningStage, kind: &EventKind) -> Result<(), ReplayError> {
    match kind.effects().learning {
        Some(LearningChange::Params {
            prediction,
            alpha,
            lambda,
            threshold,
        }) => learning
            .set_params(Some(prediction), Some(alpha), Some(lambda), Some(threshold))
            .map(|_| ())
            .map_err(|e| ReplayError::Config(format!("a recorded params_set: {e}"))),
        Some(LearningChange::Reset) => {
            learning.reset();
            Ok(())
        }
        None => Ok(()),
    }
}

/// Applies what `event` changes in gating (see [`EventKind::effects`]; nothing for other kinds).
fn apply_to_gating(gating: &mut GatingStage, event: &Event) {
    match event.kind.effects().gating {
        Some(GatingChange::Mode(mode)) => gating.set_mode(mode),
        Some(GatingChange::Teleop(action)) => {
            // Refused teleop is not recorded, so this one was accepted then and is now.
            let _ = gating.teleop(action, event.after.unwrap_or(0));
        }
        None => {}
    }
}

fn fmt_action(a: Action) -> String {
    format!("({}, {})", a.left_mm_s, a.right_mm_s)
}

/// The report as text for the terminal.
pub fn describe(report: &ReplayReport) -> String {
    let mut s = format!(
        "replayed {} ticks and {} events ({} applied to learning or gating): {} prediction values, {} safety stops, {} commands and {} behaviour probabilities compared, {} seq gaps: ",
        report.ticks,
        report.events,
        report.events_applied,
        report.predictions_compared,
        report.stops_compared,
        report.commands_compared,
        report.behaviour_compared,
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

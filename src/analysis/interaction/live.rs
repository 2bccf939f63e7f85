//! Live interaction metrics for the dashboard: fed one tick at a time, with no ground truth, it takes the
//! observed stimulus E as the command and the gate (the fixed response ϱ selected) as the response.
//!
//! Definitions (window `W` = [`LIVE_WINDOW_MS`], 1 s either side of a command onset):
//! - A *command onset* is a rising edge of the stimulus; a *response onset* a rising edge of the gate (the first
//!   tick counts as an edge when it is on).
//! - A command's response is the first response onset in `[onset − W, onset + W]` not already taken by an
//!   earlier command. Its *lead* is the command onset minus the response onset, ms: positive = the gate engaged
//!   before the stimulus (anticipation, the point of Pavlovian control), negative = after. A command is
//!   *answered early* when its lead is positive. A command with no response onset in its window is *missed*
//!   (a new command onset ends the wait for the previous one).
//! - A *false start* is a response onset in no command's window: no command onset within `W` after it, and
//!   none within `W` before it (a late response answers a command, it does not start falsely).
//!
//! A lead is known up to `W` after its command onset, a false start `W` after the response onset.

use std::collections::VecDeque;

use serde::Serialize;

use super::live_physical::LivePhysical;
use crate::record::TickRecord;

pub use super::{LIVE_WINDOW_MS, RECENT_COMMANDS};

/// The figures so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct LiveInteractionFigures {
    /// Command onsets seen.
    pub commands: u64,
    /// Commands whose response onset came before the command onset.
    pub early: u64,
    /// Commands with no response onset in their window.
    pub missed: u64,
    /// Response onsets in no command's window.
    pub false_starts: u64,
    /// Lead of the latest answered command, ms (`None` before any).
    pub last_lead_ms: Option<f64>,
    /// Mean lead of the answered commands among the last [`RECENT_COMMANDS`] resolved ones, ms.
    pub mean_lead_ms: Option<f64>,
    /// Mean lead of the battery current's drop over the last [`RECENT_COMMANDS`] commands, ms (positive =
    /// before the stimulus; [`super::live_physical`]); only from [`LiveInteraction::observe`].
    pub mean_current_lead_ms: Option<f64>,
    /// Mean lead of the wheels' motion onset, the same way, ms.
    pub mean_motion_lead_ms: Option<f64>,
}

/// The live tracker.
#[derive(Debug, Clone, Default)]
pub struct LiveInteraction {
    previous: Option<(bool, bool)>,
    last_command_ms: Option<f64>,
    awaiting_command_ms: Option<f64>,
    unmatched_responses_ms: VecDeque<f64>,
    recent_leads: VecDeque<Option<f64>>,
    figures: LiveInteractionFigures,
    physical: LivePhysical,
}

impl LiveInteraction {
    /// A tracker that has seen nothing.
    pub fn new() -> Self {
        Self::default()
    }

    /// Feeds one tick record.
    pub fn observe(&mut self, record: &TickRecord) {
        self.observe_tick(record.t_ms, record.stimulus, record.gate);
        self.physical.observe(record);
    }

    /// Feeds one tick: its time (ms, non-decreasing), the stimulus and the gate.
    pub fn observe_tick(&mut self, t_ms: f64, stimulus: bool, gate: bool) {
        let (was_stimulus, was_gate) = self.previous.unwrap_or((false, false));
        self.previous = Some((stimulus, gate));
        self.expire(t_ms);
        if stimulus && !was_stimulus {
            self.on_command(t_ms);
        }
        if gate && !was_gate {
            self.on_response(t_ms);
        }
    }

    /// The figures so far.
    pub fn figures(&self) -> LiveInteractionFigures {
        LiveInteractionFigures {
            mean_current_lead_ms: self.physical.mean_current_lead_ms(),
            mean_motion_lead_ms: self.physical.mean_motion_lead_ms(),
            ..self.figures
        }
    }

    fn expire(&mut self, t_ms: f64) {
        while let Some(&r) = self.unmatched_responses_ms.front() {
            if r >= t_ms - LIVE_WINDOW_MS {
                break;
            }
            self.unmatched_responses_ms.pop_front();
            self.figures.false_starts += 1;
        }
        if let Some(c) = self.awaiting_command_ms
            && t_ms > c + LIVE_WINDOW_MS
        {
            self.resolve(None);
        }
    }

    fn on_command(&mut self, t_ms: f64) {
        if self.awaiting_command_ms.is_some() {
            self.resolve(None);
        }
        self.figures.commands += 1;
        self.last_command_ms = Some(t_ms);
        // Every unmatched response onset is within the window now (older ones expired): the first answers
        // this command, the rest fall in its window and are no false starts.
        let first = self.unmatched_responses_ms.front().copied();
        self.unmatched_responses_ms.clear();
        match first {
            Some(r) => {
                self.awaiting_command_ms = Some(t_ms);
                self.resolve(Some(t_ms - r));
            }
            None => self.awaiting_command_ms = Some(t_ms),
        }
    }

    fn on_response(&mut self, t_ms: f64) {
        if let Some(c) = self.awaiting_command_ms {
            self.resolve(Some(c - t_ms));
        } else if self
            .last_command_ms
            .is_none_or(|c| t_ms - c > LIVE_WINDOW_MS)
        {
            self.unmatched_responses_ms.push_back(t_ms);
        }
    }

    /// Ends the wait for the awaited command: answered with `lead_ms`, or missed.
    fn resolve(&mut self, lead_ms: Option<f64>) {
        self.awaiting_command_ms = None;
        match lead_ms {
            Some(lead) => {
                self.figures.last_lead_ms = Some(lead);
                if lead > 0.0 {
                    self.figures.early += 1;
                }
            }
            None => self.figures.missed += 1,
        }
        if self.recent_leads.len() == RECENT_COMMANDS {
            self.recent_leads.pop_front();
        }
        self.recent_leads.push_back(lead_ms);
        let answered: Vec<f64> = self.recent_leads.iter().flatten().copied().collect();
        self.figures.mean_lead_ms =
            (!answered.is_empty()).then(|| answered.iter().sum::<f64>() / answered.len() as f64);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const TICK_MS: f64 = 20.0;

    /// Feeds ticks `0..ticks`; the stimulus and the gate are on over the given half-open tick spans.
    fn run(ticks: u64, stimulus: &[(u64, u64)], gate: &[(u64, u64)]) -> LiveInteractionFigures {
        let on = |spans: &[(u64, u64)], k: u64| spans.iter().any(|&(a, b)| (a..b).contains(&k));
        let mut live = LiveInteraction::new();
        for k in 0..ticks {
            live.observe_tick(k as f64 * TICK_MS, on(stimulus, k), on(gate, k));
        }
        live.figures()
    }

    #[test]
    fn a_gate_engaged_before_the_stimulus_answers_early_with_a_positive_lead() {
        // Gate from tick 90 (1.8 s), stimulus from tick 100 (2 s): lead 200 ms.
        let s = run(200, &[(100, 130)], &[(90, 140)]);
        assert_eq!(
            (s.commands, s.early, s.missed, s.false_starts),
            (1, 1, 0, 0)
        );
        assert_eq!(s.last_lead_ms, Some(200.0));
        assert_eq!(s.mean_lead_ms, Some(200.0));
    }

    #[test]
    fn a_gate_engaged_after_the_stimulus_is_a_late_answer_not_a_false_start() {
        let s = run(300, &[(100, 130)], &[(115, 140)]);
        assert_eq!(
            (s.commands, s.early, s.missed, s.false_starts),
            (1, 0, 0, 0)
        );
        assert_eq!(s.last_lead_ms, Some(-300.0));
    }

    #[test]
    fn gate_and_stimulus_on_the_same_tick_lead_zero_and_are_not_early() {
        let s = run(200, &[(100, 130)], &[(100, 130)]);
        assert_eq!((s.commands, s.early, s.false_starts), (1, 0, 0));
        assert_eq!(s.last_lead_ms, Some(0.0));
    }

    #[test]
    fn a_gate_with_no_command_within_a_second_is_a_false_start_and_a_command_without_gate_is_missed()
     {
        // Gate at 0.4 s, command at 2 s (1.6 s later): a false start, then a missed command.
        let s = run(400, &[(100, 130)], &[(20, 30)]);
        assert_eq!((s.commands, s.missed, s.false_starts), (1, 1, 1));
        assert_eq!((s.last_lead_ms, s.mean_lead_ms), (None, None));
        // Just inside the window (1 s before): an early answer instead.
        let s = run(400, &[(100, 130)], &[(50, 60)]);
        assert_eq!(
            (s.commands, s.early, s.missed, s.false_starts),
            (1, 1, 0, 0)
        );
        assert_eq!(s.last_lead_ms, Some(1000.0));
    }

    #[test]
    fn a_gate_onset_is_judged_only_once_its_window_has_passed() {
        let mut live = LiveInteraction::new();
        live.observe_tick(0.0, false, true);
        live.observe_tick(500.0, false, false);
        assert_eq!(live.figures().false_starts, 0, "a command may still come");
        live.observe_tick(1001.0, false, false);
        assert_eq!(live.figures().false_starts, 1);
    }

    #[test]
    fn extra_gate_onsets_inside_a_window_count_once() {
        // Two gate onsets before the command and a flicker after it: one early answer, no false starts.
        let s = run(300, &[(100, 130)], &[(70, 75), (90, 95), (110, 112)]);
        assert_eq!((s.commands, s.early, s.false_starts), (1, 1, 0));
        assert_eq!(s.last_lead_ms, Some(600.0), "the first onset answers");
    }

    #[test]
    fn the_mean_lead_covers_the_last_forty_commands() {
        let mut live = LiveInteraction::new();
        let mut t = 0.0;
        // 10 commands answered 300 ms late, then 40 answered 100 ms early, one every 5 s.
        for (n, lead) in [(10, -300.0), (40, 100.0)] {
            for _ in 0..n {
                let command = t + 1000.0;
                let response = command - lead;
                live.observe_tick(t, false, false);
                live.observe_tick(
                    command.min(response),
                    command <= response,
                    response <= command,
                );
                live.observe_tick(command.max(response), true, true);
                live.observe_tick(t + 2500.0, false, false);
                t += 5000.0;
            }
            assert_eq!(live.figures().mean_lead_ms, Some(lead));
        }
        let s = live.figures();
        assert_eq!(
            (s.commands, s.early, s.missed, s.false_starts),
            (50, 40, 0, 0)
        );
    }
}

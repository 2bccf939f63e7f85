//! Live interaction metrics for the dashboard: fed one tick at a time, with no ground truth, it takes the
//! observed stimulus E as the command and the gate (the fixed response ϱ selected) as the response.
//!
//! Definitions (window `W` = [`LIVE_WINDOW_MS`], 1 s either side of a command onset):
//! - A *command onset* is a debounced onset of the stimulus ([`super::debounce::COMMAND`]: the stimulus was off
//!   for more than a second before, so a flickering gesture is one command); a *response onset* a debounced
//!   onset of the gate ([`super::debounce::RESPONSE`]: held for 100 ms, so a one-tick blip is no response). A
//!   response onset is known 100 ms after it, and is then judged with its own time.
//! - A command's response is the first response onset in `[onset − W, onset + W]` not already taken by an
//!   earlier command. Its *lead* is the command onset minus the response onset, ms: positive = the gate engaged
//!   before the stimulus (anticipation, the point of Pavlovian control), negative = after. A command is
//!   *answered early* when its lead is positive. A command with no response onset in its window is *missed*
//!   (a new command onset ends the wait for the previous one).
//! - A *false start* is a response onset in no command's window: no command onset within `W` after it, and
//!   no stimulus within `W` before it (a late response answers a command, and a response restarting with a
//!   command's flickering stimulus belongs to that command; neither starts falsely).
//!
//! A lead is known up to `W` after its command onset, a false start `W` after the response onset.

use std::collections::VecDeque;

use serde::Serialize;

use super::debounce::{COMMAND, Debouncer, RESPONSE};
use super::live_physical::LivePhysical;
use crate::record::TickRecord;

pub use super::{LIVE_WINDOW_MS, RECENT_COMMANDS};

/// The figures so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Serialize)]
pub struct LiveInteractionFigures {
    /// Command onsets seen (debounced).
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
#[derive(Debug, Clone)]
pub struct LiveInteraction {
    commands: Debouncer,
    responses: Debouncer,
    last_stimulus_ms: Option<f64>,
    awaiting_command_ms: Option<f64>,
    unmatched_responses_ms: VecDeque<f64>,
    recent_leads: VecDeque<Option<f64>>,
    figures: LiveInteractionFigures,
    physical: LivePhysical,
}

impl Default for LiveInteraction {
    fn default() -> Self {
        Self::new()
    }
}

impl LiveInteraction {
    /// A tracker that has seen nothing, for 20 ms ticks.
    pub fn new() -> Self {
        Self::with_period(20.0)
    }

    /// A tracker that has seen nothing, for ticks `period_ms` apart.
    pub fn with_period(period_ms: f64) -> Self {
        LiveInteraction {
            commands: Debouncer::new(COMMAND, period_ms),
            responses: Debouncer::new(RESPONSE, period_ms),
            last_stimulus_ms: None,
            awaiting_command_ms: None,
            unmatched_responses_ms: VecDeque::new(),
            recent_leads: VecDeque::new(),
            figures: LiveInteractionFigures::default(),
            physical: LivePhysical::with_period(period_ms),
        }
    }

    /// Feeds one tick record.
    pub fn observe(&mut self, record: &TickRecord) {
        self.observe_tick(record.t_ms, record.stimulus, record.gate);
        self.physical.observe(record);
    }

    /// Feeds one tick: its time (ms, non-decreasing), the stimulus and the gate.
    pub fn observe_tick(&mut self, t_ms: f64, stimulus: bool, gate: bool) {
        self.expire(t_ms);
        if stimulus {
            self.last_stimulus_ms = Some(t_ms);
        }
        let response = self.responses.step(t_ms, gate);
        if let Some(onset) = self.commands.step(t_ms, stimulus) {
            self.on_command(onset);
        }
        if let Some(onset) = response {
            self.on_response(onset);
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
            .last_stimulus_ms
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
        for k in 0..50 {
            live.observe_tick(k as f64 * TICK_MS, false, k < 10);
        }
        assert_eq!(live.figures().false_starts, 0, "a command may still come");
        live.observe_tick(1001.0, false, false);
        assert_eq!(live.figures().false_starts, 1);
    }

    #[test]
    fn a_flickering_stimulus_is_one_command_and_a_gate_blip_is_no_response() {
        // The stimulus flickers (dropouts, noise around 90°) within one gesture: one command. A one-tick
        // gate blip 3 s later is neither a response nor a false start.
        let s = run(
            400,
            &[(100, 103), (105, 120), (122, 130), (140, 141), (170, 178)],
            &[(100, 130), (170, 178), (250, 251)],
        );
        assert_eq!(
            (s.commands, s.early, s.missed, s.false_starts),
            (1, 0, 0, 0)
        );
        assert_eq!(s.last_lead_ms, Some(0.0));
        // The gate restarting with the flicker at 3.4 s (1.4 s after the onset) belongs to the command.
        // Without debouncing these were five commands and a false start.
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
        // One command every 5 s (250 ticks), the stimulus on for 30 ticks from tick 50 of each period: 10
        // answered 300 ms late (15 ticks), then 40 answered 100 ms early (5 ticks).
        let mut live = LiveInteraction::new();
        let mut k0 = 0u64;
        for (n, lead_ticks) in [(10i64, -15i64), (40, 5)] {
            for _ in 0..n {
                let command = 50i64;
                let response = command - lead_ticks;
                for k in 0..250i64 {
                    let stimulus = (command..command + 30).contains(&k);
                    let gate = (response..response + 30).contains(&k);
                    live.observe_tick((k0 as i64 + k) as f64 * TICK_MS, stimulus, gate);
                }
                k0 += 250;
            }
            assert_eq!(
                live.figures().mean_lead_ms,
                Some(lead_ticks as f64 * TICK_MS)
            );
        }
        let s = live.figures();
        assert_eq!(
            (s.commands, s.early, s.missed, s.false_starts),
            (50, 40, 0, 0)
        );
    }
}

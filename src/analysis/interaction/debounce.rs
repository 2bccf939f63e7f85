//! Debounced onsets of an on/off signal (the gate, the stimulus), so that a one-tick blip is not a response
//! and a flickering stimulus is one command, not several.
//!
//! An *episode* is a run of "on" ticks in which no "off" gap lasts longer than `merge_gap_ms` (a gap of that
//! length or shorter is bridged). An episode counts once it has lasted `min_hold_ms` (from its first on tick
//! to the end of its latest on tick, one tick period each); its *onset* is its first on tick.
//!
//! The two settings the analyses use, and why:
//! - [`RESPONSE`] (the gate, the fixed response ϱ): hold 100 ms, merge 100 ms. A response shorter than
//!   100 ms ends before the robot's battery current has even begun to change (about 0.1 s after a command,
//!   the paper and `sim::params`), so it moves nothing; a gap under 100 ms is too short for the wheels to
//!   stop, so the response goes on.
//! - [`COMMAND`] (the observed stimulus E): hold one tick, merge 1 s. A new command needs the stimulus off
//!   for more than a second first: joint dropouts (a few frames) and sensor noise around 90° make E flicker
//!   within a gesture, while the simulated operator leaves at least 2.5 s between gestures
//!   (`sim::human::HumanParams::gap_min_s`). Without this the dashboard counted 18 commands where 9 were sent.
//!
//! [`onsets`] works on a whole series; [`Debouncer`] is the same rule one tick at a time (for the live
//! figures): it reports an onset once its episode has lasted `min_hold_ms`, with the onset's own time.

use serde::Serialize;

use super::ResponseSample;

/// How an on/off signal is debounced.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct Debounce {
    /// Off gaps of at most this length are bridged, ms.
    pub merge_gap_ms: f64,
    /// An episode counts once it has lasted this long, ms (one tick always suffices for 0).
    pub min_hold_ms: f64,
}

/// The gate's response onsets (see the module documentation).
pub const RESPONSE: Debounce = Debounce {
    merge_gap_ms: 100.0,
    min_hold_ms: 100.0,
};

/// The observed stimulus's command onsets (see the module documentation).
pub const COMMAND: Debounce = Debounce {
    merge_gap_ms: 1000.0,
    min_hold_ms: 0.0,
};

/// No debouncing: every rising edge is an onset.
pub const NONE: Debounce = Debounce {
    merge_gap_ms: 0.0,
    min_hold_ms: 0.0,
};

/// The streaming form: feed ticks in time order, get each onset once its episode has lasted long enough.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Debouncer {
    params: Debounce,
    period_ms: f64,
    /// The current episode: (first on tick, latest on tick, already reported).
    episode: Option<(f64, f64, bool)>,
}

impl Debouncer {
    /// A debouncer for ticks `period_ms` apart (an on tick lasts one period).
    pub fn new(params: Debounce, period_ms: f64) -> Self {
        Debouncer {
            params,
            period_ms: period_ms.max(0.0),
            episode: None,
        }
    }

    /// Feeds one tick; returns the time of an onset confirmed on this tick.
    pub fn step(&mut self, t_ms: f64, on: bool) -> Option<f64> {
        if !on {
            return None;
        }
        let continues = self.episode.is_some_and(|(_, last, _)| {
            // The off gap between the latest on tick's end and this tick.
            t_ms - (last + self.period_ms) <= self.params.merge_gap_ms + 1e-9
        });
        let (start, _, reported) = match self.episode {
            Some(e) if continues => e,
            _ => (t_ms, t_ms, false),
        };
        let held = t_ms + self.period_ms - start;
        let confirm = !reported && held + 1e-9 >= self.params.min_hold_ms;
        self.episode = Some((start, t_ms, reported || confirm));
        confirm.then_some(start)
    }
}

/// The debounced onsets of a whole series, ms, in time order (`samples` in time order, evenly spaced; the
/// period is taken from the first two samples).
pub fn onsets(samples: &[ResponseSample], params: &Debounce) -> Vec<f64> {
    let period = match samples {
        [a, b, ..] => (b.t_ms - a.t_ms).max(0.0),
        _ => 0.0,
    };
    let mut d = Debouncer::new(*params, period);
    samples
        .iter()
        .filter_map(|s| d.step(s.t_ms, s.responding))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 20 ms ticks `0..n`, on inside the half-open tick spans.
    fn ticks(n: u64, on: &[(u64, u64)]) -> Vec<ResponseSample> {
        (0..n)
            .map(|k| ResponseSample {
                t_ms: k as f64 * 20.0,
                responding: on.iter().any(|&(a, b)| (a..b).contains(&k)),
            })
            .collect()
    }

    #[test]
    fn a_one_tick_blip_is_no_response_and_a_held_response_is() {
        let s = ticks(100, &[(10, 11), (40, 44), (60, 65)]);
        // 1 tick and 4 ticks (80 ms) are too short; 5 ticks (100 ms) count.
        assert_eq!(onsets(&s, &RESPONSE), vec![1200.0]);
        assert_eq!(onsets(&s, &NONE), vec![200.0, 800.0, 1200.0]);
    }

    #[test]
    fn short_gaps_are_bridged_and_the_onset_is_the_first_on_tick() {
        // 3 on, 2 off (40 ms), 10 on: one episode from tick 10.
        let s = ticks(100, &[(10, 13), (15, 25)]);
        assert_eq!(onsets(&s, &RESPONSE), vec![200.0]);
        // A 6-tick gap (120 ms) is not bridged: two onsets.
        let s = ticks(100, &[(10, 20), (26, 40)]);
        assert_eq!(onsets(&s, &RESPONSE), vec![200.0, 520.0]);
    }

    #[test]
    fn a_flickering_command_is_one_command_until_a_second_of_quiet() {
        // On at 10, flicker at 14 and 30 (within a second of the last on tick), then again after 1.2 s.
        let s = ticks(300, &[(10, 12), (14, 15), (30, 40), (100, 101)]);
        assert_eq!(onsets(&s, &COMMAND), vec![200.0, 2000.0]);
        assert_eq!(onsets(&s, &NONE).len(), 4);
    }

    #[test]
    fn the_streaming_form_confirms_after_the_hold_with_the_onset_time() {
        let mut d = Debouncer::new(RESPONSE, 20.0);
        let out: Vec<Option<f64>> = (0..8).map(|k| d.step(k as f64 * 20.0, k >= 2)).collect();
        // On from tick 2; 100 ms held at the end of tick 6.
        assert_eq!(
            out,
            vec![None, None, None, None, None, None, Some(40.0), None]
        );
    }
}

//! Metrics of the gesture-command experiment ("Reducing Lag By Predicting the Next Command"): when the robot's
//! response started relative to each command's onset, and how often it started with no command coming.
//!
//! Inputs are plain numbers so the same code serves simulated runs (ground-truth onsets from the simulated human)
//! and recorded runs (onsets of the observed stimulus): a series of [`ResponseSample`]s (one per control tick:
//! was the fixed response being executed?) and the [`CommandWindow`]s.
//!
//! Definitions:
//! - A *response onset* is the first tick of a response episode that lasted at least the debounce's hold
//!   ([`MatchParams::response`], by default [`debounce::RESPONSE`]: held 100 ms, gaps up to 100 ms bridged), so
//!   a one-tick gate blip is not a response. [`response_onsets`] gives the raw rising edges.
//! - A command's window is `[onset − anticipation_ms, end + max_lag_ms]`. The command's response onset is the
//!   first onset inside its window; its *latency* is that onset's time minus the command onset (negative =
//!   the response anticipated the command, the point of Pavlovian control). A command whose window holds no
//!   onset is *missed*, or *already responding* when the response was on at the window's start.
//! - A *false start* is a response onset that lies in no command's window.
//! - *Time responding outside commands* is the summed duration of responding ticks outside every window (each
//!   tick counts until the next sample), the cost of unnecessary responses.

use serde::{Deserialize, Serialize};

/// Half-width of a command's window in the live figures, ms.
pub const LIVE_WINDOW_MS: f64 = 1000.0;

/// How many recent commands the live mean lead covers.
pub const RECENT_COMMANDS: usize = 40;

pub mod curve;
pub mod debounce;
pub mod live;
pub mod live_aligned;
pub mod live_physical;
pub mod physical;

/// Whether the fixed response was executing at one tick.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct ResponseSample {
    /// Time of the tick, ms.
    pub t_ms: f64,
    /// Whether the response (e.g. the left spin) was being executed.
    pub responding: bool,
}

/// One command gesture.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct CommandWindow {
    /// When the command began (elbow below 90°), ms.
    pub onset_ms: f64,
    /// When it ended, ms (`onset_ms` when unknown).
    pub end_ms: f64,
}

impl From<crate::sim::human::CommandEvent> for CommandWindow {
    fn from(c: crate::sim::human::CommandEvent) -> Self {
        CommandWindow {
            onset_ms: c.onset_ms,
            end_ms: c.end_ms,
        }
    }
}

/// How responses are matched to commands.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct MatchParams {
    /// How long before a command's onset a response still counts as anticipating it, ms.
    pub anticipation_ms: f64,
    /// How long after a command's end a response still counts as answering it, ms.
    pub max_lag_ms: f64,
    /// How response onsets are debounced.
    pub response: debounce::Debounce,
}

impl Default for MatchParams {
    /// 1 s of anticipation (the paper's 0.5 s timescale, twice), 0.5 s of lag, [`debounce::RESPONSE`].
    fn default() -> Self {
        MatchParams {
            anticipation_ms: 1000.0,
            max_lag_ms: 500.0,
            response: debounce::RESPONSE,
        }
    }
}

/// What happened for one command.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub enum CommandOutcome {
    /// The response started `latency_ms` after the command onset (negative: before it).
    Answered {
        /// Response onset minus command onset, ms.
        latency_ms: f64,
    },
    /// The response was already on when the window opened, and did not start anew inside it.
    AlreadyResponding,
    /// No response inside the window.
    Missed,
}

/// The metrics of one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct ResponseTiming {
    /// One outcome per command, in the order given.
    pub outcomes: Vec<CommandOutcome>,
    /// Response onsets in no command's window.
    pub false_starts: usize,
    /// When they were, ms.
    pub false_starts_ms: Vec<f64>,
    /// Responding time outside every command window, ms.
    pub responding_outside_ms: f64,
    /// Duration covered by the samples, ms.
    pub duration_ms: f64,
}

impl ResponseTiming {
    /// Latencies of the answered commands, in command order.
    pub fn latencies_ms(&self) -> Vec<f64> {
        self.outcomes
            .iter()
            .filter_map(|o| match *o {
                CommandOutcome::Answered { latency_ms } => Some(latency_ms),
                _ => None,
            })
            .collect()
    }

    /// Mean latency of the answered commands, ms.
    pub fn mean_latency_ms(&self) -> Option<f64> {
        let l = self.latencies_ms();
        (!l.is_empty()).then(|| l.iter().sum::<f64>() / l.len() as f64)
    }

    /// How many commands were answered before their onset.
    pub fn anticipated(&self) -> usize {
        self.latencies_ms().iter().filter(|&&l| l < 0.0).count()
    }

    /// How many commands got no response.
    pub fn missed(&self) -> usize {
        self.outcomes
            .iter()
            .filter(|o| matches!(o, CommandOutcome::Missed))
            .count()
    }

    /// False starts per minute of run.
    pub fn false_starts_per_minute(&self) -> f64 {
        if self.duration_ms > 0.0 {
            self.false_starts as f64 * 60_000.0 / self.duration_ms
        } else {
            0.0
        }
    }
}

/// Response onsets: times of ticks that respond while the previous did not.
pub fn response_onsets(samples: &[ResponseSample]) -> Vec<f64> {
    let mut was = false;
    let mut onsets = Vec::new();
    for s in samples {
        if s.responding && !was {
            onsets.push(s.t_ms);
        }
        was = s.responding;
    }
    onsets
}

pub(crate) fn window(c: &CommandWindow, p: &MatchParams) -> (f64, f64) {
    (
        c.onset_ms - p.anticipation_ms,
        c.end_ms.max(c.onset_ms) + p.max_lag_ms,
    )
}

/// Computes the metrics of a run. `samples` must be in time order.
pub fn measure(
    samples: &[ResponseSample],
    commands: &[CommandWindow],
    params: &MatchParams,
) -> ResponseTiming {
    let onsets = debounce::onsets(samples, &params.response);
    let windows: Vec<(f64, f64)> = commands.iter().map(|c| window(c, params)).collect();
    let in_any = |t: f64| windows.iter().any(|&(lo, hi)| t >= lo && t <= hi);
    let outcomes = commands
        .iter()
        .zip(&windows)
        .map(|(c, &(lo, hi))| {
            match onsets.iter().find(|&&t| t >= lo && t <= hi) {
                Some(&t) => CommandOutcome::Answered {
                    latency_ms: t - c.onset_ms,
                },
                None => {
                    // Responding at the window's start: the newest sample at or before `lo`.
                    let on_at_start = samples
                        .iter()
                        .take_while(|s| s.t_ms <= lo)
                        .last()
                        .is_some_and(|s| s.responding);
                    if on_at_start {
                        CommandOutcome::AlreadyResponding
                    } else {
                        CommandOutcome::Missed
                    }
                }
            }
        })
        .collect();
    let false_starts_ms: Vec<f64> = onsets.iter().copied().filter(|&t| !in_any(t)).collect();
    let responding_outside_ms = samples
        .windows(2)
        .filter(|w| w[0].responding && !in_any(w[0].t_ms))
        .map(|w| (w[1].t_ms - w[0].t_ms).max(0.0))
        .sum();
    let duration_ms = match (samples.first(), samples.last()) {
        (Some(a), Some(b)) => (b.t_ms - a.t_ms).max(0.0),
        _ => 0.0,
    };
    ResponseTiming {
        outcomes,
        false_starts: false_starts_ms.len(),
        false_starts_ms,
        responding_outside_ms,
        duration_ms,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// 20 ms ticks from 0 to `end_ms`, responding inside the given `[from, to)` spans.
    fn ticks(end_ms: f64, on: &[(f64, f64)]) -> Vec<ResponseSample> {
        (0..)
            .map(|k| f64::from(k) * 20.0)
            .take_while(|&t| t <= end_ms)
            .map(|t| ResponseSample {
                t_ms: t,
                responding: on.iter().any(|&(a, b)| t >= a && t < b),
            })
            .collect()
    }

    fn cmd(onset_ms: f64, end_ms: f64) -> CommandWindow {
        CommandWindow { onset_ms, end_ms }
    }

    #[test]
    fn onsets_are_rising_edges_and_a_responding_start_counts() {
        let s = ticks(200.0, &[(0.0, 40.0), (100.0, 140.0)]);
        assert_eq!(response_onsets(&s), vec![0.0, 100.0]);
        assert!(response_onsets(&ticks(200.0, &[])).is_empty());
    }

    #[test]
    fn reactive_lags_and_pavlovian_anticipates() {
        let commands = [cmd(2000.0, 3000.0), cmd(6000.0, 7000.0)];
        let p = MatchParams::default();
        // Reactive: 100 ms after each onset, until the end.
        let reactive = measure(
            &ticks(10_000.0, &[(2100.0, 3000.0), (6100.0, 7000.0)]),
            &commands,
            &p,
        );
        assert_eq!(reactive.latencies_ms(), vec![100.0, 100.0]);
        assert_eq!(reactive.anticipated(), 0);
        // Pavlovian: 200 ms before the first, 40 ms after the second.
        let pavlovian = measure(
            &ticks(10_000.0, &[(1800.0, 3000.0), (6040.0, 7000.0)]),
            &commands,
            &p,
        );
        assert_eq!(pavlovian.latencies_ms(), vec![-200.0, 40.0]);
        assert_eq!(pavlovian.anticipated(), 1);
        assert_eq!(pavlovian.mean_latency_ms(), Some(-80.0));
        assert_eq!((pavlovian.false_starts, pavlovian.missed()), (0, 0));
        assert_eq!(pavlovian.responding_outside_ms, 0.0);
        assert_eq!(pavlovian.duration_ms, 10_000.0);
    }

    #[test]
    fn a_one_tick_gate_blip_is_neither_an_anticipation_nor_a_false_start() {
        let commands = [cmd(2000.0, 3000.0)];
        // A blip 100 ms before the command, another at 6 s, the real response from 2.1 s.
        let s = ticks(
            8000.0,
            &[(1900.0, 1920.0), (2100.0, 3000.0), (6000.0, 6020.0)],
        );
        let m = measure(&s, &commands, &MatchParams::default());
        assert_eq!(m.latencies_ms(), vec![100.0]);
        assert_eq!((m.anticipated(), m.false_starts), (0, 0));
        // Undebounced, the blip would have been an anticipation and the second a false start.
        let raw = MatchParams {
            response: debounce::NONE,
            ..MatchParams::default()
        };
        let m = measure(&s, &commands, &raw);
        assert_eq!(m.latencies_ms(), vec![-100.0]);
        assert_eq!(m.false_starts, 1);
    }

    #[test]
    fn false_starts_and_time_responding_outside_commands() {
        let commands = [cmd(5000.0, 5600.0)];
        let p = MatchParams {
            anticipation_ms: 500.0,
            max_lag_ms: 200.0,
            ..MatchParams::default()
        };
        // A 200 ms false start at 1 s, a correct anticipation at 4.8 s, and a late stray at 8 s.
        let m = measure(
            &ticks(
                10_000.0,
                &[(1000.0, 1200.0), (4800.0, 5600.0), (8000.0, 8100.0)],
            ),
            &commands,
            &p,
        );
        assert_eq!(m.latencies_ms(), vec![-200.0]);
        assert_eq!(m.false_starts, 2);
        assert!((m.responding_outside_ms - 300.0).abs() < 1e-9, "{m:?}");
        assert!((m.false_starts_per_minute() - 12.0).abs() < 1e-9);
    }

    #[test]
    fn missed_and_already_responding_commands() {
        let commands = [cmd(2000.0, 2500.0), cmd(6000.0, 6500.0)];
        let p = MatchParams {
            anticipation_ms: 500.0,
            max_lag_ms: 200.0,
            ..MatchParams::default()
        };
        // Nothing near the first; the response is on from 4 s to 7 s, across the second's whole window.
        let m = measure(&ticks(10_000.0, &[(4000.0, 7000.0)]), &commands, &p);
        assert_eq!(
            m.outcomes,
            vec![CommandOutcome::Missed, CommandOutcome::AlreadyResponding]
        );
        assert_eq!(m.missed(), 1);
        assert_eq!(m.mean_latency_ms(), None);
        // The 4 s onset lies in no window: a false start.
        assert_eq!(m.false_starts, 1);
    }

    #[test]
    fn ground_truth_commands_convert_and_empty_runs_are_zero() {
        let c: CommandWindow = crate::sim::human::CommandEvent {
            onset_ms: 10.0,
            end_ms: 20.0,
        }
        .into();
        assert_eq!(c, cmd(10.0, 20.0));
        let m = measure(&[], &[c], &MatchParams::default());
        assert_eq!(m.outcomes, vec![CommandOutcome::Missed]);
        assert_eq!((m.duration_ms, m.false_starts_per_minute()), (0.0, 0.0));
    }
}

//! One interaction run's ticks reduced as they arrive, so a run keeps a few dozen bytes a tick instead of
//! its tick records: the response and physical samples the timing analysis reads, the observed command
//! onsets (debounced as [`observed_onsets`] does), the aligned windows of the last N of them (Figure 4),
//! and, for the runs Figure 3 draws, the handful of fields it plots ([`Fig3Tick`]).
//!
//! [`RunReducer::push`] sees each record once, in order; [`RunReducer::finish`] hands back what the run
//! keeps. The result is the same as reducing the whole list of records afterwards (tested below).

use std::collections::VecDeque;

use pavlov::analysis::interaction::ResponseSample;
use pavlov::analysis::interaction::debounce::{COMMAND, Debouncer};
use pavlov::analysis::interaction::live_physical::physical_sample;
use pavlov::analysis::interaction::physical::PhysicalSample;
use pavlov::record::TickRecord;
use serde::{Deserialize, Serialize};

use super::run::{AFTER_TICKS, AlignedWindow, BEFORE_TICKS};

/// The period assumed when a run has fewer than two ticks to measure it from, ms.
const DEFAULT_PERIOD_MS: f64 = 20.0;

/// What Figure 3 draws of one tick.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Fig3Tick {
    /// Time of the tick, ms.
    pub t_ms: f64,
    /// The left elbow angle, ° (`None` when no skeleton was seen).
    pub elbow_left: Option<f64>,
    /// The first prediction's value and threshold.
    pub prediction: Option<(f64, f64)>,
    /// The command stimulus E.
    pub stimulus: bool,
    /// Battery current, mA (`None` when not reported).
    pub current_ma: Option<i32>,
    /// The right wheel's command, mm/s.
    pub right_mm_s: i16,
}

impl Fig3Tick {
    /// The fields Figure 3 draws of `r`.
    pub fn of(r: &TickRecord) -> Fig3Tick {
        Fig3Tick {
            t_ms: r.t_ms,
            elbow_left: r.elbow.as_ref().and_then(|e| e.left),
            prediction: r.predictions.first().map(|p| (p.value, p.threshold)),
            stimulus: r.stimulus,
            current_ma: r.sensors.battery_current_ma,
            right_mm_s: r.command.right_mm_s,
        }
    }
}

/// Debounced command onsets, found tick by tick: the index of the tick that confirms each onset. The
/// debouncer's period is the first two ticks' spacing, so the first tick waits for the second.
#[derive(Default)]
pub(crate) struct OnsetFinder {
    debouncer: Option<Debouncer>,
    first: Option<(f64, bool)>,
    next: u64,
}

impl OnsetFinder {
    /// Feeds the next tick; returns the indices of onsets confirmed by it (and, on the second tick, by
    /// the first).
    pub(crate) fn step(&mut self, t_ms: f64, stimulus: bool, out: &mut Vec<u64>) {
        let index = self.next;
        self.next += 1;
        match (&mut self.debouncer, self.first.take()) {
            (Some(d), _) => {
                if d.step(t_ms, stimulus).is_some() {
                    out.push(index);
                }
            }
            (None, None) => self.first = Some((t_ms, stimulus)),
            (None, Some((t0, s0))) => {
                let mut d = Debouncer::new(COMMAND, t_ms - t0);
                if d.step(t0, s0).is_some() {
                    out.push(index - 1);
                }
                if d.step(t_ms, stimulus).is_some() {
                    out.push(index);
                }
                self.debouncer = Some(d);
            }
        }
    }

    /// Ends the run: a lone first tick is debounced with the default period.
    pub(crate) fn finish(&mut self, out: &mut Vec<u64>) {
        if let Some((t0, s0)) = self.first.take()
            && Debouncer::new(COMMAND, DEFAULT_PERIOD_MS)
                .step(t0, s0)
                .is_some()
        {
            out.push(self.next - 1);
        }
    }
}

/// Whether the aligned window of the onset at tick `i` fits a run of `len` ticks.
pub(crate) fn window_fits(i: u64, len: u64) -> bool {
    i as i64 >= BEFORE_TICKS && (i as i64 + AFTER_TICKS) < len as i64
}

/// Ticks (indices) of the observed command onsets of `ticks`, each seen through `at` as (time, stimulus),
/// debounced ([`COMMAND`]: the stimulus was off for more than a second before), where the aligned window
/// fits.
pub(crate) fn observed_onsets<T>(ticks: &[T], at: impl Fn(&T) -> (f64, bool)) -> Vec<u64> {
    let mut finder = OnsetFinder::default();
    let mut out = Vec::new();
    for t in ticks {
        let (t_ms, stimulus) = at(t);
        finder.step(t_ms, stimulus, &mut out);
    }
    finder.finish(&mut out);
    out.retain(|&i| window_fits(i, ticks.len() as u64));
    out
}

/// What a reduced run keeps.
#[derive(Debug, Default)]
pub(crate) struct Reduced {
    /// Per tick: the time and whether the response was executed.
    pub(crate) samples: Vec<ResponseSample>,
    /// Per tick: the current and whether the robot moved.
    pub(crate) physical: Vec<PhysicalSample>,
    /// The observed onsets of the aligned windows (the last N whose window fits), in order.
    pub(crate) aligned_onsets: Vec<u64>,
    /// Their aligned windows.
    pub(crate) aligned_windows: Vec<AlignedWindow>,
    /// What Figure 3 draws of every tick, when kept.
    pub(crate) figure3: Vec<Fig3Tick>,
}

/// A run's ticks reduced as they arrive.
pub(crate) struct RunReducer {
    kept: Reduced,
    keep_figure3: bool,
    /// How many aligned windows to keep (the last ones).
    aligned: usize,
    onsets: OnsetFinder,
    found: Vec<u64>,
    /// (current, rotation) of the last `BEFORE_TICKS + 1` ticks.
    recent: VecDeque<(Option<f64>, f64)>,
    /// Windows still filling: onset, values so far.
    open: VecDeque<(u64, AlignedWindow)>,
    /// Complete windows, the last `aligned` of them.
    complete: VecDeque<(u64, AlignedWindow)>,
}

/// Values in one aligned window.
const WINDOW_LEN: usize = (BEFORE_TICKS + AFTER_TICKS + 1) as usize;

impl RunReducer {
    /// A reducer for a run of about `ticks` ticks, keeping the last `aligned` aligned windows and, when
    /// `keep_figure3`, what Figure 3 draws.
    pub(crate) fn new(ticks: usize, aligned: usize, keep_figure3: bool) -> Self {
        RunReducer {
            kept: Reduced {
                samples: Vec::with_capacity(ticks),
                physical: Vec::with_capacity(ticks),
                figure3: if keep_figure3 {
                    Vec::with_capacity(ticks)
                } else {
                    Vec::new()
                },
                ..Reduced::default()
            },
            keep_figure3,
            aligned,
            onsets: OnsetFinder::default(),
            found: Vec::new(),
            recent: VecDeque::with_capacity(BEFORE_TICKS as usize + 2),
            open: VecDeque::new(),
            complete: VecDeque::new(),
        }
    }

    /// Takes the next tick.
    pub(crate) fn push(&mut self, r: &TickRecord) {
        self.kept.samples.push(ResponseSample {
            t_ms: r.t_ms,
            responding: r.gate,
        });
        self.kept.physical.push(physical_sample(r));
        if self.keep_figure3 {
            self.kept.figure3.push(Fig3Tick::of(r));
        }
        let value = (
            r.sensors.battery_current_ma.map(f64::from),
            f64::from(r.sensors.angle_deg),
        );
        self.recent.push_back(value);
        if self.recent.len() > BEFORE_TICKS as usize + 1 {
            self.recent.pop_front();
        }
        for (_, w) in self.open.iter_mut() {
            w.push(value);
        }
        while self
            .open
            .front()
            .is_some_and(|(_, w)| w.len() == WINDOW_LEN)
        {
            if let Some(done) = self.open.pop_front() {
                self.complete.push_back(done);
            }
            if self.complete.len() > self.aligned {
                self.complete.pop_front();
            }
        }
        self.onsets.step(r.t_ms, r.stimulus, &mut self.found);
        for i in self.found.drain(..) {
            // Only an onset on this tick can open a window: the first tick's is before BEFORE_TICKS.
            let index = self.kept.samples.len() as u64 - 1;
            if i == index && i as i64 >= BEFORE_TICKS {
                let mut w = Vec::with_capacity(WINDOW_LEN);
                w.extend(self.recent.iter().copied());
                self.open.push_back((i, w));
            }
        }
    }

    /// Ends the run.
    pub(crate) fn finish(mut self) -> Reduced {
        // Windows still open at the end do not fit; neither does an onset found now (the first tick's).
        let (onsets, windows) = self.complete.into_iter().unzip();
        self.kept.aligned_onsets = onsets;
        self.kept.aligned_windows = windows;
        self.kept
    }
}

#[cfg(test)]
mod tests {
    use std::sync::Arc;

    use pavlov::control::Mode;

    use super::*;

    fn rec(seq: u64, stimulus: bool) -> TickRecord {
        let mut r = TickRecord {
            stimulus,
            gate: stimulus,
            ..TickRecord::at_rest(seq, seq as f64 * 20.0, Mode::Pavlovian)
        };
        r.sensors.battery_current_ma = (seq % 7 != 0).then_some(-(seq as i32));
        r.sensors.angle_deg = (seq % 5) as i32;
        r
    }

    /// The aligned window of `onset` from the whole list, as the study made it before it streamed.
    fn window_of(records: &[Arc<TickRecord>], onset: u64) -> AlignedWindow {
        (-BEFORE_TICKS..=AFTER_TICKS)
            .map(|offset| {
                let r = usize::try_from(onset as i64 + offset)
                    .ok()
                    .and_then(|k| records.get(k));
                (
                    r.and_then(|t| t.sensors.battery_current_ma.map(f64::from)),
                    r.map_or(f64::NAN, |t| f64::from(t.sensors.angle_deg)),
                )
            })
            .collect()
    }

    #[test]
    fn onsets_are_debounced_and_need_room_for_the_aligned_window() {
        // Stimulus at 10 (too early for the window), 100..110, a flicker at 115 (debounced), 200..205,
        // and 300 (too late: the run ends at 320).
        let on = |i: u64| {
            i == 10 || (100..110).contains(&i) || i == 115 || (200..205).contains(&i) || i == 300
        };
        let records: Vec<TickRecord> = (0..320).map(|i| rec(i, on(i))).collect();
        assert_eq!(
            observed_onsets(&records, |r| (r.t_ms, r.stimulus)),
            vec![100, 200]
        );
    }

    #[test]
    fn streaming_keeps_what_the_whole_list_gives() {
        // Onsets every 150 ticks from tick 3 on, one stimulus held for 6 ticks; the run ends inside the
        // last window.
        let on = |i: u64| i >= 3 && (i - 3) % 150 < 6;
        let records: Vec<Arc<TickRecord>> = (0..1_540).map(|i| Arc::new(rec(i, on(i)))).collect();
        for keep in [0, 1, 3, 100] {
            let mut reducer = RunReducer::new(10, keep, keep == 3);
            records.iter().for_each(|r| reducer.push(r));
            let got = reducer.finish();
            let all = observed_onsets(&records, |r| (r.t_ms, r.stimulus));
            assert!(all.len() > 3, "{all:?}");
            let last: Vec<u64> = all[all.len().saturating_sub(keep)..].to_vec();
            assert_eq!(got.aligned_onsets, last, "keep {keep}");
            let windows: Vec<AlignedWindow> =
                last.iter().map(|&i| window_of(&records, i)).collect();
            // NaN never occurs in a window that fits, so plain equality holds.
            assert_eq!(got.aligned_windows, windows, "keep {keep}");
            assert_eq!(got.samples.len(), records.len());
            assert_eq!(got.physical[17], physical_sample(&records[17]));
            assert_eq!(got.figure3.len(), if keep == 3 { records.len() } else { 0 });
        }
    }

    #[test]
    fn a_lone_tick_and_an_empty_run_keep_no_window() {
        let reducer = RunReducer::new(0, 40, true);
        let got = reducer.finish();
        assert!(got.aligned_onsets.is_empty() && got.samples.is_empty());
        let mut reducer = RunReducer::new(1, 40, true);
        reducer.push(&rec(0, true));
        let got = reducer.finish();
        assert!(got.aligned_onsets.is_empty());
        assert_eq!(got.figure3, vec![Fig3Tick::of(&rec(0, true))]);
    }
}

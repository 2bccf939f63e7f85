//! Live aligned averages for the dashboard, after the paper's Figure 4 ("averaged sensor observations from 40
//! commands, aligned to the onset of the command request"): the battery current and the wheel rotation per
//! tick from [`BEFORE_MS`] before to [`AFTER_MS`] after each observed command onset (the stimulus's debounced
//! onset, [`super::debounce::COMMAND`]: a flickering stimulus is one command), averaged over the last [`RECENT_COMMANDS`] commands of each mode, reactive and Pavlovian.
//!
//! A command belongs to the mode in force on its onset tick (commands under manual control are ignored). It is
//! stored once its window has passed; a command with a tick lacking the battery current is skipped. Samples
//! are binned by their offset from the onset in whole tick periods, so each curve has one point per tick.

use std::collections::VecDeque;

use serde::Serialize;

use super::RECENT_COMMANDS;
use super::debounce::{COMMAND, Debouncer};
use crate::control::Mode;
use crate::record::TickRecord;

/// How far before a command onset the curves start, ms.
pub const BEFORE_MS: f64 = 500.0;

/// How far after a command onset the curves end, ms.
pub const AFTER_MS: f64 = 1000.0;

/// One tick's physical readings.
#[derive(Debug, Clone, Copy, PartialEq)]
struct AlignedSample {
    t_ms: f64,
    current_ma: Option<f64>,
    rotation_deg: f64,
}

/// One stored command: per bin, the (current, rotation) when a tick fell in it.
type CommandCurve = Vec<Option<(f64, f64)>>;

/// The mean curve of one mode.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct AlignedCurve {
    /// How many commands the means cover.
    pub commands: usize,
    /// Mean battery current per offset, mA (`None` where no command had a tick).
    pub current_ma: Vec<Option<f64>>,
    /// Mean rotation per tick per offset, degrees.
    pub rotation_deg: Vec<Option<f64>>,
}

/// The aligned averages of both modes.
#[derive(Debug, Clone, Default, PartialEq, Serialize)]
pub struct AlignedFigures {
    /// Offset of each point from the command onset, ms.
    pub offsets_ms: Vec<f64>,
    /// Under reactive control.
    pub reactive: AlignedCurve,
    /// Under Pavlovian control.
    pub pavlovian: AlignedCurve,
}

/// The live tracker.
#[derive(Debug, Clone)]
pub struct LiveAligned {
    period_ms: f64,
    commands: Debouncer,
    samples: VecDeque<AlignedSample>,
    pending: VecDeque<(f64, Mode)>,
    reactive: VecDeque<CommandCurve>,
    pavlovian: VecDeque<CommandCurve>,
    revision: u64,
}

fn round_tenth(x: f64) -> f64 {
    (x * 10.0).round() / 10.0
}

fn mean_curve(commands: &VecDeque<CommandCurve>, bins: usize) -> AlignedCurve {
    let mut sums = vec![(0.0, 0.0, 0usize); bins];
    for curve in commands {
        for (sum, point) in sums.iter_mut().zip(curve) {
            if let Some((current, rotation)) = point {
                sum.0 += current;
                sum.1 += rotation;
                sum.2 += 1;
            }
        }
    }
    let mean = |pick: fn(&(f64, f64, usize)) -> f64| {
        sums.iter()
            .map(|s| (s.2 > 0).then(|| round_tenth(pick(s) / s.2 as f64)))
            .collect()
    };
    AlignedCurve {
        commands: commands.len(),
        current_ma: mean(|s| s.0),
        rotation_deg: mean(|s| s.1),
    }
}

impl LiveAligned {
    /// A tracker for ticks `period_ms` apart (a non-positive or non-finite period counts as 20 ms).
    pub fn new(period_ms: f64) -> Self {
        let period_ms = if period_ms.is_finite() && period_ms > 0.0 {
            period_ms
        } else {
            20.0
        };
        LiveAligned {
            period_ms,
            commands: Debouncer::new(COMMAND, period_ms),
            samples: VecDeque::new(),
            pending: VecDeque::new(),
            reactive: VecDeque::new(),
            pavlovian: VecDeque::new(),
            revision: 0,
        }
    }

    /// Ticks before the onset bin.
    fn bins_before(&self) -> usize {
        (BEFORE_MS / self.period_ms).round() as usize
    }

    /// Points per curve.
    pub fn bins(&self) -> usize {
        self.bins_before() + (AFTER_MS / self.period_ms).round() as usize + 1
    }

    /// Counts the commands stored so far: it changes whenever the summary does.
    pub fn revision(&self) -> u64 {
        self.revision
    }

    /// Feeds one tick record (times non-decreasing).
    pub fn observe(&mut self, record: &TickRecord) {
        let t = record.t_ms;
        if let Some(onset) = self.commands.step(t, record.stimulus) {
            self.pending.push_back((onset, record.mode));
        }
        self.samples.push_back(AlignedSample {
            t_ms: t,
            current_ma: record.sensors.battery_current_ma.map(f64::from),
            rotation_deg: f64::from(record.sensors.angle_deg),
        });
        while let Some(&(onset, mode)) = self.pending.front() {
            if t < onset + AFTER_MS {
                break;
            }
            self.pending.pop_front();
            self.resolve(onset, mode);
        }
        // Keep what the oldest pending (or a future) command's window can reach, plus one tick.
        let oldest = self.pending.front().map_or(t, |p| p.0);
        let keep_from = oldest - BEFORE_MS - self.period_ms;
        while self.samples.front().is_some_and(|s| s.t_ms < keep_from) {
            self.samples.pop_front();
        }
    }

    fn resolve(&mut self, onset: f64, mode: Mode) {
        let before = self.bins_before() as f64;
        let bins = self.bins();
        let mut curve: CommandCurve = vec![None; bins];
        let in_window = self
            .samples
            .iter()
            .filter(|s| s.t_ms >= onset - BEFORE_MS - 1e-9 && s.t_ms <= onset + AFTER_MS + 1e-9);
        for s in in_window {
            let Some(current) = s.current_ma else {
                return;
            };
            let bin = ((s.t_ms - onset) / self.period_ms).round() + before;
            if bin >= 0.0
                && let Some(slot) = curve.get_mut(bin as usize)
            {
                *slot = Some((current, s.rotation_deg));
            }
        }
        let store = match mode {
            Mode::Reactive => &mut self.reactive,
            Mode::Pavlovian => &mut self.pavlovian,
            Mode::Manual => return,
        };
        if store.len() == RECENT_COMMANDS {
            store.pop_front();
        }
        store.push_back(curve);
        self.revision += 1;
    }

    /// The mean curves of both modes.
    pub fn figures(&self) -> AlignedFigures {
        let bins = self.bins();
        let before = self.bins_before() as f64;
        AlignedFigures {
            offsets_ms: (0..bins)
                .map(|k| round_tenth((k as f64 - before) * self.period_ms))
                .collect(),
            reactive: mean_curve(&self.reactive, bins),
            pavlovian: mean_curve(&self.pavlovian, bins),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A 20 ms tick: the stimulus, the current and the rotation.
    fn tick(k: u64, mode: Mode, stimulus: bool, current: Option<i32>, angle: i32) -> TickRecord {
        let mut r = TickRecord::at_rest(k, k as f64 * 20.0, mode);
        r.stimulus = stimulus;
        r.sensors.battery_current_ma = current;
        r.sensors.angle_deg = angle;
        r
    }

    /// Feeds ticks 0..n; a command lasting 10 ticks starts at each tick in `onsets`, the current steps from
    /// −150 to `step` mA and the rotation from 0 to 2° per tick `lead` ticks before each onset.
    fn run(
        live: &mut LiveAligned,
        ticks: std::ops::Range<u64>,
        mode: Mode,
        onsets: &[u64],
        step: i32,
        lead: u64,
    ) {
        for k in ticks {
            let stimulus = onsets.iter().any(|&o| k >= o && k < o + 10);
            let on = onsets.iter().any(|&o| k + lead >= o && k < o + 30);
            let (current, angle) = if on { (step, 2) } else { (-150, 0) };
            live.observe(&tick(k, mode, stimulus, Some(current), angle));
        }
    }

    #[test]
    fn curves_average_the_steps_around_each_onset() {
        let mut live = LiveAligned::new(20.0);
        assert_eq!(live.bins(), 76);
        // Reactive: two commands, the current steps 5 ticks (100 ms) after the onset to −550 and −650 mA.
        run(&mut live, 0..200, Mode::Reactive, &[50], -550, 0);
        run(&mut live, 200..400, Mode::Reactive, &[250], -650, 0);
        let s = live.figures();
        assert_eq!(s.offsets_ms.len(), 76);
        assert_eq!(
            (s.offsets_ms[0], s.offsets_ms[25], s.offsets_ms[75]),
            (-500.0, 0.0, 1000.0)
        );
        assert_eq!((s.reactive.commands, s.pavlovian.commands), (2, 0));
        // Before the onset: the rest current, no rotation; from the onset: the mean step and 2° per tick.
        assert_eq!(s.reactive.current_ma[24], Some(-150.0));
        assert_eq!(s.reactive.rotation_deg[24], Some(0.0));
        assert_eq!(s.reactive.current_ma[25], Some(-600.0));
        assert_eq!(s.reactive.rotation_deg[25], Some(2.0));
        assert!(s.pavlovian.current_ma.iter().all(Option::is_none));
    }

    #[test]
    fn modes_are_kept_apart_by_the_mode_at_onset() {
        let mut live = LiveAligned::new(20.0);
        run(&mut live, 0..200, Mode::Reactive, &[50], -600, 0);
        // Pavlovian: the current drops 10 ticks (200 ms) before the onset.
        run(&mut live, 200..400, Mode::Pavlovian, &[250], -600, 10);
        run(&mut live, 400..600, Mode::Manual, &[450], -600, 0);
        let s = live.figures();
        assert_eq!((s.reactive.commands, s.pavlovian.commands), (1, 1));
        assert_eq!(s.reactive.current_ma[20], Some(-150.0));
        assert_eq!(s.pavlovian.current_ma[20], Some(-600.0));
        assert_eq!(s.pavlovian.current_ma[14], Some(-150.0));
        assert_eq!(s.pavlovian.current_ma[15], Some(-600.0));
        assert_eq!(live.revision(), 2, "the manual command is not stored");
    }

    #[test]
    fn only_the_last_forty_commands_count() {
        let mut live = LiveAligned::new(20.0);
        // 10 commands stepping to −1000 mA, then 40 stepping to −500 mA.
        for c in 0..50u64 {
            let step = if c < 10 { -1000 } else { -500 };
            run(
                &mut live,
                c * 200..(c + 1) * 200,
                Mode::Pavlovian,
                &[c * 200 + 50],
                step,
                0,
            );
        }
        let s = live.figures();
        assert_eq!(s.pavlovian.commands, RECENT_COMMANDS);
        assert_eq!(s.pavlovian.current_ma[30], Some(-500.0));
        assert!(live.samples.len() < 200, "old samples are dropped");
    }

    #[test]
    fn a_command_waits_for_its_window_and_missing_current_skips_it() {
        let mut live = LiveAligned::new(20.0);
        // Onset at tick 50 (1 s): resolved at tick 100 (2 s), not before.
        run(&mut live, 0..100, Mode::Reactive, &[50], -600, 0);
        assert_eq!(live.figures().reactive.commands, 0);
        run(&mut live, 100..101, Mode::Reactive, &[50], -600, 0);
        assert_eq!(live.figures().reactive.commands, 1);
        // A command with one tick lacking the current is skipped.
        for k in 200..400 {
            let current = (k != 260).then_some(-150);
            live.observe(&tick(
                k,
                Mode::Reactive,
                (250..260).contains(&k),
                current,
                0,
            ));
        }
        assert_eq!((live.figures().reactive.commands, live.revision()), (1, 1));
    }

    #[test]
    fn an_onset_near_the_start_leaves_the_early_offsets_empty() {
        let mut live = LiveAligned::new(20.0);
        run(&mut live, 0..100, Mode::Reactive, &[5], -600, 0);
        let s = live.figures();
        assert_eq!(s.reactive.commands, 1);
        assert_eq!(s.reactive.current_ma[19], None);
        assert_eq!(s.reactive.current_ma[20], Some(-150.0));
    }
}

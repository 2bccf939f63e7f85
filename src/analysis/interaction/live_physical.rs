//! Live physical response onsets for the dashboard: for every observed command onset (the stimulus's debounced
//! onset, [`super::debounce::COMMAND`]), when the battery current dropped and the wheels started moving, by the definitions of
//! [`super::physical`], in the window `[onset − W, onset + W]` (`W` = [`LIVE_WINDOW_MS`]).
//!
//! A *lead* is the command onset minus the physical onset, ms: positive = before the stimulus. Each command is
//! resolved `W` after its onset; the means cover the commands among the last [`RECENT_COMMANDS`] resolved ones
//! that had an onset.

use std::collections::VecDeque;

use super::debounce::{COMMAND, Debouncer};
use super::physical::{PhysicalParams, PhysicalSample, onsets_in_window};
use super::{LIVE_WINDOW_MS, RECENT_COMMANDS};
use crate::record::TickRecord;

/// The live tracker of physical onsets.
#[derive(Debug, Clone)]
pub struct LivePhysical {
    commands: Debouncer,
    samples: VecDeque<PhysicalSample>,
    pending_onsets_ms: VecDeque<f64>,
    recent_current_leads: VecDeque<Option<f64>>,
    recent_motion_leads: VecDeque<Option<f64>>,
    params: PhysicalParams,
}

/// The physical sample of a tick record: its current and whether angle or distance is non-zero.
pub fn physical_sample(record: &TickRecord) -> PhysicalSample {
    PhysicalSample {
        t_ms: record.t_ms,
        current_ma: record.sensors.battery_current_ma.map(f64::from),
        moving: record.sensors.angle_deg != 0 || record.sensors.distance_mm != 0,
    }
}

fn push_recent(queue: &mut VecDeque<Option<f64>>, lead: Option<f64>) {
    if queue.len() == RECENT_COMMANDS {
        queue.pop_front();
    }
    queue.push_back(lead);
}

fn mean(queue: &VecDeque<Option<f64>>) -> Option<f64> {
    let known: Vec<f64> = queue.iter().flatten().copied().collect();
    (!known.is_empty()).then(|| known.iter().sum::<f64>() / known.len() as f64)
}

impl Default for LivePhysical {
    fn default() -> Self {
        Self::new()
    }
}

impl LivePhysical {
    /// A tracker that has seen nothing, with the default thresholds, for 20 ms ticks.
    pub fn new() -> Self {
        Self::with_period(20.0)
    }

    /// The same for ticks `period_ms` apart.
    pub fn with_period(period_ms: f64) -> Self {
        LivePhysical {
            commands: Debouncer::new(COMMAND, period_ms),
            samples: VecDeque::new(),
            pending_onsets_ms: VecDeque::new(),
            recent_current_leads: VecDeque::new(),
            recent_motion_leads: VecDeque::new(),
            params: PhysicalParams::default(),
        }
    }

    /// Feeds one tick record.
    pub fn observe(&mut self, record: &TickRecord) {
        self.observe_tick(record.stimulus, physical_sample(record));
    }

    /// Feeds one tick (times non-decreasing): the stimulus and the physical sample.
    pub fn observe_tick(&mut self, stimulus: bool, sample: PhysicalSample) {
        let t = sample.t_ms;
        if let Some(onset) = self.commands.step(t, stimulus) {
            self.pending_onsets_ms.push_back(onset);
        }
        self.samples.push_back(sample);
        while let Some(&onset) = self.pending_onsets_ms.front() {
            if t < onset + LIVE_WINDOW_MS {
                break;
            }
            self.pending_onsets_ms.pop_front();
            let samples = self.samples.make_contiguous();
            let latency = onsets_in_window(
                samples,
                onset - LIVE_WINDOW_MS,
                onset + LIVE_WINDOW_MS,
                onset,
                &self.params,
            );
            push_recent(
                &mut self.recent_current_leads,
                latency.current_ms.map(|l| -l),
            );
            push_recent(&mut self.recent_motion_leads, latency.motion_ms.map(|l| -l));
        }
        // Keep what the oldest pending (or a future) command's window and baseline can reach, plus one tick.
        let oldest = self.pending_onsets_ms.front().copied().unwrap_or(t);
        let keep_from = oldest - LIVE_WINDOW_MS - self.params.baseline_ms - 20.0;
        while self.samples.front().is_some_and(|s| s.t_ms < keep_from) {
            self.samples.pop_front();
        }
    }

    /// Mean current lead over the recent commands, ms.
    pub fn mean_current_lead_ms(&self) -> Option<f64> {
        mean(&self.recent_current_leads)
    }

    /// Mean motion lead over the recent commands, ms.
    pub fn mean_motion_lead_ms(&self) -> Option<f64> {
        mean(&self.recent_motion_leads)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tick(t: f64, current: f64, moving: bool) -> PhysicalSample {
        PhysicalSample {
            t_ms: t,
            current_ma: Some(current),
            moving,
        }
    }

    #[test]
    fn leads_are_resolved_a_window_after_each_onset_and_averaged() {
        let mut live = LivePhysical::new();
        // Commands at 2 s and 6 s; motion and current from 1.8 s (lead 200) and 6.1 s (lead −100).
        for k in 0..500 {
            let t = f64::from(k) * 20.0;
            let stimulus = (2000.0..2500.0).contains(&t) || (6000.0..6500.0).contains(&t);
            let on = (1800.0..2600.0).contains(&t) || (6100.0..6700.0).contains(&t);
            live.observe_tick(stimulus, tick(t, if on { -600.0 } else { -150.0 }, on));
            if t < 3000.0 {
                assert_eq!(live.mean_motion_lead_ms(), None, "unresolved at {t}");
            }
            if (3000.0..7000.0).contains(&t) {
                assert_eq!(live.mean_motion_lead_ms(), Some(200.0));
            }
        }
        assert_eq!(live.mean_motion_lead_ms(), Some(50.0));
        assert_eq!(live.mean_current_lead_ms(), Some(50.0));
        assert!(live.samples.len() < 100, "old samples are dropped");
    }

    #[test]
    fn a_command_with_no_response_has_no_lead() {
        let mut live = LivePhysical::new();
        for k in 0..200 {
            let t = f64::from(k) * 20.0;
            live.observe_tick((1000.0..1200.0).contains(&t), tick(t, -150.0, false));
        }
        assert_eq!(live.recent_motion_leads.len(), 1);
        assert_eq!(
            (live.mean_current_lead_ms(), live.mean_motion_lead_ms()),
            (None, None)
        );
    }
}

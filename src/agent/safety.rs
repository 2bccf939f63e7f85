//! The one safety predicate: when a tick's command must be a stop whatever the gate decided, and when a
//! tick's observation may be learned from. Actuation, learning and replay all ask here, so the rule that
//! stops the wheels is the rule replay checks.
//!
//! A stop overrides the gate, in this order: the operator's e-stop is latched; the robot has tripped from
//! Safe to Passive by itself (cliff, wheel drop, charger) and waits for the operator's re-arm; the link is
//! not up (stream stale, reconnecting, closed); the newest frame is older than `max_obs_age_ticks`
//! (`[safety]`). An observation is fresh exactly when none of the last three holds: a stale one is a
//! repeat of the past, acted on (with a stop) but never learned from.
//!
//! The pipeline watchdog is separate: when no decision has reached actuation for more than
//! `max_action_age_ticks` ticks (a stalled pipeline), actuation stops the wheels on its own
//! ([`pipeline_stalled`]).

use crate::record::SafetyStop;
use crate::supervision::LinkState;

/// Why `estop`, the link's `link` state and the observation's age force a stop (`None`: they do not).
pub fn stop_reason(
    estop: bool,
    link: LinkState,
    obs_age_ticks: Option<u32>,
    max_obs_age_ticks: u32,
) -> Option<SafetyStop> {
    if estop {
        Some(SafetyStop::EStop)
    } else if link == LinkState::Tripped {
        Some(SafetyStop::RobotTripped)
    } else if link != LinkState::Up {
        Some(SafetyStop::LinkDown)
    } else if obs_age_ticks.is_none_or(|age| age > max_obs_age_ticks) {
        Some(SafetyStop::StaleObservation)
    } else {
        None
    }
}

/// Whether a tick's observation may be learned from: the link is up and the frame is fresh.
pub fn observation_is_fresh(
    link: LinkState,
    obs_age_ticks: Option<u32>,
    max_obs_age_ticks: u32,
) -> bool {
    stop_reason(false, link, obs_age_ticks, max_obs_age_ticks).is_none()
}

/// Whether the pipeline has stalled on tick `seq`: the newest decision (`None`: none yet) is more than
/// `max_action_age_ticks` ticks old.
pub fn pipeline_stalled(
    seq: u64,
    last_decision_seq: Option<u64>,
    max_action_age_ticks: u32,
) -> bool {
    let limit = u64::from(max_action_age_ticks);
    match last_decision_seq {
        Some(last) => seq.saturating_sub(last) > limit,
        None => seq >= limit,
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_e_stop_comes_first_then_the_trip_then_the_link_then_the_age() {
        use LinkState::*;
        assert_eq!(stop_reason(true, Tripped, None, 5), Some(SafetyStop::EStop));
        assert_eq!(
            stop_reason(false, Tripped, Some(0), 5),
            Some(SafetyStop::RobotTripped)
        );
        for down in [Stale, Reconnecting, Down] {
            assert_eq!(
                stop_reason(false, down, Some(0), 5),
                Some(SafetyStop::LinkDown)
            );
        }
        assert_eq!(
            stop_reason(false, Up, Some(6), 5),
            Some(SafetyStop::StaleObservation)
        );
        assert_eq!(
            stop_reason(false, Up, None, 5),
            Some(SafetyStop::StaleObservation)
        );
        assert_eq!(stop_reason(false, Up, Some(5), 5), None);
    }

    #[test]
    fn freshness_is_the_absence_of_every_stop_but_the_e_stop() {
        assert!(observation_is_fresh(LinkState::Up, Some(5), 5));
        assert!(!observation_is_fresh(LinkState::Up, Some(6), 5));
        assert!(!observation_is_fresh(LinkState::Stale, Some(0), 5));
        assert!(!observation_is_fresh(LinkState::Tripped, Some(0), 5));
    }

    #[test]
    fn the_pipeline_stalls_after_max_action_age_ticks_without_a_decision() {
        assert!(!pipeline_stalled(13, Some(10), 3));
        assert!(pipeline_stalled(14, Some(10), 3));
        assert!(!pipeline_stalled(2, None, 3));
        assert!(pipeline_stalled(3, None, 3));
    }
}

//! Unit tests of [`LinkMonitor`]: staleness, re-sync, reopen with backoff, recovery, trips and re-arming.

use super::*;

fn cfg() -> MonitorConfig {
    MonitorConfig::default()
}

fn frame(mode: i32) -> SensorValues {
    let mut v = SensorValues::new();
    v.set(id::OI_MODE, mode);
    v.set(id::BUMPS_WHEEL_DROPS, 0);
    v
}

/// Frames every 15 ms from `from` to `to` (exclusive), ticking every 20 ms; returns the actions asked for.
fn run(m: &mut LinkMonitor, from: u64, to: u64, frames: bool, mode: i32) -> Vec<(u64, LinkAction)> {
    let mut actions = Vec::new();
    for t in from..to {
        if frames && t % 15 == 0 {
            m.on_frame(t, &frame(mode));
        }
        if t % 20 == 0
            && let Some(a) = m.on_tick(t)
        {
            actions.push((t, a));
        }
    }
    actions
}

#[test]
fn steady_frames_stay_up_and_ask_nothing() {
    let mut m = LinkMonitor::new(cfg(), code::SAFE, ModeQuirk::Auto, 0);
    assert!(run(&mut m, 0, 10_000, true, 2).is_empty());
    assert_eq!(m.state(), LinkState::Up);
    assert_eq!(m.mode(), Some(code::SAFE));
    assert_eq!(m.counters().stale_events, 0);
}

#[test]
fn silence_goes_stale_then_resyncs_then_reopens_with_backoff() {
    let mut m = LinkMonitor::new(cfg(), code::SAFE, ModeQuirk::Auto, 0);
    run(&mut m, 0, 1000, true, 2);
    // The last frame was at 990; the stream stops.
    let actions = run(&mut m, 1000, 2500, false, 2);
    let (t0, first) = actions[0];
    assert_eq!(first, LinkAction::Resync { with_mode: true });
    assert!(t0 > 990 + 150 && t0 <= 990 + 150 + 20, "stale at {t0}");
    assert_eq!(m.counters().stale_events, 1);
    // Two re-syncs 500 ms apart, then a reopen.
    assert_eq!(actions[1].1, LinkAction::Resync { with_mode: true });
    assert!(actions[1].0 >= t0 + 500);
    assert_eq!(actions[2].1, LinkAction::Reopen);
    assert_eq!(m.state(), LinkState::Reconnecting);
    // While the reopen is pending nothing else is asked.
    assert_eq!(actions.len(), 3);

    // Reopen fails twice: the waits double (250, 500), then it succeeds and waits for a frame.
    let mut t = 2500;
    m.reopen_failed(t);
    let a = run(&mut m, t, t + 1000, false, 2);
    assert_eq!(a[0].0 - t, 260, "first backoff 250 ms, next tick after it");
    t = a[0].0;
    m.reopen_failed(t);
    let a = run(&mut m, t, t + 2000, false, 2);
    assert_eq!(a[0].0 - t, 500, "second backoff 500 ms");
    t = a[0].0;
    m.reopened(t);
    assert_eq!(m.counters().reconnects, 1);
    assert_eq!(m.state(), LinkState::Reconnecting);
    // Frames come back: up again, and the outage is measured from the last good frame.
    run(&mut m, t + 40, t + 200, true, 2);
    assert_eq!(m.state(), LinkState::Up);
    let c = m.counters();
    assert_eq!(c.recoveries, 1);
    assert!(c.last_outage_ms.unwrap() > 2000);
    assert_eq!(c.reopen_failures, 2);
}

#[test]
fn backoff_is_capped() {
    let mut m = LinkMonitor::new(cfg(), code::SAFE, ModeQuirk::Auto, 0);
    m.on_link_lost(0);
    assert_eq!(m.on_tick(0), Some(LinkAction::Reopen));
    let mut t = 0;
    for _ in 0..12 {
        m.reopen_failed(t);
        let mut next = t;
        while m.on_tick(next).is_none() {
            next += 10;
        }
        assert!(next - t <= 5000);
        t = next;
    }
    m.reopen_failed(t);
    assert_eq!(m.on_tick(t + 4990), None);
    assert_eq!(m.on_tick(t + 5000), Some(LinkAction::Reopen));
}

#[test]
fn a_frame_during_the_resync_wait_recovers_without_a_reopen() {
    let mut m = LinkMonitor::new(cfg(), code::SAFE, ModeQuirk::Auto, 0);
    run(&mut m, 0, 300, true, 2);
    let a = run(&mut m, 300, 600, false, 2);
    assert_eq!(a.len(), 1);
    assert_eq!(m.state(), LinkState::Stale);
    run(&mut m, 600, 800, true, 2);
    assert_eq!(m.state(), LinkState::Up);
    assert_eq!(m.counters().reconnects, 0);
    assert_eq!(m.counters().recoveries, 1);
}

#[test]
fn end_of_file_reopens_at_once() {
    let mut m = LinkMonitor::new(cfg(), code::SAFE, ModeQuirk::Auto, 0);
    run(&mut m, 0, 100, true, 2);
    m.on_link_lost(100);
    assert_eq!(m.state(), LinkState::Reconnecting);
    assert_eq!(m.on_tick(100), Some(LinkAction::Reopen));
    assert_eq!(m.on_tick(120), None);
}

#[test]
fn a_trip_to_passive_is_reported_with_its_cause_and_not_overridden() {
    let mut m = LinkMonitor::new(cfg(), code::SAFE, ModeQuirk::Auto, 0);
    run(&mut m, 0, 300, true, 2);
    let mut tripped = frame(1);
    tripped.set(id::BUMPS_WHEEL_DROPS, 0b0_1100);
    m.on_frame(300, &tripped);
    assert_eq!(
        m.state(),
        LinkState::Up,
        "one Passive frame is not yet a trip"
    );
    m.on_frame(315, &tripped);
    assert_eq!(m.state(), LinkState::Tripped);
    assert_eq!(m.trip(), Some(TripCause::WheelDrop));
    assert_eq!(m.counters().trips, 1);
    // Still Passive: stays tripped, asks nothing.
    assert!(run(&mut m, 301, 2000, true, 1).is_empty());
    assert_eq!(m.state(), LinkState::Tripped);
    // The stream stalls while tripped: the re-sync does not send the mode.
    let a = run(&mut m, 2000, 2300, false, 1);
    assert_eq!(a[0].1, LinkAction::Resync { with_mode: false });
    run(&mut m, 2300, 2400, true, 1);
    assert_eq!(m.state(), LinkState::Tripped);
    // The operator re-arms: the mode is sent, and the first Safe frame clears the trip.
    assert_eq!(m.rearm(2400), Some(LinkAction::SendMode));
    run(&mut m, 2400, 2600, true, 2);
    assert_eq!(m.state(), LinkState::Up);
    assert_eq!(m.trip(), None);
    assert_eq!(m.rearm(2600), None, "nothing to re-arm");
}

#[test]
fn causes_are_read_from_the_frame() {
    let mut v = frame(1);
    assert_eq!(trip_cause(&v), TripCause::Unknown);
    v.set(id::CHARGING_SOURCES, 2);
    assert_eq!(trip_cause(&v), TripCause::Charger);
    v.set(id::CLIFF_FRONT_RIGHT, 1);
    assert_eq!(trip_cause(&v), TripCause::Cliff);
    v.set(id::BUMPS_WHEEL_DROPS, 0b1_0000);
    assert_eq!(trip_cause(&v), TripCause::WheelDrop);
    // Bumps alone (bits 0–1) are not a trip cause.
    let mut b = frame(1);
    b.set(id::BUMPS_WHEEL_DROPS, 0b11);
    assert_eq!(trip_cause(&b), TripCause::Unknown);
}

#[test]
fn passive_right_after_a_mode_command_is_not_a_trip() {
    // Start (→ Passive) and Safe go out together; a frame sent in between must not count as a trip.
    let mut m = LinkMonitor::new(cfg(), code::SAFE, ModeQuirk::Auto, 0);
    m.on_frame(15, &frame(1));
    assert_eq!(m.state(), LinkState::Up);
    assert_eq!(m.counters().trips, 0);
    m.on_frame(300, &frame(1));
    m.on_frame(315, &frame(1));
    assert_eq!(m.state(), LinkState::Tripped);
}

#[test]
fn a_single_odd_frame_is_not_a_trip() {
    let mut m = LinkMonitor::new(cfg(), code::SAFE, ModeQuirk::Auto, 0);
    run(&mut m, 0, 300, true, 2);
    m.on_frame(300, &frame(1));
    run(&mut m, 301, 600, true, 2);
    assert_eq!(m.state(), LinkState::Up);
    assert_eq!(m.counters().trips, 0);
}

#[test]
fn the_quirk_does_not_hide_a_trip() {
    let mut m = LinkMonitor::new(cfg(), code::SAFE, ModeQuirk::Auto, 0);
    // Safe reported as 3.
    run(&mut m, 0, 300, true, 3);
    assert!(m.quirk_active());
    assert_eq!(m.mode(), Some(code::SAFE));
    assert_eq!(m.state(), LinkState::Up);
    // Passive reported as 2.
    m.on_frame(300, &frame(2));
    m.on_frame(315, &frame(2));
    assert_eq!(m.state(), LinkState::Tripped);
}

#[test]
fn a_baud_rescue_comes_on_the_second_reopen_without_a_frame_and_every_other_one() {
    let mut m = LinkMonitor::new(cfg(), code::SAFE, ModeQuirk::Auto, 0);
    run(&mut m, 0, 100, true, 2);
    m.on_link_lost(100);
    let mut due = Vec::new();
    let mut t = 100;
    for _ in 0..6 {
        while m.on_tick(t) != Some(LinkAction::Reopen) {
            t += 10;
        }
        due.push(m.rescue_due());
        m.reopened(t);
    }
    assert_eq!(due, vec![None, None, Some(0), None, Some(1), None]);
    // A frame starts the count again.
    m.on_frame(t + 10, &frame(2));
    assert_eq!(m.rescue_due(), None);
    assert_eq!(m.reopen_attempt(), 0);
}

//! Fault injection for the simulated Create's serial link (issue #7): what a real robot, cable and
//! USB adapter do to a stream over weeks, as driver issue threads report them (`docs/SOURCES.md`).
//!
//! - [`FaultSpec`] says what to inject; it parses from a short string (`"drop=1e-4,text=0.002,quirk"`,
//!   presets `none`, `soak`, `all`; the grammar is in `parse`) or deserialises from TOML.
//! - [`FaultInjector`] applies it, deterministically from `(spec, seed)`. A transport that runs a
//!   [`SimRobot`] wires it in at three places:
//!
//! ```text
//! let mut faults = FaultInjector::new(spec, seed);
//! faults.configure(&mut robot);                       // once: quirk, line baud
//! robot.receive(&faults.host_bytes(&from_host));      // host → robot
//! robot.step();                                       // every 15 ms
//! let out = robot.take_output();
//! match faults.after_step(&mut robot, out) {          // robot → host
//!     StepOutcome { bytes, link: LinkFault::Normal } => write(bytes),
//!     StepOutcome { link: LinkFault::Hung, .. } => {} // nothing flows either way
//!     StepOutcome { link: LinkFault::Eof, .. } => close_connection(),
//! }
//! ```
//!
//! Per step, in order: an ending trip event is undone and a new one may start (it reaches the
//! robot's sensors on its next step); the link is hung, closes, or carries bytes; the carried bytes are
//! the boot banner (first step only, if asked), a text line between frames, the robot's bytes with
//! perhaps a text line spliced inside, all then subject to byte drops, flips and duplicates; a burst
//! may hold them back for a few steps; a steady latency delays them. Hangs and ends of file lose the
//! step's bytes and any held back or in flight. Whether each link event fires is drawn every step from one
//! stream, and bytes, text, durations, trips and host bytes have streams of their own, so changing
//! one rate barely moves when the other faults fire.

mod bytes;
mod counters;
mod parse;
mod spec;
mod text;
mod trip;

#[cfg(test)]
mod tests;
#[cfg(test)]
mod tests_robot;

use std::borrow::Cow;
use std::collections::VecDeque;

use crate::rng::Rng;
use crate::sim::STEP_SECONDS;
use crate::sim::robot::SimRobot;

pub use bytes::{ByteRates, ByteTally};
pub use counters::FaultCounters;
pub use parse::FaultSpecError;
pub use spec::{FaultSpec, MsRange, PRESETS};
pub use text::{battery_line, is_text_byte};
pub use trip::TripKind;

use trip::ActiveTrip;

/// What the link does in one 15 ms step.
#[derive(Debug, Clone, Copy, PartialEq, Eq, serde::Serialize)]
pub enum LinkFault {
    /// Bytes flow.
    Normal,
    /// Nothing flows either way this step (the robot keeps running; its output is lost).
    Hung,
    /// Close the connection now; the robot keeps running and a new connection may be opened later.
    Eof,
}

/// The result of one step: what reaches the wire now, and what the link does.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct StepOutcome {
    /// Robot→host bytes to write now (empty unless `link` is [`LinkFault::Normal`]).
    pub bytes: Vec<u8>,
    /// The link's state this step.
    pub link: LinkFault,
}

/// The per-step link events drawn at the start of a step (all drawn every step, so the sequence of
/// one kind does not depend on the rates of the others).
struct StepDraws {
    text: bool,
    inside: bool,
    burst: bool,
    hang: bool,
    eof: bool,
}

/// Applies a [`FaultSpec`] to a simulated robot's link, deterministically from its seed.
#[derive(Debug, Clone)]
pub struct FaultInjector {
    spec: FaultSpec,
    byte_rng: Rng,
    event_rng: Rng,
    text_rng: Rng,
    host_rng: Rng,
    trip_rng: Rng,
    duration_rng: Rng,
    counters: FaultCounters,
    banner_pending: bool,
    held: Vec<u8>,
    hold_steps_left: u32,
    /// Each step's bytes waiting out the steady latency, oldest first.
    in_flight: VecDeque<Vec<u8>>,
    hang_steps_left: u32,
    hung: bool,
    trip: Option<ActiveTrip>,
}

/// 15 ms steps covering `ms`, at least one.
fn steps_for_ms(ms: u32) -> u32 {
    ((f64::from(ms) / (STEP_SECONDS * 1000.0)).ceil() as u32).max(1)
}

/// A duration drawn uniformly from `range`, in whole steps.
fn draw_steps(range: MsRange, rng: &mut Rng) -> u32 {
    let span = u64::from(range.max_ms.saturating_sub(range.min_ms)) + 1;
    steps_for_ms(range.min_ms.saturating_add(rng.below(span) as u32))
}

impl FaultInjector {
    /// An injector of `spec`; all its randomness comes from `seed`.
    pub fn new(spec: FaultSpec, seed: u64) -> Self {
        // A fixed fork keeps the injector's draws apart from a robot built with the same seed.
        let root = Rng::new(seed).fork(0xFA17);
        FaultInjector {
            byte_rng: root.fork(1),
            event_rng: root.fork(2),
            text_rng: root.fork(3),
            host_rng: root.fork(4),
            trip_rng: root.fork(5),
            duration_rng: root.fork(6),
            counters: FaultCounters::default(),
            banner_pending: spec.banner,
            held: Vec::new(),
            hold_steps_left: 0,
            in_flight: VecDeque::new(),
            hang_steps_left: 0,
            hung: false,
            trip: None,
            spec,
        }
    }

    /// What this injector injects.
    pub fn spec(&self) -> &FaultSpec {
        &self.spec
    }

    /// What has been injected so far.
    pub fn counters(&self) -> &FaultCounters {
        &self.counters
    }

    /// True while the link is hung (from a [`LinkFault::Hung`] step until the next normal one).
    pub fn is_hung(&self) -> bool {
        self.hung
    }

    /// The trip event in progress, if any.
    pub fn active_trip(&self) -> Option<TripKind> {
        self.trip.map(|t| t.kind)
    }

    /// Applies the per-robot settings (mode+1 quirk, line baud); call right after creating the robot.
    pub fn configure(&self, robot: &mut SimRobot) {
        robot.set_mode_quirk(self.spec.mode_quirk);
        robot.set_line_baud(self.spec.line_baud);
    }

    /// Host→robot bytes, before `robot.receive`: lost while the link is hung, else subject to the host
    /// byte faults (borrowed unchanged when there are none).
    pub fn host_bytes<'a>(&mut self, bytes: &'a [u8]) -> Cow<'a, [u8]> {
        self.counters.host_bytes_seen += bytes.len() as u64;
        if self.hung {
            self.counters.host_lost += bytes.len() as u64;
            return Cow::Borrowed(&[]);
        }
        let rates = ByteRates {
            drop: self.spec.host_drop,
            flip: self.spec.host_flip,
            duplicate: 0.0,
        };
        if rates.is_none() {
            return Cow::Borrowed(bytes);
        }
        let mut tally = ByteTally::default();
        let out = bytes::corrupt(bytes, rates, &mut self.host_rng, &mut tally);
        self.counters.host_dropped += tally.dropped;
        self.counters.host_flipped += tally.flipped;
        Cow::Owned(out)
    }

    /// Starts a trip event of `kind` lasting `steps` robot steps (ending any event in progress); the
    /// robot's sensors see it from its next step on.
    pub fn inject_trip(&mut self, robot: &mut SimRobot, kind: TripKind, steps: u32) {
        if let Some(old) = self.trip.take() {
            old.kind.apply(robot, false);
        }
        kind.apply(robot, true);
        self.counters.trips += 1;
        match kind {
            TripKind::WheelDrop => self.counters.wheel_drop_trips += 1,
            TripKind::Cliff(_) => self.counters.cliff_trips += 1,
        }
        self.trip = Some(ActiveTrip {
            kind,
            steps_left: steps.max(1),
        });
    }

    /// Call once per 15 ms step after `robot.step()` with `robot.take_output()`: may start or end a
    /// trip event, and returns what reaches the wire now and what the link does.
    pub fn after_step(&mut self, robot: &mut SimRobot, out: Vec<u8>) -> StepOutcome {
        self.step_trip(robot);
        let draws = self.draw_step();
        let link = self.link_state(&draws);
        self.hung = link == LinkFault::Hung;
        if link != LinkFault::Normal {
            let in_flight: usize = self.in_flight.iter().map(Vec::len).sum();
            self.counters.lost_bytes += (out.len() + self.held.len() + in_flight) as u64;
            self.held.clear();
            self.hold_steps_left = 0;
            self.in_flight.clear();
            return StepOutcome {
                bytes: Vec::new(),
                link,
            };
        }
        let wire = self.wire_bytes(robot, out, &draws);
        let released = self.burst(wire, draws.burst);
        StepOutcome {
            bytes: self.delay(released),
            link,
        }
    }

    /// Ends a finished trip event; maybe starts a new one.
    fn step_trip(&mut self, robot: &mut SimRobot) {
        self.trip = self.trip.take().and_then(|t| t.tick(robot));
        let starts = self.trip_rng.chance(self.spec.trip);
        if starts && self.trip.is_none() {
            let kind = if self.trip_rng.below(2) == 0 {
                TripKind::WheelDrop
            } else {
                TripKind::Cliff(self.trip_rng.below(4) as usize)
            };
            let steps = draw_steps(self.spec.trip_ms, &mut self.trip_rng);
            self.inject_trip(robot, kind, steps);
        }
    }

    fn draw_step(&mut self) -> StepDraws {
        let r = &mut self.event_rng;
        let s = &self.spec;
        StepDraws {
            text: r.chance(s.text),
            inside: r.chance(s.text_inside),
            burst: r.chance(s.burst),
            hang: r.chance(s.hang),
            eof: r.chance(s.eof),
        }
    }

    /// Hung (continuing or starting a hang), end of file, or normal.
    fn link_state(&mut self, draws: &StepDraws) -> LinkFault {
        if self.hang_steps_left == 0 && draws.eof {
            self.counters.eofs += 1;
            return LinkFault::Eof;
        }
        if self.hang_steps_left == 0 && draws.hang {
            self.counters.hangs += 1;
            self.hang_steps_left = draw_steps(self.spec.hang_ms, &mut self.duration_rng);
        }
        if self.hang_steps_left > 0 {
            self.hang_steps_left -= 1;
            self.counters.hang_steps += 1;
            return LinkFault::Hung;
        }
        LinkFault::Normal
    }

    /// The bytes this step puts on the line: banner, text, robot output, byte faults.
    fn wire_bytes(&mut self, robot: &SimRobot, mut out: Vec<u8>, draws: &StepDraws) -> Vec<u8> {
        let mut text = String::new();
        if self.banner_pending {
            self.banner_pending = false;
            self.counters.banners += 1;
            text.push_str(&robot.boot_banner());
        }
        let mut between = draws.text;
        if draws.inside {
            let line = text::random_line(robot, &mut self.text_rng);
            if out.len() >= 2 {
                let at = 1 + self.text_rng.below(out.len() as u64 - 1) as usize;
                self.counters.text_inside += 1;
                self.counters.text_bytes += line.len() as u64;
                out.splice(at..at, line.bytes());
            } else {
                between = true;
            }
        }
        if between {
            self.counters.text_lines += 1;
            text.push_str(&text::random_line(robot, &mut self.text_rng));
        }
        self.counters.text_bytes += text.len() as u64;
        // Without text the robot's own buffer goes on to the line (a step allocates nothing).
        let wire = if text.is_empty() {
            out
        } else {
            let mut wire = text.into_bytes();
            wire.extend_from_slice(&out);
            wire
        };
        let rates = ByteRates {
            drop: self.spec.drop,
            flip: self.spec.flip,
            duplicate: self.spec.duplicate,
        };
        self.counters.bytes_seen += wire.len() as u64;
        if rates.is_none() {
            // `corrupt` would return a copy, drawing and counting nothing.
            return wire;
        }
        let mut tally = ByteTally::default();
        let wire = bytes::corrupt(&wire, rates, &mut self.byte_rng, &mut tally);
        self.counters.dropped_bytes += tally.dropped;
        self.counters.flipped_bytes += tally.flipped;
        self.counters.duplicated_bytes += tally.duplicated;
        wire
    }

    /// The steady latency: bytes come out `delay_ms` (in whole steps) after they went in.
    fn delay(&mut self, bytes: Vec<u8>) -> Vec<u8> {
        if self.spec.delay_ms == 0 {
            return bytes;
        }
        self.in_flight.push_back(bytes);
        if self.in_flight.len() > steps_for_ms(self.spec.delay_ms) as usize {
            self.in_flight.pop_front().unwrap_or_default()
        } else {
            Vec::new()
        }
    }

    /// Holds bytes during a burst; returns what is released now.
    fn burst(&mut self, wire: Vec<u8>, starts: bool) -> Vec<u8> {
        if self.hold_steps_left == 0 && starts {
            self.counters.bursts += 1;
            let longest = u64::from(self.spec.burst_steps.max(2));
            self.hold_steps_left = 2 + self.duration_rng.below(longest - 1) as u32;
        }
        if self.hold_steps_left == 0 {
            return wire;
        }
        self.held.extend_from_slice(&wire);
        self.hold_steps_left -= 1;
        if self.hold_steps_left == 0 {
            std::mem::take(&mut self.held)
        } else {
            self.counters.held_steps += 1;
            Vec::new()
        }
    }
}

//! Plausibility of a frame's values: can a Create have sent them at all?
//!
//! A stream frame passes the parser's structural checks (header, length, ids, 8-bit checksum) by
//! chance about once in 256 when it is damaged in a way that keeps its length: two bit flips that
//! cancel in the sum, or a frame shifted by a dropped or duplicated byte. Such a frame carries
//! values that are mostly impossible for a real robot: a bit set where the specification says the
//! bit is unused, a boolean of 37, a cliff signal of 40 000. [`implausible`] finds the first value
//! outside what the specifications allow, so the parser can reject the frame instead of committing
//! it (drivers that parse unframed replies learned this the hard way, e.g. pycreate2 issue 12: "validate ranges (e.g. 35 ≤ 3, cliff signals ≤ 4095) to detect
//! misalignment").
//!
//! Every bound is documented, and chosen so that **no genuine frame can break it**: where a source
//! is unsure, or the two models' documents disagree, the wider range is used, and a packet without a
//! range is not checked — except two bounds derived from physical limits with a wide margin (22
//! voltage, 54–57 motor currents). Should any bound still be wrong for some robot, the waiver below
//! limits the cost to a few frames. Sources: the packet tables of [C1 pp17–21, 24–25; C2 pp23–32, 37–39]
//! unless a page is given (tags: `docs/SOURCES.md`).
//!
//! | Packet | Create 1 | Create 2 | Source / reasoning |
//! |---|---|---|---|
//! | 7 bumps & wheel drops | 0–31 | 0–15 | C1 bits 0–4 (bit 4 caster drop), C2 bits 0–3, "(0–15)" [C1 p17; C2 p24] |
//! | 8 wall, 9–12 cliffs, 13 virtual wall | 0–1 | 0–1 | booleans, "0–1" |
//! | 14 overcurrents | 0–31 | 0–31 | bits 0–4; C2 says 0–29 but bit 1 is "reserved", so not assumed 0 |
//! | 15 C1 unused / C2 dirt detect | 0 | — | C1 "always 0"; C2 0–255 |
//! | 16 unused | 0 | 0 | "always 0" on both |
//! | 21 charging state | 0–5 | 0–6 | codes 0–5 [C1 p19; C2 p27]; the C2 membership table says 0–6 |
//! | 22 voltage | 0–25 000 mV | 0–25 000 mV | *derived*: battery rail 10–20.5 V incl. charger \[BATT\], + 20 % |
//! | 27 wall signal | 0–4095 | 0–1023 | "0–4095" / "0–1023" |
//! | 28–31 cliff signals | 0–4095 | 0–4095 | "0–4095"; drivers check it to detect misaligned replies |
//! | 32 cargo-bay digital inputs | 0–31 | — | C1 bits 0–4; the C2 "unused" byte is not said to be 0 |
//! | 33 cargo-bay analog signal | 0–1023 | — | C1 10-bit; C2 unused bytes |
//! | 34 charging sources | 0–3 | 0–3 | bits 0–1, "0–3" |
//! | 35 OI mode | 0–4 | 0–4 | 0–3, plus the mode+1 firmware quirk (create_robot#64, libcreate#67) |
//! | 36 song number | 0–15 | 0–15 | C1 0–15; C2 table 0–4 but its text says 0–15 |
//! | 37 song playing | 0–1 | 0–1 | boolean |
//! | 38 stream packet count | 0–43 | 0–108 | C1 0–43 (quick reference 0–42), C2 0–108 |
//! | 39 requested velocity | ±500 | ±500 | "−500..500 mm/s" (see the note on waivers) |
//! | 41, 42 requested right / left velocity | ±500 | ±500 | "−500..500 mm/s" |
//! | 45 light bumper | — | 0–127 | "0–127" [C2 p38] |
//! | 46–51 light-bump signals | — | 0–4095 | "0–4095" |
//! | 54–57 wheel / brush motor currents | — | ±10 000 mA | *derived*: no documented range; brush drivers rated ≤ 1.45 A \[BATT\], wheels limited at 1 A [C1 p10]; 10 A is several times any stall |
//! | 58 stasis | — | 0–3 | bits 0–1 [C2 p32, p38] |
//! | 19 distance (frame after a frame) | ±500 mm | ±500 mm | 15 ms at 500 mm/s is 7.5 mm; see below |
//! | 20 angle (frame after a frame) | ±360° | ±360° | 15 ms at 4.3 rad/s is 3.7° (×3.1 on C2 fw ≤ 3.4.0 [C2 p27]) |
//!
//! Not checked, on purpose: 17/52/53 IR codes, 18 buttons (unused bits not stated to be 0), 23 battery
//! current (charger transients undocumented), 24 temperature, 25/26 battery charge and capacity (no
//! documented limit; charge vs capacity is an estimate the firmware may get wrong), 43/44 encoders
//! (wrap), 40 requested radius (any value is echoed; C2 firmware < 3.3.0 reports it wrong).
//!
//! **Waivers.** A damaged frame is an isolated event: the frames around it are good. A value that
//! breaks its bound in many frames in a row is therefore genuine, whatever the documents say (a
//! firmware that echoes an out-of-range Drive velocity in 39, a pack above 25 V). The parser waives a
//! packet's bound after [`WAIVE_AFTER`] consecutive frames rejected for that packet with no frame
//! accepted between them, so a wrong bound costs a fraction of a second of frames, not the link.
//! (The simulator, for one, echoes a Drive velocity in 39 without clamping it to ±500 mm/s; the host
//! never sends one out of range.)
//!
//! Distance (19) and angle (20) are what accumulated **since the last report** [C1 p18–19; C2 p27]:
//! in a running stream that is 15 ms, but the first frame after a pause, a new stream request or a
//! reconnect may carry any amount (capped at ±32767). They are therefore checked only for a frame
//! that directly follows an accepted frame ([`FrameContext::FollowsFrame`]); the parser decides that
//! (see [`super::parser`]). The ±500 mm and ±360° bounds leave a wide margin (a whole second of full
//! speed) for timing jitter and frames the robot could not send.

use super::packets::id;
use super::spec::PacketFacts;
use super::{Model, SensorValues};

/// One documented range of one packet's raw value.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Bound {
    /// Packet id (7–58).
    pub id: u8,
    /// Smallest value a Create can report.
    pub min: i32,
    /// Largest value a Create can report.
    pub max: i32,
}

/// Why a frame's values cannot come from a Create: the first packet found outside its bound.
#[derive(Debug, Clone, Copy, PartialEq, Eq, thiserror::Error, serde::Serialize)]
#[error("packet {id} = {value} is outside {min}..={max}, impossible for a Create")]
pub struct Implausible {
    /// The packet.
    pub id: u8,
    /// The value the frame carried.
    pub value: i32,
    /// The bound it broke.
    pub min: i32,
    /// The bound it broke.
    pub max: i32,
}

/// Where a frame sits in the stream, which decides whether its odometry is bounded.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum FrameContext {
    /// The frame directly follows an accepted frame (one 15 ms stream period after it): distance and
    /// angle hold 15 ms of motion and are bounded.
    FollowsFrame,
    /// The first frame after a start, a reconnect, a pause or skipped bytes: distance and angle may
    /// hold any accumulated motion and are not checked.
    First,
}

const fn b(id: u8, min: i32, max: i32) -> Bound {
    Bound { id, min, max }
}

/// The largest plausible battery voltage, mV (see the module table).
pub const MAX_VOLTAGE_MV: i32 = 25_000;
/// The largest plausible motor current (packets 54–57), mA, either sign.
pub const MAX_MOTOR_CURRENT_MA: i32 = 10_000;
/// Consecutive frames rejected for the same packet, none accepted between, after which the parser
/// takes the value as genuine and stops checking that packet.
pub const WAIVE_AFTER: u32 = 16;
/// The largest plausible distance in a frame that follows a frame, mm.
pub const MAX_FRAME_DISTANCE_MM: i32 = 500;
/// The largest plausible angle in a frame that follows a frame, degrees.
pub const MAX_FRAME_ANGLE_DEG: i32 = 360;

/// The bounds checked in every frame of a model with the Create 1's packet facts (packets 7–42).
static CREATE1: &[Bound] = &[
    b(id::BUMPS_WHEEL_DROPS, 0, 31),
    b(id::WALL, 0, 1),
    b(id::CLIFF_LEFT, 0, 1),
    b(id::CLIFF_FRONT_LEFT, 0, 1),
    b(id::CLIFF_FRONT_RIGHT, 0, 1),
    b(id::CLIFF_RIGHT, 0, 1),
    b(id::VIRTUAL_WALL, 0, 1),
    b(id::OVERCURRENTS, 0, 31),
    b(id::DIRT_DETECT, 0, 0),
    b(id::UNUSED_16, 0, 0),
    b(id::CHARGING_STATE, 0, 5),
    b(id::VOLTAGE, 0, MAX_VOLTAGE_MV),
    b(id::WALL_SIGNAL, 0, 4095),
    b(id::CLIFF_LEFT_SIGNAL, 0, 4095),
    b(id::CLIFF_FRONT_LEFT_SIGNAL, 0, 4095),
    b(id::CLIFF_FRONT_RIGHT_SIGNAL, 0, 4095),
    b(id::CLIFF_RIGHT_SIGNAL, 0, 4095),
    b(id::CARGO_BAY_DIGITAL_INPUTS, 0, 31),
    b(id::CARGO_BAY_ANALOG_SIGNAL, 0, 1023),
    b(id::CHARGING_SOURCES, 0, 3),
    b(id::OI_MODE, 0, 4),
    b(id::SONG_NUMBER, 0, 15),
    b(id::SONG_PLAYING, 0, 1),
    b(id::STREAM_PACKET_COUNT, 0, 43),
    b(id::REQUESTED_VELOCITY, -500, 500),
    b(id::REQUESTED_RIGHT_VELOCITY, -500, 500),
    b(id::REQUESTED_LEFT_VELOCITY, -500, 500),
];

/// The bounds checked in every frame of a model with the Create 2's packet facts (packets 7–58).
static CREATE2: &[Bound] = &[
    b(id::BUMPS_WHEEL_DROPS, 0, 15),
    b(id::WALL, 0, 1),
    b(id::CLIFF_LEFT, 0, 1),
    b(id::CLIFF_FRONT_LEFT, 0, 1),
    b(id::CLIFF_FRONT_RIGHT, 0, 1),
    b(id::CLIFF_RIGHT, 0, 1),
    b(id::VIRTUAL_WALL, 0, 1),
    b(id::OVERCURRENTS, 0, 31),
    b(id::UNUSED_16, 0, 0),
    b(id::CHARGING_STATE, 0, 6),
    b(id::VOLTAGE, 0, MAX_VOLTAGE_MV),
    b(id::WALL_SIGNAL, 0, 1023),
    b(id::CLIFF_LEFT_SIGNAL, 0, 4095),
    b(id::CLIFF_FRONT_LEFT_SIGNAL, 0, 4095),
    b(id::CLIFF_FRONT_RIGHT_SIGNAL, 0, 4095),
    b(id::CLIFF_RIGHT_SIGNAL, 0, 4095),
    b(id::CHARGING_SOURCES, 0, 3),
    b(id::OI_MODE, 0, 4),
    b(id::SONG_NUMBER, 0, 15),
    b(id::SONG_PLAYING, 0, 1),
    b(id::STREAM_PACKET_COUNT, 0, 108),
    b(id::REQUESTED_VELOCITY, -500, 500),
    b(id::REQUESTED_RIGHT_VELOCITY, -500, 500),
    b(id::REQUESTED_LEFT_VELOCITY, -500, 500),
    b(id::LIGHT_BUMPER, 0, 127),
    b(id::LIGHT_BUMP_LEFT_SIGNAL, 0, 4095),
    b(id::LIGHT_BUMP_FRONT_LEFT_SIGNAL, 0, 4095),
    b(id::LIGHT_BUMP_CENTER_LEFT_SIGNAL, 0, 4095),
    b(id::LIGHT_BUMP_CENTER_RIGHT_SIGNAL, 0, 4095),
    b(id::LIGHT_BUMP_FRONT_RIGHT_SIGNAL, 0, 4095),
    b(id::LIGHT_BUMP_RIGHT_SIGNAL, 0, 4095),
    b(
        id::LEFT_MOTOR_CURRENT,
        -MAX_MOTOR_CURRENT_MA,
        MAX_MOTOR_CURRENT_MA,
    ),
    b(
        id::RIGHT_MOTOR_CURRENT,
        -MAX_MOTOR_CURRENT_MA,
        MAX_MOTOR_CURRENT_MA,
    ),
    b(
        id::MAIN_BRUSH_CURRENT,
        -MAX_MOTOR_CURRENT_MA,
        MAX_MOTOR_CURRENT_MA,
    ),
    b(
        id::SIDE_BRUSH_CURRENT,
        -MAX_MOTOR_CURRENT_MA,
        MAX_MOTOR_CURRENT_MA,
    ),
    b(id::STASIS, 0, 3),
];

/// Odometry bounds, checked only in a frame that follows a frame (both models).
static ODOMETRY: &[Bound] = &[
    b(id::DISTANCE, -MAX_FRAME_DISTANCE_MM, MAX_FRAME_DISTANCE_MM),
    b(id::ANGLE, -MAX_FRAME_ANGLE_DEG, MAX_FRAME_ANGLE_DEG),
];

/// The bounds checked in every frame from `model` (odometry excluded: see [`odometry_bounds`]), the
/// table its spec files it under ([`super::ModelSpec::packet_facts`]).
pub fn bounds(model: Model) -> &'static [Bound] {
    match model.spec().packet_facts {
        PacketFacts::Create1 => CREATE1,
        PacketFacts::Create2 => CREATE2,
    }
}

/// The distance and angle bounds of a frame that follows a frame.
pub fn odometry_bounds() -> &'static [Bound] {
    ODOMETRY
}

/// The first value of `values` that no `model` Create can report in a frame in `context`, or `None`
/// when every present value is plausible. Absent packets are not checked.
pub fn implausible(
    values: &SensorValues,
    model: Model,
    context: FrameContext,
) -> Option<Implausible> {
    implausible_except(values, model, context, Waived::NONE)
}

/// A set of packets whose bounds are not checked (ids 0–63).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct Waived(u64);

impl Waived {
    /// No packet waived.
    pub const NONE: Waived = Waived(0);

    /// Adds packet `id` (ids above 63 are ignored: there are none).
    pub fn insert(&mut self, id: u8) {
        if id < 64 {
            self.0 |= 1 << id;
        }
    }

    /// Whether packet `id`'s bound is waived.
    pub fn contains(self, id: u8) -> bool {
        id < 64 && self.0 & (1 << id) != 0
    }

    /// The waived packet ids, in increasing order.
    pub fn ids(self) -> impl Iterator<Item = u8> {
        (0..64u8).filter(move |&id| self.contains(id))
    }
}

/// Like [`implausible`], but not checking the packets in `waived`.
pub fn implausible_except(
    values: &SensorValues,
    model: Model,
    context: FrameContext,
    waived: Waived,
) -> Option<Implausible> {
    let odometry = match context {
        FrameContext::FollowsFrame => ODOMETRY,
        FrameContext::First => &[],
    };
    // The packets to check are those present and not waived: one mask for the whole frame instead of
    // two tests per bound (`Waived::contains`, `SensorValues::get`). Bounds are tried in the same order,
    // so the same first one is reported.
    let (slots, present) = values.slots();
    let checked = present & !waived.0;
    bounds(model).iter().chain(odometry).find_map(|bound| {
        let i = usize::from(bound.id);
        if i >= 64 || checked & (1 << i) == 0 {
            return None;
        }
        let value = *slots.get(i)?;
        (!(bound.min..=bound.max).contains(&value)).then_some(Implausible {
            id: bound.id,
            value,
            min: bound.min,
            max: bound.max,
        })
    })
}

/// The bounds [`implausible_except`] checks for one model, frame context and set of checked packets,
/// as one entry per packet-id slot, so that a whole frame is tested without a branch per bound.
#[derive(Debug, Clone, PartialEq, Eq)]
struct BoundTable {
    /// The packet's `min`, or `i32::MIN` for a packet not checked.
    lo: [i32; 64],
    /// `max − min` as unsigned, or `u32::MAX` for a packet not checked (then no value is out).
    span: [u32; 64],
    /// False when a packet has two bounds (none has): the table cannot say, ask the search.
    exact: bool,
}

impl BoundTable {
    fn new(model: Model, context: FrameContext, checked: u64) -> Self {
        let mut table = BoundTable {
            lo: [i32::MIN; 64],
            span: [u32::MAX; 64],
            exact: true,
        };
        let odometry = match context {
            FrameContext::FollowsFrame => ODOMETRY,
            FrameContext::First => &[],
        };
        for bound in bounds(model).iter().chain(odometry) {
            let i = usize::from(bound.id);
            if i >= 64 || checked & (1 << i) == 0 {
                continue;
            }
            if let (Some(lo), Some(span)) = (table.lo.get_mut(i), table.span.get_mut(i)) {
                if *span != u32::MAX {
                    table.exact = false;
                }
                *lo = bound.min;
                *span = bound.max.wrapping_sub(bound.min) as u32;
            }
        }
        table
    }

    /// Whether any checked slot is outside its bound: `v − min` as unsigned exceeds `max − min`
    /// exactly when `v` is outside `min..=max` (every bound has `min <= max`).
    fn any_out(&self, slots: &[i32]) -> bool {
        !self.exact
            || slots
                .iter()
                .zip(&self.lo)
                .zip(&self.span)
                .fold(false, |out, ((&v, &lo), &span)| {
                    out | (v.wrapping_sub(lo) as u32 > span)
                })
    }
}

/// [`implausible_except`] for a parser's frames, quicker: the bounds for the frames' model and
/// checked packets are laid out once ([`BoundTable`]), a frame is first tested against all of them
/// at once, and only a frame that breaks one is searched, in order, for the bound to report. The
/// same answers.
#[derive(Debug, Clone)]
pub(crate) struct FrameCheck {
    model: Model,
    checked: u64,
    first: BoundTable,
    follows: BoundTable,
}

impl FrameCheck {
    /// [`implausible_except`]`(values, model, context, waived)`, through `cache` (built or rebuilt
    /// when the model or the checked packets change).
    pub(crate) fn implausible(
        cache: &mut Option<FrameCheck>,
        values: &SensorValues,
        model: Model,
        context: FrameContext,
        waived: Waived,
    ) -> Option<Implausible> {
        let (slots, present) = values.slots();
        let checked = present & !waived.0;
        let check = match cache {
            Some(c) if c.model == model && c.checked == checked => c,
            _ => cache.insert(FrameCheck {
                model,
                checked,
                first: BoundTable::new(model, FrameContext::First, checked),
                follows: BoundTable::new(model, FrameContext::FollowsFrame, checked),
            }),
        };
        let table = match context {
            FrameContext::First => &check.first,
            FrameContext::FollowsFrame => &check.follows,
        };
        if table.any_out(slots) {
            implausible_except(values, model, context, waived)
        } else {
            None
        }
    }
}

#[cfg(test)]
mod tests;

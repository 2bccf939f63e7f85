//! The observation vector: one sensor snapshot as a named vector of every sensor dimension, each
//! scaled to `[0, 1]`.
//!
//! Modayil & Sutton scaled "each dimension of the robot's observation vector … to between \[0,1\]" and
//! tiled each one into 10 tiles of width 0.1. On a Create 1 the vector has 44 dimensions: the 36 single
//! packets of group 6 (ids 7–42), with packet 7 (bumps and wheel drops) and packet 14 (overcurrents)
//! each expanded into one dimension per bit: 36 − 2 + 5 + 5 = 44. Every other packet is one dimension,
//! including bit fields such as buttons (18) and charging sources (34), whose raw integer is scaled.
//!
//! On a Create 2 (packets 7–58) the analogous layout expands the four bit-field packets whose bits are
//! independent sensors: 7 (4 bits, no caster), 14 (4 bits: the reserved bit 1 is left out), 45 (light
//! bumper, 6 bits) and 58 (stasis, 2 bits); that gives 52 − 4 + 4 + 4 + 6 + 2 = 64 dimensions.
//!
//! Scaling: `clamp((raw − min) / (max − min), 0, 1)` for a whole-packet dimension, the bit itself
//! (0 or 1) for a bit dimension. A packet absent from the snapshot gives `NaN`, which the tile coder
//! treats as "no feature for this tiling" (see [`crate::learn::tiles`]); it is never silently zero.
//!
//! Ranges come from the OI specifications' packet tables [C1 pp17–21; C2 pp23–32]. Where the spec range is
//! far wider than anything the robot reports in use (voltage 0–65535 mV, current ±32768 mA), a
//! physical range is used instead and justified next to the entry, so that 10 tiles of width 0.1 still
//! separate the values that occur.

use crate::oi::spec::PacketFacts;
use crate::oi::{Model, SensorValues};

/// One dimension of the observation vector.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObsDim {
    /// A snake_case name, the same on both models when the meaning is the same.
    pub name: &'static str,
    /// The sensor packet the value comes from.
    pub packet: u8,
    /// For a bit dimension, the bit of the packet's value (0 = least significant).
    pub bit: Option<u8>,
    /// The raw value mapped to 0.0 (ignored for bit dimensions, which are 0 or 1).
    pub min: f64,
    /// The raw value mapped to 1.0.
    pub max: f64,
}

impl ObsDim {
    /// A whole-packet dimension scaled from `[min, max]`.
    const fn value(name: &'static str, packet: u8, min: f64, max: f64) -> Self {
        ObsDim {
            name,
            packet,
            bit: None,
            min,
            max,
        }
    }

    /// One bit of a bit-field packet.
    const fn bit(name: &'static str, packet: u8, bit: u8) -> Self {
        ObsDim {
            name,
            packet,
            bit: Some(bit),
            min: 0.0,
            max: 1.0,
        }
    }

    /// Scales one raw packet value into `[0, 1]` for this dimension (NaN only if the range is empty).
    pub fn scale_raw(&self, raw: i32) -> f64 {
        match self.bit {
            Some(b) => f64::from(raw.checked_shr(u32::from(b)).unwrap_or(0) & 1),
            None => ((f64::from(raw) - self.min) / (self.max - self.min)).clamp(0.0, 1.0),
        }
    }
}

use ObsDim as D;

/// Distance (packet 19) range, mm per stream frame. The firmware reports the distance since the last
/// frame (15 ms); at the 500 mm/s top wheel speed that is at most 7.5 mm, so ±10 mm covers every
/// legitimate value with 2 mm tiles (200 mm/s = 3 mm per frame lands one tile away from standstill).
const DISTANCE_MM: f64 = 10.0;
/// Angle (packet 20) range, degrees per frame: the fastest in-place turn (≈ 3.9 rad/s on a Create 1,
/// 4.3 rad/s on a Create 2) is ≈ 3.7° per 15 ms frame; ±5° gives one tile per integer degree.
const ANGLE_DEG: f64 = 5.0;
/// Battery voltage (22), mV. The spec range 0–65535 is useless for tiling. A NiMH pack shuts off below
/// ≈ 13 V and charges to ≈ 17 V; a Create 2 Li-ion pack idles ≈ 16 V; 12–18 V covers both with 0.6 V tiles.
const VOLTAGE_MV: (f64, f64) = (12_000.0, 18_000.0);
/// Battery current (23), mA, negative = discharging. Driving draws ≈ 0.5–1 A, each stalled wheel ≥ 1 A
/// (the Create 1 wheel over-current limit) plus the idle draw, charging is ≈ +1 A: −3000…+1500 mA.
const CURRENT_MA: (f64, f64) = (-3_000.0, 1_500.0);
/// Battery temperature (24), °C: indoor operation and charging stay within 0–50 °C.
const TEMPERATURE_C: (f64, f64) = (0.0, 50.0);
/// Battery charge and capacity (25, 26), mAh: the Create 1 NiMH pack is ≈ 3000 mAh, the Create 2
/// Li-ion pack reports 2068 mAh (Roomba packs up to ≈ 2700 mAh): 0–3000 mAh.
const CHARGE_MAH: (f64, f64) = (0.0, 3_000.0);
/// Requested wheel or average velocity (39, 41, 42), mm/s: the OI range −500…500.
const VELOCITY: (f64, f64) = (-500.0, 500.0);
/// Requested radius (40), mm: the OI range −2000…2000. The "straight" codes 32767 and −32768 clamp to
/// opposite ends; the experiments drive with Drive Direct, which leaves this packet constant.
const RADIUS: (f64, f64) = (-2_000.0, 2_000.0);
/// 12-bit analog signals (cliff, light-bump, Create 1 wall signal): 0–4095.
const SIGNAL_12BIT: (f64, f64) = (0.0, 4_095.0);
/// Create 2 motor currents (54–57), mA. No primary data on stall currents: a stalled wheel is modelled
/// above the 1 A Create 1 limit and the main brush is rated 1.45 A, so −500…1500 mA (back-driven motors
/// can read slightly negative).
const MOTOR_MA: (f64, f64) = (-500.0, 1_500.0);

/// The 44 dimensions of the Create 1 observation (group 6, packets 7–42), in packet order.
const CREATE1_DIMS: [ObsDim; 44] = [
    D::bit("bump_right", 7, 0),
    D::bit("bump_left", 7, 1),
    D::bit("wheel_drop_right", 7, 2),
    D::bit("wheel_drop_left", 7, 3),
    D::bit("wheel_drop_caster", 7, 4),
    D::value("wall", 8, 0.0, 1.0),
    D::value("cliff_left", 9, 0.0, 1.0),
    D::value("cliff_front_left", 10, 0.0, 1.0),
    D::value("cliff_front_right", 11, 0.0, 1.0),
    D::value("cliff_right", 12, 0.0, 1.0),
    D::value("virtual_wall", 13, 0.0, 1.0),
    // [C1 p17]: bit0 = LD1, bit1 = LD0 (sic), bit2 = LD2, bit3 = right wheel, bit4 = left wheel.
    D::bit("overcurrent_ld1", 14, 0),
    D::bit("overcurrent_ld0", 14, 1),
    D::bit("overcurrent_ld2", 14, 2),
    D::bit("overcurrent_right_wheel", 14, 3),
    D::bit("overcurrent_left_wheel", 14, 4),
    // 15 and 16 are unused bytes on the Create 1 (always 0): kept as constant dimensions, as in the paper.
    D::value("unused_15", 15, 0.0, 255.0),
    D::value("unused_16", 16, 0.0, 255.0),
    // 255 = no IR byte on the Create 1.
    D::value("ir_omni", 17, 0.0, 255.0),
    // Bits 0 (Play) and 2 (Advance): values 0, 1, 4, 5.
    D::value("buttons", 18, 0.0, 5.0),
    D::value("distance", 19, -DISTANCE_MM, DISTANCE_MM),
    D::value("angle", 20, -ANGLE_DEG, ANGLE_DEG),
    D::value("charging_state", 21, 0.0, 5.0),
    D::value("voltage", 22, VOLTAGE_MV.0, VOLTAGE_MV.1),
    D::value("current", 23, CURRENT_MA.0, CURRENT_MA.1),
    D::value("battery_temperature", 24, TEMPERATURE_C.0, TEMPERATURE_C.1),
    D::value("battery_charge", 25, CHARGE_MAH.0, CHARGE_MAH.1),
    D::value("battery_capacity", 26, CHARGE_MAH.0, CHARGE_MAH.1),
    D::value("wall_signal", 27, SIGNAL_12BIT.0, SIGNAL_12BIT.1),
    D::value("cliff_left_signal", 28, SIGNAL_12BIT.0, SIGNAL_12BIT.1),
    D::value(
        "cliff_front_left_signal",
        29,
        SIGNAL_12BIT.0,
        SIGNAL_12BIT.1,
    ),
    D::value(
        "cliff_front_right_signal",
        30,
        SIGNAL_12BIT.0,
        SIGNAL_12BIT.1,
    ),
    D::value("cliff_right_signal", 31, SIGNAL_12BIT.0, SIGNAL_12BIT.1),
    // Cargo-bay digital inputs, 5 bits (device detect is high by default): 0–31.
    D::value("cargo_bay_digital_inputs", 32, 0.0, 31.0),
    // Cargo-bay analog input, 10-bit: 0–1023.
    D::value("cargo_bay_analog_signal", 33, 0.0, 1_023.0),
    D::value("charging_sources", 34, 0.0, 3.0),
    D::value("oi_mode", 35, 0.0, 3.0),
    D::value("song_number", 36, 0.0, 15.0),
    D::value("song_playing", 37, 0.0, 1.0),
    D::value("stream_packets", 38, 0.0, 43.0),
    D::value("requested_velocity", 39, VELOCITY.0, VELOCITY.1),
    D::value("requested_radius", 40, RADIUS.0, RADIUS.1),
    D::value("requested_right_velocity", 41, VELOCITY.0, VELOCITY.1),
    D::value("requested_left_velocity", 42, VELOCITY.0, VELOCITY.1),
];

/// The 64 dimensions of the Create 2 observation (group 100, packets 7–58), in packet order.
const CREATE2_DIMS: [ObsDim; 64] = [
    D::bit("bump_right", 7, 0),
    D::bit("bump_left", 7, 1),
    D::bit("wheel_drop_right", 7, 2),
    D::bit("wheel_drop_left", 7, 3),
    // Deprecated on the Create 2: the same as the right light bumper.
    D::value("wall", 8, 0.0, 1.0),
    D::value("cliff_left", 9, 0.0, 1.0),
    D::value("cliff_front_left", 10, 0.0, 1.0),
    D::value("cliff_front_right", 11, 0.0, 1.0),
    D::value("cliff_right", 12, 0.0, 1.0),
    D::value("virtual_wall", 13, 0.0, 1.0),
    // [C2 p37]: bit0 side brush, bit1 reserved (left out), bit2 main brush, bit3 right, bit4 left wheel.
    D::bit("overcurrent_side_brush", 14, 0),
    D::bit("overcurrent_main_brush", 14, 2),
    D::bit("overcurrent_right_wheel", 14, 3),
    D::bit("overcurrent_left_wheel", 14, 4),
    D::value("dirt_detect", 15, 0.0, 255.0),
    D::value("unused_16", 16, 0.0, 255.0),
    // 0 = no character on the Create 2.
    D::value("ir_omni", 17, 0.0, 255.0),
    // Eight button bits: 0–255.
    D::value("buttons", 18, 0.0, 255.0),
    D::value("distance", 19, -DISTANCE_MM, DISTANCE_MM),
    D::value("angle", 20, -ANGLE_DEG, ANGLE_DEG),
    // The packet table says 0–5, the membership table 0–6.
    D::value("charging_state", 21, 0.0, 6.0),
    D::value("voltage", 22, VOLTAGE_MV.0, VOLTAGE_MV.1),
    D::value("current", 23, CURRENT_MA.0, CURRENT_MA.1),
    D::value("battery_temperature", 24, TEMPERATURE_C.0, TEMPERATURE_C.1),
    D::value("battery_charge", 25, CHARGE_MAH.0, CHARGE_MAH.1),
    D::value("battery_capacity", 26, CHARGE_MAH.0, CHARGE_MAH.1),
    // 10-bit on the Create 2 (deprecated; packet 51 carries the same signal).
    D::value("wall_signal", 27, 0.0, 1_023.0),
    D::value("cliff_left_signal", 28, SIGNAL_12BIT.0, SIGNAL_12BIT.1),
    D::value(
        "cliff_front_left_signal",
        29,
        SIGNAL_12BIT.0,
        SIGNAL_12BIT.1,
    ),
    D::value(
        "cliff_front_right_signal",
        30,
        SIGNAL_12BIT.0,
        SIGNAL_12BIT.1,
    ),
    D::value("cliff_right_signal", 31, SIGNAL_12BIT.0, SIGNAL_12BIT.1),
    D::value("unused_32", 32, 0.0, 255.0),
    D::value("unused_33", 33, 0.0, 65_535.0),
    D::value("charging_sources", 34, 0.0, 3.0),
    // 0–3, but some 600-series firmware reports mode + 1: 0–4 keeps that distinguishable.
    D::value("oi_mode", 35, 0.0, 4.0),
    D::value("song_number", 36, 0.0, 15.0),
    D::value("song_playing", 37, 0.0, 1.0),
    D::value("stream_packets", 38, 0.0, 108.0),
    D::value("requested_velocity", 39, VELOCITY.0, VELOCITY.1),
    D::value("requested_radius", 40, RADIUS.0, RADIUS.1),
    D::value("requested_right_velocity", 41, VELOCITY.0, VELOCITY.1),
    D::value("requested_left_velocity", 42, VELOCITY.0, VELOCITY.1),
    // Cumulative encoder counts wrap through the whole signed 16-bit range.
    D::value("left_encoder_counts", 43, -32_768.0, 32_767.0),
    D::value("right_encoder_counts", 44, -32_768.0, 32_767.0),
    D::bit("light_bumper_left", 45, 0),
    D::bit("light_bumper_front_left", 45, 1),
    D::bit("light_bumper_center_left", 45, 2),
    D::bit("light_bumper_center_right", 45, 3),
    D::bit("light_bumper_front_right", 45, 4),
    D::bit("light_bumper_right", 45, 5),
    D::value("light_bump_left_signal", 46, SIGNAL_12BIT.0, SIGNAL_12BIT.1),
    D::value(
        "light_bump_front_left_signal",
        47,
        SIGNAL_12BIT.0,
        SIGNAL_12BIT.1,
    ),
    D::value(
        "light_bump_center_left_signal",
        48,
        SIGNAL_12BIT.0,
        SIGNAL_12BIT.1,
    ),
    D::value(
        "light_bump_center_right_signal",
        49,
        SIGNAL_12BIT.0,
        SIGNAL_12BIT.1,
    ),
    D::value(
        "light_bump_front_right_signal",
        50,
        SIGNAL_12BIT.0,
        SIGNAL_12BIT.1,
    ),
    D::value(
        "light_bump_right_signal",
        51,
        SIGNAL_12BIT.0,
        SIGNAL_12BIT.1,
    ),
    D::value("ir_left", 52, 0.0, 255.0),
    D::value("ir_right", 53, 0.0, 255.0),
    D::value("left_motor_current", 54, MOTOR_MA.0, MOTOR_MA.1),
    D::value("right_motor_current", 55, MOTOR_MA.0, MOTOR_MA.1),
    D::value("main_brush_current", 56, MOTOR_MA.0, MOTOR_MA.1),
    D::value("side_brush_current", 57, MOTOR_MA.0, MOTOR_MA.1),
    // bit0 "toggling" (making forward progress), bit1 "disabled" (caster too dirty).
    D::bit("stasis_toggling", 58, 0),
    D::bit("stasis_disabled", 58, 1),
];

/// The observation layout of one robot model: which dimensions, in which order, with which ranges.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ObsLayout {
    model: Model,
    dims: &'static [ObsDim],
    /// The presence bits of the packets the dimensions read.
    packets: u64,
}

impl ObsLayout {
    /// The layout for `model`: 44 dimensions on a Create 1, 64 on a Create 2 (the table its spec files
    /// it under, [`crate::oi::ModelSpec::packet_facts`]).
    pub fn for_model(model: Model) -> Self {
        let (dims, packets): (&'static [ObsDim], u64) = match model.spec().packet_facts {
            PacketFacts::Create1 => (&CREATE1_DIMS, const { packet_mask(&CREATE1_DIMS) }),
            PacketFacts::Create2 => (&CREATE2_DIMS, const { packet_mask(&CREATE2_DIMS) }),
        };
        ObsLayout {
            model,
            dims,
            packets,
        }
    }

    /// The robot model this layout describes.
    pub fn model(&self) -> Model {
        self.model
    }

    /// Every dimension, in vector order.
    pub fn dims(&self) -> &[ObsDim] {
        self.dims
    }

    /// The number of dimensions.
    pub fn len(&self) -> usize {
        self.dims.len()
    }

    /// Always false: both layouts have dimensions (here for clippy's `len_without_is_empty`).
    pub fn is_empty(&self) -> bool {
        self.dims.is_empty()
    }

    /// The position of the dimension called `name`.
    pub fn index_of(&self, name: &str) -> Option<usize> {
        self.dims.iter().position(|d| d.name == name)
    }

    /// The dimension names, in vector order.
    pub fn names(&self) -> impl Iterator<Item = &'static str> + '_ {
        self.dims.iter().map(|d| d.name)
    }

    /// Writes every dimension of `values` unscaled into `out` (cleared first): the packet's value in its
    /// own units, the bit (0 or 1) for a bit dimension, NaN for an absent packet.
    pub fn raw(&self, values: &SensorValues, out: &mut Vec<f64>) {
        out.clear();
        out.extend(self.dims.iter().map(|d| {
            values.get(d.packet).map_or(f64::NAN, |v| match d.bit {
                Some(b) => f64::from(v.checked_shr(u32::from(b)).unwrap_or(0) & 1),
                None => f64::from(v),
            })
        }));
    }

    /// Writes the scaled observation of `raw` into `out` (cleared first; `len()` values, each in
    /// `[0, 1]`, or `NaN` for a packet absent from `raw`). Does not allocate once `out` has capacity.
    pub fn scale(&self, raw: &SensorValues, out: &mut Vec<f64>) {
        out.clear();
        let (slots, present) = raw.slots();
        if present & self.packets == self.packets {
            // Every packet the layout reads is present (a whole frame's snapshot): read the slots
            // without asking each dimension's packet whether it is there. The same values.
            out.extend(
                self.dims
                    .iter()
                    .map(|d| d.scale_raw(slots.get(usize::from(d.packet)).copied().unwrap_or(0))),
            );
            return;
        }
        out.extend(
            self.dims
                .iter()
                .map(|d| raw.get(d.packet).map_or(f64::NAN, |v| d.scale_raw(v))),
        );
    }
}

impl ObsLayout {
    /// [`ObsLayout::scale`] of `raw`, given that `out` holds `scale` of `previous`: only the dimensions
    /// whose packet's value changed are scaled again. A dimension is a function of its packet's value
    /// alone, so every other one keeps the same bits. Falls back to `scale` unless both snapshots hold
    /// every packet the layout reads and `out` has one value per dimension.
    pub fn rescale(&self, raw: &SensorValues, previous: &SensorValues, out: &mut Vec<f64>) {
        let (slots, present) = raw.slots();
        let (before, present_before) = previous.slots();
        let complete =
            present & self.packets == self.packets && present_before & self.packets == self.packets;
        if !complete || out.len() != self.dims.len() {
            self.scale(raw, out);
            return;
        }
        for (d, o) in self.dims.iter().zip(out.iter_mut()) {
            let p = usize::from(d.packet);
            // Present, so below the slots' end: `get` never misses here.
            let now = slots.get(p).copied().unwrap_or(0);
            if before.get(p) != Some(&now) {
                *o = d.scale_raw(now);
            }
        }
    }
}

/// The presence bits of every packet `dims` read (packets 7–58: all below 64).
const fn packet_mask(dims: &[ObsDim]) -> u64 {
    let mut mask = 0u64;
    let mut i = 0;
    while i < dims.len() {
        mask |= 1u64 << dims[i].packet;
        i += 1;
    }
    mask
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::collections::HashSet;

    #[test]
    fn create1_has_the_papers_44_dimensions_over_group_6() {
        let layout = ObsLayout::for_model(Model::Create1);
        assert_eq!(layout.len(), 44);
        let packets: HashSet<u8> = layout.dims().iter().map(|d| d.packet).collect();
        assert_eq!(packets, (7..=42).collect::<HashSet<u8>>());
        assert_eq!(layout.dims().iter().filter(|d| d.packet == 7).count(), 5);
        assert_eq!(layout.dims().iter().filter(|d| d.packet == 14).count(), 5);
    }

    #[test]
    fn create2_covers_packets_7_to_58() {
        let layout = ObsLayout::for_model(Model::Create2);
        assert_eq!(layout.len(), 64);
        let packets: HashSet<u8> = layout.dims().iter().map(|d| d.packet).collect();
        assert_eq!(packets, (7..=58).collect::<HashSet<u8>>());
        assert_eq!(layout.dims().iter().filter(|d| d.packet == 7).count(), 4);
        assert!(layout.index_of("wheel_drop_caster").is_none());
    }

    #[test]
    fn names_are_unique_ranges_non_empty_and_in_packet_order() {
        for model in [Model::Create1, Model::Create2] {
            let layout = ObsLayout::for_model(model);
            let names: HashSet<&str> = layout.names().collect();
            assert_eq!(names.len(), layout.len(), "{model}");
            for pair in layout.dims().windows(2) {
                assert!(pair[0].packet <= pair[1].packet, "{model}: {:?}", pair[1]);
            }
            for d in layout.dims() {
                assert!(d.max > d.min, "{model}: {}", d.name);
                assert!(d.bit.is_none_or(|b| b < 8), "{model}: {}", d.name);
            }
        }
    }

    #[test]
    fn bits_and_ranges_scale_as_documented() {
        let layout = ObsLayout::for_model(Model::Create1);
        let mut raw = SensorValues::new();
        for id in 7..=42 {
            raw.set(id, 0);
        }
        raw.set(7, 0b10010); // bump left + caster drop
        raw.set(14, 0b11000); // both wheels over current
        raw.set(22, 15_000); // half of 12–18 V
        raw.set(23, -6_000); // beyond the range: clamps to 0
        raw.set(19, 5); // +5 mm of ±10 mm
        raw.set(42, 500);
        let mut out = Vec::new();
        layout.scale(&raw, &mut out);
        assert_eq!(out.len(), 44);
        let at = |name: &str| out[layout.index_of(name).unwrap()];
        assert_eq!(at("bump_right"), 0.0);
        assert_eq!(at("bump_left"), 1.0);
        assert_eq!(at("wheel_drop_caster"), 1.0);
        assert_eq!(at("overcurrent_ld1"), 0.0);
        assert_eq!(at("overcurrent_right_wheel"), 1.0);
        assert_eq!(at("overcurrent_left_wheel"), 1.0);
        assert!((at("voltage") - 0.5).abs() < 1e-12);
        assert_eq!(at("current"), 0.0);
        assert!((at("distance") - 0.75).abs() < 1e-12);
        assert_eq!(at("requested_left_velocity"), 1.0);
        assert!(out.iter().all(|v| (0.0..=1.0).contains(v)));
    }

    #[test]
    fn absent_packets_are_nan_not_zero() {
        let layout = ObsLayout::for_model(Model::Create2);
        let mut raw = SensorValues::new();
        raw.set(23, -500);
        let mut out = vec![7.0; 3];
        layout.scale(&raw, &mut out);
        assert_eq!(out.len(), 64);
        let current = layout.index_of("current").unwrap();
        assert!(out[current].is_finite());
        assert_eq!(out.iter().filter(|v| v.is_nan()).count(), 63);
    }

    proptest::proptest! {
        /// Any complete snapshot, whatever its raw values, scales into `[0, 1]` and activates exactly one
        /// tile per dimension in the paper's one-tiling-per-dimension coder (44 of 440 on a Create 1).
        #[test]
        fn every_complete_snapshot_activates_one_tile_per_dimension(
            raw in proptest::collection::vec(proptest::num::i32::ANY, 52),
            create2 in proptest::bool::ANY,
        ) {
            let model = if create2 { Model::Create2 } else { Model::Create1 };
            let layout = ObsLayout::for_model(model);
            let mut snapshot = SensorValues::new();
            for (id, v) in (7..=model.last_packet()).zip(&raw) {
                snapshot.set(id, *v);
            }
            let mut obs = Vec::new();
            layout.scale(&snapshot, &mut obs);
            proptest::prop_assert!(obs.iter().all(|v| (0.0..=1.0).contains(v)));
            let coder = crate::learn::TileCoder::one_dim(layout.len(), 10).unwrap();
            let mut active = Vec::new();
            coder.active(&obs, &mut active);
            proptest::prop_assert_eq!(active.len(), layout.len());
            proptest::prop_assert_eq!(coder.num_features(), 10 * layout.len());
            for (d, &i) in active.iter().enumerate() {
                proptest::prop_assert!(i / 10 == d, "feature {} outside tiling {}", i, d);
            }
        }
    }

    proptest::proptest! {
        /// Scaling only what changed since a previous snapshot gives the bits a full `scale` gives, for
        /// any two snapshots (complete or not, equal in some packets, different in others).
        #[test]
        fn rescaling_the_changed_dimensions_matches_a_full_scale(
            before in proptest::collection::vec(-3..3i32, 59),
            after in proptest::collection::vec(proptest::prop_oneof![-3..3i32, proptest::num::i32::ANY], 59),
            missing in proptest::option::of(7u8..=58),
            create2 in proptest::bool::ANY,
        ) {
            let layout = ObsLayout::for_model(if create2 { Model::Create2 } else { Model::Create1 });
            let snapshot = |raw: &[i32], skip: Option<u8>| {
                let mut v = SensorValues::new();
                for id in 7..=58u8 {
                    if Some(id) != skip {
                        v.set(id, raw[usize::from(id)]);
                    }
                }
                v
            };
            let (previous, now) = (snapshot(&before, None), snapshot(&after, missing));
            let mut out = Vec::new();
            layout.scale(&previous, &mut out);
            layout.rescale(&now, &previous, &mut out);
            let mut full = Vec::new();
            layout.scale(&now, &mut full);
            let bits = |v: &[f64]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            proptest::prop_assert_eq!(bits(&out), bits(&full));
        }
    }

    #[test]
    fn extreme_raw_values_stay_in_range() {
        for model in [Model::Create1, Model::Create2] {
            let layout = ObsLayout::for_model(model);
            for v in [i32::MIN, -32_768, -1, 0, 1, 255, 32_767, 65_535, i32::MAX] {
                for d in layout.dims() {
                    let s = d.scale_raw(v);
                    assert!((0.0..=1.0).contains(&s), "{model} {} {v} -> {s}", d.name);
                }
            }
        }
    }
}

//! [`ModelSpec`]: everything that differs between the robot models, in one table with one `const`
//! entry per model ([`CREATE1`], [`CREATE2`]), reached with [`Model::spec`](super::Model::spec).
//!
//! Every per-model decision in the crate reads a field of this table rather than matching on the
//! model: the serial rate, the packets and groups the robot answers, the stream's budget, which
//! opcodes exist and how many data bytes they take, the bits the LED and motor commands accept, what
//! the PWM Motors bytes mean, the drive limits, and capabilities such as encoders or a cargo bay.
//!
//! Tables with a row per sensor packet (the plausibility bounds in [`super::plausible`], the
//! observation layout in [`crate::obs`], the simulator's physical parameters in [`crate::sim::params`])
//! stay where they are documented, filed under a [`PacketFacts`] key that the entry names in
//! [`ModelSpec::packet_facts`]. This module depends on nothing else in the crate, so every other
//! module can read it; that is also why it names those tables by key instead of holding them.
//!
//! Adding a model is one entry here plus its packet facts: a new key (and a row in each table the
//! compiler then lists, as every lookup matches the key exhaustively), or an existing key when the
//! model answers the same packets with the same body — a Roomba 600-class robot speaks the
//! Create 2's OI, which \[C2\] is "based on".
//!
//! Facts: the two OI specifications, \[C1\] (Create 1) and \[C2\] (Create 2) with page numbers, and
//! \[KT\] for a measured speed step (tags: `docs/SOURCES.md`).

/// How many data bytes follow an opcode [C1 pp7–16; C2 pp8–22].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum DataShape {
    /// Exactly this many.
    Fixed(usize),
    /// A count byte N, then N bytes (Stream 148, Query List 149, Script 152).
    CountedList,
    /// Song number, count N, then N (note, duration) pairs (Song 140).
    Song,
}

/// What the three data bytes of PWM Motors (opcode 144) drive, and their ranges.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum PwmMotorsDuty {
    /// Create 1 "PWM Low Side Drivers": low-side drivers 2, 1, 0, each a duty of 0–128 (128 = 100 %)
    /// [C1 p10].
    LowSideDrivers,
    /// Create 2 "PWM Motors": main brush and side brush −127…127 (signed bytes), vacuum 0…127
    /// [C2 pp8–22].
    Brushes,
}

/// The key under which the per-packet tables that live outside this module (plausibility bounds,
/// observation layout, simulator physics) file a model. Each lookup matches it exhaustively, so a new
/// key makes the compiler list every table that needs a row for it.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum PacketFacts {
    /// The Create 1's packets 7–42 [C1 pp17–21, 24–25] and its body.
    Create1,
    /// The Create 2's packets 7–58 [C2 pp23–32, 37–39] and its body.
    Create2,
}

/// Everything that differs between two robot models, each field with its source.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ModelSpec {
    /// A short lowercase name, as used in the configuration, on the command line and by serde.
    pub name: &'static str,
    /// Default serial rate, bits/s: 57600 [C1 p5], 115200 [C2 p4].
    pub baud: u32,
    /// The group packet that holds every single sensor packet the model has, from 7 up: 6 (packets
    /// 7–42) [C1 p17, p24], 100 (packets 7–58) [C2 p37]. A single packet is available exactly when it
    /// is a member of this group.
    pub all_sensors_group: u8,
    /// The highest single sensor packet id: 42 [C1 pp17–21], 58 [C2 pp23–32] (the last member of
    /// `all_sensors_group`).
    pub last_packet: u8,
    /// The group packets the model answers: 0–6 [C1 p17, p24]; 0–6, 100, 101, 106, 107 [C2 p37].
    pub groups: &'static [u8],
    /// Period of the sensor stream, ms: 15 on both [C1 p14; C2 p22].
    pub stream_period_ms: u32,
    /// Most packet ids one Stream (148) or Query List (149) may name: 43 [C1 p14]; 108, the range of
    /// packet 38 "number of stream packets" [C2 p29].
    pub max_packet_list_len: usize,
    /// Highest song slot of Song (140) and Play (141): 15 [C1 p11], 4 [C2 p19].
    pub last_song_number: u8,
    /// Bits the Motors command (138) may set: low-side drivers 0–2 (0x07) [C1 p10]; side brush,
    /// vacuum, main brush, side-brush direction, main-brush direction (0x1F) [C2 p15].
    pub motor_bits: u8,
    /// Bits the LEDs command (139) may set: Play (bit 1) and Advance (bit 3) [C1 p9]; Debris, Spot,
    /// Dock, Check Robot (bits 0–3) [C2 p16].
    pub led_bits: u8,
    /// What the PWM Motors (144) data bytes mean [C1 p10; C2 pp8–22].
    pub pwm_motors: PwmMotorsDuty,
    /// The opcodes beyond those both models share, with their data bytes, in increasing order
    /// [C1 pp7–16; C2 pp8–22]. Opcode 136 is in both lists with a different shape: Demo with one
    /// byte on the Create 1, Max with none on the Create 2.
    pub model_opcodes: &'static [(u8, DataShape)],
    /// Packet 17 when no IR byte is received: 255 [C1 p18], 0 [C2 p26]. The simulator reports the
    /// same for the Create 2's left and right receivers (52, 53).
    pub ir_no_byte: u8,
    /// Fastest wheel speed a Drive (137) or Drive Direct (145) may ask for, mm/s, either sign: 500
    /// on both [C1 p9; C2 p13].
    pub max_wheel_speed_mm_s: i16,
    /// Spacing of the discrete speeds the wheel speed controller runs at, mm/s: ≈28.5 on the
    /// Create 2 [C2 p13–14; KT]. The Create 1 document says nothing about a step (`None`: treated as
    /// continuous).
    pub speed_step_mm_s: Option<f64>,
    /// Current at which a drive wheel is limited and its over-current flag set, A: 1.0 on the
    /// Create 1 [C1 p10, p17]. The Create 2 document gives no limit (`None`).
    pub wheel_overcurrent_limit_a: Option<f64>,
    /// Reset (opcode 7) exists: Create 2 only [C2 pp8–22]. The simulator also hears it in Off.
    pub has_reset_opcode: bool,
    /// Play (141) is ignored while a song is playing [C1 p13]; the Create 2 document does not say
    /// so, and the simulator lets a new Play start over there.
    pub play_ignored_while_playing: bool,
    /// Packet 7 has the caster wheel-drop bit (bit 4): Create 1 only [C1 p17; C2 p24].
    pub has_caster_drop: bool,
    /// Cargo-bay digital and analog inputs, packets 32 and 33 [C1 p20]; on the Create 2 those bytes
    /// are unused.
    pub has_cargo_bay: bool,
    /// Cumulative wheel encoder counts, packets 43 and 44 [C2 p30–31]: Create 2 only.
    pub has_encoders: bool,
    /// The light bumper, packets 45–51 [C2 p32, p38]: Create 2 only.
    pub has_light_bumpers: bool,
    /// Left and right IR receivers, packets 52 and 53 (members of group 101 [C2 p37]): Create 2 only.
    pub has_directional_ir: bool,
    /// Wheel and brush motor currents, packets 54–57 (members of group 101 [C2 p37]): Create 2 only.
    pub has_motor_currents: bool,
    /// The stasis caster, packet 58 [C2 p32, p38]: Create 2 only.
    pub has_stasis: bool,
    /// The key of this model's rows in the per-packet tables outside this module.
    pub packet_facts: PacketFacts,
}

impl ModelSpec {
    /// Bytes the robot can send in one stream period at its default baud, 10 bits a byte on the wire:
    /// 86 at 57600, 172 at 115200 [C1 p14; C2 p22].
    pub const fn stream_budget_bytes(&self) -> usize {
        (self.baud as usize * self.stream_period_ms as usize) / 10_000
    }

    /// The data bytes of opcode `op` if it is one of this model's own ([`ModelSpec::model_opcodes`]).
    pub fn model_opcode(&self, op: u8) -> Option<DataShape> {
        self.model_opcodes
            .iter()
            .find(|&&(code, _)| code == op)
            .map(|&(_, shape)| shape)
    }
}

/// The original iRobot Create (OI specification v2, 2006).
pub const CREATE1: ModelSpec = ModelSpec {
    name: "create1",
    baud: 57_600,
    all_sensors_group: 6,
    last_packet: 42,
    groups: &[0, 1, 2, 3, 4, 5, 6],
    stream_period_ms: 15,
    max_packet_list_len: 43,
    last_song_number: 15,
    motor_bits: 0x07,
    led_bits: 0b1010,
    pwm_motors: PwmMotorsDuty::LowSideDrivers,
    model_opcodes: &[
        (136, DataShape::Fixed(1)),    // Demo
        (147, DataShape::Fixed(1)),    // Digital Outputs
        (151, DataShape::Fixed(1)),    // Send IR
        (152, DataShape::CountedList), // Script
        (153, DataShape::Fixed(0)),    // Play Script
        (154, DataShape::Fixed(0)),    // Show Script
        (155, DataShape::Fixed(1)),    // Wait Time
        (156, DataShape::Fixed(2)),    // Wait Distance
        (157, DataShape::Fixed(2)),    // Wait Angle
        (158, DataShape::Fixed(1)),    // Wait Event
    ],
    ir_no_byte: 255,
    max_wheel_speed_mm_s: 500,
    speed_step_mm_s: None,
    wheel_overcurrent_limit_a: Some(1.0),
    has_reset_opcode: false,
    play_ignored_while_playing: true,
    has_caster_drop: true,
    has_cargo_bay: true,
    has_encoders: false,
    has_light_bumpers: false,
    has_directional_ir: false,
    has_motor_currents: false,
    has_stasis: false,
    packet_facts: PacketFacts::Create1,
};

/// The iRobot Create 2 (the Roomba 600 Open Interface, 2016 document).
pub const CREATE2: ModelSpec = ModelSpec {
    name: "create2",
    baud: 115_200,
    all_sensors_group: 100,
    last_packet: 58,
    groups: &[0, 1, 2, 3, 4, 5, 6, 100, 101, 106, 107],
    stream_period_ms: 15,
    max_packet_list_len: 108,
    last_song_number: 4,
    motor_bits: 0x1F,
    led_bits: 0x0F,
    pwm_motors: PwmMotorsDuty::Brushes,
    model_opcodes: &[
        (7, DataShape::Fixed(0)),    // Reset
        (133, DataShape::Fixed(0)),  // Power
        (136, DataShape::Fixed(0)),  // Max
        (146, DataShape::Fixed(4)),  // Drive PWM
        (162, DataShape::Fixed(2)),  // Scheduling LEDs
        (163, DataShape::Fixed(4)),  // Digit LEDs Raw
        (164, DataShape::Fixed(4)),  // Digit LEDs ASCII
        (165, DataShape::Fixed(1)),  // Buttons
        (167, DataShape::Fixed(15)), // Schedule
        (168, DataShape::Fixed(3)),  // Set Day/Time
        (173, DataShape::Fixed(0)),  // Stop
    ],
    ir_no_byte: 0,
    max_wheel_speed_mm_s: 500,
    speed_step_mm_s: Some(28.5),
    wheel_overcurrent_limit_a: None,
    has_reset_opcode: true,
    play_ignored_while_playing: false,
    has_caster_drop: false,
    has_cargo_bay: false,
    has_encoders: true,
    has_light_bumpers: true,
    has_directional_ir: true,
    has_motor_currents: true,
    has_stasis: true,
    packet_facts: PacketFacts::Create2,
};

#[cfg(test)]
mod tests {
    use super::*;
    use crate::obs::ObsLayout;
    use crate::oi::Model;
    use crate::oi::command::{Command, ParsedCommand, led_bits, motor_bits, parse_command};
    use crate::oi::frame::check_stream_budget;
    use crate::oi::model::{BAUD_RATES, stream_budget_bytes};
    use crate::oi::packets::{self, available_on, group_members, id};
    use crate::oi::plausible::bounds;

    #[test]
    fn the_entries_hold_the_documented_facts() {
        let c1 = Model::Create1.spec();
        assert_eq!((c1.name, c1.baud), ("create1", 57_600));
        assert_eq!((c1.all_sensors_group, c1.last_packet), (6, 42));
        assert_eq!(c1.groups, &[0, 1, 2, 3, 4, 5, 6]);
        assert_eq!((c1.stream_period_ms, c1.stream_budget_bytes()), (15, 86));
        assert_eq!((c1.max_packet_list_len, c1.last_song_number), (43, 15));
        assert_eq!(c1.led_bits, led_bits::C1_PLAY | led_bits::C1_ADVANCE);
        assert_eq!(c1.motor_bits, 0x07);
        assert_eq!(c1.model_opcode(136), Some(DataShape::Fixed(1)));
        assert_eq!(c1.ir_no_byte, 255);
        assert_eq!(c1.speed_step_mm_s, None);
        assert_eq!(c1.wheel_overcurrent_limit_a, Some(1.0));

        let c2 = Model::Create2.spec();
        assert_eq!((c2.name, c2.baud), ("create2", 115_200));
        assert_eq!((c2.all_sensors_group, c2.last_packet), (100, 58));
        assert_eq!(c2.groups, &[0, 1, 2, 3, 4, 5, 6, 100, 101, 106, 107]);
        assert_eq!((c2.stream_period_ms, c2.stream_budget_bytes()), (15, 172));
        assert_eq!((c2.max_packet_list_len, c2.last_song_number), (108, 4));
        let c2_leds =
            led_bits::C2_DEBRIS | led_bits::C2_SPOT | led_bits::C2_DOCK | led_bits::C2_CHECK_ROBOT;
        assert_eq!(c2.led_bits, c2_leds);
        let c2_motors = motor_bits::SIDE_BRUSH
            | motor_bits::VACUUM
            | motor_bits::MAIN_BRUSH
            | motor_bits::SIDE_BRUSH_CLOCKWISE
            | motor_bits::MAIN_BRUSH_OUTWARD;
        assert_eq!(c2.motor_bits, c2_motors);
        assert_eq!(c2.model_opcode(136), Some(DataShape::Fixed(0)));
        assert_eq!(c2.ir_no_byte, 0);
        assert_eq!(c2.speed_step_mm_s, Some(28.5));
        assert_eq!(c2.wheel_overcurrent_limit_a, None);

        for spec in [c1, c2] {
            assert_eq!(spec.max_wheel_speed_mm_s, 500);
        }
    }

    /// Lists every variant by an exhaustive match, so a new model that is not in [`Model::ALL`] fails
    /// to compile here rather than going untested.
    fn in_all(model: Model) -> bool {
        match model {
            Model::Create1 | Model::Create2 => Model::ALL.contains(&model),
        }
    }

    #[test]
    fn every_model_round_trips_through_its_spec() {
        assert!(in_all(Model::Create1) && in_all(Model::Create2));
        for model in Model::ALL {
            let spec = model.spec();
            assert!(std::ptr::eq(spec, model.spec()));
            assert_eq!(spec.name.parse::<Model>(), Ok(model));
            assert_eq!(model.to_string(), spec.name);
            // The configuration file names the model through serde: the same name.
            let serde_name = toml::Value::try_from(model).map(|v| v.as_str().map(str::to_owned));
            assert_eq!(serde_name, Ok(Some(spec.name.to_owned())), "{model:?}");
            let others = Model::ALL.into_iter().filter(|&m| m != model);
            assert!(others.clone().all(|m| m.spec().name != spec.name));
            assert!(others.clone().all(|m| !std::ptr::eq(m.spec(), spec)));
        }
        assert_eq!(
            "roomba".parse::<Model>(),
            Err("unknown model `roomba` (expected create1 or create2)".to_string())
        );
    }

    /// Checks that hold for every entry today and fail for an entry whose fields contradict each other
    /// or the packet tables.
    #[test]
    fn every_entry_is_consistent() {
        for model in Model::ALL {
            let spec = model.spec();
            let name = spec.name;
            assert!(BAUD_RATES.contains(&spec.baud), "{name}: baud");

            // The all-sensors group is one of the model's groups and holds exactly packets 7..=last.
            assert!(spec.groups.contains(&spec.all_sensors_group), "{name}");
            let all = group_members(spec.all_sensors_group).unwrap_or_default();
            assert!(all.iter().copied().eq(7..=spec.last_packet), "{name}");
            // Every group exists and holds only packets the model answers.
            for &group in spec.groups {
                let members = group_members(group);
                assert!(members.is_some(), "{name}: group {group}");
                let members = members.unwrap_or_default();
                assert!(members.iter().all(|m| all.contains(m)), "{name}: {group}");
            }

            // One all-sensors frame fits in a stream period at the model's baud, and the frame
            // helpers (which take a baud alone) assume the model's stream period.
            let frame = check_stream_budget(&[spec.all_sensors_group], spec.baud);
            assert!(frame.is_ok(), "{name}: {frame:?}");
            assert!(frame.unwrap_or(usize::MAX) <= spec.stream_budget_bytes());
            assert_eq!(stream_budget_bytes(spec.baud), spec.stream_budget_bytes());

            // A Stream may name every packet and group the model answers at once, and packet 38
            // reports up to the model's limit.
            let answered = (0..=u8::MAX).filter(|&i| available_on(i, model)).count();
            assert!(spec.max_packet_list_len >= answered, "{name}");
            let bound = |packet: u8| bounds(model).iter().find(|b| b.id == packet).copied();
            let count = bound(id::STREAM_PACKET_COUNT).map(|b| b.max);
            assert_eq!(
                count,
                i32::try_from(spec.max_packet_list_len).ok(),
                "{name}"
            );
            // The plausibility bounds and the observation layout name only packets the model answers,
            // and the layout covers every one of them.
            assert!(bounds(model).iter().all(|b| all.contains(&b.id)), "{name}");
            let layout = ObsLayout::for_model(model);
            assert!(layout.dims().iter().all(|d| all.contains(&d.packet)));
            assert!(
                all.iter()
                    .all(|&p| layout.dims().iter().any(|d| d.packet == p))
            );

            // Capabilities agree with the packets the model answers and their bounds.
            let has = |ids: &[u8]| ids.iter().all(|&i| available_on(i, model));
            let lacks = |ids: &[u8]| ids.iter().all(|&i| !available_on(i, model));
            let agrees = |flag: bool, ids: &[u8]| if flag { has(ids) } else { lacks(ids) };
            assert!(agrees(spec.has_encoders, &[43, 44]), "{name}: encoders");
            assert!(agrees(
                spec.has_light_bumpers,
                &[45, 46, 47, 48, 49, 50, 51]
            ));
            assert!(agrees(spec.has_directional_ir, &[52, 53]), "{name}: IR");
            assert!(agrees(spec.has_motor_currents, &[54, 55, 56, 57]), "{name}");
            assert!(agrees(spec.has_stasis, &[58]), "{name}: stasis");
            let cargo_checked = bound(id::CARGO_BAY_DIGITAL_INPUTS).is_some();
            assert_eq!(spec.has_cargo_bay, cargo_checked, "{name}: cargo bay");
            let caster_bit = packets::bits::WHEEL_DROP_CASTER;
            let bumps_max = bound(id::BUMPS_WHEEL_DROPS).map_or(0, |b| b.max);
            assert_eq!(spec.has_caster_drop, bumps_max & caster_bit != 0, "{name}");
            let songs = bound(id::SONG_NUMBER).map_or(0, |b| b.max);
            assert!(i32::from(spec.last_song_number) <= songs, "{name}: songs");

            // The model's opcodes are sorted, reach the parser with their data bytes, and Reset is
            // among them exactly when the model has it.
            let codes: Vec<u8> = spec.model_opcodes.iter().map(|&(op, _)| op).collect();
            assert!(codes.windows(2).all(|w| w[0] < w[1]), "{name}: {codes:?}");
            for &(op, shape) in spec.model_opcodes {
                let (buf, len) = match shape {
                    DataShape::Fixed(n) => (vec![op; n + 1], n + 1),
                    DataShape::CountedList => (vec![op, 0], 2),
                    DataShape::Song => (vec![op, 0, 0], 3),
                };
                let parsed = parse_command(model, &buf);
                let consumed = match parsed {
                    ParsedCommand::Complete { consumed, .. } => Some(consumed),
                    _ => None,
                };
                assert_eq!(consumed, Some(len), "{name}: opcode {op}");
            }
            assert_eq!(spec.has_reset_opcode, spec.model_opcode(7).is_some());
            assert_eq!(
                spec.has_reset_opcode,
                Command::Reset.validate(model).is_ok()
            );

            // Limits are positive where they are given.
            assert!(spec.max_wheel_speed_mm_s > 0, "{name}");
            let step = spec.speed_step_mm_s.unwrap_or(1.0);
            assert!(step > 0.0 && step < f64::from(spec.max_wheel_speed_mm_s));
            assert!(spec.wheel_overcurrent_limit_a.unwrap_or(1.0) > 0.0);
        }
    }

    #[test]
    fn availability_matches_the_documents_columns() {
        for packet in &packets::PACKETS {
            assert_eq!(available_on(packet.id, Model::Create1), packet.create1);
            assert_eq!(available_on(packet.id, Model::Create2), packet.create2);
        }
    }
}

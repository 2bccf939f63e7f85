//! The sensor packet table: every single packet 7–58 and every group, and their byte encoding.
//!
//! One static table ([`PACKETS`]) says, for each single packet, its size (1 or 2 bytes), signedness,
//! unit, documented range and which models answer it [C1 pp17–21, 24–25; C2 pp23–32, 37–39].
//! Groups expand to their member packets in order [C1 p17, p24; C2 p37]. Multi-byte values are
//! big-endian, high byte first [C1 p17; C2 p23]. Bit-field masks and named ids live in [`bits`] and [`id`].

use super::{Model, OiError, SensorValues};

/// One single sensor packet, as the specifications describe it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PacketSpec {
    /// Packet id, 7–58.
    pub id: u8,
    /// A short snake_case name (`"cliff_left_signal"`).
    pub name: &'static str,
    /// Data bytes: 1 or 2.
    pub size: u8,
    /// True for two's-complement values (distance, angle, current, temperature, requested velocities, …).
    pub signed: bool,
    /// Unit of the raw value: `"mm"`, `"mm/s"`, `"deg"`, `"mV"`, `"mA"`, `"mAh"`, `"degC"`, `"counts"`,
    /// `"bits"` (a bit field), `"bool"` (0 or 1), `"code"` (an enumeration) or `""` (a plain number).
    pub unit: &'static str,
    /// Smallest documented value (for unused bytes: the byte's range).
    pub min: i32,
    /// Largest documented value, over both models where they differ.
    pub max: i32,
    /// The Create 1 column of the specifications' tables: answered by the Create 1 (packets 7–42).
    /// A record of the documents, not consulted: a model answers the members of its all-sensors group
    /// ([`available_on`]); a test checks that the two agree.
    pub create1: bool,
    /// The Create 2 column (packets 7–58); like `create1`, a record checked against [`available_on`].
    pub create2: bool,
}

impl PacketSpec {
    /// The range the packet's bytes can carry: u8, i8, u16 or i16.
    pub fn wire_range(&self) -> (i32, i32) {
        match (self.size, self.signed) {
            (1, false) => (0, 255),
            (1, true) => (-128, 127),
            (_, false) => U16,
            (_, true) => I16,
        }
    }
}

/// Named packet and group ids.
pub mod id {
    pub const BUMPS_WHEEL_DROPS: u8 = 7;
    pub const WALL: u8 = 8;
    pub const CLIFF_LEFT: u8 = 9;
    pub const CLIFF_FRONT_LEFT: u8 = 10;
    pub const CLIFF_FRONT_RIGHT: u8 = 11;
    pub const CLIFF_RIGHT: u8 = 12;
    pub const VIRTUAL_WALL: u8 = 13;
    pub const OVERCURRENTS: u8 = 14;
    pub const DIRT_DETECT: u8 = 15;
    pub const UNUSED_16: u8 = 16;
    pub const IR_OMNI: u8 = 17;
    pub const BUTTONS: u8 = 18;
    pub const DISTANCE: u8 = 19;
    pub const ANGLE: u8 = 20;
    pub const CHARGING_STATE: u8 = 21;
    pub const VOLTAGE: u8 = 22;
    pub const CURRENT: u8 = 23;
    pub const TEMPERATURE: u8 = 24;
    pub const BATTERY_CHARGE: u8 = 25;
    pub const BATTERY_CAPACITY: u8 = 26;
    pub const WALL_SIGNAL: u8 = 27;
    pub const CLIFF_LEFT_SIGNAL: u8 = 28;
    pub const CLIFF_FRONT_LEFT_SIGNAL: u8 = 29;
    pub const CLIFF_FRONT_RIGHT_SIGNAL: u8 = 30;
    pub const CLIFF_RIGHT_SIGNAL: u8 = 31;
    pub const CARGO_BAY_DIGITAL_INPUTS: u8 = 32;
    pub const CARGO_BAY_ANALOG_SIGNAL: u8 = 33;
    pub const CHARGING_SOURCES: u8 = 34;
    pub const OI_MODE: u8 = 35;
    pub const SONG_NUMBER: u8 = 36;
    pub const SONG_PLAYING: u8 = 37;
    pub const STREAM_PACKET_COUNT: u8 = 38;
    pub const REQUESTED_VELOCITY: u8 = 39;
    pub const REQUESTED_RADIUS: u8 = 40;
    pub const REQUESTED_RIGHT_VELOCITY: u8 = 41;
    pub const REQUESTED_LEFT_VELOCITY: u8 = 42;
    pub const LEFT_ENCODER: u8 = 43;
    pub const RIGHT_ENCODER: u8 = 44;
    pub const LIGHT_BUMPER: u8 = 45;
    pub const LIGHT_BUMP_LEFT_SIGNAL: u8 = 46;
    pub const LIGHT_BUMP_FRONT_LEFT_SIGNAL: u8 = 47;
    pub const LIGHT_BUMP_CENTER_LEFT_SIGNAL: u8 = 48;
    pub const LIGHT_BUMP_CENTER_RIGHT_SIGNAL: u8 = 49;
    pub const LIGHT_BUMP_FRONT_RIGHT_SIGNAL: u8 = 50;
    pub const LIGHT_BUMP_RIGHT_SIGNAL: u8 = 51;
    pub const IR_LEFT: u8 = 52;
    pub const IR_RIGHT: u8 = 53;
    pub const LEFT_MOTOR_CURRENT: u8 = 54;
    pub const RIGHT_MOTOR_CURRENT: u8 = 55;
    pub const MAIN_BRUSH_CURRENT: u8 = 56;
    pub const SIDE_BRUSH_CURRENT: u8 = 57;
    pub const STASIS: u8 = 58;

    /// Group 6: packets 7–42, the whole Create 1 sensor set (52 bytes).
    pub const GROUP_ALL_CREATE1: u8 = 6;
    /// Group 100: packets 7–58, the whole Create 2 sensor set (80 bytes).
    pub const GROUP_ALL_CREATE2: u8 = 100;
}

/// Bit masks of the bit-field packets, and the codes of the enumerated ones.
pub mod bits {
    pub use super::id;

    // Packet 7, bumps and wheel drops [C1 p17; C2 p24]. The caster drop is Create 1 only.
    pub const BUMP_RIGHT: i32 = 1;
    pub const BUMP_LEFT: i32 = 1 << 1;
    pub const WHEEL_DROP_RIGHT: i32 = 1 << 2;
    pub const WHEEL_DROP_LEFT: i32 = 1 << 3;
    pub const WHEEL_DROP_CASTER: i32 = 1 << 4;

    // Packet 14, overcurrents: Create 1 bit0 LD1, bit1 LD0, bit2 LD2 [C1 p17];
    // Create 2 bit0 side brush, bit1 reserved, bit2 main brush [C2 p37]; bit3/bit4 right/left wheel on both.
    pub const OC_SIDE_BRUSH_OR_LD1: i32 = 1;
    pub const OC_LD0: i32 = 1 << 1;
    pub const OC_MAIN_BRUSH_OR_LD2: i32 = 1 << 2;
    pub const OC_RIGHT_WHEEL: i32 = 1 << 3;
    pub const OC_LEFT_WHEEL: i32 = 1 << 4;

    // Packet 18, buttons. Create 1: bit0 Play, bit2 Advance [C1 p18].
    pub const BUTTON_PLAY: i32 = 1;
    pub const BUTTON_ADVANCE: i32 = 1 << 2;
    // Create 2: Clean, Spot, Dock, Minute, Hour, Day, Schedule, Clock [C2 p26].
    pub const BUTTON_CLEAN: i32 = 1;
    pub const BUTTON_SPOT: i32 = 1 << 1;
    pub const BUTTON_DOCK: i32 = 1 << 2;
    pub const BUTTON_MINUTE: i32 = 1 << 3;
    pub const BUTTON_HOUR: i32 = 1 << 4;
    pub const BUTTON_DAY: i32 = 1 << 5;
    pub const BUTTON_SCHEDULE: i32 = 1 << 6;
    pub const BUTTON_CLOCK: i32 = 1 << 7;

    // Packet 21, charging state codes [C1 p19; C2 p27].
    pub const CHARGING_NOT: i32 = 0;
    pub const CHARGING_RECONDITIONING: i32 = 1;
    pub const CHARGING_FULL: i32 = 2;
    pub const CHARGING_TRICKLE: i32 = 3;
    pub const CHARGING_WAITING: i32 = 4;
    pub const CHARGING_FAULT: i32 = 5;

    // Packet 34, charging sources available [C1 p20; C2 p29].
    pub const CHARGER_INTERNAL: i32 = 1;
    pub const CHARGER_HOME_BASE: i32 = 1 << 1;

    // Packet 35, OI mode codes [C1 p20; C2 p29].
    pub const MODE_OFF: i32 = 0;
    pub const MODE_PASSIVE: i32 = 1;
    pub const MODE_SAFE: i32 = 2;
    pub const MODE_FULL: i32 = 3;

    // Packet 45, light bumper (Create 2) [C2 p38].
    pub const LIGHT_BUMP_LEFT: i32 = 1;
    pub const LIGHT_BUMP_FRONT_LEFT: i32 = 1 << 1;
    pub const LIGHT_BUMP_CENTER_LEFT: i32 = 1 << 2;
    pub const LIGHT_BUMP_CENTER_RIGHT: i32 = 1 << 3;
    pub const LIGHT_BUMP_FRONT_RIGHT: i32 = 1 << 4;
    pub const LIGHT_BUMP_RIGHT: i32 = 1 << 5;

    // Packet 58, stasis (Create 2) [C2 p32, p38].
    pub const STASIS_TOGGLING: i32 = 1;
    pub const STASIS_DISABLED: i32 = 1 << 1;
}

/// Table builder: `p(id, name, size, signed, unit, min, max, (create1, create2))`.
const fn p(
    id: u8,
    name: &'static str,
    size: u8,
    signed: bool,
    unit: &'static str,
    range: (i32, i32),
    models: (bool, bool),
) -> PacketSpec {
    PacketSpec {
        id,
        name,
        size,
        signed,
        unit,
        min: range.0,
        max: range.1,
        create1: models.0,
        create2: models.1,
    }
}

const U: bool = false;
const S: bool = true;
const BOTH: (bool, bool) = (true, true);
const C2: (bool, bool) = (false, true);
const BOOL: (i32, i32) = (0, 1);
const BYTE: (i32, i32) = (0, 255);
const I16: (i32, i32) = (i16::MIN as i32, i16::MAX as i32);
const U16: (i32, i32) = (0, u16::MAX as i32);
const SIGNAL: (i32, i32) = (0, 4095);
const WHEEL_MM_S: (i32, i32) = (-500, 500);

/// Every single sensor packet, indexed by `id - 7` [C1 pp17–21, 24–25; C2 pp23–32, 37–39].
pub static PACKETS: [PacketSpec; 52] = PACKET_TABLE;

/// [`PACKETS`] as a constant, for the tables built from it at compile time.
#[rustfmt::skip]
const PACKET_TABLE: [PacketSpec; 52] = [
    p(7,  "bumps_wheel_drops",        1, U, "bits",   (0, 31),    BOTH), // C2 has no caster bit: 0–15
    p(8,  "wall",                     1, U, "bool",   BOOL,       BOTH), // C2: = light-bumper right
    p(9,  "cliff_left",               1, U, "bool",   BOOL,       BOTH),
    p(10, "cliff_front_left",         1, U, "bool",   BOOL,       BOTH),
    p(11, "cliff_front_right",        1, U, "bool",   BOOL,       BOTH),
    p(12, "cliff_right",              1, U, "bool",   BOOL,       BOTH),
    p(13, "virtual_wall",             1, U, "bool",   BOOL,       BOTH),
    p(14, "overcurrents",             1, U, "bits",   (0, 31),    BOTH),
    p(15, "dirt_detect",              1, U, "",       BYTE,       BOTH), // C1: unused, always 0
    p(16, "unused_16",                1, U, "",       BYTE,       BOTH), // always 0
    p(17, "ir_omni",                  1, U, "code",   BYTE,       BOTH), // none: C1 255, C2 0
    p(18, "buttons",                  1, U, "bits",   BYTE,       BOTH),
    p(19, "distance",                 2, S, "mm",     I16,        BOTH),
    p(20, "angle",                    2, S, "deg",    I16,        BOTH),
    p(21, "charging_state",           1, U, "code",   (0, 6),     BOTH), // text 0–5, C2 table 0–6
    p(22, "voltage",                  2, U, "mV",     U16,        BOTH),
    p(23, "current",                  2, S, "mA",     I16,        BOTH),
    p(24, "temperature",              1, S, "degC",   (-128, 127), BOTH),
    p(25, "battery_charge",           2, U, "mAh",    U16,        BOTH),
    p(26, "battery_capacity",         2, U, "mAh",    U16,        BOTH),
    p(27, "wall_signal",              2, U, "",       SIGNAL,     BOTH), // C2: 0–1023
    p(28, "cliff_left_signal",        2, U, "",       SIGNAL,     BOTH),
    p(29, "cliff_front_left_signal",  2, U, "",       SIGNAL,     BOTH),
    p(30, "cliff_front_right_signal", 2, U, "",       SIGNAL,     BOTH),
    p(31, "cliff_right_signal",       2, U, "",       SIGNAL,     BOTH),
    p(32, "cargo_bay_digital_inputs", 1, U, "bits",   (0, 31),    BOTH), // C2: unused byte
    p(33, "cargo_bay_analog_signal",  2, U, "",       (0, 1023),  BOTH), // C2: unused bytes
    p(34, "charging_sources",         1, U, "bits",   (0, 3),     BOTH),
    p(35, "oi_mode",                  1, U, "code",   (0, 3),     BOTH),
    p(36, "song_number",              1, U, "",       (0, 15),    BOTH), // C2: 0–4
    p(37, "song_playing",             1, U, "bool",   BOOL,       BOTH),
    p(38, "stream_packet_count",      1, U, "",       (0, 108),   BOTH), // C1: 0–43
    p(39, "requested_velocity",       2, S, "mm/s",   WHEEL_MM_S, BOTH),
    p(40, "requested_radius",         2, S, "mm",     I16,        BOTH),
    p(41, "requested_right_velocity", 2, S, "mm/s",   WHEEL_MM_S, BOTH),
    p(42, "requested_left_velocity",  2, S, "mm/s",   WHEEL_MM_S, BOTH),
    p(43, "left_encoder",             2, S, "counts", I16,        C2), // wraps
    p(44, "right_encoder",            2, S, "counts", I16,        C2), // wraps
    p(45, "light_bumper",             1, U, "bits",   (0, 127),   C2),
    p(46, "light_bump_left_signal",         2, U, "", SIGNAL,     C2),
    p(47, "light_bump_front_left_signal",   2, U, "", SIGNAL,     C2),
    p(48, "light_bump_center_left_signal",  2, U, "", SIGNAL,     C2),
    p(49, "light_bump_center_right_signal", 2, U, "", SIGNAL,     C2),
    p(50, "light_bump_front_right_signal",  2, U, "", SIGNAL,     C2),
    p(51, "light_bump_right_signal",        2, U, "", SIGNAL,     C2),
    p(52, "ir_left",                  1, U, "code",   BYTE,       C2),
    p(53, "ir_right",                 1, U, "code",   BYTE,       C2),
    p(54, "left_motor_current",       2, S, "mA",     I16,        C2),
    p(55, "right_motor_current",      2, S, "mA",     I16,        C2),
    p(56, "main_brush_current",       2, S, "mA",     I16,        C2),
    p(57, "side_brush_current",       2, S, "mA",     I16,        C2),
    p(58, "stasis",                   1, U, "bits",   (0, 3),     C2),
];

/// First and last single packet ids.
const FIRST_PACKET: u8 = 7;
const LAST_PACKET: u8 = 58;

/// `N` consecutive ids starting at `first`.
const fn id_run<const N: usize>(first: u8) -> [u8; N] {
    let mut ids = [0u8; N];
    let mut i = 0;
    while i < N {
        ids[i] = first + i as u8;
        i += 1;
    }
    ids
}

static GROUP_0: [u8; 20] = id_run(7); // 7–26
static GROUP_1: [u8; 10] = id_run(7); // 7–16
static GROUP_2: [u8; 4] = id_run(17); // 17–20
static GROUP_3: [u8; 6] = id_run(21); // 21–26
static GROUP_4: [u8; 8] = id_run(27); // 27–34
static GROUP_5: [u8; 8] = id_run(35); // 35–42
static GROUP_6: [u8; 36] = id_run(7); // 7–42
static GROUP_100: [u8; 52] = id_run(7); // 7–58
static GROUP_101: [u8; 16] = id_run(43); // 43–58
static GROUP_106: [u8; 6] = id_run(46); // 46–51
static GROUP_107: [u8; 5] = id_run(54); // 54–58

/// The table entry of single packet `id` (7–58); `None` for groups and unknown ids.
pub fn spec(id: u8) -> Option<&'static PacketSpec> {
    if (FIRST_PACKET..=LAST_PACKET).contains(&id) {
        PACKETS.get(usize::from(id - FIRST_PACKET))
    } else {
        None
    }
}

/// The member packets of group `id`, in the order the robot sends them [C1 p17; C2 p37]:
/// groups 0–6 (both models) and 100, 101, 106, 107 (Create 2; 102–105 are not defined).
pub fn group_members(id: u8) -> Option<&'static [u8]> {
    let members: &'static [u8] = match id {
        0 => &GROUP_0,
        1 => &GROUP_1,
        2 => &GROUP_2,
        3 => &GROUP_3,
        4 => &GROUP_4,
        5 => &GROUP_5,
        6 => &GROUP_6,
        100 => &GROUP_100,
        101 => &GROUP_101,
        106 => &GROUP_106,
        107 => &GROUP_107,
        _ => return None,
    };
    Some(members)
}

/// Data bytes of a single packet or of a whole group (group 6: 52, group 100: 80); `None` if unknown.
/// A table lookup: the sums over the members are computed once, at compile time (the table `DATA_LEN`).
pub fn data_len(id: u8) -> Option<usize> {
    match DATA_LEN[usize::from(id)] {
        0 => None,
        n => Some(usize::from(n)),
    }
}

/// The members of packet-or-group `id` as a run of consecutive ids `(first, count)` (every group is
/// one: see the `GROUP_*` tables), for tables built at compile time; `None` if unknown.
const fn member_run(id: u8) -> Option<(u8, u8)> {
    match id {
        FIRST_PACKET..=LAST_PACKET => Some((id, 1)),
        0 => Some((7, 20)),
        1 => Some((7, 10)),
        2 => Some((17, 4)),
        3 => Some((21, 6)),
        4 => Some((27, 8)),
        5 => Some((35, 8)),
        6 => Some((7, 36)),
        100 => Some((7, 52)),
        101 => Some((43, 16)),
        106 => Some((46, 6)),
        107 => Some((54, 5)),
        _ => None,
    }
}

/// Data bytes of every packet-or-group id, 0 for an unknown id (no known id has 0 bytes; the largest,
/// group 100, has 80). A test checks it against the member lists.
static DATA_LEN: [u8; 256] = {
    let mut table = [0u8; 256];
    let mut id = 0;
    while id < 256 {
        if let Some((first, count)) = member_run(id as u8) {
            let mut n = 0u8;
            let mut k = 0;
            while k < count {
                n += PACKET_TABLE[(first + k - FIRST_PACKET) as usize].size;
                k += 1;
            }
            table[id] = n;
        }
        id += 1;
    }
    table
};

/// How single packet `id` goes on the wire: its size and the range its value is saturated to.
#[derive(Debug, Clone, Copy)]
struct Wire {
    size: u8,
    lo: i32,
    hi: i32,
}

/// [`Wire`] of every single packet, indexed by `id - 7`, built at compile time from [`PACKET_TABLE`]:
/// the range is [`PacketSpec::wire_range`], except that a packet that wraps (the encoders) gets the
/// whole `i32` range, where clamping is the identity, so `v as u16` wraps it exactly as before.
static WIRE: [Wire; 52] = {
    let mut table = [Wire {
        size: 0,
        lo: 0,
        hi: 0,
    }; 52];
    let mut i = 0;
    while i < 52 {
        let s = &PACKET_TABLE[i];
        let (lo, hi) = if wraps_around(s.id) {
            (i32::MIN, i32::MAX)
        } else {
            match (s.size, s.signed) {
                (1, false) => (0, 255),
                (1, true) => (-128, 127),
                (_, false) => U16,
                (_, true) => I16,
            }
        };
        table[i] = Wire {
            size: s.size,
            lo,
            hi,
        };
        i += 1;
    }
    table
};

/// Whether `model` answers packet or group `id` (Create 1: 0–42; Create 2: 0–58, 100, 101, 106, 107):
/// a single packet when it is a member of the model's all-sensors group, a group when the model lists
/// it ([`super::ModelSpec::all_sensors_group`], [`super::ModelSpec::groups`]).
pub fn available_on(id: u8, model: Model) -> bool {
    let model_spec = model.spec();
    if spec(id).is_some() {
        group_members(model_spec.all_sensors_group).is_some_and(|members| members.contains(&id))
    } else {
        model_spec.groups.contains(&id)
    }
}

/// Like [`available_on`], but says why not.
pub fn check_available(id: u8, model: Model) -> Result<(), OiError> {
    if spec(id).is_none() && group_members(id).is_none() {
        Err(OiError::UnknownPacket(id))
    } else if available_on(id, model) {
        Ok(())
    } else {
        Err(OiError::NotOnModel { id, model })
    }
}

/// True for the packets whose counters wrap around instead of saturating: the wheel encoders
/// ("cumulative, wraps" [C2 p30–31]).
const fn wraps_around(id: u8) -> bool {
    id == id::LEFT_ENCODER || id == id::RIGHT_ENCODER
}

/// Appends single packet `id`'s `value`, big-endian in the packet's size. A value that does not fit
/// the wire type is saturated (distance and angle are "capped at the minimum or maximum" [C1 p18; C2 p27]),
/// except the encoders, which wrap like the firmware's 16-bit counters [C2 p30].
pub fn encode_value(id: u8, value: i32, out: &mut Vec<u8>) -> Result<(), OiError> {
    let s = spec(id).ok_or(OiError::UnknownPacket(id))?;
    let (lo, hi) = s.wire_range();
    let v = if wraps_around(id) {
        value
    } else {
        value.clamp(lo, hi)
    };
    if s.size == 1 {
        out.push(v as u8);
    } else {
        out.extend_from_slice(&(v as u16).to_be_bytes());
    }
    Ok(())
}

/// Decodes single packet `id` from exactly its data bytes (big-endian; signed packets sign-extended).
pub fn decode_value(id: u8, bytes: &[u8]) -> Result<i32, OiError> {
    let s = spec(id).ok_or(OiError::UnknownPacket(id))?;
    match (bytes, s.signed) {
        ([b], false) if s.size == 1 => Ok(i32::from(*b)),
        ([b], true) if s.size == 1 => Ok(i32::from(*b as i8)),
        ([h, l], false) if s.size == 2 => Ok(i32::from(u16::from_be_bytes([*h, *l]))),
        ([h, l], true) if s.size == 2 => Ok(i32::from(i16::from_be_bytes([*h, *l]))),
        _ => Err(OiError::BadLength {
            id,
            expected: usize::from(s.size),
            got: bytes.len(),
        }),
    }
}

/// The single packets that packet-or-group `id` stands for, in wire order.
fn members_of(id: u8) -> Result<&'static [u8], OiError> {
    if let Some(s) = spec(id) {
        Ok(std::slice::from_ref(&s.id))
    } else {
        group_members(id).ok_or(OiError::UnknownPacket(id))
    }
}

/// Appends the data of a single packet or a whole group: its members' values concatenated in order,
/// absent values as 0. This is exactly what the robot sends after the id in a stream frame, and the
/// whole reply to Sensors (142) [C1 p13; C2 p21].
pub fn encode_data(id: u8, values: &SensorValues, out: &mut Vec<u8>) -> Result<(), OiError> {
    let mut buf: DataBuf = [0; 256];
    let n = encode_data_into(id, values, &mut buf)?;
    out.extend_from_slice(buf.get(..n).unwrap_or_default());
    Ok(())
}

/// A buffer that one packet's or group's data always fits in (at most 80 bytes, group 100), indexed
/// by a byte so that no write can fall outside it.
pub(crate) type DataBuf = [u8; 256];

/// Like [`encode_data`], into the front of `buf`; returns the bytes written. Each member is encoded
/// as [`encode_value`] does (its value or 0 when absent, saturated to its wire range, the encoders
/// wrapped, big-endian), from the compile-time [`WIRE`] table and without a branch per member.
pub(crate) fn encode_data_into(
    id: u8,
    values: &SensorValues,
    buf: &mut DataBuf,
) -> Result<usize, OiError> {
    let (first, count) = member_run(id).ok_or(OiError::UnknownPacket(id))?;
    let (first, count) = (usize::from(first), usize::from(count));
    let (slots, present) = values.slots();
    // Every run lies within packets 7..=58, so within both tables.
    let start = first - usize::from(FIRST_PACKET);
    let (Some(wires), Some(slots)) = (
        WIRE.get(start..start + count),
        slots.get(first..first + count),
    ) else {
        return Err(OiError::UnknownPacket(id));
    };
    let mut n = 0u8;
    for (k, (w, &slot)) in wires.iter().zip(slots).enumerate() {
        // `get_or_zero`: the slot when its presence bit is set, else 0.
        let bit = ((present >> (first + k)) & 1) as i32;
        let value = slot & bit.wrapping_neg();
        // `clamp(lo, hi)` as max then min: the same for lo <= hi (every entry), without its check.
        let [h, l] = (value.max(w.lo).min(w.hi) as u16).to_be_bytes();
        // Two bytes are `h l`, one byte is `l` (`v as u8`). The byte after the value is written
        // either way; when it is not the value's, the next member overwrites it.
        buf[usize::from(n)] = if w.size == 2 { h } else { l };
        buf[usize::from(n.wrapping_add(1))] = l;
        n = n.wrapping_add(w.size);
    }
    Ok(usize::from(n))
}

/// Decodes the data of a single packet or a whole group (`bytes` must be exactly [`data_len`] long)
/// and stores every member's value in `into`.
pub fn decode_data(id: u8, bytes: &[u8], into: &mut SensorValues) -> Result<(), OiError> {
    let members = members_of(id)?;
    let expected = data_len(id).ok_or(OiError::UnknownPacket(id))?;
    if bytes.len() != expected {
        return Err(OiError::BadLength {
            id,
            expected,
            got: bytes.len(),
        });
    }
    let mut rest = bytes;
    for &m in members {
        let size = spec(m).map_or(0, |s| usize::from(s.size));
        let (head, tail) = rest.split_at_checked(size).ok_or(OiError::BadLength {
            id,
            expected,
            got: bytes.len(),
        })?;
        into.set(m, decode_value(m, head)?);
        rest = tail;
    }
    Ok(())
}

#[cfg(test)]
mod tests;

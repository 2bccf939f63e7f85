//! Host-to-robot commands: encoding with per-model validation, and the robot-side byte parser.
//!
//! [`Command::encode`] turns a command into the exact bytes of [C1 pp7–16] or [C2 pp8–22], rejecting
//! arguments outside the documented ranges and commands the model does not have. [`parse_command`]
//! is the robot's side of the same wire: it knows the exact data-byte count of every opcode of each
//! model (including the variable-length 140, 148, 149 and 152), which the simulated robot needs because
//! the real one blocks until all data bytes of a command have arrived [C1 p7; C2 p8].

use super::packets::check_available;
use super::spec::{DataShape, PwmMotorsDuty};
use super::{Model, OiError};

/// Opcodes [C1 pp7–16; C2 pp8–22, p35].
pub mod opcode {
    pub const RESET: u8 = 7; // Create 2 only
    pub const START: u8 = 128;
    pub const BAUD: u8 = 129;
    pub const CONTROL: u8 = 130;
    pub const SAFE: u8 = 131;
    pub const FULL: u8 = 132;
    pub const POWER: u8 = 133; // Create 2 only
    pub const SPOT: u8 = 134;
    pub const CLEAN: u8 = 135; // Create 1: Cover
    pub const DEMO_OR_MAX: u8 = 136; // Create 1: Demo (1 data byte); Create 2: Max (none)
    pub const DRIVE: u8 = 137;
    pub const MOTORS: u8 = 138; // Create 1: Low Side Drivers
    pub const LEDS: u8 = 139;
    pub const SONG: u8 = 140;
    pub const PLAY: u8 = 141;
    pub const SENSORS: u8 = 142;
    pub const SEEK_DOCK: u8 = 143; // Create 1: Cover and Dock
    pub const PWM_MOTORS: u8 = 144; // Create 1: PWM Low Side Drivers
    pub const DRIVE_DIRECT: u8 = 145;
    pub const DRIVE_PWM: u8 = 146; // Create 2 only
    pub const STREAM: u8 = 148;
    pub const QUERY_LIST: u8 = 149;
    pub const PAUSE_RESUME_STREAM: u8 = 150;
    pub const SCRIPT: u8 = 152; // Create 1 only
    pub const STOP: u8 = 173; // Create 2 only
}

/// Bits of the Motors command (138) on the Create 2 [C2 p15]; on the Create 1 bits 0–2 are LD0–LD2 [C1 p10].
pub mod motor_bits {
    pub const SIDE_BRUSH: u8 = 1;
    pub const VACUUM: u8 = 1 << 1;
    pub const MAIN_BRUSH: u8 = 1 << 2;
    pub const SIDE_BRUSH_CLOCKWISE: u8 = 1 << 3;
    pub const MAIN_BRUSH_OUTWARD: u8 = 1 << 4;
}

/// Bits of the LEDs command (139): Create 1 Play and Advance [C1 p9]; Create 2 Debris, Spot, Dock,
/// Check Robot [C2 p16].
pub mod led_bits {
    pub const C1_PLAY: u8 = 1 << 1;
    pub const C1_ADVANCE: u8 = 1 << 3;
    pub const C2_DEBRIS: u8 = 1;
    pub const C2_SPOT: u8 = 1 << 1;
    pub const C2_DOCK: u8 = 1 << 2;
    pub const C2_CHECK_ROBOT: u8 = 1 << 3;
}

/// The turning radius of a Drive command [C1 p9; C2 p13].
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Radius {
    /// Drive straight: special value 32768 (0x8000); 32767 (0x7FFF) also means straight.
    Straight,
    /// Turn in place clockwise: special value −1 (0xFFFF).
    TurnInPlaceClockwise,
    /// Turn in place counter-clockwise: special value 1.
    TurnInPlaceCounterClockwise,
    /// Radius in mm, −2000…2000, positive turns left. 0 is undefined in the specs and rejected;
    /// ±1 are the turn-in-place values and parse back as those variants.
    Mm(i16),
}

impl Radius {
    /// The 16-bit value on the wire.
    pub fn to_wire(self) -> i16 {
        match self {
            Radius::Straight => i16::MIN, // 0x8000
            Radius::TurnInPlaceClockwise => -1,
            Radius::TurnInPlaceCounterClockwise => 1,
            Radius::Mm(r) => r,
        }
    }

    /// The radius a wire value means (the robot's view; any value is accepted).
    pub fn from_wire(raw: i16) -> Radius {
        match raw {
            i16::MIN | i16::MAX => Radius::Straight,
            -1 => Radius::TurnInPlaceClockwise,
            1 => Radius::TurnInPlaceCounterClockwise,
            r => Radius::Mm(r),
        }
    }
}

/// A command from the host to the robot.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Command {
    /// 128: start the OI, enter Passive.
    Start,
    /// 7 (Create 2 only): like re-inserting the battery; prints the firmware banner.
    Reset,
    /// 129: baud code 0–11 (0 = 300 … 10 = 57600, 11 = 115200).
    Baud(u8),
    /// 130: same as Safe.
    Control,
    /// 131: Safe mode.
    Safe,
    /// 132: Full mode.
    Full,
    /// 133 (Create 2 only): power down.
    Power,
    /// 134: Spot clean / demo.
    Spot,
    /// 135: Clean (Create 1: Cover).
    Clean,
    /// 136 on the Create 1: run demo −1 (abort) … 9.
    Demo(i8),
    /// 136 on the Create 2: Max clean.
    Max,
    /// 137: average velocity −500…500 mm/s and radius.
    Drive { velocity: i16, radius: Radius },
    /// 138: motor bits (Create 1: low-side drivers 0–2; Create 2: [`motor_bits`]).
    Motors(u8),
    /// 139: LED bits, power LED colour (0 green … 255 red) and intensity.
    Leds {
        bits: u8,
        power_color: u8,
        power_intensity: u8,
    },
    /// 140: define song `number` (Create 1: 0–15, Create 2: 0–4) as 1–16 `(note, duration in 1/64 s)`.
    Song { number: u8, notes: Vec<(u8, u8)> },
    /// 141: play a defined song.
    Play(u8),
    /// 142: request one packet or group, answered once without framing.
    Sensors(u8),
    /// 143: seek the dock (Create 1: Cover and Dock).
    SeekDock,
    /// 144: Create 1 `[LD2, LD1, LD0]` duty 0–128; Create 2 `[main −127…127, side −127…127, vacuum 0…127]`
    /// (the signed bytes as two's complement).
    PwmMotors([u8; 3]),
    /// 145: each wheel −500…500 mm/s; the right wheel goes first on the wire.
    DriveDirect { right: i16, left: i16 },
    /// 146 (Create 2 only): each wheel PWM −255…255; right first.
    DrivePwm { right: i16, left: i16 },
    /// 148: stream these packets/groups every 15 ms.
    Stream(Vec<u8>),
    /// 149: request these packets/groups once, answered without framing.
    QueryList(Vec<u8>),
    /// 150 0: pause the stream, keeping its list.
    PauseStream,
    /// 150 1: resume the stream with the last list.
    ResumeStream,
    /// 173 (Create 2 only): stop the OI, enter Off.
    Stop,
    /// Any other opcode the model defines (e.g. Create 1 Digital Outputs 147, Script 152, Wait 155–158;
    /// Create 2 Digit LEDs 163/164, Schedule 167), with its raw data bytes.
    Other { opcode: u8, data: Vec<u8> },
}

/// The data-byte layout of `op` on `model`, or `None` if the model has no such opcode [C1 p7–16; C2 p8–22]:
/// the opcodes both models share, then the model's own ([`super::ModelSpec::model_opcodes`]).
fn data_shape(model: Model, op: u8) -> Option<DataShape> {
    use DataShape::{CountedList, Fixed, Song};
    let common = match op {
        128 | 130 | 131 | 132 | 134 | 135 | 143 => Some(Fixed(0)),
        129 | 138 | 141 | 142 | 150 => Some(Fixed(1)),
        139 | 144 => Some(Fixed(3)),
        137 | 145 => Some(Fixed(4)),
        140 => Some(Song),
        148 | 149 => Some(CountedList),
        _ => None,
    };
    common.or_else(|| model.spec().model_opcode(op))
}

/// Opcodes that have their own [`Command`] variant (so `Other` must not carry them).
fn has_own_variant(op: u8) -> bool {
    matches!(op, 7 | 128..=146 | 148..=150 | 173)
}

/// Most ids one Stream or Query List may name: Create 1 43 [C1 p14], Create 2 108 (packet 38's range [C2 p29]).
pub fn max_packet_list_len(model: Model) -> usize {
    model.spec().max_packet_list_len
}

/// Highest song slot: Create 1 15 [C1 p11], Create 2 4 [C2 p19].
pub fn last_song_number(model: Model) -> u8 {
    model.spec().last_song_number
}

fn invalid(msg: String) -> OiError {
    OiError::InvalidArgument(msg)
}

fn check_range(what: &str, value: i32, lo: i32, hi: i32) -> Result<(), OiError> {
    if (lo..=hi).contains(&value) {
        Ok(())
    } else {
        Err(invalid(format!("{what} {value} is outside {lo}..={hi}")))
    }
}

fn check_mask(what: &str, value: u8, allowed: u8, model: Model) -> Result<(), OiError> {
    if value & !allowed == 0 {
        Ok(())
    } else {
        Err(invalid(format!(
            "{what} {value:#010b} sets bits the {model} does not have (allowed {allowed:#010b})"
        )))
    }
}

fn check_packet_list(ids: &[u8], model: Model) -> Result<(), OiError> {
    if ids.is_empty() {
        return Err(OiError::EmptyStreamList);
    }
    let limit = max_packet_list_len(model);
    if ids.len() > limit {
        return Err(OiError::TooManyPackets {
            count: ids.len(),
            limit,
            model,
        });
    }
    ids.iter().try_for_each(|&id| check_available(id, model))
}

fn push_i16(out: &mut Vec<u8>, v: i16) {
    out.extend_from_slice(&v.to_be_bytes());
}

impl Command {
    /// A short name for messages ("Drive Direct").
    pub fn name(&self) -> &'static str {
        match self {
            Command::Start => "Start",
            Command::Reset => "Reset",
            Command::Baud(_) => "Baud",
            Command::Control => "Control",
            Command::Safe => "Safe",
            Command::Full => "Full",
            Command::Power => "Power",
            Command::Spot => "Spot",
            Command::Clean => "Clean",
            Command::Demo(_) => "Demo",
            Command::Max => "Max",
            Command::Drive { .. } => "Drive",
            Command::Motors(_) => "Motors",
            Command::Leds { .. } => "LEDs",
            Command::Song { .. } => "Song",
            Command::Play(_) => "Play",
            Command::Sensors(_) => "Sensors",
            Command::SeekDock => "Seek Dock",
            Command::PwmMotors(_) => "PWM Motors",
            Command::DriveDirect { .. } => "Drive Direct",
            Command::DrivePwm { .. } => "Drive PWM",
            Command::Stream(_) => "Stream",
            Command::QueryList(_) => "Query List",
            Command::PauseStream => "Pause Stream",
            Command::ResumeStream => "Resume Stream",
            Command::Stop => "Stop",
            Command::Other { .. } => "Other",
        }
    }

    /// The opcode byte (Demo and Max share 136; `Other` carries its own).
    pub fn opcode(&self, _model: Model) -> u8 {
        use opcode as op;
        match self {
            Command::Start => op::START,
            Command::Reset => op::RESET,
            Command::Baud(_) => op::BAUD,
            Command::Control => op::CONTROL,
            Command::Safe => op::SAFE,
            Command::Full => op::FULL,
            Command::Power => op::POWER,
            Command::Spot => op::SPOT,
            Command::Clean => op::CLEAN,
            Command::Demo(_) | Command::Max => op::DEMO_OR_MAX,
            Command::Drive { .. } => op::DRIVE,
            Command::Motors(_) => op::MOTORS,
            Command::Leds { .. } => op::LEDS,
            Command::Song { .. } => op::SONG,
            Command::Play(_) => op::PLAY,
            Command::Sensors(_) => op::SENSORS,
            Command::SeekDock => op::SEEK_DOCK,
            Command::PwmMotors(_) => op::PWM_MOTORS,
            Command::DriveDirect { .. } => op::DRIVE_DIRECT,
            Command::DrivePwm { .. } => op::DRIVE_PWM,
            Command::Stream(_) => op::STREAM,
            Command::QueryList(_) => op::QUERY_LIST,
            Command::PauseStream | Command::ResumeStream => op::PAUSE_RESUME_STREAM,
            Command::Stop => op::STOP,
            Command::Other { opcode, .. } => *opcode,
        }
    }

    /// The exact bytes for `model`, after checking every argument against the model's specification.
    pub fn encode(&self, model: Model) -> Result<Vec<u8>, OiError> {
        let mut out = Vec::with_capacity(8);
        self.encode_into(model, &mut out)?;
        Ok(out)
    }

    /// Like [`Command::encode`], appending to `out` (nothing is appended on error).
    pub fn encode_into(&self, model: Model, out: &mut Vec<u8>) -> Result<(), OiError> {
        self.validate(model)?;
        out.push(self.opcode(model));
        match self {
            Command::Baud(code) | Command::Motors(code) | Command::Play(code) => out.push(*code),
            Command::Sensors(id) => out.push(*id),
            Command::Demo(d) => out.push(*d as u8),
            Command::Drive { velocity, radius } => {
                push_i16(out, *velocity);
                push_i16(out, radius.to_wire());
            }
            Command::Leds {
                bits,
                power_color,
                power_intensity,
            } => out.extend_from_slice(&[*bits, *power_color, *power_intensity]),
            Command::Song { number, notes } => {
                out.push(*number);
                out.push(notes.len() as u8); // validated: 1..=16
                for &(note, duration) in notes {
                    out.extend_from_slice(&[note, duration]);
                }
            }
            Command::PwmMotors(duty) => out.extend_from_slice(duty),
            Command::DriveDirect { right, left } | Command::DrivePwm { right, left } => {
                push_i16(out, *right);
                push_i16(out, *left);
            }
            Command::Stream(ids) | Command::QueryList(ids) => {
                out.push(ids.len() as u8); // validated: <= 108
                out.extend_from_slice(ids);
            }
            Command::PauseStream => out.push(0),
            Command::ResumeStream => out.push(1),
            Command::Other { data, .. } => out.extend_from_slice(data),
            _ => {}
        }
        Ok(())
    }

    /// Checks that `model` has this command and that every argument is in its documented range.
    pub fn validate(&self, model: Model) -> Result<(), OiError> {
        let spec = model.spec();
        // A command that only some models have exists on `model` when its opcode there takes exactly
        // the command's data bytes (136 is Demo with one byte on the Create 1, Max with none on the
        // Create 2).
        let needs = |shape: DataShape| {
            if data_shape(model, self.opcode(model)) == Some(shape) {
                Ok(())
            } else {
                Err(OiError::CommandNotOnModel {
                    command: self.name(),
                    model,
                })
            }
        };
        let max_speed = i32::from(spec.max_wheel_speed_mm_s);
        match self {
            Command::Reset | Command::Power | Command::Max | Command::Stop => {
                needs(DataShape::Fixed(0))
            }
            Command::DrivePwm { right, left } => {
                needs(DataShape::Fixed(4))?;
                check_range("right wheel PWM", i32::from(*right), -255, 255)?;
                check_range("left wheel PWM", i32::from(*left), -255, 255)
            }
            Command::Demo(d) => {
                needs(DataShape::Fixed(1))?;
                check_range("demo number", i32::from(*d), -1, 9)
            }
            Command::Baud(code) => check_range("baud code", i32::from(*code), 0, 11),
            Command::Drive { velocity, radius } => {
                check_range(
                    "velocity (mm/s)",
                    i32::from(*velocity),
                    -max_speed,
                    max_speed,
                )?;
                match radius {
                    Radius::Mm(0) => Err(invalid(
                        "radius 0 is undefined; use Radius::Straight or a turn in place".into(),
                    )),
                    Radius::Mm(r) => check_range("radius (mm)", i32::from(*r), -2000, 2000),
                    _ => Ok(()),
                }
            }
            Command::DriveDirect { right, left } => {
                check_range(
                    "right wheel velocity (mm/s)",
                    i32::from(*right),
                    -max_speed,
                    max_speed,
                )?;
                check_range(
                    "left wheel velocity (mm/s)",
                    i32::from(*left),
                    -max_speed,
                    max_speed,
                )
            }
            Command::Motors(bits) => check_mask("motor bits", *bits, spec.motor_bits, model),
            Command::Leds { bits, .. } => check_mask("LED bits", *bits, spec.led_bits, model),
            Command::Song { number, notes } => {
                check_range(
                    "song number",
                    i32::from(*number),
                    0,
                    i32::from(last_song_number(model)),
                )?;
                check_range(
                    "song length (notes)",
                    i32::try_from(notes.len()).unwrap_or(i32::MAX),
                    1,
                    16,
                )
            }
            Command::Play(number) => check_range(
                "song number",
                i32::from(*number),
                0,
                i32::from(last_song_number(model)),
            ),
            Command::Sensors(id) => check_available(*id, model),
            Command::PwmMotors(duty) => match spec.pwm_motors {
                PwmMotorsDuty::LowSideDrivers => duty
                    .iter()
                    .try_for_each(|&d| check_range("low-side driver duty", i32::from(d), 0, 128)),
                PwmMotorsDuty::Brushes => {
                    check_range("main brush PWM", i32::from(duty[0] as i8), -127, 127)?;
                    check_range("side brush PWM", i32::from(duty[1] as i8), -127, 127)?;
                    check_range("vacuum PWM", i32::from(duty[2]), 0, 127)
                }
            },
            Command::Stream(ids) | Command::QueryList(ids) => check_packet_list(ids, model),
            Command::Other { opcode, data } => validate_other(model, *opcode, data),
            Command::Start
            | Command::Control
            | Command::Safe
            | Command::Full
            | Command::Spot
            | Command::Clean
            | Command::SeekDock
            | Command::PauseStream
            | Command::ResumeStream => Ok(()),
        }
    }
}

fn validate_other(model: Model, op: u8, data: &[u8]) -> Result<(), OiError> {
    if has_own_variant(op) {
        return Err(invalid(format!(
            "opcode {op} has its own Command variant; Other is for the remaining opcodes"
        )));
    }
    match data_shape(model, op) {
        None => Err(invalid(format!("opcode {op} is not a {model} command"))),
        Some(DataShape::Fixed(n)) if data.len() != n => Err(invalid(format!(
            "opcode {op} takes {n} data bytes, got {}",
            data.len()
        ))),
        Some(DataShape::CountedList) => match data.split_first() {
            Some((&n, rest)) if usize::from(n) == rest.len() => {
                check_range("script length", i32::from(n), 0, 100)
            }
            _ => Err(invalid(format!(
                "opcode {op} takes a count byte N followed by exactly N bytes"
            ))),
        },
        _ => Ok(()),
    }
}

/// What [`parse_command`] found at the start of a buffer.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum ParsedCommand {
    /// The buffer is empty or ends before the command's last data byte; wait for more.
    Incomplete,
    /// A whole command, `consumed` bytes long including the opcode.
    Complete { command: Command, consumed: usize },
    /// The model has no such opcode (the specs do not say what the robot does; the simulator drops the byte).
    UnknownOpcode(u8),
}

/// The robot's side: reads one command from the start of `buf` (which must begin at an opcode), with
/// the exact per-model data-byte counts. Any data values are accepted, as the firmware would; only
/// the opcode itself can be unknown.
pub fn parse_command(model: Model, buf: &[u8]) -> ParsedCommand {
    let Some(&op) = buf.first() else {
        return ParsedCommand::Incomplete;
    };
    let Some(shape) = data_shape(model, op) else {
        return ParsedCommand::UnknownOpcode(op);
    };
    let total = match shape {
        DataShape::Fixed(n) => Some(1 + n),
        DataShape::CountedList => buf.get(1).map(|&n| 2 + usize::from(n)),
        DataShape::Song => buf.get(2).map(|&n| 3 + 2 * usize::from(n)),
    };
    match total.and_then(|t| buf.get(1..t)) {
        Some(data) => ParsedCommand::Complete {
            command: decode_command(op, data),
            consumed: 1 + data.len(),
        },
        None => ParsedCommand::Incomplete,
    }
}

fn be16(data: &[u8], at: usize) -> i16 {
    match data.get(at..at + 2) {
        Some(&[h, l]) => i16::from_be_bytes([h, l]),
        _ => 0,
    }
}

fn byte(data: &[u8], at: usize) -> u8 {
    data.get(at).copied().unwrap_or(0)
}

/// Builds the command for `op` from exactly its data bytes (lengths already checked by [`parse_command`],
/// from the model's opcode table).
fn decode_command(op: u8, data: &[u8]) -> Command {
    let d0 = byte(data, 0);
    match op {
        128 => Command::Start,
        7 => Command::Reset,
        129 => Command::Baud(d0),
        130 => Command::Control,
        131 => Command::Safe,
        132 => Command::Full,
        133 => Command::Power,
        134 => Command::Spot,
        135 => Command::Clean,
        // Demo where the model's 136 takes a data byte (Create 1), Max where it takes none (Create 2).
        136 if data.len() == 1 => Command::Demo(d0 as i8),
        136 => Command::Max,
        137 => Command::Drive {
            velocity: be16(data, 0),
            radius: Radius::from_wire(be16(data, 2)),
        },
        138 => Command::Motors(d0),
        139 => Command::Leds {
            bits: d0,
            power_color: byte(data, 1),
            power_intensity: byte(data, 2),
        },
        140 => Command::Song {
            number: d0,
            notes: data
                .get(2..)
                .unwrap_or_default()
                .chunks_exact(2)
                .map(|pair| (byte(pair, 0), byte(pair, 1)))
                .collect(),
        },
        141 => Command::Play(d0),
        142 => Command::Sensors(d0),
        143 => Command::SeekDock,
        144 => Command::PwmMotors([d0, byte(data, 1), byte(data, 2)]),
        145 => Command::DriveDirect {
            right: be16(data, 0),
            left: be16(data, 2),
        },
        146 => Command::DrivePwm {
            right: be16(data, 0),
            left: be16(data, 2),
        },
        148 => Command::Stream(data.get(1..).unwrap_or_default().to_vec()),
        149 => Command::QueryList(data.get(1..).unwrap_or_default().to_vec()),
        150 if d0 == 0 => Command::PauseStream,
        150 if d0 == 1 => Command::ResumeStream,
        173 => Command::Stop,
        _ => Command::Other {
            opcode: op,
            data: data.to_vec(),
        },
    }
}

#[cfg(test)]
mod tests;

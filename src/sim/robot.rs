//! [`SimRobot`]: the simulated Create as the host sees it — Open Interface command bytes in, sensor
//! bytes out — over the physical [`World`].
//!
//! - [`SimRobot::receive`] buffers command bytes in any chunking and executes each command once all of
//!   its data bytes are there (the robot blocks until they arrive [C1 p7; C2 p8]); unknown opcodes drop
//!   one byte and are counted.
//! - [`SimRobot::step`] advances 15 ms: the world moves, the firmware reads its sensors, Safe-mode
//!   trips are checked, and one stream frame is sent if a stream is running.
//! - Everything the robot sends (stream frames, Sensors and Query List replies, the Create 2's reset
//!   banner) goes through a transmit buffer that the line drains at the baud rate; what overflows it is
//!   lost, which is how an over-budget stream corrupts [C1 p14; C2 p22].
//!
//! Submodules: `execute` (the mode machine and every command), `report` (sensor values, replies and
//! frames), `drive` (drive-command arithmetic).

mod drive;
mod execute;
mod report;

use crate::oi::Model;
use crate::oi::SensorValues;
use crate::oi::command::{ParsedCommand, parse_command};
use crate::rng::Rng;

use super::odometry::Odometry;
use super::params::SimParams;
use super::readings::{Readings, Sensing};
use super::world::{DriveTarget, LEFT, RIGHT, World};

/// The Open Interface mode (packet 35) [C1 p6–7; C2 p7–10].
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum OiMode {
    /// Listening only for Start (and Reset on the Create 2).
    Off,
    /// Sensors readable, actuator commands ignored.
    Passive,
    /// Full control with the cliff / wheel-drop safety trips.
    Safe,
    /// Full control, no safety trips.
    Full,
}

impl OiMode {
    /// The value of packet 35.
    pub fn code(self) -> i32 {
        match self {
            OiMode::Off => 0,
            OiMode::Passive => 1,
            OiMode::Safe => 2,
            OiMode::Full => 3,
        }
    }

    /// True in Safe and Full, the modes that accept actuator commands.
    pub fn controls_actuators(self) -> bool {
        matches!(self, OiMode::Safe | OiMode::Full)
    }
}

/// Why the robot counted something it did not act on.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct SimCounters {
    /// Bytes dropped because their opcode is unknown to the model.
    pub unknown_opcode_bytes: u64,
    /// Bytes ignored in Off mode (anything but Start, and Reset on the Create 2).
    pub ignored_in_off: u64,
    /// Actuator commands consumed and ignored in Passive mode.
    pub ignored_in_passive: u64,
    /// Sensors / Query List / Stream requests (or ids in them) naming packets the model lacks, and
    /// other requests with invalid arguments (bad baud code, song number).
    pub rejected_requests: u64,
    /// Commands executed.
    pub commands: u64,
    /// Stream frames sent.
    pub frames_sent: u64,
    /// Output bytes lost because the transmit buffer was full.
    pub dropped_tx_bytes: u64,
    /// Safe-mode trips (cliff or wheel drop) that stopped the robot and entered Passive.
    pub safety_trips: u64,
}

/// The last Drive / Drive Direct arguments (packets 39–42).
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
struct Requested {
    velocity: i32,
    radius: i32,
    right: i32,
    left: i32,
}

/// A byte-exact simulated Create.
#[derive(Debug, Clone)]
pub struct SimRobot {
    model: Model,
    world: World,
    sensing: Sensing,
    readings: Readings,
    odometry: Odometry,
    mode: OiMode,
    input: Vec<u8>,
    output: Vec<u8>,
    tx_level: usize,
    baud: u32,
    /// Fault injection: the line's real rate when it differs from `baud` (a robot that fell back to a
    /// slower rate), bits/s.
    line_baud: Option<u32>,
    /// Fault injection: report packet 35 as mode + 1 (the firmware quirk of create_robot issue 64).
    mode_quirk: bool,
    stream_ids: Vec<u8>,
    /// Whether `stream_ids` take Distance and Angle (`report::takes_odometry`), found when they are set.
    stream_takes_odometry: [bool; 2],
    /// Reused for every stream frame: a copy of the ids it reports, and the frame's bytes.
    frame_scratch: (Vec<u8>, Vec<u8>),
    stream_paused: bool,
    drive: DriveTarget,
    requested: Requested,
    songs: Vec<Option<u32>>,
    song_number: u8,
    song_steps_left: u32,
    counters: SimCounters,
    steps: u64,
}

impl SimRobot {
    /// A robot of `model` at rest in its start pose, OI in Off, all randomness from `seed`.
    pub fn new(model: Model, params: SimParams, seed: u64) -> Self {
        let root = Rng::new(seed);
        let sensing = Sensing::new(&params, model.spec(), &root.fork(1));
        let odometry = Odometry::new(&params);
        let world = World::new(params, root.fork(2));
        let mut robot = SimRobot {
            model,
            sensing,
            readings: Readings::default(),
            odometry,
            mode: OiMode::Off,
            input: Vec::new(),
            output: Vec::new(),
            tx_level: 0,
            baud: model.baud(),
            line_baud: None,
            mode_quirk: false,
            stream_ids: Vec::new(),
            stream_takes_odometry: [false; 2],
            frame_scratch: (Vec::new(), Vec::new()),
            stream_paused: false,
            drive: DriveTarget::STOP,
            requested: Requested::default(),
            songs: vec![None; usize::from(crate::oi::command::last_song_number(model)) + 1],
            song_number: 0,
            song_steps_left: 0,
            counters: SimCounters::default(),
            steps: 0,
            world,
        };
        robot.readings = robot.sensing.read(&robot.world);
        robot
    }

    /// Command bytes from the host, in any chunking.
    pub fn receive(&mut self, bytes: &[u8]) {
        self.input.extend_from_slice(bytes);
        let mut pos = 0;
        while let Some(rest) = self.input.get(pos..).filter(|r| !r.is_empty()) {
            if self.mode == OiMode::Off {
                let byte = rest.first().copied().unwrap_or_default();
                pos += 1;
                self.off_byte(byte);
                continue;
            }
            match parse_command(self.model, rest) {
                ParsedCommand::Incomplete => break,
                ParsedCommand::UnknownOpcode(_) => {
                    self.counters.unknown_opcode_bytes += 1;
                    pos += 1;
                }
                ParsedCommand::Complete { command, consumed } => {
                    pos += consumed.max(1);
                    self.counters.commands += 1;
                    self.execute(command);
                }
            }
        }
        self.input.drain(..pos.min(self.input.len()));
    }

    /// Advances the world by exactly 15 ms and, if a stream runs, sends one frame.
    pub fn step(&mut self) {
        let budget = crate::oi::model::stream_budget_bytes(self.line_rate());
        self.tx_level = self.tx_level.saturating_sub(budget);
        self.world.step();
        let commands = [
            self.world.wheel_command(LEFT),
            self.world.wheel_command(RIGHT),
        ];
        self.odometry.advance(self.world.step_travel_mm(), commands);
        self.readings = self.sensing.read(&self.world);
        self.song_steps_left = self.song_steps_left.saturating_sub(1);
        self.check_safety();
        self.send_stream_frame();
        self.steps += 1;
    }

    /// Bytes the robot has sent since the last call.
    pub fn take_output(&mut self) -> Vec<u8> {
        std::mem::take(&mut self.output)
    }

    /// Like [`SimRobot::take_output`], giving the robot `spare` (emptied) to send into from now on: a
    /// caller that hands back each step's buffer once it is done with it allocates nothing once warm.
    pub fn swap_output(&mut self, mut spare: Vec<u8>) -> Vec<u8> {
        spare.clear();
        std::mem::replace(&mut self.output, spare)
    }

    /// The physical truth.
    pub fn world(&self) -> &World {
        &self.world
    }

    /// The physical truth, for fault injection (lift the robot, put a cliff under a sensor, move it).
    pub fn world_mut(&mut self) -> &mut World {
        &mut self.world
    }

    /// The OI mode.
    pub fn oi_mode(&self) -> OiMode {
        self.mode
    }

    /// Every packet the model has, as the robot would report it now (odometry is not reset).
    pub fn sensors(&self) -> SensorValues {
        let mut values = SensorValues::new();
        self.fill_values(
            &mut values,
            self.odometry.peek_distance_mm(),
            self.odometry.peek_angle_deg(),
        );
        values
    }

    /// Steps taken since construction.
    pub fn elapsed_steps(&self) -> u64 {
        self.steps
    }

    /// The robot's model.
    pub fn model(&self) -> Model {
        self.model
    }

    /// What the robot counted but did not act on, and what it sent.
    pub fn counters(&self) -> &SimCounters {
        &self.counters
    }

    /// The packet ids being streamed (empty when no stream was requested).
    pub fn stream_ids(&self) -> &[u8] {
        &self.stream_ids
    }

    /// Fault injection: makes packet 35 read mode + 1 (Safe as 3, Full as 4), as some Create 2
    /// firmware does (`AutonomyLab/create_robot#64`, `AutonomyLab/libcreate#67`).
    pub fn set_mode_quirk(&mut self, on: bool) {
        self.mode_quirk = on;
    }

    /// True when packet 35 reads mode + 1.
    pub fn mode_quirk(&self) -> bool {
        self.mode_quirk
    }

    /// Fault injection: the transmit line really runs at `baud` bits/s whatever the OI baud is (`None`:
    /// at the OI baud). A line slower than the stream needs overflows the transmit buffer, and the
    /// stream corrupts [C1 p14; C2 p22].
    pub fn set_line_baud(&mut self, baud: Option<u32>) {
        self.line_baud = baud;
    }

    /// The rate the robot's UART runs at, bits/s: the model's default until a Baud command changes it. A
    /// host at another rate cannot talk to it.
    pub fn oi_baud(&self) -> u32 {
        self.baud
    }

    /// The rate the transmit buffer drains at, bits/s: the line's when fault injection slowed it, else the
    /// OI baud.
    pub fn line_rate(&self) -> u32 {
        self.line_baud.unwrap_or(self.baud)
    }

    /// Queues `bytes` for sending; whatever does not fit in the transmit buffer is lost.
    fn transmit(&mut self, bytes: &[u8]) {
        let budget = crate::oi::model::stream_budget_bytes(self.line_rate());
        let capacity = budget + self.world.params().tx_buffer_bytes;
        let room = capacity.saturating_sub(self.tx_level);
        let sent = bytes.len().min(room);
        self.output
            .extend_from_slice(bytes.get(..sent).unwrap_or_default());
        self.tx_level += sent;
        self.counters.dropped_tx_bytes += (bytes.len() - sent) as u64;
    }

    /// In Off the robot listens only for Start (and Reset on the Create 2); every other byte is
    /// dropped one at a time.
    fn off_byte(&mut self, byte: u8) {
        use crate::oi::command::opcode;
        match byte {
            opcode::START => {
                self.counters.commands += 1;
                self.execute(crate::oi::command::Command::Start);
            }
            opcode::RESET if self.model.spec().has_reset_opcode => {
                self.counters.commands += 1;
                self.execute(crate::oi::command::Command::Reset);
            }
            _ => self.counters.ignored_in_off += 1,
        }
    }
}

#[cfg(test)]
mod tests;

//! The OI mode machine and what every command does [C1 pp6–16; C2 pp7–22].
//!
//! - Start → Passive from any mode. Safe/Control → Safe, Full → Full (from Passive, Safe or Full).
//! - Actuator commands (drive, motors, LEDs, Play, and the model's other output commands) act only in
//!   Safe and Full; in Passive they are consumed and ignored (counted).
//! - Entering Passive or Off stops the wheels: in those modes nothing may drive them (whether the real
//!   firmware stops them on Start is undocumented).
//! - Spot, Clean, Max, Seek Dock, Demo and Power enter Passive; the simulator runs no built-in
//!   behaviour.
//! - Create 2: Stop → Off and ends the stream; Reset → Off, ends the stream, clears the OI state and
//!   prints a boot banner.
//! - Safe-mode trips (checked every step): any wheel drop, or a cliff while driving forward (or backward
//!   on a radius tighter than the body) → stop the motors, Passive. Full ignores them.

use crate::oi::command::{Command, max_packet_list_len};
use crate::oi::packets::available_on;
use crate::sim::STEP_SECONDS;
use crate::sim::world::DriveTarget;

use crate::oi::model::BAUD_RATES;

use super::drive::{drive_wheel_speeds, pwm_target, speed_target};
use super::{OiMode, Requested, SimRobot};

impl SimRobot {
    /// Executes one complete command in the present mode.
    pub(super) fn execute(&mut self, command: Command) {
        let mode = self.mode;
        match command {
            Command::Start => self.enter(OiMode::Passive),
            Command::Reset => self.reset(),
            Command::Stop => {
                self.stream_ids.clear();
                self.enter(OiMode::Off);
            }
            Command::Safe | Command::Control => self.enter(OiMode::Safe),
            Command::Full => self.enter(OiMode::Full),
            Command::Power
            | Command::Spot
            | Command::Clean
            | Command::Max
            | Command::Demo(_)
            | Command::SeekDock => self.enter(OiMode::Passive),
            Command::Baud(code) => match BAUD_RATES.get(usize::from(code)) {
                Some(&baud) => self.baud = baud,
                None => self.counters.rejected_requests += 1,
            },
            Command::Song { number, notes } => self.define_song(number, &notes),
            Command::Sensors(id) => self.reply(&[id]),
            Command::QueryList(ids) => self.reply(&ids),
            Command::Stream(ids) => self.start_stream(ids),
            Command::PauseStream => self.stream_paused = true,
            Command::ResumeStream => self.stream_paused = false,
            _ if !mode.controls_actuators() => self.counters.ignored_in_passive += 1,
            Command::Drive { velocity, radius } => {
                let p = self.world.params();
                let (left, right) = drive_wheel_speeds(velocity, radius, p);
                let target = speed_target(left, right, p);
                self.requested.velocity = i32::from(velocity);
                self.requested.radius = i32::from(radius.to_wire());
                self.set_drive(target);
            }
            Command::DriveDirect { right, left } => {
                let p = self.world.params();
                let max = p.max_wheel_speed_mm_s as i32;
                let (right, left) = (i32::from(right), i32::from(left));
                let target = speed_target(f64::from(left), f64::from(right), p);
                self.requested.right = right.clamp(-max, max);
                self.requested.left = left.clamp(-max, max);
                self.set_drive(target);
            }
            Command::DrivePwm { right, left } => self.set_drive(pwm_target(left, right)),
            Command::Play(number) => self.play(number),
            // Cleaning motors, LEDs, digital outputs, IR, scripts, schedules: accepted, no effect on
            // the simulated world.
            Command::Motors(_) | Command::PwmMotors(_) | Command::Leds { .. } => {}
            Command::Other { .. } => {}
        }
    }

    fn set_drive(&mut self, target: DriveTarget) {
        self.drive = target;
        self.world.command(target);
    }

    /// Changes mode; leaving the actuator modes stops the wheels.
    fn enter(&mut self, mode: OiMode) {
        if !mode.controls_actuators() {
            self.drive = DriveTarget::STOP;
            self.world.halt();
        }
        self.mode = mode;
    }

    /// Create 2 Reset (7): like re-inserting the battery [C2 p8, p27]; prints [`SimRobot::boot_banner`].
    fn reset(&mut self) {
        self.odometry = crate::sim::odometry::Odometry::new(self.world.params());
        self.stream_ids.clear();
        self.stream_paused = false;
        self.requested = Requested::default();
        self.songs.iter_mut().for_each(|s| *s = None);
        self.song_steps_left = 0;
        self.baud = self.model.baud();
        self.enter(OiMode::Off);
        let banner = self.boot_banner();
        self.transmit(banner.as_bytes());
    }

    /// The text a Create 2 prints when it boots (after Reset or power-on), lines ending in CR LF: a short
    /// banner built from the lines a real one prints (pycreate2 issue 12), not a byte-exact copy.
    pub fn boot_banner(&self) -> String {
        format!(
            "\r\nbl-start\r\nRoomba by iRobot!\r\nr3-robot/tags/release-stm32-3.7.7:6913 CLEAN\r\n\
             initial-lithium-battery-capacity: set to {} mAH\r\n",
            self.world.params().capacity_mah.round() as i64
        )
    }

    fn define_song(&mut self, number: u8, notes: &[(u8, u8)]) {
        let sixty_fourths: u32 = notes.iter().map(|&(_, d)| u32::from(d)).sum();
        match self.songs.get_mut(usize::from(number)) {
            Some(slot) if !notes.is_empty() => *slot = Some(sixty_fourths),
            _ => self.counters.rejected_requests += 1,
        }
    }

    fn play(&mut self, number: u8) {
        // Create 1: "ignored if a song is already playing" [C1 p13].
        if self.model.spec().play_ignored_while_playing && self.song_steps_left > 0 {
            return;
        }
        match self.songs.get(usize::from(number)).copied().flatten() {
            Some(sixty_fourths) => {
                let seconds = f64::from(sixty_fourths) / 64.0;
                self.song_number = number;
                self.song_steps_left = (seconds / STEP_SECONDS).ceil() as u32;
            }
            None => self.counters.rejected_requests += 1,
        }
    }

    /// Stream (148): an empty list stops the stream; a list naming a packet the model lacks, or longer
    /// than the model allows, is rejected whole and the old stream goes on.
    fn start_stream(&mut self, ids: Vec<u8>) {
        if ids.is_empty() {
            self.stream_ids.clear();
            return;
        }
        let valid = ids.len() <= max_packet_list_len(self.model)
            && ids.iter().all(|&id| available_on(id, self.model))
            && crate::oi::frame::stream_payload_len(&ids).is_ok();
        if valid {
            self.stream_takes_odometry = super::report::takes_odometry(&ids);
            self.stream_ids = ids;
            self.stream_paused = false;
        } else {
            self.counters.rejected_requests += 1;
        }
    }

    /// Safe-mode trips [C1 p6; C2 p7], checked once per step after the sensors are read.
    pub(super) fn check_safety(&mut self) {
        if self.mode != OiMode::Safe {
            return;
        }
        let dropped = self.world.wheel_drops().iter().any(|&d| d);
        let cliff = self.readings.cliffs.iter().any(|&c| c);
        if dropped || (cliff && self.driving_into_cliff_danger()) {
            self.counters.safety_trips += 1;
            self.enter(OiMode::Passive);
        }
    }

    /// Moving forward, or backward on a radius smaller than the body's.
    fn driving_into_cliff_danger(&self) -> bool {
        let (left, right) = match self.drive {
            DriveTarget::Speed {
                left_mm_s,
                right_mm_s,
            } => (left_mm_s, right_mm_s),
            DriveTarget::Duty { left, right } => (left, right),
        };
        let common = (left + right) / 2.0;
        if common > 0.0 {
            return true;
        }
        if common < 0.0 {
            let half_base = self.world.params().wheel_base_m * 1000.0 / 2.0;
            let turn = right - left;
            let radius = if turn == 0.0 {
                f64::INFINITY
            } else {
                (half_base * (left + right) / turn).abs()
            };
            return radius < self.world.params().body_radius_m * 1000.0;
        }
        false
    }
}

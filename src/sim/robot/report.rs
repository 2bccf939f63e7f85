//! What the robot reports: the value of every packet, Sensors (142) / Query List (149) replies (the
//! requested packets' data concatenated, no framing [C1 p13; C2 p21]) and stream frames (header 19,
//! length, id/data pairs, checksum [C1 p14; C2 p22]).
//!
//! A report that contains Distance (19) or Angle (20) — alone or in a group — hands over what has
//! accumulated and starts afresh [C1 p18–19; C2 p27].

use crate::oi::SensorValues;
use crate::oi::frame::encode_stream_frame_into;
use crate::oi::packets::{available_on, encode_data, group_members, id};
use crate::sim::world::{LEFT, RIGHT};

use super::SimRobot;

impl SimRobot {
    /// Sets every packet the model has, with the given odometry values.
    pub(super) fn fill_values(&self, v: &mut SensorValues, distance: i32, angle: i32) {
        let spec = self.model.spec();
        let r = &self.readings;
        // No IR byte seen: 255 on the Create 1, 0 on the Create 2 [C1 p18; C2 p26].
        let ir_none = i32::from(spec.ir_no_byte);
        v.set(id::BUMPS_WHEEL_DROPS, r.bumps_drops);
        v.set(id::WALL, i32::from(r.wall));
        let cliff_ids = [
            id::CLIFF_LEFT,
            id::CLIFF_FRONT_LEFT,
            id::CLIFF_FRONT_RIGHT,
            id::CLIFF_RIGHT,
        ];
        for (&pid, &c) in cliff_ids.iter().zip(&r.cliffs) {
            v.set(pid, i32::from(c));
        }
        v.set(id::VIRTUAL_WALL, 0);
        v.set(id::OVERCURRENTS, r.overcurrents);
        v.set(id::DIRT_DETECT, 0);
        v.set(id::UNUSED_16, 0);
        v.set(id::IR_OMNI, ir_none);
        v.set(id::BUTTONS, 0);
        v.set(id::DISTANCE, distance);
        v.set(id::ANGLE, angle);
        v.set(id::CHARGING_STATE, 0);
        v.set(id::VOLTAGE, r.voltage_mv);
        v.set(id::CURRENT, r.current_ma);
        v.set(id::TEMPERATURE, r.temperature_c);
        v.set(id::BATTERY_CHARGE, r.charge_mah);
        v.set(id::BATTERY_CAPACITY, r.capacity_mah);
        v.set(id::WALL_SIGNAL, r.wall_signal);
        let signal_ids = [
            id::CLIFF_LEFT_SIGNAL,
            id::CLIFF_FRONT_LEFT_SIGNAL,
            id::CLIFF_FRONT_RIGHT_SIGNAL,
            id::CLIFF_RIGHT_SIGNAL,
        ];
        for (&pid, &s) in signal_ids.iter().zip(&r.cliff_signals) {
            v.set(pid, s);
        }
        // Cargo bay: digital input 4 (device detect) is high by default [C1 p20]; without one, 0.
        let cargo = if spec.has_cargo_bay { 16 } else { 0 };
        v.set(id::CARGO_BAY_DIGITAL_INPUTS, cargo);
        v.set(id::CARGO_BAY_ANALOG_SIGNAL, 0);
        v.set(id::CHARGING_SOURCES, 0);
        v.set(id::OI_MODE, self.mode.code() + i32::from(self.mode_quirk));
        v.set(id::SONG_NUMBER, i32::from(self.song_number));
        v.set(id::SONG_PLAYING, i32::from(self.song_steps_left > 0));
        v.set(id::STREAM_PACKET_COUNT, self.stream_ids.len() as i32);
        v.set(id::REQUESTED_VELOCITY, self.requested.velocity);
        v.set(id::REQUESTED_RADIUS, self.requested.radius);
        v.set(id::REQUESTED_RIGHT_VELOCITY, self.requested.right);
        v.set(id::REQUESTED_LEFT_VELOCITY, self.requested.left);
        if spec.has_encoders {
            v.set(id::LEFT_ENCODER, self.odometry.encoder(LEFT));
            v.set(id::RIGHT_ENCODER, self.odometry.encoder(RIGHT));
        }
        if spec.has_light_bumpers {
            v.set(id::LIGHT_BUMPER, r.light_bumper);
            let bump_ids = [
                id::LIGHT_BUMP_LEFT_SIGNAL,
                id::LIGHT_BUMP_FRONT_LEFT_SIGNAL,
                id::LIGHT_BUMP_CENTER_LEFT_SIGNAL,
                id::LIGHT_BUMP_CENTER_RIGHT_SIGNAL,
                id::LIGHT_BUMP_FRONT_RIGHT_SIGNAL,
                id::LIGHT_BUMP_RIGHT_SIGNAL,
            ];
            for (&pid, &s) in bump_ids.iter().zip(&r.light_bump_signals) {
                v.set(pid, s);
            }
        }
        if spec.has_directional_ir {
            v.set(id::IR_LEFT, ir_none);
            v.set(id::IR_RIGHT, ir_none);
        }
        if spec.has_motor_currents {
            v.set(id::LEFT_MOTOR_CURRENT, r.wheel_current_ma[LEFT]);
            v.set(id::RIGHT_MOTOR_CURRENT, r.wheel_current_ma[RIGHT]);
            v.set(id::MAIN_BRUSH_CURRENT, 0);
            v.set(id::SIDE_BRUSH_CURRENT, 0);
        }
        if spec.has_stasis {
            v.set(id::STASIS, r.stasis);
        }
    }

    /// The values for a report whose packets take (and so reset) the odometry as `takes` says
    /// (see [`takes_odometry`]).
    fn report_values(&mut self, takes: [bool; 2]) -> SensorValues {
        let [takes_distance, takes_angle] = takes;
        let distance = if takes_distance {
            self.odometry.take_distance_mm()
        } else {
            self.odometry.peek_distance_mm()
        };
        let angle = if takes_angle {
            self.odometry.take_angle_deg()
        } else {
            self.odometry.peek_angle_deg()
        };
        let mut values = SensorValues::new();
        self.fill_values(&mut values, distance, angle);
        values
    }

    /// Sensors / Query List: the data of each requested packet the model has, in order. Ids the
    /// model lacks are skipped and counted (the firmware's answer is undocumented).
    pub(super) fn reply(&mut self, ids: &[u8]) {
        let known: Vec<u8> = ids
            .iter()
            .copied()
            .filter(|&i| available_on(i, self.model))
            .collect();
        self.counters.rejected_requests += (ids.len() - known.len()) as u64;
        if known.is_empty() {
            return;
        }
        let values = self.report_values(takes_odometry(&known));
        let mut out = Vec::new();
        for &i in &known {
            if encode_data(i, &values, &mut out).is_err() {
                self.counters.rejected_requests += 1;
            }
        }
        self.transmit(&out);
    }

    /// One stream frame, if a stream is requested, not paused, and the OI is on.
    pub(super) fn send_stream_frame(&mut self) {
        if self.stream_ids.is_empty() || self.stream_paused || self.mode == super::OiMode::Off {
            return;
        }
        let (mut ids, mut frame) = std::mem::take(&mut self.frame_scratch);
        ids.clear();
        ids.extend_from_slice(&self.stream_ids);
        // The stream's ids have not changed since `start_stream` found what they take.
        let values = self.report_values(self.stream_takes_odometry);
        match encode_stream_frame_into(&ids, &values, &mut frame) {
            Ok(()) => {
                self.transmit(&frame);
                self.counters.frames_sent += 1;
            }
            Err(_) => self.counters.rejected_requests += 1,
        }
        self.frame_scratch = (ids, frame);
    }
}

/// Whether a report of `ids` contains Distance and Angle (alone or in a group): `[distance, angle]`.
pub(super) fn takes_odometry(ids: &[u8]) -> [bool; 2] {
    let contains = |packet: u8| {
        ids.iter().any(|&i| {
            i == packet || group_members(i).is_some_and(|members| members.contains(&packet))
        })
    };
    [contains(id::DISTANCE), contains(id::ANGLE)]
}

//! [`World`]: the physical truth of the simulation — a differential-drive Create in the paper's
//! triangular enclosure, its two wheel motors and its battery — advanced in 15 ms steps.
//!
//! Each step runs `substeps` sub-steps: commands whose latency has elapsed reach the wheels, each wheel
//! motor advances (see [`super::motor`]), walls constrain the motion, the pose integrates, the battery
//! discharges. Walls are line segments and the body a disc; a wall the robot is driving into blocks
//! the common (forward/backward) motion of the wheels completely, because the weighted robot's wheels
//! do not slip (paper) — they stall — while turning in place stays free. Contacts on the front half of
//! the body press the bumper (left or right by the contact's bearing). When both wheels drive into the
//! wall both stall (the bumper's grip on the wall keeps the robot from pivoting on the stronger wheel).

use std::collections::VecDeque;

use super::battery::Battery;
use super::geometry::{Contact, Enclosure, Vec2};
use super::motor::{MotorConstants, WheelCommand, WheelMotor};
use super::params::SimParams;
use crate::rng::Rng;

pub use super::STEP_SECONDS;
/// Index of the left wheel in per-wheel arrays.
pub const LEFT: usize = 0;
/// Index of the right wheel in per-wheel arrays.
pub const RIGHT: usize = 1;
/// Most commands waiting out their latency at once; older ones are dropped beyond this.
const MAX_PENDING: usize = 64;

/// Where the robot is: centre position (m) and heading (rad, counter-clockwise from +x).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pose {
    pub x_m: f64,
    pub y_m: f64,
    pub heading_rad: f64,
}

/// What the firmware asks of the two wheels.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum DriveTarget {
    /// Closed-loop wheel speeds, mm/s (already limited and quantised; 0 brakes that wheel).
    Speed { left_mm_s: f64, right_mm_s: f64 },
    /// Open-loop duty −1..=1 per wheel (Drive PWM).
    Duty { left: f64, right: f64 },
}

impl DriveTarget {
    /// Both wheels braked.
    pub const STOP: DriveTarget = DriveTarget::Speed {
        left_mm_s: 0.0,
        right_mm_s: 0.0,
    };

    fn wheel(self, side: usize) -> WheelCommand {
        let (speed, duty) = match self {
            DriveTarget::Speed {
                left_mm_s,
                right_mm_s,
            } => (Some([left_mm_s, right_mm_s][side & 1]), None),
            DriveTarget::Duty { left, right } => (None, Some([left, right][side & 1])),
        };
        match (speed, duty) {
            (Some(v), _) if v != 0.0 => WheelCommand::Speed(v),
            (_, Some(d)) if d != 0.0 => WheelCommand::Duty(d),
            _ => WheelCommand::Brake,
        }
    }
}

/// The simulated physical world.
#[derive(Debug, Clone)]
pub struct World {
    params: SimParams,
    constants: MotorConstants,
    enclosure: Enclosure,
    pose: Pose,
    wheels: [WheelMotor; 2],
    battery: Battery,
    pending: VecDeque<(u64, DriveTarget)>,
    latency_substeps: u64,
    substep_count: u64,
    steps: u64,
    lifted: bool,
    cliffs: [bool; 4],
    contacts: Vec<Contact>,
    /// The centre (its coordinates' bits) whose contacts within the contact tolerance `contacts` holds,
    /// if it holds such contacts: the same centre gives the same contacts, so they are reused.
    contacts_at: Option<(u64, u64)>,
    bumps: [bool; 2],
    blocked: bool,
    step_travel_mm: [f64; 2],
    total_travel_mm: [f64; 2],
    odometer_m: f64,
    rng: Rng,
    /// The last angle (its bits) given to [`World::direction`] and its unit vector.
    direction_memo: (u64, Vec2),
}

impl World {
    /// The robot at its start pose, at rest, batteries at their initial charge; `rng` drives the
    /// floor irregularities.
    pub fn new(params: SimParams, rng: Rng) -> Self {
        let constants = MotorConstants::new(&params);
        let dt = constants.dt_s();
        let sense_alpha = if params.current_sense_tau_s > 0.0 {
            1.0 - (-dt / params.current_sense_tau_s).exp()
        } else {
            1.0
        };
        let latency_substeps = (params.command_latency_s.max(0.0) / dt).round() as u64;
        World {
            enclosure: Enclosure::right_triangle(params.enclosure_leg_m),
            pose: Pose {
                x_m: params.start_x_m,
                y_m: params.start_y_m,
                heading_rad: params.start_heading_rad,
            },
            wheels: [WheelMotor::default(), WheelMotor::default()],
            battery: Battery::new(&params, sense_alpha),
            pending: VecDeque::new(),
            latency_substeps,
            substep_count: 0,
            steps: 0,
            lifted: false,
            cliffs: [false; 4],
            contacts: Vec::with_capacity(4),
            contacts_at: None,
            bumps: [false; 2],
            blocked: false,
            step_travel_mm: [0.0; 2],
            total_travel_mm: [0.0; 2],
            odometer_m: 0.0,
            rng,
            direction_memo: (0f64.to_bits(), Vec2::from_angle(0.0)),
            constants,
            params,
        }
    }

    /// Hands a drive command to the firmware; it reaches the wheels after the command latency.
    pub fn command(&mut self, target: DriveTarget) {
        if self.pending.len() >= MAX_PENDING {
            self.pending.pop_front();
        }
        let due = self.substep_count + self.latency_substeps;
        self.pending.push_back((due, target));
    }

    /// Stops both wheels at once, discarding queued commands (a safety trip inside the firmware).
    pub fn halt(&mut self) {
        self.pending.clear();
        for w in &mut self.wheels {
            w.command(WheelCommand::Brake);
        }
    }

    /// Advances the world by one 15 ms step.
    pub fn step(&mut self) {
        let dt = self.constants.dt_s();
        self.step_travel_mm = [0.0; 2];
        for w in &mut self.wheels {
            w.vary_floor(&self.constants, STEP_SECONDS, &mut self.rng);
        }
        for _ in 0..self.params.substeps.max(1) {
            self.substep_count += 1;
            while let Some(&(due, target)) = self.pending.front() {
                if due > self.substep_count {
                    break;
                }
                self.pending.pop_front();
                for (side, w) in self.wheels.iter_mut().enumerate() {
                    w.command(target.wheel(side));
                }
            }
            self.substep(dt);
        }
        self.steps += 1;
        self.update_contacts_and_bumps();
    }

    fn substep(&mut self, dt: f64) {
        let v_batt = self.battery.voltage_v();
        for w in &mut self.wheels {
            w.substep(&self.constants, v_batt);
        }
        let (vl, vr) = (
            self.wheels[LEFT].speed_m_s(),
            self.wheels[RIGHT].speed_m_s(),
        );
        let common = (vl + vr) / 2.0;
        self.blocked = false;
        if !self.lifted {
            self.find_contacts();
            if !self.contacts.is_empty() {
                let heading = self.direction(self.pose.heading_rad);
                self.blocked = self
                    .contacts
                    .iter()
                    .any(|c| common * heading.dot(c.normal) < 0.0);
            }
        }
        if self.blocked {
            if vl * vr > 0.0 {
                // Both wheels drive into the wall: the bumper's grip on the wall stops the robot
                // pivoting on the stronger wheel, so both stall.
                self.wheels[LEFT].constrain_speed(0.0);
                self.wheels[RIGHT].constrain_speed(0.0);
            } else {
                // Turning while touching: only the forward/backward part is stopped.
                self.wheels[LEFT].constrain_speed(vl - common);
                self.wheels[RIGHT].constrain_speed(vr - common);
            }
        }
        let (vl, vr) = (
            self.wheels[LEFT].speed_m_s(),
            self.wheels[RIGHT].speed_m_s(),
        );
        self.step_travel_mm[LEFT] += vl * dt * 1000.0;
        self.step_travel_mm[RIGHT] += vr * dt * 1000.0;
        self.total_travel_mm[LEFT] += vl * dt * 1000.0;
        self.total_travel_mm[RIGHT] += vr * dt * 1000.0;
        if !self.lifted {
            let common = (vl + vr) / 2.0;
            let turn = (vr - vl) / self.params.wheel_base_m * dt;
            let mid_angle = self.pose.heading_rad + turn / 2.0;
            let advance_m = common * dt;
            // A robot turning on the spot against a wall moves its centre by less than the
            // coordinates resolve: the sine and cosine of the mid-step heading would change nothing.
            if !moves_below_resolution(self.centre(), mid_angle, advance_m) {
                let mid = self.direction(mid_angle);
                let moved = self.centre() + mid * advance_m;
                self.pose.x_m = moved.x;
                self.pose.y_m = moved.y;
            }
            self.pose.heading_rad = wrap_angle(self.pose.heading_rad + turn);
            self.odometer_m += common.abs() * dt;
            self.push_out_of_walls_in_substep();
        }
        let motors: f64 = self.wheels.iter().map(WheelMotor::battery_current_a).sum();
        self.battery.update(dt, motors);
    }

    /// Makes `contacts` the contacts within the contact tolerance at the present centre: found anew
    /// unless they were found for this very centre (bit for bit; the walls, the radius and the tolerance
    /// never change), when finding them again would give the same list.
    fn find_contacts(&mut self) {
        let centre = self.centre();
        let at = (centre.x.to_bits(), centre.y.to_bits());
        if self.contacts_at != Some(at) {
            self.enclosure.contacts(
                centre,
                self.params.body_radius_m,
                self.params.contact_tolerance_m,
                &mut self.contacts,
            );
            self.contacts_at = Some(at);
        }
    }

    /// [`World::push_out_of_walls`] in a sub-step, with the contacts the next sub-step (or the step's
    /// end) will test found at the same time.
    ///
    /// Exact: with a tolerance `tol ≥ 0` the contacts within `radius + tol` include every contact
    /// within `radius` with the same normal and depth (both depend only on the centre and the wall),
    /// in the same wall order, and a contact is pushed out only when its depth `radius − dist` is
    /// positive, that is when `dist < radius`: exactly the tolerance-0 contacts that push. So the
    /// pushes are those of `push_out_of_walls`, and when they leave the centre's bits unchanged the
    /// contacts found here are the ones the next test needs.
    fn push_out_of_walls_in_substep(&mut self) {
        let tolerance = self.params.contact_tolerance_m;
        if tolerance.is_nan() || tolerance < 0.0 {
            self.push_out_of_walls();
            return;
        }
        self.find_contacts();
        for c in &self.contacts {
            if c.depth > 0.0 {
                self.pose.x_m += c.normal.x * c.depth;
                self.pose.y_m += c.normal.y * c.depth;
            }
        }
    }

    /// Moves the body out of any wall it overlaps (numerical drift while sliding into a corner).
    fn push_out_of_walls(&mut self) {
        self.contacts_at = None;
        self.enclosure.contacts(
            self.centre(),
            self.params.body_radius_m,
            0.0,
            &mut self.contacts,
        );
        for c in &self.contacts {
            if c.depth > 0.0 {
                self.pose.x_m += c.normal.x * c.depth;
                self.pose.y_m += c.normal.y * c.depth;
            }
        }
    }

    fn update_contacts_and_bumps(&mut self) {
        self.bumps = [false; 2];
        if self.lifted {
            return;
        }
        self.find_contacts();
        if self.contacts.is_empty() {
            return;
        }
        let heading = self.direction(self.pose.heading_rad);
        let p = &self.params;
        for c in &self.contacts {
            let toward = -c.normal;
            let bearing = heading.cross(toward).atan2(heading.dot(toward));
            if bearing.abs() > p.bumper_half_arc_rad {
                continue;
            }
            if bearing >= -p.bumper_overlap_rad {
                self.bumps[LEFT] = true;
            }
            if bearing <= p.bumper_overlap_rad {
                self.bumps[RIGHT] = true;
            }
        }
    }

    /// `Vec2::from_angle(angle)`, reusing the last result when `angle` is bit for bit the last one (a
    /// robot at rest or driving straight keeps its heading for many sub-steps).
    fn direction(&mut self, angle: f64) -> Vec2 {
        let bits = angle.to_bits();
        if bits != self.direction_memo.0 {
            self.direction_memo = (bits, Vec2::from_angle(angle));
        }
        self.direction_memo.1
    }

    fn centre(&self) -> Vec2 {
        Vec2::new(self.pose.x_m, self.pose.y_m)
    }

    /// Distance to the nearest wall seen by an infrared sensor on the rim at `mount_bearing` (rad from
    /// the heading, counter-clockwise) looking along `look_bearing`, m. `None` if lifted or no wall.
    pub fn ir_range_m(&self, mount_bearing: f64, look_bearing: f64) -> Option<f64> {
        if self.lifted {
            return None;
        }
        let h = self.pose.heading_rad;
        let (mount, look) = (h + mount_bearing, h + look_bearing);
        let mount_dir = Vec2::from_angle(mount);
        // A sensor looking out along its mount bearing (the light bumpers): one sine and cosine.
        let look_dir = if look.to_bits() == mount.to_bits() {
            mount_dir
        } else {
            Vec2::from_angle(look)
        };
        self.ir_range_along(mount_dir, look_dir)
    }

    /// [`World::ir_range_m`] given the unit vectors of the sensor's mount and look directions
    /// (`Vec2::from_angle` of the heading plus each bearing).
    pub fn ir_range_along(&self, mount_dir: Vec2, look_dir: Vec2) -> Option<f64> {
        if self.lifted {
            return None;
        }
        let origin = self.centre() + mount_dir * self.params.body_radius_m;
        self.enclosure.ray_distance(origin, look_dir)
    }

    /// Lifts the robot off the floor (both wheel drops set, wheels turn freely, no motion) or puts it
    /// back.
    pub fn set_lifted(&mut self, lifted: bool) {
        self.lifted = lifted;
    }

    /// Puts a drop-off under cliff sensor `index` (0 left, 1 front left, 2 front right, 3 right) or
    /// removes it. The enclosure itself has no cliffs; this is for tests and fault injection.
    pub fn set_cliff(&mut self, index: usize, cliff: bool) {
        if let Some(c) = self.cliffs.get_mut(index) {
            *c = cliff;
        }
    }

    /// Parameters the world runs with.
    pub fn params(&self) -> &SimParams {
        &self.params
    }

    /// The robot's pose.
    pub fn pose(&self) -> Pose {
        self.pose
    }

    /// Puts the robot at `pose` (for tests and experiment set-up; the body is pushed out of walls).
    pub fn set_pose(&mut self, pose: Pose) {
        self.pose = pose;
        self.push_out_of_walls();
        self.update_contacts_and_bumps();
    }

    /// The enclosure.
    pub fn enclosure(&self) -> &Enclosure {
        &self.enclosure
    }

    /// Wheel rim speed, mm/s (`LEFT` or `RIGHT`).
    pub fn wheel_speed_mm_s(&self, side: usize) -> f64 {
        self.wheel(side).speed_m_s() * 1000.0
    }

    /// Motor current, A, as the firmware measures it (low-passed), signed with the torque.
    pub fn wheel_current_a(&self, side: usize) -> f64 {
        self.wheel(side).sensed_current_a()
    }

    /// The motor current the duty asked for before the driver's limit, A, as the firmware measures it.
    pub fn wheel_current_demand_a(&self, side: usize) -> f64 {
        self.wheel(side).sensed_demand_a()
    }

    /// Motor duty −1..=1.
    pub fn wheel_duty(&self, side: usize) -> f64 {
        self.wheel(side).duty()
    }

    /// The command the wheel is executing now (after the latency).
    pub fn wheel_command(&self, side: usize) -> WheelCommand {
        self.wheel(side).current_command()
    }

    /// True when a wall stops the wheel while its motor pushes: a stall.
    pub fn stalled(&self, side: usize) -> bool {
        let w = self.wheel(side);
        self.blocked && w.pushing() && w.speed_m_s() == 0.0
    }

    fn wheel(&self, side: usize) -> &WheelMotor {
        &self.wheels[side & 1]
    }

    /// Bumper switches `[left, right]`.
    pub fn bumps(&self) -> [bool; 2] {
        self.bumps
    }

    /// True if any wall touches the body.
    pub fn touching_wall(&self) -> bool {
        !self.lifted && !self.contacts.is_empty()
    }

    /// True if during the last sub-step a wall stopped the robot's forward/backward motion.
    pub fn blocked(&self) -> bool {
        self.blocked
    }

    /// Wheel drops `[left, right]`: both set while lifted.
    pub fn wheel_drops(&self) -> [bool; 2] {
        [self.lifted; 2]
    }

    /// Cliff sensors `[left, front left, front right, right]`.
    pub fn cliffs(&self) -> [bool; 4] {
        self.cliffs
    }

    /// The battery.
    pub fn battery(&self) -> &Battery {
        &self.battery
    }

    /// Signed travel of each wheel during the last step, mm.
    pub fn step_travel_mm(&self) -> [f64; 2] {
        self.step_travel_mm
    }

    /// Signed travel of each wheel since the start, mm.
    pub fn total_travel_mm(&self) -> [f64; 2] {
        self.total_travel_mm
    }

    /// Distance the robot's centre has moved since the start (unsigned), m.
    pub fn odometer_m(&self) -> f64 {
        self.odometer_m
    }

    /// Steps taken.
    pub fn steps(&self) -> u64 {
        self.steps
    }

    /// Simulated time, s.
    pub fn time_s(&self) -> f64 {
        self.steps as f64 * STEP_SECONDS
    }
}

/// True when `centre + Vec2::from_angle(angle) * advance` is certainly `centre`, bit for bit, whatever the
/// sine and cosine: then they need not be computed.
///
/// Exact: for a finite `angle` both components of the direction are at most 1 in magnitude (2 is
/// allowed here, so nothing is assumed of libm's last bit), so each rounded product is at most
/// `2·|advance|`. A finite coordinate `c` with `|c| ≥ 1e-290` is a normal double whose neighbours lie at
/// least `|c|·2⁻⁵³` away (the gap just below a power of two is the narrowest), so adding anything smaller
/// than half of that, `|c|·2⁻⁵⁴` (computed exactly: a power-of-two scaling that stays normal), rounds
/// back to `c`. A NaN anywhere makes the test false.
fn moves_below_resolution(centre: Vec2, angle: f64, advance: f64) -> bool {
    const HALF_GAP: f64 = 1.0 / (1u64 << 54) as f64;
    const SMALLEST: f64 = 1e-290;
    let (x, y) = (centre.x.abs(), centre.y.abs());
    angle.is_finite()
        && x.is_finite()
        && y.is_finite()
        && x >= SMALLEST
        && y >= SMALLEST
        && 2.0 * advance.abs() < x.min(y) * HALF_GAP
}

/// `a` wrapped into (−π, π].
pub fn wrap_angle(a: f64) -> f64 {
    let tau = std::f64::consts::TAU;
    // `a.rem_euclid(tau)`, without its `fmod` when `|a| < τ`: `fmod` returns such an `a` unchanged.
    let r = if a.abs() < tau { a } else { a % tau };
    let w = if r < 0.0 { r + tau } else { r };
    if w > std::f64::consts::PI { w - tau } else { w }
}

#[cfg(test)]
mod tests;

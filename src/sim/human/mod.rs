//! The simulated human operator of the command experiment ("Reducing Lag By Predicting the Next Command"): a
//! person standing ~2.5 m in front of a depth sensor who now and then bends the left elbow past 90° to command
//! a left spin, sometimes starts a bend and stops short, and moves the right arm for unrelated reasons.
//!
//! Each [`SimHuman::step`] yields one 30 fps tracker frame of joint positions in the sensor's frame (mm,
//! OSCeleton raw mode), with jitter and with joints dropped in short bursts the way OSCeleton omits
//! low-confidence joints. The true trajectory is known, so [`SimHuman::commands`] gives the exact ground truth
//! of every command: when the true left elbow angle went below 90° and when it came back.
//!
//! The bend is a minimum-jerk movement from the resting angle (~160°) to 50–70° over 0.6–1.2 s, so the arm has
//! been bending visibly for a few hundred ms before it crosses 90°: the regularity a Pavlovian control can learn
//! to anticipate. Parts: `params` (every parameter, with reasoning), `gesture` (elbow-angle
//! trajectories), `body` (kinematics and sway), `sensor` (jitter and dropouts). Same seed, same
//! frames; each part draws from its own forked random stream.

mod body;
mod gesture;
mod params;
mod sensor;
#[cfg(test)]
mod tests;

pub use params::{HumanParams, HumanParamsError};

use crate::rng::Rng;
use crate::skeleton::{Joint, Side};

use body::{ArmPose, Sway, joint_positions};
use gesture::{ArmMotion, ArmRole, Gesture, draw};
use sensor::SensorModel;

/// One tracker frame.
#[derive(Debug, Clone, PartialEq)]
pub struct HumanFrame {
    /// Simulation time of the frame, ms (frame `k` is at `k · frame_period_ms`).
    pub t_ms: f64,
    /// Reported joints in mm (x to the sensor's right, y up, z away from the sensor); dropped joints are absent.
    pub joints: Vec<(Joint, [f64; 3])>,
    /// The tracker's user id.
    pub user_id: i32,
}

/// Ground truth of one command gesture.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct CommandEvent {
    /// When the true left elbow angle first went below 90°, ms (exact, between frames).
    pub onset_ms: f64,
    /// When it came back to 90°, ms (planned at the onset, so it can lie after the latest frame).
    pub end_ms: f64,
}

/// Ground truth of any arm movement, commands or not.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct GestureRecord {
    /// Which arm moved.
    pub side: Side,
    /// Whether this is a command (a left-arm bend past 90°).
    pub is_command: bool,
    /// When the elbow started to bend, ms.
    pub start_ms: f64,
    /// When the arm was back at rest, ms.
    pub end_ms: f64,
    /// Resting angle it started from, degrees.
    pub from_deg: f64,
    /// Smallest true angle reached, degrees.
    pub min_deg: f64,
}

impl GestureRecord {
    fn new(side: Side, g: &Gesture) -> Self {
        GestureRecord {
            side,
            is_command: side == Side::Left && g.crosses_threshold(),
            start_ms: g.start_ms,
            end_ms: g.end_ms(),
            from_deg: g.from_deg,
            min_deg: g.min_deg,
        }
    }
}

/// Random-stream labels, so each part of the simulation draws independently.
const STREAM_LEFT: u64 = 1;
const STREAM_RIGHT: u64 = 2;
const STREAM_SWAY: u64 = 3;
const STREAM_NOISE: u64 = 4;
const STREAM_DROPS: u64 = 5;
const STREAM_BODY: u64 = 6;

/// The simulated operator.
#[derive(Debug, Clone)]
pub struct SimHuman {
    params: HumanParams,
    frame: u64,
    left: ArmMotion,
    right: ArmMotion,
    abduction_deg: [f64; 2],
    sway: Sway,
    sensor: SensorModel,
    pending: Vec<CommandEvent>,
    commands: Vec<CommandEvent>,
    gestures: Vec<GestureRecord>,
    true_elbow_deg: [f64; 2],
}

impl SimHuman {
    /// An operator with these parameters; everything random is fixed by `seed`. Never panics; check the
    /// parameters with [`HumanParams::validate`] first if they come from outside.
    pub fn new(params: HumanParams, seed: u64) -> Self {
        let root = Rng::new(seed);
        let mut body = root.fork(STREAM_BODY);
        let abduction_deg = [
            draw(&mut body, params.upper_arm_abduction_deg),
            draw(&mut body, params.upper_arm_abduction_deg),
        ];
        SimHuman {
            left: ArmMotion::new(ArmRole::Commanding, root.fork(STREAM_LEFT), &params),
            right: ArmMotion::new(ArmRole::Other, root.fork(STREAM_RIGHT), &params),
            sway: Sway::new(root.fork(STREAM_SWAY)),
            sensor: SensorModel::new(root.fork(STREAM_NOISE), root.fork(STREAM_DROPS), &params),
            true_elbow_deg: [params.rest_elbow_deg; 2],
            abduction_deg,
            params,
            frame: 0,
            pending: Vec::new(),
            commands: Vec::new(),
            gestures: Vec::new(),
        }
    }

    /// Duration of one sensor frame, ms (33.3 at 30 fps).
    pub fn frame_period_ms(&self) -> f64 {
        self.params.frame_period_ms()
    }

    /// The parameters in use.
    pub fn params(&self) -> &HumanParams {
        &self.params
    }

    /// Ground truth so far: every command whose onset is at or before the latest frame, in order.
    pub fn commands(&self) -> &[CommandEvent] {
        &self.commands
    }

    /// Every arm movement started so far (commands, partial bends, right-arm movements), in start order per arm.
    pub fn gestures(&self) -> &[GestureRecord] {
        &self.gestures
    }

    /// The true (noise-free) interior elbow angle at the latest frame, degrees.
    pub fn true_elbow_deg(&self, side: Side) -> f64 {
        match side {
            Side::Left => self.true_elbow_deg[0],
            Side::Right => self.true_elbow_deg[1],
        }
    }

    /// Advance by one sensor frame and return it. The first call returns the frame at t = 0.
    pub fn step(&mut self) -> HumanFrame {
        let period = self.frame_period_ms();
        let t_ms = self.frame as f64 * period;
        let dt_ms = if self.frame == 0 { 0.0 } else { period };
        self.frame += 1;

        if let Some(g) = self.left.advance(t_ms, dt_ms, &self.params) {
            self.gestures.push(GestureRecord::new(Side::Left, &g));
            if let Some((onset_ms, end_ms)) = g.threshold_crossings() {
                self.pending.push(CommandEvent { onset_ms, end_ms });
            }
        }
        if let Some(g) = self.right.advance(t_ms, dt_ms, &self.params) {
            self.gestures.push(GestureRecord::new(Side::Right, &g));
        }
        let (due, later): (Vec<_>, Vec<_>) =
            self.pending.drain(..).partition(|c| c.onset_ms <= t_ms);
        self.commands.extend(due);
        self.pending = later;

        let sway = self.sway.step(dt_ms, &self.params);
        let left = self.arm_pose(Side::Left, t_ms);
        let right = self.arm_pose(Side::Right, t_ms);
        self.true_elbow_deg = [left.elbow_deg, right.elbow_deg];
        let truth = joint_positions(sway, left, right, &self.params);
        HumanFrame {
            t_ms,
            joints: self.sensor.observe(truth, &self.params),
            user_id: self.params.user_id,
        }
    }

    fn arm_pose(&self, side: Side, t_ms: f64) -> ArmPose {
        let (arm, abduction_deg) = match side {
            Side::Left => (&self.left, self.abduction_deg[0]),
            Side::Right => (&self.right, self.abduction_deg[1]),
        };
        let (flexion_deg, forearm_yaw_deg) = arm.pose_extras(t_ms);
        ArmPose {
            elbow_deg: arm.angle_deg(t_ms),
            abduction_deg,
            flexion_deg,
            forearm_yaw_deg,
        }
    }
}

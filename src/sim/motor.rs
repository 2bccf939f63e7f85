//! One drive wheel: the firmware's speed controller, a DC gear motor and the wheel's friction.
//!
//! The model, in wheel-rim units (m/s, N, A):
//! - **controller**: the set-point ramps toward the commanded speed at the acceleration limit; duty
//!   `u = feed-forward(set-point) + kp·e + ∫ki·e` with `e` the speed error, clamped to ±1. A zero
//!   speed command brakes (duty 0, controller reset). A command of the opposite direction restarts the
//!   ramp from the wheel's present speed with the integral cleared; re-sending the same command changes
//!   nothing (hosts re-send every tick).
//! - **motor**: armature current `i = (u·V_batt − k·v) / R` (the electrical time constant, ~1 ms, is
//!   below the 1 ms sub-step and is neglected); force `k·i`.
//! - **current limit**: the driver limits the armature current to the wheel's over-current limit (1.0 A on
//!   the Create 1 [C1 p17]) by lowering the duty, as the spec says of its current limits ("If too much
//!   current is requested, the current is limited and the overcurrent flag is set" [C1 p10]). The current
//!   the duty would have driven, the *demand*, is what the over-current flag compares with the limit
//!   (`sim::readings`); the battery supplies only the limited current. With `limit_wheel_current` off
//!   (the other reading of the spec, for robustness studies) the current follows the demand.
//! - **wheel**: mass `m`; kinetic friction, viscous friction and a breakaway (static) friction that
//!   holds a wheel at rest until the motor force exceeds it. Friction is scaled by a slowly varying
//!   floor-irregularity factor.
//! - **sensing**: the firmware's current measurement is a first-order low-pass of the armature current.
//!
//! A wheel whose robot is pushed against a wall is held at zero speed by the world (the weighted robot
//! does not slip); the integral then winds up to full duty and the demand rises toward `V_batt / R`, the
//! stall current, while the current itself stays at the limit.

use super::params::SimParams;
use crate::rng::Rng;

/// What the firmware is asked to do with one wheel.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum WheelCommand {
    /// Motor braked (duty 0): a stop command, or no command yet.
    Brake,
    /// Closed-loop speed, mm/s (already limited and quantised).
    Speed(f64),
    /// Open-loop duty −1..=1 (Drive PWM, Create 2).
    Duty(f64),
}

/// Motor and controller constants derived once from [`SimParams`].
#[derive(Debug, Clone, PartialEq)]
pub struct MotorConstants {
    resistance_ohm: f64,
    back_emf: f64,
    mass_kg: f64,
    kinetic_n: f64,
    breakaway_n: f64,
    viscous_n_per_m_s: f64,
    accel_m_s2: f64,
    /// `accel_m_s2 · dt_s`: the most the set-point moves in one sub-step, m/s.
    accel_step_m_s: f64,
    /// `resistance · kinetic / back-EMF`: the voltage that overcomes kinetic friction, V.
    friction_v: f64,
    kp: f64,
    ki: f64,
    integral_limit: f64,
    nominal_v: f64,
    floor_sd: f64,
    floor_tau_s: f64,
    driver_efficiency: f64,
    current_limit_a: f64,
    limit_current: bool,
    /// Sub-step length, s.
    dt_s: f64,
    /// Low-pass factor of the current measurement per sub-step.
    sense_alpha: f64,
    /// [`floor_factors`] of a 15 ms step (the `dt` the world varies the floor by), computed once.
    step_floor_factors: (f64, f64),
}

/// The floor irregularity's decay over `dt` and the spread of its innovation: `(a, sd)` of
/// `floor ← a·floor + N(0, sd)`.
fn floor_factors(floor_sd: f64, floor_tau_s: f64, dt: f64) -> (f64, f64) {
    let a = (-dt / floor_tau_s).exp();
    let sd = floor_sd * (1.0 - a * a).sqrt();
    (a, sd)
}

impl MotorConstants {
    pub fn new(p: &SimParams) -> Self {
        let back_emf = p.motor_back_emf_v_per_m_s();
        let dt_s = super::STEP_SECONDS / f64::from(p.substeps.max(1));
        let sense_alpha = if p.current_sense_tau_s > 0.0 {
            1.0 - (-dt_s / p.current_sense_tau_s).exp()
        } else {
            1.0
        };
        let resistance_ohm = p.motor_resistance_ohm();
        let kinetic_n = back_emf * p.friction_current_a;
        let accel_m_s2 = p.accel_limit_mm_s2 / 1000.0;
        MotorConstants {
            resistance_ohm,
            back_emf,
            mass_kg: p.wheel_effective_mass_kg(),
            kinetic_n,
            breakaway_n: back_emf * p.breakaway_current_a,
            viscous_n_per_m_s: back_emf * p.viscous_current_a_per_m_s,
            accel_m_s2,
            accel_step_m_s: accel_m_s2 * dt_s,
            friction_v: resistance_ohm * kinetic_n / back_emf,
            kp: p.speed_kp,
            ki: p.speed_ki,
            integral_limit: p.integral_limit,
            nominal_v: p.motor_nominal_voltage_v,
            floor_sd: p.floor_friction_sd,
            floor_tau_s: p.floor_friction_tau_s,
            driver_efficiency: p.driver_efficiency,
            current_limit_a: p.overcurrent_limit_a,
            limit_current: p.limit_wheel_current,
            dt_s,
            sense_alpha,
            step_floor_factors: floor_factors(
                p.floor_friction_sd,
                p.floor_friction_tau_s,
                super::STEP_SECONDS,
            ),
        }
    }

    /// Sub-step length, s.
    pub fn dt_s(&self) -> f64 {
        self.dt_s
    }

    /// The duty that holds speed `v` m/s against kinetic friction at nominal voltage.
    fn feed_forward(&self, v: f64) -> f64 {
        if v == 0.0 {
            return 0.0;
        }
        (self.back_emf * v + self.friction_v * v.signum()) / self.nominal_v
    }
}

/// The state of one wheel and its motor.
#[derive(Debug, Clone, PartialEq)]
pub struct WheelMotor {
    command: WheelCommand,
    /// The speed command in m/s (`mm/s / 1000`; 0 unless the command is a speed).
    target_m_s: f64,
    setpoint_m_s: f64,
    integral: f64,
    speed_m_s: f64,
    duty: f64,
    current_a: f64,
    sensed_current_a: f64,
    sensed_demand_a: f64,
    battery_current_a: f64,
    floor: f64,
    pushing: bool,
}

impl Default for WheelMotor {
    fn default() -> Self {
        WheelMotor {
            command: WheelCommand::Brake,
            target_m_s: 0.0,
            setpoint_m_s: 0.0,
            integral: 0.0,
            speed_m_s: 0.0,
            duty: 0.0,
            current_a: 0.0,
            sensed_current_a: 0.0,
            sensed_demand_a: 0.0,
            battery_current_a: 0.0,
            floor: 0.0,
            pushing: false,
        }
    }
}

impl WheelMotor {
    /// Takes a new command from the firmware.
    pub fn command(&mut self, cmd: WheelCommand) {
        if cmd == self.command {
            return;
        }
        match cmd {
            WheelCommand::Brake | WheelCommand::Duty(_) => {
                self.integral = 0.0;
                self.setpoint_m_s = 0.0;
            }
            WheelCommand::Speed(mm_s) => {
                let target = mm_s / 1000.0;
                let same_way = matches!(self.command, WheelCommand::Speed(_))
                    && target * self.setpoint_m_s > 0.0;
                if !same_way {
                    self.setpoint_m_s = self.speed_m_s;
                    self.integral = 0.0;
                }
            }
        }
        self.command = cmd;
        self.target_m_s = match cmd {
            WheelCommand::Speed(mm_s) => mm_s / 1000.0,
            WheelCommand::Brake | WheelCommand::Duty(_) => 0.0,
        };
    }

    /// Advances the floor-irregularity factor by `dt` (once per 15 ms step; it varies slowly).
    pub fn vary_floor(&mut self, c: &MotorConstants, dt: f64, rng: &mut Rng) {
        if c.floor_tau_s <= 0.0 || c.floor_sd <= 0.0 {
            self.floor = 0.0;
            return;
        }
        // The same function of the same values as computing them here: the same bits.
        let (a, sd) = if dt.to_bits() == super::STEP_SECONDS.to_bits() {
            c.step_floor_factors
        } else {
            floor_factors(c.floor_sd, c.floor_tau_s, dt)
        };
        self.floor = (a * self.floor + rng.normal(0.0, sd)).clamp(-0.9, 3.0);
    }

    /// One sub-step at battery voltage `v_batt`: controller, current, friction, speed. The caller may
    /// then constrain the speed with [`WheelMotor::constrain_speed`].
    pub fn substep(&mut self, c: &MotorConstants, v_batt: f64) {
        let dt = c.dt_s;
        let v = self.speed_m_s;
        self.duty = match self.command {
            WheelCommand::Brake => 0.0,
            WheelCommand::Duty(d) => d.clamp(-1.0, 1.0),
            WheelCommand::Speed(_) => {
                let target = self.target_m_s;
                let step = c.accel_step_m_s;
                self.setpoint_m_s += (target - self.setpoint_m_s).clamp(-step, step);
                let e = self.setpoint_m_s - v;
                self.integral =
                    (self.integral + c.ki * e * dt).clamp(-c.integral_limit, c.integral_limit);
                (c.feed_forward(self.setpoint_m_s) + c.kp * e + self.integral).clamp(-1.0, 1.0)
            }
        };
        let demand = (self.duty * v_batt - c.back_emf * v) / c.resistance_ohm;
        self.current_a = demand;
        if c.limit_current && demand.abs() > c.current_limit_a && v_batt > 0.0 {
            // The driver lowers the duty until the current is at the limit.
            self.current_a = c.current_limit_a * demand.signum();
            self.duty = (self.current_a * c.resistance_ohm + c.back_emf * v) / v_batt;
        }
        self.battery_current_a = (self.duty * self.current_a).max(0.0) / c.driver_efficiency;

        let force = c.back_emf * self.current_a;
        let scale = 1.0 + self.floor;
        let kinetic = c.kinetic_n * scale;
        let breakaway = c.breakaway_n * scale;
        self.pushing = false;
        if v == 0.0 {
            if force.abs() > breakaway {
                self.speed_m_s = (force - kinetic * force.signum()) / c.mass_kg * dt;
            } else {
                self.pushing = force.abs() > kinetic;
            }
        } else {
            let net = force - kinetic * v.signum() - c.viscous_n_per_m_s * scale * v;
            let next = v + net / c.mass_kg * dt;
            // Friction stops a wheel; it does not reverse it.
            self.speed_m_s = if next * v < 0.0 && force.abs() <= breakaway {
                0.0
            } else {
                next
            };
        }

        self.sensed_current_a += (self.current_a - self.sensed_current_a) * c.sense_alpha;
        self.sensed_demand_a += (demand - self.sensed_demand_a) * c.sense_alpha;
    }

    /// Sets the wheel's speed from outside (a wall holding the robot). A wheel brought to rest while
    /// its motor pushes counts as pushing.
    pub fn constrain_speed(&mut self, speed_m_s: f64) {
        if speed_m_s == 0.0 && self.speed_m_s != 0.0 {
            self.pushing = true;
        }
        self.speed_m_s = speed_m_s;
    }

    /// The command the wheel is executing.
    pub fn current_command(&self) -> WheelCommand {
        self.command
    }

    /// Wheel rim speed, m/s.
    pub fn speed_m_s(&self) -> f64 {
        self.speed_m_s
    }

    /// The controller's present set-point, m/s.
    pub fn setpoint_m_s(&self) -> f64 {
        self.setpoint_m_s
    }

    /// Motor duty −1..=1.
    pub fn duty(&self) -> f64 {
        self.duty
    }

    /// Armature current, A (signed with the motor torque).
    pub fn current_a(&self) -> f64 {
        self.current_a
    }

    /// Armature current as the firmware measures it (low-passed), A.
    pub fn sensed_current_a(&self) -> f64 {
        self.sensed_current_a
    }

    /// The current the duty asked for before the driver's limit, as the firmware measures it (low-passed), A:
    /// what the over-current flag compares with the limit.
    pub fn sensed_demand_a(&self) -> f64 {
        self.sensed_demand_a
    }

    /// Current this wheel's driver draws from the battery, A (≥ 0).
    pub fn battery_current_a(&self) -> f64 {
        self.battery_current_a
    }

    /// True when the motor pushes but the wheel stands still (held by a wall or by static friction
    /// beyond the kinetic level): a stall in the making.
    pub fn pushing(&self) -> bool {
        self.pushing
    }

    /// The floor-irregularity friction factor minus one.
    pub fn floor_variation(&self) -> f64 {
        self.floor
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn run(m: &mut WheelMotor, c: &MotorConstants, seconds: f64, v_batt: f64) {
        let n = (seconds / c.dt_s()).round() as usize;
        for _ in 0..n {
            m.substep(c, v_batt);
        }
    }

    #[test]
    fn speed_follows_the_command_with_a_lag() {
        let p = SimParams::default();
        let c = MotorConstants::new(&p);
        let mut m = WheelMotor::default();
        m.command(WheelCommand::Speed(300.0));
        run(&mut m, &c, 0.1, 16.0);
        assert!(m.speed_m_s() < 0.1, "too fast: {}", m.speed_m_s());
        // The set-point ramp takes 1.2 s to reach 0.3 m/s at 250 mm/s².
        run(&mut m, &c, 1.5, 16.0);
        assert!(
            (m.speed_m_s() - 0.3).abs() < 0.01,
            "speed {}",
            m.speed_m_s()
        );
        // Cruising current is a fraction of an ampere.
        assert!(
            m.current_a() > 0.1 && m.current_a() < 0.5,
            "i {}",
            m.current_a()
        );
        m.command(WheelCommand::Brake);
        run(&mut m, &c, 0.5, 16.0);
        assert_eq!(m.speed_m_s(), 0.0);
    }

    #[test]
    fn a_held_wheel_demands_the_stall_current_and_draws_the_limit() {
        let p = SimParams::default();
        let c = MotorConstants::new(&p);
        let mut m = WheelMotor::default();
        m.command(WheelCommand::Speed(300.0));
        for _ in 0..2000 {
            m.substep(&c, 16.0);
            m.constrain_speed(0.0);
        }
        let stall = 16.0 / p.motor_resistance_ohm();
        assert!(stall > 1.5, "{stall}");
        assert!(
            (m.sensed_demand_a() - stall).abs() < 0.02,
            "demand {}",
            m.sensed_demand_a()
        );
        // The current is limited at 1.0 A [C1 p17]; the battery supplies the limited current only.
        assert!(
            (m.sensed_current_a() - p.overcurrent_limit_a).abs() < 1e-6,
            "i {}",
            m.sensed_current_a()
        );
        let duty = p.overcurrent_limit_a * p.motor_resistance_ohm() / 16.0;
        assert!((m.duty() - duty).abs() < 1e-9, "duty {}", m.duty());
        assert!(
            (m.battery_current_a() - duty * p.overcurrent_limit_a / p.driver_efficiency).abs()
                < 1e-9
        );
        assert!(m.pushing());
        // Reversing clears the wind-up at once.
        m.command(WheelCommand::Speed(-200.0));
        run(&mut m, &c, 0.1, 16.0);
        assert!(m.sensed_current_a() < 0.5, "i {}", m.sensed_current_a());
    }

    #[test]
    fn static_friction_holds_a_gently_pushed_wheel() {
        let p = SimParams::default();
        let c = MotorConstants::new(&p);
        let mut m = WheelMotor::default();
        // A duty just under breakaway: current flows, the wheel does not turn.
        let duty = 0.9 * p.breakaway_current_a * p.motor_resistance_ohm() / 16.0;
        m.command(WheelCommand::Duty(duty));
        run(&mut m, &c, 0.2, 16.0);
        assert_eq!(m.speed_m_s(), 0.0);
        assert!(m.current_a() > 0.0);
        m.command(WheelCommand::Duty(1.5 * duty));
        run(&mut m, &c, 0.2, 16.0);
        assert!(m.speed_m_s() > 0.0);
    }

    #[test]
    fn same_command_twice_changes_nothing() {
        let p = SimParams::default();
        let c = MotorConstants::new(&p);
        let mut a = WheelMotor::default();
        let mut b = WheelMotor::default();
        a.command(WheelCommand::Speed(200.0));
        b.command(WheelCommand::Speed(200.0));
        for _ in 0..300 {
            a.substep(&c, 16.0);
            b.command(WheelCommand::Speed(200.0));
            b.substep(&c, 16.0);
        }
        assert_eq!(a, b);
    }
}

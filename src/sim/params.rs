//! [`SimParams`]: every physical parameter of the simulated Create in one documented place.
//!
//! Each field says where its value comes from. Source tags (`docs/SOURCES.md`): [C1 pN] Create 1 OI spec,
//! [C2 pN] Create 2 OI spec, \[HR\] *Hacking Roomba*, \[BATT\] iRobot's Create 2 battery note; "paper" is
//! Modayil & Sutton, *Prediction Driven Behavior*. Values marked *estimate* have no primary source; the comment gives the reasoning.
//!
//! ## How the parameters produce the paper's latencies
//!
//! The paper measured, on the real robot, about **0.1 s** from a spin command to a change in battery
//! current and about **0.3 s** to the first odometry report of motion. The simulator reproduces both
//! mechanistically, measured from the moment the command bytes reach the robot:
//!
//! 1. `command_latency_s` (60 ms): the firmware picks the command up on its 15 ms control cycle and
//!    hands it to the wheel speed controller; nothing changes before that.
//! 2. The controller ramps its set-point at `accel_limit_mm_s2`, so the motor duty, and with it the
//!    battery current, grows gradually; the firmware's current measurement is a low-pass filter
//!    (`current_sense_tau_s`). Together with (1) this puts the first change of more than 30 mA in the
//!    reported battery current at 0.09–0.12 s (mean 0.10 s over seeds).
//! 3. The gearbox holds the wheel until the motor force exceeds the breakaway (static) friction
//!    (`breakaway_current_a`); while the wheel is held the speed controller's integrator winds up, so
//!    current is drawn well before the wheel turns (exactly the paper's "current first, motion later").
//! 4. Angle and distance are integer degrees and millimetres: a spin must turn a whole degree (≈2 mm of
//!    wheel travel) before odometry reports anything. (2)–(4) put the first non-zero angle at
//!    0.225–0.315 s (mean 0.27 s), independent of the spin speed (the ramp dominates).
//!
//! These are robot-side figures, from the command bytes arriving to the frame reporting the change; the
//! paper's also contain its Bluetooth link and 20 ms host tick, which a runtime adds on top.
//!
//! `robot::tests::spin_command_latencies_match_the_paper` checks both over several seeds and both models.

use crate::oi::Model;
use crate::oi::spec::PacketFacts;

/// The wheel over-current limit used for a model whose document gives none, A: the Create 1's 1.0 A
/// [C1 p10, p17].
const UNPUBLISHED_OVERCURRENT_LIMIT_A: f64 = 1.0;

/// Open-circuit voltage of the pack as `(state of charge 0..=1, volts)` points, increasing in charge.
pub type OcvCurve = [(f64, f64); 7];

/// All physical parameters of one simulated robot and its world.
#[derive(Debug, Clone, PartialEq)]
pub struct SimParams {
    // ----- world -----
    /// Length of the two short walls of the right-triangle enclosure, m. Paper: "an enclosure in the
    /// shape of right angle triangle, where the short walls were one meter in length". The right angle
    /// is at the origin, the legs run along +x and +y, the hypotenuse joins (L, 0) and (0, L).
    pub enclosure_leg_m: f64,
    /// Start position, m: the triangle's centroid (L/3, L/3), the point farthest from being cornered
    /// that is still central; 0.236 m from the hypotenuse and 0.333 m from each leg, so a robot of
    /// radius 0.165 m starts clear of every wall.
    pub start_x_m: f64,
    /// See `start_x_m`.
    pub start_y_m: f64,
    /// Start heading, rad (0 = +x, counter-clockwise positive): π/4, facing the hypotenuse head-on,
    /// so "drive forward" from the start reaches a wall after ≈7 cm.
    pub start_heading_rad: f64,

    // ----- body and kinematics -----
    /// Body radius, m: Ø 329.9 mm [C2 p5]; the Create 1 is ~330 mm too [C1 p3].
    pub body_radius_m: f64,
    /// Distance between the wheels, m: 258 mm (Create 1), 235 mm (Create 2) [LC types.cpp; C2 p5].
    /// Also the base the firmware uses to turn wheel travel into the angle packet [C2 p27].
    pub wheel_base_m: f64,
    /// Wheel diameter, m: 72 mm (Create 2) [C2 p5, p31]; 78 mm on the Create 1 is libcreate's unused
    /// default (*estimate*; only the Create 2 encoders use it).
    pub wheel_diameter_m: f64,
    /// Encoder counts per wheel revolution: 508.8 [C2 p31].
    pub encoder_counts_per_rev: f64,
    /// Fastest commandable wheel speed, mm/s: ±500 [C1 p9; C2 p13] (the model's
    /// [`crate::oi::ModelSpec::max_wheel_speed_mm_s`]).
    pub max_wheel_speed_mm_s: f64,
    /// Commanded wheel speeds at or below this magnitude do not move the wheel, mm/s: 10 on the
    /// Create 2 (measured \[KT\]); 0 on the Create 1 (no data).
    pub speed_dead_band_mm_s: f64,
    /// The Create 2 speed controller runs at discrete speeds ≈28.5 mm/s apart [C2 p13–14; KT]:
    /// anything in `[11 + 28.5k, 11 + 28.5(k+1))` mm/s drives at `11 + 28.5(k+1)`. `None` on the
    /// Create 1 (no data: continuous). The model's [`crate::oi::ModelSpec::speed_step_mm_s`].
    pub speed_quantum_mm_s: Option<f64>,

    // ----- bumper -----
    /// The bumper covers the front half of the body: contacts with a bearing (relative to the
    /// heading) within ±90° press it; contacts further back press nothing (the Create has no rear
    /// bumper).
    pub bumper_half_arc_rad: f64,
    /// Contacts within this bearing of straight ahead press both bumper switches (a head-on push
    /// closes both halves), rad: 10°, *estimate*.
    pub bumper_overlap_rad: f64,
    /// Gap below which the body counts as touching a wall, m: 1 mm (numerical slack).
    pub contact_tolerance_m: f64,

    // ----- mass and friction -----
    /// Robot mass, kg: ~3.5 kg [C2 p5]; the Create 1 is taken to be similar (*estimate*).
    pub robot_mass_kg: f64,
    /// Extra mass on the robot, kg: "a small weight (approximately two kilograms) was placed on the back
    /// of the robot so that the wheels would not spin" (paper). With it the wheels never slip: a wheel
    /// whose robot is pushed against a wall cannot turn.
    pub payload_kg: f64,
    /// Motor rotor inertia reflected through the gearbox to the wheel rim, as a mass per wheel, kg
    /// (*estimate*: a small rotor behind a high-ratio gearbox weighs about as much as a fifth of the
    /// robot's share). Each wheel carries half the robot plus this.
    pub rotor_reflected_mass_kg: f64,
    /// Kinetic friction of one wheel's gearbox and tyre, expressed as the motor current that balances
    /// it, A (*estimate*: with the viscous term gives ≈0.2–0.25 A per wheel when cruising, i.e.
    /// ≈0.5–0.6 A for the whole robot with the idle draw [HR p378: "≈500 mA driving"]).
    pub friction_current_a: f64,
    /// Static (breakaway) friction of a wheel at rest, as a motor current, A (*estimate*, tuned with
    /// `accel_limit_mm_s2` so the first odometry report comes ≈0.3 s after a command, as in the paper).
    pub breakaway_current_a: f64,
    /// Viscous friction, as motor current per m/s of wheel speed, A·s/m (*estimate*).
    pub viscous_current_a_per_m_s: f64,
    /// Floor irregularity: the friction of each wheel is multiplied by `1 + f` where `f` is an
    /// Ornstein–Uhlenbeck process with this standard deviation (*estimate*; the paper: isolated
    /// over-currents "when the robot overcame friction or small irregularities on the floor").
    pub floor_friction_sd: f64,
    /// Correlation time of the floor irregularity, s (*estimate*: a few centimetres of floor at the
    /// usual speeds).
    pub floor_friction_tau_s: f64,

    // ----- drive motors and their speed controller -----
    /// Battery voltage at which the motor constants below hold, V: 14.4 V nominal pack [HR p33].
    pub motor_nominal_voltage_v: f64,
    /// Current of a blocked motor at full duty and nominal voltage, A (*estimate*: comfortably above
    /// the 1.0 A over-current limit [C1 p17], as a stalled Create's persistent over-current flags need).
    /// Sets the armature resistance `R = V_nominal / I_stall`. It is the *demand* of a stalled wheel: the
    /// driver limits the current itself to `overcurrent_limit_a` (`sim::motor`).
    pub stall_current_a: f64,
    /// Unloaded wheel speed at full duty and nominal voltage, mm/s (*estimate*: some headroom above the
    /// 500 mm/s the firmware allows). Sets the back-EMF constant.
    pub no_load_speed_mm_s: f64,
    /// Dead time from a complete command arriving to the speed controller acting on it, s (*estimate*,
    /// see the module doc: the firmware's 15 ms cycle plus hand-over; calibrated to the paper's 0.1 s).
    pub command_latency_s: f64,
    /// Acceleration limit of the controller's speed set-point, mm/s² (*estimate*, see the module doc).
    /// On a new command the ramp restarts from the wheel's present speed.
    pub accel_limit_mm_s2: f64,
    /// Proportional gain of the wheel speed controller, duty per m/s of speed error (*estimate*: a
    /// gentle loop; the feed-forward — back-EMF plus kinetic friction at nominal voltage — does most of
    /// the work on the ≈80 ms mechanical time constant, the integral removes what it misses).
    pub speed_kp: f64,
    /// Integral gain of the wheel speed controller, duty per m of accumulated speed error (*estimate*).
    pub speed_ki: f64,
    /// Limit of the integral term, duty: large enough to wind a blocked wheel up to full duty, which is
    /// what drives the current of a stalled wheel toward the stall current.
    pub integral_limit: f64,
    /// Physics sub-steps per 15 ms step (1 ms each): the controller and the wheel dynamics are stiff
    /// enough that 15 ms explicit steps would ring.
    pub substeps: u32,

    // ----- currents and over-current sensing -----
    /// Time constant of the firmware's current measurement (battery and wheel currents), s (*estimate*:
    /// a sense resistor and RC filter averaged over a control cycle or two).
    pub current_sense_tau_s: f64,
    /// Wheel over-current limit, A: 1.0 A [C1 p17] (the model's
    /// [`crate::oi::ModelSpec::wheel_overcurrent_limit_a`]). The Create 2 limit is unpublished; the
    /// same value is used. The driver limits the wheel's current to it and sets the flag: packet 14 lists
    /// the wheels' 1.0 A with the low side drivers' limits as "the current limits" [C1 p17], and of those
    /// limits the spec says "If too much current is requested, the current is limited and the overcurrent
    /// flag is set" [C1 p10] (written on the low side drivers' page; applying it to the wheels is our
    /// reading of one table of limits).
    pub overcurrent_limit_a: f64,
    /// Whether the driver limits a wheel's current to `overcurrent_limit_a` (true: the reading of [C1 p10,
    /// p17] above) or only flags it, the current following the duty's demand (false: the other reading;
    /// `[sim.params] limit_wheel_current`).
    pub limit_wheel_current: bool,
    /// Each 15 ms the over-current bit of a wheel is set with probability
    /// `1 / (1 + exp(-(|I| - limit) / scale))`, `I` the sensed current the duty demands before the limit:
    /// rare when cruising (≈0.2 A), occasional on a hard start or a rough patch, almost always when
    /// stalled (a demand of ≈1.6 A, the current itself held at the limit).
    /// Scale in A (*estimate*, tuned so isolated flags occur several times a minute in normal driving,
    /// as the paper reports, while a stalled wheel is flagged in ≈98 % of frames).
    pub overcurrent_scale_a: f64,
    /// Fraction of a motor's electrical power that the H-bridge draws from the battery beyond the motor
    /// itself: battery current of a wheel = `|duty · I_motor| / driver_efficiency` (*estimate*).
    pub driver_efficiency: f64,

    // ----- battery -----
    /// Pack capacity, mAh: 2068 on the Create 2 (reset banner, pycreate2#12); ~3000 mAh NiMH on the
    /// Create 1 [HR p33] (pack *estimate*).
    pub capacity_mah: f64,
    /// State of charge at start, 0..=1: 0.913 = 1888/2068 mAh, the Create 2 idle sample
    /// (create_robot#64); the same fraction for the Create 1.
    pub initial_charge_fraction: f64,
    /// Open-circuit voltage against state of charge. Create 2: 4-cell Li-ion, 16.8 V full, ≈16.05 V at
    /// 91 % (matches the 16 028 mV idle sample, create_robot#64), cut-off near 13 V. Create 1: 12-cell
    /// NiMH, 14.4 V nominal [HR p33], 15–17 V charged, shut-off below ~13 V (ROS answers 27623).
    pub ocv_curve: OcvCurve,
    /// Internal resistance of the pack, Ω (*estimate*: chosen so that a 2–3 A stall load sags the pack
    /// by 0.5–1 V).
    pub internal_resistance_ohm: f64,
    /// Current drawn by the electronics with the motors off, A: 0.111 A on the Create 2
    /// (create_robot#64); 0.15 A for the Create 1 (*estimate*).
    pub idle_current_a: f64,
    /// Noise of the reported battery current, mA (standard deviation; *estimate*).
    pub current_noise_ma: f64,
    /// Noise of the reported wheel currents (packets 54, 55), mA (*estimate*).
    pub wheel_current_noise_ma: f64,
    /// Noise of the reported voltage, mV (*estimate*).
    pub voltage_noise_mv: f64,
    /// Ambient temperature, °C: 21 °C (create_robot#64 sample).
    pub ambient_temp_c: f64,
    /// Heat capacity of the pack, J/K (*estimate*: ~0.5 kg of cells).
    pub battery_heat_capacity_j_per_k: f64,
    /// Thermal conductance from pack to air, W/K (*estimate*).
    pub battery_thermal_conductance_w_per_k: f64,

    // ----- infrared sensors -----
    /// Mean cliff signal over the enclosure's wooden floor, 0–4095 [C1 p18; C2 p25] (*estimate* of the
    /// level: a bright floor reads high). Each of the four sensors gets its own offset (seeded).
    pub cliff_signal_mean: f64,
    /// Sensor-to-sensor spread of the cliff signal level (*estimate*).
    pub cliff_signal_spread: f64,
    /// Per-reading noise of the cliff signals (*estimate*).
    pub cliff_signal_noise: f64,
    /// Wall signal (packet 27) with a wall touching the sensor. The packet's range is 0–4095 on the
    /// Create 1 and 0–1023 on the Create 2 [C1 p19; C2 p29]; the level reached is an *estimate*.
    pub wall_signal_peak: f64,
    /// Distance over which the wall signal falls by e, m (*estimate*: the Create's side sensor sees a
    /// wall a few centimetres away).
    pub wall_signal_scale_m: f64,
    /// Signal above which the wall bit (packet 8) / light-bumper bits (packet 45) are set (*estimate*).
    pub wall_signal_threshold: f64,
    /// Noise of the wall and light-bump signals (*estimate*).
    pub wall_signal_noise: f64,
    /// The Create 1 wall sensor: `(mount, look)` bearings relative to the heading, rad. It sits on the
    /// right of the bumper and looks to the right (the Create's wall sensor is on its right side); the exact
    /// angles are an *estimate* (mounted at −60°, looking at −90°).
    pub wall_sensor_bearings_rad: (f64, f64),
    /// Bearings of the Create 2's six light-bump sensors (left, front left, centre left, centre right,
    /// front right, right), rad; each looks outward along its bearing (*estimate* of the Roomba 600
    /// layout across the bumper face; packets 46–51 [C2 p32]).
    pub light_bump_bearings_rad: [f64; 6],
    /// Highest light-bump signal, 0–4095 [C1 p18; C2 p25] (*estimate* of the level reached at a wall).
    pub light_bump_peak: f64,
    /// Distance over which a light-bump signal falls by e, m (*estimate*: they see walls ~10 cm away).
    pub light_bump_scale_m: f64,
    /// Light-bump signal above which its bit in packet 45 is set (*estimate*).
    pub light_bump_threshold: f64,

    // ----- odometry -----
    /// Keep the fraction of a millimetre / degree that a report leaves behind and add it to the next
    /// one (true), or drop it at every report (false). The firmware behaviour is unknown (the Create 1
    /// slow-turn reports reading 0, create_robot#28, hint at dropping); keeping it makes odometry
    /// sum to the true motion.
    pub keep_odometry_remainder: bool,

    // ----- serial output -----
    /// Bytes the robot's transmit buffer holds beyond what the line drains in one 15 ms slot
    /// (*estimate*). Stream requests larger than the slot fill it and then lose bytes, which is how the
    /// spec's "the data stream will eventually become corrupted" [C1 p14; C2 p22] shows up.
    pub tx_buffer_bytes: usize,
}

impl SimParams {
    /// The parameters of `model` in the paper's enclosure: the limits its spec documents, and the
    /// physical parameters filed under its [`crate::oi::ModelSpec::packet_facts`].
    pub fn for_model(model: Model) -> Self {
        let spec = model.spec();
        let common = SimParams {
            enclosure_leg_m: 1.0,
            start_x_m: 1.0 / 3.0,
            start_y_m: 1.0 / 3.0,
            start_heading_rad: std::f64::consts::FRAC_PI_4,
            body_radius_m: 0.165,
            wheel_base_m: 0.258,
            wheel_diameter_m: 0.078,
            encoder_counts_per_rev: 508.8,
            max_wheel_speed_mm_s: f64::from(spec.max_wheel_speed_mm_s),
            speed_dead_band_mm_s: 0.0,
            speed_quantum_mm_s: spec.speed_step_mm_s,
            bumper_half_arc_rad: std::f64::consts::FRAC_PI_2,
            bumper_overlap_rad: 10f64.to_radians(),
            contact_tolerance_m: 0.001,
            robot_mass_kg: 3.5,
            payload_kg: 2.0,
            rotor_reflected_mass_kg: 0.6,
            friction_current_a: 0.14,
            breakaway_current_a: 0.5,
            viscous_current_a_per_m_s: 0.2,
            floor_friction_sd: 0.15,
            floor_friction_tau_s: 0.3,
            motor_nominal_voltage_v: 14.4,
            stall_current_a: 1.5,
            no_load_speed_mm_s: 650.0,
            command_latency_s: 0.06,
            accel_limit_mm_s2: 250.0,
            speed_kp: 1.0,
            speed_ki: 30.0,
            integral_limit: 1.0,
            substeps: 15,
            current_sense_tau_s: 0.03,
            overcurrent_limit_a: spec
                .wheel_overcurrent_limit_a
                .unwrap_or(UNPUBLISHED_OVERCURRENT_LIMIT_A),
            limit_wheel_current: true,
            overcurrent_scale_a: 0.12,
            driver_efficiency: 0.9,
            capacity_mah: 3000.0,
            initial_charge_fraction: 0.913,
            ocv_curve: NIMH_12_CELL,
            internal_resistance_ohm: 0.35,
            idle_current_a: 0.15,
            current_noise_ma: 6.0,
            wheel_current_noise_ma: 5.0,
            voltage_noise_mv: 8.0,
            ambient_temp_c: 21.0,
            battery_heat_capacity_j_per_k: 400.0,
            battery_thermal_conductance_w_per_k: 0.5,
            cliff_signal_mean: 1200.0,
            cliff_signal_spread: 120.0,
            cliff_signal_noise: 4.0,
            wall_signal_peak: 3000.0,
            wall_signal_scale_m: 0.02,
            wall_signal_threshold: 200.0,
            wall_signal_noise: 2.0,
            wall_sensor_bearings_rad: ((-60f64).to_radians(), (-90f64).to_radians()),
            light_bump_bearings_rad: [65f64, 38.0, 12.0, -12.0, -38.0, -65.0].map(f64::to_radians),
            light_bump_peak: 3000.0,
            light_bump_scale_m: 0.03,
            light_bump_threshold: 100.0,
            keep_odometry_remainder: true,
            tx_buffer_bytes: 128,
        };
        match spec.packet_facts {
            PacketFacts::Create1 => common,
            PacketFacts::Create2 => SimParams {
                wheel_base_m: 0.235,
                wheel_diameter_m: 0.072,
                speed_dead_band_mm_s: 10.0,
                capacity_mah: 2068.0,
                ocv_curve: LI_ION_4_CELL,
                internal_resistance_ohm: 0.25,
                idle_current_a: 0.111,
                cliff_signal_mean: 2600.0,
                cliff_signal_spread: 200.0,
                wall_signal_peak: 1000.0,
                wall_signal_threshold: 80.0,
                ..common
            },
        }
    }

    /// Armature resistance of a drive motor, Ω.
    pub fn motor_resistance_ohm(&self) -> f64 {
        self.motor_nominal_voltage_v / self.stall_current_a
    }

    /// Back-EMF constant of a drive motor at the wheel rim, V per m/s (equal to its force constant in
    /// N per A for an ideal motor): the unloaded speed at nominal voltage, after the friction current,
    /// fixes it.
    pub fn motor_back_emf_v_per_m_s(&self) -> f64 {
        let friction_drop = self.motor_resistance_ohm() * self.friction_current_a;
        (self.motor_nominal_voltage_v - friction_drop) / (self.no_load_speed_mm_s / 1000.0)
    }

    /// Mass that one wheel accelerates, kg: half the loaded robot plus the reflected rotor.
    pub fn wheel_effective_mass_kg(&self) -> f64 {
        (self.robot_mass_kg + self.payload_kg) / 2.0 + self.rotor_reflected_mass_kg
    }

    /// Wheel travel per encoder count, mm: π·72/508.8 = 0.4446 mm on the Create 2 [C2 p31].
    pub fn mm_per_encoder_count(&self) -> f64 {
        std::f64::consts::PI * self.wheel_diameter_m * 1000.0 / self.encoder_counts_per_rev
    }
}

impl Default for SimParams {
    /// The Create 1, the robot of the paper.
    fn default() -> Self {
        SimParams::for_model(Model::Create1)
    }
}

/// 12-cell NiMH pack (Create 1 era): 14.4 V nominal [HR p33], ~16.8 V fresh off the charger, shut-off
/// near 13 V.
const NIMH_12_CELL: OcvCurve = [
    (0.0, 12.0),
    (0.05, 13.2),
    (0.2, 14.2),
    (0.5, 14.6),
    (0.8, 15.2),
    (0.9, 15.8),
    (1.0, 16.8),
];

/// 4-cell Li-ion pack (Create 2): 4.2 V/cell full, ≈4.01 V/cell at 91 % (16 028 mV idle sample,
/// create_robot#64), 3.0 V/cell empty.
const LI_ION_4_CELL: OcvCurve = [
    (0.0, 12.0),
    (0.05, 13.6),
    (0.2, 14.4),
    (0.5, 15.0),
    (0.8, 15.7),
    (0.9, 16.0),
    (1.0, 16.8),
];

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn models_differ_where_the_specs_differ() {
        let c1 = SimParams::for_model(Model::Create1);
        let c2 = SimParams::for_model(Model::Create2);
        assert_eq!(c1.wheel_base_m, 0.258);
        assert_eq!(c2.wheel_base_m, 0.235);
        assert_eq!(c2.speed_quantum_mm_s, Some(28.5));
        assert_eq!(c1.speed_quantum_mm_s, None);
        assert_eq!(SimParams::default(), c1);
    }

    #[test]
    fn derived_motor_constants_are_consistent() {
        let p = SimParams::default();
        let r = p.motor_resistance_ohm();
        let ke = p.motor_back_emf_v_per_m_s();
        // At nominal voltage and the no-load speed, the back-EMF plus the friction drop is the supply.
        let v = ke * p.no_load_speed_mm_s / 1000.0 + r * p.friction_current_a;
        assert!((v - p.motor_nominal_voltage_v).abs() < 1e-9);
        assert!(p.stall_current_a > p.overcurrent_limit_a);
        let c2 = SimParams::for_model(Model::Create2);
        assert!((c2.mm_per_encoder_count() - 0.44456).abs() < 1e-4);
    }

    #[test]
    fn start_pose_is_clear_of_every_wall() {
        for m in [Model::Create1, Model::Create2] {
            let p = SimParams::for_model(m);
            let r = p.body_radius_m;
            assert!(p.start_x_m > r && p.start_y_m > r);
            let to_hypotenuse = (p.enclosure_leg_m - p.start_x_m - p.start_y_m) / 2f64.sqrt();
            assert!(to_hypotenuse > r);
        }
    }

    #[test]
    fn ocv_curves_increase() {
        for m in [Model::Create1, Model::Create2] {
            let c = SimParams::for_model(m).ocv_curve;
            assert!(c.windows(2).all(|w| w[0].0 < w[1].0 && w[0].1 < w[1].1));
        }
    }
}

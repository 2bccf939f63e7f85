//! The firmware's sensing: once per 15 ms step it turns the physical truth of the [`World`] into
//! sensor readings, with measurement noise and the stochastic wheel over-current flags.
//!
//! Over-current: each step, the bit of a wheel is set with probability
//! `1 / (1 + exp(-(|I| − limit) / scale))` of its sensed current `I` — the chance that the current's
//! ripple and the floor's irregularities push the instantaneous value over the 1.0 A limit [C1 p10].
//! Cruising (≈0.2 A) this is about one frame in a thousand per wheel; overcoming static friction at
//! a start (≈0.5 A) about one in seventy; a stalled wheel (≈1.5 A) has it in 98 % of frames, so the
//! flags persist (paper: "isolated
//! observations of an over-current condition occurred regularly in normal operation", a stall makes
//! them persistent).

use super::geometry::Vec2;
use super::params::SimParams;
use super::world::{LEFT, RIGHT, World};
use crate::oi::ModelSpec;
use crate::oi::packets::bits;
use crate::rng::Rng;

/// Sensor readings of one step, in packet units.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Readings {
    /// Packet 7: bumps, wheel drops (and the Create 1 caster drop).
    pub bumps_drops: i32,
    /// Packet 8: wall seen.
    pub wall: bool,
    /// Packets 9–12: cliffs left, front left, front right, right.
    pub cliffs: [bool; 4],
    /// Packet 14: over-current bits (wheels: bit 4 left, bit 3 right).
    pub overcurrents: i32,
    /// Packet 22, mV.
    pub voltage_mv: i32,
    /// Packet 23, mA (negative: discharging).
    pub current_ma: i32,
    /// Packet 24, °C.
    pub temperature_c: i32,
    /// Packet 25, mAh.
    pub charge_mah: i32,
    /// Packet 26, mAh.
    pub capacity_mah: i32,
    /// Packet 27.
    pub wall_signal: i32,
    /// Packets 28–31.
    pub cliff_signals: [i32; 4],
    /// Packet 45 (Create 2; 0 on a model without light bumpers).
    pub light_bumper: i32,
    /// Packets 46–51 (Create 2; 0 on a model without light bumpers).
    pub light_bump_signals: [i32; 6],
    /// Packets 54, 55 (Create 2; 0 on a model without them): left and right wheel motor current, mA.
    pub wheel_current_ma: [i32; 2],
    /// Packet 58 (Create 2).
    pub stasis: i32,
}

/// Noise sources and per-sensor calibration of the firmware's sensing.
#[derive(Debug, Clone)]
pub struct Sensing {
    params: SimParams,
    caster_bit: bool,
    /// The light bumpers are read: the model reports them, or its packet 8 mirrors one.
    light_bumpers: bool,
    /// The model reports the wheel motor currents (packets 54, 55).
    motor_currents: bool,
    cliff_offsets: [f64; 4],
    noise: Rng,
    overcurrent: Rng,
    /// The wall sensor's, then each light bumper's.
    ir_memos: [IrMemo; 7],
}

impl Sensing {
    /// Sensing for a robot described by `params` of the model `spec` describes. Packet 7 has the caster
    /// drop bit when [`ModelSpec::has_caster_drop`] (bit 4, the Create 1). Readings of packets the model
    /// lacks (the light bumpers and motor currents of a Create 1) are not computed and stay 0 — nothing
    /// reports them — but their noise is still drawn, so every other reading is what computing them
    /// would have given.
    pub fn new(params: &SimParams, spec: &ModelSpec, rng: &Rng) -> Self {
        let mut calibration = rng.fork(1);
        let spread = params.cliff_signal_spread;
        let cliff_offsets = [(); 4].map(|_| calibration.normal(0.0, spread));
        let caster_bit = spec.has_caster_drop;
        Sensing {
            params: params.clone(),
            caster_bit,
            // Without the caster bit packet 8 mirrors the right light bumper (see `read`).
            light_bumpers: spec.has_light_bumpers || !caster_bit,
            motor_currents: spec.has_motor_currents,
            cliff_offsets,
            noise: rng.fork(2),
            overcurrent: rng.fork(3),
            ir_memos: [IrMemo::default(); 7],
        }
    }

    /// Reads every sensor once.
    pub fn read(&mut self, world: &World) -> Readings {
        let p = &self.params;
        let mut r = Readings::default();

        let [bump_l, bump_r] = world.bumps();
        let [drop_l, drop_r] = world.wheel_drops();
        r.bumps_drops = flag(bump_r, bits::BUMP_RIGHT)
            | flag(bump_l, bits::BUMP_LEFT)
            | flag(drop_r, bits::WHEEL_DROP_RIGHT)
            | flag(drop_l, bits::WHEEL_DROP_LEFT)
            | flag(self.caster_bit && drop_l && drop_r, bits::WHEEL_DROP_CASTER);

        for side in [LEFT, RIGHT] {
            // The flag says the driver is limiting: the demanded current against the limit.
            let amps = world.wheel_current_demand_a(side).abs();
            let z = (amps - p.overcurrent_limit_a) / p.overcurrent_scale_a.max(1e-9);
            let probability = 1.0 / (1.0 + (-z).exp());
            if self.overcurrent.chance(probability) {
                r.overcurrents |= if side == LEFT {
                    bits::OC_LEFT_WHEEL
                } else {
                    bits::OC_RIGHT_WHEEL
                };
            }
            if self.motor_currents {
                let ma = world.wheel_current_a(side) * 1000.0;
                r.wheel_current_ma[side] = round_in(
                    ma + self.noise.normal(0.0, p.wheel_current_noise_ma),
                    f64::from(i16::MIN),
                    f64::from(i16::MAX),
                );
            } else {
                self.noise.skip_normal();
            }
        }

        let b = world.battery();
        let ma = -b.sensed_current_a() * 1000.0 + self.noise.normal(0.0, p.current_noise_ma);
        r.current_ma = round_in(ma, f64::from(i16::MIN), f64::from(i16::MAX));
        let mv = b.voltage_v() * 1000.0 + self.noise.normal(0.0, p.voltage_noise_mv);
        r.voltage_mv = round_in(mv, 0.0, 65_535.0);
        r.temperature_c = round_in(b.temperature_c(), -128.0, 127.0);
        r.charge_mah = round_in(b.charge_mah(), 0.0, 65_535.0);
        r.capacity_mah = round_in(b.capacity_mah(), 0.0, 65_535.0);

        let cliffs = world.cliffs();
        r.cliffs = cliffs;
        for (i, signal) in r.cliff_signals.iter_mut().enumerate() {
            let level =
                (p.cliff_signal_mean + self.cliff_offsets[i]) * if cliffs[i] { 0.05 } else { 1.0 };
            let noisy = level + self.noise.normal(0.0, p.cliff_signal_noise);
            *signal = round_in(noisy, 0.0, 4095.0);
        }

        let (mount, look) = p.wall_sensor_bearings_rad;
        let noise = &mut self.noise;
        let sd = p.wall_signal_noise;
        let [wall_memo, bump_memos @ ..] = &mut self.ir_memos;
        let wall_clean = ir_signal(
            wall_memo,
            world,
            mount,
            look,
            p.wall_signal_peak,
            p.wall_signal_scale_m,
        );
        let wall = wall_clean + noise.normal(0.0, sd);
        r.wall_signal = round_in(wall, 0.0, 4095.0);
        for (i, (&bearing, memo)) in p.light_bump_bearings_rad.iter().zip(bump_memos).enumerate() {
            if !self.light_bumpers {
                noise.skip_normal();
                continue;
            }
            let (peak, scale) = (p.light_bump_peak, p.light_bump_scale_m);
            let s = ir_signal(memo, world, bearing, bearing, peak, scale) + noise.normal(0.0, sd);
            r.light_bump_signals[i] = round_in(s, 0.0, 4095.0);
            if s > p.light_bump_threshold {
                r.light_bumper |= 1 << i;
            }
        }
        r.wall = if self.caster_bit {
            wall > p.wall_signal_threshold
        } else {
            // Create 2: packet 8 is deprecated and mirrors the right light bumper [C2 p24].
            r.light_bumper & bits::LIGHT_BUMP_RIGHT != 0
        };

        let forward = (world.wheel_speed_mm_s(LEFT) + world.wheel_speed_mm_s(RIGHT)) / 2.0;
        if forward > 20.0 && !world.blocked() {
            r.stasis = bits::STASIS_TOGGLING;
        }
        r
    }
}

/// Reflected infrared from the nearest wall seen by a sensor (before noise): [`World::ir_range_m`]
/// and the exponential fade, with the sines, cosines and exponential of the sensor's last reading
/// reused for the same arguments.
fn ir_signal(
    memo: &mut IrMemo,
    world: &World,
    mount: f64,
    look: f64,
    peak: f64,
    scale: f64,
) -> f64 {
    let h = world.pose().heading_rad;
    let (mount, look) = (h + mount, h + look);
    let mount_dir = memo.mount.get(mount, Vec2::from_angle);
    // A sensor looking out along its mount bearing (the light bumpers): one sine and cosine.
    let look_dir = if look.to_bits() == mount.to_bits() {
        mount_dir
    } else {
        memo.look.get(look, Vec2::from_angle)
    };
    match world.ir_range_along(mount_dir, look_dir) {
        Some(d) if scale > 0.0 => peak * memo.fade.get(-d.max(0.0) / scale, f64::exp),
        _ => 0.0,
    }
}

/// One infrared sensor's last sines and cosines and fade (a robot at rest reads them again and again).
#[derive(Debug, Clone, Copy, Default)]
struct IrMemo {
    mount: Memo<Vec2>,
    look: Memo<Vec2>,
    fade: Memo<f64>,
}

/// The last argument (its bits) of a pure function of one `f64` and the value it gave: the same bits
/// in give the same value out, so it is reused rather than computed again.
#[derive(Debug, Clone, Copy, Default)]
struct Memo<T>(Option<(u64, T)>);

impl<T: Copy> Memo<T> {
    fn get(&mut self, arg: f64, f: impl FnOnce(f64) -> T) -> T {
        let bits = arg.to_bits();
        match self.0 {
            Some((at, value)) if at == bits => value,
            _ => {
                let value = f(arg);
                self.0 = Some((bits, value));
                value
            }
        }
    }
}

fn flag(on: bool, bit: i32) -> i32 {
    if on { bit } else { 0 }
}

/// `v` rounded (half away from zero) and limited to `lo..=hi`: `v.round().clamp(lo, hi) as i32`, without
/// the call to `round` for `|v| < 2⁵²`. There the truncation `v as i64` is exact and so is the fraction
/// `v − trunc(v)`; a fraction of a half or more steps one away from zero. (A −0 from `round` becomes +0
/// here, which the conversion to `i32` does not tell apart.)
fn round_in(v: f64, lo: f64, hi: f64) -> i32 {
    const EXACT_BELOW: f64 = 4_503_599_627_370_496.0; // 2⁵²: every f64 at or above it is an integer
    let rounded = if v.abs() < EXACT_BELOW {
        let truncated = v as i64 as f64;
        let fraction = v - truncated;
        if fraction >= 0.5 {
            truncated + 1.0
        } else if fraction <= -0.5 {
            truncated - 1.0
        } else {
            truncated
        }
    } else {
        v.round()
    };
    rounded.clamp(lo, hi) as i32
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oi::Model;
    use crate::sim::world::{DriveTarget, Pose};

    fn setup(model: Model) -> (World, Sensing) {
        let p = SimParams::for_model(model);
        let rng = Rng::new(9);
        let s = Sensing::new(&p, model.spec(), &rng);
        (World::new(p, rng.fork(10)), s)
    }

    /// `round_in` without `round` gives the integers `v.round().clamp(lo, hi) as i32` gives.
    #[test]
    fn rounding_matches_f64_round() {
        fn by_round(v: f64, lo: f64, hi: f64) -> i32 {
            v.round().clamp(lo, hi) as i32
        }
        let mut rng = Rng::new(11);
        let mut values: Vec<f64> = (0..200_000)
            .map(|i| match i % 4 {
                0 => rng.uniform(-40_000.0, 70_000.0),
                1 => rng.uniform(-3.0, 3.0),
                2 => rng.below(140_000) as f64 / 2.0 - 35_000.0,
                _ => rng.normal(0.0, 1e17),
            })
            .collect();
        // Halves, integers and their neighbours, the ends of the exact range, and the odd values.
        for base in [
            0.5,
            1.0,
            1.5,
            2.5,
            4095.5,
            32_767.5,
            65_535.5,
            4_503_599_627_370_495.5,
            4_503_599_627_370_496.0,
        ] {
            values.extend(crate::sim::test_floats::around(base));
        }
        values.extend([
            0.0,
            -0.0,
            0.49999999999999994,
            -0.49999999999999994,
            f64::NAN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            1e300,
            -1e300,
            f64::MIN_POSITIVE,
            -5e-324,
        ]);
        for (lo, hi) in [
            (f64::from(i16::MIN), f64::from(i16::MAX)),
            (0.0, 65_535.0),
            (-128.0, 127.0),
            (0.0, 4095.0),
        ] {
            for &v in &values {
                assert_eq!(
                    round_in(v, lo, hi),
                    by_round(v, lo, hi),
                    "{v:e} in {lo}..={hi}"
                );
            }
        }
    }

    #[test]
    fn idle_readings_are_plausible() {
        let (mut w, mut s) = setup(Model::Create2);
        w.step();
        let r = s.read(&w);
        assert_eq!(r.bumps_drops, 0);
        assert_eq!(r.overcurrents, 0);
        assert!((-140..=-80).contains(&r.current_ma), "{}", r.current_ma);
        assert!(
            (15_900..=16_200).contains(&r.voltage_mv),
            "{}",
            r.voltage_mv
        );
        assert_eq!(r.capacity_mah, 2068);
        assert!(r.cliff_signals.iter().all(|&c| c > 1500));
        assert_eq!(r.cliffs, [false; 4]);
    }

    #[test]
    fn a_lifted_create1_reports_both_drops_and_the_caster() {
        let (mut w, mut s) = setup(Model::Create1);
        w.set_lifted(true);
        w.step();
        let r = s.read(&w);
        let all = bits::WHEEL_DROP_LEFT | bits::WHEEL_DROP_RIGHT | bits::WHEEL_DROP_CASTER;
        assert_eq!(r.bumps_drops, all);
        w.set_cliff(2, true);
        w.step();
        let r = s.read(&w);
        assert_eq!(r.cliffs, [false, false, true, false]);
        assert!(r.cliff_signals[2] < r.cliff_signals[1] / 4);
    }

    #[test]
    fn walls_light_up_the_infrared_sensors_on_their_side() {
        let (mut w, mut s) = setup(Model::Create2);
        // Parallel to the x-axis wall, 5 mm away, with the wall on the right.
        w.set_pose(Pose {
            x_m: 0.5,
            y_m: 0.17,
            heading_rad: 0.0,
        });
        w.step();
        let r = s.read(&w);
        assert!(r.light_bump_signals[5] > r.light_bump_signals[0] + 100);
        assert!(r.light_bumper & bits::LIGHT_BUMP_RIGHT != 0);
        assert!(r.wall);
        let (mut w1, mut s1) = setup(Model::Create1);
        w1.set_pose(w.pose());
        w1.step();
        let r1 = s1.read(&w1);
        assert!(r1.wall && r1.wall_signal > 500, "{}", r1.wall_signal);
        w1.command(DriveTarget::STOP);
    }

    /// A Create 1 skips its light bumpers and motor currents; everything else it reads is what sensing
    /// that computes them reads, step by step (their noise is still drawn).
    #[test]
    fn skipped_readings_leave_every_other_reading_unchanged() {
        let p = SimParams::for_model(Model::Create1);
        let spec = *Model::Create1.spec();
        let full_spec = ModelSpec {
            has_light_bumpers: true,
            has_motor_currents: true,
            ..spec
        };
        let rng = Rng::new(9);
        let mut lean = Sensing::new(&p, &spec, &rng);
        let mut full = Sensing::new(&p, &full_spec, &rng);
        let mut w = World::new(p, rng.fork(10));
        w.command(DriveTarget::Speed {
            left_mm_s: 300.0,
            right_mm_s: 250.0,
        });
        let (mut lit, mut currents) = (0, 0);
        for i in 0..3000 {
            if i == 1500 {
                w.command(DriveTarget::Speed {
                    left_mm_s: -150.0,
                    right_mm_s: 150.0,
                });
            }
            w.step();
            let lean_r = lean.read(&w);
            let mut full_r = full.read(&w);
            lit += usize::from(full_r.light_bumper != 0);
            currents += usize::from(full_r.wheel_current_ma != [0; 2]);
            assert_eq!(lean_r.light_bump_signals, [0; 6]);
            assert_eq!(lean_r.wheel_current_ma, [0; 2]);
            full_r.light_bumper = 0;
            full_r.light_bump_signals = [0; 6];
            full_r.wheel_current_ma = [0; 2];
            assert_eq!(lean_r, full_r, "step {i}");
        }
        // The skipped readings were there to skip: walls came near and currents flowed.
        assert!(lit > 10 && currents > 1000, "{lit} {currents}");
    }

    /// The infrared signals with their sines, cosines and fades reused are those computed afresh from
    /// [`World::ir_range_m`], bit for bit, driving, at rest (when the memo answers) and lifted.
    #[test]
    fn the_infrared_memo_reads_what_computing_afresh_reads() {
        let (mut w, _) = setup(Model::Create2);
        let p = w.params().clone();
        let mut sensors = vec![(
            p.wall_sensor_bearings_rad.0,
            p.wall_sensor_bearings_rad.1,
            p.wall_signal_peak,
            p.wall_signal_scale_m,
        )];
        for &b in &p.light_bump_bearings_rad {
            sensors.push((b, b, p.light_bump_peak, p.light_bump_scale_m));
        }
        let mut memos = vec![IrMemo::default(); sensors.len()];
        let mut lit = 0;
        for i in 0..3000 {
            match i {
                0 => w.command(DriveTarget::Speed {
                    left_mm_s: 300.0,
                    right_mm_s: 260.0,
                }),
                1000 => w.command(DriveTarget::STOP),
                1500 => w.command(DriveTarget::Speed {
                    left_mm_s: -100.0,
                    right_mm_s: 100.0,
                }),
                2000 => w.set_lifted(true),
                2500 => w.set_lifted(false),
                _ => {}
            }
            w.step();
            for (&(mount, look, peak, scale), memo) in sensors.iter().zip(&mut memos) {
                let fresh = match w.ir_range_m(mount, look) {
                    Some(d) if scale > 0.0 => peak * (-d.max(0.0) / scale).exp(),
                    _ => 0.0,
                };
                let got = ir_signal(memo, &w, mount, look, peak, scale);
                assert_eq!(got.to_bits(), fresh.to_bits(), "step {i}");
                lit += usize::from(got > 100.0);
            }
        }
        assert!(lit > 100, "{lit}");
    }
}

//! The battery pack: charge integrating the current, terminal voltage sagging under load, pack
//! temperature, and the energy drawn (the paper's efficiency metric is distance per energy).
//!
//! Terminal voltage `V = OCV(state of charge) − R_int · I`; `I` = idle electronics + the motor drivers'
//! draw (always discharging: the simulated robot never sits on a charger). Temperature follows
//! `C·dT/dt = I²·R_int − G·(T − T_ambient)`.

use super::params::{OcvCurve, SimParams};

/// The pack and its measurements.
#[derive(Debug, Clone, PartialEq)]
pub struct Battery {
    capacity_mah: f64,
    charge_mah: f64,
    ocv: OcvCurve,
    r_int: f64,
    idle_a: f64,
    ambient_c: f64,
    heat_capacity: f64,
    conductance: f64,
    sense_alpha: f64,
    current_a: f64,
    sensed_current_a: f64,
    voltage_v: f64,
    temperature_c: f64,
    energy_j: f64,
}

impl Battery {
    /// A pack as described by `p`; `sense_alpha` is the current measurement's low-pass factor per
    /// update.
    pub fn new(p: &SimParams, sense_alpha: f64) -> Self {
        let charge_mah = p.capacity_mah * p.initial_charge_fraction.clamp(0.0, 1.0);
        let mut b = Battery {
            capacity_mah: p.capacity_mah,
            charge_mah,
            ocv: p.ocv_curve,
            r_int: p.internal_resistance_ohm,
            idle_a: p.idle_current_a,
            ambient_c: p.ambient_temp_c,
            heat_capacity: p.battery_heat_capacity_j_per_k,
            conductance: p.battery_thermal_conductance_w_per_k,
            sense_alpha,
            current_a: p.idle_current_a,
            sensed_current_a: p.idle_current_a,
            voltage_v: 0.0,
            temperature_c: p.ambient_temp_c,
            energy_j: 0.0,
        };
        b.voltage_v = b.open_circuit_v() - b.r_int * b.current_a;
        b
    }

    /// Open-circuit voltage at the present charge, V (linear between the curve's points).
    pub fn open_circuit_v(&self) -> f64 {
        let soc = self.state_of_charge();
        let mut prev = self.ocv[0];
        if soc <= prev.0 {
            return prev.1;
        }
        for &(s, v) in &self.ocv[1..] {
            if soc <= s {
                let t = (soc - prev.0) / (s - prev.0);
                return prev.1 + t * (v - prev.1);
            }
            prev = (s, v);
        }
        prev.1
    }

    /// Advances by `dt` s with the motor drivers drawing `motor_a` A in total.
    pub fn update(&mut self, dt: f64, motor_a: f64) {
        self.current_a = self.idle_a + motor_a.max(0.0);
        self.sensed_current_a += (self.current_a - self.sensed_current_a) * self.sense_alpha;
        self.charge_mah = (self.charge_mah - self.current_a * dt / 3.6).max(0.0);
        self.voltage_v = (self.open_circuit_v() - self.r_int * self.current_a).max(0.0);
        self.energy_j += self.voltage_v * self.current_a * dt;
        if self.heat_capacity > 0.0 {
            let heat = self.current_a * self.current_a * self.r_int;
            let loss = self.conductance * (self.temperature_c - self.ambient_c);
            self.temperature_c += (heat - loss) / self.heat_capacity * dt;
        }
    }

    /// Charge left, 0..=1.
    pub fn state_of_charge(&self) -> f64 {
        if self.capacity_mah > 0.0 {
            (self.charge_mah / self.capacity_mah).clamp(0.0, 1.0)
        } else {
            0.0
        }
    }

    /// Charge left, mAh.
    pub fn charge_mah(&self) -> f64 {
        self.charge_mah
    }

    /// Full capacity, mAh.
    pub fn capacity_mah(&self) -> f64 {
        self.capacity_mah
    }

    /// Current drawn now, A (positive = discharging; the OI reports it negated).
    pub fn current_a(&self) -> f64 {
        self.current_a
    }

    /// Current drawn as the firmware measures it (low-passed), A.
    pub fn sensed_current_a(&self) -> f64 {
        self.sensed_current_a
    }

    /// Terminal voltage, V.
    pub fn voltage_v(&self) -> f64 {
        self.voltage_v
    }

    /// Pack temperature, °C.
    pub fn temperature_c(&self) -> f64 {
        self.temperature_c
    }

    /// Energy drawn since the start, J.
    pub fn energy_j(&self) -> f64 {
        self.energy_j
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oi::Model;

    #[test]
    fn create2_idle_matches_the_published_sample() {
        let p = SimParams::for_model(Model::Create2);
        let b = Battery::new(&p, 1.0);
        // create_robot#64: 16 028 mV at −111 mA with 1888/2068 mAh.
        assert!((b.voltage_v() - 16.028).abs() < 0.1, "V {}", b.voltage_v());
        assert!((b.charge_mah() - 1888.0).abs() < 1.0);
    }

    #[test]
    fn load_sags_voltage_drains_charge_and_warms_the_pack() {
        let p = SimParams::default();
        let mut b = Battery::new(&p, 1.0);
        let v0 = b.voltage_v();
        let q0 = b.charge_mah();
        for _ in 0..60_000 {
            b.update(0.001, 3.0);
        }
        // One minute at ≈3.15 A is ≈52 mAh.
        let used = q0 - b.charge_mah();
        assert!((used - 3.15 / 60.0 * 1000.0).abs() < 0.5, "used {used}");
        let sag = v0 - b.voltage_v();
        assert!(sag > 0.5 && sag < 1.5, "sag {sag}");
        assert!(b.temperature_c() > p.ambient_temp_c);
        let e = b.energy_j();
        assert!(e > 60.0 * 3.0 * 13.0 && e < 60.0 * 3.2 * 17.0, "energy {e}");
    }

    #[test]
    fn ocv_interpolates_and_clamps() {
        let p = SimParams::for_model(Model::Create2);
        let mut b = Battery::new(&p, 1.0);
        b.charge_mah = 0.85 * b.capacity_mah;
        assert!((b.open_circuit_v() - 15.85).abs() < 1e-9);
        b.charge_mah = 0.0;
        assert_eq!(b.open_circuit_v(), 12.0);
        b.update(1.0, 1.0);
        assert_eq!(b.charge_mah(), 0.0);
    }
}

//! [`RunCounters`]: running counters of a run, accumulated from its [`TickRecord`]s.
//!
//! The dashboard shows them live and the experiment runner reports them at the end of a run; both feed
//! the same accumulator one record at a time, so the figures agree. Everything is computed from the
//! record alone:
//!
//! - over-current observations: ticks on which either wheel's over-current flag was set;
//! - stall events: rising edges of the stimulus E (off → on), and the time E was on;
//! - distance: Σ |distance_mm| (odometry since the previous tick), in metres;
//! - energy: Σ V·|I|·dt from the battery voltage and current, in joules (ticks without both readings add
//!   nothing and are counted in [`RunCounters::ticks_without_power`]);
//! - efficiency: metres travelled per kilojoule spent.
//!
//! `dt` is the gap between consecutive records' scheduled times, so skipped ticks are covered; the first
//! record (and any record whose time does not move forward) counts as one nominal period.

use serde::{Deserialize, Serialize};

use crate::record::TickRecord;

/// Running counters of one run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunCounters {
    /// The nominal tick period, ms (used for the first record).
    pub period_ms: f64,
    /// Records seen.
    pub ticks: u64,
    /// Ticks with either wheel's over-current flag set.
    pub overcurrent_observations: u64,
    /// Rising edges of the stimulus.
    pub stall_events: u64,
    /// Time the stimulus was on, seconds.
    pub time_stalled_s: f64,
    /// Distance travelled, Σ|distance|, metres.
    pub distance_m: f64,
    /// Electrical energy drawn, Σ V·|I|·dt, joules.
    pub energy_j: f64,
    /// Ticks that lacked the battery voltage or current.
    pub ticks_without_power: u64,
    /// Run time covered by the records, seconds.
    pub elapsed_s: f64,
    last_t_ms: Option<f64>,
    last_stimulus: bool,
}

impl RunCounters {
    /// Empty counters for a run ticking every `period_ms`.
    pub fn new(period_ms: f64) -> Self {
        RunCounters {
            period_ms,
            ticks: 0,
            overcurrent_observations: 0,
            stall_events: 0,
            time_stalled_s: 0.0,
            distance_m: 0.0,
            energy_j: 0.0,
            ticks_without_power: 0,
            elapsed_s: 0.0,
            last_t_ms: None,
            last_stimulus: false,
        }
    }

    /// Adds one tick.
    pub fn observe(&mut self, record: &TickRecord) {
        let dt_ms = match self.last_t_ms {
            Some(prev) if record.t_ms > prev => record.t_ms - prev,
            _ => self.period_ms,
        };
        let dt_s = dt_ms / 1000.0;
        self.last_t_ms = Some(record.t_ms);
        self.ticks += 1;
        self.elapsed_s += dt_s;

        let s = &record.sensors;
        if s.overcurrent_left || s.overcurrent_right {
            self.overcurrent_observations += 1;
        }
        if record.stimulus {
            if !self.last_stimulus {
                self.stall_events += 1;
            }
            self.time_stalled_s += dt_s;
        }
        self.last_stimulus = record.stimulus;
        self.distance_m += f64::from(s.distance_mm.unsigned_abs()) / 1000.0;
        match (s.battery_voltage_mv, s.battery_current_ma) {
            (Some(mv), Some(ma)) => {
                let volts = f64::from(mv) / 1000.0;
                let amps = f64::from(ma.unsigned_abs()) / 1000.0;
                self.energy_j += volts.abs() * amps * dt_s;
            }
            _ => self.ticks_without_power += 1,
        }
    }

    /// Metres per kilojoule; `None` before any energy was measured.
    pub fn efficiency_m_per_kj(&self) -> Option<f64> {
        (self.energy_j > 0.0).then(|| self.distance_m / (self.energy_j / 1000.0))
    }

    /// Over-current observations per minute of run time; `None` before any time has passed.
    pub fn overcurrent_per_minute(&self) -> Option<f64> {
        (self.elapsed_s > 0.0).then(|| self.overcurrent_observations as f64 * 60.0 / self.elapsed_s)
    }

    /// A serialisable snapshot with the derived figures filled in.
    pub fn totals(&self) -> RunTotals {
        RunTotals {
            ticks: self.ticks,
            elapsed_s: self.elapsed_s,
            overcurrent_observations: self.overcurrent_observations,
            stall_events: self.stall_events,
            time_stalled_s: self.time_stalled_s,
            distance_m: self.distance_m,
            energy_j: self.energy_j,
            efficiency_m_per_kj: self.efficiency_m_per_kj(),
        }
    }
}

/// The figures of a [`RunCounters`], as sent to the dashboard and written in reports.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RunTotals {
    /// Records seen.
    pub ticks: u64,
    /// Run time covered, seconds.
    pub elapsed_s: f64,
    /// Ticks with either over-current flag.
    pub overcurrent_observations: u64,
    /// Rising edges of the stimulus.
    pub stall_events: u64,
    /// Time the stimulus was on, seconds.
    pub time_stalled_s: f64,
    /// Distance travelled, metres.
    pub distance_m: f64,
    /// Energy drawn, joules.
    pub energy_j: f64,
    /// Metres per kilojoule (`null` before any energy was measured).
    pub efficiency_m_per_kj: Option<f64>,
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::control::Mode;

    fn record(seq: u64, t_ms: f64) -> TickRecord {
        TickRecord::at_rest(seq, t_ms, Mode::Pavlovian)
    }

    #[test]
    fn overcurrent_counts_ticks_with_either_flag_once() {
        let mut m = RunCounters::new(20.0);
        let flags = [
            (false, false),
            (true, false),
            (false, true),
            (true, true),
            (false, false),
        ];
        for (i, (l, r)) in flags.into_iter().enumerate() {
            let mut rec = record(i as u64, i as f64 * 20.0);
            rec.sensors.overcurrent_left = l;
            rec.sensors.overcurrent_right = r;
            m.observe(&rec);
        }
        assert_eq!(m.overcurrent_observations, 3);
        assert_eq!(m.ticks, 5);
    }

    #[test]
    fn stall_events_are_rising_edges_and_time_stalled_follows_the_stimulus() {
        let mut m = RunCounters::new(20.0);
        let stim = [false, true, true, true, false, true, false, false, true];
        for (i, &e) in stim.iter().enumerate() {
            let mut rec = record(i as u64, i as f64 * 20.0);
            rec.stimulus = e;
            m.observe(&rec);
        }
        assert_eq!(m.stall_events, 3);
        let on = stim.iter().filter(|&&e| e).count() as f64;
        assert!((m.time_stalled_s - on * 0.02).abs() < 1e-12);
    }

    #[test]
    fn a_run_starting_stalled_counts_one_event() {
        let mut m = RunCounters::new(20.0);
        let mut rec = record(0, 0.0);
        rec.stimulus = true;
        m.observe(&rec);
        assert_eq!(m.stall_events, 1);
    }

    #[test]
    fn distance_sums_absolute_odometry() {
        let mut m = RunCounters::new(20.0);
        for (i, d) in [10, -4, 0, 7, -3].into_iter().enumerate() {
            let mut rec = record(i as u64, i as f64 * 20.0);
            rec.sensors.distance_mm = d;
            m.observe(&rec);
        }
        assert!((m.distance_m - 0.024).abs() < 1e-12);
    }

    #[test]
    fn energy_integrates_voltage_times_current_over_the_record_gaps() {
        let mut m = RunCounters::new(20.0);
        // 16 V, −500 mA (discharging) on every tick; the third record comes after a skipped tick (40 ms).
        for (i, t) in [0.0, 20.0, 60.0].into_iter().enumerate() {
            let mut rec = record(i as u64, t);
            rec.sensors.battery_voltage_mv = Some(16_000);
            rec.sensors.battery_current_ma = Some(-500);
            m.observe(&rec);
        }
        // 8 W over 20 + 20 + 40 ms = 0.64 J.
        assert!((m.energy_j - 0.64).abs() < 1e-9, "{}", m.energy_j);
        assert!((m.elapsed_s - 0.08).abs() < 1e-12);
        assert_eq!(m.ticks_without_power, 0);
    }

    #[test]
    fn missing_battery_readings_add_no_energy_and_are_counted() {
        let mut m = RunCounters::new(20.0);
        let mut rec = record(0, 0.0);
        rec.sensors.battery_voltage_mv = Some(16_000);
        m.observe(&rec);
        assert_eq!(m.energy_j, 0.0);
        assert_eq!(m.ticks_without_power, 1);
        assert_eq!(m.efficiency_m_per_kj(), None);
    }

    #[test]
    fn efficiency_is_metres_per_kilojoule() {
        let mut m = RunCounters::new(20.0);
        for i in 0..50 {
            let mut rec = record(i, i as f64 * 20.0);
            rec.sensors.distance_mm = 4; // 0.2 m in total
            rec.sensors.battery_voltage_mv = Some(10_000);
            rec.sensors.battery_current_ma = Some(1_000); // 10 W for 1 s = 10 J
            m.observe(&rec);
        }
        let eff = m.efficiency_m_per_kj().unwrap();
        assert!((eff - 0.2 / 0.01).abs() < 1e-6, "{eff}");
        let s = m.totals();
        assert_eq!(s.ticks, 50);
        assert_eq!(s.efficiency_m_per_kj, Some(eff));
        assert!((m.overcurrent_per_minute().unwrap()).abs() < 1e-12);
    }

    #[test]
    fn time_going_backwards_counts_as_one_period() {
        let mut m = RunCounters::new(20.0);
        m.observe(&record(0, 100.0));
        m.observe(&record(1, 100.0));
        m.observe(&record(2, 50.0));
        assert!((m.elapsed_s - 0.06).abs() < 1e-12);
    }
}

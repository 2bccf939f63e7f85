//! The flat `/pavlov/signals` message: one tick's numbers with names, for plotting.
//!
//! `/pavlov/ticks` carries the whole [`TickRecord`], whose observations are a bare vector
//! (`obs[3]`) and whose predictions are a list (`predictions[0].value`). This message names them
//! (`obs.bump`, `predictions.stall`) and turns every flag into 0/1, so each field is a number a Plot
//! panel takes as it is. Built only while a client is subscribed.

use pavlov::record::TickRecord;
use serde::Serialize;
use std::collections::BTreeMap;

/// One tick as flat numbers (see `schema::signals`).
#[derive(Debug, Serialize)]
pub(crate) struct Signals<'a> {
    seq: u64,
    t_ms: f64,
    mode: pavlov::control::Mode,
    /// Observations by name; `None` (JSON null) where the packet was missing.
    obs: BTreeMap<&'a str, Option<f32>>,
    predictions: BTreeMap<&'a str, f64>,
    thresholds: BTreeMap<&'a str, f64>,
    stimulus: u8,
    gate: u8,
    estop: u8,
    safety_stop: u8,
    command_left_mm_s: i16,
    command_right_mm_s: i16,
    default_left_mm_s: i16,
    default_right_mm_s: i16,
    overcurrent_left: u8,
    overcurrent_right: u8,
    bump_left: u8,
    bump_right: u8,
    battery_current_ma: Option<i32>,
    battery_voltage_mv: Option<i32>,
    battery_charge_mah: Option<i32>,
    distance_mm: i32,
    angle_deg: i32,
    elbow_left: Option<f64>,
    elbow_right: Option<f64>,
    obs_age_ticks: Option<u32>,
    lateness_us: u32,
    link_up: u8,
}

impl<'a> Signals<'a> {
    /// The flat view of `record`, with `obs_names` naming its observation vector in order.
    pub(crate) fn of(record: &'a TickRecord, obs_names: &'a [String]) -> Self {
        let flag = u8::from;
        let s = &record.sensors;
        let elbow = record.elbow.as_ref();
        Signals {
            seq: record.seq,
            t_ms: record.t_ms,
            mode: record.mode,
            obs: obs_names
                .iter()
                .zip(&record.obs)
                .map(|(name, v)| (name.as_str(), (!v.is_nan()).then_some(*v)))
                .collect(),
            predictions: record
                .predictions
                .iter()
                .map(|p| (p.name.as_str(), p.value))
                .collect(),
            thresholds: record
                .predictions
                .iter()
                .map(|p| (p.name.as_str(), p.threshold))
                .collect(),
            stimulus: flag(record.stimulus),
            gate: flag(record.gate),
            estop: flag(record.estop),
            safety_stop: flag(record.safety_stop.is_some()),
            command_left_mm_s: record.command.left_mm_s,
            command_right_mm_s: record.command.right_mm_s,
            default_left_mm_s: record.default_action.left_mm_s,
            default_right_mm_s: record.default_action.right_mm_s,
            overcurrent_left: flag(s.overcurrent_left),
            overcurrent_right: flag(s.overcurrent_right),
            bump_left: flag(s.bump_left),
            bump_right: flag(s.bump_right),
            battery_current_ma: s.battery_current_ma,
            battery_voltage_mv: s.battery_voltage_mv,
            battery_charge_mah: s.battery_charge_mah,
            distance_mm: s.distance_mm,
            angle_deg: s.angle_deg,
            elbow_left: elbow.and_then(|e| e.left),
            elbow_right: elbow.and_then(|e| e.right),
            obs_age_ticks: record.obs_age_ticks,
            lateness_us: record.lateness_us,
            link_up: flag(record.link.up),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::super::schema::{self, tests::conforms, tests::full_record};
    use super::*;

    #[test]
    fn observations_and_predictions_are_named_and_flags_are_numbers() {
        let record = full_record();
        let names = vec!["bump".to_string(), "wall".into(), "current".into()];
        let value = serde_json::to_value(Signals::of(&record, &names)).unwrap();
        assert_eq!(value["obs"]["bump"], 0.25);
        assert!(value["obs"]["wall"].is_null(), "NaN is null");
        assert_eq!(value["obs"]["current"], 1.0);
        assert_eq!(value["predictions"]["stall"], 0.4);
        assert_eq!(value["thresholds"]["stall"], 0.5);
        assert_eq!(value["gate"], 1);
        assert_eq!(value["estop"], 1);
        assert_eq!(value["safety_stop"], 1);
        assert_eq!(value["stimulus"], 1);
        assert_eq!(value["default_left_mm_s"], 200);
        assert_eq!(value["battery_current_ma"], -250);
        assert_eq!(value["elbow_left"], 91.5);
        assert_eq!(value["seq"], 7);
        let schema = schema::signals(&names, &["stall".to_string()]);
        conforms(&value, &schema, "$").unwrap();
        // The same message against a schema made for other names fails: names are part of the schema.
        let other = schema::signals(&["x".to_string()], &["stall".to_string()]);
        assert!(conforms(&value, &other, "$").is_err());
    }
}

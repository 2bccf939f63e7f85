//! A tick record as a Protocol Buffers message (`pavlov.Tick`), the encoding of an MCAP recording's
//! `ticks` channel: the recorder's encoder and the reader's decoder.
//!
//! Why protobuf and not JSON for ticks: a tick is written 50 times a second in real time and ~50 000 times
//! a second in an experiment under virtual time, on the same two cores that compute the runs; encoding a
//! tick as protobuf takes a fraction of the time JSON needs (floats are copied, not printed) and gives a
//! third of the bytes to compress (the book's "Recording format", `docs/src/recordings.md`, has the
//! measurements). Foxglove, the `mcap` CLI and `mcap-protobuf-support` decode it with the schema the file
//! carries ([`super::schema`]).
//!
//! The message's shape is the record's own: `pavlov::record` declares each struct's field numbers beside
//! its definition, and `pavlov::record::wire` derives the encoder, the decoder and the schema from them.
//! What this file adds is the reader's side of the scaled observation `obs`: it is a pure function of the
//! raw sensor snapshot the message carries (`inputs.values`) and the robot model in the recording's
//! configuration, so the reader recomputes it bit for bit ([`decode`]); storing it would add half the
//! bytes again. (Only a record without inputs, from a JSON Lines recording older than replay, carries its
//! `obs` in field 17.)

use pavlov::record::TickRecord;
use pavlov::record::wire::Message as _;

/// Why a message is not a tick this version can read.
pub use pavlov::record::wire::WireError as TickDecodeError;

/// Encodes tick records with one reused buffer, so that encoding allocates nothing once warm.
#[derive(Debug, Default)]
pub struct TickEncoder {
    buf: Vec<u8>,
}

impl TickEncoder {
    /// The message for `r`, valid until the next call.
    pub fn encode(&mut self, r: &TickRecord) -> &[u8] {
        self.buf.clear();
        r.encode_to(&mut self.buf);
        &self.buf
    }
}

/// Decodes a `ticks` message, with `obs` recomputed from its raw snapshot by `layout`.
pub(crate) fn decode(
    bytes: &[u8],
    layout: &pavlov::obs::ObsLayout,
) -> Result<TickRecord, TickDecodeError> {
    let mut r = TickRecord::decode(bytes)?;
    match r.inputs.as_ref() {
        None => {}
        Some(inputs) => {
            r.obs = match &inputs.values {
                Some(values) => {
                    let mut scaled = Vec::with_capacity(layout.len());
                    layout.scale(values, &mut scaled);
                    scaled.into_iter().map(|x| x as f32).collect()
                }
                None => vec![f32::NAN; layout.len()],
            };
        }
    }
    Ok(r)
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;
    use pavlov::control::{Action, Mode};
    use pavlov::obs::ObsLayout;
    use pavlov::oi::{Model, SensorValues};
    use pavlov::record::{
        ElbowAngles, LinkStatus, PredictionValue, SafetyStop, SensorReadings, TickInputs,
    };
    use pavlov::skeleton::SkeletonStatus;
    use pavlov::supervision::{LinkState, TripCause};

    fn layout() -> ObsLayout {
        ObsLayout::for_model(Model::Create1)
    }

    fn values(k: i32) -> SensorValues {
        let mut v = SensorValues::new();
        for id in 7..=42u8 {
            v.set(id, (i32::from(id) * 37 + k) % 300 - 150);
        }
        v.set(22, 15_000 + k);
        v.set(23, -1_200 - k);
        v
    }

    fn obs_of(v: Option<&SensorValues>) -> Vec<f32> {
        let l = layout();
        match v {
            Some(v) => {
                let mut out = Vec::new();
                l.scale(v, &mut out);
                out.into_iter().map(|x| x as f32).collect()
            }
            None => vec![f32::NAN; l.len()],
        }
    }

    /// Records that between them use every variant and every option both ways.
    #[allow(
        clippy::needless_update,
        reason = "a field added later takes its default here, so the records keep their bytes"
    )]
    pub(crate) fn records() -> Vec<TickRecord> {
        let stops = [
            None,
            Some(SafetyStop::EStop),
            Some(SafetyStop::StaleObservation),
            Some(SafetyStop::LinkDown),
            Some(SafetyStop::RobotTripped),
        ];
        let states = [
            LinkState::Up,
            LinkState::Stale,
            LinkState::Reconnecting,
            LinkState::Tripped,
            LinkState::Down,
        ];
        let trips = [
            None,
            Some(TripCause::WheelDrop),
            Some(TripCause::Cliff),
            Some(TripCause::Charger),
            Some(TripCause::Unknown),
        ];
        (0..15u64)
            .map(|i| {
                let k = i as usize;
                let vals = (i % 4 != 3).then(|| values(i as i32));
                TickRecord {
                    seq: i * 1_000_003,
                    t_ms: if i == 2 {
                        -0.0
                    } else {
                        i as f64 * 20.000000000000004
                    },
                    mode: [Mode::Reactive, Mode::Pavlovian, Mode::Manual][k % 3],
                    obs_age_ticks: (i % 2 == 0).then_some(i as u32 * 7),
                    sensors: SensorReadings {
                        overcurrent_left: i % 2 == 0,
                        overcurrent_right: i % 3 == 0,
                        bump_left: i % 5 == 0,
                        bump_right: i % 7 == 0,
                        battery_current_ma: (i % 3 != 1).then_some(-1_500 + i as i32),
                        battery_voltage_mv: (i % 3 != 2).then_some(16_000),
                        battery_charge_mah: (i % 4 != 0).then_some(2_500),
                        distance_mm: 3 - i as i32,
                        angle_deg: -(i as i32),
                        oi_mode: (i % 2 == 1).then_some(2),
                    },
                    obs: obs_of(vals.as_ref()),
                    elbow: (i % 3 == 0).then(|| ElbowAngles {
                        left: Some(91.25 + i as f64),
                        left_avg: (i % 2 == 0).then_some(0.1 + 0.2),
                        right: (i % 2 == 1).then_some(170.5 - i as f64),
                        right_avg: Some(-0.0),
                        skeleton: [
                            SkeletonStatus::Tracked,
                            SkeletonStatus::Stale,
                            SkeletonStatus::Absent,
                        ][(i % 3) as usize],
                    }),
                    stimulus: i % 2 == 1,
                    predictions: (0..k % 3)
                        .map(|p| PredictionValue {
                            name: format!("p{p}"),
                            value: if i == 1 { -0.0 } else { 1.0 / (i as f64 + 3.0) },
                            threshold: if p == 1 { f64::INFINITY } else { 0.5 },
                        })
                        .collect(),
                    gate: i % 4 == 0,
                    rule: match i % 4 {
                        0 => Some(format!("rule {i} ✓")),
                        1 => Some("stimulus".into()),
                        2 => Some(String::new()),
                        _ => None,
                    },
                    default_action: Action::new(-500 + i as i16, 500),
                    command: Action::new(i16::MIN, i16::MAX),
                    safety_stop: stops[k % 5],
                    estop: i % 6 == 0,
                    lateness_us: i as u32 * 1_000,
                    link: LinkStatus {
                        up: i % 2 == 0,
                        good_frames: u64::MAX - i,
                        bad_frames: i,
                        skipped_bytes: 3 * i,
                        state: states[k % 5],
                        mode: (i % 3 != 0).then_some(3),
                        trip: trips[(k + 2) % 5],
                        reconnects: i / 2,
                        stale_events: i / 3,
                    },
                    inputs: (i % 5 != 4).then(|| TickInputs {
                        values: vals.clone(),
                        forced_stimulus: i % 2 == 0,
                        previous_followed_default: i % 3 == 0,
                        // Certain, as every record of the golden file was (see the core's tests for b).
                        previous_behaviour_prob: 1.0,
                    }),
                    ..TickRecord::default()
                }
            })
            .collect()
    }

    /// Equality bit for bit: as JSON text, where NaN (an observation without a reading) is `null` on
    /// both sides and −0.0 differs from 0.0.
    fn same(a: &TickRecord, b: &TickRecord) -> bool {
        serde_json::to_string(a).unwrap() == serde_json::to_string(b).unwrap()
    }

    #[test]
    fn every_record_reads_back_exactly_with_its_observation_recomputed() {
        let layout = layout();
        let mut enc = TickEncoder::default();
        for r in records() {
            let back = decode(enc.encode(&r), &layout).unwrap();
            assert!(same(&r, &back), "{r:?}\n{back:?}");
        }
    }

    #[test]
    fn the_bytes_are_those_recordings_were_written_with() {
        // tests/data/tick_messages_recording3.bin holds these records as `prost`'s derived encoder and
        // the hand-written encoder of `pavlov-recording/3` wrote them (each behind its length, u32 LE;
        // see tests/data/README.md): the encoding derived from the record's types writes the same bytes.
        let golden = include_bytes!("../../../../tests/data/tick_messages_recording3.bin");
        let mut rest = golden.as_slice();
        let mut enc = TickEncoder::default();
        let records = records();
        for r in &records {
            let (len, tail) = rest.split_at(4);
            let len = u32::from_le_bytes(len.try_into().unwrap()) as usize;
            let (bytes, tail) = tail.split_at(len);
            assert_eq!(enc.encode(r), bytes, "tick {}", r.seq);
            rest = tail;
        }
        assert!(rest.is_empty(), "{} records in the file", records.len());
    }

    #[test]
    fn bad_bytes_and_bad_values_are_errors_naming_them() {
        let layout = layout();
        assert!(matches!(
            decode(&[0xff, 0xff, 0xff], &layout),
            Err(TickDecodeError::Malformed(_))
        ));
        let mut enc = TickEncoder::default();
        let mut bytes = enc.encode(&records()[0]).to_vec();
        // Field 11 (command) holding field 1 (left_mm_s) = 40 000, zig-zag encoded.
        bytes.extend_from_slice(&[0x5a, 0x04, 0x08, 0x80, 0xf1, 0x04]);
        let err = decode(&bytes, &layout).unwrap_err();
        assert_eq!(
            err,
            TickDecodeError::BadValue {
                field: "command.left_mm_s".into(),
                value: 40_000
            }
        );
        assert!(err.to_string().contains("`command.left_mm_s`"), "{err}");
    }
}

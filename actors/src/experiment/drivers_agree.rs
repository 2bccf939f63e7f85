//! The two drivers of a paused run ([`Driver::Actors`], [`Driver::Stepped`]) make the same run: the same
//! tick records handed to the collector, and recordings holding the same ticks and events, bit for bit.

use std::path::PathBuf;
use std::sync::Arc;

use pavlov::config::Config;
use pavlov::control::Mode;
use pavlov::record::TickRecord;
use sha2::{Digest, Sha256};

use super::runner::{Collect, Driver, Finished, RunError, RunRequest, run_paused_on};
use crate::storage::recording::bench_support::TickEncoder;

/// Hashes every record as a recording writes it (its `pavlov.Tick` protobuf message).
#[derive(Default)]
pub(super) struct Hash(Sha256, u64, TickEncoder);

impl Collect for Hash {
    type Output = (String, u64);

    fn record(&mut self, record: Arc<TickRecord>) {
        self.0.update(self.2.encode(&record));
        self.1 += 1;
    }

    async fn finish(self) -> Result<Self::Output, RunError> {
        let digest = self.0.finalize();
        Ok((digest.iter().map(|b| format!("{b:02x}")).collect(), self.1))
    }
}

/// The stall study's configuration for run 1 of study seed `seed` in `mode`.
fn config(seed: u64, mode: Mode) -> Config {
    let mut config =
        Config::from_toml(include_str!("../../../config/stall.toml")).expect("stall config");
    config.control.mode = mode;
    config.sim.seed = super::stall::run_seed(seed, 1);
    config
}

/// A fresh scratch folder for one run's recording (both drivers record into the same one in turn, so that
/// the events naming the recording's path agree).
fn scratch(name: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("pavlov-drivers-{name}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch folder");
    dir
}

/// What a run made: the run (with the collector's hash), and its recording's ticks (as protobuf messages)
/// and events.
type Made = (
    Finished<(String, u64)>,
    Vec<Vec<u8>>,
    Vec<pavlov::event::Event>,
);

/// Runs `config` for `ticks` on `driver`, recorded into a scratch folder.
fn run(driver: Driver, config: Config, ticks: u64, name: &str) -> Made {
    let dir = scratch(name);
    let request = RunRequest {
        config,
        ticks,
        record: Some((dir.clone(), name.to_string())),
    };
    let done = run_paused_on(driver, request, Hash::default()).expect("run");
    let path = done.recording.clone().expect("a recording");
    let recording = crate::storage::recording::load(&path).expect("the recording reads back");
    let mut encoder = TickEncoder::default();
    let records = recording
        .records
        .iter()
        .map(|r| encoder.encode(r).to_vec())
        .collect();
    let _ = std::fs::remove_dir_all(&dir);
    (done, records, recording.events)
}

#[test]
fn the_stepped_driver_records_what_the_actors_record_for_seeds_1_to_3() {
    let ticks = 1500;
    let runs = [
        (1, Mode::Pavlovian),
        (2, Mode::Pavlovian),
        (3, Mode::Pavlovian),
        (1, Mode::Reactive),
    ];
    for (seed, mode) in runs {
        let name = format!("{seed}-{mode:?}");
        let (actors, actor_ticks, actor_events) =
            run(Driver::Actors, config(seed, mode), ticks, &name);
        let (stepped, stepped_ticks, stepped_events) =
            run(Driver::Stepped, config(seed, mode), ticks, &name);
        assert_eq!(
            actors.output.1, ticks,
            "{name}: the actors' run is complete"
        );
        assert_eq!(actors.lagged, 0, "{name}");
        assert_eq!(
            stepped.output, actors.output,
            "{name}: the collector saw other ticks"
        );
        assert_eq!(actors.recorded, stepped.recorded, "{name}: records written");
        assert_eq!(actor_ticks.len() as u64, actors.recorded, "{name}");
        assert!(
            actor_ticks == stepped_ticks,
            "{name}: the recordings hold other ticks (first difference at tick {:?})",
            actor_ticks
                .iter()
                .zip(&stepped_ticks)
                .position(|(a, b)| a != b)
        );
        assert_eq!(
            actor_events, stepped_events,
            "{name}: the recordings' events"
        );
    }
}

//! What recording one tick costs on the recorder's thread, on 3000 ticks of a real stall run (the real
//! server on the simulated Create under the paused clock):
//! - `json`: the tick as a JSON line (the JSON Lines format's cost, before any I/O);
//! - `protobuf`: the tick as a `pavlov.Tick` message (what the MCAP recorder encodes);
//! - `mcap_zstd1`: the whole MCAP write of a tick: encoding, framing, zstd level 1, CRC, and the
//!   finished chunks handed to a writer that discards them.
//!
//! README "Recording format" quotes the figures. Run: `cargo bench -p pavlov-actors --bench recording`.

use std::hint::black_box;
use std::io::{Seek, SeekFrom, Write};

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use pavlov::record::TickRecord;
use pavlov_actors::server::{RobotTarget, Server};
use pavlov_actors::storage::recording::RecordingHeader;
use pavlov_actors::storage::recording::StartState;
use pavlov_actors::storage::recording::bench_support::{McapSink, TickEncoder};

const TICKS: usize = 3000;

fn config() -> pavlov::config::Config {
    pavlov::config::Config::from_toml(include_str!("../config/stall.toml")).expect("stall config")
}

/// The records of a 60-second stall run.
fn records() -> Vec<TickRecord> {
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .start_paused(true)
        .build()
        .expect("runtime");
    rt.block_on(async {
        let server = Server::builder(config(), RobotTarget::Simulated)
            .start()
            .await
            .expect("server");
        let mut rx = server.feed().subscribe();
        let mut out = Vec::with_capacity(TICKS);
        while out.len() < TICKS {
            if let Ok(r) = rx.recv().await {
                out.push((*r).clone());
            }
        }
        server.shutdown().await;
        out
    })
}

/// A file that keeps nothing.
#[derive(Default)]
struct Discard(u64);

impl Write for Discard {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0 += buf.len() as u64;
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

impl Seek for Discard {
    fn seek(&mut self, _: SeekFrom) -> std::io::Result<u64> {
        Ok(self.0)
    }
}

fn bench(c: &mut Criterion) {
    let records = records();
    let mut header = RecordingHeader::new(&config(), "bench");
    header.start = Some(StartState {
        after: None,
        events_before: 0,
        learner: pavlov::agent::LearningStage::new(&config())
            .expect("learner")
            .stage_snapshot(),
    });
    let mut g = c.benchmark_group("record_tick");
    g.throughput(Throughput::Elements(records.len() as u64));
    g.bench_function("json", |b| {
        let mut buf = Vec::with_capacity(2048);
        b.iter(|| {
            for r in &records {
                buf.clear();
                serde_json::to_writer(&mut buf, r).expect("json");
                black_box(&buf);
            }
        })
    });
    g.bench_function("protobuf", |b| {
        let mut enc = TickEncoder::default();
        b.iter(|| {
            for r in &records {
                black_box(enc.encode(r));
            }
        })
    });
    g.bench_function("mcap_zstd1", |b| {
        let mut sink = McapSink::create(Discard::default(), &header).expect("sink");
        b.iter(|| {
            for r in &records {
                sink.tick(r).expect("tick");
            }
        })
    });
    g.finish();
}

criterion_group!(benches, bench);
criterion_main!(benches);

//! Benchmarks of the Open Interface code: stream-parser throughput on a realistic Create 2 byte stream
//! (group-100 frames with about 5% garbage between them), and command / frame encoding.

use std::hint::black_box;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use pavlov::oi::command::Command;
use pavlov::oi::frame::encode_stream_frame;
use pavlov::oi::packets::spec;
use pavlov::oi::parser::StreamParser;
use pavlov::oi::{Model, SensorValues};
use pavlov::rng::Rng;

const GROUP_ALL: u8 = 100;

/// Random in-range values for every packet of group 100.
fn random_values(rng: &mut Rng) -> SensorValues {
    let mut values = SensorValues::new();
    for id in 7..=58u8 {
        if let Some(s) = spec(id) {
            let (lo, hi) = s.wire_range();
            values.set(id, lo + rng.below((hi - lo + 1) as u64) as i32);
        }
    }
    values
}

/// `frames` group-100 frames (84 bytes each); before a quarter of them, a burst of 2–32 random bytes
/// (a fifth of them false headers, 19): on average 4.25 garbage bytes per frame, about 5% of the stream.
fn garbage_stream(frames: usize, seed: u64) -> (Vec<u8>, usize) {
    let mut rng = Rng::new(seed);
    let mut stream = Vec::new();
    let mut garbage = 0;
    for _ in 0..frames {
        if rng.chance(0.25) {
            let burst = 1 + rng.below(16) as usize;
            for _ in 0..2 * burst {
                let b = if rng.chance(0.2) {
                    19
                } else {
                    rng.below(256) as u8
                };
                stream.push(b);
            }
            garbage += 2 * burst;
        }
        let values = random_values(&mut rng);
        stream.extend(encode_stream_frame(&[GROUP_ALL], &values).unwrap_or_default());
    }
    (stream, garbage)
}

fn parser_throughput(c: &mut Criterion) {
    let (stream, garbage) = garbage_stream(2_000, 7);
    eprintln!(
        "parser bench stream: {} bytes, {:.1}% garbage",
        stream.len(),
        100.0 * garbage as f64 / stream.len() as f64
    );
    let mut group = c.benchmark_group("stream_parser");
    group.throughput(Throughput::Bytes(stream.len() as u64));
    for chunk in [64usize, 4096] {
        group.bench_function(format!("group100_5pct_garbage_chunks_of_{chunk}"), |b| {
            b.iter(|| {
                let mut parser = StreamParser::new(&[GROUP_ALL]).unwrap_or_else(|e| panic!("{e}"));
                let mut frames = 0usize;
                for c in stream.chunks(chunk) {
                    parser.feed(black_box(c), |v| {
                        frames += 1;
                        black_box(v);
                    });
                }
                frames
            })
        });
    }
    group.bench_function("group100_5pct_garbage_feed_newest_4096", |b| {
        b.iter(|| {
            let mut parser = StreamParser::new(&[GROUP_ALL]).unwrap_or_else(|e| panic!("{e}"));
            let mut newest = None;
            for c in stream.chunks(4096) {
                newest = parser.feed_newest(black_box(c)).or(newest);
            }
            newest
        })
    });
    group.finish();
}

fn encoding(c: &mut Criterion) {
    let drive = Command::DriveDirect {
        right: 250,
        left: -120,
    };
    c.bench_function("encode_drive_direct", |b| {
        b.iter(|| black_box(&drive).encode(Model::Create2))
    });
    let mut out = Vec::with_capacity(16);
    c.bench_function("encode_drive_direct_into_reused_buffer", |b| {
        b.iter(|| {
            out.clear();
            black_box(&drive).encode_into(Model::Create2, &mut out)
        })
    });
    let values = random_values(&mut Rng::new(3));
    c.bench_function("encode_stream_frame_group100", |b| {
        b.iter(|| encode_stream_frame(black_box(&[GROUP_ALL]), black_box(&values)))
    });
}

criterion_group!(benches, parser_throughput, encoding);
criterion_main!(benches);

//! Actuation's safety net against a robot that goes quiet: the test plays the robot on an in-memory link,
//! streams valid frames for one second and then stops. Within the configured 5 ticks the server must be
//! writing nothing but stops, and say why in the tick records; 150 ms after the last frame it re-sends
//! Start, Safe and Stream (the link cannot be reopened here, so it keeps re-syncing with backoff).

use crate::common;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use pavlov::oi::command::{Command, ParsedCommand, parse_command};
use pavlov::oi::frame::encode_stream_frame;
use pavlov::oi::packets::id;
use pavlov::oi::{Model, SensorValues};
use pavlov::record::SafetyStop;
use pavlov_actors::link::OpenLink;
use pavlov_actors::server::{RobotTarget, Server};
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::time::Instant;

fn quiet_robot_frame() -> Vec<u8> {
    let mut v = SensorValues::new();
    for p in 7..=42 {
        v.set(p, 0);
    }
    v.set(id::VOLTAGE, 15_500);
    v.set(id::CURRENT, -300);
    v.set(id::TEMPERATURE, 25);
    v.set(id::BATTERY_CHARGE, 2000);
    v.set(id::BATTERY_CAPACITY, 3000);
    v.set(id::OI_MODE, 2);
    encode_stream_frame(&[6], &v).expect("group 6 frame")
}

#[tokio::test(start_paused = true)]
async fn a_stale_sensor_stream_stops_the_wheels_within_five_ticks() {
    common::init_logging();
    let (host, device) = tokio::io::duplex(64 * 1024);
    let (host_r, host_w) = tokio::io::split(host);
    let (mut dev_r, mut dev_w) = tokio::io::split(device);
    let start = Instant::now();
    let streaming_for = Duration::from_secs(1);

    // What the server writes, with when it arrived.
    let written: Arc<Mutex<Vec<(Duration, u8)>>> = Arc::default();
    let sink = written.clone();
    tokio::spawn(async move {
        let mut buf = [0u8; 256];
        while let Ok(n) = dev_r.read(&mut buf).await {
            if n == 0 {
                break;
            }
            let at = start.elapsed();
            sink.lock()
                .unwrap()
                .extend(buf[..n].iter().map(|&b| (at, b)));
        }
    });
    // The robot: one frame every 15 ms for a second, then silence (the link stays open).
    tokio::spawn(async move {
        let frame = quiet_robot_frame();
        let mut every = tokio::time::interval(Duration::from_millis(15));
        while start.elapsed() < streaming_for {
            every.tick().await;
            if dev_w.write_all(&frame).await.is_err() {
                return;
            }
        }
        std::future::pending::<()>().await;
    });

    let link = OpenLink {
        reader: Box::new(host_r),
        writer: Box::new(host_w),
        opener: None,
    };
    let server = Server::builder(
        common::stall_config(),
        RobotTarget::Link { link, sim: None },
    )
    .start()
    .await
    .expect("server starts");
    let mut rx = server.feed().subscribe();
    let records = common::collect(&mut rx, 100).await; // 2 s
    server.shutdown().await;

    let bytes = written.lock().unwrap().clone();
    assert_eq!(
        bytes.iter().take(5).map(|&(_, b)| b).collect::<Vec<_>>(),
        vec![128, 131, 148, 1, 6],
        "start-up sequence"
    );
    // Every command the server wrote, parsed as the robot would, with when it arrived.
    let mut commands: Vec<(Duration, Command)> = Vec::new();
    let mut at = 0;
    while at < bytes.len() {
        let rest: Vec<u8> = bytes[at..].iter().map(|&(_, b)| b).collect();
        match parse_command(Model::Create1, &rest) {
            ParsedCommand::Complete { command, consumed } => {
                commands.push((bytes[at].0, command));
                at += consumed;
            }
            other => panic!("the server wrote an unparsable command at byte {at}: {other:?}"),
        }
    }
    let drives: Vec<(Duration, i16, i16)> = commands
        .iter()
        .filter_map(|(t, c)| match c {
            Command::DriveDirect { right, left } => Some((*t, *left, *right)),
            _ => None,
        })
        .collect();
    // Once the stream is stale (150 ms), Start and Stream are sent again (with Safe: no trip was seen).
    let resyncs: Vec<Duration> = commands
        .windows(3)
        .filter(|w| {
            w[0].0 > streaming_for
                && matches!(w[0].1, Command::Start)
                && matches!(w[1].1, Command::Safe)
                && matches!(&w[2].1, Command::Stream(ids) if ids == &vec![6])
        })
        .map(|w| w[0].0)
        .collect();
    assert!(!resyncs.is_empty(), "no re-sync after the stream stopped");
    assert!(
        resyncs[0] <= streaming_for + Duration::from_millis(150 + 20 + 15),
        "first re-sync at {:?}",
        resyncs[0]
    );
    let limit = streaming_for + Duration::from_millis(20 * 6 + 15);
    let before: Vec<_> = drives.iter().filter(|d| d.0 < streaming_for).collect();
    let after: Vec<_> = drives.iter().filter(|d| d.0 > limit).collect();
    assert!(
        before.iter().any(|&&(_, l, r)| (l, r) != (0, 0)),
        "the default policy drives while the stream is fresh"
    );
    assert!(after.len() > 20, "commands keep flowing: {}", after.len());
    assert!(
        after.iter().all(|&&(_, l, r)| (l, r) == (0, 0)),
        "a non-zero command after the stream went stale: {after:?}"
    );
    let stale: Vec<_> = records
        .iter()
        .filter(|r| r.safety_stop == Some(SafetyStop::StaleObservation))
        .collect();
    assert!(!stale.is_empty());
    let first_stale = stale[0].t_ms;
    assert!(
        first_stale <= 1000.0 + 20.0 * 7.0,
        "first stale stop at {first_stale} ms"
    );
}

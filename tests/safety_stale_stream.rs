//! Actuation's safety net against a robot that goes quiet: the test plays the robot on an in-memory link,
//! streams valid frames for one second and then stops. Within the configured 5 ticks the server must be
//! writing nothing but stops, and say why in the tick records.

mod common;

use std::sync::{Arc, Mutex};
use std::time::Duration;

use pavlov::oi::SensorValues;
use pavlov::oi::frame::encode_stream_frame;
use pavlov::oi::packets::id;
use pavlov::record::SafetyStop;
use pavlov_actors::server::Server;
use tokio::io::{AsyncReadExt, AsyncWriteExt};
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

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

    let server = Server::start_on_link(
        common::stall_config(),
        Box::new(host_r),
        Box::new(host_w),
        None,
        CancellationToken::new(),
    )
    .await
    .expect("server starts");
    let mut rx = server.feed.subscribe();
    let records = common::collect(&mut rx, 100).await; // 2 s
    server.shutdown().await;

    let bytes = written.lock().unwrap().clone();
    assert_eq!(
        bytes.iter().take(5).map(|&(_, b)| b).collect::<Vec<_>>(),
        vec![128, 131, 148, 1, 6],
        "start-up sequence"
    );
    // Drive Direct commands after the start-up sequence (the shut-down sequence ends the stream).
    let drives: Vec<(Duration, i16, i16)> = bytes[5..]
        .chunks(5)
        .filter(|c| c.len() == 5 && c[0].1 == 145)
        .map(|c| {
            let right = i16::from_be_bytes([c[1].1, c[2].1]);
            let left = i16::from_be_bytes([c[3].1, c[4].1]);
            (c[0].0, left, right)
        })
        .collect();
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

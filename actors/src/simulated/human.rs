//! The simulated human as a skeleton streamer: [`SimHuman`] frames encoded as real OSC (OSCeleton or
//! KinectV2-OSC) and sent over UDP (`pavlov human`), and [`drive_pose`], which publishes the same frames straight
//! into a pose channel for deterministic in-process experiments.
//!
//! Wire layout, as the real streamers send it:
//! - OSCeleton (`osceleton_mm`, `osceleton_normalized`): a bundle `/new_user` + `/new_skel` at the start; then one
//!   bundle per frame holding `/joint ,sifff name user x y z` for every joint the frame reports (dropped joints
//!   are left out, as OSCeleton leaves out joints below confidence 0.5); `/lost_user` at the end.
//! - KinectV2-OSC (`kinect_v2`): one unbundled `/bodies/<id>/joints/<JointType> ,fffs x y z "Tracked"` message per
//!   reported joint, in metres (the body id is `KINECT_ID_BASE` + the user id).

use std::net::SocketAddr;
use std::time::Duration;

use pavlov::config::SkeletonFormat;
use pavlov::sim::human::{HumanFrame, HumanParams, SimHuman};
use pavlov::skeleton::{JointSample, PoseTracker, mm_to_osceleton_normalized};
use rosc::{OscBundle, OscMessage, OscPacket, OscTime, OscType};
use tokio::net::UdpSocket;
use tokio::sync::watch;
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

/// Kinect v2 tracking ids are large 64-bit numbers; the simulated body's id is this plus its user id.
pub(crate) const KINECT_ID_BASE: u64 = 72_057_594_037_927_936;

/// OSC's "immediately" time tag, which OSCeleton puts on its bundles.
const IMMEDIATELY: OscTime = OscTime {
    seconds: 0,
    fractional: 1,
};

/// Errors of `pavlov human`.
#[derive(Debug, thiserror::Error)]
pub enum SenderError {
    /// The socket could not be opened or a datagram could not be sent.
    #[error("skeleton sender: {0}")]
    Io(#[from] std::io::Error),
    /// A packet could not be encoded.
    #[error("skeleton sender: cannot encode OSC: {0}")]
    Encode(String),
}

/// What `pavlov human` does.
#[derive(Debug, Clone, PartialEq)]
pub struct SenderOptions {
    /// Where the ingest listens.
    pub to: SocketAddr,
    /// The simulated human's seed.
    pub seed: u64,
    /// The wire format.
    pub format: SkeletonFormat,
    /// Pace frames at the sensor's frame rate (30 Hz) on the wall clock; otherwise send them back to back.
    pub realtime: bool,
    /// Stop after this many frames (otherwise run until cancelled).
    pub frames: Option<u64>,
}

/// What was sent.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct SendReport {
    /// Frames sent.
    pub frames: u64,
    /// Datagrams sent.
    pub datagrams: u64,
    /// Datagrams the system refused to send (counted, not fatal: a streamer does not care whether anyone
    /// listens).
    pub send_errors: u64,
    /// Ground-truth commands the human made.
    pub commands: usize,
}

/// An OSC message (also used by the skeleton tests to build packets).
pub fn message(addr: impl Into<String>, args: Vec<OscType>) -> OscPacket {
    OscPacket::Message(OscMessage {
        addr: addr.into(),
        args,
    })
}

/// An OSC bundle with the "immediately" time tag, as OSCeleton sends them.
pub fn bundle(content: Vec<OscPacket>) -> OscPacket {
    OscPacket::Bundle(OscBundle {
        timetag: IMMEDIATELY,
        content,
    })
}

/// OSCeleton's `/joint ,sifff name user x y z`.
pub fn osceleton_joint(name: &str, user: i32, p: [f64; 3]) -> OscPacket {
    message(
        "/joint",
        vec![
            OscType::String(name.into()),
            OscType::Int(user),
            OscType::Float(p[0] as f32),
            OscType::Float(p[1] as f32),
            OscType::Float(p[2] as f32),
        ],
    )
}

/// OSCeleton's start of a session: a bundle of `/new_user` and `/new_skel` for `user`.
pub(crate) fn session_start(user: i32) -> OscPacket {
    bundle(vec![
        message("/new_user", vec![OscType::Int(user)]),
        message("/new_skel", vec![OscType::Int(user)]),
    ])
}

/// OSCeleton's end of a session: `/lost_user` for `user`.
pub(crate) fn session_end(user: i32) -> OscPacket {
    message("/lost_user", vec![OscType::Int(user)])
}

/// The packets (datagrams) of one frame in `format`.
pub(crate) fn frame_packets(frame: &HumanFrame, format: SkeletonFormat) -> Vec<OscPacket> {
    let f = |v: f64| OscType::Float(v as f32);
    match format {
        SkeletonFormat::OsceletonMm | SkeletonFormat::OsceletonNormalized => {
            let joints = frame
                .joints
                .iter()
                .map(|&(joint, pos_mm)| {
                    let p = if format == SkeletonFormat::OsceletonNormalized {
                        mm_to_osceleton_normalized(pos_mm)
                    } else {
                        pos_mm
                    };
                    osceleton_joint(joint.osceleton_name(), frame.user_id, p)
                })
                .collect();
            vec![bundle(joints)]
        }
        SkeletonFormat::KinectV2 => {
            let id = KINECT_ID_BASE.saturating_add_signed(i64::from(frame.user_id));
            frame
                .joints
                .iter()
                .map(|&(joint, p)| {
                    message(
                        format!("/bodies/{id}/joints/{}", joint.kinect_v2_name()),
                        vec![
                            f(p[0] / 1000.0),
                            f(p[1] / 1000.0),
                            f(p[2] / 1000.0),
                            OscType::String("Tracked".into()),
                        ],
                    )
                })
                .collect()
        }
    }
}

fn encode(p: &OscPacket) -> Result<Vec<u8>, SenderError> {
    rosc::encoder::encode(p).map_err(|e| SenderError::Encode(e.to_string()))
}

async fn send(
    socket: &UdpSocket,
    to: SocketAddr,
    p: &OscPacket,
    report: &mut SendReport,
) -> Result<(), SenderError> {
    match socket.send_to(&encode(p)?, to).await {
        Ok(_) => report.datagrams += 1,
        Err(e) => {
            if report.send_errors == 0 {
                tracing::warn!("cannot send skeleton datagrams to {to}: {e}");
            }
            report.send_errors += 1;
        }
    }
    Ok(())
}

/// Runs a [`SimHuman`] and sends its frames to `opts.to` until `opts.frames` are sent or `cancel` fires.
pub async fn send_human(
    opts: SenderOptions,
    cancel: CancellationToken,
) -> Result<SendReport, SenderError> {
    let local: SocketAddr = if opts.to.is_ipv4() {
        ([0, 0, 0, 0], 0).into()
    } else {
        (std::net::Ipv6Addr::UNSPECIFIED, 0).into()
    };
    let socket = UdpSocket::bind(local).await?;
    let mut human = SimHuman::new(HumanParams::default(), opts.seed);
    let user = human.params().user_id;
    let osceleton = opts.format != SkeletonFormat::KinectV2;
    let mut report = SendReport::default();
    if osceleton {
        send(&socket, opts.to, &session_start(user), &mut report).await?;
    }
    let start = Instant::now();
    while opts.frames.is_none_or(|n| report.frames < n) {
        let frame = human.step();
        if opts.realtime {
            let due = start + Duration::from_secs_f64(frame.t_ms.max(0.0) / 1000.0);
            tokio::select! {
                _ = cancel.cancelled() => break,
                _ = tokio::time::sleep_until(due) => {}
            }
        } else if cancel.is_cancelled() {
            break;
        }
        for p in frame_packets(&frame, opts.format) {
            send(&socket, opts.to, &p, &mut report).await?;
        }
        report.frames += 1;
        if !opts.realtime {
            tokio::task::yield_now().await;
        }
    }
    if osceleton {
        send(&socket, opts.to, &session_end(user), &mut report).await?;
    }
    report.commands = human.commands().len();
    Ok(report)
}

/// Steps `human` once per frame period under tokio time (frame `k` at `started + k · period`) and publishes its
/// joints straight into `pose`, stamped in ms since `started` like the UDP ingest does. Returns the human,
/// with its ground-truth [`SimHuman::commands`], when `cancel` fires.
pub async fn drive_pose(
    mut human: SimHuman,
    pose: watch::Sender<PoseTracker>,
    started: Instant,
    cancel: CancellationToken,
) -> SimHuman {
    // One wait for the cancellation, polled again on every pass (not a new one per pass).
    let cancelled = cancel.cancelled();
    tokio::pin!(cancelled);
    loop {
        let frame = human.step();
        let due = started + Duration::from_secs_f64(frame.t_ms.max(0.0) / 1000.0);
        tokio::select! {
            biased;
            _ = &mut cancelled => break,
            _ = tokio::time::sleep_until(due) => {}
        }
        let at_ms = u64::try_from(
            Instant::now()
                .saturating_duration_since(started)
                .as_millis(),
        )
        .unwrap_or(u64::MAX);
        pose.send_modify(|p| {
            for &(joint, pos_mm) in &frame.joints {
                p.update(
                    joint,
                    JointSample {
                        pos_mm,
                        at_ms,
                        confidence: 1.0,
                    },
                );
            }
        });
    }
    human
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pipeline::skeleton_ingest::decode::{DecodeCounts, Decoder, SkeletonEvent};
    use pavlov::skeleton::Joint;

    fn decode_all(packets: &[OscPacket], format: SkeletonFormat) -> Vec<SkeletonEvent> {
        let d = Decoder::new(format, false);
        let mut events = Vec::new();
        let mut counts = DecodeCounts::default();
        for p in packets {
            let bytes = encode(p).unwrap();
            let (_, back) = rosc::decoder::decode_udp(&bytes).unwrap();
            assert!(d.decode(&back, &mut events, &mut counts).is_empty());
        }
        events
    }

    #[test]
    fn every_format_round_trips_through_the_decoder_to_the_same_mm() {
        let mut human = SimHuman::new(HumanParams::default(), 3);
        let frame = human.step();
        assert!(!frame.joints.is_empty());
        for format in [
            SkeletonFormat::OsceletonMm,
            SkeletonFormat::OsceletonNormalized,
            SkeletonFormat::KinectV2,
        ] {
            let packets = frame_packets(&frame, format);
            let events = decode_all(&packets, format);
            assert_eq!(events.len(), frame.joints.len(), "{format:?}");
            for (e, &(joint, pos)) in events.iter().zip(&frame.joints) {
                let SkeletonEvent::Joint {
                    joint: j, pos_mm, ..
                } = *e
                else {
                    panic!("{e:?}")
                };
                assert_eq!(j, joint);
                for k in 0..3 {
                    // f32 on the wire: well under a millimetre at 2.5 m.
                    assert!(
                        (pos_mm[k] - pos[k]).abs() < 0.5,
                        "{format:?} {pos_mm:?} {pos:?}"
                    );
                }
            }
        }
    }

    #[test]
    fn osceleton_session_packets_announce_and_lose_the_user() {
        let events = decode_all(
            &[session_start(4), session_end(4)],
            SkeletonFormat::OsceletonMm,
        );
        assert_eq!(
            events,
            vec![
                SkeletonEvent::NewUser(4),
                SkeletonEvent::NewSkeleton(4),
                SkeletonEvent::LostUser(4)
            ]
        );
    }

    #[tokio::test(start_paused = true)]
    async fn drive_pose_publishes_frames_on_schedule_and_returns_the_human() {
        let (tx, rx) = watch::channel(PoseTracker::new(100));
        let started = Instant::now();
        let cancel = CancellationToken::new();
        let human = SimHuman::new(HumanParams::default(), 7);
        let period = human.frame_period_ms();
        let task = tokio::spawn(drive_pose(human, tx, started, cancel.clone()));
        tokio::time::sleep(Duration::from_millis(990)).await;
        // Frames 0..=29 are due by 990 ms; the newest carries frame 29's time.
        let last = (990.0 / period).floor();
        let newest = Joint::ALL
            .iter()
            .filter_map(|&j| rx.borrow().sample(j).map(|s| s.at_ms))
            .max()
            .unwrap();
        // (tokio's timer rounds deadlines up to whole milliseconds)
        let due = last * period;
        assert!(
            newest as f64 >= due.floor() && newest as f64 <= due.ceil(),
            "{newest} vs {due}"
        );
        cancel.cancel();
        let mut human = task.await.unwrap();
        // One more frame was stepped and left pending at the cancel, so the next is frame last + 2.
        let next = human.step().t_ms;
        assert!((next - (last + 2.0) * period).abs() < 1e-6, "{next}");
    }
}

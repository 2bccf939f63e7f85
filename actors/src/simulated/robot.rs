//! The simulated Create as a running robot: the Create runs [`pavlov::sim::robot::SimRobot`] in its own task and steps it every 15 ms of
//! tokio time, so it works identically under the paused (virtual) clock. It can sit behind an in-process
//! duplex stream (the default for `pavlov serve`) or behind a pseudo-terminal (`pavlov sim --pty`), where
//! any OI client, including `pavlov serve --robot <path>`, drives it over a real serial device.
//!
//! A [`FaultInjector`] sits between the robot and the line (`--faults`): it damages, delays and interleaves
//! the robot's bytes, hangs or unplugs the line, and trips the robot. In process, an unplugged robot keeps
//! running and takes the next connection from its `SimDevice`, which is how link supervision reconnects.

use std::time::Duration;

use futures_util::FutureExt;

use pavlov::sim::faults::{FaultInjector, LinkFault, StepOutcome};
use pavlov::sim::robot::SimRobot;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt, ReadHalf, WriteHalf};
use tokio::sync::{mpsc, watch};
use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

use super::device::{SIM_LINK_BUFFER, SimDevice};
use crate::link::{LinkError, LinkReader, LinkWriter};
pub use crate::telemetry::sim_status::SimStatus;

/// The OI sensor period: the robot steps and streams every 15 ms [C1 p13; C2 p21].
pub(crate) const SIM_STEP: Duration = Duration::from_millis(15);

/// A simulated robot running behind an in-process byte stream.
pub(crate) struct SimLink {
    /// Host side, robot-to-host bytes.
    pub(crate) reader: LinkReader,
    /// Host side, host-to-robot bytes.
    pub(crate) writer: LinkWriter,
    /// The robot's plug: opens a new connection to the same running robot (link supervision uses it to
    /// reconnect after an end-of-file or a hang).
    pub(crate) device: SimDevice,
    /// The simulator task; it returns the robot when the host has closed its link and dropped every
    /// [`SimDevice`], or when `cancel` fires.
    pub(crate) robot: JoinHandle<SimRobot>,
    /// The robot's state after each step.
    pub(crate) status: watch::Receiver<SimStatus>,
}

/// Spawns `robot` behind a tokio duplex stream, with `faults` injected on the line and into the robot.
pub(crate) fn spawn_sim_with_faults(
    mut robot: SimRobot,
    faults: FaultInjector,
    cancel: CancellationToken,
) -> SimLink {
    faults.configure(&mut robot);
    let (device, sockets) = SimDevice::new(robot.model());
    let (host, first) = tokio::io::duplex(SIM_LINK_BUFFER);
    let first = (first, Some(robot.model().baud()));
    let (reader, writer) = tokio::io::split(host);
    let (status_tx, status) = watch::channel(SimStatus::default());
    let handle = tokio::spawn(drive_sim(
        robot,
        Plug {
            first: Some(first),
            more: Some(sockets),
        },
        (faults, status_tx),
        cancel,
        EndOfFile::Stop,
    ));
    SimLink {
        reader: Box::new(reader),
        writer: Box::new(writer),
        device,
        robot: handle,
        status,
    }
}

/// What the simulator does when its host closes the link.
#[derive(Clone, Copy, PartialEq, Eq)]
enum EndOfFile {
    /// Wait for the next connection from the plug, and stop when there can be none.
    Stop,
    /// Keep running on the same stream for the next client (PTY).
    KeepRunning,
}

/// Where the robot's connections come from, each with the rate of the host's side (`None`: not modelled,
/// e.g. a PTY, whose host side sets its rate where the simulator cannot see it).
struct Plug<S> {
    /// The connection the robot starts on.
    first: Option<(S, Option<u32>)>,
    /// Later connections ([`SimDevice::connect_at`]); `None` for a fixed stream.
    more: Option<mpsc::Receiver<(S, u32)>>,
}

impl<S> Plug<S> {
    /// The next connection; `None` when no more can come.
    async fn next(&mut self) -> Option<(S, Option<u32>)> {
        if let Some(s) = self.first.take() {
            return Some(s);
        }
        match &mut self.more {
            Some(rx) => rx.recv().await.map(|(s, baud)| (s, Some(baud))),
            None => None,
        }
    }
}

/// Whether bytes flow on the line in a step with this fault.
fn link_flows(outcome: LinkFault) -> bool {
    matches!(outcome, LinkFault::Normal)
}

/// One 15 ms step of the robot on its line.
pub(crate) struct Stepped {
    /// What the fault injector made of the step's output, and what the line does.
    pub(crate) outcome: StepOutcome,
    /// Whether bytes flow on the line this step (no hang, no unplug).
    pub(crate) flowing: bool,
    /// Whether the host's side runs at the robot's rate (a UART at another rate sees noise).
    pub(crate) rates_match: bool,
}

impl Stepped {
    /// The bytes that reach the host from this step, if any.
    pub(crate) fn to_host(&self) -> Option<&[u8]> {
        (self.flowing && self.rates_match && !self.outcome.bytes.is_empty())
            .then_some(self.outcome.bytes.as_slice())
    }
}

impl Stepped {
    /// Hands this step's buffer back to be sent into again (see [`step_robot`]).
    pub(crate) fn recycle(self, spare: &mut Vec<u8>) {
        *spare = self.outcome.bytes;
    }
}

/// Steps `robot` by 15 ms through `faults`, with the host's side at `host_baud` (`None`: not modelled).
/// The robot sends its next output into `spare` (taken): hand each step's buffer back with
/// [`Stepped::recycle`] and a step allocates nothing once warm (without link faults, whose injector
/// passes the buffer through). The simulator task and the stepped virtual-time driver
/// ([`crate::experiment::stepped`]) both step the robot through it.
pub(crate) fn step_robot(
    robot: &mut SimRobot,
    faults: &mut FaultInjector,
    host_baud: Option<u32>,
    spare: &mut Vec<u8>,
) -> Stepped {
    robot.step();
    let out = robot.swap_output(std::mem::take(spare));
    let outcome = faults.after_step(robot, out);
    let flowing = link_flows(outcome.link);
    Stepped {
        rates_match: host_baud.is_none_or(|b| b == robot.oi_baud()),
        flowing,
        outcome,
    }
}

/// Hands bytes the host sent to `robot` through `faults`; while the line hangs (`flowing` false), or the
/// rates differ, they are lost.
pub(crate) fn host_to_robot(
    robot: &mut SimRobot,
    faults: &mut FaultInjector,
    host_baud: Option<u32>,
    flowing: bool,
    bytes: &[u8],
) {
    if flowing && host_baud.is_none_or(|b| b == robot.oi_baud()) {
        let bytes = faults.host_bytes(bytes);
        robot.receive(&bytes);
    }
}

async fn drive_sim<S>(
    mut robot: SimRobot,
    mut plug: Plug<S>,
    (mut faults, status): (FaultInjector, watch::Sender<SimStatus>),
    cancel: CancellationToken,
    eof: EndOfFile,
) -> SimRobot
where
    S: AsyncRead + AsyncWrite + Unpin,
{
    let mut conn: Option<(ReadHalf<S>, WriteHalf<S>)> = None;
    // The host side's rate; bytes pass only when it equals the robot's (a UART at another rate sees noise).
    let mut host_baud: Option<u32> = None;
    let mut plugged = true;
    let mut step = tokio::time::interval(SIM_STEP);
    let mut buf = vec![0u8; 4096];
    let mut spare = Vec::new();
    let mut reading = true;
    let mut flowing = true;
    // One wait for the cancellation, polled again on every pass (not a new one per pass).
    let cancelled = cancel.cancelled();
    tokio::pin!(cancelled);
    loop {
        tokio::select! {
            biased;
            _ = &mut cancelled => break,
            next = plug.next(), if plugged => match next {
                Some((io, baud)) => {
                    conn = Some(tokio::io::split(io));
                    host_baud = baud;
                    reading = true;
                }
                None => {
                    plugged = false;
                    if conn.is_none() {
                        break;
                    }
                }
            },
            n = read_conn(&mut conn, &mut buf), if reading && conn.is_some() => match n {
                Ok(n) if n > 0 => host_to_robot(&mut robot, &mut faults, host_baud, flowing, &buf[..n]),
                other => {
                    if let Err(e) = other {
                        tracing::debug!("simulator link read: {e}");
                    }
                    match eof {
                        EndOfFile::Stop => {
                            conn = None;
                            if !plugged {
                                break;
                            }
                        }
                        // No client on the PTY right now: poll again on the next step.
                        EndOfFile::KeepRunning => reading = false,
                    }
                }
            },
            _ = step.tick() => {
                reading = true;
                let stepped = step_robot(&mut robot, &mut faults, host_baud, &mut spare);
                flowing = stepped.flowing;
                if stepped.outcome.link == LinkFault::Eof && eof == EndOfFile::Stop {
                    // Unplug: the host reads end-of-file and must reconnect through the device. A PTY
                    // cannot signal end-of-file without destroying the device: it hangs this step instead.
                    conn = None;
                }
                // A UART transmits whether or not anyone listens: when the host is not reading and the
                // buffer is full, the bytes are lost instead of stalling the robot's clock.
                if let Some(bytes) = stepped.to_host()
                    && let Some((_, tx)) = conn.as_mut()
                    && let Some(Err(e)) = tx.write(bytes).now_or_never()
                {
                    tracing::debug!("simulator link write: {e}");
                }
                let baud_mismatch = !stepped.rates_match;
                stepped.recycle(&mut spare);
                let world = robot.world();
                status.send_replace(SimStatus {
                    oi_mode: robot.oi_mode().code(),
                    wheel_speed_mm_s: [world.wheel_speed_mm_s(0), world.wheel_speed_mm_s(1)],
                    connected: conn.is_some(),
                    flowing: flowing && !baud_mismatch,
                    faults: faults.counters().clone(),
                });
            }
        }
    }
    robot
}

async fn read_conn<S: AsyncRead>(
    conn: &mut Option<(ReadHalf<S>, WriteHalf<S>)>,
    buf: &mut [u8],
) -> std::io::Result<usize> {
    match conn {
        Some((rx, _)) => rx.read(buf).await,
        None => std::future::pending().await,
    }
}

/// A simulated robot on a pseudo-terminal: `path` is the device a client opens.
pub struct SimPty {
    /// The slave device path, e.g. `/dev/pts/3`.
    pub path: String,
    /// The simulator task.
    pub robot: JoinHandle<SimRobot>,
    /// The robot's state after each step.
    pub status: watch::Receiver<SimStatus>,
    // Holding the slave open keeps the master readable while no client is attached.
    _slave: tokio_serial::SerialStream,
}

/// Creates a PTY and runs `robot` on its master side, with `faults` injected.
pub fn spawn_sim_pty(
    mut robot: SimRobot,
    faults: FaultInjector,
    cancel: CancellationToken,
) -> Result<SimPty, LinkError> {
    use tokio_serial::SerialPort;
    let (master, slave) = tokio_serial::SerialStream::pair().map_err(LinkError::Pty)?;
    let path = slave.name().unwrap_or_default();
    faults.configure(&mut robot);
    let (status_tx, status) = watch::channel(SimStatus::default());
    let handle = tokio::spawn(drive_sim(
        robot,
        Plug {
            first: Some((master, None)),
            more: None,
        },
        (faults, status_tx),
        cancel,
        EndOfFile::KeepRunning,
    ));
    Ok(SimPty {
        path,
        status,
        robot: handle,
        _slave: slave,
    })
}

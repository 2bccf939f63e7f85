//! Opening the byte stream to the robot: a real serial port, or the simulated Create.
//!
//! The simulated Create runs [`pavlov::sim::robot::SimRobot`] in its own task and steps it every 15 ms of
//! tokio time, so it works identically under the paused (virtual) clock. It can sit behind an in-process
//! duplex stream (the default for `pavlov serve`) or behind a pseudo-terminal (`pavlov sim --pty`), where
//! any OI client, including `pavlov serve --robot <path>`, drives it over a real serial device.

use std::time::Duration;

use futures_util::FutureExt;

use pavlov::oi::Model;
use pavlov::sim::robot::SimRobot;
use tokio::io::{AsyncRead, AsyncReadExt, AsyncWrite, AsyncWriteExt};
use tokio::task::JoinHandle;
use tokio_serial::{DataBits, FlowControl, Parity, SerialPortBuilderExt, StopBits};
use tokio_util::sync::CancellationToken;

use super::{LinkError, LinkReader, LinkWriter};

/// The OI sensor period: the robot steps and streams every 15 ms [C1 p13; C2 p21].
pub const SIM_STEP: Duration = Duration::from_millis(15);

/// Opens `path` raw 8N1, no flow control, at the model's baud.
pub fn open_serial(path: &str, model: Model) -> Result<(LinkReader, LinkWriter), LinkError> {
    let port = tokio_serial::new(path, model.baud())
        .data_bits(DataBits::Eight)
        .parity(Parity::None)
        .stop_bits(StopBits::One)
        .flow_control(FlowControl::None)
        .open_native_async()
        .map_err(|source| LinkError::Open {
            path: path.to_string(),
            source,
        })?;
    let (r, w) = tokio::io::split(port);
    Ok((Box::new(r), Box::new(w)))
}

/// A simulated robot running behind an in-process byte stream.
pub struct SimLink {
    /// Host side, robot-to-host bytes.
    pub reader: LinkReader,
    /// Host side, host-to-robot bytes.
    pub writer: LinkWriter,
    /// The simulator task; it returns the robot when the host closes its writer or `cancel` fires.
    pub robot: JoinHandle<SimRobot>,
}

/// Spawns `robot` behind a tokio duplex stream.
pub fn spawn_sim(robot: SimRobot, cancel: CancellationToken) -> SimLink {
    let (host, device) = tokio::io::duplex(64 * 1024);
    let (reader, writer) = tokio::io::split(host);
    let handle = tokio::spawn(run_sim(robot, device, cancel));
    SimLink {
        reader: Box::new(reader),
        writer: Box::new(writer),
        robot: handle,
    }
}

/// Runs `robot` on `io`: command bytes in, stream frames out, one world step every 15 ms.
///
/// It stops when the host side reaches end-of-file (after the host's shut-down sequence has been applied)
/// or when `cancel` fires, and hands the robot back so callers can inspect the final physical state.
pub async fn run_sim<S>(robot: SimRobot, io: S, cancel: CancellationToken) -> SimRobot
where
    S: AsyncRead + AsyncWrite + Unpin,
{
    drive_sim(robot, io, cancel, EndOfFile::Stop).await
}

/// What the simulator does when its host closes the link.
#[derive(Clone, Copy, PartialEq, Eq)]
enum EndOfFile {
    /// Stop and hand the robot back (in-process link).
    Stop,
    /// Keep running for the next client (PTY).
    KeepRunning,
}

async fn drive_sim<S>(
    mut robot: SimRobot,
    io: S,
    cancel: CancellationToken,
    eof: EndOfFile,
) -> SimRobot
where
    S: AsyncRead + AsyncWrite + Unpin,
{
    let (mut rx, mut tx) = tokio::io::split(io);
    let mut step = tokio::time::interval(SIM_STEP);
    let mut buf = vec![0u8; 4096];
    let mut reading = true;
    loop {
        tokio::select! {
            biased;
            _ = cancel.cancelled() => break,
            n = rx.read(&mut buf), if reading => match n {
                Ok(0) if eof == EndOfFile::Stop => break,
                Ok(0) => {
                    // No client on the PTY right now: poll again on the next step.
                    reading = false;
                }
                Ok(n) => robot.receive(&buf[..n]),
                Err(e) => {
                    if eof == EndOfFile::Stop {
                        tracing::debug!("simulator link read: {e}");
                        break;
                    }
                    reading = false;
                }
            },
            _ = step.tick() => {
                reading = true;
                robot.step();
                let out = robot.take_output();
                // A UART transmits whether or not anyone listens: when the host is not reading and the
                // buffer is full, the bytes are lost instead of stalling the robot's clock.
                if !out.is_empty() {
                    if let Some(Err(e)) = tx.write(&out).now_or_never() {
                        tracing::debug!("simulator link write: {e}");
                    }
                }
            }
        }
    }
    robot
}

/// A simulated robot on a pseudo-terminal: `path` is the device a client opens.
pub struct SimPty {
    /// The slave device path, e.g. `/dev/pts/3`.
    pub path: String,
    /// The simulator task.
    pub robot: JoinHandle<SimRobot>,
    // Holding the slave open keeps the master readable while no client is attached.
    _slave: tokio_serial::SerialStream,
}

/// Creates a PTY and runs `robot` on its master side.
pub fn spawn_sim_pty(robot: SimRobot, cancel: CancellationToken) -> Result<SimPty, LinkError> {
    use tokio_serial::SerialPort;
    let (master, slave) = tokio_serial::SerialStream::pair().map_err(LinkError::Pty)?;
    let path = slave.name().unwrap_or_default();
    let handle = tokio::spawn(run_sim_pty(robot, master, cancel));
    Ok(SimPty {
        path,
        robot: handle,
        _slave: slave,
    })
}

/// Like [`run_sim`], but a client closing the device is not the end: the robot keeps running and the
/// next client that opens the device picks up where the last left off.
async fn run_sim_pty(
    robot: SimRobot,
    io: tokio_serial::SerialStream,
    cancel: CancellationToken,
) -> SimRobot {
    drive_sim(robot, io, cancel, EndOfFile::KeepRunning).await
}

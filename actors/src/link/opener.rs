//! Reopening the robot link: the supervisor closes a dead or silent port and opens it again through a
//! [`LinkOpener`], so the same code reconnects a USB/Bluetooth serial device and the simulated Create.
//!
//! - [`SerialOpener`]: opens the serial device path again (raw 8N1 at the model's baud).
//! - [`SimDevice`]: a new in-process connection to the running simulated robot, as if its cable had been
//!   unplugged and plugged back in; the robot itself keeps running in between.
//!
//! Both can also run a **baud rescue**: a damaged byte on the way to the robot can form a Baud command and
//! move the robot to another rate, where the host can no longer reach it. The rescue opens the port at
//! every other rate in turn and sends Baud with the model's default code, waiting 100 ms after each
//! [C1 p7; C2 p9]; at the robot's rate this brings it back, at the others it is line noise the robot drops.

use std::time::Duration;

use futures_util::future::BoxFuture;
use pavlov::oi::Model;
use pavlov::oi::command::Command;
use pavlov::oi::model::BAUD_RATES;
use tokio::io::AsyncWriteExt;
use tokio::io::DuplexStream;
use tokio::sync::mpsc;

use super::{LinkError, LinkReader, LinkWriter, transport};
use tokio_serial::SerialPortBuilderExt;

/// Something that can open the link (again).
pub trait LinkOpener: Send {
    /// Opens a fresh link. The future must not borrow `self`, so that it can run in its own task.
    fn open(&mut self) -> BoxFuture<'static, Result<(LinkReader, LinkWriter), LinkError>>;
    /// A short description for logs.
    fn describe(&self) -> String;
    /// Sends Baud (the model's default) at every other rate; see the module doc.
    fn rescue_baud(&mut self) -> BoxFuture<'static, ()>;
}

/// The robot needs 100 ms after a Baud command before it talks at the new rate [C1 p7; C2 p9].
const AFTER_BAUD: Duration = Duration::from_millis(110);

/// The rescue's rates: every Baud rate but `model`'s default, the documented fallback (19200) first.
fn rescue_rates(model: Model) -> impl Iterator<Item = u32> {
    let fallback = 19_200;
    std::iter::once(fallback)
        .chain(BAUD_RATES.into_iter().rev().filter(move |&r| r != fallback))
        .filter(move |&r| r != model.baud())
}

/// The Baud command that returns `model` to its default rate.
fn baud_back(model: Model) -> Vec<u8> {
    let code = pavlov::oi::model::baud_code(model.baud()).unwrap_or(10);
    Command::Baud(code).encode(model).unwrap_or_default()
}

/// Reopens a serial device.
pub struct SerialOpener {
    path: String,
    model: Model,
}

impl SerialOpener {
    /// An opener for `path` at `model`'s baud.
    pub fn new(path: impl Into<String>, model: Model) -> Self {
        SerialOpener {
            path: path.into(),
            model,
        }
    }
}

impl LinkOpener for SerialOpener {
    fn open(&mut self) -> BoxFuture<'static, Result<(LinkReader, LinkWriter), LinkError>> {
        let (path, model) = (self.path.clone(), self.model);
        Box::pin(async move { transport::open_serial(&path, model) })
    }

    fn describe(&self) -> String {
        format!("serial port {}", self.path)
    }

    fn rescue_baud(&mut self) -> BoxFuture<'static, ()> {
        let (path, model) = (self.path.clone(), self.model);
        Box::pin(async move {
            for rate in rescue_rates(model) {
                let port = tokio_serial::new(&path, rate)
                    .flow_control(tokio_serial::FlowControl::None)
                    .open_native_async();
                match port {
                    Ok(mut port) => {
                        let _ = port.write_all(&baud_back(model)).await;
                        let _ = port.flush().await;
                        // Closing may drop bytes still in the driver's buffer: wait for them to leave first.
                        tokio::time::sleep(AFTER_BAUD).await;
                    }
                    Err(e) => {
                        tracing::debug!("baud rescue: cannot open {path} at {rate}: {e}");
                        return;
                    }
                }
            }
        })
    }
}

/// Capacity of each in-process connection, bytes each way (about 11 s of Create 2 stream frames).
pub const SIM_LINK_BUFFER: usize = 64 * 1024;

/// A connection plugged into the simulated robot, with the rate the host's side runs at.
pub type SimSocket = (DuplexStream, u32);

/// The plug of the in-process simulated Create: every [`SimDevice::connect`] hands the robot a new
/// connection and drops the old one. Bytes pass only while the host's rate equals the robot's.
#[derive(Clone)]
pub struct SimDevice {
    plug: mpsc::Sender<SimSocket>,
    model: Model,
}

impl SimDevice {
    /// A device for a robot of `model` and the receiver the simulator task takes its connections from.
    pub fn new(model: Model) -> (SimDevice, mpsc::Receiver<SimSocket>) {
        let (plug, sockets) = mpsc::channel(4);
        (SimDevice { plug, model }, sockets)
    }

    /// Opens a new connection to the robot at the model's default rate.
    pub fn connect(&self) -> Result<(LinkReader, LinkWriter), LinkError> {
        self.connect_at(self.model.baud())
    }

    /// Opens a new connection to the robot with the host's side at `baud`.
    pub fn connect_at(&self, baud: u32) -> Result<(LinkReader, LinkWriter), LinkError> {
        let (host, device) = tokio::io::duplex(SIM_LINK_BUFFER);
        self.plug.try_send((device, baud)).map_err(|_| {
            LinkError::Io(std::io::Error::new(
                std::io::ErrorKind::NotConnected,
                "the simulated robot is not running",
            ))
        })?;
        let (r, w) = tokio::io::split(host);
        Ok((Box::new(r), Box::new(w)))
    }
}

impl LinkOpener for SimDevice {
    fn open(&mut self) -> BoxFuture<'static, Result<(LinkReader, LinkWriter), LinkError>> {
        // Connect when the future runs: after the old port is closed and any baud rescue is done.
        let device = self.clone();
        Box::pin(async move { device.connect() })
    }

    fn describe(&self) -> String {
        "the simulated Create".into()
    }

    fn rescue_baud(&mut self) -> BoxFuture<'static, ()> {
        let device = self.clone();
        Box::pin(async move {
            for rate in rescue_rates(device.model) {
                let Ok((reader, mut writer)) = device.connect_at(rate) else {
                    return;
                };
                let _ = writer.write_all(&baud_back(device.model)).await;
                let _ = writer.flush().await;
                tokio::time::sleep(AFTER_BAUD).await;
                drop((reader, writer));
            }
        })
    }
}

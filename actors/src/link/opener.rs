//! Reopening the robot link: the supervisor closes a dead or silent port and opens it again through a
//! [`LinkOpener`], so the same code reconnects a USB/Bluetooth serial device and the simulated Create.
//!
//! - [`SerialOpener`]: opens the serial device path again (raw 8N1 at the model's baud).
//! - [`SimDevice`]: a new in-process connection to the running simulated robot, as if its cable had been
//!   unplugged and plugged back in; the robot itself keeps running in between.

use futures_util::future::BoxFuture;
use pavlov::oi::Model;
use tokio::io::DuplexStream;
use tokio::sync::mpsc;

use super::{LinkError, LinkReader, LinkWriter, transport};

/// Something that can open the link (again).
pub trait LinkOpener: Send {
    /// Opens a fresh link. The future must not borrow `self`, so that it can run in its own task.
    fn open(&mut self) -> BoxFuture<'static, Result<(LinkReader, LinkWriter), LinkError>>;
    /// A short description for logs.
    fn describe(&self) -> String;
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
}

/// Capacity of each in-process connection, bytes each way (about 11 s of Create 2 stream frames).
pub const SIM_LINK_BUFFER: usize = 64 * 1024;

/// The plug of the in-process simulated Create: every [`SimDevice::connect`] hands the robot a new
/// connection and drops the old one.
#[derive(Clone)]
pub struct SimDevice {
    plug: mpsc::Sender<DuplexStream>,
}

impl SimDevice {
    /// A device and the receiver the simulator task takes its connections from.
    pub fn new() -> (SimDevice, mpsc::Receiver<DuplexStream>) {
        let (plug, sockets) = mpsc::channel(4);
        (SimDevice { plug }, sockets)
    }

    /// Opens a new connection to the robot.
    pub fn connect(&self) -> Result<(LinkReader, LinkWriter), LinkError> {
        let (host, device) = tokio::io::duplex(SIM_LINK_BUFFER);
        self.plug.try_send(device).map_err(|_| {
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
        let result = self.connect();
        Box::pin(async move { result })
    }

    fn describe(&self) -> String {
        "the simulated Create".into()
    }
}

//! The plug of the in-process simulated Create: each [`SimDevice::connect`] hands the running robot a new
//! connection, as if its cable had been unplugged and plugged back in; the robot itself keeps running in
//! between. Link supervision reconnects through it exactly as it reopens a serial port.

use futures_util::future::BoxFuture;
use pavlov::oi::Model;
use pavlov::oi::handshake::baud_back_bytes;
use tokio::io::{AsyncWriteExt, DuplexStream};
use tokio::sync::mpsc;

use crate::link::opener::{AFTER_BAUD, LinkOpener};
use crate::link::{LinkError, LinkReader, LinkWriter};

/// Capacity of each in-process connection, bytes each way (about 11 s of Create 2 stream frames).
pub(crate) const SIM_LINK_BUFFER: usize = 64 * 1024;

/// A connection plugged into the simulated robot, with the rate the host's side runs at.
pub(crate) type SimSocket = (DuplexStream, u32);

/// The plug of the in-process simulated Create: every [`SimDevice::connect`] hands the robot a new
/// connection and drops the old one. Bytes pass only while the host's rate equals the robot's.
#[derive(Clone)]
pub(crate) struct SimDevice {
    plug: mpsc::Sender<SimSocket>,
    model: Model,
}

impl SimDevice {
    /// A device for a robot of `model` and the receiver the simulator task takes its connections from.
    pub(crate) fn new(model: Model) -> (SimDevice, mpsc::Receiver<SimSocket>) {
        let (plug, sockets) = mpsc::channel(4);
        (SimDevice { plug, model }, sockets)
    }

    /// Opens a new connection to the robot at the model's default rate.
    pub(crate) fn connect(&self) -> Result<(LinkReader, LinkWriter), LinkError> {
        self.connect_at(self.model.baud())
    }

    /// Opens a new connection to the robot with the host's side at `baud`.
    pub(crate) fn connect_at(&self, baud: u32) -> Result<(LinkReader, LinkWriter), LinkError> {
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

    fn rescue_baud(&mut self, rates: Vec<u32>) -> BoxFuture<'static, ()> {
        let device = self.clone();
        Box::pin(async move {
            for rate in rates {
                let Ok((reader, mut writer)) = device.connect_at(rate) else {
                    return;
                };
                let _ = writer.write_all(&baud_back_bytes(device.model)).await;
                let _ = writer.flush().await;
                tokio::time::sleep(AFTER_BAUD).await;
                drop((reader, writer));
            }
        })
    }
}

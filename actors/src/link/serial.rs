//! The serial port to a real Create (or to `pavlov sim --pty`): opened raw 8N1 without flow control at the
//! model's baud [C1 p5; C2 p4], and reopened the same way by link supervision.

use futures_util::future::BoxFuture;
use pavlov::oi::Model;
use pavlov::oi::handshake::baud_back_bytes;
use tokio::io::AsyncWriteExt;
use tokio_serial::{DataBits, FlowControl, Parity, SerialPortBuilderExt, StopBits};

use super::opener::{AFTER_BAUD, LinkOpener};
use super::{LinkError, LinkReader, LinkWriter};

/// Opens `path` raw 8N1, no flow control, at the model's baud.
pub(crate) fn open_serial(path: &str, model: Model) -> Result<(LinkReader, LinkWriter), LinkError> {
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

/// Reopens a serial device.
pub(crate) struct SerialOpener {
    path: String,
    model: Model,
}

impl SerialOpener {
    /// An opener for `path` at `model`'s baud.
    pub(crate) fn new(path: impl Into<String>, model: Model) -> Self {
        SerialOpener {
            path: path.into(),
            model,
        }
    }
}

impl LinkOpener for SerialOpener {
    fn open(&mut self) -> BoxFuture<'static, Result<(LinkReader, LinkWriter), LinkError>> {
        let (path, model) = (self.path.clone(), self.model);
        Box::pin(async move { open_serial(&path, model) })
    }

    fn describe(&self) -> String {
        format!("serial port {}", self.path)
    }

    fn rescue_baud(&mut self, rates: Vec<u32>) -> BoxFuture<'static, ()> {
        let (path, model) = (self.path.clone(), self.model);
        Box::pin(async move {
            for rate in rates {
                let port = tokio_serial::new(&path, rate)
                    .flow_control(tokio_serial::FlowControl::None)
                    .open_native_async();
                match port {
                    Ok(mut port) => {
                        let _ = port.write_all(&baud_back_bytes(model)).await;
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

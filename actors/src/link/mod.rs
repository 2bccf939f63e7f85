//! The robot link: the byte stream to an iRobot Create, real (tokio-serial) or simulated, its writer and
//! its supervision. The byte sequences spoken over it are the core's (`pavlov::oi::handshake`).
//!
//! - `serial`: opening (and reopening) a serial port.
//! - `writer`: the writer actor, the only task that writes to the robot.
//! - `opener`: what link supervision reopens a port through, with the baud rescue.
//! - `supervisor`: stale-stream detection, re-sync, reconnect with backoff, trips (see `pavlov::supervision`).

pub(crate) mod opener;
pub(crate) mod serial;
pub(crate) mod supervisor;
pub(crate) mod writer;

use tokio::io::{AsyncRead, AsyncWrite};

/// The robot-to-host half of a link.
pub(crate) type LinkReader = Box<dyn AsyncRead + Send + Unpin>;
/// The host-to-robot half of a link.
pub(crate) type LinkWriter = Box<dyn AsyncWrite + Send + Unpin>;

/// An open link and, when it can be reopened, how.
pub struct OpenLink {
    /// The robot-to-host half.
    pub reader: LinkReader,
    /// The host-to-robot half.
    pub writer: LinkWriter,
    /// Reopens the link after it died (`None`: it cannot be reopened; supervision re-syncs instead).
    pub opener: Option<Box<dyn opener::LinkOpener>>,
}

/// Errors of the robot link.
#[derive(Debug, thiserror::Error)]
pub enum LinkError {
    /// The serial port could not be opened or configured.
    #[error("cannot open serial port {path}: {source}")]
    Open {
        /// The device path.
        path: String,
        /// The driver's error.
        source: tokio_serial::Error,
    },
    /// The stream request does not fit or is invalid.
    #[error("invalid sensor stream request: {0}")]
    Stream(#[from] pavlov::oi::OiError),
    /// An I/O error on the link.
    #[error("robot link I/O error: {0}")]
    Io(#[from] std::io::Error),
    /// A PTY could not be created.
    #[error("cannot create a pseudo-terminal: {0}")]
    Pty(tokio_serial::Error),
}

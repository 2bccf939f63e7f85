//! Reopening the robot link: the supervisor closes a dead or silent port and opens it again through a
//! [`LinkOpener`], so the same code reconnects a USB/Bluetooth serial device
//! ([`super::serial::SerialOpener`]) and the simulated Create ([`crate::simulated::device::SimDevice`]).
//!
//! Both can also run a **baud rescue**: a damaged byte on the way to the robot can form a Baud command and
//! move the robot to another rate, where the host can no longer reach it. A rescue opens the port at a
//! few other rates in turn and sends Baud with the model's default code, waiting 100 ms after each
//! [C1 p7; C2 p9]; at the robot's rate this brings it back, at the others it is line noise the robot drops.
//! Which rates, and how many at once (two, so the port is never left unread for much more than 200 ms),
//! is the core's decision ([`pavlov::oi::handshake::baud_rescue_batch`]).

use std::time::Duration;

use futures_util::future::BoxFuture;

use super::{LinkError, LinkReader, LinkWriter};

/// Something that can open the link (again).
pub trait LinkOpener: Send {
    /// Opens a fresh link. The future must not borrow `self`, so that it can run in its own task.
    fn open(&mut self) -> BoxFuture<'static, Result<(LinkReader, LinkWriter), LinkError>>;
    /// A short description for logs.
    fn describe(&self) -> String;
    /// Sends Baud (the model's default) at each of `rates`; see the module doc.
    fn rescue_baud(&mut self, rates: Vec<u32>) -> BoxFuture<'static, ()>;
}

/// The robot needs 100 ms after a Baud command before it talks at the new rate [C1 p7; C2 p9].
pub(crate) const AFTER_BAUD: Duration = Duration::from_millis(110);

//! The parts that stand in for hardware nobody has here: the simulated Create behind an in-process byte
//! stream or a pseudo-terminal, and the simulated human operator streaming real OSC skeleton packets.
//! They speak the same bytes the real devices do, so everything else runs unchanged.
//!
//! - [`robot`]: the simulator task (one world step every 15 ms), on a duplex stream or a PTY, with faults.
//! - `device`: `device::SimDevice`, the robot's plug, through which link supervision reconnects.
//! - [`human`]: the simulated operator as a UDP skeleton streamer, or straight into a pose channel.

pub(crate) mod device;
pub mod human;
pub mod robot;

pub use robot::SimStatus;

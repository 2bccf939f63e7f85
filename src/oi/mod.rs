//! The iRobot Create Open Interface (OI), Create 1 and Create 2, as pure data and functions.
//!
//! - [`model`]: the robot models, their names, and [`Model::spec`].
//! - [`spec`]: [`ModelSpec`], the one table of everything that differs between the models (baud, packets
//!   and groups, stream budget, opcodes, command ranges, capabilities), one `const` entry per model.
//! - [`sensors`]: [`SensorValues`], a snapshot of raw packet values indexed by packet id.
//! - [`events`]: the event bits (over-currents, bumps, wheel drops, cliffs) OR-ed over the frames between ticks.
//! - [`error`]: [`OiError`], what can be wrong with a packet id, value, command or stream request.
//! - [`packets`]: the table of sensor packets 7–58 and groups, and their byte encoding.
//! - [`command`]: host-to-robot commands, encoded and parsed per model.
//! - [`frame`]: stream frames (header 19, length, id/data pairs, checksum).
//! - [`parser`]: the incremental, resynchronising stream parser.
//! - [`plausible`]: the documented value ranges that reveal a damaged frame with a valid checksum.
//! - [`mode`]: the OI modes (packet 35 codes; Safe or Full to drive in).
//! - [`handshake`]: the byte sequences of start-up, re-sync, re-arm and shut-down.
//!
//! Facts: the two OI specifications, cited as \[C1\] (Create 1) and \[C2\] (Create 2) with their page numbers
//! (`docs/SOURCES.md`).

pub mod command;
pub mod error;
pub mod events;
pub mod frame;
pub mod handshake;
pub mod mode;
pub mod model;
pub mod packets;
pub mod parser;
pub mod plausible;
pub mod sensors;
pub mod spec;

pub use error::OiError;
pub use model::Model;
pub use sensors::SensorValues;
pub use spec::ModelSpec;

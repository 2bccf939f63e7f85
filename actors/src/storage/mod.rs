//! What the server keeps on disk, always off the tick path: recordings of every tick, their reader and
//! replay, and the learned weights' checkpoints.
//!
//! - [`recorder`]: writes the tick feed on its own thread; [`recording`]: the format and its reader;
//!   [`replay`]: runs a recording back through the core and checks it is reproduced exactly.
//! - [`checkpoint_files`]: per-run automatic checkpoints, saves, pruning, and finding one to resume.
//! - [`horde_file`]: the Horde's checkpoints, weights written as they are in memory, through a
//!   `paced_file` that reaches the disk a few megabytes at a time.
//! - `names`: the plain names clients give saves and recordings; `utc`: time stamps for names on disk.

pub mod checkpoint_files;
pub mod horde_file;
pub(crate) mod names;
pub(crate) mod paced_file;
pub mod recorder;
pub mod recording;
pub mod replay;
pub(crate) mod utc;

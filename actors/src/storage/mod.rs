//! What the server keeps on disk, always off the tick path: recordings of every tick, their reader and
//! replay, and the learned weights' checkpoints.
//!
//! - [`recorder`]: writes the tick feed on its own thread; [`recording`]: the format and its reader;
//!   [`replay`]: runs a recording back through the core and checks it is reproduced exactly.
//! - [`checkpoint_files`]: atomic checkpoint files, pruning, and finding one to resume from.

pub mod checkpoint_files;
pub mod recorder;
pub mod recording;
pub mod replay;

//! Checkpoint files on disk: one folder per server run for the automatic checkpoints, a folder of
//! saves, atomic writes off the tick path, pruning that touches only the current run, and finding the
//! newest valid checkpoint for `--resume`.
//!
//! - [`layout`]: where files go (`runs/<run id>/`, `saved/`, the flat files of earlier versions),
//!   atomic writes, pruning;
//! - `saves`: `save_weights`' names, its never-overwrite rule and its quota;
//! - [`resume`]: candidates across runs, newest first, each checked, with the reasons for those skipped;
//! - `writer`: the thread that writes them;
//! - `policy`: a run's policy, for the learning actor: its folder, when a checkpoint is due, what a save
//!   is called, when the writer starts.

pub mod layout;
pub(crate) mod policy;
pub mod resume;
pub(crate) mod saves;
pub(crate) mod writer;

pub use layout::{RUNS_DIR, SAVED_DIR, list, write_atomic};
pub(crate) use policy::CheckpointFiles;
pub use resume::{
    Candidate, ResumeError, Resumed, SkipReason, Skipped, candidates, load_checked,
    load_for_resume, resume_file, resume_newest,
};
pub(crate) use writer::{Announce, SaveJob};

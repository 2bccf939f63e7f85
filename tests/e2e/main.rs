//! The end-to-end tests: the whole server over real sockets, a real PTY and a real browser, one module per
//! area. The 24-simulated-hour soak is its own binary (`tests/soak.rs`), run in release by `tests/run.sh`.

mod cli;
mod common;
mod dashboard;
mod docs;
mod experiment;
#[cfg(feature = "zenoh")]
mod fleet;
mod foxglove;
mod foxglove_spec;
mod horde;
mod house;
mod runtime;
mod skeleton;
mod storage;

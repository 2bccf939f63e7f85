//! # pavlov-actors — the lab server's async shell
//!
//! Independent tokio tasks that own their state and talk over channels, each a thin shell over the pure
//! core in the `pavlov` crate. One folder per concern (see `ARCHITECTURE.md`):
//!
//! - [`server`]: starts a server run (link, pipeline, recorder, skeleton) and stops it in a safe order;
//! - [`bus`]: the event log, the tick feed and the recorder's queue, beneath every actor that uses them;
//! - [`command`]: the command vocabulary;
//! - [`pipeline`]: the tick graph (ticker, sensor and skeleton ingest, learning, gating, actuation, feed);
//! - [`horde`]: `[horde]`'s predictions, learned on a thread of their own, off the control path;
//! - [`link`]: the serial link, its writer and its supervision;
//! - [`simulated`]: the simulated Create and the simulated human;
//! - [`dashboard`]: HTTP, the websocket and its protocol;
//! - [`foxglove`]: the tick stream and events, live over the Foxglove WebSocket protocol (`--foxglove`);
//! - [`telemetry`]: tick health, histograms, Prometheus;
//! - [`storage`]: recordings, replay, checkpoint files;
//! - [`experiment`]: the paper's experiments on the real runtime under virtual time;
//! - [`mod@bench`]: the real-time benchmark and its load and abuse clients.

pub mod bench;
pub mod bus;
pub mod command;
pub mod dashboard;
pub mod experiment;
#[cfg(feature = "zenoh")]
pub mod fleet;
pub mod foxglove;
pub mod horde;
pub mod link;
pub mod pipeline;
pub mod provenance;
pub mod server;
pub mod simulated;
pub mod storage;
pub mod telemetry;
#[cfg(feature = "zenoh")]
pub mod zenoh_bridge;

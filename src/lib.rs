//! # pavlov — the pure core of a Pavlovian-control lab server
//!
//! Everything in this crate is synchronous and deterministic: no async runtime, no sockets, no clocks,
//! no threads. The runtime in `actors/` is a thin async shell that moves data between channels and calls
//! into these modules once per 20 ms tick.
//!
//! - [`checkpoint`]: lifelong checkpoints, the learned state with the configuration it belongs to (above
//!   both [`learn`] and [`config`], which it names).
//! - [`agent`]: the per-tick learning and gating stages that the runtime, replay and experiments share.
//! - [`analysis`]: what a run means: run counters, interaction timing, statistics.
//! - [`config`]: the TOML configuration, validated with errors that name the key.
//! - [`oi`]: the iRobot Create 1 / Create 2 Open Interface: commands, the sensor-packet table, the stream parser.
//! - [`obs`]: a sensor snapshot as a named observation vector scaled to `[0, 1]`.
//! - [`learn`]: tile coding and TD(λ) predictions (Modayil & Sutton, "Prediction Driven Behavior").
//! - [`control`]: stimulus detectors, the mixing function and gate, default policies and fixed responses.
//! - [`skeleton`]: joints, elbow angles and their smoothing, for the gesture-command experiment.
//! - [`sim`]: a byte-exact simulated Create and a simulated human operator.
//! - [`record`]: [`record::TickRecord`], everything that happened on one tick.
//! - [`event`]: [`event::Event`], a change made at run time (a command, a link change), as data.
//! - [`supervision`]: the robot link's state machine: stale stream, re-sync, reconnect, Safe-mode trips.
//! - [`rng`]: the seeded random-number generator every stochastic part of the core draws from.

pub mod agent;
pub mod analysis;
pub mod checkpoint;
pub mod config;
pub mod control;
pub mod event;
pub mod learn;
pub mod obs;
pub mod oi;
pub mod record;
pub mod rng;
pub mod sim;
pub mod skeleton;
pub mod supervision;

//! # pavlov-actors — the lab server's async shell
//!
//! Independent tokio tasks that own their state and talk over channels, each a thin shell over the pure
//! core in the `pavlov` crate: the [`ticker`] (20 ms), [`sensor_ingest`] (robot bytes → observation),
//! [`skeleton_ingest`] (pose), [`learning`], [`gating`], [`actuation`] and the [`link`] writer; the
//! [`feed`] of tick records; the [`command`] router; and [`server`], which wires them together.

pub mod actuation;
pub mod bench;
pub mod checkpoint;
pub mod command;
pub mod experiment;
pub mod feed;
pub mod gating;
pub mod histogram;
pub mod human_sender;
pub mod learning;
pub mod link;
pub mod recorder;
pub mod recording;
pub mod replay;
pub mod sensor_ingest;
pub mod server;
pub mod skeleton_ingest;
pub mod ticker;
pub mod ws;

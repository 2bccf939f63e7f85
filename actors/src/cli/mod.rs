//! The command line: one module per command, each with its clap arguments and its entry point.
//!
//! The arguments' doc comments are clap's `--help` text, written for a terminal: `[robot] model` names a
//! configuration section and `results/<seed>` holds a placeholder; rustdoc is told not to read them as
//! links or HTML, so the help stays as the user reads it.
#![allow(rustdoc::broken_intra_doc_links, rustdoc::invalid_html_tags)]

pub mod args;
pub mod bench;
pub mod convert;
pub mod experiment;
pub mod fleet;

/// What `--zenoh` and `pavlov fleet` say in a binary built without the `zenoh` feature.
#[cfg(not(feature = "zenoh"))]
pub(crate) const NO_ZENOH: &str = "this pavlov was built without Zenoh: build it with the `zenoh` feature \
     (`cargo install --path actors --features zenoh`, or `cargo run --release --features zenoh -- …`)";
pub mod human;
pub mod replay;
pub mod serve;
pub mod sim;

use std::sync::LazyLock;

use clap::{Parser, Subcommand};

/// `pavlov --version`: the version, the commit and dirty flag, features, compiler, target and profile.
static LONG_VERSION: LazyLock<String> =
    LazyLock::new(|| pavlov_actors::provenance::BUILD.long_version());

/// `pavlov`.
#[derive(Parser)]
#[command(
    name = "pavlov",
    version = pavlov_actors::provenance::BUILD.version,
    long_version = LONG_VERSION.as_str(),
    about = "Pavlovian control of an iRobot Create: online TD(λ) predictions driving fixed responses",
    long_about = "A lab server that runs Pavlovian control (Modayil & Sutton, \"Prediction Driven Behavior\") on an \
iRobot Create 1 or 2: every 20 ms it reads the robot's sensors, learns TD(λ) predictions online, and lets a fixed \
response take over from the default policy when a prediction crosses its threshold. Without --robot it drives a \
simulated Create that speaks the real Open Interface bytes.\n\nLogging: set RUST_LOG (e.g. RUST_LOG=debug or \
RUST_LOG=pavlov_actors=trace); the default is info."
)]
pub struct Cli {
    /// The command.
    #[command(subcommand)]
    pub command: Command,
}

/// The commands.
#[derive(Subcommand)]
pub enum Command {
    /// Run the server. Without --robot it drives the simulated Create in process.
    Serve(serve::ServeArgs),
    /// Reproduce the paper's experiments on the simulated Create (e.g. `pavlov experiment stall --seed 1`).
    Experiment(experiment::ExperimentArgs),
    /// Run a recording back through the learning and gating stages and check that it reproduces exactly.
    Replay(replay::ReplayArgs),
    /// Rewrite a recording in the other format: `--to jsonl` (for jq and pandas) or `--to mcap`.
    Convert(convert::ConvertArgs),
    /// Run the simulated Create on its own, on a pseudo-terminal that any OI client can open.
    Sim(sim::SimArgs),
    /// Run the simulated human operator and stream its skeleton as OSC over UDP (what a depth sensor with
    /// OSCeleton or KinectV2-OSC would send), e.g. to a `pavlov serve` running the interaction experiment.
    Human(human::HumanArgs),
    /// Benchmark: run the server on the simulator in real time and print tick lateness and
    /// tick-to-command latency percentiles, optionally with websocket clients and abusers attached.
    Bench(bench::BenchArgs),
    /// One dashboard page for a lab's robots: subscribes to pavlov/v1/*/… on Zenoh (what `serve --zenoh`
    /// publishes) and lists each robot's mode, link, tick health and counters, linking to its dashboard.
    #[cfg_attr(
        not(feature = "zenoh"),
        command(
            about = "(needs the zenoh feature: cargo install --path actors --features zenoh) One dashboard \
                     page for a lab's robots on Zenoh"
        )
    )]
    Fleet(fleet::FleetArgs),
}

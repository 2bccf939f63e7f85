//! `pavlov`: the lab server for Pavlovian control on an iRobot Create.
//!
//! The binary's edge: logging (tracing-subscriber with `RUST_LOG`), the runtime, and dispatch to the
//! commands in [`cli`], with `anyhow` error reports. Everything else lives in the `pavlov-actors` library
//! and the `pavlov` core.

/// `println!` that never panics: a closed stdout (`pavlov serve | head -1`) must not take the server down.
macro_rules! say {
    ($($arg:tt)*) => {{
        use std::io::Write as _;
        let _ = writeln!(std::io::stdout(), $($arg)*);
    }};
}

mod cli;

use anyhow::{Context, Result};
use clap::Parser;

use cli::{Cli, Command};

fn main() -> Result<()> {
    let _log = pavlov_actors::telemetry::logging::init(
        tracing_subscriber::EnvFilter::try_from_default_env()
            .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
    );
    let cli = Cli::parse();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("cannot start the async runtime")?;
    rt.block_on(async move {
        match cli.command {
            Command::Serve(args) => cli::serve::run(args).await,
            Command::Experiment(args) => cli::experiment::run(args),
            Command::Replay(args) => cli::replay::run(args),
            Command::Convert(args) => cli::convert::run(args),
            Command::Sim(args) => cli::sim::run(args).await,
            Command::Human(args) => cli::human::run(args).await,
            Command::Bench(args) => cli::bench::run(args).await,
            Command::Fleet(args) => cli::fleet::run(args).await,
        }
    })
}

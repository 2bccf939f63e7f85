//! `pavlov fleet`: one dashboard page for every robot that `pavlov serve --zenoh` publishes.

use std::path::PathBuf;

#[cfg(feature = "zenoh")]
use anyhow::Context;
use anyhow::Result;
#[cfg(feature = "zenoh")]
use pavlov_actors::fleet::Fleet;
#[cfg(feature = "zenoh")]
use pavlov_actors::zenoh_bridge;

#[cfg(feature = "zenoh")]
use super::args::shutdown_signal;

/// Where the fleet page listens by default (loopback: it forwards commands).
const DEFAULT_LISTEN: &str = "127.0.0.1:8090";

/// `pavlov fleet`'s arguments.
#[derive(clap::Args)]
pub struct FleetArgs {
    /// Where to serve the fleet page (HTTP).
    #[arg(long, value_name = "ADDR", default_value = DEFAULT_LISTEN)]
    listen: String,
    /// A Zenoh configuration file (JSON5: mode, listen/connect endpoints, scouting); default: Zenoh's
    /// defaults (a peer that finds the robots by multicast scouting).
    #[arg(long, value_name = "CONFIG")]
    zenoh: Option<PathBuf>,
}

/// Runs the fleet page until Ctrl-C or SIGTERM.
#[cfg(not(feature = "zenoh"))]
pub async fn run(args: FleetArgs) -> Result<()> {
    let _ = (args.listen, args.zenoh);
    anyhow::bail!("pavlov fleet: {}", super::NO_ZENOH)
}

/// Runs the fleet page until Ctrl-C or SIGTERM.
#[cfg(feature = "zenoh")]
pub async fn run(args: FleetArgs) -> Result<()> {
    let config = zenoh_bridge::load_config(args.zenoh.as_deref()).context("pavlov fleet")?;
    let fleet = Fleet::start(config, &args.listen)
        .await
        .context("cannot start the fleet page")?;
    say!("fleet: http://{}/", fleet.local_addr());
    shutdown_signal().await;
    fleet.shutdown().await;
    Ok(())
}

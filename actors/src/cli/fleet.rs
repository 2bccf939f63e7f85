//! `pavlov fleet`: one dashboard page for every robot that `pavlov serve --zenoh` publishes.

use std::path::PathBuf;

use anyhow::{Context, Result};
use pavlov_actors::fleet::{DEFAULT_LISTEN, Fleet};
use pavlov_actors::zenoh_bridge;

use super::args::shutdown_signal;

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

//! `pavlov bench`: the server on the simulator in real time, with tick lateness and tick-to-command
//! percentiles, optionally under websocket load and abuse. It prints figures; it asserts nothing.

use std::time::Duration;

use anyhow::Result;
use pavlov_actors::bench::{self, abuse::Abuse, load};

use super::args::{ConfigArgs, load_config, repository_web_dir};

/// `pavlov bench`'s arguments.
#[derive(clap::Args)]
pub struct BenchArgs {
    #[command(flatten)]
    config: ConfigArgs,
    /// How long to run, in seconds of real time.
    #[arg(long, default_value_t = 60, value_name = "SECONDS")]
    seconds: u64,
    /// Also run with this many websocket clients reading the dashboard stream, and compare.
    #[arg(long, default_value_t = 0, value_name = "N")]
    ws_clients: usize,
    /// With --ws-clients: add one websocket client that never reads.
    #[arg(long)]
    stalled_client: bool,
    /// With --ws-clients: the clients close and connect again every this many seconds, reading the
    /// dashboard's history each time (and the report times it).
    #[arg(long, value_name = "SECONDS")]
    ws_reconnect_every: Option<f64>,
    /// Run the websocket load twice, without and with abusers (command and malformed-message floods,
    /// over-size messages, connection storms, clients that never read, 100 watchers, 200 idle sockets
    /// reopened as soon as closed), and compare tick lateness and an operator's e-stop latency.
    #[arg(long)]
    ws_abuse: bool,
}

/// Runs the benchmark and prints its report.
pub async fn run(args: BenchArgs) -> Result<()> {
    let cfg = load_config(&args.config)?;
    let duration = Duration::from_secs(args.seconds);
    let reconnect_every = match args.ws_reconnect_every {
        None => None,
        Some(s) if s.is_finite() && s > 0.0 && s <= 3600.0 => Some(Duration::from_secs_f64(s)),
        Some(s) => {
            anyhow::bail!("--ws-reconnect-every must be above 0 and at most 3600 seconds, got {s}")
        }
    };
    if args.ws_abuse {
        let load = load::Load {
            clients: args.ws_clients.max(1),
            stalled: args.stalled_client,
            reconnect_every,
        };
        let report =
            load::run_abuse_comparison(cfg, duration, repository_web_dir(), load, Abuse::default())
                .await?;
        say!("{report}");
        return Ok(());
    }
    let report = bench::run_realtime(cfg.clone(), duration).await?;
    say!("{report}");
    if args.ws_clients > 0 || args.stalled_client {
        let load = load::Load {
            clients: args.ws_clients,
            stalled: args.stalled_client,
            reconnect_every,
        };
        let loaded =
            load::run_realtime_with_clients(cfg, duration, repository_web_dir(), load).await?;
        say!(
            "with {} websocket clients{}{}:",
            args.ws_clients,
            match reconnect_every {
                Some(d) => format!(" reconnecting every {:.1} s", d.as_secs_f64()),
                None => String::new(),
            },
            if args.stalled_client {
                " + 1 stalled"
            } else {
                ""
            }
        );
        say!("{loaded}");
        say!(
            "tick lateness p99: {} µs without clients, {} µs with them",
            report.lateness.p99_us,
            loaded.bench.lateness.p99_us
        );
    }
    Ok(())
}

//! `pavlov bench`: the server on the simulator in real time, with tick lateness and tick-to-command
//! percentiles, optionally under websocket load and abuse. It prints figures; it asserts nothing.

use std::time::Duration;

use anyhow::Result;
#[cfg(feature = "zenoh")]
use pavlov_actors::bench::zenoh_load;
use pavlov_actors::bench::{self, abuse::Abuse, foxglove_load, horde, load, study, timers};
use pavlov_actors::dashboard::WebAssets;

use super::args::{ConfigArgs, load_config, validate};

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
    /// Also run with the Foxglove endpoint (`serve --foxglove`) and this many Foxglove clients subscribed
    /// to every channel, and compare.
    #[arg(long, default_value_t = 0, value_name = "N")]
    foxglove_clients: usize,
    /// Compare the tick timers: the timer thread against tokio's interval, interleaved (thread, tokio,
    /// tokio, thread; --seconds in all for each), with tick lateness and tick → command for both.
    #[arg(long, conflicts_with_all = ["ws_clients", "stalled_client", "ws_abuse", "foxglove_clients"])]
    compare_timers: bool,
    /// Compare the configuration with its [horde] against the same without [horde], interleaved (Horde,
    /// plain, plain, Horde; --seconds in all for each): the Horde's step time, ticks learned and
    /// skipped, tick lateness and tick → command for both, and skipped ticks around Horde checkpoints.
    #[arg(long, conflicts_with_all = ["ws_clients", "stalled_client", "ws_abuse", "foxglove_clients", "compare_timers"])]
    horde: bool,
    /// Measure the Zenoh bridge (`serve --zenoh`): off, on, on, off (--seconds in all), on = publishing
    /// every tick, event and status to a subscriber on loopback TCP; ticks skipped and tick → command.
    #[arg(long, conflicts_with_all = ["ws_clients", "stalled_client", "ws_abuse", "foxglove_clients", "compare_timers"])]
    zenoh: bool,
    /// Time the stall study in virtual time instead (the configuration as above; 10 + 10 runs of
    /// 6 minutes, recorded into a temporary folder that is removed afterwards), twice: CPU time (user +
    /// system) and wall time per simulated tick, side by side, with the load average.
    #[arg(long, conflicts_with_all = ["ws_clients", "stalled_client", "ws_abuse", "foxglove_clients", "compare_timers", "horde", "zenoh"])]
    virtual_time: bool,
    /// With --virtual-time: runs per policy.
    #[arg(
        long,
        default_value_t = 10,
        value_name = "N",
        requires = "virtual_time"
    )]
    study_runs: usize,
    /// With --virtual-time: minutes per run.
    #[arg(
        long,
        default_value_t = 6.0,
        value_name = "MIN",
        requires = "virtual_time"
    )]
    study_minutes: f64,
    /// With --virtual-time: do not record the runs.
    #[arg(long, requires = "virtual_time")]
    no_record: bool,
    /// Override [tick] spin_us: wake this many µs before each deadline and spin (the timer thread only).
    #[arg(long, value_name = "US")]
    spin_us: Option<u32>,
}

/// Runs the benchmark and prints its report.
pub async fn run(args: BenchArgs) -> Result<()> {
    if args.virtual_time {
        return tokio::task::spawn_blocking(move || virtual_time(&args)).await?;
    }
    let mut cfg = load_config(&args.config)?;
    if let Some(spin) = args.spin_us {
        cfg.tick.spin_us = spin;
        validate(&cfg, "--spin-us")?;
    }
    let duration = Duration::from_secs(args.seconds);
    if args.horde {
        if !cfg.horde.is_enabled() {
            anyhow::bail!(
                "--horde needs a configuration with [[horde.families]] (e.g. --config config/horde.toml)"
            );
        }
        let report = horde::run_horde_comparison(cfg, duration).await?;
        say!("{report}");
        return Ok(());
    }
    if args.compare_timers {
        let report = timers::run_timer_comparison(cfg, duration).await?;
        say!("{report}");
        return Ok(());
    }
    if args.zenoh {
        #[cfg(feature = "zenoh")]
        {
            let report = zenoh_load::run_zenoh_comparison(cfg, duration).await?;
            say!("{report}");
            return Ok(());
        }
        #[cfg(not(feature = "zenoh"))]
        anyhow::bail!("--zenoh: {}", super::NO_ZENOH);
    }
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
            load::run_abuse_comparison(cfg, duration, WebAssets::Embedded, load, Abuse::default())
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
            load::run_realtime_with_clients(cfg.clone(), duration, WebAssets::Embedded, load)
                .await?;
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
    if args.foxglove_clients > 0 {
        let loaded =
            foxglove_load::run_realtime_with_foxglove_clients(cfg, duration, args.foxglove_clients)
                .await?;
        say!("with {} Foxglove clients:", args.foxglove_clients);
        say!("{loaded}");
        say!("{}", foxglove_load::comparison(&report, &loaded));
    }
    Ok(())
}

/// `--virtual-time`: the stall study, timed twice.
fn virtual_time(args: &BenchArgs) -> Result<()> {
    anyhow::ensure!(
        (1..=1000).contains(&args.study_runs),
        "--study-runs must be 1 to 1000, got {}",
        args.study_runs
    );
    anyhow::ensure!(
        args.study_minutes.is_finite() && args.study_minutes > 0.0 && args.study_minutes <= 1440.0,
        "--study-minutes must be above 0 and at most 1440, got {}",
        args.study_minutes
    );
    let config = load_config(&args.config)?;
    // As `experiment stall` does: the number of CPUs, at most 2.
    let threads = std::thread::available_parallelism().map_or(1, |n| n.get().min(2));
    for attempt in 1..=2 {
        let scratch = (!args.no_record).then(|| {
            std::env::temp_dir().join(format!(
                "pavlov-bench-study-{}-{attempt}",
                std::process::id()
            ))
        });
        let timing = study::time_stall_study(
            &config,
            args.study_runs,
            args.study_minutes,
            threads,
            scratch.clone(),
        );
        if let Some(dir) = &scratch {
            let _ = std::fs::remove_dir_all(dir);
        }
        say!("run {attempt} of 2: {}", timing?);
    }
    Ok(())
}

//! `pavlov serve`: the lab server on the simulated Create or a real one, with its dashboard.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result};
use pavlov_actors::dashboard::Dashboard;
use pavlov_actors::foxglove::{self, Foxglove};
use pavlov_actors::server::{RobotTarget, Server};
use pavlov_actors::storage::{checkpoint_files, recorder, recording};
#[cfg(feature = "zenoh")]
use pavlov_actors::zenoh_bridge::{self, ZenohBridge};

use super::args::{
    ConfigArgs, DashboardArgs, read_config, shutdown_signal, skeleton_format_name, validate,
};

/// `pavlov serve`'s own arguments.
#[derive(clap::Args)]
pub struct ServeArgs {
    #[command(flatten)]
    config: ConfigArgs,
    /// Serial device of a real Create (e.g. /dev/ttyUSB0), or the PTY printed by `pavlov sim --pty`.
    #[arg(long, value_name = "DEVICE")]
    robot: Option<String>,
    #[command(flatten)]
    dashboard: DashboardArgs,
    /// Record every tick and event into DIR/recording.mcap (MCAP, replayable with `pavlov replay DIR`); refused
    /// if DIR already holds a recording. Recordings started from the dashboard go into ./recordings.
    #[arg(long, value_name = "DIR")]
    record: Option<PathBuf>,
    /// Continue learning from the newest valid checkpoint in [checkpoint] dir, over every run; newer
    /// ones that cannot be used are skipped and named. Refused (before the robot is touched) if none is
    /// valid.
    #[arg(long, conflicts_with = "resume_from")]
    resume: bool,
    /// Continue learning from this checkpoint file: an automatic checkpoint or a `save_weights` save
    /// (e.g. weights/saved/w.json). Refused if it cannot be used.
    #[arg(long, value_name = "FILE")]
    resume_from: Option<PathBuf>,
    /// Also stream every tick, event and the configuration over the Foxglove WebSocket protocol on ADDR
    /// (default 127.0.0.1:8765): in Foxglove, open a Foxglove WebSocket connection to ws://ADDR. Clients
    /// only read; with --token and watch_without_token = false they must add ?token=TOKEN to the URL.
    /// An address that is not loopback requires --token.
    #[arg(
        long,
        value_name = "ADDR",
        num_args = 0..=1,
        default_missing_value = foxglove::DEFAULT_ADDR
    )]
    foxglove: Option<String>,
    /// Also publish every tick, event and a status on Zenoh under pavlov/v1/<robot>/… ([zenoh] robot) and
    /// answer queries for the configuration, the newest checkpoint and (with [zenoh] commands = true and a
    /// token) commands. CONFIG is a Zenoh configuration file (JSON5: mode, listen/connect endpoints,
    /// scouting); without it, Zenoh's defaults (a peer found by multicast scouting).
    #[cfg_attr(
        not(feature = "zenoh"),
        arg(
            help = "(needs the zenoh feature: cargo install --path actors --features zenoh) Also \
                    publish the run on Zenoh under pavlov/v1/<robot>/…"
        )
    )]
    #[arg(long, value_name = "CONFIG", num_args = 0..=1)]
    zenoh: Option<Option<PathBuf>>,
}

/// The folder dashboard-started recordings go into.
const RECORDINGS_ROOT: &str = "recordings";

/// Runs the server until Ctrl-C or SIGTERM.
pub async fn run(args: ServeArgs) -> Result<()> {
    let ServeArgs {
        config: config_args,
        robot,
        dashboard,
        record,
        resume,
        resume_from,
        foxglove: foxglove_addr,
        zenoh: zenoh_file,
    } = args;
    let (mut cfg, origin) = read_config(&config_args)?;
    let generated_token = dashboard.apply(&mut cfg)?;
    validate(&cfg, &origin)?;
    // The server checkpoints its weights periodically and at shutdown.
    cfg.checkpoint.autosave = true;
    cfg.checkpoint.resume |= resume;
    if let Some(file) = resume_from {
        cfg.checkpoint.resume_from = Some(file.display().to_string());
    }
    if cfg.checkpoint.resume || cfg.checkpoint.resume_from.is_some() {
        // Refuse before anything is started (the recorder would create its file); the server then
        // resumes for real and reports what it took and skipped.
        checkpoint_files::load_for_resume(&cfg).context(
            if cfg.checkpoint.resume_from.is_some() {
                "cannot resume (--resume-from)"
            } else {
                "cannot resume (--resume)"
            },
        )?;
    }
    if robot.is_some() && config_args.faults.is_some() {
        anyhow::bail!(
            "--faults injects faults into the simulated Create; a real robot on --robot brings its own \
             (to test a serial link with faults, run `pavlov sim --pty --faults …` and point --robot at it)"
        );
    }
    let robot_name = match &robot {
        None => format!("a simulated {}", cfg.robot.model),
        Some(p) => format!("the {} on {p}", cfg.robot.model),
    };
    let target = match robot {
        Some(path) => RobotTarget::Serial(path),
        None => RobotTarget::Simulated,
    };
    tracing::info!(?target, mode = ?cfg.control.mode, "starting pavlov");
    // Every listening socket is bound before the robot is touched: a busy port stops here.
    let bound = Dashboard::bind(&cfg.dashboard)?;
    let foxglove_bound = foxglove_addr
        .as_deref()
        .map(|addr| Foxglove::bind(addr, &cfg.dashboard))
        .transpose()
        .context("cannot start the Foxglove endpoint (--foxglove)")?;
    #[cfg(not(feature = "zenoh"))]
    if zenoh_file.is_some() {
        anyhow::bail!("--zenoh: {}", super::NO_ZENOH);
    }
    #[cfg(feature = "zenoh")]
    let zenoh_config = zenoh_file
        .as_ref()
        .map(|f| zenoh_bridge::load_config(f.as_deref()))
        .transpose()
        .context("cannot start the Zenoh bridge (--zenoh)")?;
    #[cfg(feature = "zenoh")]
    if zenoh_config.is_some() && cfg.zenoh.commands && cfg.dashboard.token.is_none() {
        return Err(zenoh_bridge::ZenohError::CommandsNeedToken)
            .context("cannot start the Zenoh bridge (--zenoh)");
    }
    let recorder = recorder::Recorder::spawn_new(
        recording::RecordingHeader::new(&cfg, "pavlov serve"),
        record.clone(),
        PathBuf::from(RECORDINGS_ROOT),
        recorder::DEFAULT_CAPACITY,
    )
    .context("cannot start the recorder (--record)")?;
    if let Some(dir) = &record {
        say!(
            "recording every tick into {}",
            dir.join(recording::MCAP_FILE).display()
        );
    }
    let server = Server::builder(cfg, target)
        .recorder(recorder.link.clone())
        .start()
        .await
        .context("cannot start the server")?;
    let assets = dashboard.assets();
    let page_from = assets.describe();
    let dash = match Dashboard::serve(bound, &server, assets).await {
        Ok(d) => d,
        Err(e) => {
            server.shutdown().await;
            return Err(e).context("cannot start the dashboard");
        }
    };
    let fox = match foxglove_bound {
        None => None,
        Some(bound) => match Foxglove::serve(bound, &server).await {
            Ok(f) => Some(f),
            Err(e) => {
                dash.shutdown().await;
                server.shutdown().await;
                return Err(e).context("cannot start the Foxglove endpoint (--foxglove)");
            }
        },
    };
    #[cfg(feature = "zenoh")]
    let zenoh = match zenoh_config {
        None => None,
        Some(zc) => {
            let url = if server.config().zenoh.dashboard_url.is_empty() {
                dash.url()
            } else {
                server.config().zenoh.dashboard_url.clone()
            };
            match ZenohBridge::start(zc, &server, url).await {
                Ok(z) => Some(z),
                Err(e) => {
                    if let Some(f) = fox {
                        f.shutdown().await;
                    }
                    dash.shutdown().await;
                    server.shutdown().await;
                    return Err(e).context("cannot start the Zenoh bridge (--zenoh)");
                }
            }
        }
    };
    if let Some(resumed) = &server.checkpoints().resumed {
        for line in resumed.report_lines() {
            say!("{line}");
        }
    }
    if let Some(dir) = &server.checkpoints().run_dir {
        say!("this run's checkpoints: {}", dir.display());
    }
    say!("pavlov is driving {robot_name}; press Ctrl-C to stop");
    say!("dashboard: {}", dash.url());
    say!("dashboard page: {page_from}");
    if let Some(token) = &generated_token {
        say!(
            "no token was given for {}, so commands need this random one (pass --token to choose one): {token}",
            server.config().dashboard.bind
        );
        say!("operator page: {}#token={token}", dash.url());
    } else if server.config().dashboard.token.is_some() {
        say!(
            "dashboard commands need the token: open {}#token=<your token>",
            dash.url()
        );
    }
    if let Some(f) = &fox {
        let query = if f.token_required() {
            "/?token=<your token>"
        } else {
            ""
        };
        say!(
            "foxglove: open Foxglove (app.foxglove.dev or the desktop app) and connect to {}{query}",
            f.url()
        );
    }
    if let Some(sk) = &server.skeleton() {
        say!(
            "skeleton: listening for {} on udp://{}",
            skeleton_format_name(server.config().skeleton.format),
            sk.local_addr
        );
    }
    #[cfg(feature = "zenoh")]
    if let Some(z) = &zenoh {
        say!(
            "zenoh: publishing on pavlov/v1/{}/{{tick,event,status}} (liveliness token pavlov/v1/{}/alive); commands over Zenoh {}",
            z.robot(),
            z.robot(),
            if server.config().zenoh.commands {
                "on (with the token)"
            } else {
                "off"
            }
        );
    }
    shutdown_signal().await;
    tracing::info!("shutting down: stopping the robot");
    #[cfg(feature = "zenoh")]
    if let Some(z) = zenoh {
        z.shutdown().await;
    }
    if let Some(f) = fox {
        f.shutdown().await;
    }
    dash.shutdown().await;
    server.shutdown().await;
    // The recorder ends once the feed is gone; do not hang on it if something still holds the feed.
    let report = tokio::time::timeout(
        Duration::from_secs(2),
        tokio::task::spawn_blocking(move || recorder.join()),
    )
    .await;
    if let Ok(Ok(r)) = report {
        tracing::info!(written = r.written, files = ?r.files, "recorder closed");
    }
    Ok(())
}

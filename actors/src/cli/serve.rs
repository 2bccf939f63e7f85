//! `pavlov serve`: the lab server on the simulated Create or a real one, with its dashboard.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result};
use pavlov_actors::dashboard::Dashboard;
use pavlov_actors::server::{RobotTarget, Server};
use pavlov_actors::storage::{checkpoint_files, recorder, recording};

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
    /// Record every tick into DIR/ticks.jsonl (JSON Lines, replayable with `pavlov replay DIR`). Without
    /// it, recording starts and stops on the dashboard's commands, under ./recordings.
    #[arg(long, value_name = "DIR")]
    record: Option<PathBuf>,
    /// Continue learning from the newest checkpoint in [checkpoint] dir. Refused (before the robot is
    /// touched) if there is none or it was made for a different configuration.
    #[arg(long)]
    resume: bool,
}

/// Runs the server until Ctrl-C or SIGTERM.
pub async fn run(args: ServeArgs) -> Result<()> {
    let ServeArgs {
        config: config_args,
        robot,
        dashboard,
        record,
        resume,
    } = args;
    let (mut cfg, origin) = read_config(&config_args)?;
    let generated_token = dashboard.apply(&mut cfg)?;
    validate(&cfg, &origin)?;
    // The server checkpoints its weights periodically and at shutdown.
    cfg.checkpoint.autosave = true;
    cfg.checkpoint.resume |= resume;
    if cfg.checkpoint.resume {
        let (path, cp) =
            checkpoint_files::load_for_resume(&cfg).context("cannot resume (--resume)")?;
        println!(
            "resuming from {} (tick {})",
            path.display(),
            cp.created_tick
        );
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
    let recorder = recorder::Recorder::spawn(
        recording::RecordingHeader::new(&cfg, "pavlov serve"),
        record.clone(),
        record
            .clone()
            .unwrap_or_else(|| PathBuf::from("recordings")),
        recorder::DEFAULT_CAPACITY,
    )
    .context("cannot start the recorder")?;
    if let Some(dir) = &record {
        println!(
            "recording every tick into {}",
            dir.join(recording::TICKS_FILE).display()
        );
    }
    let server = Server::builder(cfg, target)
        .recorder(recorder.link.clone())
        .start()
        .await
        .context("cannot start the server")?;
    let dash = match Dashboard::start(&server, dashboard.web_dir()).await {
        Ok(d) => d,
        Err(e) => {
            server.shutdown().await;
            return Err(e).context("cannot start the dashboard");
        }
    };
    println!("pavlov is driving {robot_name}; press Ctrl-C to stop");
    println!("dashboard: {}", dash.url());
    if let Some(token) = &generated_token {
        println!(
            "no token was given for {}, so commands need this random one (pass --token to choose one): {token}",
            server.config.dashboard.bind
        );
        println!("operator page: {}#token={token}", dash.url());
    } else if server.config.dashboard.token.is_some() {
        println!(
            "dashboard commands need the token: open {}#token=<your token>",
            dash.url()
        );
    }
    if let Some(sk) = &server.skeleton {
        println!(
            "skeleton: listening for {} on udp://{}",
            skeleton_format_name(server.config.skeleton.format),
            sk.local_addr
        );
    }
    shutdown_signal().await;
    tracing::info!("shutting down: stopping the robot");
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

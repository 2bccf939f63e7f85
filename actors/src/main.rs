//! `pavlov`: the lab server for Pavlovian control on an iRobot Create.
//!
//! The binary's edge: command-line parsing (clap), logging (tracing-subscriber with `RUST_LOG`), signals,
//! and `anyhow` error reports. Everything else lives in the `pavlov-actors` library and the `pavlov` core.

use std::path::PathBuf;
use std::time::Duration;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use pavlov::config::{Config, SkeletonFormat};
use pavlov::control::Mode;
use pavlov::oi::Model;
use pavlov::sim::faults::{FaultInjector, FaultSpec};
use pavlov::sim::params::SimParams;
use pavlov::sim::robot::SimRobot;
use pavlov_actors::human_sender::{SenderOptions, send_human};
use pavlov_actors::server::{RobotTarget, Server};
use pavlov_actors::ws::Dashboard;
use pavlov_actors::ws::load::{Load, run_realtime_with_clients};
use pavlov_actors::{bench, link::transport};
use tokio_util::sync::CancellationToken;

/// The stall experiment's configuration, built in so that `pavlov serve` works with no files at all.
const DEFAULT_CONFIG: &str = include_str!("../../config/stall.toml");

#[derive(Parser)]
#[command(
    name = "pavlov",
    version,
    about = "Pavlovian control of an iRobot Create: online TD(λ) predictions driving fixed responses",
    long_about = "A lab server that runs Pavlovian control (Modayil & Sutton, \"Prediction Driven Behavior\") on an \
iRobot Create 1 or 2: every 20 ms it reads the robot's sensors, learns TD(λ) predictions online, and lets a fixed \
response take over from the default policy when a prediction crosses its threshold. Without --robot it drives a \
simulated Create that speaks the real Open Interface bytes.\n\nLogging: set RUST_LOG (e.g. RUST_LOG=debug or \
RUST_LOG=pavlov_actors=trace); the default is info."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(clap::Args, Clone)]
struct ConfigArgs {
    /// Experiment configuration (TOML; see config/README.md). Default: the built-in stall experiment
    /// (config/stall.toml).
    #[arg(long, short = 'c', value_name = "FILE")]
    config: Option<PathBuf>,
    /// Override [robot] model: create1 (57600 baud) or create2 (115200 baud).
    #[arg(long, value_name = "MODEL")]
    model: Option<Model>,
    /// Override [control] mode at start-up: reactive, pavlovian or manual.
    #[arg(long, value_name = "MODE", value_parser = parse_mode)]
    mode: Option<Mode>,
    /// Override [sim] seed: the seed of the simulated robot (and human).
    #[arg(long, value_name = "N")]
    seed: Option<u64>,
    /// Override [sim] faults: what the simulated Create injects, e.g. `soak`, `all` or
    /// `drop=1e-4,flip=1e-4,text=0.002,hang=2e-5,eof=1e-5,trip=1e-5,quirk` (see README, "Fault injection").
    #[arg(long, value_name = "SPEC")]
    faults: Option<String>,
}

/// The dashboard endpoint's command-line overrides.
#[derive(clap::Args, Clone)]
struct DashboardArgs {
    /// Override [dashboard] bind: where the dashboard page and its websocket listen (default 127.0.0.1:8080).
    /// Any non-loopback address requires --token.
    #[arg(long, value_name = "ADDR")]
    bind: Option<String>,
    /// Override [dashboard] token: the secret a websocket client presents before it may send commands
    /// (open the page as http://HOST:PORT/#token=TOKEN).
    #[arg(long, value_name = "TOKEN")]
    token: Option<String>,
    /// Where the dashboard's npm packages are installed (its node_modules/uplot); default: the repository's web/.
    #[arg(long, value_name = "DIR")]
    web_dir: Option<PathBuf>,
}

impl DashboardArgs {
    fn apply(&self, cfg: &mut Config) -> Result<()> {
        if let Some(b) = &self.bind {
            cfg.dashboard.bind = b.clone();
        }
        if let Some(t) = &self.token {
            cfg.dashboard.token = Some(t.clone());
        }
        cfg.validate()
            .context("invalid dashboard settings (--bind / --token)")?;
        Ok(())
    }

    fn web_dir(&self) -> PathBuf {
        self.web_dir
            .clone()
            .unwrap_or_else(|| PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../web")))
    }
}

#[derive(Subcommand)]
enum Command {
    /// Run the server. Without --robot it drives the simulated Create in process.
    Serve {
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
    },
    /// Reproduce the paper's experiments on the simulated Create (e.g. `pavlov experiment stall --seed 1`).
    Experiment(pavlov_actors::experiment::cli::ExperimentArgs),
    /// Run a recording back through the learning and gating stages and check that it reproduces exactly.
    Replay(pavlov_actors::experiment::cli::ReplayArgs),
    /// Run the simulated Create on its own, on a pseudo-terminal that any OI client can open.
    Sim {
        /// Create the PTY and print its path (the only transport for now; required).
        #[arg(long, required = true)]
        pty: bool,
        /// Robot model to simulate.
        #[arg(long, default_value = "create1", value_name = "MODEL")]
        model: Model,
        /// Seed of the simulation's random draws.
        #[arg(long, default_value_t = 1, value_name = "N")]
        seed: u64,
        /// Faults to inject: a preset (none, soak, all) or `key=value,...` (see README, "Fault injection").
        /// On a PTY an end-of-file cannot be signalled without destroying the device, so `eof` hangs instead.
        #[arg(long, default_value = "none", value_name = "SPEC")]
        faults: String,
    },
    /// Run the simulated human operator and stream its skeleton as OSC over UDP (what a depth sensor with
    /// OSCeleton or KinectV2-OSC would send), e.g. to a `pavlov serve` running the interaction experiment.
    Human {
        /// Where to send (the server's [skeleton] listen address).
        #[arg(long, default_value = "127.0.0.1:7110", value_name = "ADDR")]
        to: std::net::SocketAddr,
        /// Seed of the simulated human.
        #[arg(long, default_value_t = 1, value_name = "N")]
        seed: u64,
        /// Wire format: osceleton_mm, osceleton_normalized or kinect_v2.
        #[arg(long, default_value = "osceleton_mm", value_name = "FORMAT", value_parser = parse_skeleton_format)]
        format: SkeletonFormat,
        /// Pace frames at the sensor's 30 Hz on the wall clock (the default).
        #[arg(long, conflicts_with = "fast")]
        realtime: bool,
        /// Send frames back to back instead of in real time.
        #[arg(long)]
        fast: bool,
        /// Stop after this many frames (default: run until Ctrl-C).
        #[arg(long, value_name = "N")]
        frames: Option<u64>,
    },
    /// Benchmark: run the server on the simulator in real time and print tick lateness and
    /// tick-to-command latency percentiles, optionally with websocket clients and abusers attached.
    Bench {
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
        /// Run the websocket load twice, without and with abusers (command and malformed-message floods,
        /// over-size messages, connection storms, clients that never read), and compare tick lateness.
        #[arg(long)]
        ws_abuse: bool,
    },
}

fn parse_mode(s: &str) -> Result<Mode, String> {
    match s {
        "reactive" => Ok(Mode::Reactive),
        "pavlovian" => Ok(Mode::Pavlovian),
        "manual" => Ok(Mode::Manual),
        other => Err(format!(
            "unknown mode `{other}` (expected reactive, pavlovian or manual)"
        )),
    }
}

fn load_config(args: &ConfigArgs) -> Result<Config> {
    let (text, origin) = match &args.config {
        Some(path) => (
            std::fs::read_to_string(path)
                .with_context(|| format!("cannot read configuration {}", path.display()))?,
            path.display().to_string(),
        ),
        None => (
            DEFAULT_CONFIG.to_string(),
            "built-in config/stall.toml".into(),
        ),
    };
    let mut cfg =
        Config::from_toml(&text).with_context(|| format!("invalid configuration in {origin}"))?;
    if let Some(m) = args.model {
        cfg.robot.model = m;
        // The built-in stream list names the Create 1's group; follow the model unless one was configured.
        if args.config.is_none() {
            cfg.robot.stream.clear();
        }
    }
    if let Some(m) = args.mode {
        cfg.control.mode = m;
    }
    if let Some(s) = args.seed {
        cfg.sim.seed = s;
    }
    if let Some(f) = &args.faults {
        cfg.sim.faults = f.clone();
    }
    cfg.validate().with_context(|| {
        format!("invalid configuration in {origin} after command-line overrides")
    })?;
    Ok(cfg)
}

async fn shutdown_signal() {
    let ctrl_c = tokio::signal::ctrl_c();
    #[cfg(unix)]
    {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut term) => {
                tokio::select! {
                    _ = ctrl_c => {},
                    _ = term.recv() => {},
                }
            }
            Err(_) => {
                let _ = ctrl_c.await;
            }
        }
    }
    #[cfg(not(unix))]
    {
        let _ = ctrl_c.await;
    }
}

async fn serve(
    args: ConfigArgs,
    robot: Option<String>,
    dashboard: DashboardArgs,
    record: Option<PathBuf>,
    resume: bool,
) -> Result<()> {
    let mut cfg = load_config(&args)?;
    dashboard.apply(&mut cfg)?;
    // The server checkpoints its weights periodically and at shutdown.
    cfg.checkpoint.autosave = true;
    cfg.checkpoint.resume |= resume;
    if cfg.checkpoint.resume {
        let (path, cp) =
            pavlov_actors::checkpoint::load_for_resume(&cfg).context("cannot resume (--resume)")?;
        println!(
            "resuming from {} (tick {})",
            path.display(),
            cp.created_tick
        );
    }
    let target = match robot {
        Some(path) => RobotTarget::Serial(path),
        None => RobotTarget::Simulated,
    };
    if matches!(target, RobotTarget::Serial(_)) && args.faults.is_some() {
        anyhow::bail!(
            "--faults injects faults into the simulated Create; a real robot on --robot brings its own \
             (to test a serial link with faults, run `pavlov sim --pty --faults …` and point --robot at it)"
        );
    }
    let robot_name = match &target {
        RobotTarget::Simulated => format!("a simulated {}", cfg.robot.model),
        RobotTarget::Serial(p) => format!("the {} on {p}", cfg.robot.model),
    };
    tracing::info!(?target, mode = ?cfg.control.mode, "starting pavlov");
    let recorder = pavlov_actors::recorder::Recorder::spawn(
        pavlov_actors::recording::RecordingHeader::new(&cfg, "pavlov serve"),
        record.clone(),
        record
            .clone()
            .unwrap_or_else(|| PathBuf::from("recordings")),
        pavlov_actors::recorder::DEFAULT_CAPACITY,
    )
    .context("cannot start the recorder")?;
    if let Some(dir) = &record {
        println!(
            "recording every tick into {}",
            dir.join("ticks.jsonl").display()
        );
    }
    let server = Server::start_with_recorder(cfg, target, Some(recorder.link.clone()))
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
    if server.config.dashboard.token.is_some() {
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

async fn sim_pty(model: Model, seed: u64, faults: &str) -> Result<()> {
    let cancel = CancellationToken::new();
    let robot = SimRobot::new(model, SimParams::for_model(model), seed);
    let spec: FaultSpec = faults
        .parse()
        .with_context(|| format!("invalid --faults `{faults}`"))?;
    if !spec.is_none() {
        tracing::info!(faults = %spec.describe(), "injecting faults");
    }
    let injector = FaultInjector::new(spec, seed);
    let pty = transport::spawn_sim_pty(robot, injector, cancel.clone())
        .context("cannot start the simulated robot")?;
    let status = pty.status.clone();
    println!("{}", pty.path);
    tracing::info!(path = %pty.path, %model, seed, "simulated Create listening on a pseudo-terminal");
    shutdown_signal().await;
    cancel.cancel();
    let robot = pty.robot.await.context("the simulator task failed")?;
    // The robot's final state, one JSON line on stdout, so scripts and tests can check how it was left.
    let world = robot.world();
    let c = robot.counters();
    let injected = status.borrow().faults.clone();
    println!(
        "{}",
        serde_json::json!({
            "oi_mode": robot.oi_mode().code(),
            "wheel_speed_mm_s": [world.wheel_speed_mm_s(0), world.wheel_speed_mm_s(1)],
            "odometer_m": world.odometer_m(),
            "commands": c.commands,
            "frames_sent": c.frames_sent,
            "elapsed_s": robot.elapsed_steps() as f64 * 0.015,
            "safety_trips": c.safety_trips,
            "faults": injected,
        })
    );
    Ok(())
}

fn parse_skeleton_format(s: &str) -> Result<SkeletonFormat, String> {
    match s {
        "osceleton_mm" => Ok(SkeletonFormat::OsceletonMm),
        "osceleton_normalized" => Ok(SkeletonFormat::OsceletonNormalized),
        "kinect_v2" => Ok(SkeletonFormat::KinectV2),
        other => Err(format!(
            "unknown skeleton format `{other}` (expected osceleton_mm, osceleton_normalized or kinect_v2)"
        )),
    }
}

fn skeleton_format_name(f: SkeletonFormat) -> &'static str {
    match f {
        SkeletonFormat::OsceletonMm => "OSCeleton (mm)",
        SkeletonFormat::OsceletonNormalized => "OSCeleton (normalized)",
        SkeletonFormat::KinectV2 => "KinectV2-OSC",
    }
}

async fn human(
    to: std::net::SocketAddr,
    seed: u64,
    format: SkeletonFormat,
    realtime: bool,
    frames: Option<u64>,
) -> Result<()> {
    let cancel = CancellationToken::new();
    let opts = SenderOptions {
        to,
        seed,
        format,
        realtime,
        frames,
    };
    println!(
        "simulated human (seed {seed}) sending {} to udp://{to}",
        skeleton_format_name(format)
    );
    let on_signal = cancel.clone();
    let watcher = tokio::spawn(async move {
        shutdown_signal().await;
        tracing::info!("stopping the simulated human");
        on_signal.cancel();
    });
    // On Ctrl-C the sender stops after the current frame and sends /lost_user.
    let report = send_human(opts, cancel).await;
    watcher.abort();
    let report = report.context("the simulated human could not send")?;
    println!(
        "sent {} frames in {} datagrams ({} send errors); {} commands (ground truth)",
        report.frames, report.datagrams, report.send_errors, report.commands
    );
    Ok(())
}

fn main() -> Result<()> {
    tracing_subscriber::fmt()
        .with_env_filter(
            tracing_subscriber::EnvFilter::try_from_default_env()
                .unwrap_or_else(|_| tracing_subscriber::EnvFilter::new("info")),
        )
        .with_writer(std::io::stderr)
        .init();
    let cli = Cli::parse();
    let rt = tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .build()
        .context("cannot start the async runtime")?;
    rt.block_on(async move {
        match cli.command {
            Command::Serve {
                config,
                robot,
                dashboard,
                record,
                resume,
            } => serve(config, robot, dashboard, record, resume).await,
            Command::Experiment(args) => pavlov_actors::experiment::cli::experiment(args),
            Command::Replay(args) => pavlov_actors::experiment::cli::replay(args),
            Command::Sim {
                pty: _,
                model,
                seed,
                faults,
            } => sim_pty(model, seed, &faults).await,
            Command::Human {
                to,
                seed,
                format,
                realtime: _,
                fast,
                frames,
            } => human(to, seed, format, !fast, frames).await,
            Command::Bench {
                config,
                seconds,
                ws_clients,
                stalled_client,
                ws_abuse,
            } => {
                let cfg = load_config(&config)?;
                let duration = Duration::from_secs(seconds);
                if ws_abuse {
                    let load = Load {
                        clients: ws_clients.max(1),
                        stalled: stalled_client,
                    };
                    let web_dir = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../web"));
                    let report = pavlov_actors::ws::load::run_abuse_comparison(
                        cfg,
                        duration,
                        web_dir,
                        load,
                        pavlov_actors::ws::abuse::Abuse::default(),
                    )
                    .await?;
                    println!("{report}");
                    return Ok(());
                }
                let report = bench::run_realtime(cfg.clone(), duration).await?;
                println!("{report}");
                if ws_clients > 0 || stalled_client {
                    let load = Load {
                        clients: ws_clients,
                        stalled: stalled_client,
                    };
                    let web_dir = PathBuf::from(concat!(env!("CARGO_MANIFEST_DIR"), "/../web"));
                    let loaded = run_realtime_with_clients(cfg, duration, web_dir, load).await?;
                    println!(
                        "with {ws_clients} websocket clients{}:",
                        if stalled_client { " + 1 stalled" } else { "" }
                    );
                    println!("{loaded}");
                    println!(
                        "tick lateness p99: {} µs without clients, {} µs with them",
                        report.lateness.p99_us, loaded.bench.lateness.p99_us
                    );
                }
                Ok(())
            }
        }
    })
}

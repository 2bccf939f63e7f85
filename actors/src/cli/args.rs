//! Arguments shared by several commands: the configuration file with its overrides, and the dashboard
//! endpoint's.

use std::path::PathBuf;

use anyhow::{Context, Result};
use pavlov::config::{Config, ConfigError, SkeletonFormat};
use pavlov::control::Mode;
use pavlov::oi::Model;
use pavlov_actors::dashboard::WebAssets;

/// The stall experiment's configuration, built in so that `pavlov serve` works with no files at all.
pub const DEFAULT_CONFIG: &str = include_str!("../../../config/stall.toml");

/// The configuration and the command-line overrides of its keys.
#[derive(clap::Args, Clone)]
pub struct ConfigArgs {
    /// Experiment configuration (TOML; see config/README.md). Default: the built-in stall experiment
    /// (config/stall.toml).
    #[arg(long, short = 'c', value_name = "FILE")]
    pub config: Option<PathBuf>,
    /// Override [robot] model: create1 (57600 baud) or create2 (115200 baud).
    #[arg(long, value_name = "MODEL")]
    pub model: Option<Model>,
    /// Override [control] mode at start-up: reactive, pavlovian or manual.
    #[arg(long, value_name = "MODE", value_parser = parse_mode)]
    pub mode: Option<Mode>,
    /// Override [sim] seed: the seed of the simulated robot (and human).
    #[arg(long, value_name = "N")]
    pub seed: Option<u64>,
    /// Override [sim] faults: what the simulated Create injects, e.g. `soak`, `all` or
    /// `drop=1e-4,flip=1e-4,text=0.002,hang=2e-5,eof=1e-5,trip=1e-5,quirk` (see the book, docs/src/faults.md).
    #[arg(long, value_name = "SPEC")]
    pub faults: Option<String>,
}

/// The dashboard endpoint's command-line overrides.
#[derive(clap::Args, Clone)]
pub struct DashboardArgs {
    /// Override [dashboard] bind: where the dashboard page and its websocket listen (default 127.0.0.1:8080).
    /// On any non-loopback address commands need a token: --token, or a random one printed at start-up.
    #[arg(long, value_name = "ADDR")]
    pub bind: Option<String>,
    /// Override [dashboard] token: the secret a websocket client presents before it may send commands
    /// (open the page as http://HOST:PORT/#token=TOKEN); at least 16 characters on a non-loopback address.
    #[arg(long, value_name = "TOKEN")]
    pub token: Option<String>,
    /// Serve the dashboard's files (index.html, *.js, *.css, node_modules/uplot/dist/) from DIR, read at
    /// every request, instead of the copies built into the binary: for working on the page (e.g. --web-dir web
    /// in the repository, after `npm ci --prefix web`). Default: the built-in files; nothing else is needed.
    #[arg(long, value_name = "DIR")]
    pub web_dir: Option<PathBuf>,
}

impl DashboardArgs {
    /// Applies the overrides to `cfg`; when the result binds a non-loopback address without a token, sets a
    /// random one (returned, so that it can be shown to the operator). The caller validates the result.
    pub fn apply(&self, cfg: &mut Config) -> Result<Option<String>> {
        if let Some(b) = &self.bind {
            cfg.dashboard.bind = b.clone();
        }
        if let Some(t) = &self.token {
            cfg.dashboard.token = Some(t.clone());
        }
        let generated = if cfg.dashboard.is_public() && cfg.dashboard.token().is_none() {
            let token = pavlov_actors::dashboard::generate_token().context(
                "cannot generate a dashboard token (reading /dev/urandom); pass --token",
            )?;
            cfg.dashboard.token = Some(token.clone());
            Some(token)
        } else {
            None
        };
        Ok(generated)
    }

    /// Where the dashboard's files come from: built in, or `--web-dir`.
    pub fn assets(&self) -> WebAssets {
        self.web_dir
            .clone()
            .map_or(WebAssets::Embedded, WebAssets::Dir)
    }
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

/// Reads the configuration and applies the overrides.
pub fn load_config(args: &ConfigArgs) -> Result<Config> {
    let (cfg, origin) = read_config(args)?;
    validate(&cfg, &origin)?;
    Ok(cfg)
}

/// Checks a configuration read from `origin`, with the command-line overrides applied.
pub fn validate(cfg: &Config, origin: &str) -> Result<()> {
    cfg.validate().with_context(|| {
        format!("invalid configuration in {origin} (with the command-line overrides)")
    })
}

/// Reads the configuration and applies the overrides without checking the values (the caller completes
/// the configuration and validates it); returns it with where it came from.
pub fn read_config(args: &ConfigArgs) -> Result<(Config, String)> {
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
    let mut cfg: Config = toml::from_str(&text)
        .map_err(|e| ConfigError::Parse(e.to_string()))
        .with_context(|| format!("invalid configuration in {origin}"))?;
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
    Ok((cfg, origin))
}

/// Parses a skeleton wire format's name.
pub fn parse_skeleton_format(s: &str) -> Result<SkeletonFormat, String> {
    match s {
        "osceleton_mm" => Ok(SkeletonFormat::OsceletonMm),
        "osceleton_normalized" => Ok(SkeletonFormat::OsceletonNormalized),
        "kinect_v2" => Ok(SkeletonFormat::KinectV2),
        other => Err(format!(
            "unknown skeleton format `{other}` (expected osceleton_mm, osceleton_normalized or kinect_v2)"
        )),
    }
}

/// A skeleton wire format's name for people.
pub fn skeleton_format_name(f: SkeletonFormat) -> &'static str {
    match f {
        SkeletonFormat::OsceletonMm => "OSCeleton (mm)",
        SkeletonFormat::OsceletonNormalized => "OSCeleton (normalized)",
        SkeletonFormat::KinectV2 => "KinectV2-OSC",
    }
}

/// Waits for Ctrl-C or SIGTERM.
pub async fn shutdown_signal() {
    let ctrl_c = tokio::signal::ctrl_c();
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

//! `pavlov human`: the simulated operator streaming real OSC skeleton packets over UDP.

use anyhow::{Context, Result};
use pavlov::config::SkeletonFormat;
use pavlov_actors::simulated::human::{SenderOptions, send_human};
use tokio_util::sync::CancellationToken;

use super::args::{parse_skeleton_format, shutdown_signal, skeleton_format_name};

/// `pavlov human`'s arguments.
#[derive(clap::Args)]
pub struct HumanArgs {
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
}

/// Sends until Ctrl-C, SIGTERM or `--frames`.
pub async fn run(args: HumanArgs) -> Result<()> {
    let HumanArgs {
        to,
        seed,
        format,
        realtime: _,
        fast,
        frames,
    } = args;
    let cancel = CancellationToken::new();
    let opts = SenderOptions {
        to,
        seed,
        format,
        realtime: !fast,
        frames,
    };
    say!(
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
    say!(
        "sent {} frames in {} datagrams ({} send errors); {} commands (ground truth)",
        report.frames,
        report.datagrams,
        report.send_errors,
        report.commands
    );
    Ok(())
}

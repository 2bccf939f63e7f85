//! `pavlov sim --pty`: the simulated Create on a pseudo-terminal that any OI client can open.

use anyhow::{Context, Result};
use pavlov::oi::Model;
use pavlov::sim::faults::{FaultInjector, FaultSpec};
use pavlov::sim::params::SimParams;
use pavlov::sim::robot::SimRobot;
use pavlov_actors::simulated::robot;
use tokio_util::sync::CancellationToken;

use super::args::shutdown_signal;

/// `pavlov sim`'s arguments.
#[derive(clap::Args)]
pub struct SimArgs {
    /// Create the PTY and print its path (the only transport for now; required).
    #[arg(long, required = true)]
    pty: bool,
    /// Robot model to simulate.
    #[arg(long, default_value = "create1", value_name = "MODEL")]
    model: Model,
    /// Seed of the simulation's random draws.
    #[arg(long, default_value_t = 1, value_name = "N")]
    seed: u64,
    /// Faults to inject: a preset (none, soak, all) or `key=value,...` (see the book, docs/src/faults.md).
    /// On a PTY an end-of-file cannot be signalled without destroying the device, so `eof` hangs instead.
    #[arg(long, default_value = "none", value_name = "SPEC")]
    faults: String,
}

/// Runs the simulator until Ctrl-C or SIGTERM, then prints its final state as one JSON line.
pub async fn run(args: SimArgs) -> Result<()> {
    let SimArgs {
        pty: _,
        model,
        seed,
        faults,
    } = args;
    let cancel = CancellationToken::new();
    let robot = SimRobot::new(model, SimParams::for_model(model), seed);
    let spec: FaultSpec = faults
        .parse()
        .with_context(|| format!("invalid --faults `{faults}`"))?;
    if !spec.is_none() {
        tracing::info!(faults = %spec.describe(), "injecting faults");
    }
    let injector = FaultInjector::new(spec, seed);
    let pty = robot::spawn_sim_pty(robot, injector, cancel.clone())
        .context("cannot start the simulated robot")?;
    let status = pty.status.clone();
    say!("{}", pty.path);
    tracing::info!(path = %pty.path, %model, seed, "simulated Create listening on a pseudo-terminal");
    shutdown_signal().await;
    cancel.cancel();
    let robot = pty.robot.await.context("the simulator task failed")?;
    // The robot's final state, one JSON line on stdout, so scripts and tests can check how it was left.
    let world = robot.world();
    let c = robot.counters();
    let injected = status.borrow().faults.clone();
    say!(
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

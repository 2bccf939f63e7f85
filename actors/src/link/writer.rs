//! The link writer actor: the only task that writes bytes to the robot.
//!
//! Actuation hands it whole commands through a bounded queue and never waits for the port. The writer
//! stamps when each motor command reached the OS (tick-to-command latency). On shut-down it writes the
//! stop/pause/Passive sequence, flushes, and closes its half of the link.

use std::sync::{Arc, Mutex};

use tokio::io::AsyncWriteExt;
use tokio::sync::mpsc;
use tokio::time::Instant;

use super::LinkWriter;
use crate::histogram::LatencyHistogram;

/// One write request.
#[derive(Debug)]
pub struct WriteRequest {
    /// The encoded command.
    pub bytes: Vec<u8>,
    /// The deadline of the tick that produced it, for the tick-to-command histogram.
    pub tick_deadline: Option<Instant>,
}

/// Counters of the writer.
#[derive(Default)]
pub struct WriterStats {
    /// Time from the tick's deadline to the motor command written to the OS.
    pub tick_to_command: LatencyHistogram,
    /// Write errors seen.
    pub errors: u64,
    /// Bytes written.
    pub bytes: u64,
}

/// Shared handle on the writer's statistics.
pub type SharedWriterStats = Arc<Mutex<WriterStats>>;

/// Runs until the request channel closes, then writes `shutdown` and closes the link.
pub async fn run(
    mut link: LinkWriter,
    mut requests: mpsc::Receiver<WriteRequest>,
    shutdown: Vec<u8>,
    stats: SharedWriterStats,
) {
    while let Some(req) = requests.recv().await {
        let res = async {
            link.write_all(&req.bytes).await?;
            link.flush().await
        }
        .await;
        let done = Instant::now();
        if let Ok(mut s) = stats.lock() {
            match res {
                Ok(()) => {
                    s.bytes += req.bytes.len() as u64;
                    if let Some(d) = req.tick_deadline {
                        s.tick_to_command.record(done.saturating_duration_since(d));
                    }
                }
                Err(ref e) => {
                    s.errors += 1;
                    tracing::warn!("robot link write failed: {e}");
                }
            }
        }
    }
    if let Err(e) = async {
        link.write_all(&shutdown).await?;
        link.flush().await?;
        link.shutdown().await
    }
    .await
    {
        tracing::error!("could not send the shut-down sequence to the robot: {e}");
    } else {
        tracing::info!("robot stopped, stream paused, OI back in Passive");
    }
}

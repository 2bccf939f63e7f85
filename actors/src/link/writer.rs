//! The link writer actor: the only task that writes bytes to the robot.
//!
//! Actuation hands it whole commands through a bounded queue and never waits for the port. Link
//! supervision has a second, priority queue ([`WriterControl`]): bytes to send first (re-sync, re-arm) and
//! a freshly reopened port to switch to, with the start-up sequence to send on it. A write that the port
//! does not take within [`WRITE_TIMEOUT`] is abandoned and counted, so a hung port never holds the queue.
//! The writer stamps when each motor command reached the OS (tick-to-command latency). On shut-down it
//! writes the stop/pause/Passive sequence, flushes, and closes its half of the link.

use std::time::Duration;

use tokio::io::AsyncWriteExt;
use tokio::sync::mpsc;
use tokio::time::Instant;

use super::LinkWriter;
use crate::telemetry::counters::SharedWriterStats;

/// One write request.
#[derive(Debug)]
pub(crate) struct WriteRequest {
    /// The encoded command.
    pub(crate) bytes: Vec<u8>,
    /// The deadline of the tick that produced it, for the tick-to-command histogram.
    pub(crate) tick_deadline: Option<Instant>,
}

/// A write that takes longer than this is abandoned (the port is hung; supervision will reopen it).
pub(crate) const WRITE_TIMEOUT: Duration = Duration::from_millis(200);

/// Link supervision's requests, served before any motor command.
pub(crate) enum WriterControl {
    /// Send these bytes now (Start and Stream again, or the mode after a re-arm).
    Send(Vec<u8>),
    /// Close the port now (a serial device is opened exclusively, so it must be closed before it can be
    /// reopened); writes go nowhere until [`WriterControl::Replace`]. The sender learns when it is closed.
    Close(tokio::sync::oneshot::Sender<()>),
    /// Switch to a reopened port and send `startup` on it; the old port is closed.
    Replace {
        /// The new port's host-to-robot half.
        link: LinkWriter,
        /// The start-up sequence.
        startup: Vec<u8>,
    },
}

/// Runs until the request channel closes, then writes `shutdown` and closes the link.
pub(crate) async fn run(
    mut link: LinkWriter,
    mut requests: mpsc::Receiver<WriteRequest>,
    mut control: mpsc::Receiver<WriterControl>,
    shutdown: Vec<u8>,
    stats: SharedWriterStats,
) {
    let mut control_open = true;
    loop {
        tokio::select! {
            biased;
            c = control.recv(), if control_open => match c {
                Some(WriterControl::Send(bytes)) => {
                    let res = write_bounded(&mut link, &bytes).await;
                    count(&stats, &res, bytes.len(), None, Instant::now());
                }
                Some(WriterControl::Close(done)) => {
                    link = Box::new(tokio::io::sink());
                    let _ = done.send(());
                }
                Some(WriterControl::Replace { link: fresh, startup }) => {
                    // Dropping the old half closes it; a port that has hung is simply abandoned.
                    link = fresh;
                    if let Ok(mut s) = stats.lock() {
                        s.replaced += 1;
                    }
                    let res = write_bounded(&mut link, &startup).await;
                    count(&stats, &res, startup.len(), None, Instant::now());
                }
                None => control_open = false,
            },
            req = requests.recv() => {
                let Some(req) = req else { break };
                let res = write_bounded(&mut link, &req.bytes).await;
                count(&stats, &res, req.bytes.len(), req.tick_deadline, Instant::now());
            }
        }
    }
    if let Err(e) = async {
        tokio::time::timeout(WRITE_TIMEOUT, async {
            link.write_all(&shutdown).await?;
            link.flush().await?;
            link.shutdown().await
        })
        .await
        .map_err(|_| std::io::Error::new(std::io::ErrorKind::TimedOut, "the port took nothing"))?
    }
    .await
    {
        tracing::error!("could not send the shut-down sequence to the robot: {e}");
    } else {
        tracing::info!("robot stopped, stream paused, OI back in Passive");
    }
}

/// The outcome of one write.
enum WriteOutcome {
    Done,
    Failed(std::io::Error),
    TimedOut,
}

async fn write_bounded(link: &mut LinkWriter, bytes: &[u8]) -> WriteOutcome {
    let write = async {
        link.write_all(bytes).await?;
        link.flush().await
    };
    match tokio::time::timeout(WRITE_TIMEOUT, write).await {
        Ok(Ok(())) => WriteOutcome::Done,
        Ok(Err(e)) => WriteOutcome::Failed(e),
        Err(_) => WriteOutcome::TimedOut,
    }
}

fn count(
    stats: &SharedWriterStats,
    res: &WriteOutcome,
    len: usize,
    deadline: Option<Instant>,
    done: Instant,
) {
    let Ok(mut s) = stats.lock() else { return };
    match res {
        WriteOutcome::Done => {
            s.bytes += len as u64;
            if let Some(d) = deadline {
                s.tick_to_command.record(done.saturating_duration_since(d));
            }
        }
        WriteOutcome::Failed(e) => {
            s.errors += 1;
            // Every tick writes; while the link is down only the first few failures are worth a line.
            if s.errors <= 3 || s.errors.is_power_of_two() {
                tracing::warn!(errors = s.errors, "robot link write failed: {e}");
            }
        }
        WriteOutcome::TimedOut => {
            s.timeouts += 1;
            if s.timeouts <= 3 || s.timeouts.is_power_of_two() {
                tracing::warn!(timeouts = s.timeouts, "robot link write timed out");
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use tokio::io::AsyncReadExt;

    #[tokio::test(start_paused = true)]
    async fn a_hung_port_times_out_and_a_replacement_takes_over() {
        // A port with a 4-byte buffer whose far end never reads: the second command cannot be written.
        let (hung, _far_end) = tokio::io::duplex(4);
        let (req_tx, req_rx) = mpsc::channel(16);
        let (ctl_tx, ctl_rx) = mpsc::channel(4);
        let stats = SharedWriterStats::default();
        let writer = tokio::spawn(run(
            Box::new(hung),
            req_rx,
            ctl_rx,
            vec![9, 9],
            stats.clone(),
        ));
        for _ in 0..2 {
            let bytes = vec![145, 0, 0, 0, 0];
            req_tx
                .send(WriteRequest {
                    bytes,
                    tick_deadline: None,
                })
                .await
                .unwrap();
        }
        tokio::time::sleep(WRITE_TIMEOUT * 3).await;
        assert!(
            stats.lock().unwrap().timeouts >= 1,
            "the hung write did not time out"
        );

        // Supervision switches to a fresh port: the start-up sequence goes out first, then commands.
        let (fresh, mut robot) = tokio::io::duplex(1024);
        ctl_tx
            .send(WriterControl::Replace {
                link: Box::new(fresh),
                startup: vec![128, 131],
            })
            .await
            .unwrap();
        req_tx
            .send(WriteRequest {
                bytes: vec![145, 0, 1, 0, 1],
                tick_deadline: None,
            })
            .await
            .unwrap();
        drop(req_tx);
        writer.await.unwrap();
        let mut got = Vec::new();
        robot.read_to_end(&mut got).await.unwrap();
        // Start-up, the command, then the shut-down sequence.
        assert_eq!(got, vec![128, 131, 145, 0, 1, 0, 1, 9, 9]);
        assert_eq!(stats.lock().unwrap().replaced, 1);
    }
}

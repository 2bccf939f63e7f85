//! The bridge's queryables: `pavlov/<robot>/config`, `pavlov/<robot>/checkpoint` and
//! `pavlov/<robot>/command`.
//!
//! A command query's payload is JSON `{"token": "…", "command": {"cmd": "set_mode", "mode": "manual"}}`
//! (the command as the websocket takes it, `web/PROTOCOL.md`). The answer is a reply
//! `{"ok": true, "result": …}` with what the owner applied, or an error reply
//! `{"ok": false, "error": CODE, "message": …}` with CODE one of `off` (`[zenoh] commands = false`),
//! `token` (missing or wrong), `invalid` (not such a message), or the websocket's `busy`, `rejected`,
//! `unavailable`. Every outcome is counted (`pavlov_zenoh_commands_total{outcome}`).
//!
//! A checkpoint is read and sent by a task of its own, one at a time, so a large file never holds up a
//! command (an e-stop) behind it: a checkpoint query while one is being sent is answered `busy`, and a
//! file larger than [`MAX_CHECKPOINT_REPLY_BYTES`] with an error naming its size.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use serde::Deserialize;
use serde_json::json;
use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;
use zenoh::Session;
use zenoh::handlers::FifoChannelHandler;
use zenoh::query::{Query, Queryable};

use super::{ZenohError, key};
use crate::command::{ControlCommand, ControlRequest};
use crate::dashboard::auth::constant_time_eq;
use crate::server::Server;
use crate::telemetry::counters::ZenohCounters;

/// How long a command may take to be answered by its owner.
const COMMAND_TIMEOUT: Duration = Duration::from_secs(2);
/// The largest command message, bytes.
const MAX_COMMAND_BYTES: usize = 4096;
/// The largest checkpoint file sent in a reply, bytes (an agent's checkpoint with the largest allowed
/// weight tables is a few MB).
pub(crate) const MAX_CHECKPOINT_REPLY_BYTES: u64 = 64 * 1024 * 1024;

type Q = Queryable<FifoChannelHandler<Query>>;

/// The three queryables.
pub(crate) struct Queryables {
    config: Q,
    checkpoint: Q,
    command: Q,
}

/// Declares the queryables of `robot` on `session`.
pub(crate) async fn declare(session: Session, robot: String) -> Result<Queryables, ZenohError> {
    let declare = |leaf: &str| {
        let k = key(&robot, leaf);
        let session = session.clone();
        async move {
            session
                .declare_queryable(k.clone())
                .await
                .map_err(|e| ZenohError::Declare {
                    key: k,
                    reason: e.to_string(),
                })
        }
    };
    Ok(Queryables {
        config: declare("config").await?,
        checkpoint: declare("checkpoint").await?,
        command: declare("command").await?,
    })
}

/// What the queryables answer with.
pub(crate) struct Answers {
    config: Vec<u8>,
    run_dir: Option<PathBuf>,
    token: Option<String>,
    commands_on: bool,
    commands: mpsc::Sender<ControlRequest>,
    counters: Arc<ZenohCounters>,
}

/// A command query's payload.
#[derive(Deserialize)]
#[serde(deny_unknown_fields)]
struct CommandMessage {
    #[serde(default)]
    token: Option<String>,
    command: ControlCommand,
}

/// The newest automatic checkpoint in `dir`, if not larger than [`MAX_CHECKPOINT_REPLY_BYTES`].
pub(crate) async fn newest_checkpoint(dir: Option<&Path>) -> Result<Vec<u8>, String> {
    let Some(dir) = dir else {
        return Err("this server writes no checkpoints".into());
    };
    let list = crate::storage::checkpoint_files::list(dir)
        .map_err(|e| format!("cannot list {}: {e}", dir.display()))?;
    let Some((_, newest)) = list.last() else {
        return Err(format!("no checkpoint in {} yet", dir.display()));
    };
    let size = tokio::fs::metadata(newest)
        .await
        .map_err(|e| format!("cannot read {}: {e}", newest.display()))?
        .len();
    if size > MAX_CHECKPOINT_REPLY_BYTES {
        return Err(format!(
            "{} is {size} bytes, more than the {MAX_CHECKPOINT_REPLY_BYTES} a reply may carry; copy it \
             from the robot's disk instead",
            newest.display()
        ));
    }
    tokio::fs::read(newest)
        .await
        .map_err(|e| format!("cannot read {}: {e}", newest.display()))
}

/// A refusal: its code and message.
struct Refusal(&'static str, String);

impl Answers {
    /// The answers for `server`.
    pub(crate) fn new(server: &Server, counters: Arc<ZenohCounters>) -> Answers {
        let mut config = server.config.clone();
        if config.dashboard.token.is_some() {
            config.dashboard.token = Some("<redacted>".into());
        }
        let message = json!({
            "program": format!("pavlov {}", env!("CARGO_PKG_VERSION")),
            "config": config,
            "obs_names": server.obs_names,
        });
        Answers {
            config: serde_json::to_vec(&message).unwrap_or_default(),
            run_dir: server.checkpoints.run_dir.clone(),
            token: server.config.dashboard.token.clone(),
            commands_on: server.config.zenoh.commands,
            commands: server.commands.clone(),
            counters,
        }
    }

    /// Answers queries until `cancel`.
    pub(crate) async fn run(self, q: Queryables, cancel: CancellationToken) {
        let sending = Arc::new(AtomicBool::new(false));
        loop {
            tokio::select! {
                _ = cancel.cancelled() => break,
                Ok(query) = q.config.recv_async() => {
                    self.counters.queries.fetch_add(1, Ordering::Relaxed);
                    let _ = query.reply(query.key_expr().clone(), self.config.clone()).await;
                }
                Ok(query) = q.checkpoint.recv_async() => {
                    self.counters.queries.fetch_add(1, Ordering::Relaxed);
                    if sending.swap(true, Ordering::AcqRel) {
                        let _ = query.reply_err("busy: a checkpoint is being sent; ask again").await;
                        continue;
                    }
                    let (dir, sending) = (self.run_dir.clone(), sending.clone());
                    tokio::spawn(async move {
                        match newest_checkpoint(dir.as_deref()).await {
                            Ok(bytes) => { let _ = query.reply(query.key_expr().clone(), bytes).await; }
                            Err(why) => { let _ = query.reply_err(why).await; }
                        }
                        sending.store(false, Ordering::Release);
                    });
                }
                Ok(query) = q.command.recv_async() => {
                    let payload = query.payload().map(|p| p.to_bytes().into_owned()).unwrap_or_default();
                    match self.command(&payload).await {
                        Ok(answer) => { let _ = query.reply(query.key_expr().clone(), answer).await; }
                        Err(Refusal(code, message)) => {
                            tracing::info!("zenoh: command refused ({code}): {message}");
                            let body = json!({ "ok": false, "error": code, "message": message });
                            let _ = query.reply_err(body.to_string()).await;
                        }
                    }
                }
            }
        }
    }

    fn count(&self, c: &AtomicU64) {
        c.fetch_add(1, Ordering::Relaxed);
    }

    async fn command(&self, payload: &[u8]) -> Result<String, Refusal> {
        if !self.commands_on {
            self.count(&self.counters.commands_refused_off);
            return Err(Refusal(
                "off",
                "commands over Zenoh are off on this robot ([zenoh] commands = false)".into(),
            ));
        }
        if payload.len() > MAX_COMMAND_BYTES {
            self.count(&self.counters.commands_refused_invalid);
            return Err(Refusal(
                "invalid",
                format!(
                    "the command message is {} bytes, more than {MAX_COMMAND_BYTES}",
                    payload.len()
                ),
            ));
        }
        let message: CommandMessage = match serde_json::from_slice(payload) {
            Ok(m) => m,
            Err(e) => {
                self.count(&self.counters.commands_refused_invalid);
                return Err(Refusal(
                    "invalid",
                    format!("expected {{\"token\": …, \"command\": {{\"cmd\": …}}}}: {e}"),
                ));
            }
        };
        // The token is checked before anything of the command is acted on.
        let expected = self.token.as_deref().unwrap_or_default();
        let good = message.token.as_deref().is_some_and(|t| {
            !expected.is_empty() && constant_time_eq(t.as_bytes(), expected.as_bytes())
        });
        if !good {
            self.count(&self.counters.commands_refused_token);
            let why = if message.token.is_none() {
                "the command carries no token (\"token\": the dashboard's token)"
            } else {
                "the token is wrong"
            };
            return Err(Refusal("token", why.into()));
        }
        let (request, reply) = ControlRequest::new(message.command);
        if self.commands.try_send(request).is_err() {
            self.count(&self.counters.commands_failed);
            return Err(Refusal(
                "busy",
                "the command queue is full; try again".into(),
            ));
        }
        match tokio::time::timeout(COMMAND_TIMEOUT, reply).await {
            Ok(Ok(Ok(applied))) => {
                self.count(&self.counters.commands_applied);
                Ok(json!({ "ok": true, "result": applied }).to_string())
            }
            Ok(Ok(Err(e))) => {
                self.count(&self.counters.commands_failed);
                Err(Refusal(e.code(), e.to_string()))
            }
            Ok(Err(_)) | Err(_) => {
                self.count(&self.counters.commands_failed);
                Err(Refusal(
                    "unavailable",
                    format!("no answer from the server within {COMMAND_TIMEOUT:?}"),
                ))
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("pavlov-zenoh-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).expect("temp dir");
        d
    }

    #[tokio::test]
    async fn the_newest_checkpoint_is_sent_and_an_oversized_one_refused() {
        assert!(
            newest_checkpoint(None)
                .await
                .unwrap_err()
                .contains("no checkpoints")
        );
        let d = dir("checkpoint");
        let why = newest_checkpoint(Some(&d)).await.unwrap_err();
        assert!(why.contains("no checkpoint in"), "{why}");
        std::fs::write(d.join("checkpoint-5.json"), b"old").unwrap();
        std::fs::write(d.join("checkpoint-12.json"), b"new").unwrap();
        assert_eq!(newest_checkpoint(Some(&d)).await.unwrap(), b"new");
        // A sparse file: its length is past the limit without writing 64 MB.
        let big = std::fs::File::create(d.join("checkpoint-20.json")).unwrap();
        big.set_len(MAX_CHECKPOINT_REPLY_BYTES + 1).unwrap();
        let why = newest_checkpoint(Some(&d)).await.unwrap_err();
        assert!(
            why.contains(&format!("{} bytes", MAX_CHECKPOINT_REPLY_BYTES + 1)),
            "{why}"
        );
        let _ = std::fs::remove_dir_all(&d);
    }
}

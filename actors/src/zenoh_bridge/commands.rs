//! The bridge's queryables: `pavlov/<robot>/config`, `pavlov/<robot>/checkpoint` and
//! `pavlov/<robot>/command`.
//!
//! A command query's payload is JSON `{"token": "…", "command": {"cmd": "set_mode", "mode": "manual"}}`
//! (the command as the websocket takes it, `web/PROTOCOL.md`). The answer is a reply
//! `{"ok": true, "result": …}` with what the owner applied, or an error reply
//! `{"ok": false, "error": CODE, "message": …}` with CODE one of `off` (`[zenoh] commands = false`),
//! `token` (missing or wrong), `invalid` (not such a message), or the websocket's `busy`, `rejected`,
//! `unavailable`. Every outcome is counted (`pavlov_zenoh_commands_total{outcome}`).

use std::path::PathBuf;
use std::sync::Arc;
use std::sync::atomic::{AtomicU64, Ordering};
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
        loop {
            tokio::select! {
                _ = cancel.cancelled() => break,
                Ok(query) = q.config.recv_async() => {
                    self.counters.queries.fetch_add(1, Ordering::Relaxed);
                    let _ = query.reply(query.key_expr().clone(), self.config.clone()).await;
                }
                Ok(query) = q.checkpoint.recv_async() => {
                    self.counters.queries.fetch_add(1, Ordering::Relaxed);
                    match self.newest_checkpoint().await {
                        Ok(bytes) => { let _ = query.reply(query.key_expr().clone(), bytes).await; }
                        Err(why) => { let _ = query.reply_err(why).await; }
                    }
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

    async fn newest_checkpoint(&self) -> Result<Vec<u8>, String> {
        let Some(dir) = &self.run_dir else {
            return Err("this server writes no checkpoints".into());
        };
        let list = crate::storage::checkpoint_files::list(dir)
            .map_err(|e| format!("cannot list {}: {e}", dir.display()))?;
        let Some((_, newest)) = list.last() else {
            return Err(format!("no checkpoint in {} yet", dir.display()));
        };
        tokio::fs::read(newest)
            .await
            .map_err(|e| format!("cannot read {}: {e}", newest.display()))
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

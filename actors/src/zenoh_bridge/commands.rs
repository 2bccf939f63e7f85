//! The bridge's queryables: `pavlov/v1/<robot>/config`, `pavlov/v1/<robot>/checkpoint` and
//! `pavlov/v1/<robot>/command`.
//!
//! Every reply is made under the robot's own key, not the query's (a query `pavlov/v1/*/config` gets one
//! reply per robot, each under `pavlov/v1/<robot>/config`, which Zenoh's default consolidation keeps
//! apart), and declares `application/json`. Zenoh's error replies carry no key, so each error reply's
//! JSON names the robot and the key: `{"ok": false, "robot": …, "key": …, "error": CODE, "message": …}`.
//!
//! A command query's payload is JSON `{"token": "…", "command": {"cmd": "set_mode", "mode": "manual"}}`
//! (the command as the websocket takes it, `web/PROTOCOL.md`). The answer is a reply
//! `{"ok": true, "result": …}` with what the owner applied, or an error reply
//! `{"ok": false, "robot": …, "key": …, "error": CODE, "message": …}` with CODE one of `off` (`[zenoh] commands = false`),
//! `token` (missing or wrong), `invalid` (not such a message), or the websocket's `busy`, `rejected`,
//! `unavailable`. Every outcome is counted (`pavlov_zenoh_commands_total{outcome}`).
//!
//! A checkpoint is read and sent by a task of its own, one at a time, so a large file never holds up a
//! command (an e-stop) behind it: a checkpoint query while one is being sent is answered `busy`, and a
//! file larger than [`MAX_CHECKPOINT_REPLY_BYTES`] with an error naming its size. Commands are
//! checked and handed to their owner in the order they arrive, and only the wait for the owner's outcome
//! (up to [`COMMAND_TIMEOUT`]) runs in a task of its own, at most [`MAX_COMMANDS_IN_FLIGHT`] at once (a
//! command beyond them is answered `busy` and not applied): a slow command never holds up the next one,
//! e.g. an e-stop, and two commands are never applied out of order.

use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, AtomicU64, Ordering};
use std::time::Duration;

use serde::Deserialize;
use serde_json::json;
use tokio::sync::{mpsc, oneshot};
use tokio_util::sync::CancellationToken;
use zenoh::Session;
use zenoh::handlers::FifoChannelHandler;
use zenoh::query::{Query, Queryable};

use super::{ZenohError, key, wire};
#[cfg(test)]
use crate::command::{CommandError, LatchCommand};
use crate::command::{ControlCommand, ControlRequest, Outcome};
use crate::dashboard::auth::constant_time_eq;
use crate::server::Server;
use crate::telemetry::counters::ZenohCounters;

/// How long a command may take to be answered by its owner.
const COMMAND_TIMEOUT: Duration = Duration::from_secs(2);
/// The largest command message, bytes.
const MAX_COMMAND_BYTES: usize = 4096;
/// Commands being answered at once; a command beyond them is answered `busy`.
const MAX_COMMANDS_IN_FLIGHT: usize = 8;
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
    robot: String,
    /// The session, for its clock: replies are stamped with its HLC.
    clock: Session,
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
    /// The answers for `server`, stamped with `session`'s clock.
    pub(crate) fn new(server: &Server, session: Session, counters: Arc<ZenohCounters>) -> Answers {
        let config = server.config().redacted();
        let message = json!({
            "program": crate::provenance::BUILD.program(),
            "config": config,
            "obs_names": server.obs_names(),
        });
        Answers {
            robot: server.config().zenoh.robot.clone(),
            clock: session,
            config: serde_json::to_vec(&message).unwrap_or_default(),
            run_dir: server.checkpoints().run_dir.clone(),
            token: server.config().dashboard.token.clone(),
            commands_on: server.config().zenoh.commands,
            commands: server.commands().clone(),
            counters,
        }
    }

    /// Answers queries until `cancel`.
    pub(crate) async fn run(self, q: Queryables, cancel: CancellationToken) {
        let sending = Arc::new(AtomicBool::new(false));
        let in_flight = Arc::new(tokio::sync::Semaphore::new(MAX_COMMANDS_IN_FLIGHT));
        let this = Arc::new(self);
        loop {
            tokio::select! {
                _ = cancel.cancelled() => break,
                Ok(query) = q.config.recv_async() => {
                    this.counters.queries.fetch_add(1, Ordering::Relaxed);
                    this.reply(&query, "config", this.config.clone()).await;
                }
                Ok(query) = q.checkpoint.recv_async() => {
                    this.counters.queries.fetch_add(1, Ordering::Relaxed);
                    if sending.swap(true, Ordering::AcqRel) {
                        let busy = Refusal("busy", "a checkpoint is being sent; ask again".into());
                        this.refuse(&query, "checkpoint", busy).await;
                        continue;
                    }
                    let (this, sending) = (this.clone(), sending.clone());
                    tokio::spawn(async move {
                        match newest_checkpoint(this.run_dir.as_deref()).await {
                            Ok(bytes) => this.reply(&query, "checkpoint", bytes).await,
                            Err(why) => {
                                this.refuse(&query, "checkpoint", Refusal("unavailable", why)).await;
                            }
                        }
                        sending.store(false, Ordering::Release);
                    });
                }
                Ok(query) = q.command.recv_async() => {
                    // Checked and handed to the owner here, in arrival order; only the wait for the
                    // owner's outcome runs apart, so a slow one never holds up the next command.
                    let Ok(permit) = in_flight.clone().try_acquire_owned() else {
                        this.count(&this.counters.commands_failed);
                        let busy = format!("{MAX_COMMANDS_IN_FLIGHT} commands are being answered; try again");
                        this.answer(&query, Err(Refusal("busy", busy))).await;
                        continue;
                    };
                    let payload = query.payload().map(|p| p.to_bytes().into_owned()).unwrap_or_default();
                    match this.submit(&payload) {
                        Err(refusal) => this.answer(&query, Err(refusal)).await,
                        Ok(reply) => {
                            let this = this.clone();
                            tokio::spawn(async move {
                                let outcome = this.outcome(reply).await;
                                this.answer(&query, outcome).await;
                                drop(permit);
                            });
                        }
                    }
                }
            }
        }
    }

    /// Replies `bytes` to `query` under this robot's key `leaf`, declaring JSON, with a timestamp.
    async fn reply(&self, query: &Query, leaf: &str, bytes: impl Into<zenoh::bytes::ZBytes>) {
        let k = key(&self.robot, leaf);
        if let Err(e) = query
            .reply(k.clone(), bytes)
            .encoding(wire::json_encoding())
            .timestamp(self.clock.new_timestamp())
            .await
        {
            tracing::debug!("zenoh: reply on {k} failed: {e}");
        }
    }

    /// The error reply's body for `refusal` on `leaf`: JSON naming the robot and the key.
    fn refusal_body(&self, leaf: &str, Refusal(code, message): Refusal) -> String {
        json!({
            "ok": false,
            "robot": self.robot,
            "key": key(&self.robot, leaf),
            "error": code,
            "message": message,
        })
        .to_string()
    }

    /// An error reply to `query` on `leaf`.
    async fn refuse(&self, query: &Query, leaf: &str, refusal: Refusal) {
        let body = self.refusal_body(leaf, refusal);
        let _ = query.reply_err(body).encoding(wire::json_encoding()).await;
    }

    /// Answers a command `query` with `answer`: a reply, or an error reply with the refusal's code and
    /// message.
    async fn answer(&self, query: &Query, answer: Result<String, Refusal>) {
        match answer {
            Ok(answer) => self.reply(query, "command", answer).await,
            Err(refusal) => {
                tracing::info!("zenoh: command refused ({}): {}", refusal.0, refusal.1);
                self.refuse(query, "command", refusal).await;
            }
        }
    }

    fn count(&self, c: &AtomicU64) {
        c.fetch_add(1, Ordering::Relaxed);
    }

    /// Checks a command query's payload and hands the command to its owner, in the order queries arrive;
    /// the receiver of the owner's outcome.
    fn submit(&self, payload: &[u8]) -> Result<oneshot::Receiver<Outcome>, Refusal> {
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
        Ok(reply)
    }

    /// Waits for the owner's outcome of a submitted command.
    async fn outcome(&self, reply: oneshot::Receiver<Outcome>) -> Result<String, Refusal> {
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

    /// A Zenoh session on its own: no endpoints, no scouting (queries reach its own queryables).
    async fn lone_session() -> Session {
        let text = r#"{ mode: "peer", listen: { endpoints: [] },
            scouting: { multicast: { enabled: false }, gossip: { enabled: false } } }"#;
        let config = zenoh::Config::from_json5(text).expect("config");
        zenoh::open(config).await.expect("session")
    }

    /// Sends `command` with `token` to robot `t`; the reply's text, or the error reply's.
    async fn ask(
        session: &Session,
        token: &str,
        command: serde_json::Value,
    ) -> Result<String, String> {
        let body = json!({ "token": token, "command": command }).to_string();
        let replies = session
            .get("pavlov/v1/t/command")
            .payload(body)
            .timeout(Duration::from_secs(10))
            .await
            .expect("query");
        let reply = replies.recv_async().await.expect("a reply");
        let text = |b: Vec<u8>| String::from_utf8_lossy(&b).into_owned();
        match reply.result() {
            Ok(sample) => {
                assert_eq!(sample.key_expr().as_str(), "pavlov/v1/t/command");
                assert_eq!(sample.encoding(), &wire::json_encoding());
                Ok(text(sample.payload().to_bytes().into_owned()))
            }
            Err(e) => {
                assert_eq!(e.encoding(), &wire::json_encoding());
                Err(text(e.payload().to_bytes().into_owned()))
            }
        }
    }

    /// The answers of robot `robot` with commands off.
    fn answers_of(robot: &str, session: &Session) -> Answers {
        let (tx, _) = mpsc::channel::<ControlRequest>(1);
        Answers {
            robot: robot.into(),
            clock: session.clone(),
            config: format!(r#"{{"robot": "{robot}"}}"#).into_bytes(),
            run_dir: None,
            token: None,
            commands_on: false,
            commands: tx,
            counters: Arc::new(ZenohCounters::default()),
        }
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_wildcard_query_gets_one_reply_per_robot_under_its_own_key() {
        let session = lone_session().await;
        let cancel = CancellationToken::new();
        for robot in ["a", "b", "c"] {
            let q = declare(session.clone(), robot.into())
                .await
                .expect("declare");
            tokio::spawn(answers_of(robot, &session).run(q, cancel.clone()));
        }
        // Zenoh's default consolidation: replies under one key would be merged into one.
        let replies = session
            .get("pavlov/v1/*/config")
            .timeout(Duration::from_secs(10))
            .await
            .expect("query");
        let mut keys = Vec::new();
        while let Ok(reply) = replies.recv_async().await {
            let sample = reply.result().expect("a reply, not an error");
            assert_eq!(sample.encoding(), &wire::json_encoding());
            assert!(sample.timestamp().is_some(), "a stamped reply");
            keys.push(sample.key_expr().as_str().to_string());
        }
        keys.sort();
        assert_eq!(
            keys,
            [
                "pavlov/v1/a/config",
                "pavlov/v1/b/config",
                "pavlov/v1/c/config"
            ]
        );
        // Error replies name who refused: commands are off on every one of them.
        let replies = session
            .get("pavlov/v1/*/command")
            .payload(r#"{"command": {"cmd": "estop"}}"#)
            .timeout(Duration::from_secs(10))
            .await
            .expect("query");
        let mut robots = Vec::new();
        while let Ok(reply) = replies.recv_async().await {
            let err = reply.result().expect_err("an error reply");
            let body: serde_json::Value =
                serde_json::from_slice(&err.payload().to_bytes()).expect("JSON");
            assert_eq!(body["error"], "off");
            assert_eq!(
                body["key"],
                format!(
                    "pavlov/v1/{}/command",
                    body["robot"].as_str().unwrap_or("?")
                )
            );
            robots.push(body["robot"].as_str().unwrap_or_default().to_string());
        }
        robots.sort();
        assert_eq!(robots, ["a", "b", "c"]);
        cancel.cancel();
        let _ = session.close().await;
    }

    #[tokio::test(flavor = "multi_thread", worker_threads = 2)]
    async fn a_slow_command_holds_up_neither_the_next_nor_their_order() {
        let session = lone_session().await;
        let queryables = declare(session.clone(), "t".into()).await.expect("declare");
        let (tx, mut owner) = mpsc::channel::<ControlRequest>(8);
        let answers = Answers {
            robot: "t".into(),
            clock: session.clone(),
            config: Vec::new(),
            run_dir: None,
            token: Some("the-right-token-0123".into()),
            commands_on: true,
            commands: tx,
            counters: Arc::new(ZenohCounters::default()),
        };
        let cancel = CancellationToken::new();
        tokio::spawn(answers.run(queryables, cancel.clone()));
        let token = "the-right-token-0123";

        // The first command reaches its owner, which does not answer yet.
        let first = tokio::spawn({
            let s = session.clone();
            async move { ask(&s, token, json!({ "cmd": "estop" })).await }
        });
        let held = owner.recv().await.expect("the first command");
        assert_eq!(held.command, LatchCommand::Estop {}.into());
        // The second is answered while the first still waits, and reached the owner after it.
        let second = tokio::spawn({
            let s = session.clone();
            async move { ask(&s, token, json!({ "cmd": "release" })).await }
        });
        let next = tokio::time::timeout(Duration::from_secs(10), owner.recv())
            .await
            .expect("the second command waited behind the first")
            .expect("the second command");
        assert_eq!(next.command, LatchCommand::Release {}.into());
        let _ = next
            .reply
            .send(Err(CommandError::Rejected("second, refused".into())));
        let answer = second.await.expect("task").unwrap_err();
        assert!(answer.contains("second, refused"), "{answer}");
        let refusal: serde_json::Value = serde_json::from_str(&answer).expect("JSON");
        assert_eq!(refusal["robot"], "t");
        assert_eq!(refusal["key"], "pavlov/v1/t/command");
        assert!(
            !first.is_finished(),
            "the first was answered before its owner did"
        );
        // A wrong token is refused at once, and never reaches the owner.
        let wrong = ask(&session, "wrong", json!({ "cmd": "estop" }))
            .await
            .unwrap_err();
        assert!(wrong.contains("the token is wrong"), "{wrong}");
        assert!(owner.try_recv().is_err());
        // The first is answered when its owner answers.
        let _ = held
            .reply
            .send(Err(CommandError::Rejected("first, refused".into())));
        let answer = first.await.expect("task").unwrap_err();
        assert!(answer.contains("first, refused"), "{answer}");
        cancel.cancel();
        let _ = session.close().await;
    }
}

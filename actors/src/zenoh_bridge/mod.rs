//! `pavlov serve --zenoh [CONFIG]`: this robot on Zenoh, so a lab's robots can be watched and commanded
//! from one place (`pavlov fleet`, or anything that speaks Zenoh, e.g. next to ROS 2's rmw_zenoh).
//!
//! Keys, with `<robot>` = `[zenoh] robot` (one key-expression chunk, checked at start-up) and `v1` the
//! wire format's version (the conventions, encodings and settings are in [`wire`]):
//! - `pavlov/v1/<robot>/tick`: every [`TickRecord`](pavlov::record::TickRecord) as JSON (put, dropped by
//!   Zenoh under congestion rather than queued; the attachment numbers the puts, so a gap is visible);
//! - `pavlov/v1/<robot>/event`: every [`Event`](pavlov::event::Event) as JSON;
//! - `pavlov/v1/<robot>/status`: every `[zenoh] status_every_ms`, the fleet's row (`status`): mode, link,
//!   tick health, key counters, the dashboard's URL;
//! - `pavlov/v1/<robot>/alive`: a liveliness token, held while the bridge runs (presence);
//! - `pavlov/v1/<robot>/config` (query): the configuration in force, token redacted;
//! - `pavlov/v1/<robot>/checkpoint` (query): this run's newest automatic checkpoint file, or an error reply;
//! - `pavlov/v1/<robot>/command` (query): a command (`commands`), answered with the outcome.
//!
//! Every reply is made under the robot's own key (so a wildcard query gets one reply per robot under
//! Zenoh's default consolidation), and every error reply is JSON naming the robot and the key.
//!
//! Commands are off unless `[zenoh] commands = true`, and then each must carry the dashboard's token (so
//! a token must be configured): one secret for the websocket and Zenoh, checked in constant time, counted
//! per outcome in `/metrics`. Zenoh's own access control was not chosen: its rules match interfaces,
//! usernames or TLS certificate names, which need Zenoh's authentication (user/password or TLS, left out
//! of this build) to mean anything on a shared lab network, and a second set of credentials to manage.
//!
//! Nothing here can delay the tick: the publisher reads the feed's and the event log's lossy broadcasts
//! (bounded rings that drop the oldest; what it loses is counted as `pavlov_zenoh_missed_total`) without
//! waiting on them, waking half a tick period away from the tick (`publish`), and the bridge runs on a
//! runtime of its own (one worker thread, `zenoh-bridge`) besides Zenoh's own threads.

pub(crate) mod commands;
pub(crate) mod publish;
pub(crate) mod status;
pub mod wire;

use std::path::Path;
use std::sync::Arc;
use std::time::Duration;

use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

use crate::server::Server;
use crate::telemetry::counters::{ZenohCounters, ZenohFigures};

pub use wire::{KEY_ROOT, key};

/// Errors starting the bridge.
#[derive(Debug, thiserror::Error)]
pub enum ZenohError {
    /// The Zenoh configuration file could not be read or is invalid.
    #[error("--zenoh {path}: {reason}")]
    Config {
        /// The file.
        path: String,
        /// Zenoh's message (it names the key).
        reason: String,
    },
    /// Commands are on but no token is configured.
    #[error(
        "[zenoh] commands = true needs a token (--token or [dashboard] token): Zenoh peers are not \
         limited to this machine, so commands over Zenoh always need one"
    )]
    CommandsNeedToken,
    /// Commands are on but the token is weak enough to guess (too short, or too little variety).
    #[error(
        "[zenoh] commands = true {0}; Zenoh peers are not limited to this machine, and wrong tokens \
         are counted, not throttled"
    )]
    CommandsNeedStrongToken(String),
    /// The session could not be opened (e.g. a listen endpoint in use).
    #[error("cannot open the Zenoh session: {0}")]
    Open(String),
    /// A publisher or queryable could not be declared.
    #[error("cannot declare {key} on Zenoh: {reason}")]
    Declare {
        /// The key.
        key: String,
        /// Zenoh's message.
        reason: String,
    },
    /// The bridge's runtime could not be created.
    #[error("cannot start the Zenoh bridge's runtime: {0}")]
    Runtime(std::io::Error),
}

/// Zenoh's configuration: the file `path` (Zenoh's own JSON5 format: mode, connect/listen endpoints,
/// scouting), or Zenoh's defaults (a peer that finds others by multicast scouting).
pub fn load_config(path: Option<&Path>) -> Result<zenoh::Config, ZenohError> {
    match path {
        None => Ok(zenoh::Config::default()),
        Some(p) => zenoh::Config::from_file(p).map_err(|e| ZenohError::Config {
            path: p.display().to_string(),
            reason: e.to_string(),
        }),
    }
}

/// The running bridge.
pub struct ZenohBridge {
    robot: String,
    cancel: CancellationToken,
    tasks: Vec<JoinHandle<()>>,
    counters: Arc<ZenohCounters>,
    /// The presence token, undeclared when the bridge stops (or by Zenoh when the process dies).
    alive: Option<zenoh::liveliness::LivelinessToken>,
    session: Option<zenoh::Session>,
    runtime: Option<tokio::runtime::Runtime>,
}

impl Drop for ZenohBridge {
    fn drop(&mut self) {
        self.cancel.cancel();
        if let Some(rt) = self.runtime.take() {
            rt.shutdown_background();
        }
    }
}

impl ZenohBridge {
    /// Opens a Zenoh session with `config` (hardened: [`wire::harden`]) and starts publishing `server`'s ticks, events and status and
    /// answering its queries; `dashboard_url` is published in the status.
    pub async fn start(
        mut config: zenoh::Config,
        server: &Server,
        dashboard_url: String,
    ) -> Result<ZenohBridge, ZenohError> {
        let settings = server.config().zenoh.clone();
        if settings.commands {
            match &server.config().dashboard.token {
                None => return Err(ZenohError::CommandsNeedToken),
                Some(t) => {
                    if let Some(problem) = pavlov::config::public_token_problem(t) {
                        return Err(ZenohError::CommandsNeedStrongToken(problem));
                    }
                }
            }
        }
        pavlov::config::check_robot_name(&settings.robot).map_err(|reason| {
            ZenohError::Declare {
                key: key(&settings.robot, "*"),
                reason,
            }
        })?;
        wire::harden(&mut config, wire::ROBOT_MAX_MESSAGE_BYTES).map_err(|reason| {
            ZenohError::Config {
                path: "(settings pavlov adds)".into(),
                reason,
            }
        })?;
        let runtime = tokio::runtime::Builder::new_multi_thread()
            .worker_threads(1)
            .thread_name("zenoh-bridge")
            .enable_all()
            .build()
            .map_err(ZenohError::Runtime)?;
        let session = runtime
            .spawn(async move { zenoh::open(config).await })
            .await
            .map_err(|e| ZenohError::Open(e.to_string()))?
            .map_err(|e| ZenohError::Open(e.to_string()))?;
        let counters = server.health().zenoh.clone();
        let mut bridge = ZenohBridge {
            robot: settings.robot.clone(),
            cancel: CancellationToken::new(),
            tasks: Vec::new(),
            counters: counters.clone(),
            alive: None,
            session: Some(session.clone()),
            runtime: None,
        };
        let publisher = publish::Publisher::declare(
            session.clone(),
            settings.robot.clone(),
            counters.clone(),
            publish::Inputs {
                ticks: server.feed().subscribe(),
                events: server.events().subscribe(),
            },
        );
        let publisher = runtime
            .spawn(publisher)
            .await
            .map_err(|e| ZenohError::Open(e.to_string()))??;
        let status = status::StatusSource::new(server, dashboard_url, counters.clone());
        let answers = commands::Answers::new(server, session.clone(), counters.clone());
        let queryables = runtime
            .spawn(commands::declare(session.clone(), settings.robot.clone()))
            .await
            .map_err(|e| ZenohError::Open(e.to_string()))??;
        let alive_key = key(&settings.robot, wire::ALIVE_LEAF);
        let token_session = session.clone();
        let alive = runtime
            .spawn(async move {
                token_session
                    .liveliness()
                    .declare_token(alive_key.clone())
                    .await
                    .map_err(|e| ZenohError::Declare {
                        key: alive_key,
                        reason: e.to_string(),
                    })
            })
            .await
            .map_err(|e| ZenohError::Open(e.to_string()))??;
        bridge.alive = Some(alive);
        let cancel = bridge.cancel.clone();
        let phase = publish::Phase {
            first_tick: server.started(),
            period: Duration::from_millis(server.config().tick.period_ms.max(1)),
        };
        bridge.tasks.push(runtime.spawn(publisher.run(
            status,
            phase,
            Duration::from_millis(settings.status_every_ms),
            cancel.clone(),
        )));
        bridge
            .tasks
            .push(runtime.spawn(answers.run(queryables, cancel)));
        bridge.runtime = Some(runtime);
        tracing::info!(robot = %settings.robot, commands = settings.commands, "zenoh bridge running");
        Ok(bridge)
    }

    /// The robot's name in the keys.
    pub fn robot(&self) -> &str {
        &self.robot
    }

    /// The bridge's counters now.
    pub fn stats(&self) -> ZenohFigures {
        self.counters.figures()
    }

    /// Stops publishing and answering, and closes the session.
    pub async fn shutdown(mut self) {
        self.cancel.cancel();
        for task in std::mem::take(&mut self.tasks) {
            let _ = tokio::time::timeout(Duration::from_secs(3), task).await;
        }
        if let (Some(alive), Some(rt)) = (self.alive.take(), self.runtime.as_ref()) {
            let gone = rt.spawn(async move { alive.undeclare().await });
            let _ = tokio::time::timeout(Duration::from_secs(3), gone).await;
        }
        if let (Some(session), Some(rt)) = (self.session.take(), self.runtime.as_ref()) {
            let closing = rt.spawn(async move { session.close().await });
            let _ = tokio::time::timeout(Duration::from_secs(3), closing).await;
        }
    }
}

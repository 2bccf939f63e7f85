//! `pavlov fleet`: one page for a lab's robots. It subscribes to `pavlov/v1/*/tick`, `pavlov/v1/*/event`
//! and `pavlov/v1/*/status` on Zenoh (what `pavlov serve --zenoh` publishes) and to the robots'
//! liveliness tokens `pavlov/v1/*/alive` (presence), keeps one row per robot (`table`), and serves
//! a small dashboard (`web/fleet.html`, `web/fleet.js`) listing each robot's mode, link, tick health, key
//! counters, when it was last seen, and a link to its own dashboard (`http`).
//!
//! Its session gets [`wire::harden`]: HLC timestamps on, and no message over
//! 256 KiB (`table::MAX_SAMPLE_BYTES`) reassembled.
//!
//! Commands typed on the fleet page are forwarded as Zenoh queries to `pavlov/v1/<robot>/command` with the
//! token the user gives; the fleet holds no token of its own, so each robot decides (see
//! [`crate::zenoh_bridge`]).

pub(crate) mod http;
pub(crate) mod table;

use std::net::SocketAddr;
use std::sync::{Arc, Mutex};
use std::time::{Duration, SystemTime, UNIX_EPOCH};

use tokio::task::JoinHandle;
use tokio_util::sync::CancellationToken;

use crate::zenoh_bridge::{KEY_ROOT, wire};
use table::{Leaf, Meta, RobotTable};

/// Now, Unix ms.
fn now_ms() -> u64 {
    SystemTime::now()
        .duration_since(UNIX_EPOCH)
        .map_or(0, |d| d.as_millis() as u64)
}

/// What the table needs of a sample besides its key and payload.
fn meta_of(sample: &zenoh::sample::Sample) -> Meta {
    Meta {
        timestamp: sample.timestamp().map(|t| t.to_string()),
        source: sample.timestamp().map(|t| t.get_id().to_string()),
        pub_seq: sample
            .attachment()
            .and_then(|a| wire::seq_of(&a.to_bytes())),
    }
}

/// Errors starting the fleet.
#[derive(Debug, thiserror::Error)]
pub enum FleetError {
    /// The listen address does not parse.
    #[error("--listen {0}: not an address like 127.0.0.1:8090")]
    BadAddress(String),
    /// The listen address could not be bound.
    #[error("cannot listen on {addr}: {source}")]
    Bind {
        /// The address.
        addr: String,
        /// Why.
        source: std::io::Error,
    },
    /// The Zenoh session could not be opened or a subscriber declared.
    #[error("zenoh: {0}")]
    Zenoh(String),
}

/// The running fleet view.
pub struct Fleet {
    addr: SocketAddr,
    cancel: CancellationToken,
    tasks: Vec<JoinHandle<()>>,
    session: zenoh::Session,
    table: Arc<Mutex<RobotTable>>,
}

impl Fleet {
    /// Opens a Zenoh session with `config`, subscribes to every robot, and serves the page on `listen`.
    pub async fn start(mut config: zenoh::Config, listen: &str) -> Result<Fleet, FleetError> {
        wire::harden(&mut config, table::MAX_SAMPLE_BYTES).map_err(FleetError::Zenoh)?;
        let addr: SocketAddr = listen
            .parse()
            .map_err(|_| FleetError::BadAddress(listen.to_string()))?;
        let listener = tokio::net::TcpListener::bind(addr)
            .await
            .map_err(|source| FleetError::Bind {
                addr: listen.to_string(),
                source,
            })?;
        let addr = listener.local_addr().map_err(|source| FleetError::Bind {
            addr: listen.to_string(),
            source,
        })?;
        let session = zenoh::open(config)
            .await
            .map_err(|e| FleetError::Zenoh(format!("cannot open the session: {e}")))?;
        let table = Arc::new(Mutex::new(RobotTable::default()));
        let cancel = CancellationToken::new();
        let mut tasks = Vec::new();
        for leaf in [Leaf::Tick, Leaf::Event, Leaf::Status] {
            let keyexpr = format!("{KEY_ROOT}/*/{}", leaf.name());
            let subscriber = session
                .declare_subscriber(keyexpr.clone())
                .await
                .map_err(|e| FleetError::Zenoh(format!("cannot subscribe to {keyexpr}: {e}")))?;
            let (table, cancel) = (table.clone(), cancel.clone());
            tasks.push(tokio::spawn(async move {
                loop {
                    tokio::select! {
                        _ = cancel.cancelled() => break,
                        s = subscriber.recv_async() => match s {
                            Ok(sample) => {
                                let bytes = sample.payload().to_bytes();
                                let meta = meta_of(&sample);
                                if let Ok(mut t) = table.lock() {
                                    t.observe(sample.key_expr().as_str(), leaf, &bytes, meta, now_ms());
                                }
                            }
                            Err(_) => break,
                        }
                    }
                }
            }));
        }
        let alive_keys = format!("{KEY_ROOT}/*/{}", wire::ALIVE_LEAF);
        let tokens = session
            .liveliness()
            .declare_subscriber(alive_keys.clone())
            .history(true)
            .await
            .map_err(|e| FleetError::Zenoh(format!("cannot subscribe to {alive_keys}: {e}")))?;
        {
            let (table, cancel) = (table.clone(), cancel.clone());
            tasks.push(tokio::spawn(async move {
                loop {
                    tokio::select! {
                        _ = cancel.cancelled() => break,
                        s = tokens.recv_async() => match s {
                            Ok(sample) => {
                                let alive = sample.kind() == zenoh::sample::SampleKind::Put;
                                if let Ok(mut t) = table.lock() {
                                    t.presence(sample.key_expr().as_str(), alive, now_ms());
                                }
                            }
                            Err(_) => break,
                        }
                    }
                }
            }));
        }
        let state = http::State {
            table: table.clone(),
            session: session.clone(),
        };
        tasks.push(tokio::spawn(http::serve(listener, state, cancel.clone())));
        tracing::info!(%addr, "fleet page listening");
        Ok(Fleet {
            addr,
            cancel,
            tasks,
            session,
            table,
        })
    }

    /// The address the page is served on.
    pub fn local_addr(&self) -> SocketAddr {
        self.addr
    }

    /// The robots seen so far, as the page's `/api/robots` lists them.
    pub fn robots(&self) -> serde_json::Value {
        self.table
            .lock()
            .map_or(serde_json::Value::Null, |t| t.to_json(now_ms()))
    }

    /// Stops serving and closes the session.
    pub async fn shutdown(self) {
        self.cancel.cancel();
        for task in self.tasks {
            let _ = tokio::time::timeout(Duration::from_secs(3), task).await;
        }
        let session = self.session;
        let _ = tokio::time::timeout(Duration::from_secs(3), async move { session.close().await })
            .await;
    }
}

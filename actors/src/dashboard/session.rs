//! One websocket connection: a forwarder (hub → the client's queue, at the client's rate), a writer (queue →
//! socket), a reader (socket → parsed messages) and a worker (messages, one at a time and in order → the
//! server's command router → ack or error).
//!
//! The operator first: the reader applies an operator's `estop` itself, straight into the e-stop latch
//! ([`crate::pipeline::latch`]), the moment it reads it, however many slow commands (a run of
//! `save_weights`) the same connection sent before and the worker still has to do; it is not refused for
//! the rate limit either. A `release` read before such an `estop` and still waiting is answered
//! `superseded` instead of undoing it. Every other message takes its place in one line
//! (`super::waiting`) in the order it was read, a refusal the reader makes (`rate_limited`, `busy`)
//! included, and the worker answers the line in order, so replies leave in the order of the messages (but
//! for the `estop`'s). The reader never waits on the worker: a request finding [`MAX_REQUESTS`] waiting is
//! refused `busy` in its turn, and a connection whose refusals fill their room while its commands wait is
//! closed with 1008; what a client sent before it closed is still done.
//!
//! On connect the client gets `hello`, then the history (the hub's snapshot, made into messages by the
//! writer one at a time, replies going first), then live telemetry from where the history ends: the
//! forwarder skips what the history already held.
//!
//! The forwarder never waits on the socket: when the client falls behind, its queue drops the oldest
//! telemetry. The writer gives up on a client whose socket accepts nothing for `WRITE_STALL`. Bad
//! messages get an error reply and the connection stays open; only what the websocket layer cannot
//! resynchronise after closes it, with the code RFC 6455 gives: 1009 for an over-size message, 1007 for a
//! text message that is not UTF-8, 1002 for any other protocol violation. Every message draws on the
//! connection's `TokenBucket`: one over the limit is answered `rate_limited` and not processed, and a
//! connection over its limit is read at most `OVER_LIMIT_READS_PER_SECOND` messages a second. When
//! `super::out_queue::CONTROL_CAPACITY` replies are waiting, the reader stops reading (so a fast client is
//! slowed by TCP, not by memory) for up to [`UNREAD_PATIENCE`], then disconnects the client. Each way a
//! connection can be closed for misbehaving is counted in `SessionCounters`.

use std::collections::HashMap;
use std::net::SocketAddr;
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::{Arc, Mutex, PoisonError, Weak};
use std::time::Duration;

use axum::extract::ws::{CloseFrame, Message, Utf8Bytes, WebSocket, close_code};
use futures_util::{SinkExt, StreamExt};
use serde_json::{Value, json};
use tokio::sync::{broadcast, mpsc};
use tokio_util::sync::CancellationToken;

use super::auth::Access;
use super::history_messages::{HistoryMessages, REDACTED};
use super::horde_feed::{self, HordeFeed, HordeWindow, MAX_VALUES as MAX_HORDE_VALUES};
use super::hub::{HubHandle, Outgoing};
use super::messages::Hello;
use super::out_queue::{Decimator, OutQueue};
use super::protocol::{
    ClientCommand, ClientRequest, Rejection, SessionCommand, ack_json, error_json, parse_request,
    peek_id,
};
use super::rate::{RateLimit, TokenBucket};
use super::waiting::{LineIn, LineOut, NoRoom, Turn};
pub use super::waiting::{MAX_REFUSAL_BYTES, MAX_REFUSALS, MAX_REQUESTS};
use crate::command::{ControlCommand, ControlRequest, LatchCommand};
use crate::pipeline::latch::EstopLatch;

/// A client whose socket accepts nothing for this long is disconnected.
pub(crate) const WRITE_STALL: Duration = Duration::from_secs(10);
/// How long a full reply queue may stay full before the client is disconnected.
pub const UNREAD_PATIENCE: Duration = Duration::from_secs(5);
/// While a connection is over its rate limit, the server reads at most this many of its messages a second;
/// the rest wait in TCP buffers, so a flood costs the server little CPU and no memory.
pub(crate) const OVER_LIMIT_READS_PER_SECOND: u32 = 1000;
/// Messages over the limit between two pauses of the reader.
const PACE_BATCH: u32 = 10;
/// How long a command may wait for room in the router's inbox.
const ROUTER_SEND_TIMEOUT: Duration = Duration::from_secs(1);
/// How long a command may take to be applied before the client is told it timed out.
const COMMAND_TIMEOUT: Duration = Duration::from_secs(3);
/// How long a closing connection may take to flush its last replies.
const CLOSE_GRACE: Duration = Duration::from_secs(1);

/// Whether the `n`-th occurrence of an abuse event is worth a log line: the first three, then every power of
/// two, so a flood is visible in the log without the log becoming the flood (the counters have every one).
pub(crate) fn worth_logging(n: u64) -> bool {
    n <= 3 || n.is_power_of_two()
}

/// Endpoint-wide counters the sessions update.
#[derive(Debug, Default)]
pub(crate) struct SessionCounters {
    /// Telemetry messages dropped for slow clients, all clients together.
    pub(crate) telemetry_dropped: AtomicU64,
    /// Commands forwarded to the server.
    pub(crate) commands: AtomicU64,
    /// Error replies sent (including `rate_limited`).
    pub(crate) errors: AtomicU64,
    /// Messages refused with `rate_limited`.
    pub(crate) rate_limited: AtomicU64,
    /// Connections closed with 1009 for an over-size message.
    pub(crate) closed_oversize: AtomicU64,
    /// Connections dropped because their replies piled up unread.
    pub(crate) closed_unread: AtomicU64,
    /// Connections dropped because their socket accepted nothing for [`WRITE_STALL`].
    pub(crate) closed_write_stall: AtomicU64,
    /// Connections closed with 1002 for violating the websocket protocol.
    pub(crate) closed_protocol: AtomicU64,
    /// Connections closed with 1007 for a text message that is not UTF-8.
    pub(crate) closed_invalid_utf8: AtomicU64,
    /// Connections closed with 1008 because their refused messages filled the room refusals have while
    /// their commands wait.
    pub(crate) closed_refusals_piled: AtomicU64,
    /// Each connected client's queue, by the client's address: what it dropped, for the tests that check
    /// that a slow client's losses are its own ([`SessionCounters::telemetry_dropped_for`]).
    queues: Mutex<HashMap<SocketAddr, Weak<OutQueue<Out>>>>,
}

impl SessionCounters {
    /// Telemetry dropped so far for the client connected from `peer` (`None`: no such client now).
    pub(crate) fn telemetry_dropped_for(&self, peer: SocketAddr) -> Option<u64> {
        let queues = self.queues.lock().unwrap_or_else(PoisonError::into_inner);
        queues
            .get(&peer)
            .and_then(Weak::upgrade)
            .map(|q| q.dropped())
    }

    /// Lists `queue` as `peer`'s until the returned guard is dropped.
    fn register(self: &Arc<Self>, peer: SocketAddr, queue: &Arc<OutQueue<Out>>) -> Registered {
        let queue = Arc::downgrade(queue);
        let mut queues = self.queues.lock().unwrap_or_else(PoisonError::into_inner);
        queues.insert(peer, queue.clone());
        Registered {
            counters: self.clone(),
            peer,
            queue,
        }
    }
}

/// A connection's place in [`SessionCounters`]'s list of queues, taken out when the connection ends.
struct Registered {
    counters: Arc<SessionCounters>,
    peer: SocketAddr,
    queue: Weak<OutQueue<Out>>,
}

impl Drop for Registered {
    fn drop(&mut self) {
        let mut queues = self
            .counters
            .queues
            .lock()
            .unwrap_or_else(PoisonError::into_inner);
        // Only this connection's: a later one may have the same address once this socket is gone.
        if queues
            .get(&self.peer)
            .is_some_and(|q| q.ptr_eq(&self.queue))
        {
            queues.remove(&self.peer);
        }
    }
}

/// Everything a session needs.
pub(crate) struct Session {
    /// The client's address.
    pub(crate) peer: SocketAddr,
    /// Where the telemetry comes from.
    pub(crate) hub: HubHandle,
    /// The server's command inbox.
    pub(crate) commands: mpsc::Sender<ControlRequest>,
    /// The e-stop latch, set by an operator's `estop` ahead of its earlier commands.
    pub(crate) estop: EstopLatch,
    /// What this client may do.
    pub(crate) access: Access,
    /// The largest `history` message, bytes.
    pub(crate) history_message_bytes: usize,
    /// The tick period, ms.
    pub(crate) period_ms: u64,
    /// Telemetry queued before the oldest is dropped.
    pub(crate) queue: usize,
    /// The tick rate, Hz.
    pub(crate) tick_hz: f64,
    /// The message rate limit.
    pub(crate) rate: RateLimit,
    /// Shared counters.
    pub(crate) counters: Arc<SessionCounters>,
    /// Fires when the endpoint shuts down.
    pub(crate) cancel: CancellationToken,
    /// The Horde's names and values, for the clients that ask (`None`: no `[horde]`).
    pub(crate) horde: Option<Arc<HordeFeed>>,
}

/// One connection's watch of the Horde: its streaming task (stopped when replaced or dropped) and whether
/// the names went out already.
#[derive(Default)]
struct HordeSubscription {
    task: Option<tokio::task::JoinHandle<()>>,
    names_sent: bool,
}

impl HordeSubscription {
    fn stop(&mut self) -> bool {
        match self.task.take() {
            Some(t) => {
                t.abort();
                true
            }
            None => false,
        }
    }
}

impl Drop for HordeSubscription {
    fn drop(&mut self) {
        self.stop();
    }
}

enum Out {
    Text(Utf8Bytes),
    Close(u16, &'static str),
}

impl Session {
    /// Serves one connection until either side ends it; `hello` is its first message, but for what is in
    /// force (taken with the history when the session starts). It is made into text and let go at once:
    /// a connection keeps no copy of the configuration it was shown.
    pub(crate) async fn run(self, socket: WebSocket, hello: Hello) {
        tracing::debug!(access = ?self.access, "websocket client connected");
        let (sink, stream) = socket.split();
        let queue = Arc::new(OutQueue::new(self.queue));
        let _registered = self.counters.register(self.peer, &queue);
        let stride = Arc::new(AtomicU64::new(1));
        let watcher = self.access == Access::Watch;
        let (rx, snapshot) = self.hub.join();
        let mut in_force = snapshot.in_force.clone();
        if watcher && in_force.recording.is_some() {
            in_force.recording = Some(REDACTED.into());
        }
        let hello = hello.with_in_force(in_force).to_json();
        let _ = queue.push_control(Out::Text(hello.into()));
        // The recent `learning` messages go out after the history, before the live telemetry.
        let recent_learning = self.hub.recent_learning();
        let seen = Seen {
            through_seq: snapshot.last_seq,
            through_event: snapshot.last_event_id,
            through_learning: recent_learning.last().map(|(seq, _)| *seq),
        };
        let history = HistoryMessages::new(
            snapshot,
            self.history_message_bytes,
            self.period_ms,
            watcher,
        );
        let forwarder = tokio::spawn(forward(
            rx,
            Forwarding {
                queue: queue.clone(),
                stride: stride.clone(),
                counters: self.counters.clone(),
                watcher,
                seen,
            },
        ));
        let past = Past {
            history: Some(history),
            learning: recent_learning.into_iter().map(|(_, text)| text).collect(),
        };
        let writer = write(sink, queue.clone(), self.counters.clone(), past);
        tokio::pin!(writer);
        tokio::select! {
            _ = &mut writer => {}
            _ = self.read(stream, &queue, &stride) => {
                queue.close();
                let _ = tokio::time::timeout(CLOSE_GRACE, &mut writer).await;
            }
            _ = self.cancel.cancelled() => {
                let _ = queue.push_control(Out::Close(close_code::AWAY, "server shutting down"));
                queue.close();
                let _ = tokio::time::timeout(CLOSE_GRACE, &mut writer).await;
            }
        }
        forwarder.abort();
    }

    /// Reads the connection and answers it: a reader takes every message off the socket as it comes, and
    /// answers an operator's `estop` at once (the latch is set before the next tick); every other message
    /// waits in one line (at most [`MAX_REQUESTS`] requests) for a worker that handles them one at a time,
    /// in order.
    async fn read(
        &self,
        stream: futures_util::stream::SplitStream<WebSocket>,
        queue: &Arc<OutQueue<Out>>,
        stride: &AtomicU64,
    ) {
        let (waiting, turns) = super::waiting::line();
        let estops = AtomicU64::new(0);
        let worker = self.work(turns, stride, queue, &estops);
        tokio::pin!(worker);
        tokio::select! {
            ended = self.receive(stream, waiting, queue, &estops) => {
                if ended == Ended::Closed {
                    // What the client sent before it closed is still done, in order.
                    (&mut worker).await;
                }
            }
            () = &mut worker => {}
        }
    }

    /// Takes messages off the socket: an operator's `estop` is applied here, ahead of the line; the rest
    /// take their place in the line for [`Session::work`], refusals too (a request is answered `busy` when
    /// [`MAX_REQUESTS`] are waiting).
    async fn receive(
        &self,
        mut stream: futures_util::stream::SplitStream<WebSocket>,
        waiting: LineIn<Waiting>,
        queue: &Arc<OutQueue<Out>>,
        estops: &AtomicU64,
    ) -> Ended {
        let mut bucket = TokenBucket::new(self.rate, std::time::Instant::now());
        let mut pace = Pacer::default();
        while let Some(msg) = stream.next().await {
            let over_limit = matches!(
                msg,
                Ok(Message::Text(_) | Message::Binary(_) | Message::Ping(_) | Message::Pong(_))
            ) && !bucket.try_take(std::time::Instant::now());
            let turn = match msg {
                Ok(Message::Text(text)) => {
                    let request = parse_request(&text);
                    if self.access == Access::Command
                        && let Ok(r) = &request
                        && r.command
                            == ClientCommand::Control(ControlCommand::Latch(LatchCommand::Estop {}))
                    {
                        // Never behind this connection's queue, nor refused for its rate.
                        estops.fetch_add(1, Ordering::SeqCst);
                        let reply = self.estop_now(r);
                        if !self.reply(queue, reply).await {
                            return Ended::Unread;
                        }
                        if over_limit {
                            pace.over_limit().await;
                        }
                        continue;
                    }
                    if over_limit {
                        Turn::Refusal(self.rate_limited(peek_id(&text)))
                    } else {
                        Turn::Request(Waiting {
                            request,
                            estops_before: estops.load(Ordering::SeqCst),
                        })
                    }
                }
                Ok(Message::Binary(_)) if over_limit => Turn::Refusal(self.rate_limited(None)),
                Ok(Message::Binary(_)) => {
                    let e = super::protocol::ProtocolError::Binary;
                    Turn::Refusal(self.error(&None, e.code(), &e.to_string()))
                }
                Ok(Message::Ping(_) | Message::Pong(_)) => {
                    if over_limit {
                        pace.over_limit().await;
                    }
                    continue;
                }
                Ok(Message::Close(_)) => return Ended::Closed,
                Err(e) => {
                    self.close_after_read_error(&e, queue);
                    return Ended::Broken;
                }
            };
            let placed = match turn {
                Turn::Request(w) => match waiting.push_request(w) {
                    Ok(()) => Ok(()),
                    Err((w, NoRoom::Full)) => {
                        // Refused in its turn, with the id of the message it answers.
                        let id = match w.request {
                            Ok(r) => r.id,
                            Err(r) => r.id,
                        };
                        let busy = self.error(
                            &id,
                            "busy",
                            &format!(
                                "{MAX_REQUESTS} messages of this connection are waiting for their turn; this one was not processed"
                            ),
                        );
                        waiting.push_refusal(busy)
                    }
                    Err((_, NoRoom::Gone)) => Err(NoRoom::Gone),
                },
                Turn::Refusal(reply) => waiting.push_refusal(reply),
            };
            match placed {
                Ok(()) => {}
                // The worker is held by the client's own unread replies: that is why its refusals piled up.
                Err(NoRoom::Full) if queue.replies_full() => {
                    self.count_unread();
                    return Ended::Unread;
                }
                Err(NoRoom::Full) => {
                    self.close_flooding(queue);
                    return Ended::Broken;
                }
                Err(NoRoom::Gone) => return Ended::Unread,
            }
            if over_limit {
                pace.over_limit().await;
            }
        }
        Ended::Closed
    }

    /// Handles the queued messages one at a time, in the order they came; returns when the reader is done
    /// and the queue is empty, or when the client does not read its replies.
    async fn work(
        &self,
        mut turns: LineOut<Waiting>,
        stride: &AtomicU64,
        queue: &Arc<OutQueue<Out>>,
        estops: &AtomicU64,
    ) {
        let mut horde = HordeSubscription::default();
        while let Some(turn) = turns.next().await {
            let reply = match turn {
                Turn::Refusal(reply) => reply,
                Turn::Request(Waiting {
                    request,
                    estops_before,
                }) => {
                    let overtaken = estops.load(Ordering::SeqCst) > estops_before;
                    self.handle(request, overtaken, stride, queue, &mut horde)
                        .await
                }
            };
            if !self.reply(queue, reply).await {
                return;
            }
        }
    }

    /// Queues a reply, waiting up to [`UNREAD_PATIENCE`] for room; false (counted) when the client does not
    /// read its replies and must be disconnected.
    async fn reply(&self, queue: &OutQueue<Out>, reply: String) -> bool {
        if queue
            .push_control_waiting(Out::Text(reply.into()), UNREAD_PATIENCE)
            .await
            .is_ok()
        {
            return true;
        }
        self.count_unread();
        false
    }

    /// Counts (and logs) a client disconnected because it does not read its replies.
    fn count_unread(&self) {
        let n = self.counters.closed_unread.fetch_add(1, Ordering::Relaxed) + 1;
        if worth_logging(n) {
            tracing::warn!(
                total = n,
                "websocket client does not read its replies; disconnecting it"
            );
        }
    }

    /// An operator's `estop`, applied the moment it is read.
    fn estop_now(&self, request: &ClientRequest) -> String {
        self.counters.commands.fetch_add(1, Ordering::Relaxed);
        tracing::info!(cmd = %request.cmd, "command from a websocket client, ahead of its queue");
        let applied = self.estop.set(true);
        let result = serde_json::to_value(&applied).unwrap_or_default();
        ack_json(&request.id, &request.cmd, &result)
    }

    /// Ends a connection that sent [`MAX_REFUSALS`] (or [`MAX_REFUSAL_BYTES`]) of refused messages while its
    /// commands were still waiting: closed with 1008 (policy violation), counted.
    fn close_flooding(&self, queue: &OutQueue<Out>) {
        let n = self
            .counters
            .closed_refusals_piled
            .fetch_add(1, Ordering::Relaxed)
            + 1;
        if worth_logging(n) {
            tracing::warn!(
                total = n,
                "a websocket client's refused messages piled up behind its waiting commands; closing it"
            );
        }
        let _ = queue.push_control(Out::Close(
            close_code::POLICY,
            "too many refused messages waiting",
        ));
    }

    /// Ends the connection after the websocket layer refused what the client sent: an over-size message
    /// closes with 1009, text that is not UTF-8 with 1007, any other protocol violation with 1002 (RFC 6455,
    /// 7.4.1); a connection that simply went away gets nothing.
    fn close_after_read_error(&self, e: &axum::Error, queue: &OutQueue<Out>) {
        let (counter, code, reason) = match classify_read_error(e) {
            ReadError::Oversize => (
                &self.counters.closed_oversize,
                close_code::SIZE,
                "message too big",
            ),
            ReadError::InvalidUtf8 => (
                &self.counters.closed_invalid_utf8,
                close_code::INVALID,
                "text frames must be UTF-8",
            ),
            ReadError::Protocol => (
                &self.counters.closed_protocol,
                close_code::PROTOCOL,
                "websocket protocol violation",
            ),
            ReadError::Gone => {
                tracing::debug!("websocket read error: {e}");
                return;
            }
        };
        let n = counter.fetch_add(1, Ordering::Relaxed) + 1;
        if worth_logging(n) {
            tracing::info!(total = n, code, "closing a websocket client: {e}");
        }
        let _ = queue.push_control(Out::Close(code, reason));
    }

    fn rate_limited(&self, id: Option<Value>) -> String {
        self.counters.rate_limited.fetch_add(1, Ordering::Relaxed);
        let RateLimit { burst, per_second } = self.rate;
        self.error(
            &id,
            "rate_limited",
            &format!(
                "too many messages: at most {per_second} per second in bursts of {burst}; this one was not processed"
            ),
        )
    }

    fn error(&self, id: &Option<Value>, code: &str, message: &str) -> String {
        self.counters.errors.fetch_add(1, Ordering::Relaxed);
        error_json(id, code, message)
    }

    /// Answers one message; `overtaken`: an `estop` read after it was applied before it.
    async fn handle(
        &self,
        request: Result<ClientRequest, Rejection>,
        overtaken: bool,
        stride: &AtomicU64,
        queue: &Arc<OutQueue<Out>>,
        horde: &mut HordeSubscription,
    ) -> String {
        let ClientRequest { id, cmd, command } = match request {
            Ok(r) => r,
            Err(rej) => return self.error(&rej.id, rej.error.code(), &rej.error.to_string()),
        };
        match command {
            ClientCommand::Session(SessionCommand::SetRate { hz }) => {
                let every = Decimator::stride_for(hz, self.tick_hz);
                stride.store(every, Ordering::Relaxed);
                ack_json(
                    &id,
                    &cmd,
                    &json!({"rate_hz": self.tick_hz / every as f64, "every": every}),
                )
            }
            ClientCommand::Session(SessionCommand::Ping) => ack_json(&id, &cmd, &json!({})),
            ClientCommand::Session(SessionCommand::HordeWatch { hz, from, count }) => {
                self.horde_watch(&id, &cmd, queue, horde, (hz, from, count))
            }
            ClientCommand::Session(SessionCommand::HordeUnwatch) => {
                let watching = horde.stop();
                ack_json(&id, &cmd, &json!({ "was_watching": watching }))
            }
            ClientCommand::Control(_) if self.access == Access::Watch => self.error(
                &id,
                "unauthorized",
                "this connection may only watch: reconnect with the token to send commands",
            ),
            ClientCommand::Control(ControlCommand::Latch(LatchCommand::Release {})) if overtaken => {
                self.error(
                    &id,
                    "superseded",
                    "an estop sent after this release was applied before it, so the release was not: send release again to release the e-stop",
                )
            }
            ClientCommand::Control(command) => {
                self.counters.commands.fetch_add(1, Ordering::Relaxed);
                tracing::info!(cmd = %cmd, "command from a websocket client");
                let (request, reply) = ControlRequest::new(command);
                match tokio::time::timeout(ROUTER_SEND_TIMEOUT, self.commands.send(request)).await {
                    Ok(Ok(())) => {}
                    Ok(Err(_)) => {
                        return self.error(&id, "unavailable", "the server is shutting down");
                    }
                    Err(_) => {
                        return self.error(
                            &id,
                            "busy",
                            "the server's command queue is full; try again",
                        );
                    }
                }
                match tokio::time::timeout(COMMAND_TIMEOUT, reply).await {
                    Ok(Ok(Ok(applied))) => {
                        let result = serde_json::to_value(&applied).unwrap_or_default();
                        ack_json(&id, &cmd, &result)
                    }
                    Ok(Ok(Err(e))) => self.error(&id, e.code(), &e.to_string()),
                    Ok(Err(_)) => {
                        self.error(&id, "unavailable", "the server stopped before answering")
                    }
                    Err(_) => self.error(&id, "timeout", "the command was not answered in time"),
                }
            }
        }
    }
}

impl Session {
    /// `horde_watch`: checks the window against the Horde's size, then (re)starts the connection's stream.
    fn horde_watch(
        &self,
        id: &Option<Value>,
        cmd: &str,
        queue: &Arc<OutQueue<Out>>,
        sub: &mut HordeSubscription,
        (hz, from, count): (f64, usize, Option<usize>),
    ) -> String {
        let Some(feed) = &self.horde else {
            return self.error(
                id,
                "no_horde",
                "this server runs no Horde: its configuration has no [[horde.families]]",
            );
        };
        let total = feed.len();
        if from >= total {
            return self.error(
                id,
                "bad_arguments",
                &format!(
                    "bad arguments for `{cmd}`: `from` must be below the Horde's {total} predictions, got {from}"
                ),
            );
        }
        let count = count.unwrap_or((total - from).min(MAX_HORDE_VALUES));
        if count > total - from {
            return self.error(
                id,
                "bad_arguments",
                &format!(
                    "bad arguments for `{cmd}`: `from` + `count` must be at most the Horde's {total} predictions, got {}",
                    from.saturating_add(count)
                ),
            );
        }
        sub.stop();
        let send_names = !sub.names_sent;
        sub.names_sent = true;
        let window = HordeWindow { from, count, hz };
        sub.task = Some(tokio::spawn(horde_feed::stream(
            feed.clone(),
            queue.clone(),
            window,
            send_names,
            Out::Text,
        )));
        ack_json(
            id,
            cmd,
            &json!({
                "total": total,
                "from": from,
                "count": count,
                "hz": hz,
                "encoding": horde_feed::ENCODING,
                "names": send_names,
            }),
        )
    }
}

/// A request waiting for its turn, and how many e-stops had been applied ahead of the line when it was
/// read.
struct Waiting {
    request: Result<ClientRequest, Rejection>,
    estops_before: u64,
}

/// Why the reader stopped.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Ended {
    /// The client closed the connection: what it sent before is still answered.
    Closed,
    /// The websocket layer refused what it sent (it is being closed with a code).
    Broken,
    /// It does not read its replies.
    Unread,
}

/// Slows the reader of a connection that is over its rate limit: a pause after every [`PACE_BATCH`]
/// messages over the limit, so it reads at most [`OVER_LIMIT_READS_PER_SECOND`] of them a second.
#[derive(Default)]
struct Pacer {
    over: u32,
}

impl Pacer {
    async fn over_limit(&mut self) {
        self.over = self.over.wrapping_add(1);
        if self.over % PACE_BATCH == 0 {
            tokio::time::sleep(Duration::from_secs(1) * PACE_BATCH / OVER_LIMIT_READS_PER_SECOND)
                .await;
        }
    }
}

/// What went wrong reading a connection.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum ReadError {
    /// A message or frame over the size limit.
    Oversize,
    /// A text message that is not UTF-8.
    InvalidUtf8,
    /// Any other violation of RFC 6455 (reserved bits, an unmasked frame, a bad opcode, …).
    Protocol,
    /// The connection ended (reset, closed without a closing handshake, I/O error).
    Gone,
}

/// Classifies a read error by the websocket library's messages (axum wraps its error type, whose version
/// differs from the one this crate's clients use, so the text is what is stable to match on).
fn classify_read_error(e: &axum::Error) -> ReadError {
    const GONE: [&str; 3] = [
        "Connection reset without closing handshake",
        "Remote sent after having closed",
        "Sending after closing",
    ];
    let mut source: Option<&(dyn std::error::Error + 'static)> = Some(e);
    let mut texts = Vec::new();
    while let Some(s) = source {
        texts.push(s.to_string());
        source = s.source();
    }
    let any = |needle: &str| texts.iter().any(|t| t.contains(needle));
    if any("Space limit exceeded") || any("too long") || any("too big") {
        ReadError::Oversize
    } else if any("UTF-8 encoding error") {
        ReadError::InvalidUtf8
    } else if any("WebSocket protocol error") && !GONE.iter().any(|g| any(g)) {
        ReadError::Protocol
    } else {
        ReadError::Gone
    }
}

/// What the client's history already held: live telemetry up to here is skipped.
#[derive(Debug, Clone, Copy)]
struct Seen {
    through_seq: Option<u64>,
    through_event: u64,
    through_learning: Option<u64>,
}

/// Where the forwarder puts what it passes, and how it chooses.
struct Forwarding {
    queue: Arc<OutQueue<Out>>,
    stride: Arc<AtomicU64>,
    counters: Arc<SessionCounters>,
    watcher: bool,
    seen: Seen,
}

async fn forward(mut rx: broadcast::Receiver<Outgoing>, f: Forwarding) {
    let Forwarding {
        queue,
        stride,
        counters,
        watcher,
        seen,
    } = f;
    let mut decimator = Decimator::all();
    loop {
        let dropped = match rx.recv().await {
            Ok(Outgoing::Tick { seq, .. }) if seen.through_seq.is_some_and(|s| seq <= s) => {
                continue;
            }
            Ok(Outgoing::Tick { seq, text }) => {
                let every = stride.load(Ordering::Relaxed);
                if every != decimator.every() {
                    decimator.set_every(every);
                }
                if !decimator.pass(seq) {
                    continue;
                }
                queue.push_telemetry(Out::Text(text))
            }
            Ok(Outgoing::Status(text)) => queue.push_telemetry(Out::Text(text)),
            Ok(Outgoing::Learning { seq, .. })
                if seen.through_learning.is_some_and(|s| seq <= s) =>
            {
                continue;
            }
            Ok(Outgoing::Learning { text, .. }) => queue.push_telemetry(Out::Text(text)),
            Ok(Outgoing::Event { id, .. }) if id <= seen.through_event => continue,
            Ok(Outgoing::Event {
                operator,
                watcher: w,
                ..
            }) => queue.push_telemetry(Out::Text(if watcher { w } else { operator })),
            Err(broadcast::error::RecvError::Lagged(n)) => {
                queue.count_dropped(n);
                n
            }
            Err(broadcast::error::RecvError::Closed) => break,
        };
        if dropped > 0 {
            counters
                .telemetry_dropped
                .fetch_add(dropped, Ordering::Relaxed);
        }
    }
}

/// What a new client is sent before its live telemetry: the history, then the recent `learning` messages.
struct Past {
    history: Option<HistoryMessages>,
    learning: std::collections::VecDeque<Utf8Bytes>,
}

/// The next message to write: a reply first, then the past (while the connection is open), then
/// telemetry; `None` once the queue is closed and drained.
async fn next_out(queue: &OutQueue<Out>, past: &mut Past) -> Option<Out> {
    if let Some(reply) = queue.try_pop_control() {
        return Some(reply);
    }
    if let Some(h) = &mut past.history {
        match h.next() {
            Some(text) if !queue.is_closed() => return Some(Out::Text(text.into())),
            _ => past.history = None,
        }
    }
    if !queue.is_closed()
        && let Some(text) = past.learning.pop_front()
    {
        return Some(Out::Text(text));
    }
    queue.pop().await
}

async fn write(
    mut sink: futures_util::stream::SplitSink<WebSocket, Message>,
    queue: Arc<OutQueue<Out>>,
    counters: Arc<SessionCounters>,
    mut past: Past,
) {
    while let Some(out) = next_out(&queue, &mut past).await {
        let (msg, last) = match out {
            Out::Text(text) => (Message::Text(text), false),
            Out::Close(code, reason) => (
                Message::Close(Some(CloseFrame {
                    code,
                    reason: Utf8Bytes::from_static(reason),
                })),
                true,
            ),
        };
        match tokio::time::timeout(WRITE_STALL, sink.send(msg)).await {
            Ok(Ok(())) if !last => {}
            Ok(Ok(())) => return,
            Ok(Err(e)) => {
                tracing::debug!("websocket write failed: {e}");
                return;
            }
            Err(_) => {
                counters.closed_write_stall.fetch_add(1, Ordering::Relaxed);
                tracing::warn!(
                    "a websocket client accepted nothing for {} s; disconnecting it",
                    WRITE_STALL.as_secs()
                );
                return;
            }
        }
    }
    let _ = sink.send(Message::Close(None)).await;
}

#[cfg(test)]
mod tests;

//! The router: takes every [`ControlRequest`] from the server's one command inbox and hands it to its
//! owner (the vocabulary is in [`crate::command`]). The e-stop latch it applies itself, straight into the
//! `watch` that actuation and gating read ([`super::latch`]), so it works even if they stalled; every other command goes with
//! its reply channel to its owner's inbox without waiting, and a full inbox is answered `busy` at once.

use tokio::sync::mpsc;
use tokio_util::sync::CancellationToken;

use super::latch::EstopLatch;
use crate::command::{
    CommandError, ControlCommand, ControlRequest, Envelope, GatingCommand, LatchCommand,
    LearningCommand, LinkCommand, RecorderCommand, Reply,
};

/// Where the router sends things.
pub(crate) struct Routes {
    /// The e-stop latch that actuation and gating watch.
    pub(crate) estop: EstopLatch,
    /// Gating's inbox.
    pub(crate) gating: mpsc::Sender<Envelope<GatingCommand>>,
    /// Learning's inbox.
    pub(crate) learning: mpsc::Sender<Envelope<LearningCommand>>,
    /// Link supervision's inbox.
    pub(crate) link: mpsc::Sender<Envelope<LinkCommand>>,
    /// The recorder's inbox, when this server records.
    pub(crate) recorder: Option<mpsc::Sender<Envelope<RecorderCommand>>>,
}

/// Routes requests until the inbox closes or `cancel` fires.
pub(crate) async fn route(
    mut inbox: mpsc::Receiver<ControlRequest>,
    routes: Routes,
    cancel: CancellationToken,
) {
    // One wait for the cancellation, polled again on every pass (not a new one per pass).
    let cancelled = cancel.cancelled();
    tokio::pin!(cancelled);
    loop {
        let next = tokio::select! {
            _ = &mut cancelled => None,
            r = inbox.recv() => r,
        };
        let Some(ControlRequest { command, reply }) = next else {
            break;
        };
        tracing::debug!(?command, "routing a command");
        match command {
            ControlCommand::Latch(c) => {
                let on = matches!(c, LatchCommand::Estop {});
                let _ = reply.send(Ok(routes.estop.set(on)));
            }
            ControlCommand::Gating(c) => forward(&routes.gating, c, reply, "gating"),
            ControlCommand::Learning(c) => forward(&routes.learning, c, reply, "learning"),
            ControlCommand::Link(c) => forward(&routes.link, c, reply, "robot link"),
            ControlCommand::Recorder(c) => match &routes.recorder {
                Some(to) => forward(to, c, reply, "recorder"),
                None => {
                    let _ = reply.send(Err(CommandError::Rejected(
                        "recording is not available in this server".into(),
                    )));
                }
            },
        }
    }
}

/// Hands `command` to its owner without waiting; a full or closed inbox is answered at once.
fn forward<C>(to: &mpsc::Sender<Envelope<C>>, command: C, reply: Reply, owner: &'static str) {
    match to.try_send(Envelope { command, reply }) {
        Ok(()) => {}
        Err(mpsc::error::TrySendError::Full(e)) => e.answer(Err(CommandError::Busy(owner))),
        Err(mpsc::error::TrySendError::Closed(e)) => e.answer(Err(CommandError::Unavailable(
            format!("the {owner} is not running"),
        ))),
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::command::Applied;
    use pavlov::control::Mode;
    use tokio::sync::watch;

    #[tokio::test]
    async fn the_router_answers_busy_at_once_instead_of_waiting_for_a_full_inbox() {
        let (estop, _estop_rx) = watch::channel(false);
        let (gating, _gating_rx) = mpsc::channel(1);
        let (learning, _l) = mpsc::channel(1);
        let (link, _k) = mpsc::channel(1);
        let (tx, rx) = mpsc::channel(8);
        let cancel = CancellationToken::new();
        let router = tokio::spawn(route(
            rx,
            Routes {
                estop: EstopLatch::new(estop, None),
                gating,
                learning,
                link,
                recorder: None,
            },
            cancel.clone(),
        ));
        let mode = || GatingCommand::SetMode { mode: Mode::Manual };
        let (first, _first_reply) = ControlRequest::new(mode());
        tx.send(first).await.unwrap();
        let (second, second_reply) = ControlRequest::new(mode());
        tx.send(second).await.unwrap();
        assert_eq!(
            second_reply.await.unwrap(),
            Err(CommandError::Busy("gating"))
        );
        // The e-stop behind a stuck owner still latches.
        let (stop, stop_reply) = ControlRequest::new(LatchCommand::Estop {});
        tx.send(stop).await.unwrap();
        assert_eq!(
            stop_reply.await.unwrap(),
            Ok(Applied::Estop { estop: true })
        );
        let (rec, rec_reply) = ControlRequest::new(RecorderCommand::StopRecording {});
        tx.send(rec).await.unwrap();
        assert_eq!(rec_reply.await.unwrap().unwrap_err().code(), "rejected");
        cancel.cancel();
        router.await.unwrap();
    }
}

//! The status message on `pavlov/v1/<robot>/status`: what the fleet page shows of a robot — its mode, the
//! link, the tick health (the `/healthz` verdict and the tick figures), key counters, and the URL of the
//! robot's own dashboard.

use std::sync::Arc;
use std::time::{SystemTime, UNIX_EPOCH};

use pavlov::control::Mode;
use pavlov::record::{LinkStatus, TickRecord};
use serde::Serialize;

use crate::server::Server;
use crate::telemetry::counters::{ZenohCounters, ZenohFigures};
use crate::telemetry::{Health, HealthFigures, Verdict};

/// What the status message says.
#[derive(Debug, Clone, Serialize)]
pub struct Status {
    /// The robot's name.
    pub robot: String,
    /// The program and its version.
    pub program: String,
    /// Where its dashboard is.
    pub dashboard_url: String,
    /// The mode of the newest tick (`None` before the first).
    pub mode: Option<Mode>,
    /// Whether the e-stop is latched.
    pub estop: bool,
    /// The newest tick.
    pub seq: Option<u64>,
    /// The link as the newest tick saw it.
    pub link: Option<LinkStatus>,
    /// `ok` or why not (the `/healthz` answer).
    pub health: String,
    /// Whether the health is ok.
    pub ok: bool,
    /// The tick figures.
    pub ticks: HealthFigures,
    /// The bridge's counters.
    pub zenoh: ZenohFigures,
    /// Whether commands are taken over Zenoh.
    pub commands: bool,
    /// When this was sent, Unix ms.
    pub unix_ms: u64,
}

/// Builds status messages from the newest tick and the server's health.
pub(crate) struct StatusSource {
    robot: String,
    dashboard_url: String,
    commands: bool,
    health: Health,
    counters: Arc<ZenohCounters>,
    mode: Option<Mode>,
    estop: bool,
    seq: Option<u64>,
    link: Option<LinkStatus>,
}

impl StatusSource {
    /// The source for `server`, publishing `dashboard_url`.
    pub(crate) fn new(
        server: &Server,
        dashboard_url: String,
        counters: Arc<ZenohCounters>,
    ) -> StatusSource {
        StatusSource {
            robot: server.config().zenoh.robot.clone(),
            dashboard_url,
            commands: server.config().zenoh.commands,
            health: server.health(),
            counters,
            mode: None,
            estop: false,
            seq: None,
            link: None,
        }
    }

    /// Notes the newest tick.
    pub(crate) fn saw(&mut self, record: &TickRecord) {
        self.mode = Some(record.mode);
        self.estop = record.estop;
        self.seq = Some(record.seq);
        self.link = Some(record.link);
    }

    /// The status now.
    pub(crate) fn status(&self) -> Status {
        let verdict = self.health.verdict();
        Status {
            robot: self.robot.clone(),
            program: crate::provenance::BUILD.program(),
            dashboard_url: self.dashboard_url.clone(),
            mode: self.mode,
            estop: self.estop,
            seq: self.seq,
            link: self.link,
            ok: verdict == Verdict::Ok,
            health: verdict.describe(),
            ticks: self.health.figures(),
            zenoh: self.counters.figures(),
            commands: self.commands,
            unix_ms: SystemTime::now()
                .duration_since(UNIX_EPOCH)
                .map_or(0, |d| d.as_millis() as u64),
        }
    }

    /// The status now, as JSON.
    pub(crate) fn message(&self) -> Vec<u8> {
        serde_json::to_vec(&self.status()).unwrap_or_default()
    }
}

//! The skeleton ingest actor: body skeletons as OSC over UDP (OSCeleton or KinectV2-OSC) into the `pose` watch
//! that learning reads every tick.
//!
//! A thin shell: it receives datagrams into a 64 KiB buffer, decodes them with `rosc`, turns them into joint
//! updates with the pure `decode::Decoder`, picks one person with the pure `select::UserSelector`, stamps
//! every joint with milliseconds since the server's `started` instant (the same clock as learning's `now_ms`,
//! so joint ages are right) and publishes the pose with `send_modify`. Malformed datagrams are counted by kind
//! in [`IngestStats`] and logged at most once per `LOG_EVERY`; nothing a sender does can stop the actor.

pub(crate) mod decode;
pub(crate) mod select;

use std::net::SocketAddr;
use std::time::Duration;

use pavlov::config::{SkeletonConfig, SkeletonFormat};
use pavlov::skeleton::PoseTracker;
use tokio::net::UdpSocket;
use tokio::sync::watch;
use tokio::task::JoinHandle;
use tokio::time::Instant;
use tokio_util::sync::CancellationToken;

use decode::{DecodeCounts, Decoder, Malformed, SkeletonEvent, UserId};
use select::{Applied, DEFAULT_SILENCE_MS, UserSelector};

/// The receive buffer: larger than any UDP datagram over IPv4 (65,507 bytes), so a full OSCeleton frame with
/// orientations (~1.5 kB) is never cut off.
pub const RECEIVE_BUFFER_BYTES: usize = 64 * 1024;

/// Malformed input is logged at most this often (the counters always count).
pub(crate) const LOG_EVERY: Duration = Duration::from_secs(5);

/// The socket's kernel receive buffer we ask for, so bursts are not lost while the actor is busy.
const SOCKET_RCVBUF_BYTES: usize = 1 << 20;

/// Errors starting the ingest.
#[derive(Debug, thiserror::Error)]
pub enum IngestError {
    /// `listen` is not a socket address.
    #[error("skeleton listen address `{0}` is not like 127.0.0.1:7110")]
    BadAddress(String),
    /// The UDP socket could not be opened.
    #[error("cannot listen for skeletons on {addr}: {source}")]
    Bind {
        /// The address.
        addr: SocketAddr,
        /// Why.
        source: std::io::Error,
    },
}

/// How the ingest runs.
#[derive(Debug, Clone, PartialEq)]
pub struct IngestSettings {
    /// UDP address to listen on (port 0: any free port).
    pub listen: SocketAddr,
    /// The wire format.
    pub format: SkeletonFormat,
    /// Swap left and right.
    pub swap_lr: bool,
    /// Silence after which another user may be selected, ms.
    pub silence_ms: u64,
    /// Receive buffer, bytes; a datagram that fills it is counted as oversized and dropped.
    pub buffer_bytes: usize,
}

impl IngestSettings {
    /// Settings from the `[skeleton]` table.
    pub(crate) fn from_config(cfg: &SkeletonConfig) -> Result<Self, IngestError> {
        let listen = cfg
            .listen
            .parse()
            .map_err(|_| IngestError::BadAddress(cfg.listen.clone()))?;
        Ok(IngestSettings {
            listen,
            format: cfg.format,
            swap_lr: cfg.swap_lr,
            silence_ms: DEFAULT_SILENCE_MS,
            buffer_bytes: RECEIVE_BUFFER_BYTES,
        })
    }
}

/// What the ingest has seen so far.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct IngestStats {
    /// Decoder counters, malformed input by kind.
    pub counts: DecodeCounts,
    /// Socket receive errors.
    pub(crate) receive_errors: u64,
    /// Joints dropped because they belong to another (or no yet selected) user.
    pub other_user_joints: u64,
    /// The selected user.
    pub current_user: Option<UserId>,
    /// How many times a user was selected.
    pub selections: u64,
    /// When the newest datagram arrived, ms since `started`.
    pub(crate) last_datagram_ms: Option<u64>,
}

/// A running ingest.
#[derive(Debug, Clone)]
pub struct SkeletonIngest {
    /// The address it listens on (the real port when 0 was asked for).
    pub local_addr: SocketAddr,
    /// Its counters, updated after every datagram.
    pub stats: watch::Receiver<IngestStats>,
}

/// A skeleton socket, bound but not yet read.
pub(crate) struct BoundSkeleton {
    socket: UdpSocket,
    settings: IngestSettings,
    local_addr: SocketAddr,
}

impl BoundSkeleton {
    /// Starts the actor on the bound socket; it runs until `cancel` fires.
    pub(crate) fn spawn(
        self,
        pose: watch::Sender<PoseTracker>,
        started: Instant,
        cancel: CancellationToken,
    ) -> (SkeletonIngest, JoinHandle<()>) {
        let BoundSkeleton {
            socket,
            settings,
            local_addr,
        } = self;
        let (stats_tx, stats_rx) = watch::channel(IngestStats::default());
        tracing::info!(%local_addr, format = ?settings.format, swap_lr = settings.swap_lr, "skeleton ingest listening");
        let handle = tokio::spawn(run(socket, settings, pose, stats_tx, started, cancel));
        (
            SkeletonIngest {
                local_addr,
                stats: stats_rx,
            },
            handle,
        )
    }
}

/// Binds the socket of `settings`.
pub(crate) fn bind(settings: IngestSettings) -> Result<BoundSkeleton, IngestError> {
    let bind_err = |source| IngestError::Bind {
        addr: settings.listen,
        source,
    };
    let socket = open_socket(settings.listen).map_err(bind_err)?;
    let local_addr = socket.local_addr().map_err(bind_err)?;
    Ok(BoundSkeleton {
        socket,
        settings,
        local_addr,
    })
}

/// Opens the socket and starts the actor; it runs until `cancel` fires.
pub async fn spawn(
    settings: IngestSettings,
    pose: watch::Sender<PoseTracker>,
    started: Instant,
    cancel: CancellationToken,
) -> Result<(SkeletonIngest, JoinHandle<()>), IngestError> {
    Ok(bind(settings)?.spawn(pose, started, cancel))
}

fn open_socket(addr: SocketAddr) -> std::io::Result<UdpSocket> {
    let socket = socket2::Socket::new(
        socket2::Domain::for_address(addr),
        socket2::Type::DGRAM,
        Some(socket2::Protocol::UDP),
    )?;
    if let Err(e) = socket.set_recv_buffer_size(SOCKET_RCVBUF_BYTES) {
        tracing::debug!("could not enlarge the skeleton socket's receive buffer: {e}");
    }
    socket.bind(&addr.into())?;
    socket.set_nonblocking(true)?;
    UdpSocket::from_std(socket.into())
}

/// Logs malformed input at most once per [`LOG_EVERY`], with how many were not logged in between.
struct MalformedLog {
    last: Option<Instant>,
    suppressed: u64,
}

impl MalformedLog {
    fn note(&mut self, kind: Malformed, from: SocketAddr, detail: &str, stats: &IngestStats) {
        let now = Instant::now();
        if self.last.is_some_and(|t| now.duration_since(t) < LOG_EVERY) {
            self.suppressed += 1;
            return;
        }
        tracing::warn!(
            ?kind, %from, detail, suppressed = self.suppressed, counts = ?stats.counts,
            "malformed skeleton input ignored"
        );
        self.last = Some(now);
        self.suppressed = 0;
    }
}

async fn run(
    socket: UdpSocket,
    settings: IngestSettings,
    pose: watch::Sender<PoseTracker>,
    stats_tx: watch::Sender<IngestStats>,
    started: Instant,
    cancel: CancellationToken,
) {
    let decoder = Decoder::new(settings.format, settings.swap_lr);
    let mut selector = UserSelector::new(settings.silence_ms);
    let mut buf = vec![0u8; settings.buffer_bytes.max(1)];
    let mut stats = IngestStats::default();
    let mut log = MalformedLog {
        last: None,
        suppressed: 0,
    };
    let mut events: Vec<SkeletonEvent> = Vec::new();
    loop {
        let received = tokio::select! {
            _ = cancel.cancelled() => break,
            r = socket.recv_from(&mut buf) => r,
        };
        let (n, from) = match received {
            Ok(r) => r,
            Err(e) => {
                stats.receive_errors += 1;
                tracing::debug!("skeleton socket receive error: {e}");
                stats_tx.send_replace(stats);
                tokio::time::sleep(Duration::from_millis(1)).await;
                continue;
            }
        };
        let now_ms = u64::try_from(
            Instant::now()
                .saturating_duration_since(started)
                .as_millis(),
        )
        .unwrap_or(u64::MAX);
        stats.counts.datagrams += 1;
        stats.last_datagram_ms = Some(now_ms);
        let datagram = buf.get(..n).unwrap_or_default();
        if n >= buf.len() {
            stats.counts.count(Malformed::Oversized);
            log.note(
                Malformed::Oversized,
                from,
                "datagram filled the buffer",
                &stats,
            );
        } else if !decode::nesting_within(datagram, decode::MAX_BUNDLE_DEPTH) {
            stats.counts.count(Malformed::TooDeep);
            log.note(Malformed::TooDeep, from, "bundles nested too deep", &stats);
        } else {
            match rosc::decoder::decode_udp(datagram) {
                Err(e) => {
                    stats.counts.count(Malformed::Undecodable);
                    log.note(Malformed::Undecodable, from, &e.to_string(), &stats);
                }
                Ok((rest, _)) if !rest.is_empty() => {
                    stats.counts.count(Malformed::Truncated);
                    let detail = format!("{} bytes left over", rest.len());
                    log.note(Malformed::Truncated, from, &detail, &stats);
                }
                Ok((_, packet)) => {
                    events.clear();
                    let bad = decoder.decode(&packet, &mut events, &mut stats.counts);
                    if let Some(&kind) = bad.first() {
                        log.note(kind, from, "in an OSC packet", &stats);
                    }
                    if !events.is_empty() {
                        apply_events(&events, &mut selector, &mut stats, now_ms, &pose);
                    }
                }
            }
        }
        stats_tx.send_replace(stats);
    }
}

fn apply_events(
    events: &[SkeletonEvent],
    selector: &mut UserSelector,
    stats: &mut IngestStats,
    now_ms: u64,
    pose: &watch::Sender<PoseTracker>,
) {
    pose.send_modify(|p| {
        for applied in selector.apply_all(events, now_ms, p) {
            match applied {
                Applied::OtherUser => stats.other_user_joints += 1,
                Applied::Selected(user) => {
                    stats.selections += 1;
                    tracing::info!(user, "skeleton: tracking user");
                }
                Applied::Lost(user) => tracing::info!(user, "skeleton: user lost"),
                Applied::Restarted(user) => tracing::info!(user, "skeleton: new skeleton"),
                Applied::JointUsed | Applied::Nothing => {}
            }
        }
    });
    stats.current_user = selector.current();
}

/// Binds the ingest's socket when `config`'s `[skeleton]` is enabled (by default: when the stimulus is
/// `left_elbow`). A socket that cannot be opened is an error: without skeletons every elbow angle would be
/// invalid and the command stimulus could never fire.
pub(crate) async fn bind_for(
    config: &pavlov::config::Config,
) -> Result<Option<BoundSkeleton>, IngestError> {
    if !config.skeleton.is_enabled(&config.control.stimulus) {
        return Ok(None);
    }
    let settings = IngestSettings::from_config(&config.skeleton)?;
    bind(settings).map(Some)
}

#[cfg(test)]
mod tests {
    use super::*;
    use pavlov::config::{Config, ConfigError};

    const STALL: &str = include_str!("../../../../config/stall.toml");
    const INTERACTION: &str = include_str!("../../../../config/interaction.toml");

    fn with(base: &str, table: &str) -> Result<Config, ConfigError> {
        Config::from_toml(&format!("{base}\n[skeleton]\n{table}\n"))
    }

    #[test]
    fn enabled_by_default_only_for_the_elbow_stimulus() {
        let stall = Config::from_toml(STALL).unwrap();
        let inter = Config::from_toml(INTERACTION).unwrap();
        assert!(!stall.skeleton.is_enabled(&stall.control.stimulus));
        assert!(inter.skeleton.is_enabled(&inter.control.stimulus));
        let forced = with(STALL, "enabled = true").unwrap();
        assert!(forced.skeleton.is_enabled(&forced.control.stimulus));
        let off = with(INTERACTION, "enabled = false").unwrap();
        assert!(!off.skeleton.is_enabled(&off.control.stimulus));
    }

    #[test]
    fn keys_parse_into_settings() {
        let cfg = with(
            INTERACTION,
            "listen = \"127.0.0.1:9000\"\nformat = \"kinect_v2\"\nswap_lr = true\nmax_joint_age_ms = 150",
        )
        .unwrap();
        let s = IngestSettings::from_config(&cfg.skeleton).unwrap();
        assert_eq!(s.listen, "127.0.0.1:9000".parse().unwrap());
        assert_eq!(s.format, SkeletonFormat::KinectV2);
        assert!(s.swap_lr);
        assert_eq!(s.buffer_bytes, RECEIVE_BUFFER_BYTES);
        assert_eq!(cfg.skeleton.max_joint_age_ms, 150);
        let normalized = with(INTERACTION, "format = \"osceleton_normalized\"").unwrap();
        assert_eq!(
            normalized.skeleton.format,
            SkeletonFormat::OsceletonNormalized
        );
    }

    #[test]
    fn bad_values_name_their_key() {
        for (table, key) in [
            ("listen = \"localhost\"", "skeleton.listen"),
            ("max_joint_age_ms = 0", "skeleton.max_joint_age_ms"),
        ] {
            match with(INTERACTION, table) {
                Err(ConfigError::Invalid { key: k, .. }) => assert_eq!(k, key),
                other => panic!("{table}: {other:?}"),
            }
        }
        for (table, word) in [("format = \"nite\"", "nite"), ("swap = true", "swap")] {
            let e = with(INTERACTION, table).unwrap_err().to_string();
            assert!(e.contains(word), "{e}");
        }
    }

    #[tokio::test]
    async fn a_taken_port_is_an_error_naming_the_address() {
        let first = std::net::UdpSocket::bind("127.0.0.1:0").unwrap();
        let addr = first.local_addr().unwrap();
        let (tx, _rx) = watch::channel(PoseTracker::new(100));
        let settings = IngestSettings {
            listen: addr,
            format: SkeletonFormat::OsceletonMm,
            swap_lr: false,
            silence_ms: DEFAULT_SILENCE_MS,
            buffer_bytes: RECEIVE_BUFFER_BYTES,
        };
        match spawn(settings, tx, Instant::now(), CancellationToken::new()).await {
            Err(e @ IngestError::Bind { .. }) => assert!(e.to_string().contains(&addr.to_string())),
            Err(e) => panic!("{e}"),
            Ok(_) => panic!("bound a taken port"),
        }
    }
}

//! `[dashboard]`: the HTTP/websocket endpoint that serves the dashboard and takes commands: where it
//! listens, the token that separates operators (who may command) from watchers (who may only watch), and
//! the limits that keep an operator's way in open however many others connect.

use serde::{Deserialize, Serialize};

use super::{ConfigError, invalid};

/// Shortest token accepted on a non-loopback bind, in characters. A 16-character token of letters and
/// digits has about 95 bits; `pavlov serve` generates 32 hex digits (128 bits) when none is given.
pub const MIN_PUBLIC_TOKEN_CHARS: usize = 16;
/// The least estimated strength of a token on a non-loopback bind, bits ([`token_strength_bits`]). A
/// 16-character token needs at least 14 distinct characters; `pavlov serve`'s generated 32 hex digits have
/// about 120 by this estimate.
pub const MIN_PUBLIC_TOKEN_BITS: f64 = 60.0;

/// A token's estimated strength, bits: its length times log₂ of the number of distinct characters in it.
/// It judges variety, not only length, so `aaaaaaaaaaaaaaaa` (0 bits) or 16 spaces are refused where a
/// length rule took them; it cannot see a dictionary word, so it is an upper bound, not a guarantee.
pub fn token_strength_bits(token: &str) -> f64 {
    let mut distinct: Vec<char> = token.chars().collect();
    let length = distinct.len();
    distinct.sort_unstable();
    distinct.dedup();
    length as f64 * (distinct.len().max(1) as f64).log2()
}

/// Why `token` is too weak to guard a non-loopback address (`None`: strong enough): shorter than
/// [`MIN_PUBLIC_TOKEN_CHARS`] or below [`MIN_PUBLIC_TOKEN_BITS`].
pub fn public_token_problem(token: &str) -> Option<String> {
    let chars = token.chars().count();
    let bits = token_strength_bits(token);
    let advice = "e.g. 32 random hex digits (`openssl rand -hex 16`), or leave --token out and use the \
                  one `pavlov serve` generates";
    if chars < MIN_PUBLIC_TOKEN_CHARS {
        Some(format!(
            "needs a token of at least {MIN_PUBLIC_TOKEN_CHARS} characters, got {chars}: {advice}"
        ))
    } else if bits < MIN_PUBLIC_TOKEN_BITS {
        Some(format!(
            "needs a token with more variety: about {bits:.0} bits (its {chars} characters, {} of them \
             distinct), at least {MIN_PUBLIC_TOKEN_BITS:.0} needed: {advice}",
            (2f64.powf(bits / chars.max(1) as f64)).round()
        ))
    } else {
        None
    }
}

/// The longest per-client outgoing queue, messages: 200 s of ticks at 50 Hz, about 10 MB. A client that
/// reads nothing is disconnected after 10 s anyway; a longer queue only holds memory and delay.
pub const MAX_CLIENT_QUEUE: usize = 10_000;
/// The longest `history_s`: an hour of ticks, about 11 MB of compact rows at 50 Hz with one prediction
/// (the ring stores about 64 bytes a tick, not the JSON it sends).
pub const MAX_HISTORY_S: u64 = 3600;

/// `[dashboard]`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields, default)]
pub struct DashboardConfig {
    /// Address to listen on. Binding anything but loopback requires `token` (at least
    /// [`MIN_PUBLIC_TOKEN_CHARS`] characters).
    pub bind: String,
    /// Shared secret a client presents in the websocket handshake before any command is accepted.
    pub token: Option<String>,
    /// Whether a client without the token may watch (receive ticks) without sending commands.
    pub watch_without_token: bool,
    /// Extra allowed `Origin` values (the server's own origin and loopback origins are always allowed).
    pub allowed_origins: Vec<String>,
    /// Largest websocket message accepted, bytes.
    pub max_message_bytes: usize,
    /// Per-client queue of outgoing messages; when full, the oldest ticks are dropped.
    pub client_queue: usize,
    /// Most operators (websocket clients that may command: they presented the token, or none is
    /// configured) at once. Watchers never take an operator's place. Formerly `max_clients`.
    #[serde(alias = "max_clients")]
    pub max_operators: usize,
    /// Most watch-only websocket clients at once (all addresses together).
    pub max_watchers: usize,
    /// Most watch-only websocket clients from one source address (an IPv6 address counts by its /64).
    pub max_watchers_per_address: usize,
    /// Most TCP connections that are not (yet) websockets, all addresses together; beyond it, a new
    /// connection evicts the oldest one of the address holding the most.
    pub max_pending: usize,
    /// Most TCP connections that are not (yet) websockets from one source address; beyond it, a new
    /// connection from that address evicts its oldest.
    pub max_pending_per_address: usize,
    /// Seconds of recent ticks (and the events among them) the server keeps in memory and sends a newly
    /// connected client after `hello`, so a page opened mid-run shows what came before; 0 keeps none.
    pub history_s: u64,
}

impl Default for DashboardConfig {
    fn default() -> Self {
        DashboardConfig {
            bind: "127.0.0.1:8080".into(),
            token: None,
            watch_without_token: true,
            allowed_origins: Vec::new(),
            max_message_bytes: 64 * 1024,
            client_queue: 256,
            max_operators: 32,
            max_watchers: 64,
            max_watchers_per_address: 16,
            max_pending: 128,
            max_pending_per_address: 16,
            history_s: 300,
        }
    }
}

fn within(key: &str, value: usize, lo: usize, hi: usize) -> Result<(), ConfigError> {
    if (lo..=hi).contains(&value) {
        Ok(())
    } else {
        Err(invalid(
            format!("dashboard.{key}"),
            format!("must be between {lo} and {hi}, got {value}"),
        ))
    }
}

impl DashboardConfig {
    /// The bound address, parsed.
    pub fn bind_addr(&self) -> Result<std::net::SocketAddr, ConfigError> {
        self.bind.parse().map_err(|_| {
            invalid(
                "dashboard.bind",
                format!("`{}` is not an address like 127.0.0.1:8080", self.bind),
            )
        })
    }

    /// Whether `bind` is an address other machines can reach (anything but loopback).
    pub fn is_public(&self) -> bool {
        self.bind_addr().is_ok_and(|a| !a.ip().is_loopback())
    }

    /// The token, if one is set and not empty.
    pub fn token(&self) -> Option<&str> {
        self.token.as_deref().filter(|t| !t.is_empty())
    }

    /// Checks every value; errors name the key and the bound.
    pub fn validate(&self) -> Result<(), ConfigError> {
        let bind = self.bind_addr()?;
        if !bind.ip().is_loopback() {
            match self.token() {
                None => {
                    return Err(invalid(
                        "dashboard.token",
                        format!(
                            "binding {} (not loopback) requires a token (`pavlov serve` generates one when none is given)",
                            self.bind
                        ),
                    ));
                }
                Some(t) => {
                    if let Some(problem) = public_token_problem(t) {
                        return Err(invalid(
                            "dashboard.token",
                            format!("binding {} (not loopback) {problem}", self.bind),
                        ));
                    }
                }
            }
        }
        within(
            "max_message_bytes",
            self.max_message_bytes,
            1024,
            16 * 1024 * 1024,
        )?;
        within("client_queue", self.client_queue, 1, MAX_CLIENT_QUEUE)?;
        within("max_operators", self.max_operators, 1, 1024)?;
        within("max_watchers", self.max_watchers, 0, 4096)?;
        within(
            "max_watchers_per_address",
            self.max_watchers_per_address,
            1,
            4096,
        )?;
        within("max_pending", self.max_pending, 1, 4096)?;
        within(
            "max_pending_per_address",
            self.max_pending_per_address,
            1,
            self.max_pending,
        )?;
        if self.history_s > MAX_HISTORY_S {
            return Err(invalid(
                "dashboard.history_s",
                format!(
                    "must be between 0 and {MAX_HISTORY_S} (an hour), got {}",
                    self.history_s
                ),
            ));
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn with(edit: impl FnOnce(&mut DashboardConfig)) -> Result<(), ConfigError> {
        let mut d = DashboardConfig::default();
        edit(&mut d);
        d.validate()
    }

    fn key_of(r: Result<(), ConfigError>) -> String {
        match r {
            Err(ConfigError::Invalid { key, .. }) => key,
            other => panic!("expected an invalid key, got {other:?}"),
        }
    }

    #[test]
    fn token_strength_is_length_times_log2_of_the_distinct_characters() {
        assert_eq!(token_strength_bits(""), 0.0);
        assert_eq!(token_strength_bits("aaaa"), 0.0);
        assert_eq!(token_strength_bits("abab"), 4.0);
        assert_eq!(token_strength_bits("0123456789abcdef"), 64.0);
        // A generated token: 32 hex digits, at least 8 distinct.
        assert!(token_strength_bits("3f2a9c0d7e1b4a5c6d8e9f0a1b2c3d4e") > 120.0);
    }

    #[test]
    fn the_defaults_are_valid() {
        assert_eq!(DashboardConfig::default().validate(), Ok(()));
    }

    #[test]
    fn a_public_bind_needs_a_long_enough_token() {
        let public = |token: Option<&str>| {
            with(|d| {
                d.bind = "0.0.0.0:8080".into();
                d.token = token.map(String::from);
            })
        };
        assert_eq!(key_of(public(None)), "dashboard.token");
        assert_eq!(key_of(public(Some(""))), "dashboard.token");
        let e = public(Some("a")).unwrap_err().to_string();
        assert!(e.starts_with("dashboard.token:") && e.contains("16"), "{e}");
        assert_eq!(key_of(public(Some("fifteen-chars!!"))), "dashboard.token");
        assert_eq!(public(Some("Sixteen-chars:7Q")), Ok(()));
        // Length alone is not strength: no variety, no token.
        for weak in [
            "                ",
            "aaaaaaaaaaaaaaaa",
            "abababababababab",
            "sixteen-chars!!!",
        ] {
            let e = public(Some(weak)).unwrap_err().to_string();
            assert!(
                e.contains("more variety") && e.contains("openssl"),
                "{weak:?}: {e}"
            );
        }
        assert_eq!(
            public(Some("0123456789abcdef")),
            Ok(()),
            "16 distinct: 64 bits"
        );
        // Loopback needs none, and takes a short one.
        assert_eq!(with(|d| d.token = Some("a".into())), Ok(()));
        assert_eq!(with(|d| d.bind = "[::1]:0".into()), Ok(()));
    }

    #[test]
    fn limits_name_their_key_and_bounds() {
        type Edit = fn(&mut DashboardConfig);
        let cases: [(&str, Edit); 7] = [
            ("dashboard.max_operators", |d| d.max_operators = 0),
            ("dashboard.max_watchers", |d| d.max_watchers = 5000),
            ("dashboard.max_watchers_per_address", |d| {
                d.max_watchers_per_address = 0
            }),
            ("dashboard.max_pending", |d| d.max_pending = 0),
            ("dashboard.max_pending_per_address", |d| {
                d.max_pending_per_address = d.max_pending + 1
            }),
            ("dashboard.client_queue", |d| d.client_queue = 0),
            ("dashboard.max_message_bytes", |d| d.max_message_bytes = 10),
        ];
        for (key, edit) in cases {
            let e = with(edit).unwrap_err();
            assert!(e.to_string().contains("must be between"), "{e}");
            assert_eq!(key_of(Err(e)), key);
        }
        assert_eq!(with(|d| d.max_watchers = 0), Ok(()));
    }

    #[test]
    fn history_is_bounded_to_an_hour() {
        assert_eq!(DashboardConfig::default().history_s, 300);
        assert_eq!(with(|d| d.history_s = 0), Ok(()));
        assert_eq!(with(|d| d.history_s = MAX_HISTORY_S), Ok(()));
        let e = with(|d| d.history_s = MAX_HISTORY_S + 1).unwrap_err();
        assert!(e.to_string().contains("between 0 and 3600"), "{e}");
        assert_eq!(key_of(Err(e)), "dashboard.history_s");
        let d: DashboardConfig = toml::from_str("history_s = 60").unwrap();
        assert_eq!(d.history_s, 60);
    }

    #[test]
    fn max_clients_is_read_as_max_operators() {
        let d: DashboardConfig = toml::from_str("max_clients = 7").unwrap();
        assert_eq!(d.max_operators, 7);
    }
}

//! Who may connect to the websocket and who may send commands, decided in the handshake.
//!
//! - **Origin.** Browsers let any page open a websocket to any host (loopback included), so the `Origin`
//!   header is checked against an allowlist: the loopback origins on the server's port, the bound address's
//!   own origin, the configured `allowed_origins`, and `http://<Host>` when the `Host` header is a literal
//!   IP address (a page loaded from this server by IP; a DNS name there could be a rebinding attack, so it
//!   must be listed). A request without `Origin` is not from a browser page and passes (tests, scripts).
//! - **Host.** `/recording` and `/metrics` are fetched by plain requests, which a page of any site can
//!   send; a DNS-rebinding page (a name of the attacker's that now resolves to this server) even reads the
//!   answer, as same-origin. Its requests carry the attacker's name in `Host`, so these routes also check
//!   `Host` ([`AccessPolicy::check_host`]): an IP literal (not `0.0.0.0` or `[::]`), `localhost`, or the
//!   host of a configured `allowed_origins` entry, on any port (a tunnel or a proxy may change the port;
//!   the name is what a rebinding page controls). A request without `Host` is not from a browser and
//!   passes.
//! - **Token.** When a token is configured, a client presents it in the handshake, either as a
//!   subprotocol entry `token.<token>` (next to `pavlov.v1`) or as the `token` query parameter. A wrong
//!   token is refused outright; no token gives a watch-only connection when `watch_without_token` is set,
//!   and is refused otherwise. Without a configured token (loopback only) every client may command.

use std::net::{IpAddr, SocketAddr};

use pavlov::config::DashboardConfig;

use super::protocol::TOKEN_PROTOCOL_PREFIX;

/// What a connection may do.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Access {
    /// Receive ticks and send commands.
    Command,
    /// Receive ticks only; commands get an `unauthorized` error.
    Watch,
}

/// Why a handshake was refused.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub(crate) enum Denied {
    /// `Origin` not on the allowlist (HTTP 403).
    #[error("origin `{0}` is not allowed; add it to [dashboard] allowed_origins")]
    Origin(String),
    /// A token was presented and it is wrong (HTTP 401).
    #[error("wrong token")]
    WrongToken,
    /// No token, and watching without one is off (HTTP 401).
    #[error("a token is required: pass ?token=… or the subprotocol token.<token>")]
    TokenRequired,
    /// `Host` is not a name of this server (HTTP 403).
    #[error(
        "Host `{0}` is not a name of this server (a DNS-rebinding page?): use its IP address or localhost, \
         or add the origin you use for it to [dashboard] allowed_origins"
    )]
    Host(String),
}

/// The rules, fixed when the endpoint starts.
#[derive(Debug, Clone)]
pub(crate) struct AccessPolicy {
    token: Option<String>,
    watch_without_token: bool,
    origins: Vec<String>,
    /// Host names (without port) `Host` may carry besides IP literals and `localhost`.
    hosts: Vec<String>,
}

fn origin_of(host: &str, port: u16) -> String {
    format!("http://{host}:{port}")
}

fn normalise_origin(origin: &str) -> String {
    origin.trim().trim_end_matches('/').to_ascii_lowercase()
}

impl AccessPolicy {
    /// The policy for an endpoint bound to `local`.
    pub(crate) fn new(config: &DashboardConfig, local: SocketAddr) -> Self {
        let port = local.port();
        let mut origins = vec![
            origin_of("127.0.0.1", port),
            origin_of("localhost", port),
            origin_of("[::1]", port),
        ];
        if !local.ip().is_unspecified() {
            let host = match local.ip() {
                IpAddr::V4(ip) => ip.to_string(),
                IpAddr::V6(ip) => format!("[{ip}]"),
            };
            origins.push(origin_of(&host, port));
        }
        let configured: Vec<String> = config
            .allowed_origins
            .iter()
            .map(|o| normalise_origin(o))
            .collect();
        let hosts = configured
            .iter()
            .filter_map(|o| o.split_once("://").map(|(_, authority)| authority))
            .map(|authority| host_name(authority).to_string())
            .collect();
        origins.extend(configured);
        AccessPolicy {
            token: config.token.clone().filter(|t| !t.is_empty()),
            watch_without_token: config.watch_without_token,
            origins,
            hosts,
        }
    }

    /// Whether commands need a token.
    pub(crate) fn token_required(&self) -> bool {
        self.token.is_some()
    }

    /// Checks the `Origin` header (`None` = absent) against the allowlist; `host` is the `Host` header.
    pub(crate) fn check_origin(
        &self,
        origin: Option<&str>,
        host: Option<&str>,
    ) -> Result<(), Denied> {
        let Some(origin) = origin else {
            return Ok(());
        };
        let o = normalise_origin(origin);
        if self.origins.contains(&o) {
            return Ok(());
        }
        if let Some(host) = host
            && host_is_ip_literal(host)
            && o == format!("http://{}", host.to_ascii_lowercase())
        {
            return Ok(());
        }
        Err(Denied::Origin(origin.to_string()))
    }

    /// Checks the `Host` header (`None` = absent): an IP literal, `localhost` or a configured origin's host,
    /// on any port.
    pub(crate) fn check_host(&self, host: Option<&str>) -> Result<(), Denied> {
        let Some(host) = host else {
            return Ok(());
        };
        let h = host.trim().to_ascii_lowercase();
        if host_is_ip_literal(&h) {
            return Ok(());
        }
        let name = host_name(&h);
        if name == "localhost" || self.hosts.iter().any(|n| n == name) {
            return Ok(());
        }
        Err(Denied::Host(host.to_string()))
    }

    /// Decides access from the token presented in the handshake, if any.
    pub(crate) fn check_token(&self, presented: Option<&str>) -> Result<Access, Denied> {
        let Some(expected) = &self.token else {
            return Ok(Access::Command);
        };
        match presented {
            Some(p) if constant_time_eq(p.as_bytes(), expected.as_bytes()) => Ok(Access::Command),
            Some(_) => Err(Denied::WrongToken),
            None if self.watch_without_token => Ok(Access::Watch),
            None => Err(Denied::TokenRequired),
        }
    }
}

/// The token a client presented: the `token.<t>` subprotocol entry wins over the `token` query parameter.
pub(crate) fn presented_token<'a>(
    query_token: Option<&'a str>,
    protocols: impl IntoIterator<Item = &'a str>,
) -> Option<&'a str> {
    protocols
        .into_iter()
        .flat_map(|h| h.split(','))
        .map(str::trim)
        .find_map(|p| p.strip_prefix(TOKEN_PROTOCOL_PREFIX))
        .or(query_token)
}

/// The name in `authority` without its port (`[::1]:8080` → `[::1]`, `lab:8080` → `lab`).
fn host_name(authority: &str) -> &str {
    let authority = authority.split('/').next().unwrap_or_default();
    match authority.rsplit_once(':') {
        Some((name, port))
            if port.bytes().all(|b| b.is_ascii_digit())
                && (!name.contains(':') || name.ends_with(']')) =>
        {
            name
        }
        _ => authority,
    }
}

fn host_is_ip_literal(host: &str) -> bool {
    if let Ok(addr) = host.parse::<SocketAddr>() {
        return !addr.ip().is_unspecified();
    }
    let bare = host.trim_start_matches('[').trim_end_matches(']');
    bare.parse::<IpAddr>().is_ok_and(|ip| !ip.is_unspecified())
}

/// Bytes of randomness in a generated token (128 bits).
const GENERATED_TOKEN_BYTES: usize = 16;

/// A random token for a server that binds a non-loopback address without one: 128 bits from the
/// operating system's generator (`/dev/urandom`), as 32 lowercase hex digits.
pub fn generate_token() -> std::io::Result<String> {
    use std::io::Read;
    let mut bytes = [0u8; GENERATED_TOKEN_BYTES];
    std::fs::File::open("/dev/urandom")?.read_exact(&mut bytes)?;
    Ok(bytes.iter().map(|b| format!("{b:02x}")).collect())
}

/// Compares without stopping at the first difference, so timing does not reveal how much of a guess is right
/// (nor, beyond the guess's own length, how long the token is). The one comparison of a presented token with
/// the configured one: the dashboard, the Foxglove gate and the Zenoh command queryable all use it.
pub(crate) fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    let mut diff = a.len() ^ b.len();
    for (i, &x) in a.iter().enumerate() {
        let y = b.get(i % b.len().max(1)).copied().unwrap_or(0);
        diff |= usize::from(x ^ y);
    }
    diff == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn policy(token: Option<&str>, watch: bool, extra: &[&str], bind: &str) -> AccessPolicy {
        let cfg = DashboardConfig {
            token: token.map(String::from),
            watch_without_token: watch,
            allowed_origins: extra.iter().map(|s| s.to_string()).collect(),
            ..DashboardConfig::default()
        };
        AccessPolicy::new(&cfg, bind.parse().unwrap())
    }

    #[test]
    fn loopback_origins_on_the_servers_port_pass() {
        let p = policy(None, true, &[], "127.0.0.1:8080");
        for o in [
            "http://127.0.0.1:8080",
            "http://localhost:8080",
            "http://LOCALHOST:8080/",
            "http://[::1]:8080",
        ] {
            assert_eq!(p.check_origin(Some(o), None), Ok(()), "{o}");
        }
        assert_eq!(p.check_origin(None, None), Ok(()));
    }

    #[test]
    fn foreign_origins_and_other_ports_are_refused() {
        let p = policy(None, true, &[], "127.0.0.1:8080");
        for o in [
            "http://evil.example",
            "http://127.0.0.1:9999",
            "https://127.0.0.1:8080",
            "null",
            "file://",
        ] {
            assert_eq!(
                p.check_origin(Some(o), Some("127.0.0.1:8080")),
                Err(Denied::Origin(o.into())),
                "{o}"
            );
        }
    }

    #[test]
    fn configured_origins_pass() {
        let p = policy(None, true, &["https://lab.example.org/"], "127.0.0.1:8080");
        assert_eq!(
            p.check_origin(Some("https://lab.example.org"), None),
            Ok(())
        );
    }

    #[test]
    fn a_page_loaded_by_ip_literal_passes_but_a_dns_name_must_be_listed() {
        let p = policy(Some("t"), true, &[], "0.0.0.0:8080");
        assert_eq!(
            p.check_origin(Some("http://192.168.1.5:8080"), Some("192.168.1.5:8080")),
            Ok(())
        );
        assert_eq!(
            p.check_origin(Some("http://[fe80::1]:8080"), Some("[fe80::1]:8080")),
            Ok(())
        );
        // DNS rebinding: the attacker's name resolves to us; Host and Origin agree but it is a name.
        assert!(
            p.check_origin(Some("http://rebind.evil:8080"), Some("rebind.evil:8080"))
                .is_err()
        );
        assert!(
            p.check_origin(Some("http://0.0.0.0:8080"), Some("0.0.0.0:8080"))
                .is_err()
        );
    }

    #[test]
    fn host_must_be_an_ip_literal_localhost_or_a_configured_origins_host() {
        let p = policy(None, true, &["https://lab.example.org"], "127.0.0.1:8080");
        for h in [
            "127.0.0.1:8080",
            "127.0.0.1",
            "localhost:8080",
            "LOCALHOST:9000",
            "[::1]:8080",
            "192.168.1.5:8080",
            "lab.example.org",
            "lab.example.org:443",
        ] {
            assert_eq!(p.check_host(Some(h)), Ok(()), "{h}");
        }
        assert_eq!(p.check_host(None), Ok(()), "not a browser");
        for h in [
            "evil.example",
            "evil.example:8080",
            "localhost.evil.example",
            "rebind.lab.example.org",
            "0.0.0.0:8080",
            "[::]:8080",
            "",
        ] {
            assert_eq!(p.check_host(Some(h)), Err(Denied::Host(h.into())), "{h}");
        }
        let refused = p.check_host(Some("evil.example")).unwrap_err().to_string();
        assert!(
            refused.contains("Host `evil.example` is not a name of this server"),
            "{refused}"
        );
    }

    #[test]
    fn the_bound_address_is_its_own_origin() {
        let p = policy(Some("t"), true, &[], "10.0.0.7:9000");
        assert_eq!(p.check_origin(Some("http://10.0.0.7:9000"), None), Ok(()));
    }

    #[test]
    fn without_a_configured_token_everyone_commands() {
        let p = policy(None, false, &[], "127.0.0.1:1");
        assert!(!p.token_required());
        assert_eq!(p.check_token(None), Ok(Access::Command));
        assert_eq!(p.check_token(Some("anything")), Ok(Access::Command));
    }

    #[test]
    fn with_a_token_only_its_holder_commands() {
        let p = policy(Some("s3cret"), true, &[], "127.0.0.1:1");
        assert_eq!(p.check_token(Some("s3cret")), Ok(Access::Command));
        assert_eq!(p.check_token(Some("s3cre")), Err(Denied::WrongToken));
        assert_eq!(p.check_token(Some("s3cret!")), Err(Denied::WrongToken));
        assert_eq!(p.check_token(Some("")), Err(Denied::WrongToken));
        assert_eq!(p.check_token(None), Ok(Access::Watch));
        let strict = policy(Some("s3cret"), false, &[], "127.0.0.1:1");
        assert_eq!(strict.check_token(None), Err(Denied::TokenRequired));
    }

    #[test]
    fn an_empty_configured_token_means_none() {
        assert!(!policy(Some(""), true, &[], "127.0.0.1:1").token_required());
    }

    #[test]
    fn the_token_comes_from_the_subprotocol_or_the_query() {
        assert_eq!(
            presented_token(Some("q"), ["pavlov.v1, token.abc"]),
            Some("abc")
        );
        assert_eq!(
            presented_token(Some("q"), ["pavlov.v1", "token.xyz"]),
            Some("xyz")
        );
        assert_eq!(presented_token(Some("q"), ["pavlov.v1"]), Some("q"));
        assert_eq!(presented_token(None, Vec::<&str>::new()), None);
    }

    #[test]
    fn generated_tokens_are_128_bit_hex_and_differ() {
        let a = generate_token().unwrap();
        let b = generate_token().unwrap();
        assert_eq!(a.len(), 32);
        assert!(
            a.bytes()
                .all(|c| c.is_ascii_hexdigit() && !c.is_ascii_uppercase())
        );
        assert_ne!(a, b);
        let public = DashboardConfig {
            bind: "0.0.0.0:8080".into(),
            token: Some(a),
            ..DashboardConfig::default()
        };
        assert_eq!(public.validate(), Ok(()));
    }

    #[test]
    fn constant_time_eq_is_equality() {
        assert!(constant_time_eq(b"abc", b"abc"));
        assert!(!constant_time_eq(b"abc", b"abd"));
        assert!(!constant_time_eq(b"abc", b"ab"));
        assert!(!constant_time_eq(b"", b"a"));
        assert!(constant_time_eq(b"", b""));
        assert!(!constant_time_eq(b"ab", b"abc"));
        assert!(!constant_time_eq(b"a", b""));
        assert!(!constant_time_eq(b"abcabc", b"abc"));
    }
}

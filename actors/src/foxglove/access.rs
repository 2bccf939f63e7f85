//! Who may open a Foxglove connection, decided from the HTTP request head before the websocket upgrade.
//!
//! Foxglove clients only ever read: the endpoint advertises no capability that lets a client publish,
//! set parameters or call services, so the token cannot unlock commands. It decides who may *watch*, with
//! the dashboard's own rule and secret (`[dashboard] token`, `--token`; `watch_without_token`):
//! - no token configured (only possible on loopback): every client may watch;
//! - a token configured: a client presents it as the `token` query parameter (`ws://HOST:8765/?token=T`,
//!   which is what the Foxglove app can send: it connects to the URL it is given) or as a websocket
//!   subprotocol entry `token.<T>` (next to `foxglove.sdk.v1`, for clients that can set one). A wrong
//!   token is refused (401); no token is refused (401) unless `watch_without_token` is set.
//!
//! The head is parsed here, purely, so the rules are tested without sockets ([`super::gate`] does the I/O).

use pavlov::config::DashboardConfig;

/// Why a connection was refused before the upgrade.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub(crate) enum Refusal {
    /// A token was presented and it is wrong (401).
    #[error("wrong token")]
    WrongToken,
    /// No token, and watching without one is off (401).
    #[error(
        "a token is required: connect to ws://HOST:PORT/?token=… (the dashboard's token, --token)"
    )]
    TokenRequired,
    /// Not an HTTP/1.1 `GET` request head (400).
    #[error("not a websocket request: {0}")]
    BadRequest(&'static str),
}

impl Refusal {
    /// The HTTP status line's code and reason.
    pub(crate) fn status(&self) -> (u16, &'static str) {
        match self {
            Refusal::WrongToken | Refusal::TokenRequired => (401, "Unauthorized"),
            Refusal::BadRequest(_) => (400, "Bad Request"),
        }
    }
}

/// The rule, fixed when the endpoint starts.
#[derive(Debug, Clone)]
pub(crate) struct WatchPolicy {
    token: Option<String>,
    watch_without_token: bool,
}

impl WatchPolicy {
    /// The dashboard's token and watch rule.
    pub(crate) fn new(config: &DashboardConfig) -> Self {
        WatchPolicy {
            token: config.token.clone().filter(|t| !t.is_empty()),
            watch_without_token: config.watch_without_token,
        }
    }

    /// Whether a client must present the token to connect at all.
    pub(crate) fn token_required(&self) -> bool {
        self.token.is_some() && !self.watch_without_token
    }

    /// Whether a token is configured (a non-loopback bind needs one).
    pub(crate) fn has_token(&self) -> bool {
        self.token.is_some()
    }

    /// Decides on a complete request head (`GET … HTTP/1.1` up to the blank line).
    pub(crate) fn admit(&self, head: &str) -> Result<(), Refusal> {
        let request = parse_head(head)?;
        let Some(expected) = &self.token else {
            return Ok(());
        };
        match request.token {
            Some(presented) if constant_time_eq(presented.as_bytes(), expected.as_bytes()) => {
                Ok(())
            }
            Some(_) => Err(Refusal::WrongToken),
            None if self.watch_without_token => Ok(()),
            None => Err(Refusal::TokenRequired),
        }
    }
}

/// What the gate needs from a request head.
#[derive(Debug, PartialEq, Eq)]
struct RequestHead {
    /// The token presented (query parameter first, then a `token.` subprotocol entry).
    token: Option<String>,
}

/// Reads the request line and the `Sec-WebSocket-Protocol` headers.
fn parse_head(head: &str) -> Result<RequestHead, Refusal> {
    let mut lines = head.split("\r\n");
    let request_line = lines.next().unwrap_or_default();
    let mut parts = request_line.split(' ');
    let (Some(method), Some(target), Some(version)) = (parts.next(), parts.next(), parts.next())
    else {
        return Err(Refusal::BadRequest("no request line"));
    };
    if method != "GET" {
        return Err(Refusal::BadRequest("only GET upgrades to a websocket"));
    }
    if version != "HTTP/1.1" {
        return Err(Refusal::BadRequest("only HTTP/1.1 upgrades to a websocket"));
    }
    let query_token = target
        .split_once('?')
        .and_then(|(_, query)| query_parameter(query, "token"));
    let protocol_token = lines
        .filter_map(|line| line.split_once(':'))
        .filter(|(name, _)| name.trim().eq_ignore_ascii_case("sec-websocket-protocol"))
        .flat_map(|(_, value)| value.split(','))
        .find_map(|entry| entry.trim().strip_prefix("token.").map(str::to_string));
    Ok(RequestHead {
        token: query_token.or(protocol_token),
    })
}

/// The first value of `name` in a query string, percent-decoded (`+` is a space, as in forms).
fn query_parameter(query: &str, name: &str) -> Option<String> {
    query
        .split('&')
        .filter_map(|pair| pair.split_once('=').or(Some((pair, ""))))
        .find(|(key, _)| *key == name)
        .map(|(_, value)| percent_decode(value))
}

fn percent_decode(s: &str) -> String {
    let bytes = s.as_bytes();
    let mut out = Vec::with_capacity(bytes.len());
    let mut i = 0;
    while i < bytes.len() {
        match bytes[i] {
            b'+' => out.push(b' '),
            b'%' if i + 2 < bytes.len() => {
                let hex = std::str::from_utf8(&bytes[i + 1..i + 3]).ok();
                match hex.and_then(|h| u8::from_str_radix(h, 16).ok()) {
                    Some(b) => {
                        out.push(b);
                        i += 2;
                    }
                    None => out.push(b'%'),
                }
            }
            b => out.push(b),
        }
        i += 1;
    }
    String::from_utf8_lossy(&out).into_owned()
}

/// Compares without stopping at the first difference, so the time taken does not tell how much matched.
fn constant_time_eq(a: &[u8], b: &[u8]) -> bool {
    if a.len() != b.len() {
        return false;
    }
    a.iter().zip(b).fold(0u8, |acc, (x, y)| acc | (x ^ y)) == 0
}

#[cfg(test)]
mod tests {
    use super::*;

    fn policy(token: Option<&str>, watch_without_token: bool) -> WatchPolicy {
        WatchPolicy::new(&DashboardConfig {
            token: token.map(str::to_string),
            watch_without_token,
            ..DashboardConfig::default()
        })
    }

    fn head(target: &str, protocols: &str) -> String {
        let mut h =
            format!("GET {target} HTTP/1.1\r\nHost: 127.0.0.1:8765\r\nUpgrade: websocket\r\n");
        if !protocols.is_empty() {
            h.push_str(&format!("Sec-WebSocket-Protocol: {protocols}\r\n"));
        }
        h.push_str("\r\n");
        h
    }

    #[test]
    fn without_a_configured_token_everyone_may_watch() {
        let p = policy(None, false);
        assert!(!p.token_required() && !p.has_token());
        assert_eq!(p.admit(&head("/", "foxglove.sdk.v1")), Ok(()));
        assert_eq!(
            p.admit(&head("/?token=anything", "foxglove.sdk.v1")),
            Ok(())
        );
    }

    #[test]
    fn with_a_token_and_no_watching_without_it_only_the_token_gets_in() {
        let p = policy(Some("s3cret"), false);
        assert!(p.token_required());
        assert_eq!(
            p.admit(&head("/", "foxglove.sdk.v1")),
            Err(Refusal::TokenRequired)
        );
        assert_eq!(
            p.admit(&head("/?token=wrong", "")),
            Err(Refusal::WrongToken)
        );
        assert_eq!(
            p.admit(&head("/?token=s3cre", "")),
            Err(Refusal::WrongToken)
        );
        assert_eq!(p.admit(&head("/?a=1&token=s3cret", "")), Ok(()));
        assert_eq!(p.admit(&head("/", "foxglove.sdk.v1, token.s3cret")), Ok(()));
        assert_eq!(
            p.admit(&head("/", "foxglove.sdk.v1, token.nope")),
            Err(Refusal::WrongToken)
        );
        // The query parameter wins over the subprotocol.
        assert_eq!(
            p.admit(&head("/?token=nope", "token.s3cret")),
            Err(Refusal::WrongToken)
        );
    }

    #[test]
    fn with_watching_allowed_a_missing_token_watches_but_a_wrong_one_is_refused() {
        let p = policy(Some("s3cret"), true);
        assert!(!p.token_required() && p.has_token());
        assert_eq!(p.admit(&head("/", "foxglove.sdk.v1")), Ok(()));
        assert_eq!(p.admit(&head("/?token=x", "")), Err(Refusal::WrongToken));
    }

    #[test]
    fn tokens_are_percent_decoded_and_an_empty_configured_token_is_none() {
        let p = policy(Some("a b/c%"), false);
        assert_eq!(p.admit(&head("/?token=a+b%2Fc%25", "")), Ok(()));
        assert_eq!(p.admit(&head("/?token=a%20b%2fc%", "")), Ok(()));
        assert!(!policy(Some(""), false).has_token());
    }

    #[test]
    fn what_is_not_a_websocket_request_is_a_bad_request() {
        let p = policy(None, true);
        assert!(matches!(
            p.admit("POST / HTTP/1.1\r\n\r\n"),
            Err(Refusal::BadRequest(_))
        ));
        assert!(matches!(
            p.admit("GET / HTTP/1.0\r\n\r\n"),
            Err(Refusal::BadRequest(_))
        ));
        assert!(matches!(p.admit("garbage"), Err(Refusal::BadRequest(_))));
        assert_eq!(Refusal::TokenRequired.status().0, 401);
        assert_eq!(Refusal::BadRequest("x").status().0, 400);
    }
}

//! Who may open a Foxglove connection, decided from the HTTP request head before the websocket upgrade.
//!
//! Foxglove clients only ever read: the endpoint advertises no capability that lets a client publish,
//! set parameters or call services, so the token cannot unlock commands. It decides who may *watch*, with
//! the dashboard's own rule and secret (`[dashboard] token`, `--token`; `watch_without_token`):
//! - no token configured (only possible on loopback): every client may watch;
//! - a token configured: a client presents it as the `token` query parameter (`ws://HOST:8765/?token=T`,
//!   which is what the Foxglove app can send: it connects to the URL it is given) or as a websocket
//!   subprotocol entry `token.<T>` (next to `foxglove.websocket.v1` or `foxglove.sdk.v1`, for clients that
//!   can set one). A wrong token is refused (401); no token is refused (401) unless `watch_without_token`
//!   is set.
//!
//! The subprotocol: the published protocol (foxglove/ws-protocol, its docs/spec.md) names
//! [`SPEC_SUBPROTOCOL`] (`foxglove.websocket.v1`); Foxglove's SDK negotiates only its own names
//! (`foxglove.sdk.v1`, `foxglove.sdk.v1.1`). The messages of `foxglove.sdk.v1` are the spec's (inline
//! schemas), so a client that offers only the spec's name is handed to the SDK as offering
//! `foxglove.sdk.v1` ([`for_sdk`]), and the SDK's answer is translated back to the name the client offered
//! ([`for_client`]). A client that offers one of the SDK's names is passed as it is. `token.<T>` entries are
//! taken out of what the SDK sees (the gate has checked them; the SDK never needs the secret).
//!
//! The head is parsed here, purely, so the rules are tested without sockets ([`super::gate`] does the I/O).

use pavlov::config::DashboardConfig;

use crate::dashboard::auth::constant_time_eq;

/// The subprotocol the published protocol names (foxglove/ws-protocol, its docs/spec.md).
pub(crate) const SPEC_SUBPROTOCOL: &str = "foxglove.websocket.v1";
/// The SDK's name for the same messages (inline schemas).
pub(crate) const SDK_SUBPROTOCOL: &str = "foxglove.sdk.v1";
/// The SDK's names start with this (`foxglove.sdk.v1`, `foxglove.sdk.v1.1`).
const SDK_PREFIX: &str = "foxglove.sdk.";

/// The request head as the SDK gets it.
#[derive(Debug, PartialEq, Eq)]
pub(crate) struct ForSdk {
    /// The head to forward (ending with the blank line).
    pub(crate) head: String,
    /// Whether the client offered only [`SPEC_SUBPROTOCOL`], so the SDK's answer must be translated back.
    pub(crate) translated: bool,
}

/// Rewrites the `Sec-WebSocket-Protocol` offers of an admitted head for the SDK: `token.` entries are
/// dropped, and when the client offered none of the SDK's names but [`SPEC_SUBPROTOCOL`], that entry
/// becomes [`SDK_SUBPROTOCOL`]. A head that offers no subprotocol the endpoint speaks is refused (400,
/// naming the one to offer) rather than left to the SDK's less helpful answer.
pub(crate) fn for_sdk(head: &str) -> Result<ForSdk, Refusal> {
    let offered: Vec<&str> = protocol_entries(head).collect();
    let sdk_named = offered.iter().any(|e| e.starts_with(SDK_PREFIX));
    let translated = !sdk_named && offered.contains(&SPEC_SUBPROTOCOL);
    if !sdk_named && !translated {
        return Err(Refusal::BadRequest(
            "no supported websocket subprotocol offered: offer foxglove.websocket.v1 (or foxglove.sdk.v1)",
        ));
    }
    let lines: Vec<String> = head
        .split("\r\n")
        .filter_map(|line| {
            let Some((name, value)) = line.split_once(':') else {
                return Some(line.to_string());
            };
            if !is_protocol_header(name) {
                return Some(line.to_string());
            }
            let kept: Vec<&str> = value
                .split(',')
                .map(str::trim)
                .filter(|e| !e.is_empty() && !e.starts_with("token."))
                .map(|e| {
                    if translated && e == SPEC_SUBPROTOCOL {
                        SDK_SUBPROTOCOL
                    } else {
                        e
                    }
                })
                .collect();
            (!kept.is_empty()).then(|| format!("{}: {}", name.trim(), kept.join(", ")))
        })
        .collect();
    Ok(ForSdk {
        head: lines.join("\r\n"),
        translated,
    })
}

/// Translates the SDK's response head for a client that offered only [`SPEC_SUBPROTOCOL`]: the chosen
/// subprotocol [`SDK_SUBPROTOCOL`] is named as the client offered it. Anything else is left as it is.
pub(crate) fn for_client(response_head: &str) -> String {
    response_head
        .split("\r\n")
        .map(|line| match line.split_once(':') {
            Some((name, value)) if is_protocol_header(name) && value.trim() == SDK_SUBPROTOCOL => {
                format!("{}: {SPEC_SUBPROTOCOL}", name.trim())
            }
            _ => line.to_string(),
        })
        .collect::<Vec<_>>()
        .join("\r\n")
}

fn is_protocol_header(name: &str) -> bool {
    name.trim().eq_ignore_ascii_case("sec-websocket-protocol")
}

/// Every entry of every `Sec-WebSocket-Protocol` header of a request head, trimmed.
fn protocol_entries(head: &str) -> impl Iterator<Item = &str> {
    head.split("\r\n")
        .skip(1)
        .filter_map(|line| line.split_once(':'))
        .filter(|(name, _)| is_protocol_header(name))
        .flat_map(|(_, value)| value.split(','))
        .map(str::trim)
        .filter(|e| !e.is_empty())
}

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
    let request_line = head.split("\r\n").next().unwrap_or_default();
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
    let protocol_token =
        protocol_entries(head).find_map(|entry| entry.strip_prefix("token.").map(str::to_string));
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

    #[test]
    fn the_specs_subprotocol_is_offered_to_the_sdk_under_its_name_and_answered_back() {
        let h = head("/?token=t", "foxglove.websocket.v1, token.s3cret");
        let fwd = for_sdk(&h).unwrap();
        assert!(fwd.translated);
        assert_eq!(fwd.head, head("/?token=t", "foxglove.sdk.v1"));
        assert!(!fwd.head.contains("s3cret"));
        // Only the subprotocol header changes; the head still ends with its blank line.
        assert!(fwd.head.ends_with("\r\n\r\n"));
        assert!(fwd.head.contains("Upgrade: websocket\r\n"));

        let answer = "HTTP/1.1 101 Switching Protocols\r\nconnection: Upgrade\r\n\
                      sec-websocket-protocol: foxglove.sdk.v1\r\nsec-websocket-accept: x=\r\n\r\n";
        assert_eq!(
            for_client(answer),
            answer.replace("foxglove.sdk.v1", "foxglove.websocket.v1")
        );
        // Two headers, mixed case, extra entries: each offer translated, the unknown kept.
        let h = "GET / HTTP/1.1\r\nsec-websocket-protocol: token.a\r\n\
                 SEC-WEBSOCKET-PROTOCOL:foxglove.websocket.v1 , other\r\n\r\n";
        let fwd = for_sdk(h).unwrap();
        assert_eq!(
            fwd.head,
            "GET / HTTP/1.1\r\nSEC-WEBSOCKET-PROTOCOL: foxglove.sdk.v1, other\r\n\r\n"
        );
    }

    #[test]
    fn an_sdk_offer_is_passed_as_it_is_and_no_known_offer_is_a_bad_request() {
        for offer in [
            "foxglove.sdk.v1",
            "foxglove.sdk.v1.1, foxglove.websocket.v1",
        ] {
            let fwd = for_sdk(&head("/", offer)).unwrap();
            assert!(!fwd.translated, "{offer}");
            assert_eq!(fwd.head, head("/", offer));
        }
        let fwd = for_sdk(&head("/", "token.x, foxglove.sdk.v1")).unwrap();
        assert_eq!(fwd.head, head("/", "foxglove.sdk.v1"));
        // The SDK's answer to its own name is not translated for such a client.
        assert!(!for_sdk(&head("/", "foxglove.sdk.v1")).unwrap().translated);
        for offer in [
            "",
            "token.s3cret",
            "foxglove.websocket.v2",
            "foxglove.websocket.v1.x",
        ] {
            assert!(
                matches!(for_sdk(&head("/", offer)), Err(Refusal::BadRequest(m)) if m.contains("foxglove.websocket.v1")),
                "{offer:?}"
            );
        }
        // A response naming another protocol (or none) is left alone.
        let other =
            "HTTP/1.1 101 Switching Protocols\r\nsec-websocket-protocol: foxglove.sdk.v1.1\r\n\r\n";
        assert_eq!(for_client(other), other);
    }
}

//! The dashboard endpoint: the websocket protocol, the browser page, abuse, and `/metrics`.

mod abuse;
mod abusers;
mod browser;
mod learning_bounds;
mod metrics;
mod protocol;

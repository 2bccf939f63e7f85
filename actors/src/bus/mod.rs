//! The buses: how the actors hand things on without waiting for one another. The event log
//! ([`events`]), the tick feed (`feed`) and the recorder's queue ([`recorder_queue`]) are used by the
//! pipeline, the command router, the link, storage and the dashboard alike, so they live on their own floor
//! beneath all of them and import none of them (only the core, `tokio` and each other). The
//! `counter_set!` macro (`counter_set.rs`) is here too: the event log counts storage failures with it, and
//! telemetry declares its sets with it.

pub(crate) mod counter_set;
pub mod events;
pub(crate) mod feed;
pub mod recorder_queue;
pub(crate) mod storage_failures;

pub use events::EventLog;
pub use feed::TickFeed;
pub use recorder_queue::{RecorderInput, StartState};

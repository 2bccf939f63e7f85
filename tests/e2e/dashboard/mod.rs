//! The dashboard endpoint: the websocket protocol, the browser page, abuse, who gets in when it is abused
//! (`operator`), what it refuses to guess and keeps to itself (`strictness`), `/metrics`, the recording's
//! download (`download`), a refused message's close frame delivered while its rest still arrives
//! (`lingering_close`), a full disk as the page shows it (`browser_storage`), the page without traps
//! (`browser_traps`: one time axis, marker labels, a watcher's buttons), and the page of a copied binary
//! run from an empty folder (`installed`).

mod abuse;
mod abusers;
mod analysis;
pub(crate) mod browser;
mod browser_analysis;
mod browser_learning;
mod browser_storage;
mod browser_traps;
mod buffers;
mod download;
mod installed;
mod learning_bounds;
mod learning_view;
mod lingering_close;
mod metrics;
mod operator;
mod operator_first;
mod protocol;
mod rig;
mod strictness;

//! What the server keeps on disk: recordings (round trip, replay, a rule table's rules, a kill mid-write, names a client may
//! give, conversion between MCAP and JSON Lines, an independent MCAP reader, `replay`'s exit statuses, a stochastic gate's run replayed bit for bit),
//! checkpoints (periodic, per run, resumed with fallback) and saves; no artifact carrying the token.

mod checkpoint;
mod checkpoint_runs;
mod crafted_files;
pub(crate) mod disk_full;
pub(crate) mod fixtures;
mod no_secrets;
mod recording_convert;
mod recording_crash;
mod recording_names;
mod recording_python;
mod recording_roundtrip;
mod recording_rules;
mod replay_cases;
mod replay_exit;
mod replay_stochastic;
mod saves;

//! What the server keeps on disk: recordings (round trip, replay, a kill mid-write) and checkpoints.

mod checkpoint;
mod recording_crash;
mod recording_roundtrip;

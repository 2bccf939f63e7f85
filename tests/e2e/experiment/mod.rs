//! The paper's two experiments through the real runtime under virtual time.

mod interaction;
mod shards;
mod stall;

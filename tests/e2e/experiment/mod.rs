//! The paper's two experiments through the real runtime under virtual time.

mod figures;
mod interaction;
mod merge_bounds;
mod results_folders;
mod shards;
mod stall;
mod variations;

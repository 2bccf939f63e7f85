//! What a run means: the numbers computed from its tick records, shared by the dashboard, the experiments
//! and the tests.
//!
//! - [`run_counters`]: the stall experiment's counters over a run (over-current observations, stall events,
//!   time stalled, distance, energy, efficiency).
//! - [`interaction`]: response timing against a human's commands, live and after the run.
//! - [`stats`]: descriptive statistics, Welch's t-test and the small numerical helpers they need.
//! - [`bootstrap`]: a difference of two means with a percentile-bootstrap confidence interval.
//! - [`realised_return`]: a prediction's values against the returns they predicted, its running error and
//!   TD error (the dashboard's learning view).

pub mod bootstrap;
pub mod interaction;
pub mod realised_return;
pub mod run_counters;
pub mod stats;

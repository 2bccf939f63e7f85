//! The per-tick stages of the control loop as plain, synchronous state machines.
//!
//! The runtime's learning and gating actors are thin async shells around these, and replay and the
//! experiments call the very same code, so a recording can be checked bit for bit.
//!
//! - [`learning`]: observation → stimulus, features, predictions (act first), then the TD(λ) update.
//! - [`gating`]: prediction + stimulus + mode → the action, with manual teleop and the e-stop.
//! - [`safety`]: the one predicate for safety stops and for observations fresh enough to learn from.
//! - [`stochastic_gate`]: the stochastic mixing function's seeded draws and the behaviour probability.
//! - [`tick_record`]: assembling a tick's record after actuation.
//! - [`readings`]: the raw readings a tick record carries.

pub mod gating;
pub mod learning;
pub mod readings;
pub mod safety;
pub mod stochastic_gate;
pub mod tick_record;

pub use gating::{GateOutput, GatingStage};
pub use learning::{LearnInput, LearnOutput, LearningStage, StageSnapshot};
pub use stochastic_gate::StochasticGate;

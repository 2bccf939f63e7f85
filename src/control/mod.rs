//! Control: stimulus detectors, the mixing function and gate, default policies π and fixed responses ϱ.
//!
//! - [`action`]: [`Action`], a pair of wheel velocities for Drive Direct.
//! - [`stall`]: [`StallDetector`], the leaky integrator of over-current flags that defines a stall E.
//! - [`mod@gate`]: [`Mode`], [`fn@gate`] (reactive `I{E}` or Pavlovian `I{E ∨ v > θ}`) and [`mix`].
//! - [`policy`]: [`Policy`], the configurable default policies and fixed responses, and
//!   [`StallDefaultPolicy`], the stall experiment's 20 s driving cycle.
//! - [`rules`]: the rule table, several responses each driven by its own prediction, and [`select`].

pub mod action;
pub mod gate;
pub mod policy;
pub mod rules;
pub mod stall;

pub use action::{Action, MAX_WHEEL_MM_S};
pub use gate::{GateKind, Mode, gate, mix};
pub use policy::{ControlError, Policy, StallDefaultPolicy};
pub use rules::{Fired, GateInput, Rule, STIMULUS_RULE, select};
pub use stall::{StallDetector, wheel_overcurrent};

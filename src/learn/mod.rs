//! Learning: tile coding and TD(λ) predictions, after Modayil & Sutton, "Prediction Driven Behavior".
//!
//! - [`tiles`]: [`TileCoder`], continuous inputs in `[0, 1]` to sparse binary features.
//! - [`bounds`]: [`ParamBounds`], every parameter's and size's bound (α·‖x‖² ≤ 1, tiles, features), one
//!   check for the configuration, `set_params` and checkpoints.
//! - [`sigma`]: [`Sigma`], the output nonlinearity (identity or logistic) and its derivative.
//! - [`td`]: [`TdLambda`], the paper's TD(λ) update over active-index feature lists, dense: the reference.
//! - [`horde`]: [`Horde`], thousands of general predictions (GVFs) in families, grouped by shared trace.
//! - [`gtd`]: [`Gtd`], off-policy GTD(λ) (Maei 2011) with importance sampling ratios, for predictions about
//!   a target policy other than the behaviour run (`learner = "gtd"`).
//! - [`named`]: the learners beyond the paper's, chosen per prediction with `learner = "…"`: `xent` (the
//!   cross-entropy gradient), `linear`, `true_online` (dutch traces), `autostep` (step sizes per weight).
//! - [`group`]: [`TraceGroup`], the same update for predictions sharing a trace, deferred so that a tick
//!   costs the active features only: what the Horde runs.
//! - [`dense`]: [`DenseTd`], one prediction's update in one vectorized pass over its few hundred
//!   weights: what each on-policy prediction of a [`PredictionSet`] runs.
//! - [`spec`]: [`PredictionSpec`], one prediction as configuration (TOML).
//! - [`inputs`]: [`SignalNames`] and [`FeatureInputs`], the named signals predictions read.
//! - [`set`]: [`PredictionSet`], many predictions learned side by side, act first then learn.
//! - [`snapshot`]: [`SetSnapshot`], checkpoints of weights, traces and the previous step.
//!
//! Facts: the paper's update equations (TD(λ) with an output nonlinearity σ), tile coding as in \[SB\] and
//! \[tiles3\] (`docs/SOURCES.md`).

pub mod bounds;
pub mod dense;
pub mod error;
pub mod group;
pub mod gtd;
pub mod horde;
pub mod inputs;
pub mod named;
pub mod set;
pub mod sigma;
pub mod snapshot;
pub mod spec;
pub mod td;
#[cfg(test)]
pub(crate) mod test_stream;
pub mod tiles;
pub mod transitions;

pub use bounds::ParamBounds;
pub use dense::DenseTd;
pub use error::LearnError;
pub use group::{Column, GroupState, TraceGroup};
pub use gtd::{Gtd, GtdParams};
pub use horde::{FamilySpec, Horde, HordeSnapshot, HordeState, TickSignals};
pub use inputs::{FeatureInputs, SignalNames};
pub use named::{Named, NamedChain};
pub use set::{Predicted, PredictionOut, PredictionSet};
pub use sigma::Sigma;
pub use snapshot::{PredictionSnapshot, PreviousStep, SetSnapshot};
pub use spec::{Cumulant, FeatureSpec, LearnerKind, PairSpec, PredictionSpec, Threshold};
pub use td::{TdLambda, TdParams, UpdateRefused};
pub use tiles::{TileCoder, TileSpec};

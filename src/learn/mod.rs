//! Learning: tile coding and TD(λ) predictions, after Modayil & Sutton, "Prediction Driven Behavior".
//!
//! - [`tiles`]: [`TileCoder`], continuous inputs in `[0, 1]` to sparse binary features.
//! - [`sigma`]: [`Sigma`], the output nonlinearity (identity or logistic) and its derivative.
//! - [`td`]: [`TdLambda`], the paper's TD(λ) update over active-index feature lists.
//! - [`spec`]: [`PredictionSpec`], one prediction as configuration (TOML).
//! - [`inputs`]: [`SignalNames`] and [`FeatureInputs`], the named signals predictions read.
//! - [`set`]: [`PredictionSet`], many predictions learned side by side, act first then learn.
//! - [`snapshot`]: [`SetSnapshot`], checkpoints of weights, traces and the previous step.
//!
//! Facts: the paper's update equations (TD(λ) with an output nonlinearity σ), tile coding as in [SB] and
//! [tiles3] (`docs/SOURCES.md`).

pub mod checkpoint;
pub mod error;
pub mod inputs;
pub mod set;
pub mod sigma;
pub mod snapshot;
pub mod spec;
pub mod td;
pub mod tiles;

pub use error::LearnError;
pub use inputs::{FeatureInputs, SignalNames};
pub use set::{PredictionOut, PredictionSet};
pub use sigma::Sigma;
pub use snapshot::{PredictionSnapshot, PreviousStep, SetSnapshot};
pub use spec::{Cumulant, FeatureSpec, PairSpec, PredictionSpec, Threshold};
pub use td::{TdLambda, TdParams};
pub use tiles::{TileCoder, TileSpec};

//! [`LearnError`]: every way a prediction configuration or a learning call can be wrong, with the
//! prediction and the offending value named.

use thiserror::Error;

/// An invalid prediction configuration, or a learning call that does not fit the configuration.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum LearnError {
    /// A prediction without a name.
    #[error("a prediction has an empty name")]
    EmptyName,
    /// A name longer than the bound.
    #[error("the name `{start}…` has {chars} characters; at most {max}")]
    NameTooLong {
        /// Its first characters.
        start: String,
        /// Its length.
        chars: usize,
        /// The bound.
        max: usize,
    },
    /// A Horde family lists the same cumulant twice (after `obs/*` and the like are expanded).
    #[error("family `{family}` lists cumulant `{cumulant}` twice")]
    DuplicateCumulant {
        /// The family.
        family: String,
        /// The cumulant, as expanded.
        cumulant: String,
    },
    /// Two predictions with the same name.
    #[error("prediction `{0}` is defined twice")]
    DuplicatePrediction(String),
    /// Two input signals or two stimuli with the same name.
    #[error("signal `{0}` is named twice")]
    DuplicateSignal(String),
    /// A parameter or size outside its bound (`super::bounds`): `field` names the configuration key
    /// within the prediction (`alpha`, `lambda`, `tau`, `initial_weight`, `threshold`, `features.tiles`,
    /// `features`), `bound` says what the value breaks.
    #[error("prediction `{name}`: {field} = {value} {bound}")]
    OutOfBounds {
        name: String,
        field: String,
        value: String,
        bound: String,
    },
    /// More predictions than `super::bounds::MAX_PREDICTIONS`.
    #[error("{count} predictions are more than the {max} allowed")]
    TooManyPredictions { count: usize, max: usize },
    /// More features in all predictions together than `super::bounds::MAX_FEATURES`.
    #[error(
        "the predictions have {total} features together, more than {max} (the weights and traces are \
         dense f64 vectors, walked on every tick)"
    )]
    TooManyFeaturesInAll { total: usize, max: usize },
    /// A tile coder with no tiles per dimension.
    #[error("tile coder: tiles per dimension must be >= 1, got {0}")]
    NoTiles(usize),
    /// A tile coder with no tilings (no inputs or no pairs).
    #[error("tile coder: it must have at least one tiling (one input or one pair)")]
    NoTilings,
    /// A pair tiling offset outside `[0, 1)` of a tile width.
    #[error("tile coder: pair offset must be a fraction of a tile in [0, 1), got {0}")]
    InvalidOffset(f64),
    /// A pair tiling that names an input position beyond the coder's inputs.
    #[error("tile coder: pair ({0}, {1}) refers to an input position >= {2}")]
    PairOutOfRange(usize, usize, usize),
    /// A feature count that does not fit in memory.
    #[error("tile coder: {0} tilings of {1} tiles each is too many features")]
    TooManyFeatures(usize, usize),
    /// A prediction reads an input signal nobody provides.
    #[error("prediction `{prediction}`: unknown input `{input}` (known: {known})")]
    UnknownInput {
        prediction: String,
        input: String,
        known: String,
    },
    /// A prediction's cumulant names a stimulus nobody provides.
    #[error("prediction `{prediction}`: unknown stimulus `{stimulus}` (known: {known})")]
    UnknownStimulus {
        prediction: String,
        stimulus: String,
        known: String,
    },
    /// A weight or trace vector of the wrong length.
    #[error("prediction `{name}`: features sized wrong: expected {expected} weights, got {got}")]
    FeatureCountMismatch {
        name: String,
        expected: usize,
        got: usize,
    },
    /// A snapshot value that is not finite.
    #[error("prediction `{0}`: snapshot holds a non-finite weight or trace")]
    NonFiniteSnapshot(String),
    /// A snapshot whose chain state names a feature index out of range.
    #[error("prediction `{name}`: snapshot feature index {index} >= {features}")]
    SnapshotIndexOutOfRange {
        name: String,
        index: usize,
        features: usize,
    },
    /// A runtime change or snapshot for a prediction that does not exist.
    #[error("no prediction named `{0}`")]
    UnknownPrediction(String),
    /// A snapshot whose set of predictions differs from the running set.
    #[error("snapshot has {got} predictions, the running set has {expected}")]
    SnapshotCountMismatch { expected: usize, got: usize },
    /// `learn` was called without a `predict` for this tick (nothing to learn from).
    #[error("learn called without a predict for this tick")]
    LearnWithoutPredict,
    /// A cumulant selector that names no signal.
    #[error("family `{family}`: cumulant `{selector}` names no signal (known: {known})")]
    UnknownSignal {
        family: String,
        selector: String,
        known: String,
    },
    /// A family without a usable name (empty, or holding `/` or `@`, which its predictions' names use).
    #[error("family name `{0}` must be non-empty and without `/` or `@`")]
    BadFamilyName(String),
    /// A family without cumulants or without timescales.
    #[error("family `{0}` needs at least one cumulant and one timescale")]
    EmptyFamily(String),
    /// A group with a logistic σ must have one prediction: its trace holds σ′(wᵀx), each prediction's own.
    #[error(
        "a trace group with a logistic σ has one prediction, not {0} (σ′ makes each trace its own)"
    )]
    SharedLogisticTrace(usize),
    /// A true-online group shares one dutch trace, which holds α: a combination that cannot share it.
    #[error("a true online group shares one dutch trace, but {0}")]
    SharedDutchTrace(String),
    /// A Horde whose Autostep state (three values more per Autostep weight) is beyond its memory bound.
    #[error(
        "the Horde would hold {values} learned values (its weights, and for each learner = \"autostep\" \
         weight its step size, h and v), more than the {max} allowed"
    )]
    AutostepStateTooLarge { values: usize, max: usize },
    /// The cumulant or δ slice given to a group's `learn` has the wrong length.
    #[error("learn: expected {expected} cumulants, got {got}")]
    CumulantCountMismatch { expected: usize, got: usize },
    /// A group state that does not fit the group it is restored into.
    #[error("prediction `{name}`: the learner state {what}")]
    BadGroupState { name: String, what: String },
    /// The stimulus slice given to `learn` has the wrong length.
    #[error("learn: expected {expected} stimulus values, got {got}")]
    StimulusCountMismatch { expected: usize, got: usize },
}

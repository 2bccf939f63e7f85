//! What the studies' tables say about the simulator's and the learner's design choices and estimates: the
//! parts that are not the paper's, each with its effect where it has been measured. The effects are the
//! README's cumulative steps (the studies' defaults rerun after each change: stall 10 + 10 runs × 6 min,
//! interaction 3 pairs × 60 min); nothing here is measured again when a table is printed.

use pavlov::sim::variation::{CHARGE_RANGE, FRICTION_SCALE_RANGE};

/// The lab-variation ranges, as the footnotes state them.
fn variation() -> String {
    format!(
        "lab variation per run (estimates, no source: src/sim/variation.rs): start charge uniform in {:.0}–{:.0} % \
         of capacity, wheel friction × {:.1}–{:.1}",
        CHARGE_RANGE[0] * 100.0,
        CHARGE_RANGE[1] * 100.0,
        FRICTION_SCALE_RANGE[0],
        FRICTION_SCALE_RANGE[1]
    )
}

/// The stall study's footnote.
pub(crate) fn stall() -> String {
    format!(
        "design choices and estimates (not the paper's; measured effect on the default study, README):\n  \
         - event bits (over-current, bumps, cliffs) OR-ed over every frame since the last tick (design choice): \
         efficiency change +30.7 % → +40.6 %, over-current change −53.8 % → −53.7 %\n  \
         - a stalled wheel held at 1.0 A (a reading of one specification sentence on the low-side-driver page): \
         efficiency change +55.7 % without it → +30.7 % with it\n  \
         - {}: over-current change −53.7 % → −49.1 %, efficiency change +40.6 % → +33.0 %",
        variation()
    )
}

/// The interaction study's footnote.
pub(crate) fn interaction() -> String {
    format!(
        "design choices and estimates (not the paper's; measured effect on 3 pairs × 60 min, README; leads \
         positive = Pavlovian earlier):\n  \
         - a missing or stale elbow breaks the learning chain (design choice; the paper is silent on it): the \
         largest single gain, decision lead +12.6 → +20.8 ms, current lead +7.3 → +15.2 ms\n  \
         - {}: current lead +15.6 → +6.1 ms; the decision lead, which no robot touches, stays at +24.4 ms",
        variation()
    )
}

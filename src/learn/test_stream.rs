//! Test inputs shared by the learners' tests: a random stream whose dimensions hold their value for a
//! while (features persist over ticks, as a robot's do).

use crate::rng::Rng;

/// `ticks` inputs of `dims` dimensions, each redrawn with probability 0.1 a tick, and stimuli of
/// probability `p_stim`.
pub(crate) fn held_stream(
    ticks: usize,
    dims: usize,
    p_stim: f64,
    seed: u64,
) -> Vec<(Vec<f64>, bool)> {
    let mut rng = Rng::new(seed);
    let mut x: Vec<f64> = (0..dims).map(|_| rng.next_f64()).collect();
    (0..ticks)
        .map(|_| {
            for v in &mut x {
                if rng.chance(0.1) {
                    *v = rng.next_f64();
                }
            }
            (x.clone(), rng.chance(p_stim))
        })
        .collect()
}

//! The simulated world: a byte-exact simulated Create and a simulated human operator.

pub mod battery;
pub mod faults;
pub mod geometry;
pub mod human;
pub mod motor;
pub mod odometry;
pub mod params;
pub mod readings;
pub mod robot;
pub mod variation;
pub mod world;

/// The OI sensor period and the world's step, s [C1 p13; C2 p21].
pub const STEP_SECONDS: f64 = 0.015;

/// Test inputs shared by the simulator's bit-for-bit tests.
#[cfg(test)]
pub(crate) mod test_floats {
    /// `edge` and its four neighbours on each side (nine floats, ascending), for `edge` and `-edge`.
    pub(crate) fn around(edge: f64) -> Vec<f64> {
        let mut out = Vec::with_capacity(18);
        for sign in [1.0, -1.0] {
            let mut v: f64 = sign * edge;
            for _ in 0..4 {
                v = v.next_down();
            }
            for _ in 0..9 {
                out.push(v);
                v = v.next_up();
            }
        }
        out
    }
}

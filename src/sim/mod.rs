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

//! The simulated world: a byte-exact simulated Create and a simulated human operator.

pub mod human;
pub mod params;
pub mod robot;
pub mod world;

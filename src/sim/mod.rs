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
pub mod world;

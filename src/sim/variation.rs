//! Lab-like variation between runs (`[sim] lab_variation`): a real lab never replays a run exactly. Each run
//! draws, from its own seed, what a person setting up the next run would change without meaning to:
//!
//! - **Battery charge at the start**: uniform in [`CHARGE_RANGE`] of capacity (*estimate*: runs start from
//!   anywhere between a freshly charged pack and half charge, when a lab would recharge). During the run the
//!   pack drains with use as always (`sim::battery`: the charge integrates the current, the voltage follows
//!   the charge and sags under load).
//! - **Start pose**: a position uniform over the enclosure where the robot stands at least
//!   [`START_CLEARANCE_M`] clear of every wall, and a heading uniform over the full turn (the robot is put
//!   down by hand, anywhere, facing anywhere).
//! - **Floor friction**: the kinetic, breakaway and viscous friction of both wheels scaled by one factor
//!   uniform in [`FRICTION_SCALE_RANGE`] (*estimate*: floor finish, dust, tyre wear and where the 2 kg weight
//!   sits plausibly change the wheels' friction by a fifth either way; no source gives the spread).
//!
//! None of these ranges was chosen by looking at a result; `docs/src/results.md` reports what comes out with them.

use super::params::SimParams;
use crate::rng::Rng;

/// The start-of-run state of charge, as a fraction of capacity.
pub const CHARGE_RANGE: [f64; 2] = [0.5, 1.0];

/// The factor on the wheels' friction.
pub const FRICTION_SCALE_RANGE: [f64; 2] = [0.8, 1.2];

/// How far from every wall the robot's body starts, at least, m.
pub const START_CLEARANCE_M: f64 = 0.02;

/// `params` with one run's draws from `rng` applied.
pub fn draw(params: &SimParams, rng: &mut Rng) -> SimParams {
    let mut p = params.clone();
    p.initial_charge_fraction = rng.uniform(CHARGE_RANGE[0], CHARGE_RANGE[1]);
    let f = rng.uniform(FRICTION_SCALE_RANGE[0], FRICTION_SCALE_RANGE[1]);
    p.friction_current_a *= f;
    p.breakaway_current_a *= f;
    p.viscous_current_a_per_m_s *= f;
    let (x, y) = start_position(&p, rng);
    p.start_x_m = x;
    p.start_y_m = y;
    p.start_heading_rad = rng.uniform(-std::f64::consts::PI, std::f64::consts::PI);
    p
}

/// Whether the robot centred at `(x, y)` stands at least `margin` clear of the enclosure's three walls
/// (legs along the axes, hypotenuse from `(L, 0)` to `(0, L)`).
fn clear_of_walls(p: &SimParams, x: f64, y: f64, margin: f64) -> bool {
    let need = p.body_radius_m + margin;
    let to_hypotenuse = (p.enclosure_leg_m - x - y) / std::f64::consts::SQRT_2;
    x >= need && y >= need && to_hypotenuse >= need
}

/// A position uniform over the region clear of the walls (rejection sampling over the enclosure's square;
/// the centroid when the region is empty or nothing is found).
fn start_position(p: &SimParams, rng: &mut Rng) -> (f64, f64) {
    let l = p.enclosure_leg_m;
    for _ in 0..10_000 {
        let (x, y) = (rng.uniform(0.0, l), rng.uniform(0.0, l));
        if clear_of_walls(p, x, y, START_CLEARANCE_M) {
            return (x, y);
        }
    }
    (l / 3.0, l / 3.0)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn every_draw_is_in_its_range_and_runs_differ() {
        let base = SimParams::default();
        let mut rng = Rng::new(5);
        let draws: Vec<SimParams> = (0..200).map(|_| draw(&base, &mut rng)).collect();
        for p in &draws {
            assert!((0.5..=1.0).contains(&p.initial_charge_fraction));
            let f = p.friction_current_a / base.friction_current_a;
            assert!((0.8..=1.2).contains(&f), "{f}");
            assert!((p.breakaway_current_a / base.breakaway_current_a - f).abs() < 1e-12);
            assert!(clear_of_walls(
                p,
                p.start_x_m,
                p.start_y_m,
                START_CLEARANCE_M
            ));
            assert!(p.start_heading_rad.abs() <= std::f64::consts::PI);
            assert_eq!(p.payload_kg, base.payload_kg, "nothing else changes");
        }
        // The draws spread over their ranges (not one fixed run).
        let spread = |f: fn(&SimParams) -> f64| {
            let xs: Vec<f64> = draws.iter().map(f).collect();
            let lo = xs.iter().copied().fold(f64::INFINITY, f64::min);
            let hi = xs.iter().copied().fold(f64::NEG_INFINITY, f64::max);
            hi - lo
        };
        assert!(spread(|p| p.initial_charge_fraction) > 0.4);
        assert!(spread(|p| p.start_heading_rad) > 5.0);
        assert!(spread(|p| p.start_x_m) > 0.2);
        // Same seed, same draw.
        assert_eq!(draw(&base, &mut Rng::new(9)), draw(&base, &mut Rng::new(9)));
    }
}

//! One arm's elbow-angle trajectory over time: a slowly drifting resting angle, interrupted by gestures that bend
//! the elbow along a minimum-jerk profile, hold, and release. Also the exact times a gesture crosses 90°.

use crate::rng::Rng;

use super::params::HumanParams;

const THRESHOLD_DEG: f64 = 90.0;

/// Minimum-jerk position profile on `[0, 1]`: `10τ³ − 15τ⁴ + 6τ⁵` (smooth start and stop, bell-shaped speed).
pub(crate) fn min_jerk(tau: f64) -> f64 {
    let t = tau.clamp(0.0, 1.0);
    t * t * t * (10.0 + t * (-15.0 + 6.0 * t))
}

/// The `τ` in `[0, 1]` at which [`min_jerk`] reaches `s` (bisection; the profile is monotonic).
fn min_jerk_inverse(s: f64) -> f64 {
    let (mut lo, mut hi) = (0.0_f64, 1.0_f64);
    for _ in 0..60 {
        let mid = 0.5 * (lo + hi);
        if min_jerk(mid) < s {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    0.5 * (lo + hi)
}

/// Exponential deviate with the given mean (0 for a non-positive mean).
pub(crate) fn exponential(rng: &mut Rng, mean: f64) -> f64 {
    if mean > 0.0 {
        -mean * (1.0 - rng.next_f64()).ln()
    } else {
        0.0
    }
}

/// A uniform draw from a `[lo, hi]` parameter range.
pub(crate) fn draw(rng: &mut Rng, range: [f64; 2]) -> f64 {
    rng.uniform(range[0], range[1])
}

/// One planned gesture of one arm. Times are absolute simulation times in ms.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gesture {
    /// When the elbow starts to bend.
    pub start_ms: f64,
    /// Resting angle the gesture starts from and returns to, degrees.
    pub from_deg: f64,
    /// Smallest angle, reached at the end of the bend and held, degrees.
    pub min_deg: f64,
    /// Duration of the bend, ms.
    pub bend_ms: f64,
    /// Duration of the hold at `min_deg`, ms.
    pub hold_ms: f64,
    /// Duration of the release back to `from_deg`, ms.
    pub return_ms: f64,
    /// Forward flexion of the upper arm at full progress, degrees.
    pub shoulder_flex_deg: f64,
    /// Yaw of the forearm's swing plane at full progress, degrees.
    pub forearm_yaw_deg: f64,
}

impl Gesture {
    /// When the arm is back at rest.
    pub fn end_ms(&self) -> f64 {
        self.start_ms + self.bend_ms + self.hold_ms + self.return_ms
    }

    /// Progress in `[0, 1]` at `t_ms`: 0 at rest, 1 while bent.
    pub fn progress(&self, t_ms: f64) -> f64 {
        let t = t_ms - self.start_ms;
        if t <= 0.0 {
            0.0
        } else if t < self.bend_ms {
            min_jerk(t / self.bend_ms)
        } else if t < self.bend_ms + self.hold_ms {
            1.0
        } else {
            1.0 - min_jerk((t - self.bend_ms - self.hold_ms) / self.return_ms)
        }
    }

    /// The true interior elbow angle at `t_ms`, degrees.
    pub fn angle_deg(&self, t_ms: f64) -> f64 {
        self.from_deg + (self.min_deg - self.from_deg) * self.progress(t_ms)
    }

    /// Whether the angle goes below 90°.
    pub fn crosses_threshold(&self) -> bool {
        self.min_deg < THRESHOLD_DEG && self.from_deg > THRESHOLD_DEG
    }

    /// The exact times the angle goes below 90° and comes back to it, when it does.
    pub fn threshold_crossings(&self) -> Option<(f64, f64)> {
        if !self.crosses_threshold() {
            return None;
        }
        let s = (self.from_deg - THRESHOLD_DEG) / (self.from_deg - self.min_deg);
        let onset = self.start_ms + self.bend_ms * min_jerk_inverse(s);
        let back = self.start_ms
            + self.bend_ms
            + self.hold_ms
            + self.return_ms * min_jerk_inverse(1.0 - s);
        Some((onset, back))
    }
}

/// Which arm an [`ArmMotion`] drives: the left arm makes commands and partial bends, the right arm makes
/// unrelated movements.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum ArmRole {
    Commanding,
    Other,
}

/// One arm's motion state: resting with a drifting angle, or in a gesture.
#[derive(Debug, Clone)]
pub struct ArmMotion {
    role: ArmRole,
    rng: Rng,
    rest_deg: f64,
    next_start_ms: f64,
    current: Option<Gesture>,
}

impl ArmMotion {
    /// A resting arm whose first gesture starts after a random delay.
    pub fn new(role: ArmRole, mut rng: Rng, p: &HumanParams) -> Self {
        let first = match role {
            ArmRole::Commanding => draw(&mut rng, p.first_gesture_after_s),
            ArmRole::Other => p.right_gap_min_s + exponential(&mut rng, p.right_gap_extra_mean_s),
        };
        let rest_deg = p
            .rest_elbow_deg
            .clamp(p.rest_elbow_limits_deg[0], p.rest_elbow_limits_deg[1]);
        ArmMotion {
            role,
            rng,
            rest_deg,
            next_start_ms: first * 1000.0,
            current: None,
        }
    }

    /// Advance to `t_ms` (by `dt_ms` since the last call). Returns a gesture when one starts at this step.
    pub fn advance(&mut self, t_ms: f64, dt_ms: f64, p: &HumanParams) -> Option<Gesture> {
        if let Some(g) = self.current
            && t_ms >= g.end_ms()
        {
            self.current = None;
            self.next_start_ms = g.end_ms() + 1000.0 * self.draw_gap(p);
        }
        if self.current.is_some() {
            return None;
        }
        if t_ms >= self.next_start_ms {
            let g = self.plan(self.next_start_ms, p);
            self.current = Some(g);
            return Some(g);
        }
        self.drift_rest(dt_ms, p);
        None
    }

    /// The true elbow angle at `t_ms` (call after [`ArmMotion::advance`] for the same time).
    pub fn angle_deg(&self, t_ms: f64) -> f64 {
        self.current.map_or(self.rest_deg, |g| g.angle_deg(t_ms))
    }

    /// (upper-arm forward flexion°, forearm-plane yaw°) at `t_ms`, for the body kinematics.
    pub fn pose_extras(&self, t_ms: f64) -> (f64, f64) {
        self.current.map_or((0.0, 0.0), |g| {
            let k = g.progress(t_ms);
            (k * g.shoulder_flex_deg, k * g.forearm_yaw_deg)
        })
    }

    fn draw_gap(&mut self, p: &HumanParams) -> f64 {
        match self.role {
            ArmRole::Commanding => {
                (p.gap_min_s + exponential(&mut self.rng, p.gap_extra_mean_s)).min(p.gap_max_s)
            }
            ArmRole::Other => (p.right_gap_min_s
                + exponential(&mut self.rng, p.right_gap_extra_mean_s))
            .min(p.gap_max_s.max(p.right_gap_min_s)),
        }
    }

    fn plan(&mut self, start_ms: f64, p: &HumanParams) -> Gesture {
        let rng = &mut self.rng;
        let min_deg = match self.role {
            ArmRole::Commanding if rng.chance(p.partial_fraction) => draw(rng, p.partial_min_deg),
            ArmRole::Commanding => draw(rng, p.command_min_deg),
            ArmRole::Other => draw(rng, p.right_min_deg),
        };
        Gesture {
            start_ms,
            from_deg: self.rest_deg,
            min_deg,
            bend_ms: 1000.0 * draw(rng, p.bend_s),
            hold_ms: 1000.0 * draw(rng, p.hold_s),
            return_ms: 1000.0 * draw(rng, p.return_s),
            shoulder_flex_deg: draw(rng, p.shoulder_flex_deg),
            forearm_yaw_deg: draw(rng, p.forearm_yaw_deg),
        }
    }

    /// Ornstein–Uhlenbeck drift of the resting angle around its mean, kept within the configured band.
    fn drift_rest(&mut self, dt_ms: f64, p: &HumanParams) {
        let tau_ms = 1000.0 * p.rest_drift_tau_s;
        if tau_ms <= 0.0 || dt_ms <= 0.0 {
            return;
        }
        let a = (-dt_ms / tau_ms).exp();
        let sd = p.rest_elbow_sd_deg * (1.0 - a * a).sqrt();
        let next =
            p.rest_elbow_deg + a * (self.rest_deg - p.rest_elbow_deg) + self.rng.normal(0.0, sd);
        self.rest_deg = next.clamp(p.rest_elbow_limits_deg[0], p.rest_elbow_limits_deg[1]);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn min_jerk_is_smooth_monotonic_and_invertible() {
        assert_eq!(min_jerk(0.0), 0.0);
        assert!((min_jerk(1.0) - 1.0).abs() < 1e-12);
        assert!((min_jerk(0.5) - 0.5).abs() < 1e-12);
        let mut prev = 0.0;
        for i in 1..=100 {
            let s = min_jerk(i as f64 / 100.0);
            assert!(s > prev);
            prev = s;
        }
        for s in [0.1, 0.3, 0.636, 0.78, 0.99] {
            assert!((min_jerk(min_jerk_inverse(s)) - s).abs() < 1e-9);
        }
    }

    fn gesture(min_deg: f64) -> Gesture {
        Gesture {
            start_ms: 1000.0,
            from_deg: 160.0,
            min_deg,
            bend_ms: 900.0,
            hold_ms: 500.0,
            return_ms: 700.0,
            shoulder_flex_deg: 10.0,
            forearm_yaw_deg: 0.0,
        }
    }

    #[test]
    fn crossing_times_are_where_the_angle_is_ninety() {
        let g = gesture(60.0);
        let (on, off) = g.threshold_crossings().unwrap();
        assert!((g.angle_deg(on) - 90.0).abs() < 1e-6);
        assert!((g.angle_deg(off) - 90.0).abs() < 1e-6);
        assert!(g.angle_deg(on - 1.0) > 90.0 && g.angle_deg(on + 1.0) < 90.0);
        assert!(
            on > g.start_ms + 300.0,
            "bending starts well before the command registers"
        );
        assert!(off > on && off < g.end_ms());
        assert!(gesture(110.0).threshold_crossings().is_none());
        assert!((gesture(110.0).angle_deg(g.start_ms + 1000.0) - 110.0).abs() < 1e-9);
        assert_eq!(g.angle_deg(0.0), 160.0);
        assert_eq!(g.angle_deg(g.end_ms() + 1.0), 160.0);
    }

    #[test]
    fn resting_arm_drifts_within_limits() {
        let p = HumanParams::default();
        let mut arm = ArmMotion::new(ArmRole::Commanding, Rng::new(3), &p);
        arm.next_start_ms = f64::INFINITY;
        let (mut lo, mut hi) = (f64::INFINITY, f64::NEG_INFINITY);
        for k in 0..9000 {
            let t = k as f64 * 1000.0 / 30.0;
            assert!(arm.advance(t, 1000.0 / 30.0, &p).is_none());
            let a = arm.angle_deg(t);
            lo = lo.min(a);
            hi = hi.max(a);
        }
        assert!(lo >= p.rest_elbow_limits_deg[0] && hi <= p.rest_elbow_limits_deg[1]);
        assert!(
            hi - lo > 5.0,
            "the resting angle should drift, range {lo}..{hi}"
        );
    }
}

//! The depth tracker's artefacts on top of the true pose: Gaussian jitter on every joint, and joints left out of
//! a frame (OSCeleton omits joints whose confidence is below 0.5) in bursts of a few frames.
//!
//! Each joint has its own two-state (Gilbert–Elliott) dropout chain: from "tracked" it enters "dropped" with
//! probability `q_in` per frame, and leaves with `q_out = 1 / burst`. Its long-run dropped fraction is
//! `q_in / (q_in + q_out)`, which is set to the configured rate, and a dropout lasts `burst` frames on average.

use crate::rng::Rng;
use crate::skeleton::Joint;

use super::params::HumanParams;

/// One joint's dropout chain.
#[derive(Debug, Clone, Copy, PartialEq)]
struct Dropout {
    dropped: bool,
    q_in: f64,
    q_out: f64,
}

impl Dropout {
    fn new(rate: f64, burst_frames: f64, rng: &mut Rng) -> Self {
        let rate = if rate.is_finite() {
            rate.clamp(0.0, 0.999)
        } else {
            0.0
        };
        let q_out = 1.0 / burst_frames.max(1.0);
        let q_in = (rate * q_out / (1.0 - rate)).min(1.0);
        Dropout {
            dropped: rng.chance(rate),
            q_in,
            q_out,
        }
    }

    fn step(&mut self, rng: &mut Rng) -> bool {
        let flip = if self.dropped { self.q_out } else { self.q_in };
        if rng.chance(flip) {
            self.dropped = !self.dropped;
        }
        self.dropped
    }
}

fn is_arm_joint(j: Joint) -> bool {
    matches!(
        j,
        Joint::LeftElbow
            | Joint::LeftWrist
            | Joint::LeftHand
            | Joint::RightElbow
            | Joint::RightWrist
            | Joint::RightHand
    )
}

/// Jitter and dropouts for every joint.
#[derive(Debug, Clone)]
pub struct SensorModel {
    noise_rng: Rng,
    drop_rng: Rng,
    chains: [Dropout; Joint::COUNT],
}

impl SensorModel {
    pub fn new(noise_rng: Rng, mut drop_rng: Rng, p: &HumanParams) -> Self {
        let chains = Joint::ALL.map(|j| {
            let rate = if is_arm_joint(j) {
                p.arm_drop_rate
            } else {
                p.body_drop_rate
            };
            Dropout::new(rate, p.drop_burst_frames, &mut drop_rng)
        });
        SensorModel {
            noise_rng,
            drop_rng,
            chains,
        }
    }

    /// What the tracker reports for one frame of true positions: dropped joints removed, the rest jittered.
    /// Every chain advances every frame, whether or not its joint is in `truth`.
    pub fn observe(
        &mut self,
        truth: Vec<(Joint, [f64; 3])>,
        p: &HumanParams,
    ) -> Vec<(Joint, [f64; 3])> {
        let mut dropped = [false; Joint::COUNT];
        for (flag, chain) in dropped.iter_mut().zip(self.chains.iter_mut()) {
            *flag = chain.step(&mut self.drop_rng);
        }
        truth
            .into_iter()
            .filter(|(j, _)| !dropped.get(j.index()).copied().unwrap_or(false))
            .map(|(j, pos)| {
                let mut noisy = pos;
                for (c, sd) in noisy.iter_mut().zip(p.noise_sd_mm) {
                    *c += self.noise_rng.normal(0.0, sd);
                }
                (j, noisy)
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn dropout_chain_has_the_configured_rate_and_burst_length() {
        let mut rng = Rng::new(11);
        let mut chain = Dropout::new(0.1, 4.0, &mut rng);
        let n = 200_000;
        let (mut dropped, mut bursts, mut prev) = (0usize, 0usize, false);
        for _ in 0..n {
            let d = chain.step(&mut rng);
            dropped += usize::from(d);
            bursts += usize::from(d && !prev);
            prev = d;
        }
        let rate = dropped as f64 / n as f64;
        let burst = dropped as f64 / bursts as f64;
        assert!((rate - 0.1).abs() < 0.01, "rate {rate}");
        assert!((burst - 4.0).abs() < 0.4, "burst {burst}");
    }

    #[test]
    fn zero_rates_and_zero_noise_pass_the_truth_through() {
        let p = HumanParams {
            arm_drop_rate: 0.0,
            body_drop_rate: 0.0,
            noise_sd_mm: [0.0; 3],
            ..HumanParams::default()
        };
        let mut s = SensorModel::new(Rng::new(1), Rng::new(2), &p);
        let truth = vec![
            (Joint::Head, [1.0, 2.0, 3.0]),
            (Joint::LeftHand, [4.0, 5.0, 6.0]),
        ];
        for _ in 0..100 {
            assert_eq!(s.observe(truth.clone(), &p), truth);
        }
    }

    #[test]
    fn noise_has_the_configured_spread() {
        let p = HumanParams {
            arm_drop_rate: 0.0,
            body_drop_rate: 0.0,
            noise_sd_mm: [5.0, 5.0, 20.0],
            ..HumanParams::default()
        };
        let mut s = SensorModel::new(Rng::new(1), Rng::new(2), &p);
        let n = 20_000;
        let (mut sx, mut sz) = (0.0, 0.0);
        for _ in 0..n {
            let out = s.observe(vec![(Joint::Torso, [0.0, 0.0, 2500.0])], &p);
            let v = out[0].1;
            sx += v[0] * v[0];
            sz += (v[2] - 2500.0).powi(2);
        }
        let (sdx, sdz) = ((sx / n as f64).sqrt(), (sz / n as f64).sqrt());
        assert!(
            (sdx - 5.0).abs() < 0.3 && (sdz - 20.0).abs() < 1.0,
            "{sdx} {sdz}"
        );
    }
}

//! [`StallDetector`]: the paper's stall event E, "a leaky integrator of the over-current sensor
//! readings \[that\] exceeded 3 (… incremented on an over-current signal, decremented otherwise, and
//! clamped to values between 0 and 5)".
//!
//! "Exceeded 3" is read as strictly greater: E holds at levels 4 and 5, so it takes at least four
//! consecutive over-current readings from rest to signal a stall, and a stall ends after the level has
//! fallen back to 3 (one clean reading from 4, two from 5).

/// The leaky integrator and its thresholds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct StallDetector {
    level: u8,
    above: u8,
    max: u8,
}

impl Default for StallDetector {
    /// The paper's detector: clamp to `[0, 5]`, stall above 3.
    fn default() -> Self {
        StallDetector::new(3, 5)
    }
}

impl StallDetector {
    /// A detector at level 0 that signals E while the level is strictly above `above`, with the level
    /// clamped to `[0, max]`. (With `above >= max` it never signals.)
    pub fn new(above: u8, max: u8) -> Self {
        StallDetector {
            level: 0,
            above,
            max,
        }
    }

    /// Integrates one over-current reading (+1 if set, −1 otherwise, clamped) and returns E.
    pub fn step(&mut self, overcurrent: bool) -> bool {
        self.level = if overcurrent {
            self.level.saturating_add(1).min(self.max)
        } else {
            self.level.saturating_sub(1)
        };
        self.is_stalled()
    }

    /// E at the current level.
    pub fn is_stalled(&self) -> bool {
        self.level > self.above
    }

    /// The integrator's level.
    pub fn level(&self) -> u8 {
        self.level
    }

    /// Sets the level (clamped to `[0, max]`), as when restoring a snapshot.
    pub fn set_level(&mut self, level: u8) {
        self.level = level.min(self.max);
    }

    /// Back to level 0.
    pub fn reset(&mut self) {
        self.level = 0;
    }
}

/// The over-current reading the detector integrates: either drive wheel's over-current bit in
/// packet 14 (bit 3 right, bit 4 left, on both the Create 1 and the Create 2).
pub fn wheel_overcurrent(packet_14: i32) -> bool {
    packet_14 & 0b1_1000 != 0
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn follows_the_documented_sequence() {
        let mut d = StallDetector::default();
        let readings = [1, 1, 1, 1, 1, 1, 1, 0, 0, 1, 0, 0, 0, 0, 0, 0];
        let levels = [1, 2, 3, 4, 5, 5, 5, 4, 3, 4, 3, 2, 1, 0, 0, 0];
        for (k, (&r, &want)) in readings.iter().zip(&levels).enumerate() {
            let e = d.step(r == 1);
            assert_eq!(d.level(), want, "step {k}");
            assert_eq!(e, want > 3, "step {k}: level {want}");
        }
    }

    #[test]
    fn isolated_readings_never_signal_a_stall() {
        let mut d = StallDetector::default();
        for k in 0..1000 {
            assert!(!d.step(k % 2 == 0), "step {k}");
        }
        assert!(d.level() <= 1);
    }

    #[test]
    fn custom_levels_and_reset() {
        let mut d = StallDetector::new(1, 2);
        assert!(!d.step(true));
        assert!(d.step(true));
        assert!(d.step(true));
        assert_eq!(d.level(), 2);
        d.reset();
        assert_eq!(d.level(), 0);
        let mut never = StallDetector::new(5, 5);
        assert!((0..20).all(|_| !never.step(true)));
    }

    #[test]
    fn wheel_bits_are_bits_3_and_4() {
        assert!(!wheel_overcurrent(0b0_0111));
        assert!(wheel_overcurrent(0b0_1000));
        assert!(wheel_overcurrent(0b1_0000));
        assert!(!wheel_overcurrent(0));
    }
}

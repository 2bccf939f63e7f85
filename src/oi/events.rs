//! Event bits seen between two control ticks: the robot streams a frame every 15 ms [C1 p14; C2 p22], the
//! control loop ticks every 20 ms and acts on the newest frame, so about one frame in four is never the
//! newest at a tick. Its continuous values are superseded by the next frame, but a flag it carried (an
//! over-current, a bump, a wheel drop, a cliff) would be lost. [`EventLatch`] ORs those bits over every frame
//! since the last tick and puts them into the tick's snapshot, so no flag is lost.
//!
//! The packets (bit fields of Create 1 and 2 alike [C1 p17; C2 p24–25]): 7 (bumps and wheel drops),
//! 9–12 (the four cliff sensors), 14 (wheel and low side driver over-currents).

use super::SensorValues;
use super::packets::id;

/// The packets whose bits are OR-ed between ticks.
pub const EVENT_PACKETS: [u8; 6] = [
    id::BUMPS_WHEEL_DROPS,
    id::CLIFF_LEFT,
    id::CLIFF_FRONT_LEFT,
    id::CLIFF_FRONT_RIGHT,
    id::CLIFF_RIGHT,
    id::OVERCURRENTS,
];

/// The OR of the event packets over the frames since it was last taken.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct EventLatch {
    bits: [i32; EVENT_PACKETS.len()],
    frames: u32,
}

impl EventLatch {
    /// An empty latch.
    pub fn new() -> Self {
        Self::default()
    }

    /// Folds in one frame's event packets (those it carries).
    pub fn fold(&mut self, frame: &SensorValues) {
        for (bits, &packet) in self.bits.iter_mut().zip(&EVENT_PACKETS) {
            if let Some(v) = frame.get(packet) {
                *bits |= v;
            }
        }
        self.frames = self.frames.saturating_add(1);
    }

    /// Frames folded in since the last [`EventLatch::apply_and_clear`].
    pub fn frames(&self) -> u32 {
        self.frames
    }

    /// ORs the latched bits into `newest`'s event packets (those it carries), then empties the latch. With no
    /// frame since the last call, `newest` is left as it is.
    pub fn apply_and_clear(&mut self, newest: &mut SensorValues) {
        for (&bits, &packet) in self.bits.iter().zip(&EVENT_PACKETS) {
            if let Some(v) = newest.get(packet) {
                newest.set(packet, v | bits);
            }
        }
        *self = Self::default();
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oi::packets::bits;

    fn frame(overcurrent: i32, bumps: i32, cliff_left: i32, voltage: i32) -> SensorValues {
        let mut v = SensorValues::new();
        v.set(id::OVERCURRENTS, overcurrent);
        v.set(id::BUMPS_WHEEL_DROPS, bumps);
        v.set(id::CLIFF_LEFT, cliff_left);
        v.set(id::VOLTAGE, voltage);
        v
    }

    #[test]
    fn a_flag_in_a_frame_that_was_not_the_newest_reaches_the_tick() {
        // Two frames between ticks: the first carries an over-current and a bump, the second (the newest)
        // nothing.
        let mut latch = EventLatch::new();
        let first = frame(bits::OC_LEFT_WHEEL, bits::BUMP_RIGHT, 0, 15_000);
        let mut newest = frame(0, 0, 1, 14_900);
        latch.fold(&first);
        latch.fold(&newest);
        assert_eq!(latch.frames(), 2);
        latch.apply_and_clear(&mut newest);
        assert_eq!(newest.get(id::OVERCURRENTS), Some(bits::OC_LEFT_WHEEL));
        assert_eq!(newest.get(id::BUMPS_WHEEL_DROPS), Some(bits::BUMP_RIGHT));
        assert_eq!(newest.get(id::CLIFF_LEFT), Some(1));
        // Continuous values stay the newest frame's.
        assert_eq!(newest.get(id::VOLTAGE), Some(14_900));
        assert_eq!(latch, EventLatch::new(), "cleared for the next tick");
    }

    #[test]
    fn no_frame_since_the_last_tick_leaves_the_newest_as_it_is_and_absent_packets_stay_absent() {
        let mut latch = EventLatch::new();
        let mut newest = frame(bits::OC_RIGHT_WHEEL, 0, 0, 15_000);
        let kept = newest.clone();
        latch.apply_and_clear(&mut newest);
        assert_eq!(newest, kept);
        let mut partial = SensorValues::new();
        partial.set(id::VOLTAGE, 15_000);
        latch.fold(&frame(bits::OC_LEFT_WHEEL, 0, 0, 1));
        latch.apply_and_clear(&mut partial);
        assert_eq!(partial.get(id::OVERCURRENTS), None);
    }
}

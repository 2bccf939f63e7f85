//! [`FaultCounters`]: what a [`super::FaultInjector`] has injected so far, for logs, metrics and
//! tests.

/// What has been injected so far. Byte counts are bytes; step counts are 15 ms steps.
#[derive(Debug, Clone, Default, PartialEq, Eq, serde::Serialize)]
pub struct FaultCounters {
    /// Robot→host bytes that went through the byte faults (robot output plus injected text).
    pub bytes_seen: u64,
    /// Robot→host bytes dropped.
    pub dropped_bytes: u64,
    /// Robot→host bytes with one bit inverted.
    pub flipped_bytes: u64,
    /// Robot→host bytes sent twice.
    pub duplicated_bytes: u64,
    /// Boot banners sent.
    pub banners: u64,
    /// Text lines sent between frames.
    pub text_lines: u64,
    /// Text lines spliced inside the step's bytes.
    pub text_inside: u64,
    /// Bytes of injected text (banners and lines).
    pub text_bytes: u64,
    /// Bursts started.
    pub bursts: u64,
    /// Steps whose output was held back by a burst.
    pub held_steps: u64,
    /// Hangs started.
    pub hangs: u64,
    /// Steps the link was hung.
    pub hang_steps: u64,
    /// Ends of file.
    pub eofs: u64,
    /// Robot→host bytes lost to hangs and ends of file (including bytes a burst was holding).
    pub lost_bytes: u64,
    /// Trip events started (wheel drops plus cliffs).
    pub trips: u64,
    /// Trip events that lifted the robot.
    pub wheel_drop_trips: u64,
    /// Trip events that put a cliff under a sensor.
    pub cliff_trips: u64,
    /// Host→robot bytes offered to [`super::FaultInjector::host_bytes`].
    pub host_bytes_seen: u64,
    /// Host→robot bytes dropped.
    pub host_dropped: u64,
    /// Host→robot bytes with one bit inverted.
    pub host_flipped: u64,
    /// Host→robot bytes lost while the link was hung.
    pub host_lost: u64,
}

impl FaultCounters {
    /// Every fault event injected: byte faults (both ways), banners, text lines, bursts, hangs, ends of
    /// file and trips.
    pub fn total_events(&self) -> u64 {
        self.dropped_bytes
            + self.flipped_bytes
            + self.duplicated_bytes
            + self.banners
            + self.text_lines
            + self.text_inside
            + self.bursts
            + self.hangs
            + self.eofs
            + self.trips
            + self.host_dropped
            + self.host_flipped
    }
}

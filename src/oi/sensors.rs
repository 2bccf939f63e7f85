//! [`SensorValues`]: one snapshot of raw sensor packet values, indexed by packet id.
//!
//! Values are kept exactly as the robot reports them (after big-endian decoding and sign extension),
//! in the packet's own units: mm, mV, mA, bit fields as integers. Scaling to `[0, 1]` happens in
//! [`crate::obs`]; meaning (sizes, signedness, bit layouts) lives in the packet table.

use serde::{Deserialize, Serialize};

/// The number of packet-id slots: ids 0..=58 (only 7..=58 hold single packets).
pub const PACKET_SLOTS: usize = 59;

/// Raw values of single sensor packets 7–58, each present or absent. Held inline (no heap), so a
/// snapshot is made, copied and dropped without allocating: the parser makes one per frame and every
/// tick's record holds one.
#[derive(Debug, Clone, PartialEq, Eq, Serialize, Deserialize)]
pub struct SensorValues {
    #[serde(with = "slots_serde")]
    values: [i32; PACKET_SLOTS],
    present: u64,
}

/// Serde for the slots as a sequence of [`PACKET_SLOTS`] numbers, as when they were a `Vec` (serde's
/// derive stops at arrays of 32).
mod slots_serde {
    use serde::de::Error;
    use serde::{Deserialize, Deserializer, Serializer};

    use super::PACKET_SLOTS;

    pub(super) fn serialize<S: Serializer>(
        slots: &[i32; PACKET_SLOTS],
        s: S,
    ) -> Result<S::Ok, S::Error> {
        s.collect_seq(slots.iter())
    }

    pub(super) fn deserialize<'de, D: Deserializer<'de>>(
        d: D,
    ) -> Result<[i32; PACKET_SLOTS], D::Error> {
        let v = Vec::<i32>::deserialize(d)?;
        let n = v.len();
        v.try_into()
            .map_err(|_| D::Error::invalid_length(n, &"one value per packet-id slot (59)"))
    }
}

impl Default for SensorValues {
    fn default() -> Self {
        Self::new()
    }
}

impl SensorValues {
    /// An empty snapshot: no packet present.
    pub fn new() -> Self {
        SensorValues {
            values: [0; PACKET_SLOTS],
            present: 0,
        }
    }

    /// The value of packet `id`, if the snapshot holds it.
    pub fn get(&self, id: u8) -> Option<i32> {
        let i = id as usize;
        if i < PACKET_SLOTS && self.present & (1 << i) != 0 {
            Some(self.values[i])
        } else {
            None
        }
    }

    /// The value of packet `id`, or 0 when absent.
    pub fn get_or_zero(&self, id: u8) -> i32 {
        self.get(id).unwrap_or(0)
    }

    /// Sets packet `id` (ids above 58 are ignored).
    pub fn set(&mut self, id: u8, value: i32) {
        let i = id as usize;
        if i < PACKET_SLOTS {
            self.values[i] = value;
            self.present |= 1 << i;
        }
    }

    /// Copies every packet present in `other` into `self`.
    pub fn merge(&mut self, other: &SensorValues) {
        for (id, v) in other.iter() {
            self.set(id, v);
        }
    }

    /// `(id, value)` for every present packet, in increasing id order.
    pub fn iter(&self) -> impl Iterator<Item = (u8, i32)> + '_ {
        (0..PACKET_SLOTS as u8).filter_map(move |id| self.get(id).map(|v| (id, v)))
    }

    /// The snapshot as stored: slot `id` holds packet `id`'s value when bit `id` of the mask is set, and 0
    /// otherwise. For writers that copy it whole (the recorder's protobuf encoding).
    pub fn slots(&self) -> (&[i32], u64) {
        (&self.values, self.present)
    }

    /// A snapshot of the first [`PACKET_SLOTS`] of `slots` with presence mask `present` (bits above
    /// the slots are dropped), for the parser's decoding. A slot whose bit is clear must hold 0, as
    /// [`SensorValues::slots`] promises its readers.
    pub(crate) fn from_slots(slots: &[i32; 64], present: u64) -> Self {
        let mut values = [0; PACKET_SLOTS];
        if let Some(head) = slots.get(..PACKET_SLOTS) {
            values.copy_from_slice(head);
        }
        SensorValues {
            values,
            present: present & ((1 << PACKET_SLOTS) - 1),
        }
    }

    /// True when no packet is present.
    pub fn is_empty(&self) -> bool {
        self.present == 0
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn set_get_merge() {
        let mut a = SensorValues::new();
        assert!(a.is_empty());
        a.set(22, 15_000);
        a.set(23, -300);
        a.set(200, 1);
        assert_eq!(a.get(22), Some(15_000));
        assert_eq!(a.get(23), Some(-300));
        assert_eq!(a.get(24), None);
        let mut b = SensorValues::new();
        b.set(23, 5);
        b.merge(&a);
        assert_eq!(b.iter().collect::<Vec<_>>(), vec![(22, 15_000), (23, -300)]);
        let (slots, present) = b.slots();
        assert_eq!(present, 1 << 22 | 1 << 23);
        assert_eq!((slots[22], slots[23], slots[24]), (15_000, -300, 0));
    }
}

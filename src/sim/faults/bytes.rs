//! Byte-level line faults: each byte independently dropped, or else bit-flipped and/or duplicated.

use crate::rng::Rng;

/// Per-byte fault probabilities, each in [0, 1].
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct ByteRates {
    /// The byte is lost.
    pub drop: f64,
    /// The byte (not dropped) has one random bit inverted.
    pub flip: f64,
    /// The byte (not dropped) is sent twice (after any flip).
    pub duplicate: f64,
}

impl ByteRates {
    /// True when no byte would ever be touched.
    pub fn is_none(&self) -> bool {
        self.drop <= 0.0 && self.flip <= 0.0 && self.duplicate <= 0.0
    }
}

/// What `corrupt` did.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub struct ByteTally {
    /// Bytes lost.
    pub dropped: u64,
    /// Bytes with a bit inverted.
    pub flipped: u64,
    /// Bytes sent twice.
    pub duplicated: u64,
}

/// `bytes` as they come out of a line with `rates`. With all rates zero it draws nothing from `rng`
/// and returns the bytes unchanged.
pub fn corrupt(bytes: &[u8], rates: ByteRates, rng: &mut Rng, tally: &mut ByteTally) -> Vec<u8> {
    if rates.is_none() {
        return bytes.to_vec();
    }
    let mut out = Vec::with_capacity(bytes.len() + 4);
    for &b in bytes {
        if rng.chance(rates.drop) {
            tally.dropped += 1;
            continue;
        }
        let b = if rng.chance(rates.flip) {
            tally.flipped += 1;
            b ^ (1u8 << rng.below(8))
        } else {
            b
        };
        out.push(b);
        if rng.chance(rates.duplicate) {
            tally.duplicated += 1;
            out.push(b);
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zero_rates_pass_bytes_through_untouched() {
        let mut rng = Rng::new(1);
        let before = rng.clone();
        let mut tally = ByteTally::default();
        let data: Vec<u8> = (0..=255).collect();
        assert_eq!(
            corrupt(&data, ByteRates::default(), &mut rng, &mut tally),
            data
        );
        assert_eq!(tally, ByteTally::default());
        assert_eq!(rng, before);
    }

    #[test]
    fn certain_faults_do_exactly_what_they_say() {
        let mut rng = Rng::new(2);
        let data: Vec<u8> = (0..100).collect();
        let mut t = ByteTally::default();
        let all_dropped = ByteRates {
            drop: 1.0,
            ..ByteRates::default()
        };
        assert!(corrupt(&data, all_dropped, &mut rng, &mut t).is_empty());
        assert_eq!(t.dropped, 100);

        let mut t = ByteTally::default();
        let flipped = ByteRates {
            flip: 1.0,
            ..ByteRates::default()
        };
        let out = corrupt(&data, flipped, &mut rng, &mut t);
        assert_eq!(out.len(), 100);
        assert!(
            out.iter()
                .zip(&data)
                .all(|(a, b)| (a ^ b).count_ones() == 1)
        );
        assert_eq!(t.flipped, 100);

        let mut t = ByteTally::default();
        let doubled = ByteRates {
            duplicate: 1.0,
            ..ByteRates::default()
        };
        let out = corrupt(&data, doubled, &mut rng, &mut t);
        let expected: Vec<u8> = data.iter().flat_map(|&b| [b, b]).collect();
        assert_eq!(out, expected);
        assert_eq!(t.duplicated, 100);
    }
}

//! Stream frames: `[19][N][id1][data1…]…[idk][datak…][checksum]`, sent every 15 ms [C1 p14; C2 p22].
//!
//! `N` counts the id and data bytes between the length byte and the checksum. The checksum makes the
//! sum of every byte of the frame, header through checksum, ≡ 0 (mod 256) [C2 p22], on both models:
//! [C1 p14] words it as excluding the header (and prints checksum 182 for the same example), but every
//! working Create 1 driver includes the header ([C1 p14] and \[R500\] print a checksum without it, yet
//! libcreate, RLPark and the real robot include it).
//! A frame must fit in one 15 ms slot at the link's baud rate or the stream corrupts [C1 p14; C2 p22].

use super::model::stream_budget_bytes;
use super::packets::{DataBuf, data_len, encode_data_into};
use super::{OiError, SensorValues};

/// The first byte of every stream frame.
pub const STREAM_HEADER: u8 = 19;

/// The length byte N of a frame for `ids`: Σ(1 + data bytes).
pub fn stream_payload_len(ids: &[u8]) -> Result<usize, OiError> {
    if ids.is_empty() {
        return Err(OiError::EmptyStreamList);
    }
    let mut n = 0usize;
    for &id in ids {
        n += 1 + data_len(id).ok_or(OiError::UnknownPacket(id))?;
    }
    if n > usize::from(u8::MAX) {
        return Err(OiError::FrameTooLong { data_bytes: n });
    }
    Ok(n)
}

/// Total bytes of one frame for `ids` (single packets and/or groups): 3 + Σ(1 + data bytes).
pub fn stream_frame_len(ids: &[u8]) -> Result<usize, OiError> {
    stream_payload_len(ids).map(|n| n + 3)
}

/// The frame length, or [`OiError::OverBudget`] if a frame would not fit in one 15 ms slot at `baud`
/// (15 ms × baud / 10 bits: 86 bytes at 57600, 172 at 115200 [C1 p14; C2 p22]).
pub fn check_stream_budget(ids: &[u8], baud: u32) -> Result<usize, OiError> {
    let frame_bytes = stream_frame_len(ids)?;
    let budget = stream_budget_bytes(baud);
    if frame_bytes > budget {
        Err(OiError::OverBudget {
            frame_bytes,
            budget,
            baud,
        })
    } else {
        Ok(frame_bytes)
    }
}

/// The byte that makes `bytes` plus it sum to 0 mod 256.
pub fn checksum_for(bytes: &[u8]) -> u8 {
    byte_sum(bytes).wrapping_neg()
}

/// The low byte of the sum of `bytes`.
pub fn byte_sum(bytes: &[u8]) -> u8 {
    bytes.iter().fold(0u8, |acc, &b| acc.wrapping_add(b))
}

/// The robot's side: one whole frame for `ids` with `values` (absent values are sent as 0).
pub fn encode_stream_frame(ids: &[u8], values: &SensorValues) -> Result<Vec<u8>, OiError> {
    let mut frame = Vec::with_capacity(stream_payload_len(ids)? + 3);
    encode_stream_frame_into(ids, values, &mut frame)?;
    Ok(frame)
}

/// Like [`encode_stream_frame`], into `frame` (cleared first; left empty on error): a caller that keeps
/// the buffer encodes every frame without allocating.
pub fn encode_stream_frame_into(
    ids: &[u8],
    values: &SensorValues,
    frame: &mut Vec<u8>,
) -> Result<(), OiError> {
    frame.clear();
    let n = stream_payload_len(ids)?;
    // The frame is assembled in a fixed array (header, N ≤ 255 bytes, checksum) and copied out once,
    // instead of growing `frame` a byte at a time; the bytes are the same.
    let mut bytes = [0u8; 3 + u8::MAX as usize];
    bytes[0] = STREAM_HEADER;
    bytes[1] = n as u8; // stream_payload_len guarantees n <= 255
    let mut at = 2;
    let mut data: DataBuf = [0; 256];
    for &id in ids {
        let len = encode_data_into(id, values, &mut data)?;
        // `n` counted every id and its data, so they fit before the checksum's byte.
        if let Some(slot) = bytes.get_mut(at) {
            *slot = id;
        }
        if let (Some(dst), Some(src)) = (bytes.get_mut(at + 1..at + 1 + len), data.get(..len)) {
            dst.copy_from_slice(src);
        }
        at += 1 + len;
    }
    let body = bytes.get(..at).unwrap_or_default();
    let sum = checksum_for(body);
    frame.extend_from_slice(body);
    frame.push(sum);
    Ok(())
}

/// True when the bytes of a whole frame (header through checksum) sum to 0 mod 256.
pub fn checksum_ok(frame: &[u8]) -> bool {
    !frame.is_empty() && byte_sum(frame) == 0
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::oi::Model;
    use crate::oi::packets::id;

    #[test]
    fn spec_example_frame_for_29_and_13() {
        // [C2 p22]: 19 5 29 2 25 13 0 163, checksum including the header.
        let mut v = SensorValues::new();
        v.set(id::CLIFF_FRONT_LEFT_SIGNAL, 0x0219);
        v.set(id::VIRTUAL_WALL, 0);
        let frame = encode_stream_frame(&[29, 13], &v).unwrap();
        assert_eq!(frame, vec![19, 5, 29, 2, 25, 13, 0, 163]);
        assert!(checksum_ok(&frame));
        assert_eq!(stream_frame_len(&[29, 13]), Ok(frame.len()));
    }

    #[test]
    fn reference_vector_with_signed_values() {
        let mut v = SensorValues::new();
        v.set(id::BUMPS_WHEEL_DROPS, 1);
        v.set(id::DISTANCE, 15);
        v.set(id::ANGLE, -3);
        let frame = encode_stream_frame(&[7, 19, 20], &v).unwrap();
        assert_eq!(frame, vec![19, 8, 7, 1, 19, 0, 15, 20, 255, 253, 171]);
    }

    #[test]
    fn checksum_detects_a_changed_byte() {
        let frame = [19u8, 5, 29, 2, 25, 13, 0, 163];
        for i in 0..frame.len() {
            let mut bad = frame;
            bad[i] ^= 0x10;
            assert!(!checksum_ok(&bad), "flipping byte {i}");
        }
        assert!(!checksum_ok(&[]));
        assert_eq!(checksum_for(&frame[..7]), 163);
    }

    #[test]
    fn whole_sensor_groups_fit_their_default_baud() {
        assert_eq!(stream_frame_len(&[6]), Ok(56));
        assert_eq!(stream_frame_len(&[100]), Ok(84));
        assert_eq!(check_stream_budget(&[6], Model::Create1.baud()), Ok(56));
        assert_eq!(check_stream_budget(&[100], Model::Create2.baud()), Ok(84));
        assert_eq!(check_stream_budget(&[100, 100], 115_200), Ok(165));
        assert_eq!(
            check_stream_budget(&[100, 6], 57_600),
            Err(OiError::OverBudget {
                frame_bytes: 137,
                budget: 86,
                baud: 57_600
            })
        );
        assert_eq!(
            check_stream_budget(&[6], 19_200),
            Err(OiError::OverBudget {
                frame_bytes: 56,
                budget: 28,
                baud: 19_200
            })
        );
        let frame = encode_stream_frame(&[100], &SensorValues::new()).unwrap();
        assert_eq!(&frame[..3], &[19, 81, 100]);
        assert_eq!(frame.len(), 84);
        assert!(checksum_ok(&frame));
    }

    #[test]
    fn bad_lists_are_refused() {
        assert_eq!(stream_frame_len(&[]), Err(OiError::EmptyStreamList));
        assert_eq!(stream_frame_len(&[7, 59]), Err(OiError::UnknownPacket(59)));
        assert_eq!(
            stream_frame_len(&[100, 100, 100, 100]),
            Err(OiError::FrameTooLong { data_bytes: 324 })
        );
        assert_eq!(
            encode_stream_frame(&[105], &SensorValues::new()),
            Err(OiError::UnknownPacket(105))
        );
    }
}

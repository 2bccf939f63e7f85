//! [`StreamParser`]: the host-side, incremental, resynchronising parser of stream frames.
//!
//! Fed arbitrary chunks of the serial byte stream (even one byte at a time), it finds every valid
//! frame for the requested packet list and hands over its values. A candidate frame needs the header
//! 19, the length byte N expected for the requested list, the requested ids at exactly their places,
//! and a checksum that makes every byte header..checksum sum to 0 mod 256 [C1 p14; C2 p22]. On any
//! mismatch the search resumes **one byte after the false header**, never after the whole claimed
//! frame, because a real frame may start inside a false one; text the Create 2 firmware prints between
//! frames (banners, `bat: …` lines) is skipped the same way. Values are committed only after the
//! checksum holds. Memory is bounded: at most one frame's worth of bytes is kept between calls.

use super::frame::{STREAM_HEADER, byte_sum, stream_payload_len};
use super::packets::{group_members, spec};
use super::{OiError, SensorValues};

/// Counters of what the parser has seen since it was created.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct ParserStats {
    /// Frames that passed every check and were handed over.
    pub good_frames: u64,
    /// Header + expected length that then failed the id or checksum check.
    pub bad_frames: u64,
    /// Bytes not part of any good frame (garbage, text, false headers).
    pub skipped_bytes: u64,
}

/// Where one single packet's value sits in a frame.
#[derive(Debug, Clone, Copy)]
struct Field {
    offset: usize,
    id: u8,
    size: u8,
    signed: bool,
}

/// The fixed shape of a valid frame for the requested list.
#[derive(Debug, Clone)]
struct Layout {
    payload_len: u8,
    frame_len: usize,
    /// `(offset in frame, expected id byte)` for each requested id.
    id_checks: Vec<(usize, u8)>,
    fields: Vec<Field>,
}

/// What a window starting at a header byte turned out to be.
enum Verdict {
    /// Not enough bytes yet to decide.
    NeedMore,
    /// The length byte is not the expected N: just a stray 19.
    NotACandidate,
    /// Header and length matched, ids or checksum did not.
    Bad,
    /// A valid frame.
    Good,
}

impl Layout {
    fn new(requested: &[u8]) -> Result<Layout, OiError> {
        let payload_len = stream_payload_len(requested)?;
        let mut id_checks = Vec::with_capacity(requested.len());
        let mut fields = Vec::new();
        let mut offset = 2;
        for &id in requested {
            id_checks.push((offset, id));
            offset += 1;
            let single = spec(id).map(|s| std::slice::from_ref(&s.id));
            let members = single
                .or_else(|| group_members(id))
                .ok_or(OiError::UnknownPacket(id))?;
            for s in members.iter().filter_map(|&m| spec(m)) {
                fields.push(Field {
                    offset,
                    id: s.id,
                    size: s.size,
                    signed: s.signed,
                });
                offset += usize::from(s.size);
            }
        }
        Ok(Layout {
            payload_len: payload_len as u8, // <= 255, checked by stream_payload_len
            frame_len: payload_len + 3,
            id_checks,
            fields,
        })
    }

    /// Judges the bytes starting at a header byte, deciding as early as the bytes allow.
    fn judge(&self, window: &[u8]) -> Verdict {
        match window.get(1) {
            None => return Verdict::NeedMore,
            Some(&n) if n != self.payload_len => return Verdict::NotACandidate,
            Some(_) => {}
        }
        let ids_wrong = self
            .id_checks
            .iter()
            .any(|&(off, id)| window.get(off).is_some_and(|&b| b != id));
        if ids_wrong {
            return Verdict::Bad;
        }
        match window.get(..self.frame_len) {
            None => Verdict::NeedMore,
            Some(frame) if byte_sum(frame) == 0 => Verdict::Good,
            Some(_) => Verdict::Bad,
        }
    }

    /// The values of a frame already judged good.
    fn decode(&self, frame: &[u8]) -> SensorValues {
        let mut values = SensorValues::new();
        for f in &self.fields {
            let hi = frame.get(f.offset).copied().unwrap_or(0);
            let v = match (f.size, f.signed) {
                (1, false) => i32::from(hi),
                (1, true) => i32::from(hi as i8),
                (_, signed) => {
                    let lo = frame.get(f.offset + 1).copied().unwrap_or(0);
                    let raw = u16::from_be_bytes([hi, lo]);
                    if signed {
                        i32::from(raw as i16)
                    } else {
                        i32::from(raw)
                    }
                }
            };
            values.set(f.id, v);
        }
        values
    }

    /// Scans candidate frame starts `0..start_limit` of `data`, handing over good frames. Returns where
    /// it stopped: `start_limit` (or just past a frame that ran beyond it), or the start of a candidate
    /// that needs bytes beyond the end of `data`.
    fn scan(
        &self,
        stats: &mut ParserStats,
        data: &[u8],
        start_limit: usize,
        on_frame: &mut impl FnMut(SensorValues),
    ) -> usize {
        let mut i = 0;
        while i < start_limit {
            let searched = data.get(i..start_limit).unwrap_or_default();
            match searched.iter().position(|&b| b == STREAM_HEADER) {
                None => {
                    stats.skipped_bytes += searched.len() as u64;
                    return start_limit;
                }
                Some(k) => {
                    stats.skipped_bytes += k as u64;
                    i += k;
                }
            }
            let window = data.get(i..).unwrap_or_default();
            match self.judge(window) {
                Verdict::NeedMore => return i,
                Verdict::NotACandidate => {
                    stats.skipped_bytes += 1;
                    i += 1;
                }
                Verdict::Bad => {
                    stats.bad_frames += 1;
                    stats.skipped_bytes += 1;
                    i += 1;
                }
                Verdict::Good => {
                    on_frame(self.decode(window));
                    stats.good_frames += 1;
                    i += self.frame_len;
                }
            }
        }
        i
    }
}

/// Incremental parser of the frames of one Stream request.
#[derive(Debug, Clone)]
pub struct StreamParser {
    requested: Vec<u8>,
    layout: Layout,
    /// Bytes kept between calls: a possible frame start and what followed it (< one frame).
    pending: Vec<u8>,
    stats: ParserStats,
}

impl StreamParser {
    /// A parser for the frames answering a Stream request for `requested` (single packets and/or groups,
    /// in the order they were sent).
    pub fn new(requested: &[u8]) -> Result<Self, OiError> {
        let layout = Layout::new(requested)?;
        Ok(StreamParser {
            requested: requested.to_vec(),
            pending: Vec::with_capacity(2 * layout.frame_len),
            layout,
            stats: ParserStats::default(),
        })
    }

    /// Parses the next `chunk` of the byte stream, calling `on_frame` once per valid frame, in order.
    pub fn feed(&mut self, chunk: &[u8], mut on_frame: impl FnMut(SensorValues)) {
        let mut rest = chunk;
        loop {
            if self.pending.is_empty() {
                let stop = self
                    .layout
                    .scan(&mut self.stats, rest, rest.len(), &mut on_frame);
                self.pending
                    .extend_from_slice(rest.get(stop..).unwrap_or_default());
                return;
            }
            if rest.is_empty() {
                return;
            }
            // Candidates starting in the kept bytes need at most one frame's worth of the new ones.
            let kept = self.pending.len();
            let (head, tail) = rest.split_at(rest.len().min(self.layout.frame_len));
            self.pending.extend_from_slice(head);
            let stop = self
                .layout
                .scan(&mut self.stats, &self.pending, kept, &mut on_frame);
            if stop < kept {
                // Still waiting for the rest of a candidate (then `tail` is empty).
                self.pending.drain(..stop);
                rest = tail;
            } else {
                self.pending.clear();
                rest = rest.get(stop - kept..).unwrap_or_default();
            }
        }
    }

    /// Parses `chunk` and returns only the newest valid frame in it, for a driver that must never work
    /// through a backlog in order (libcreate#68 in the reference).
    pub fn feed_newest(&mut self, chunk: &[u8]) -> Option<SensorValues> {
        let mut newest = None;
        self.feed(chunk, |values| newest = Some(values));
        newest
    }

    /// Counters since creation (kept across [`StreamParser::reset`]).
    pub fn stats(&self) -> ParserStats {
        self.stats
    }

    /// Drops any buffered partial frame (e.g. after a reconnect); keeps the counters.
    pub fn reset(&mut self) {
        self.pending.clear();
    }

    /// The packet list this parser expects.
    pub fn requested(&self) -> &[u8] {
        &self.requested
    }

    /// Bytes of one valid frame.
    pub fn frame_len(&self) -> usize {
        self.layout.frame_len
    }

    /// Bytes currently kept while waiting for the rest of a possible frame (always < one frame).
    pub fn buffered(&self) -> usize {
        self.pending.len()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spec_test_vector_parses() {
        let mut p = StreamParser::new(&[29, 13]).unwrap();
        let mut got = Vec::new();
        p.feed(&[19, 5, 29, 2, 25, 13, 0, 163], |v| got.push(v));
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].get(29), Some(537));
        assert_eq!(got[0].get(13), Some(0));
    }
}

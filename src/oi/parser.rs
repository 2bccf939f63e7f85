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
//!
//! An 8-bit sum lets about one damaged frame in 256 through (two flips that cancel, a frame shifted
//! by a dropped or duplicated byte). A parser told its robot's model ([`StreamParser::with_model`])
//! also rejects a frame whose values no Create can report ([`super::plausible`]): it counts as a bad
//! frame (and as implausible) and the search resumes one byte after its header, like any bad frame.
//! Distance and angle are bounded only in a frame that starts exactly where the previous accepted
//! frame ended (nothing skipped in between): the first frame after a start, [`StreamParser::reset`]
//! or skipped bytes may carry motion accumulated over any time. After resuming a paused stream
//! (opcode 150), call [`StreamParser::reset`] so its first frame is not held to 15 ms of motion.
//! A packet that breaks its bound in [`WAIVE_AFTER`] frames in a row (none accepted between) is taken
//! as genuine and no longer checked ([`StreamParser::waived`]): damage is isolated, a real value persists.

use super::frame::{STREAM_HEADER, byte_sum, stream_payload_len};
use super::packets::{group_members, spec};
use super::plausible::{FrameCheck, FrameContext, Implausible, WAIVE_AFTER, Waived};
use super::sensors::PACKET_SLOTS;
use super::{Model, OiError, SensorValues};

/// Counters of what the parser has seen since it was created.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, serde::Serialize)]
pub struct ParserStats {
    /// Frames that passed every check and were handed over.
    pub good_frames: u64,
    /// Header + expected length that then failed the id, checksum or plausibility check.
    pub bad_frames: u64,
    /// Of `bad_frames`, those whose ids and checksum held but whose values no Create can report
    /// (only with a model, [`StreamParser::with_model`]).
    pub implausible_frames: u64,
    /// Bytes not part of any good frame (garbage, text, false headers).
    pub skipped_bytes: u64,
}

/// The parser's running state that scanning updates: counters, plausibility settings and results.
#[derive(Debug, Clone, Default)]
struct ScanState {
    stats: ParserStats,
    /// The robot model whose plausible values are enforced; `None`: no plausibility checks.
    model: Option<Model>,
    /// `stats.skipped_bytes` when the last frame was accepted; `None` before the first one (or after
    /// a reset). A frame follows the previous one directly iff nothing was skipped since.
    skipped_at_accept: Option<u64>,
    /// Why the most recent implausible frame was rejected.
    last_implausible: Option<Implausible>,
    /// The packet the latest run of implausible frames broke, and how many in a row (none accepted).
    streak: Option<(u8, u32)>,
    /// Packets whose bound a run of [`WAIVE_AFTER`] frames proved wrong for this robot.
    waived: Waived,
    /// The plausibility bounds laid out for the frames' model and packets.
    check: Option<FrameCheck>,
}

impl ScanState {
    fn skip(&mut self, bytes: usize) {
        self.stats.skipped_bytes += bytes as u64;
    }

    /// Why `values` cannot be a frame from the robot, if plausibility is checked.
    fn reject(&mut self, values: &SensorValues) -> Option<Implausible> {
        let model = self.model?;
        let context = if self.skipped_at_accept == Some(self.stats.skipped_bytes) {
            FrameContext::FollowsFrame
        } else {
            FrameContext::First
        };
        FrameCheck::implausible(&mut self.check, values, model, context, self.waived)
    }

    /// Counts a frame rejected for `why`; a long enough run for one packet waives its bound.
    fn rejected(&mut self, why: Implausible) {
        self.stats.bad_frames += 1;
        self.stats.implausible_frames += 1;
        self.last_implausible = Some(why);
        let run = match self.streak {
            Some((id, n)) if id == why.id => n + 1,
            _ => 1,
        };
        self.streak = Some((why.id, run));
        if run >= WAIVE_AFTER {
            self.waived.insert(why.id);
            self.streak = None;
        }
    }

    /// Counts an accepted frame.
    fn accepted(&mut self) {
        self.stats.good_frames += 1;
        self.skipped_at_accept = Some(self.stats.skipped_bytes);
        self.streak = None;
    }
}

/// Where one single packet's value sits in a frame, and how to read it.
#[derive(Debug, Clone, Copy)]
struct Field {
    /// Below 258: a frame is at most 3 + 255 bytes.
    offset: u16,
    /// 7–58.
    id: u8,
    /// Two bytes (big-endian) rather than one.
    two: bool,
    /// Sign extension as a shift pair, `(raw << shift) >> shift` on an `i32`: 24 for a signed byte,
    /// 16 for a signed 16-bit value, 0 for an unsigned one (exactly `as i8` / `as i16` / nothing).
    shift: u8,
}

/// A frame copied for decoding: 512 bytes, so that an offset masked to 9 bits (all of them are
/// below 258) is always inside it, and bytes beyond the frame read as 0.
type FrameBuf = [u8; 512];

/// The fixed shape of a valid frame for the requested list.
#[derive(Debug, Clone)]
struct Layout {
    payload_len: u8,
    frame_len: usize,
    /// `(offset in frame, expected id byte)` for each requested id.
    id_checks: Vec<(usize, u8)>,
    fields: Vec<Field>,
    /// The presence bit of every field's packet: what decoding a frame marks present.
    present: u64,
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
                    offset: offset as u16, // < 258, checked by stream_payload_len
                    id: s.id,
                    two: s.size == 2,
                    shift: match (s.size, s.signed) {
                        (_, false) => 0,
                        (1, true) => 24,
                        (_, true) => 16,
                    },
                });
                offset += usize::from(s.size);
            }
        }
        let present = fields
            .iter()
            .filter(|f| usize::from(f.id) < PACKET_SLOTS)
            .fold(0u64, |mask, f| mask | 1 << f.id);
        Ok(Layout {
            payload_len: payload_len as u8, // <= 255, checked by stream_payload_len
            frame_len: payload_len + 3,
            id_checks,
            fields,
            present,
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

    /// The values of a frame already judged good: every field in order (a packet requested twice
    /// keeps its last value), written straight into the snapshot's slots without a branch per field.
    fn decode(&self, frame: &[u8]) -> SensorValues {
        let mut bytes: FrameBuf = [0; 512];
        let len = frame.len().min(self.frame_len).min(bytes.len());
        if let (Some(dst), Some(src)) = (bytes.get_mut(..len), frame.get(..len)) {
            dst.copy_from_slice(src);
        }
        // Indexed by id masked to 6 bits (ids are 7–58), then cut to the snapshot's 59 slots; a
        // slot no field writes stays 0, as an absent packet's must.
        let mut slots = [0i32; 64];
        for f in &self.fields {
            let at = usize::from(f.offset) & 511;
            let hi = u32::from(bytes[at]);
            let lo = u32::from(bytes[(at + 1) & 511]);
            let raw = if f.two { hi << 8 | lo } else { hi };
            slots[usize::from(f.id) & 63] = (raw << f.shift) as i32 >> f.shift;
        }
        SensorValues::from_slots(&slots, self.present)
    }

    /// Scans candidate frame starts `0..start_limit` of `data`, handing over good frames. Returns where
    /// it stopped: `start_limit` (or just past a frame that ran beyond it), or the start of a candidate
    /// that needs bytes beyond the end of `data`.
    fn scan(
        &self,
        state: &mut ScanState,
        data: &[u8],
        start_limit: usize,
        on_frame: &mut impl FnMut(SensorValues),
    ) -> usize {
        let mut i = 0;
        while i < start_limit {
            let searched = data.get(i..start_limit).unwrap_or_default();
            match searched.iter().position(|&b| b == STREAM_HEADER) {
                None => {
                    state.skip(searched.len());
                    return start_limit;
                }
                Some(k) => {
                    state.skip(k);
                    i += k;
                }
            }
            let window = data.get(i..).unwrap_or_default();
            match self.judge(window) {
                Verdict::NeedMore => return i,
                Verdict::NotACandidate => {
                    state.skip(1);
                    i += 1;
                }
                Verdict::Bad => {
                    state.stats.bad_frames += 1;
                    state.skip(1);
                    i += 1;
                }
                Verdict::Good => {
                    let values = self.decode(window);
                    if let Some(why) = state.reject(&values) {
                        state.rejected(why);
                        state.skip(1);
                        i += 1;
                    } else {
                        on_frame(values);
                        state.accepted();
                        i += self.frame_len;
                    }
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
    state: ScanState,
}

impl StreamParser {
    /// A parser for the frames answering a Stream request for `requested` (single packets and/or groups,
    /// in the order they were sent). It checks structure only; see [`StreamParser::with_model`].
    pub fn new(requested: &[u8]) -> Result<Self, OiError> {
        let layout = Layout::new(requested)?;
        Ok(StreamParser {
            requested: requested.to_vec(),
            pending: Vec::with_capacity(2 * layout.frame_len),
            layout,
            state: ScanState::default(),
        })
    }

    /// The same parser, also rejecting frames whose values a `model` Create cannot report
    /// ([`super::plausible`]); they count in [`ParserStats::implausible_frames`] and `bad_frames`.
    pub fn with_model(mut self, model: Model) -> Self {
        self.state.model = Some(model);
        self
    }

    /// The model whose plausible values are enforced, if any.
    pub fn model(&self) -> Option<Model> {
        self.state.model
    }

    /// Why the most recent implausible frame was rejected (for a log line), if any was.
    pub fn last_implausible(&self) -> Option<Implausible> {
        self.state.last_implausible
    }

    /// Packets no longer checked because [`WAIVE_AFTER`] frames in a row broke their bound (worth a
    /// warning: the robot reports values its documents rule out).
    pub fn waived(&self) -> Waived {
        self.state.waived
    }

    /// Parses the next `chunk` of the byte stream, calling `on_frame` once per valid frame, in order.
    pub fn feed(&mut self, chunk: &[u8], mut on_frame: impl FnMut(SensorValues)) {
        let mut rest = chunk;
        loop {
            if self.pending.is_empty() {
                let stop = self
                    .layout
                    .scan(&mut self.state, rest, rest.len(), &mut on_frame);
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
                .scan(&mut self.state, &self.pending, kept, &mut on_frame);
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
    /// through a backlog in order (a parser that did led to delays of minutes: AutonomyLab/libcreate issue 68).
    pub fn feed_newest(&mut self, chunk: &[u8]) -> Option<SensorValues> {
        let mut newest = None;
        self.feed(chunk, |values| newest = Some(values));
        newest
    }

    /// Counters since creation (kept across [`StreamParser::reset`]).
    pub fn stats(&self) -> ParserStats {
        self.state.stats
    }

    /// Drops any buffered partial frame (e.g. after a reconnect or before resuming a paused stream);
    /// keeps the counters. The next frame is treated as a first frame: its distance and angle may hold
    /// motion accumulated over any time.
    pub fn reset(&mut self) {
        self.pending.clear();
        self.state.skipped_at_accept = None;
        self.state.streak = None;
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
mod tests;

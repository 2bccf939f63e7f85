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
use super::plausible::{FrameContext, Implausible, WAIVE_AFTER, Waived, implausible_except};
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
}

impl ScanState {
    fn skip(&mut self, bytes: usize) {
        self.stats.skipped_bytes += bytes as u64;
    }

    /// Why `values` cannot be a frame from the robot, if plausibility is checked.
    fn reject(&self, values: &SensorValues) -> Option<Implausible> {
        let model = self.model?;
        let context = if self.skipped_at_accept == Some(self.stats.skipped_bytes) {
            FrameContext::FollowsFrame
        } else {
            FrameContext::First
        };
        implausible_except(values, model, context, self.waived)
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
    /// through a backlog in order (libcreate#68 in the reference).
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
mod tests {
    use super::*;
    use crate::oi::frame::{checksum_for, encode_stream_frame};
    use crate::oi::packets::{data_len, decode_data};
    use proptest::prelude::*;

    const BAT_LINE: &[u8] =
        b"bat:   min 0  sec 10  mV 17061  mA 1016  tenths-deg-C 348  mAH 2696  state 5\r\n";

    fn collect(p: &mut StreamParser, bytes: &[u8]) -> Vec<SensorValues> {
        let mut got = Vec::new();
        p.feed(bytes, |v| got.push(v));
        got
    }

    /// A frame for `requested` carrying `data` (all ids' data bytes concatenated).
    fn frame_with_data(requested: &[u8], data: &[u8]) -> Vec<u8> {
        let payload: usize = requested.iter().map(|&id| 1 + data_len(id).unwrap()).sum();
        let mut frame = vec![STREAM_HEADER, payload as u8];
        let mut rest = data;
        for &id in requested {
            let (mine, tail) = rest.split_at(data_len(id).unwrap());
            frame.push(id);
            frame.extend_from_slice(mine);
            rest = tail;
        }
        frame.push(checksum_for(&frame));
        frame
    }

    /// The values a frame built by [`frame_with_data`] carries, decoded by the packet table.
    fn values_of(requested: &[u8], data: &[u8]) -> SensorValues {
        let mut values = SensorValues::new();
        let mut rest = data;
        for &id in requested {
            let (mine, tail) = rest.split_at(data_len(id).unwrap());
            decode_data(id, mine, &mut values).unwrap();
            rest = tail;
        }
        values
    }

    /// Independent oracle: does a valid frame for `requested` start at `pos`?
    fn valid_frame_at(stream: &[u8], pos: usize, requested: &[u8]) -> bool {
        let payload: usize = requested.iter().map(|&id| 1 + data_len(id).unwrap()).sum();
        let Some(frame) = stream.get(pos..pos + payload + 3) else {
            return false;
        };
        let mut off = 2;
        let ids_ok = requested.iter().all(|&id| {
            let ok = frame[off] == id;
            off += 1 + data_len(id).unwrap();
            ok
        });
        frame[0] == 19 && usize::from(frame[1]) == payload && ids_ok && byte_sum(frame) == 0
    }

    #[test]
    fn spec_test_vector_parses_even_one_byte_at_a_time() {
        let bytes = [19, 5, 29, 2, 25, 13, 0, 163];
        let mut p = StreamParser::new(&[29, 13]).unwrap();
        let mut got = Vec::new();
        for b in bytes {
            p.feed(&[b], |v| got.push(v));
        }
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].get(29), Some(0x0219));
        assert_eq!(got[0].get(13), Some(0));
        assert_eq!(got[0].iter().count(), 2);
        assert_eq!(
            p.stats(),
            ParserStats {
                good_frames: 1,
                bad_frames: 0,
                implausible_frames: 0,
                skipped_bytes: 0
            }
        );
    }

    #[test]
    fn text_between_frames_is_skipped() {
        let frame = [19, 5, 29, 2, 25, 13, 0, 163];
        let mut stream = b"Roomba by iRobot!\r\n".to_vec();
        stream.extend(frame);
        stream.extend(BAT_LINE);
        stream.extend(frame);
        let mut p = StreamParser::new(&[29, 13]).unwrap();
        assert_eq!(collect(&mut p, &stream).len(), 2);
        let st = p.stats();
        assert_eq!(st.good_frames, 2);
        assert_eq!(st.skipped_bytes as usize, stream.len() - 16);
    }

    #[test]
    fn a_real_frame_starting_inside_a_false_one_is_found() {
        // False candidate at 0 with the right length and ids but a wrong checksum; the real frame starts
        // at byte 6, inside the 8 bytes the false one claims.
        let mut stream = vec![19, 5, 29, 0, 0, 13];
        stream.extend([19, 5, 29, 2, 25, 13, 0, 163]);
        let mut p = StreamParser::new(&[29, 13]).unwrap();
        let got = collect(&mut p, &stream);
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].get(29), Some(537));
        assert_eq!(
            p.stats(),
            ParserStats {
                good_frames: 1,
                bad_frames: 1,
                implausible_frames: 0,
                skipped_bytes: 6
            }
        );
    }

    #[test]
    fn corrupted_frames_commit_nothing() {
        let mut frame = vec![19, 5, 29, 2, 25, 13, 0, 163];
        frame[3] = 3; // data changed, checksum now wrong
        let mut p = StreamParser::new(&[29, 13]).unwrap();
        assert!(collect(&mut p, &frame).is_empty());
        assert_eq!(p.stats().bad_frames, 1);
        assert_eq!(p.stats().good_frames, 0);
    }

    #[test]
    fn group_frames_decode_every_member() {
        let mut v = SensorValues::new();
        for id in 7..=58u8 {
            v.set(id, i32::from(id) * 3);
        }
        v.set(23, -1500);
        let frame = encode_stream_frame(&[100], &v).unwrap();
        let mut p = StreamParser::new(&[100]).unwrap();
        assert_eq!(p.frame_len(), 84);
        let got = collect(&mut p, &frame);
        assert_eq!(got, vec![v]);
    }

    #[test]
    fn feed_newest_returns_only_the_last_frame() {
        let mut stream = Vec::new();
        for value in [100, 200, 300] {
            let mut v = SensorValues::new();
            v.set(29, value);
            v.set(13, 1);
            stream.extend(encode_stream_frame(&[29, 13], &v).unwrap());
        }
        let mut p = StreamParser::new(&[29, 13]).unwrap();
        assert_eq!(p.feed_newest(&stream).and_then(|v| v.get(29)), Some(300));
        assert_eq!(p.stats().good_frames, 3);
        assert_eq!(p.feed_newest(&[19, 5]), None);
    }

    #[test]
    fn reset_drops_a_partial_frame_and_keeps_stats() {
        let frame = [19, 5, 29, 2, 25, 13, 0, 163];
        let mut p = StreamParser::new(&[29, 13]).unwrap();
        collect(&mut p, &frame);
        collect(&mut p, &frame[..4]);
        assert_eq!(p.buffered(), 4);
        p.reset();
        assert_eq!(p.buffered(), 0);
        assert!(collect(&mut p, &frame[4..]).is_empty());
        assert_eq!(collect(&mut p, &frame).len(), 1);
        assert_eq!(p.stats().good_frames, 2);
    }

    #[test]
    fn bad_requests_are_refused() {
        assert_eq!(StreamParser::new(&[]).err(), Some(OiError::EmptyStreamList));
        assert_eq!(
            StreamParser::new(&[13, 3, 102]).err(),
            Some(OiError::UnknownPacket(102))
        );
        assert_eq!(StreamParser::new(&[29, 13]).unwrap().requested(), &[29, 13]);
    }

    #[test]
    fn an_implausible_frame_is_counted_and_a_real_frame_inside_it_is_found() {
        // A frame for [35, 37] whose checksum holds but whose OI mode (138) and song-playing flag (19)
        // are impossible; the real frame starts at its song-playing byte, inside it.
        let fake = [19, 4, 35, 138, 37, 19, 4];
        assert_eq!(byte_sum(&fake), 0);
        let real = [19, 4, 35, 2, 37, 0];
        assert_eq!(&fake[5..], &real[..2]);
        let mut stream = fake.to_vec();
        stream.extend(&real[2..]);
        stream.push(checksum_for(&real));

        let mut plain = StreamParser::new(&[35, 37]).unwrap();
        let got = collect(&mut plain, &stream);
        assert_eq!(got.len(), 1, "without a model the fake frame is committed");
        assert_eq!(got[0].get(35), Some(138));

        let mut checked = StreamParser::new(&[35, 37])
            .unwrap()
            .with_model(Model::Create2);
        assert_eq!(checked.model(), Some(Model::Create2));
        let got = collect(&mut checked, &stream);
        assert_eq!(got.len(), 1);
        assert_eq!(got[0].get(35), Some(2));
        assert_eq!(
            checked.stats(),
            ParserStats {
                good_frames: 1,
                bad_frames: 1,
                implausible_frames: 1,
                skipped_bytes: 5
            }
        );
        let why = checked.last_implausible().unwrap();
        assert_eq!((why.id, why.value, why.max), (35, 138, 4));
    }

    #[test]
    fn odometry_is_bounded_only_in_a_frame_that_directly_follows_an_accepted_one() {
        let frame = |distance: i32| {
            let mut v = SensorValues::new();
            v.set(19, distance);
            v.set(35, 2);
            encode_stream_frame(&[19, 35], &v).unwrap()
        };
        let mut p = StreamParser::new(&[19, 35])
            .unwrap()
            .with_model(Model::Create1);
        // First frame: a long accumulation is plausible.
        assert_eq!(collect(&mut p, &frame(3000)).len(), 1);
        // Directly after it: 3 m in 15 ms is not; 7 mm is.
        assert!(collect(&mut p, &frame(3000)).is_empty());
        assert_eq!(p.stats().implausible_frames, 1);
        assert_eq!(collect(&mut p, &frame(7)).len(), 1);
        assert_eq!(collect(&mut p, &frame(-501)).len(), 0);
        // The rejected frame's bytes were skipped: the next one is a first frame.
        assert_eq!(collect(&mut p, &frame(-3000)).len(), 1);
        assert_eq!(
            collect(&mut p, &frame(-500)).len(),
            1,
            "−500 mm is the bound"
        );
        // After skipped bytes or a reset, the next frame is a first frame again.
        let mut after_text = BAT_LINE.to_vec();
        after_text.extend(frame(-3000));
        assert_eq!(collect(&mut p, &after_text).len(), 1);
        p.reset();
        assert_eq!(collect(&mut p, &frame(3000)).len(), 1);
        assert_eq!(p.stats().implausible_frames, 2);
        assert_eq!(p.stats().good_frames, 6);
    }

    #[test]
    fn a_bound_broken_frame_after_frame_is_waived_as_genuine() {
        let frame = |velocity: i32, mode: i32| {
            let mut v = SensorValues::new();
            v.set(39, velocity);
            v.set(35, mode);
            encode_stream_frame(&[39, 35], &v).unwrap()
        };
        let mut p = StreamParser::new(&[39, 35])
            .unwrap()
            .with_model(Model::Create2);
        // Isolated implausible frames between good ones never add up to a waiver.
        for _ in 0..3 * WAIVE_AFTER {
            assert!(collect(&mut p, &frame(900, 2)).is_empty());
            assert_eq!(collect(&mut p, &frame(100, 2)).len(), 1);
        }
        assert_eq!(p.waived(), Waived::NONE);
        // A run broken by another packet's implausible frame starts afresh.
        for _ in 1..WAIVE_AFTER {
            assert!(collect(&mut p, &frame(900, 2)).is_empty());
        }
        assert!(collect(&mut p, &frame(0, 9)).is_empty());
        for _ in 1..WAIVE_AFTER {
            assert!(collect(&mut p, &frame(900, 2)).is_empty());
        }
        assert_eq!(p.waived(), Waived::NONE);
        // The run's last frame waives 39; the mode is still checked.
        assert!(collect(&mut p, &frame(900, 2)).is_empty());
        assert_eq!(p.waived().ids().collect::<Vec<_>>(), vec![39]);
        assert_eq!(collect(&mut p, &frame(900, 2)).len(), 1);
        assert!(collect(&mut p, &frame(900, 9)).is_empty());
        let st = p.stats();
        assert_eq!(
            st.implausible_frames,
            u64::from(3 * WAIVE_AFTER + 2 * WAIVE_AFTER + 1)
        );
        assert_eq!(st.good_frames, u64::from(3 * WAIVE_AFTER + 1));
    }

    /// Requested lists: 1–4 single packets and/or groups whose frame fits the length byte.
    fn requested() -> impl Strategy<Value = Vec<u8>> {
        let ids: Vec<u8> = (0..=58).chain([100, 101, 106, 107]).collect();
        prop::collection::vec(prop::sample::select(ids), 1..=4)
            .prop_filter("frame fits the length byte", |r| {
                stream_payload_len(r).is_ok()
            })
    }

    /// Raw material for one garbage segment, turned into bytes by [`garbage`].
    fn garbage_seed() -> impl Strategy<Value = (u8, Vec<u8>, usize)> {
        (
            0u8..6,
            prop::collection::vec(any::<u8>(), 0..24),
            any::<usize>(),
        )
    }

    /// Garbage: random bytes, firmware text, truncated or corrupted frames, runs of false headers.
    fn garbage(requested: &[u8], (kind, bytes, cut): &(u8, Vec<u8>, usize)) -> Vec<u8> {
        let data_bytes: usize = requested.iter().map(|&id| data_len(id).unwrap()).sum();
        let data: Vec<u8> = bytes.iter().copied().cycle().take(data_bytes).collect();
        let data = if data.len() == data_bytes {
            data
        } else {
            vec![0; data_bytes]
        };
        let fake = frame_with_data(requested, &data);
        match kind {
            0 => bytes.clone(),
            1 => BAT_LINE.to_vec(),
            2 => fake[..1 + cut % (fake.len() - 1)].to_vec(),
            3 => {
                let mut corrupted = fake;
                let at = cut % corrupted.len();
                corrupted[at] ^= 1 + (*cut / 7 % 255) as u8;
                corrupted
            }
            4 => bytes
                .iter()
                .map(|&b| if b % 2 == 0 { 19 } else { b })
                .collect(),
            _ => vec![19, fake[1]],
        }
    }

    /// A stream of frames with garbage before each and after the last, plus the expected values.
    fn stream_case() -> impl Strategy<Value = (Vec<u8>, Vec<u8>, Vec<SensorValues>, Vec<usize>)> {
        requested().prop_flat_map(|req| {
            let d: usize = req.iter().map(|&id| data_len(id).unwrap()).sum();
            let frames = prop::collection::vec(prop::collection::vec(any::<u8>(), d), 0..8);
            let junk = prop::collection::vec(garbage_seed(), 9);
            (Just(req), frames, junk).prop_map(|(req, frames, junk)| {
                let mut stream = Vec::new();
                let mut expected = Vec::new();
                let mut garbage_positions = Vec::new();
                for (i, seed) in junk.iter().enumerate() {
                    let g = garbage(&req, seed);
                    garbage_positions.extend(stream.len()..stream.len() + g.len());
                    stream.extend(g);
                    if let Some(data) = frames.get(i) {
                        stream.extend(frame_with_data(&req, data));
                        expected.push(values_of(&req, data));
                    }
                }
                (req, stream, expected, garbage_positions)
            })
        })
    }

    fn check_accounting(p: &StreamParser, fed: usize) {
        let st = p.stats();
        assert!(st.skipped_bytes as usize <= fed);
        assert!(p.buffered() < p.frame_len());
        assert_eq!(
            st.skipped_bytes as usize + st.good_frames as usize * p.frame_len() + p.buffered(),
            fed,
            "every byte is skipped, in a good frame, or buffered"
        );
    }

    proptest! {
        #[test]
        fn every_frame_survives_interleaved_garbage((req, stream, expected, junk_at) in stream_case()) {
            // Garbage that happens to hold a complete valid frame would be a real frame; rule it out.
            prop_assume!(junk_at.iter().all(|&pos| !valid_frame_at(&stream, pos, &req)));
            let mut p = StreamParser::new(&req).unwrap();
            let got = collect(&mut p, &stream);
            prop_assert_eq!(&got, &expected);
            prop_assert_eq!(p.stats().good_frames as usize, expected.len());
            check_accounting(&p, stream.len());
        }

        #[test]
        fn chunk_boundaries_do_not_matter((req, stream, _, _) in stream_case(),
                                          cuts in prop::collection::vec(1usize..100, 1..40)) {
            let mut whole = StreamParser::new(&req).unwrap();
            let expected = collect(&mut whole, &stream);
            let mut chunked = StreamParser::new(&req).unwrap();
            let mut got = Vec::new();
            let mut rest = &stream[..];
            for &n in cuts.iter().cycle() {
                if rest.is_empty() {
                    break;
                }
                let (chunk, tail) = rest.split_at(n.min(rest.len()));
                chunked.feed(chunk, |v| got.push(v));
                rest = tail;
            }
            prop_assert_eq!(&got, &expected);
            prop_assert_eq!(chunked.stats(), whole.stats());
            prop_assert_eq!(chunked.buffered(), whole.buffered());
            let mut bytewise = StreamParser::new(&req).unwrap();
            let mut one_by_one = Vec::new();
            for b in &stream {
                bytewise.feed(std::slice::from_ref(b), |v| one_by_one.push(v));
                prop_assert!(bytewise.buffered() < bytewise.frame_len());
            }
            prop_assert_eq!(&one_by_one, &expected);
            prop_assert_eq!(bytewise.stats(), whole.stats());
        }

        #[test]
        fn plausibility_checks_do_not_depend_on_chunking((req, stream, _, _) in stream_case(),
                                                         chunk in 1usize..100,
                                                         create1 in any::<bool>()) {
            let model = if create1 { Model::Create1 } else { Model::Create2 };
            let parser = || StreamParser::new(&req).unwrap().with_model(model);
            let mut whole = parser();
            let expected = collect(&mut whole, &stream);
            let mut plain = StreamParser::new(&req).unwrap();
            let unchecked = collect(&mut plain, &stream);
            let mut chunked = parser();
            let mut got = Vec::new();
            for c in stream.chunks(chunk) {
                chunked.feed(c, |v| got.push(v));
            }
            prop_assert_eq!(&got, &expected);
            prop_assert_eq!(chunked.stats(), whole.stats());
            check_accounting(&whole, stream.len());
            let st = whole.stats();
            prop_assert!(st.implausible_frames <= st.bad_frames);
            // Every committed frame is plausible, and no check ever rejects what it commits.
            for v in &expected {
                prop_assert_eq!(crate::oi::plausible::implausible(v, model, crate::oi::plausible::FrameContext::First), None);
            }
            if st.implausible_frames == 0 {
                prop_assert_eq!(&expected, &unchecked);
            }
        }

        #[test]
        fn random_bytes_never_panic_and_stats_add_up(req in requested(),
                                                      bytes in prop::collection::vec(
                                                          prop_oneof![Just(19u8), Just(5u8), Just(29u8), any::<u8>()],
                                                          0..2000),
                                                      chunk in 1usize..300) {
            let mut p = StreamParser::new(&req).unwrap();
            let mut frames = 0u64;
            for c in bytes.chunks(chunk) {
                p.feed(c, |_| frames += 1);
            }
            prop_assert_eq!(frames, p.stats().good_frames);
            check_accounting(&p, bytes.len());
        }
    }
}

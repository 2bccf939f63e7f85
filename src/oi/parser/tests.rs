//! Unit tests of the stream parser: framing, resynchronisation, chunking, plausibility, statistics.
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

//! Reads an MCAP recording by scanning its records from the start, with the `mcap` crate's linear
//! reader: no footer, summary or index is needed, so a file cut by a kill is read up to its last complete
//! chunk (each chunk's CRC is checked before any of its messages is taken) and reported torn.
//!
//! A file that ends early is torn, never an error; anything damaged before the end (a bad CRC, a record
//! that does not parse, a message that does not decode as its channel's schema) is an error naming it.

use std::collections::{BTreeMap, HashMap};

use mcap::McapError;
use mcap::records::Record;
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use pavlov::config::Config;
use pavlov::event::Event;
use pavlov::obs::ObsLayout;

use super::schema::{CONFIG, EVENTS, LEARNER, METADATA_NAME, TICKS};
use super::{Recording, RecordingError, RecordingHeader, StartState, tick_pb};

/// What the scan collects before the ticks are decoded (they need the configuration's robot model).
#[derive(Default)]
struct Scan {
    topics: HashMap<u16, String>,
    ticks: Vec<Vec<u8>>,
    events: Vec<Vec<u8>>,
    config: Option<Vec<u8>>,
    start: Option<Vec<u8>>,
    metadata: BTreeMap<String, String>,
    torn: bool,
}

impl Scan {
    fn take(&mut self, record: Record<'_>) {
        match record {
            Record::Channel(c) => {
                self.topics.insert(c.id, c.topic);
            }
            Record::Message { header, data } => {
                let Some(topic) = self.topics.get(&header.channel_id) else {
                    return;
                };
                let data = data.into_owned();
                match topic.as_str() {
                    TICKS => self.ticks.push(data),
                    EVENTS => self.events.push(data),
                    CONFIG if self.config.is_none() => self.config = Some(data),
                    LEARNER if self.start.is_none() => self.start = Some(data),
                    _ => {}
                }
            }
            Record::Metadata(m) if m.name == METADATA_NAME => self.metadata = m.metadata,
            _ => {}
        }
    }
}

/// Scans every record of `bytes`.
fn scan(bytes: &[u8]) -> Result<Scan, RecordingError> {
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_validate_chunk_crcs(true)
            .with_prevalidate_chunk_crcs(true),
    );
    let mut fed = 0;
    let mut out = Scan::default();
    while let Some(event) = reader.next_event() {
        match event {
            Ok(LinearReadEvent::ReadRequest(want)) => {
                let n = want.min(bytes.len() - fed);
                reader.insert(n).copy_from_slice(&bytes[fed..fed + n]);
                reader.notify_read(n);
                fed += n;
            }
            Ok(LinearReadEvent::Record { opcode, data }) => {
                let record = mcap::parse_record(opcode, data)
                    .map_err(|e| RecordingError::BadMcap(e.to_string()))?;
                out.take(record);
            }
            // The file ends inside a record, or without its footer: it was cut.
            Err(McapError::UnexpectedEof) => {
                out.torn = true;
                break;
            }
            Err(e) => return Err(RecordingError::BadMcap(e.to_string())),
        }
    }
    Ok(out)
}

fn bad(topic: &str, index: usize, message: impl ToString) -> RecordingError {
    RecordingError::BadMessage {
        topic: topic.to_string(),
        index,
        message: message.to_string(),
    }
}

/// Parses an MCAP recording.
pub fn parse_mcap(bytes: &[u8]) -> Result<Recording, RecordingError> {
    let scan = scan(bytes)?;
    let config: Config = serde_json::from_slice(
        scan.config
            .as_deref()
            .ok_or(RecordingError::Missing("`config` message"))?,
    )
    .map_err(|e| bad(CONFIG, 0, e))?;
    let start: StartState = serde_json::from_slice(
        scan.start
            .as_deref()
            .ok_or(RecordingError::Missing("`learner` message"))?,
    )
    .map_err(|e| bad(LEARNER, 0, e))?;
    let meta = |key: &str| scan.metadata.get(key).cloned().unwrap_or_default();
    let mut header = RecordingHeader::read_back(&config, meta("label"));
    header.format = meta("format");
    header.program = meta("program");
    header.provenance = crate::provenance::Provenance::from_metadata(&header.program, |k| {
        scan.metadata.get(k).cloned()
    });
    header.started_utc = meta("started_utc");
    header.start = Some(start);
    let layout = ObsLayout::for_model(config.robot.model);
    let records = scan
        .ticks
        .iter()
        .enumerate()
        .map(|(i, b)| tick_pb::decode(b, &layout).map_err(|e| bad(TICKS, i, e)))
        .collect::<Result<Vec<_>, _>>()?;
    let events = scan
        .events
        .iter()
        .enumerate()
        .map(|(i, b)| serde_json::from_slice::<Event>(b).map_err(|e| bad(EVENTS, i, e)))
        .collect::<Result<Vec<_>, _>>()?;
    Ok(Recording {
        header,
        records,
        events,
        torn_tail: scan.torn,
    })
}

#[cfg(test)]
mod tests {
    use std::cell::RefCell;
    use std::io::{Seek, SeekFrom, Write};
    use std::rc::Rc;

    use pavlov::agent::LearningStage;
    use pavlov::control::Mode;
    use pavlov::event::EventKind;
    use pavlov::record::{TickInputs, TickRecord};

    use super::*;
    use crate::storage::recording::mcap_write::McapSink;

    fn config() -> Config {
        Config::from_toml(include_str!("../../../../config/stall.toml")).unwrap()
    }

    fn header() -> RecordingHeader {
        let cfg = config();
        let mut h = RecordingHeader::new(&cfg, "unit");
        h.started_utc = "20260101T000000Z".into();
        h.start = Some(StartState {
            after: Some(9),
            events_before: 3,
            learner: LearningStage::new(&cfg).unwrap().stage_snapshot(),
        });
        h
    }

    fn record(seq: u64) -> TickRecord {
        let mut values = pavlov::oi::SensorValues::new();
        values.set(22, 15_000 + seq as i32);
        values.set(14, (seq % 3) as i32);
        let mut obs = Vec::new();
        ObsLayout::for_model(config().robot.model).scale(&values, &mut obs);
        TickRecord {
            obs: obs.into_iter().map(|x| x as f32).collect(),
            inputs: Some(TickInputs {
                values: Some(values),
                forced_stimulus: false,
                previous_followed_default: false,
            }),
            ..TickRecord::at_rest(seq, seq as f64 * 20.0, Mode::Pavlovian)
        }
    }

    /// A file in memory whose length the test can see while the writer holds it (the writer only
    /// appends).
    #[derive(Clone, Default)]
    struct Shared(Rc<RefCell<Vec<u8>>>);

    impl Write for Shared {
        fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
            self.0.borrow_mut().extend_from_slice(buf);
            Ok(buf.len())
        }
        fn flush(&mut self) -> std::io::Result<()> {
            Ok(())
        }
    }

    impl Seek for Shared {
        fn seek(&mut self, pos: SeekFrom) -> std::io::Result<u64> {
            match pos {
                SeekFrom::Current(0) | SeekFrom::End(0) => Ok(self.0.borrow().len() as u64),
                _ => Err(std::io::Error::other(
                    "the recording writer never seeks back",
                )),
            }
        }
    }

    /// A recording of ticks 10..10+n with an event every 7 ticks, a chunk finished every 25 ticks;
    /// returns the finished file and the length of the file after each finished chunk.
    fn write(n: u64) -> (Vec<u8>, Vec<usize>) {
        let file = Shared::default();
        let mut sink = McapSink::create(file.clone(), &header()).unwrap();
        let mut ends = Vec::new();
        for seq in 10..10 + n {
            sink.tick(&record(seq)).unwrap();
            if seq % 7 == 0 {
                let e = Event {
                    id: seq,
                    after: Some(seq),
                    kind: EventKind::WeightsReset,
                };
                sink.event(&e).unwrap();
            }
            if seq % 25 == 0 {
                sink.flush().unwrap();
                ends.push(file.0.borrow().len());
            }
        }
        sink.finish().unwrap();
        let bytes = file.0.borrow().clone();
        (bytes, ends)
    }

    #[test]
    fn a_finished_file_reads_back_whole_with_its_provenance() {
        let (bytes, _) = write(100);
        let rec = parse_mcap(&bytes).unwrap();
        assert!(!rec.torn_tail);
        assert_eq!(rec.records.len(), 100);
        for (i, r) in rec.records.iter().enumerate() {
            let want = record(10 + i as u64);
            assert_eq!(r.inputs, want.inputs);
            let bits = |v: &[f32]| v.iter().map(|x| x.to_bits()).collect::<Vec<_>>();
            assert_eq!(bits(&r.obs), bits(&want.obs), "recomputed exactly");
            assert_eq!(r.seq, want.seq);
        }
        assert_eq!(rec.events.len(), 14);
        assert_eq!(rec.header.format, "pavlov-recording/3");
        let want = RecordingHeader {
            format: rec.header.format.clone(),
            ..header()
        };
        assert!(
            rec.header == want,
            "the header differs from the one written"
        );
    }

    #[test]
    fn a_file_cut_anywhere_after_its_opening_reads_every_complete_chunk_and_is_torn() {
        let (bytes, ends) = write(100);
        let opening = ends.first().copied().unwrap();
        // Cut at every seventh byte after the opening, and at each chunk's end.
        let mut cuts: Vec<usize> = (opening..bytes.len())
            .step_by(7)
            .chain(ends.iter().copied())
            .collect();
        cuts.sort_unstable();
        let mut last = 0;
        for cut in cuts {
            let rec = parse_mcap(&bytes[..cut]).unwrap_or_else(|e| panic!("cut at {cut}: {e}"));
            assert!(rec.torn_tail, "cut at {cut}");
            // The ticks of every chunk that ends before the cut (16 in the first, 25 in each other, the
            // last 9 in the one `finish` writes), and no more.
            let chunks = ends.iter().filter(|&&e| e <= cut).count();
            let flushed = if chunks == 0 {
                0
            } else {
                16 + 25 * (chunks - 1)
            };
            let n = rec.records.len();
            assert!(
                n == flushed || (chunks == ends.len() && n == 100),
                "cut at {cut}: {n} ticks"
            );
            assert!(n >= last, "cut at {cut}: fewer ticks than a shorter cut");
            last = n;
            for (i, r) in rec.records.iter().enumerate() {
                assert_eq!(r.seq, 10 + i as u64);
            }
        }
        assert_eq!(last, 100, "the last chunk is read once it is complete");
    }

    #[test]
    fn damage_before_the_end_is_an_error_and_a_file_without_config_names_what_is_missing() {
        let (bytes, ends) = write(100);
        let mut bad = bytes.clone();
        // Inside the second chunk of ticks: its CRC no longer matches.
        let at = (ends[1] + ends[2]) / 2;
        bad[at] ^= 0x55;
        assert!(
            matches!(parse_mcap(&bad), Err(RecordingError::BadMcap(_))),
            "{:?}",
            parse_mcap(&bad).map(|r| r.records.len())
        );
        // Only the magic and the header record.
        let err = parse_mcap(&bytes[..40]).unwrap_err();
        assert!(err.to_string().contains("no `config` message"), "{err}");
    }
}

//! Writes a recording as MCAP: zstd-compressed chunks, the channels and schemas of [`super::schema`], the
//! provenance in a metadata record. The container is written by [`super::mcap_container`], byte for byte
//! as the `mcap` crate's writer writes it with the options a recording always used (zstd at
//! [`ZSTD_LEVEL`] in chunks of [`CHUNK_SIZE`] finished whole, no message indexes, the full summary; a
//! test here writes a recording both ways and compares them), at a fraction of its cost per message.
//!
//! The opening (magic, header, metadata, the `config` and `learner` messages) is flushed to the file at
//! once, so even a recording killed in its first second names its configuration and start state. After
//! that the writer appends ticks and events to the open chunk; a chunk is finished — compressed and
//! written whole, in one piece, never seeked back into — when it reaches [`CHUNK_SIZE`] or when the owner
//! calls [`McapSink::flush`] (the recorder does at least once a second). So a file cut by a kill holds
//! every chunk finished before it, and a reader that scans it linearly ([`super::mcap_read`]) gets them
//! all. [`McapSink::finish`] adds the summary and footer that indexed readers use.

use std::collections::BTreeMap;
use std::io::{Seek, Write};

use pavlov::event::Event;
use pavlov::record::TickRecord;
use pavlov::record::wire::Message as _;

use super::mcap_container::Container;
use super::schema::{self, CONFIG, EVENTS, LEARNER, TICKS};
use super::{Recording, RecordingHeader, StartState, Step, in_order};

/// The uncompressed size at which a chunk is finished (about 1 700 ticks). Measured on the stall study:
/// against 1 MiB, files 0.3 % larger and about 3 % less CPU for the whole study (zstd's working set
/// stays small beside the runs it shares the cores with).
pub(crate) const CHUNK_SIZE: u64 = 1 << 18;
/// zstd's fastest level: the recorder shares the cores with the runs it records.
pub(crate) const ZSTD_LEVEL: u32 = 1;
/// The profile named in the file's header.
const PROFILE: &str = "pavlov";

/// Why writing failed.
#[derive(Debug, thiserror::Error)]
pub enum McapWriteError {
    /// Writing the file (or compressing a chunk) failed; a recording's writer refuses to go on after
    /// the first failure.
    #[error("I/O error: {0}")]
    Io(#[from] std::io::Error),
    /// A JSON message could not be serialised.
    #[error("cannot serialise the {what}: {source}")]
    Json {
        /// Which message.
        what: &'static str,
        /// The cause.
        source: serde_json::Error,
    },
    /// The header has no start state (the recording has not begun).
    #[error("the recording's start state is not known")]
    NoStart,
    /// The recording's configuration does not build a learner (for its start state).
    #[error("the recording's configuration: {0}")]
    Config(String),
}

/// The channel ids of one file.
struct Channels {
    ticks: u16,
    events: u16,
}

/// An MCAP recording being written.
pub struct McapSink<W: Write + Seek> {
    /// The file; a tick's message is encoded straight into its open chunk (allocating nothing once
    /// warm).
    out: Container<W>,
    channels: Channels,
    /// Nanoseconds per tick, for an event's log time.
    period_ns: u64,
    ticks_written: u32,
    events_written: u32,
    /// Messages written since the last finished chunk.
    pending: bool,
}

fn json(what: &'static str, value: &impl serde::Serialize) -> Result<Vec<u8>, McapWriteError> {
    serde_json::to_vec(value).map_err(|source| McapWriteError::Json { what, source })
}

/// A tick's log time: its scheduled time since the run started, ns.
fn tick_time_ns(t_ms: f64) -> u64 {
    // Non-negative and far below 2⁶⁴ ns (584 years); `as` saturates anyway.
    (t_ms * 1e6).round() as u64
}

/// The provenance as metadata: every value a string, as MCAP metadata requires.
fn provenance(header: &RecordingHeader, start: &StartState) -> BTreeMap<String, String> {
    let opt = |v: Option<u64>| v.map_or_else(String::new, |v| v.to_string());
    let provenance = header
        .provenance
        .as_ref()
        .map(|p| p.to_metadata())
        .unwrap_or_default();
    [
        ("format", schema::MCAP_FORMAT.to_string()),
        ("program", header.program.clone()),
        ("label", header.label.clone()),
        ("started_utc", header.started_utc.clone()),
        ("seed", header.config.sim.seed.to_string()),
        ("robot_model", header.config.robot.model.to_string()),
        ("start_after", opt(start.after)),
        ("events_before", start.events_before.to_string()),
        ("obs_names", header.obs_names.join(",")),
    ]
    .into_iter()
    .chain(provenance)
    .map(|(k, v)| (k.to_string(), v))
    .collect()
}

impl<W: Write + Seek> McapSink<W> {
    /// Opens a recording on `out` for `header` (which must carry its start state), and writes and
    /// flushes its opening.
    pub fn create(mut out: W, header: &RecordingHeader) -> Result<Self, McapWriteError> {
        let start = header.start.as_ref().ok_or(McapWriteError::NoStart)?;
        let position = out.stream_position()?;
        // The `mcap` crate's writer names itself in the header; the files are the ones it writes.
        let mut out = Container::create(
            out,
            position,
            PROFILE,
            mcap::LIBRARY_IDENTIFIER,
            CHUNK_SIZE,
            ZSTD_LEVEL as i32,
        )?;
        let tick_schema = out.add_schema(
            schema::TICK_SCHEMA_NAME,
            "protobuf",
            schema::TICK_DESCRIPTOR_SET.as_slice(),
        )?;
        let event_schema = out.add_schema(
            "pavlov.Event",
            "jsonschema",
            schema::EVENT_SCHEMA.as_bytes(),
        )?;
        let config_schema = out.add_schema(
            "pavlov.Config",
            "jsonschema",
            schema::CONFIG_SCHEMA.as_bytes(),
        )?;
        let learner_schema = out.add_schema(
            "pavlov.StartState",
            "jsonschema",
            schema::LEARNER_SCHEMA.as_bytes(),
        )?;
        let config = out.add_channel(config_schema, CONFIG, "json")?;
        let learner = out.add_channel(learner_schema, LEARNER, "json")?;
        let ticks = out.add_channel(tick_schema, TICKS, "protobuf")?;
        let events = out.add_channel(event_schema, EVENTS, "json")?;
        out.write_metadata(schema::METADATA_NAME, &provenance(header, start))?;
        let period_ns = header.config.tick.period_ms.saturating_mul(1_000_000);
        // The first recorded tick's time.
        let t0 = start.after.map_or(0, |a| a.saturating_add(1)) * period_ns;
        for (channel, data) in [
            (config, json("configuration", &header.config)?),
            (learner, json("start state", start)?),
        ] {
            out.message(channel, 0, t0, t0, |buf| buf.extend_from_slice(&data))?;
        }
        out.flush()?;
        Ok(McapSink {
            out,
            channels: Channels { ticks, events },
            period_ns,
            ticks_written: 0,
            events_written: 0,
            pending: false,
        })
    }

    /// Appends a tick.
    pub fn tick(&mut self, record: &TickRecord) -> Result<(), McapWriteError> {
        let t = tick_time_ns(record.t_ms);
        self.out
            .message(self.channels.ticks, self.ticks_written, t, t, |buf| {
                record.encode_to(buf)
            })?;
        self.ticks_written = self.ticks_written.wrapping_add(1);
        self.pending = true;
        Ok(())
    }

    /// Appends an event; its log time is that of the tick it applies from.
    pub(crate) fn event(&mut self, event: &Event) -> Result<(), McapWriteError> {
        let data = json("event", event)?;
        let t = event.after.map_or(0, |a| a.saturating_add(1)) * self.period_ns;
        self.out
            .message(self.channels.events, self.events_written, t, t, |buf| {
                buf.extend_from_slice(&data)
            })?;
        self.events_written = self.events_written.wrapping_add(1);
        self.pending = true;
        Ok(())
    }

    /// Whether messages were written since the last finished chunk.
    pub(crate) fn pending(&self) -> bool {
        self.pending
    }

    /// Finishes the open chunk and hands it to the file.
    pub(crate) fn flush(&mut self) -> Result<(), McapWriteError> {
        if self.pending {
            self.out.flush()?;
            self.pending = false;
        }
        Ok(())
    }

    /// Finishes the file (the last chunk, the summary and the footer) and returns what it was written to.
    pub(crate) fn finish(self) -> Result<W, McapWriteError> {
        Ok(self.out.finish()?)
    }
}

/// Writes a whole recording read back (e.g. from JSON Lines) as MCAP on `out`, each event after the
/// tick it follows. A recording from before start states were recorded begins with the run, so its start
/// state is the configuration's initial learner.
pub fn write_recording<W: Write + Seek>(rec: &Recording, out: W) -> Result<W, McapWriteError> {
    let mut header = rec.header.clone();
    if header.start.is_none() {
        let stage = pavlov::agent::LearningStage::new(&header.config)
            .map_err(|e| McapWriteError::Config(e.to_string()))?;
        header.start = Some(StartState {
            after: None,
            events_before: 0,
            learner: stage.stage_snapshot(),
        });
    }
    let mut sink = McapSink::create(out, &header)?;
    for step in in_order(rec) {
        match step {
            Step::Tick(r) => sink.tick(r)?,
            Step::Event(e) => sink.event(e)?,
        }
    }
    sink.finish()
}

#[cfg(test)]
mod tests {
    use std::io::Cursor;

    use mcap::records::{MessageHeader, Metadata};
    use mcap::{Compression, WriteOptions};
    use pavlov::agent::LearningStage;
    use pavlov::config::Config;
    use pavlov::event::EventKind;

    use super::*;
    use crate::storage::recording::tick_pb::TickEncoder;
    use crate::storage::recording::tick_pb::tests::records;

    fn header(after: Option<u64>) -> RecordingHeader {
        let cfg = Config::from_toml(include_str!("../../../../config/stall.toml")).unwrap();
        let mut h = RecordingHeader::new(&cfg, "unit");
        h.started_utc = "20260101T000000Z".into();
        h.start = Some(StartState {
            after,
            events_before: 3,
            learner: LearningStage::new(&cfg).unwrap().stage_snapshot(),
        });
        h
    }

    /// What a recording is made of, in order.
    enum Step {
        Tick(Box<TickRecord>),
        Event(Event),
        Flush,
    }

    /// The recording as the `mcap` crate's writer wrote it with the same options (the recorder's
    /// writer before `mcap_container`).
    fn with_the_mcap_crate(header: &RecordingHeader, steps: &[Step]) -> Vec<u8> {
        let start = header.start.as_ref().unwrap();
        let options = WriteOptions::new()
            .compression(Some(Compression::Zstd))
            .compression_level(ZSTD_LEVEL)
            .compression_threads(0)
            .chunk_size(Some(CHUNK_SIZE))
            .disable_seeking(true)
            .emit_message_indexes(false)
            .profile("pavlov");
        let mut out = options.create(Cursor::new(Vec::new())).unwrap();
        let tick_schema = out
            .add_schema(
                schema::TICK_SCHEMA_NAME,
                "protobuf",
                schema::TICK_DESCRIPTOR_SET.as_slice(),
            )
            .unwrap();
        let event_schema = out
            .add_schema(
                "pavlov.Event",
                "jsonschema",
                schema::EVENT_SCHEMA.as_bytes(),
            )
            .unwrap();
        let config_schema = out
            .add_schema(
                "pavlov.Config",
                "jsonschema",
                schema::CONFIG_SCHEMA.as_bytes(),
            )
            .unwrap();
        let learner_schema = out
            .add_schema(
                "pavlov.StartState",
                "jsonschema",
                schema::LEARNER_SCHEMA.as_bytes(),
            )
            .unwrap();
        let none = BTreeMap::new();
        let config = out
            .add_channel(config_schema, CONFIG, "json", &none)
            .unwrap();
        let learner = out
            .add_channel(learner_schema, LEARNER, "json", &none)
            .unwrap();
        let ticks = out
            .add_channel(tick_schema, TICKS, "protobuf", &none)
            .unwrap();
        let events = out
            .add_channel(event_schema, EVENTS, "json", &none)
            .unwrap();
        out.write_metadata(&Metadata {
            name: schema::METADATA_NAME.to_string(),
            metadata: provenance(header, start),
        })
        .unwrap();
        let period_ns = header.config.tick.period_ms * 1_000_000;
        let t0 = start.after.map_or(0, |a| a + 1) * period_ns;
        let message = |channel_id, sequence, t| MessageHeader {
            channel_id,
            sequence,
            log_time: t,
            publish_time: t,
        };
        out.write_to_known_channel(
            &message(config, 0, t0),
            &json("configuration", &header.config).unwrap(),
        )
        .unwrap();
        out.write_to_known_channel(
            &message(learner, 0, t0),
            &json("start state", start).unwrap(),
        )
        .unwrap();
        out.flush().unwrap();
        let mut encoder = TickEncoder::default();
        let (mut n_ticks, mut n_events) = (0u32, 0u32);
        for step in steps {
            match step {
                Step::Tick(r) => {
                    let t = tick_time_ns(r.t_ms);
                    out.write_to_known_channel(&message(ticks, n_ticks, t), encoder.encode(r))
                        .unwrap();
                    n_ticks += 1;
                }
                Step::Event(e) => {
                    let t = e.after.map_or(0, |a| a + 1) * period_ns;
                    out.write_to_known_channel(
                        &message(events, n_events, t),
                        &json("event", e).unwrap(),
                    )
                    .unwrap();
                    n_events += 1;
                }
                Step::Flush => out.flush().unwrap(),
            }
        }
        out.finish().unwrap();
        out.into_inner().into_inner()
    }

    fn with_the_sink(header: &RecordingHeader, steps: &[Step]) -> Vec<u8> {
        let mut sink = McapSink::create(Cursor::new(Vec::new()), header).unwrap();
        for step in steps {
            match step {
                Step::Tick(r) => sink.tick(r).unwrap(),
                Step::Event(e) => sink.event(e).unwrap(),
                Step::Flush => {
                    sink.pending = true;
                    sink.flush().unwrap();
                }
            }
        }
        sink.finish().unwrap().into_inner()
    }

    /// `n` ticks cycling through records that use every field, with events and flushes between them.
    fn steps(n: u64) -> Vec<Step> {
        let records = records();
        let mut steps = Vec::new();
        for k in 0..n {
            let mut r = records[(k % records.len() as u64) as usize].clone();
            r.seq = 100 + k;
            r.t_ms = r.seq as f64 * 20.0;
            steps.push(Step::Tick(Box::new(r)));
            if k % 97 == 5 {
                steps.push(Step::Event(Event {
                    id: k,
                    after: Some(100 + k),
                    kind: EventKind::WeightsReset,
                }));
            }
            if k % 1_500 == 700 {
                steps.push(Step::Flush);
            }
        }
        steps
    }

    #[test]
    fn the_file_is_the_one_the_mcap_crate_writes_byte_for_byte() {
        // Several full chunks (of two zstd blocks and more), flushed ones, events, and a last chunk
        // finished by `finish`; then a recording without ticks, and one that began mid-run.
        for (after, n) in [(None, 6_000), (None, 0), (Some(41), 3)] {
            let h = header(after);
            let steps = steps(n);
            let ours = with_the_sink(&h, &steps);
            let theirs = with_the_mcap_crate(&h, &steps);
            assert_eq!(ours.len(), theirs.len(), "{n} ticks");
            assert!(ours == theirs, "{n} ticks: the files differ");
            let summary = mcap::Summary::read(&ours).unwrap().expect("a summary");
            // The opening's two chunks, then the ticks': several full ones and flushed ones.
            let chunks = summary.chunk_indexes.len();
            assert!(n < 6_000 || chunks >= 8, "{chunks} chunks");
        }
    }

    #[test]
    fn a_file_dropped_unfinished_is_finished_and_a_failed_one_is_left_as_it_is() {
        let h = header(None);
        use std::cell::{Cell, RefCell};
        use std::rc::Rc;
        /// A file in memory, and whether its disk is full.
        struct Shared(Rc<RefCell<Vec<u8>>>, Rc<Cell<bool>>);
        impl Write for Shared {
            fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
                if self.1.get() {
                    return Err(std::io::Error::from_raw_os_error(28));
                }
                self.0.borrow_mut().extend_from_slice(buf);
                Ok(buf.len())
            }
            fn flush(&mut self) -> std::io::Result<()> {
                Ok(())
            }
        }
        impl Seek for Shared {
            fn seek(&mut self, _: std::io::SeekFrom) -> std::io::Result<u64> {
                Ok(self.0.borrow().len() as u64)
            }
        }
        let steps = steps(50);
        let shared = Rc::new(RefCell::new(Vec::new()));
        let mut sink = McapSink::create(Shared(shared.clone(), Rc::default()), &h).unwrap();
        for step in &steps {
            if let Step::Tick(r) = step {
                sink.tick(r).unwrap();
            }
        }
        drop(sink);
        let dropped = shared.borrow().clone();
        let only_ticks: Vec<Step> = steps
            .into_iter()
            .filter(|s| matches!(s, Step::Tick(_)))
            .collect();
        assert!(dropped == with_the_mcap_crate(&h, &only_ticks));

        // A file whose disk is full: the error is the OS's, and nothing is written after it.
        let full = Rc::new(RefCell::new(Vec::new()));
        let no_room = Rc::new(Cell::new(false));
        let mut sink = McapSink::create(Shared(full.clone(), no_room.clone()), &h).unwrap();
        let opened = full.borrow().len();
        no_room.set(true);
        for step in &only_ticks {
            if let Step::Tick(r) = step {
                sink.tick(r).unwrap();
            }
        }
        sink.pending = true;
        let err = sink.flush().unwrap_err();
        assert!(err.to_string().contains("No space left on device"), "{err}");
        // The disk has room again, but the recording stopped at its error.
        no_room.set(false);
        assert!(
            sink.tick(match &only_ticks[0] {
                Step::Tick(r) => r,
                _ => unreachable!(),
            })
            .is_err()
        );
        assert!(sink.finish().is_err());
        assert_eq!(full.borrow().len(), opened);
    }
}

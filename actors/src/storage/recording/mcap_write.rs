//! Writes a recording as MCAP with the `mcap` crate: zstd-compressed chunks, the channels and schemas of
//! [`super::schema`], the provenance in a metadata record.
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

use mcap::records::{MessageHeader, Metadata};
use mcap::{Compression, WriteOptions};
use pavlov::event::Event;
use pavlov::record::TickRecord;

use super::schema::{self, CONFIG, EVENTS, LEARNER, TICKS};
use super::tick_pb::TickEncoder;
use super::{Recording, RecordingHeader, StartState, Step, in_order};

/// The uncompressed size at which a chunk is finished (about 1 700 ticks). Measured on the stall study:
/// against 1 MiB, files 0.3 % larger and about 3 % less CPU for the whole study (zstd's working set
/// stays small beside the runs it shares the cores with).
pub(crate) const CHUNK_SIZE: u64 = 1 << 18;
/// zstd's fastest level: the recorder shares the cores with the runs it records.
pub(crate) const ZSTD_LEVEL: u32 = 1;

/// Why writing failed.
#[derive(Debug, thiserror::Error)]
pub enum McapWriteError {
    /// The MCAP writer (or the file under it) failed.
    #[error("{0}")]
    Mcap(#[from] mcap::McapError),
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
    out: mcap::Writer<W>,
    channels: Channels,
    /// Nanoseconds per tick, for an event's log time.
    period_ns: u64,
    /// Encodes the tick messages (allocating nothing once warm).
    encoder: TickEncoder,
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
    pub fn create(out: W, header: &RecordingHeader) -> Result<Self, McapWriteError> {
        let start = header.start.as_ref().ok_or(McapWriteError::NoStart)?;
        let options = WriteOptions::new()
            .compression(Some(Compression::Zstd))
            .compression_level(ZSTD_LEVEL)
            // Compress on the recorder's own thread: zstd's worker threads would compete with the runs.
            .compression_threads(0)
            .chunk_size(Some(CHUNK_SIZE))
            // A chunk is written whole when finished, so a kill never leaves one half-described.
            .disable_seeking(true)
            // The chunk index in the summary is enough to seek; per-message indexes would cost 16
            // uncompressed bytes a tick.
            .emit_message_indexes(false)
            .profile("pavlov");
        let mut out = options.create(out)?;
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
        let none = BTreeMap::new();
        let config = out.add_channel(config_schema, CONFIG, "json", &none)?;
        let learner = out.add_channel(learner_schema, LEARNER, "json", &none)?;
        let ticks = out.add_channel(tick_schema, TICKS, "protobuf", &none)?;
        let events = out.add_channel(event_schema, EVENTS, "json", &none)?;
        out.write_metadata(&Metadata {
            name: schema::METADATA_NAME.to_string(),
            metadata: provenance(header, start),
        })?;
        let period_ns = header.config.tick.period_ms.saturating_mul(1_000_000);
        // The first recorded tick's time.
        let t0 = start.after.map_or(0, |a| a.saturating_add(1)) * period_ns;
        for (channel, data) in [
            (config, json("configuration", &header.config)?),
            (learner, json("start state", start)?),
        ] {
            out.write_to_known_channel(
                &MessageHeader {
                    channel_id: channel,
                    sequence: 0,
                    log_time: t0,
                    publish_time: t0,
                },
                &data,
            )?;
        }
        out.flush()?;
        Ok(McapSink {
            out,
            channels: Channels { ticks, events },
            period_ns,
            encoder: TickEncoder::default(),
            ticks_written: 0,
            events_written: 0,
            pending: false,
        })
    }

    /// Appends a tick.
    pub fn tick(&mut self, record: &TickRecord) -> Result<(), McapWriteError> {
        let data = self.encoder.encode(record);
        let t = tick_time_ns(record.t_ms);
        self.out.write_to_known_channel(
            &MessageHeader {
                channel_id: self.channels.ticks,
                sequence: self.ticks_written,
                log_time: t,
                publish_time: t,
            },
            data,
        )?;
        self.ticks_written = self.ticks_written.wrapping_add(1);
        self.pending = true;
        Ok(())
    }

    /// Appends an event; its log time is that of the tick it applies from.
    pub(crate) fn event(&mut self, event: &Event) -> Result<(), McapWriteError> {
        let data = json("event", event)?;
        let t = event.after.map_or(0, |a| a.saturating_add(1)) * self.period_ns;
        self.out.write_to_known_channel(
            &MessageHeader {
                channel_id: self.channels.events,
                sequence: self.events_written,
                log_time: t,
                publish_time: t,
            },
            &data,
        )?;
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
    pub(crate) fn finish(mut self) -> Result<W, McapWriteError> {
        self.out.finish()?;
        let mut inner = self.out.into_inner();
        inner.flush().map_err(mcap::McapError::from)?;
        Ok(inner)
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

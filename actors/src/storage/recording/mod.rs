//! Recordings: what they hold, and reading them back from either of their two formats.
//!
//! A recording is a run's header ([`RecordingHeader`]: the program's version, a free label, the
//! configuration in force, the observation names, when it began and where the run stood then —
//! [`StartState`]: the last tick before it and the learner's complete state), its tick records
//! ([`TickRecord`]) and the changes made at run time ([`Event`]). So a recording replays from its first
//! tick wherever it was started from.
//!
//! - **MCAP** (`recording.mcap`, what the recorder writes): zstd-compressed chunks, one channel per kind
//!   of message (`ticks` in protobuf, `events`, `config`, `learner` in JSON), the provenance in a metadata
//!   record ([`schema`], `mcap_write`). Foxglove, the `mcap` CLI and the `mcap` Python package open it.
//!   A file cut by a kill is read up to its last complete chunk and reported torn (`mcap_read`).
//! - **JSON Lines** (`ticks.jsonl`, what earlier versions wrote, and what `pavlov convert --to jsonl`
//!   makes for `jq` and `pandas`): a header line, then one tick or `{"event": …}` per line ([`jsonl`]).
//!
//! [`load`] tells the two apart by content (MCAP files begin with its magic bytes). Reading is
//! synchronous and pure apart from the file read.

use std::path::{Path, PathBuf};

use pavlov::config::Config;
use pavlov::event::Event;
use pavlov::record::TickRecord;
use serde::{Deserialize, Serialize};

use crate::provenance::Provenance;

mod bounded_file;
pub(crate) mod finish;
pub mod jsonl;
mod mcap_container;
mod mcap_fields;
mod mcap_read;
mod mcap_scan;
pub(crate) mod mcap_write;
pub mod schema;
mod tick_descriptor;
pub(crate) mod tick_pb;

/// What the recording benchmark (`cargo bench -p pavlov-actors --bench recording`) measures: a tick's
/// protobuf encoding alone, and a whole MCAP tick write (encoding, framing, zstd, CRC).
#[doc(hidden)]
pub mod bench_support {
    pub use super::mcap_write::McapSink;
    pub use super::tick_pb::TickEncoder;
}

pub use bounded_file::MAX_FILE;
pub use jsonl::parse;
pub use mcap_read::parse_mcap;
pub use mcap_scan::{
    MAX_CHUNK, MAX_RATIO, MAX_RECORD, MAX_WINDOW_LOG, Place, RATIO_ALLOWANCE, decompression_budget,
};
pub use mcap_write::{McapWriteError, write_recording};
pub use tick_pb::TickDecodeError;

/// The format of recordings this code writes, in both encodings: MCAP's metadata `format` key and the
/// JSON Lines header's `format` field. Version 3 added the MCAP encoding and the provenance
/// ([`Provenance`]); a JSON Lines file of version 2 (no provenance) still reads.
pub(crate) const FORMAT: &str = "pavlov-recording/3";

/// The JSON Lines format before provenance, still read.
pub(crate) const FORMAT_2: &str = "pavlov-recording/2";

/// Where the run stood when a recording began (it travels through the recorder's queue, so it lives on
/// the bus).
pub use crate::bus::recorder_queue::StartState;

/// The file the recorder writes inside a recording's directory.
pub const MCAP_FILE: &str = "recording.mcap";
/// The JSON Lines file inside a recording's directory (older recordings, `pavlov convert --to jsonl`).
pub const TICKS_FILE: &str = "ticks.jsonl";

/// What a recording says about itself (in MCAP: the metadata record and the `config` and `learner`
/// messages; in JSON Lines: the first line).
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordingHeader {
    /// The format tag ([`FORMAT`] in JSON Lines).
    pub(crate) format: String,
    /// The program that wrote it (`pavlov <version> (<commit>[, dirty])`; older recordings:
    /// `pavlov <version>`).
    #[serde(default)]
    pub program: String,
    /// The build and invocation that wrote it (`None`: a recording older than format 3).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub provenance: Option<Provenance>,
    /// A free label (e.g. the experiment run), empty if none.
    #[serde(default)]
    pub label: String,
    /// The configuration in force (its `[sim] seed` is the run's seed), its secrets redacted.
    pub config: Config,
    /// Names of the `obs` vector's dimensions, in order.
    pub(crate) obs_names: Vec<String>,
    /// When the recording began, UTC (`20261124T013000Z`).
    #[serde(default)]
    pub started_utc: String,
    /// Where the run stood when the recording began.
    #[serde(default)]
    pub start: Option<StartState>,
}

impl RecordingHeader {
    /// A header for a run of `config` by this process (its provenance; the configuration with its
    /// secrets redacted), with the observation names of its robot model; the recorder fills in when and
    /// from what state the recording starts.
    pub fn new(config: &Config, label: impl Into<String>) -> Self {
        let provenance = Provenance::of(config);
        RecordingHeader {
            program: provenance.program.clone(),
            provenance: Some(provenance),
            ..Self::read_back(config, label)
        }
    }

    /// A header as read back from a file: no provenance until the reader finds one.
    pub(crate) fn read_back(config: &Config, label: impl Into<String>) -> Self {
        let layout = pavlov::obs::ObsLayout::for_model(config.robot.model);
        RecordingHeader {
            format: FORMAT.to_string(),
            program: String::new(),
            provenance: None,
            label: label.into(),
            config: config.redacted(),
            obs_names: layout.names().map(str::to_string).collect(),
            started_utc: String::new(),
            start: None,
        }
    }
}

/// A recording read back.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    /// What the recording says about itself.
    pub header: RecordingHeader,
    /// Every complete tick record, in file order.
    pub records: Vec<TickRecord>,
    /// Every event, in file order.
    pub events: Vec<Event>,
    /// True when the file ends early (the writer was killed): a torn last line of JSON Lines, or an
    /// MCAP file without its footer, of which every complete chunk was read.
    pub torn_tail: bool,
}

/// Why a recording could not be read.
#[derive(Debug, thiserror::Error)]
pub enum RecordingError {
    /// The file could not be read.
    #[error("cannot read {path}: {source}")]
    Io {
        /// The file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The file has no header line.
    #[error("empty recording: no header line")]
    Empty,
    /// The header line is not a recording header.
    #[error("line 1 is not a {FORMAT} header: {0}")]
    BadHeader(String),
    /// A line before the last one is not a tick record or an event.
    #[error("line {line}: not a tick record or an event: {message}")]
    BadRecord {
        /// 1-based line number.
        line: usize,
        /// The parser's message.
        message: String,
    },
    /// The MCAP container is damaged before its end (not merely cut short).
    #[error("not a readable MCAP file: {0}")]
    BadMcap(String),
    /// A record of the MCAP file is malformed: a field runs past its record, a CRC does not match, a
    /// chunk does not inflate.
    #[error("the MCAP record at {at} (opcode 0x{opcode:02x}): {message}")]
    Malformed {
        /// Where it begins.
        at: Place,
        /// Its opcode.
        opcode: u8,
        /// What is wrong with it.
        message: String,
    },
    /// A record claims a length no file of ours holds.
    #[error(
        "the MCAP record at {at} (opcode 0x{opcode:02x}) claims {claimed} bytes; at most {allowed} are allowed there"
    )]
    RecordTooLarge {
        /// Where it begins.
        at: Place,
        /// Its opcode.
        opcode: u8,
        /// The length it claims.
        claimed: u64,
        /// The most it may claim there ([`MAX_RECORD`] in the file, what is left inside a chunk).
        allowed: u64,
    },
    /// A chunk claims more uncompressed bytes than any chunk may.
    #[error(
        "the MCAP chunk at {at} claims {claimed} bytes uncompressed; at most {allowed} are allowed"
    )]
    ChunkTooLarge {
        /// Where it begins.
        at: Place,
        /// Its claimed uncompressed size.
        claimed: u64,
        /// [`MAX_CHUNK`].
        allowed: u64,
    },
    /// The chunks claim more uncompressed bytes than the file's length allows.
    #[error(
        "the MCAP chunk at {at} claims {claimed} bytes uncompressed, but only {left} of the file's \
         {allowed} are left ({MAX_RATIO} times its length plus {RATIO_ALLOWANCE}: a decompression bomb?)"
    )]
    DecompressionBudget {
        /// Where it begins.
        at: Place,
        /// Its claimed uncompressed size.
        claimed: u64,
        /// What the chunks before it left of the budget.
        left: u64,
        /// The whole file's budget ([`decompression_budget`]).
        allowed: u64,
    },
    /// A chunk inflates to more than it claims.
    #[error(
        "the MCAP chunk at {at} inflates to more than the {claimed} bytes it claims (a decompression bomb?)"
    )]
    Inflates {
        /// Where it begins.
        at: Place,
        /// Its claimed uncompressed size.
        claimed: u64,
    },
    /// The file holds more messages than its length allows.
    #[error(
        "the MCAP message at {at} is one too many: a file of {allowed} bytes may hold {allowed} \
         messages, one a byte (the recorder writes about 50 bytes a tick)"
    )]
    TooManyMessages {
        /// Where the first message too many begins.
        at: Place,
        /// The file's length, and so the most messages it may hold.
        allowed: usize,
    },
    /// The file is larger than any recording read whole.
    #[error("{path} is {size} bytes; recordings over {allowed} bytes are not read")]
    TooLarge {
        /// The file.
        path: PathBuf,
        /// Its size (at least; a file still growing may be larger).
        size: u64,
        /// [`MAX_FILE`].
        allowed: u64,
    },
    /// The path is not a regular file (a FIFO, a device, a socket).
    #[error("{path} is {kind}, not a regular file: recordings are read only from regular files")]
    NotAFile {
        /// The path.
        path: PathBuf,
        /// What it is.
        kind: &'static str,
    },
    /// A message does not decode as its channel's schema.
    #[error("message {index} on channel `{topic}`: {message}")]
    BadMessage {
        /// The channel.
        topic: String,
        /// 0-based position among that channel's messages.
        index: usize,
        /// The decoder's message.
        message: String,
    },
    /// The MCAP file lacks a part every recording has.
    #[error("the MCAP file has no {0} (is it a pavlov recording, cut before its first second?)")]
    Missing(&'static str),
}

/// The recording file for `path`: the path itself if it is a file; in a directory, `recording.mcap`, or
/// `ticks.jsonl` when there is no MCAP file.
pub fn recording_file(path: &Path) -> PathBuf {
    if path.is_dir() {
        let mcap = path.join(MCAP_FILE);
        let jsonl = path.join(TICKS_FILE);
        if !mcap.exists() && jsonl.exists() {
            jsonl
        } else {
            mcap
        }
    } else {
        path.to_path_buf()
    }
}

/// Whether `bytes` begin like an MCAP file.
pub fn is_mcap(bytes: &[u8]) -> bool {
    bytes.starts_with(mcap::MAGIC)
}

/// Reads a recording from its bytes, MCAP or JSON Lines. No length an MCAP file states is trusted: records
/// over [`MAX_RECORD`], chunks claiming over [`MAX_CHUNK`] uncompressed or more than the file's
/// [`decompression_budget`], chunks inflating past their claim and files holding more messages than bytes
/// are refused with an error naming the place, the claim and the limit; any input gives `Ok` or `Err`,
/// never a panic.
pub fn from_bytes(bytes: &[u8]) -> Result<Recording, RecordingError> {
    if is_mcap(bytes) {
        parse_mcap(bytes)
    } else {
        // A torn multi-byte character can only be at the very end: keep the valid prefix, and the
        // parser reports the torn line.
        let text = match std::str::from_utf8(bytes) {
            Ok(t) => t,
            Err(e) if e.error_len().is_none() => {
                std::str::from_utf8(&bytes[..e.valid_up_to()]).unwrap_or_default()
            }
            Err(e) => {
                return Err(RecordingError::BadRecord {
                    line: bytes[..e.valid_up_to()]
                        .iter()
                        .filter(|&&b| b == b'\n')
                        .count()
                        + 1,
                    message: e.to_string(),
                });
            }
        };
        parse(text)
    }
}

/// Reads a recording from a file or a recording directory, in either format: only a regular file of at
/// most [`MAX_FILE`] bytes (`bounded_file`).
pub fn load(path: &Path) -> Result<Recording, RecordingError> {
    from_bytes(&bounded_file::read(&recording_file(path))?)
}

/// One step of a recording in the order it happened.
#[derive(Debug, Clone, Copy)]
pub(crate) enum Step<'a> {
    /// A tick.
    Tick(&'a TickRecord),
    /// An event.
    Event(&'a Event),
}

/// The ticks and events of `rec` in the order they happened: each event (in id order) just before the
/// first tick it applies to.
pub(crate) fn in_order(rec: &Recording) -> impl Iterator<Item = Step<'_>> {
    let mut events: Vec<&Event> = rec.events.iter().collect();
    events.sort_by_key(|e| e.id);
    let mut events = events.into_iter().peekable();
    let mut out = Vec::with_capacity(rec.records.len() + rec.events.len());
    for r in &rec.records {
        while let Some(e) = events.next_if(|e| e.after.is_none_or(|a| a < r.seq)) {
            out.push(Step::Event(e));
        }
        out.push(Step::Tick(r));
    }
    out.extend(events.map(Step::Event));
    out.into_iter()
}

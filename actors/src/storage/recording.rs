//! The recording format (JSON Lines) and its reader.
//!
//! A recording is one file, `ticks.jsonl`: a header line ([`RecordingHeader`]: format tag, the program's
//! version, a free label, the configuration in force, the observation names, and where the run stood when
//! the recording began — [`StartState`]: the last tick before it, and the learner's complete state then)
//! followed by one [`TickRecord`] per line and, between them, `{"event": …}` lines for every change made
//! at run time ([`Event`]). So a recording replays from its first tick wherever it was started from. A
//! process killed mid-write leaves at most a torn last line, which the reader skips and reports
//! ([`Recording::torn_tail`]); a bad line anywhere else is an error naming the line.
//!
//! Reading is synchronous and pure apart from the file read in [`load`].

use std::path::{Path, PathBuf};

use pavlov::agent::StageSnapshot;
use pavlov::config::Config;
use pavlov::event::Event;
use pavlov::record::TickRecord;
use serde::{Deserialize, Serialize};

/// The format tag of the header line.
pub(crate) const FORMAT: &str = "pavlov-recording/2";

/// Where the run stood when a recording began.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StartState {
    /// The last tick the learner had handled (`None`: the recording begins with the run); the recording
    /// holds the ticks after it.
    pub after: Option<u64>,
    /// Events with a smaller id happened before the recording (the learner's state includes them).
    pub events_before: u64,
    /// The learner's complete state: weights, traces, parameters in force, previous step, stall level.
    pub learner: StageSnapshot,
}

/// The file name of a recording inside its directory.
pub const TICKS_FILE: &str = "ticks.jsonl";

/// The first line of a recording.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct RecordingHeader {
    /// Always [`FORMAT`].
    pub(crate) format: String,
    /// The program that wrote it (`pavlov <version>`).
    #[serde(default)]
    pub program: String,
    /// A free label (e.g. the experiment run), empty if none.
    #[serde(default)]
    pub label: String,
    /// The configuration in force (its `[sim] seed` is the run's seed).
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
    /// A header for a run of `config`, with the observation names of its robot model; the recorder
    /// fills in when and from what state the recording starts.
    pub fn new(config: &Config, label: impl Into<String>) -> Self {
        let layout = pavlov::obs::ObsLayout::for_model(config.robot.model);
        RecordingHeader {
            format: FORMAT.to_string(),
            program: concat!("pavlov ", env!("CARGO_PKG_VERSION")).to_string(),
            label: label.into(),
            config: config.clone(),
            obs_names: layout.names().map(str::to_string).collect(),
            started_utc: String::new(),
            start: None,
        }
    }
}

/// An event's line: `{"event": …}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct EventLine {
    /// The event.
    pub(crate) event: Event,
}

/// The prefix that tells an event's line from a tick's.
const EVENT_PREFIX: &str = "{\"event\":";

/// A recording read back.
#[derive(Debug, Clone, PartialEq)]
pub struct Recording {
    /// The header line.
    pub header: RecordingHeader,
    /// Every complete tick record, in file order.
    pub records: Vec<TickRecord>,
    /// Every event, in file order.
    pub events: Vec<Event>,
    /// True when the last line was incomplete (the writer was killed) and was skipped.
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
}

/// Parses a recording's text.
pub fn parse(text: &str) -> Result<Recording, RecordingError> {
    let ends_with_newline = text.ends_with('\n');
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let (_, first) = lines.next().ok_or(RecordingError::Empty)?;
    let header: RecordingHeader =
        serde_json::from_str(first).map_err(|e| RecordingError::BadHeader(e.to_string()))?;
    if header.format != FORMAT {
        return Err(RecordingError::BadHeader(format!(
            "format is `{}`",
            header.format
        )));
    }
    let rest: Vec<(usize, &str)> = lines.collect();
    let mut records = Vec::with_capacity(rest.len());
    let mut events = Vec::new();
    let mut torn_tail = false;
    for (k, (i, line)) in rest.iter().enumerate() {
        let parsed = if line.starts_with(EVENT_PREFIX) {
            serde_json::from_str::<EventLine>(line).map(|l| events.push(l.event))
        } else {
            serde_json::from_str::<TickRecord>(line).map(|r| records.push(r))
        };
        match parsed {
            Ok(()) => {}
            // Only the very last line may be torn: the writer appends whole lines.
            Err(_) if k + 1 == rest.len() && !ends_with_newline => torn_tail = true,
            Err(e) => {
                return Err(RecordingError::BadRecord {
                    line: i + 1,
                    message: e.to_string(),
                });
            }
        }
    }
    Ok(Recording {
        header,
        records,
        events,
        torn_tail,
    })
}

/// The recording file for `path`: the path itself if it is a file, else `path/ticks.jsonl`.
pub(crate) fn ticks_path(path: &Path) -> PathBuf {
    if path.is_dir() {
        path.join(TICKS_FILE)
    } else {
        path.to_path_buf()
    }
}

/// Reads a recording from a file or a recording directory.
pub fn load(path: &Path) -> Result<Recording, RecordingError> {
    let file = ticks_path(path);
    let text = std::fs::read_to_string(&file).map_err(|source| RecordingError::Io {
        path: file.clone(),
        source,
    })?;
    parse(&text)
}

#[cfg(test)]
mod tests {
    use super::*;
    use pavlov::control::{Action, Mode};
    use pavlov::record::{LinkStatus, SensorReadings};

    fn config() -> Config {
        Config::from_toml(include_str!("../../../config/stall.toml")).unwrap()
    }

    fn record(seq: u64) -> TickRecord {
        TickRecord {
            seq,
            t_ms: seq as f64 * 20.0,
            mode: Mode::Reactive,
            obs_age_ticks: Some(0),
            sensors: SensorReadings::default(),
            obs: vec![0.25, 1.0],
            elbow: None,
            stimulus: seq % 3 == 0,
            predictions: Vec::new(),
            gate: false,
            default_action: Action::new(100, 100),
            command: Action::STOP,
            safety_stop: None,
            estop: false,
            lateness_us: 0,
            link: LinkStatus::default(),
            inputs: None,
        }
    }

    fn text(n: u64) -> String {
        let mut s = serde_json::to_string(&RecordingHeader::new(&config(), "test")).unwrap();
        s.push('\n');
        for i in 0..n {
            s.push_str(&serde_json::to_string(&record(i)).unwrap());
            s.push('\n');
        }
        s
    }

    #[test]
    fn a_recording_reads_back_whole() {
        let rec = parse(&text(5)).unwrap();
        assert_eq!(rec.records, (0..5).map(record).collect::<Vec<_>>());
        assert_eq!(rec.header.obs_names.len(), 44);
        assert_eq!(rec.header.label, "test");
        assert!(!rec.torn_tail);
    }

    #[test]
    fn a_torn_last_line_is_skipped_and_reported() {
        let full = text(4);
        // Cut inside the last record.
        let cut = &full[..full.len() - 25];
        let rec = parse(cut).unwrap();
        assert_eq!(rec.records.len(), 3);
        assert!(rec.torn_tail);
    }

    #[test]
    fn a_bad_line_in_the_middle_is_an_error_naming_it() {
        let mut lines: Vec<String> = text(4).lines().map(str::to_string).collect();
        lines[2] = "{not json".into();
        let joined = lines.join("\n") + "\n";
        match parse(&joined) {
            Err(RecordingError::BadRecord { line, .. }) => assert_eq!(line, 3),
            other => panic!("{other:?}"),
        }
        assert!(matches!(parse(""), Err(RecordingError::Empty)));
        assert!(matches!(
            parse("{\"x\":1}\n"),
            Err(RecordingError::BadHeader(_))
        ));
    }
}

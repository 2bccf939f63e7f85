//! The JSON Lines format: a header line ([`RecordingHeader`], format `FORMAT`), then one
//! [`TickRecord`] per line and, between them, `{"event": …}` lines ([`Event`]). Earlier versions
//! recorded in it; `pavlov convert --to jsonl` writes it for `jq`, `grep` and `pandas`. A process killed
//! mid-write leaves at most a torn last line, which the reader skips and reports
//! ([`Recording::torn_tail`]); a bad line anywhere else is an error naming the line.

use std::io::Write;

use pavlov::event::Event;
use pavlov::record::TickRecord;
use serde::{Deserialize, Serialize};

use super::{FORMAT, FORMAT_2, Recording, RecordingError, RecordingHeader, Step, in_order};

/// An event's line: `{"event": …}`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub(crate) struct EventLine {
    /// The event.
    pub(crate) event: Event,
}

/// The prefix that tells an event's line from a tick's.
const EVENT_PREFIX: &str = "{\"event\":";

/// Parses a JSON Lines recording.
pub fn parse(text: &str) -> Result<Recording, RecordingError> {
    let ends_with_newline = text.ends_with('\n');
    let mut lines = text
        .lines()
        .enumerate()
        .filter(|(_, l)| !l.trim().is_empty());
    let (_, first) = lines.next().ok_or(RecordingError::Empty)?;
    let header: RecordingHeader =
        serde_json::from_str(first).map_err(|e| RecordingError::BadHeader(e.to_string()))?;
    if header.format != FORMAT && header.format != FORMAT_2 {
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

/// Writes `rec` as JSON Lines: the header, then its ticks with each event after the tick it follows.
pub fn write(rec: &Recording, out: &mut impl Write) -> std::io::Result<()> {
    let header = RecordingHeader {
        format: FORMAT.to_string(),
        ..rec.header.clone()
    };
    serde_json::to_writer(&mut *out, &header)?;
    out.write_all(b"\n")?;
    for step in in_order(rec) {
        match step {
            Step::Tick(r) => serde_json::to_writer(&mut *out, r)?,
            Step::Event(e) => serde_json::to_writer(&mut *out, &EventLine { event: e.clone() })?,
        }
        out.write_all(b"\n")?;
    }
    out.flush()
}

#[cfg(test)]
mod tests {
    use super::*;
    use pavlov::config::Config;
    use pavlov::control::{Action, Mode};
    use pavlov::record::{LinkStatus, SensorReadings};

    fn config() -> Config {
        Config::from_toml(include_str!("../../../../config/stall.toml")).unwrap()
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
            gate: seq % 3 == 0,
            rule: (seq % 3 == 0).then(|| ["stimulus", "stall"][(seq % 2) as usize].to_string()),
            default_action: Action::new(100, 100),
            command: Action::STOP,
            safety_stop: None,
            estop: false,
            lateness_us: 0,
            link: LinkStatus::default(),
            ..TickRecord::at_rest(seq, seq as f64 * 20.0, Mode::Reactive)
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
        let text = text(5);
        // The rule is written where the gate engaged, and left out (read back as none) elsewhere, as
        // in recordings made before the rule table.
        let lines: Vec<&str> = text.lines().collect();
        assert!(lines[1].contains("\"rule\":\"stimulus\""), "{}", lines[1]);
        assert!(lines[4].contains("\"rule\":\"stall\""), "{}", lines[4]);
        assert!(!lines[2].contains("rule"), "{}", lines[2]);
        let rec = parse(&text).unwrap();
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

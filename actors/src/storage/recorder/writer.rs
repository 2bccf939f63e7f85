//! The recorder thread's writer: one recording open at a time, written as MCAP
//! ([`crate::storage::recording::mcap_write`]; the format is in [`crate::storage::recording`]).
//!
//! Flushing: a chunk is finished when it is full (by size, in the MCAP writer) and when the oldest
//! message not yet on disk has waited [`FLUSH_EVERY`]; while the queue is dry and something waits, the
//! thread naps at most [`POLL`] (and never past that deadline) instead of blocking, so a tick handed to
//! the queue never has to wake it. A kill therefore loses at most about a second.
//!
//! Failing: when opening, writing, flushing or finishing the file fails (a full disk, a file-size limit),
//! the recording stops there: what can still be finished is, so every chunk on disk before the error
//! stays readable (the reader tolerates the cut tail), and a `recording_stopped` event names the file and
//! carries the reason, the error as the OS gave it. The dashboard then no longer names the recording, and
//! `/metrics` counts the failure (the event log counts it). A later `start_recording` opens a new file as
//! usual, and records again once there is room.

use std::fs::File;
use std::io::BufWriter;
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant, SystemTime};

use pavlov::event::{Event, EventKind};
use pavlov::record::TickRecord;
use tokio::sync::{mpsc, oneshot};

use super::{FLUSH_EVERY, RecorderInput, RecorderReport, SnapshotSource};
use crate::bus::EventLog;
use crate::command::{Applied, CommandError, Envelope, Inbox, Outcome, RecorderCommand};
use crate::storage::names::{NAME_RULES, check_plain_name};
use crate::storage::recording::mcap_write::McapSink;
use crate::storage::recording::{MCAP_FILE, RecordingHeader, StartState, TICKS_FILE};
use crate::storage::utc;

/// The longest nap while the queue is dry and a chunk waits to be finished.
pub(super) const POLL: Duration = Duration::from_millis(10);
/// While the queue never runs dry, how many items pass between two looks at the clock.
const CLOCK_EVERY: u32 = 64;

/// What opening a recording does to one already there.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(super) enum Existing {
    Replace,
    Refuse,
}

/// Where a recording learns the run's state at its start.
pub(super) trait StartSource: Send {
    /// The learner's state between two ticks, now.
    fn start_state(&mut self) -> Result<StartState, String>;
}

impl StartSource for SnapshotSource {
    fn start_state(&mut self) -> Result<StartState, String> {
        let (tx, rx) = oneshot::channel();
        self.blocking_send(tx)
            .map_err(|_| "the learning actor is not running".to_string())?;
        rx.blocking_recv()
            .map_err(|_| "the learning actor stopped before answering".to_string())
    }
}

/// A recording that has begun.
struct Begun {
    sink: McapSink<BufWriter<File>>,
    /// The last tick before the recording.
    after: Option<u64>,
    /// Events with a smaller id are from before the recording.
    events_before: u64,
    /// When the oldest message not yet in a finished chunk was written.
    unflushed_since: Option<Instant>,
    /// The last tick written (where `recording_stopped` takes effect).
    last_tick: Option<u64>,
}

struct OpenFile {
    path: PathBuf,
    /// The file, from when it is created until the recording begins.
    reserved: Option<File>,
    begun: Option<Begun>,
}

pub(super) struct Writer {
    header: RecordingHeader,
    root: PathBuf,
    file: Option<OpenFile>,
    source: Option<Box<dyn StartSource>>,
    /// The event log without the recorder's own queue (events the recorder makes are written directly).
    events: Option<EventLog>,
    /// The newest tick the recorder was handed (where an event about a failure takes effect).
    last_seen: Option<u64>,
    pub(super) report: RecorderReport,
}

/// The text of `e` and of every error under it, each told once: the OS's own words included (a write
/// error of the MCAP writer says only that writing failed; the `std::io::Error` under it says why).
pub(super) fn reason(e: &(dyn std::error::Error + 'static)) -> String {
    let mut parts: Vec<String> = Vec::new();
    let mut next = Some(e);
    while let Some(err) = next {
        let text = err.to_string();
        if !parts.iter().any(|p| p.ends_with(&text)) {
            parts.push(text);
        }
        next = err.source();
    }
    parts.join(": ")
}

fn create(dir: &Path, existing: Existing) -> std::io::Result<(File, PathBuf)> {
    std::fs::create_dir_all(dir)?;
    let path = dir.join(MCAP_FILE);
    // A recording of an earlier version, in JSON Lines.
    let older = dir.join(TICKS_FILE);
    let never_overwritten = |p: &Path| {
        std::io::Error::new(
            std::io::ErrorKind::AlreadyExists,
            format!(
                "{} already holds a recording, and a recording is never overwritten",
                p.display()
            ),
        )
    };
    let file = match existing {
        Existing::Replace => {
            if older.exists() {
                std::fs::remove_file(&older)?;
            }
            File::create(&path)
        }
        Existing::Refuse if older.exists() => Err(never_overwritten(&older)),
        Existing::Refuse => File::options()
            .write(true)
            .create_new(true)
            .open(&path)
            .map_err(|e| match e.kind() {
                std::io::ErrorKind::AlreadyExists => never_overwritten(&path),
                _ => e,
            }),
    }?;
    Ok((file, path))
}

impl Writer {
    pub(super) fn new(header: RecordingHeader, root: PathBuf) -> Self {
        Writer {
            header,
            root,
            file: None,
            source: None,
            events: None,
            last_seen: None,
            report: RecorderReport::default(),
        }
    }

    /// Creates the recording file in `dir` now; it begins once the run's state is known.
    pub(super) fn reserve(&mut self, dir: &Path, existing: Existing) -> std::io::Result<()> {
        let (file, path) = create(dir, existing)?;
        self.report.files.push(path.clone());
        self.file = Some(OpenFile {
            path,
            reserved: Some(file),
            begun: None,
        });
        Ok(())
    }

    /// Opens the reserved recording with the run's state now (or `known`): writes its provenance,
    /// configuration and start state, and flushes them.
    fn begin(&mut self, known: Option<StartState>) -> Result<(), String> {
        let Some(f) = self.file.as_mut().filter(|f| f.begun.is_none()) else {
            return Ok(());
        };
        let Some(file) = f.reserved.take() else {
            return Err(format!("{}: the file is not open", f.path.display()));
        };
        let start = match known {
            Some(start) => start,
            None => self
                .source
                .as_mut()
                .ok_or_else(|| "the server is not running yet".to_string())?
                .start_state()?,
        };
        let (after, events_before) = (start.after, start.events_before);
        let mut header = self.header.clone();
        header.started_utc = utc::stamp(SystemTime::now());
        header.start = Some(start);
        let sink = McapSink::create(BufWriter::with_capacity(64 * 1024, file), &header)
            .map_err(|e| format!("{}: {}", f.path.display(), reason(&e)))?;
        f.begun = Some(Begun {
            sink,
            after,
            events_before,
            unflushed_since: None,
            last_tick: after,
        });
        let path = f.path.display().to_string();
        self.announce(after, EventKind::RecordingStarted { path });
        Ok(())
    }

    /// Makes an event about the recorder, and writes it into the open recording.
    fn announce(&mut self, after: Option<u64>, kind: EventKind) {
        if let Some(events) = &self.events {
            let event = events.emit(after, kind);
            self.write_event(&event);
        }
    }

    /// Stops the open recording as asked: announces the stop (written into it) and finishes the file. A
    /// finish that fails (no room for the last chunk or the summary) is announced as a second stop, with
    /// the reason.
    fn close(&mut self) {
        let Some(f) = self.file.as_ref() else { return };
        if let Some(b) = &f.begun {
            let path = f.path.display().to_string();
            self.announce(
                b.last_tick,
                EventKind::RecordingStopped { path, reason: None },
            );
        }
        if let Some(f) = self.file.take()
            && let Some(b) = f.begun
        {
            let last = b.last_tick;
            if let Err(e) = b.sink.finish() {
                self.failed(&f.path, last, format!("finishing the file: {}", reason(&e)));
            }
        }
    }

    /// The open recording's write failed with `e`: it stops here. What can still be finished is (every
    /// chunk already on disk stays readable), and the stop is announced with the reason.
    fn fail(&mut self, e: &(dyn std::error::Error + 'static)) {
        let Some(f) = self.file.take() else { return };
        let why = reason(e);
        let last = match f.begun {
            Some(b) => {
                let last = b.last_tick;
                // Usually fails as well (the MCAP writer refuses to go on after an error); the chunks
                // before the error are on disk either way.
                if let Err(e) = b.sink.finish() {
                    tracing::debug!(
                        "finishing {} after its error: {}",
                        f.path.display(),
                        reason(&e)
                    );
                }
                last
            }
            None => self.last_seen,
        };
        self.failed(&f.path, last, why);
    }

    /// Reports that the recording at `path` stopped after tick `after` because of `why`: in the log, the
    /// report, and as a `recording_stopped` event with the reason (the recording is closed already, so
    /// the event goes to the clients only).
    fn failed(&mut self, path: &Path, after: Option<u64>, why: String) {
        let path = path.display().to_string();
        tracing::error!("recording stopped: {path}: {why}");
        self.report.errors.push(format!("{path}: {why}"));
        if let Some(events) = &self.events {
            events.emit(
                after,
                EventKind::RecordingStopped {
                    path,
                    reason: Some(why),
                },
            );
        }
    }

    /// A recording that could not begin (its file was made for it and holds nothing worth keeping):
    /// removes the file and announces the failure.
    fn failed_to_begin(&mut self, why: String) {
        let Some(f) = self.file.take() else { return };
        if let Err(e) = std::fs::remove_file(&f.path) {
            tracing::warn!("cannot remove {}: {e}", f.path.display());
        }
        self.report.files.retain(|p| p != &f.path);
        let after = self.last_seen;
        self.failed(&f.path, after, why);
    }

    /// The open recording, if it has begun.
    fn begun(&mut self) -> Option<&mut Begun> {
        self.file.as_mut().and_then(|f| f.begun.as_mut())
    }

    fn write(&mut self, record: &TickRecord) {
        self.last_seen = Some(record.seq);
        let Some(b) = self.begun() else {
            self.report.discarded += 1;
            return;
        };
        if b.after.is_some_and(|a| record.seq <= a) {
            self.report.discarded += 1;
            return;
        }
        match b.sink.tick(record) {
            Ok(()) => {
                b.unflushed_since.get_or_insert_with(Instant::now);
                b.last_tick = Some(record.seq);
                self.report.written += 1;
            }
            Err(e) => self.fail(&e),
        }
    }

    fn write_event(&mut self, event: &Event) {
        let Some(b) = self.begun() else { return };
        if event.id < b.events_before {
            return;
        }
        match b.sink.event(event) {
            Ok(()) => {
                b.unflushed_since.get_or_insert_with(Instant::now);
                self.report.events += 1;
            }
            Err(e) => self.fail(&e),
        }
    }

    /// Finishes the open chunk if its oldest message has waited [`FLUSH_EVERY`]. Returns how long until
    /// that is due when something still waits (`None`: nothing does).
    fn flush_due(&mut self) -> Option<Duration> {
        let b = self.begun()?;
        if !b.sink.pending() {
            b.unflushed_since = None;
            return None;
        }
        let since = *b.unflushed_since.get_or_insert_with(Instant::now);
        let waited = since.elapsed();
        if waited < FLUSH_EVERY {
            return Some(FLUSH_EVERY - waited);
        }
        let result = b.sink.flush();
        b.unflushed_since = None;
        if let Err(e) = result {
            self.fail(&e);
        }
        None
    }

    /// Connects the running server; a recording reserved at spawn begins with the run (`initial`).
    fn attach(&mut self, source: Box<dyn StartSource>, events: EventLog, initial: StartState) {
        self.source = Some(source);
        self.events = Some(events.detached());
        if let Err(e) = self.begin(Some(initial)) {
            self.failed_to_begin(format!("the recording could not begin: {e}"));
        }
    }

    fn command(&mut self, cmd: RecorderCommand) -> Outcome {
        match cmd {
            RecorderCommand::StartRecording { dir } => {
                let dir = match dir {
                    Some(name) => {
                        check_plain_name(&name).map_err(|e| {
                            CommandError::Rejected(format!(
                                "start_recording takes {NAME_RULES}, of a folder inside the recordings folder {}; {e}",
                                self.root.display()
                            ))
                        })?;
                        self.root.join(name)
                    }
                    None => self.new_default_dir(),
                };
                if self.source.is_none() {
                    return Err(CommandError::Rejected(
                        "start_recording: the server is not running yet".into(),
                    ));
                }
                let (file, path) = create(&dir, Existing::Refuse)
                    .map_err(|e| CommandError::Rejected(format!("start_recording: {e}")))?;
                // Only now is the running recording closed: a refused start leaves it open.
                self.close();
                self.report.files.push(path.clone());
                self.file = Some(OpenFile {
                    path: path.clone(),
                    reserved: Some(file),
                    begun: None,
                });
                if let Err(e) = self.begin(None) {
                    self.failed_to_begin(format!("the recording could not begin: {e}"));
                    return Err(CommandError::Rejected(format!("start_recording: {e}")));
                }
                Ok(Applied::Recording {
                    recording: path.display().to_string(),
                })
            }
            RecorderCommand::StopRecording {} => match self.file.as_ref().map(|f| f.path.clone()) {
                Some(p) => {
                    self.close();
                    Ok(Applied::Stopped {
                        stopped: p.display().to_string(),
                    })
                }
                None => Err(CommandError::Rejected("no recording is running".into())),
            },
        }
    }

    /// `root/recording-<UTC time>`, with `-2`, `-3`, … when that folder exists (twice in a second).
    fn new_default_dir(&self) -> PathBuf {
        let base = format!("recording-{}", utc::stamp(SystemTime::now()));
        let mut dir = self.root.join(&base);
        let mut n = 2;
        while dir.exists() {
            dir = self.root.join(format!("{base}-{n}"));
            n += 1;
        }
        dir
    }

    fn take(&mut self, input: RecorderInput) {
        match input {
            RecorderInput::Tick(record) => self.write(&record),
            RecorderInput::Event(event) => self.write_event(&event),
            RecorderInput::Attach {
                snapshots,
                events,
                initial,
            } => self.attach(Box::new(snapshots), events, *initial),
        }
    }

    /// Applies the commands waiting, after every item queued before them: those were sent earlier (a
    /// tick in the queue is older than a snapshot the learner gives now, so it belongs to the recording
    /// open until then, and a stopped recording keeps every tick made before the stop).
    fn commands(
        &mut self,
        input: &mut mpsc::Receiver<RecorderInput>,
        commands: &mut Inbox<RecorderCommand>,
    ) {
        if commands.is_empty() {
            return;
        }
        for _ in 0..input.len() {
            match input.try_recv() {
                Ok(item) => self.take(item),
                Err(_) => break,
            }
        }
        for _ in 0..commands.len() {
            if let Ok(Envelope { command, reply }) = commands.try_recv() {
                let _ = reply.send(self.command(command));
            }
        }
    }

    pub(super) fn run(
        mut self,
        mut input: mpsc::Receiver<RecorderInput>,
        mut commands: Inbox<RecorderCommand>,
    ) -> RecorderReport {
        let mut items = 0u32;
        loop {
            let next = match input.try_recv() {
                Ok(item) => item,
                Err(mpsc::error::TryRecvError::Empty) => match self.flush_due() {
                    // Something waits to be flushed: nap, then look again.
                    Some(due) => {
                        std::thread::sleep(due.min(POLL));
                        self.commands(&mut input, &mut commands);
                        continue;
                    }
                    // Nothing waits: sleep until the next item (a command waits for it too).
                    None => match input.blocking_recv() {
                        Some(item) => item,
                        None => break,
                    },
                },
                Err(mpsc::error::TryRecvError::Disconnected) => break,
            };
            self.take(next);
            self.commands(&mut input, &mut commands);
            items = items.wrapping_add(1);
            if items % CLOCK_EVERY == 0 {
                self.flush_due();
            }
        }
        while let Ok(Envelope { command, reply }) = commands.try_recv() {
            let _ = reply.send(self.command(command));
        }
        self.close();
        self.report
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use pavlov::agent::LearningStage;
    use pavlov::config::Config;
    use pavlov::control::Mode;
    use std::sync::Arc;

    fn record(seq: u64) -> Arc<TickRecord> {
        Arc::new(TickRecord {
            obs: vec![0.5],
            ..TickRecord::at_rest(seq, seq as f64 * 20.0, Mode::Pavlovian)
        })
    }

    fn config() -> Config {
        Config::from_toml(include_str!("../../../../config/stall.toml")).unwrap()
    }

    fn header() -> RecordingHeader {
        RecordingHeader::new(&config(), "unit")
    }

    /// A learner that always stands after tick `after`.
    struct Fixed(Option<u64>);

    impl StartSource for Fixed {
        fn start_state(&mut self) -> Result<StartState, String> {
            let stage = LearningStage::new(&config()).map_err(|e| e.to_string())?;
            Ok(StartState {
                after: self.0,
                events_before: 1,
                learner: stage.stage_snapshot(),
            })
        }
    }

    fn writer(root: &Path, after: Option<u64>) -> Writer {
        let mut w = Writer::new(header(), root.to_path_buf());
        let initial = Fixed(None).start_state().unwrap();
        w.attach(Box::new(Fixed(after)), EventLog::new(), initial);
        w
    }

    fn start(w: &mut Writer, dir: Option<&str>) -> Outcome {
        w.command(RecorderCommand::StartRecording {
            dir: dir.map(str::to_string),
        })
    }

    fn fresh(name: &str) -> PathBuf {
        let root = std::env::temp_dir().join(format!("pavlov-rec-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        root
    }

    #[test]
    fn a_reserved_recording_begins_on_attach_with_the_learner_state() {
        let root = fresh("reserved");
        let mut w = Writer::new(header(), root.clone());
        w.reserve(&root.join("run"), Existing::Refuse).unwrap();
        // Before the server is attached, nothing can be written.
        w.write(&record(0));
        assert_eq!(w.report.written, 0);
        let initial = Fixed(None).start_state().unwrap();
        w.attach(Box::new(Fixed(Some(99))), EventLog::new(), initial);
        for i in 0..10 {
            w.write(&record(i));
        }
        w.close();
        assert_eq!(w.report.written, 10);
        let back = crate::storage::recording::load(&root.join("run")).unwrap();
        assert_eq!(back.records.len(), 10);
        assert_eq!(back.records[9], *record(9));
        assert_eq!(back.header.label, "unit");
        assert!(back.header.program.starts_with("pavlov "));
        let start = back.header.start.expect("start state");
        assert_eq!(start.after, None);
        assert_eq!(start.learner.predictions.predictions.len(), 1);
        // Started and stopped are events of the recording itself.
        let kinds: Vec<&str> = back.events.iter().map(|e| e.kind.name()).collect();
        assert_eq!(kinds, vec!["recording_started", "recording_stopped"]);
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn a_recording_started_mid_run_holds_only_the_ticks_and_events_after_its_snapshot() {
        let root = fresh("midrun");
        let mut w = writer(&root, Some(41));
        assert!(start(&mut w, Some("mid")).is_ok());
        for i in 38..45 {
            w.write(&record(i));
        }
        let log = EventLog::new();
        let old = Event {
            id: 0,
            after: Some(30),
            kind: EventKind::WeightsReset,
        };
        w.write_event(&old);
        w.write_event(&log.emit(Some(42), EventKind::WeightsReset));
        w.close();
        let back = crate::storage::recording::load(&root.join("mid")).unwrap();
        let seqs: Vec<u64> = back.records.iter().map(|r| r.seq).collect();
        assert_eq!(seqs, vec![42, 43, 44]);
        let resets = back
            .events
            .iter()
            .filter(|e| e.kind == EventKind::WeightsReset)
            .count();
        assert_eq!(resets, 1, "the event from before the snapshot is left out");
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn default_names_are_new_even_twice_in_a_second() {
        let root = fresh("default");
        let mut w = writer(&root, None);
        let mut paths = Vec::new();
        for _ in 0..3 {
            match start(&mut w, None) {
                Ok(Applied::Recording { recording }) => paths.push(recording),
                other => panic!("{other:?}"),
            }
        }
        w.close();
        paths.sort();
        paths.dedup();
        assert_eq!(paths.len(), 3, "{paths:?}");
        for p in &paths {
            assert!(Path::new(p).starts_with(&root), "{p}");
        }
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn a_refused_start_leaves_the_running_recording_open() {
        let root = fresh("keep");
        let mut w = writer(&root, None);
        assert!(start(&mut w, Some("first")).is_ok());
        let err = start(&mut w, Some("first")).unwrap_err().to_string();
        assert!(err.contains("never overwritten"), "{err}");
        let err = start(&mut w, Some("../x")).unwrap_err().to_string();
        assert!(err.contains("separator"), "{err}");
        w.write(&record(1));
        w.close();
        assert_eq!(w.report.written, 1, "the first recording kept going");
        let back = crate::storage::recording::load(&root.join("first")).unwrap();
        assert_eq!(back.records.len(), 1);
        let _ = std::fs::remove_dir_all(&root);
    }

    #[test]
    fn start_is_refused_before_the_server_runs() {
        let root = fresh("early");
        let mut w = Writer::new(header(), root.clone());
        let err = start(&mut w, Some("x")).unwrap_err().to_string();
        assert!(err.contains("not running yet"), "{err}");
        assert!(!root.join("x").exists());
    }

    #[test]
    fn the_reason_of_a_write_error_carries_the_os_words() {
        let e = crate::storage::recording::mcap_write::McapWriteError::Io(
            std::io::Error::from_raw_os_error(28),
        );
        let text = reason(&e);
        assert!(
            text.contains("No space left on device (os error 28)"),
            "{text}"
        );
        assert_eq!(text.matches("I/O error").count(), 1, "{text}");
    }

    #[test]
    fn a_recording_the_disk_refuses_stops_with_the_reason_and_a_new_one_records() {
        let root = fresh("full");
        let dir = root.join("full");
        std::fs::create_dir_all(&dir).unwrap();
        // The recording's file leads to /dev/full: every write fails with ENOSPC, as on a full disk.
        std::os::unix::fs::symlink("/dev/full", dir.join(MCAP_FILE)).unwrap();
        let mut w = Writer::new(header(), root.clone());
        w.reserve(&dir, Existing::Replace).unwrap();
        let log = EventLog::new();
        let mut live = log.subscribe();
        let initial = Fixed(None).start_state().unwrap();
        w.attach(Box::new(Fixed(None)), log.clone(), initial);
        let event = live.try_recv().expect("an event");
        match &event.kind {
            EventKind::RecordingStopped {
                path,
                reason: Some(why),
            } => {
                assert_eq!(Path::new(path), dir.join(MCAP_FILE));
                assert!(why.contains("No space left on device"), "{why}");
            }
            other => panic!("{other:?}"),
        }
        assert_eq!(log.storage_failures().figures().recordings, 1);
        assert!(w.file.is_none(), "nothing is being recorded");
        assert!(!w.report.errors.is_empty());
        // The file made for it is gone; nothing else was touched.
        assert!(std::fs::symlink_metadata(dir.join(MCAP_FILE)).is_err());
        w.write(&record(0));
        assert_eq!(w.report.written, 0);
        // Asked again, with room, it records.
        assert!(start(&mut w, Some("again")).is_ok());
        w.write(&record(1));
        w.close();
        assert_eq!(w.report.written, 1);
        let back = crate::storage::recording::load(&root.join("again")).unwrap();
        assert_eq!(back.records.len(), 1);
        let _ = std::fs::remove_dir_all(&root);
    }
}

//! The recorder: writes the tick feed to a JSON Lines recording on a dedicated thread.
//!
//! The feed hands each record to the recorder's bounded queue with `try_send` (a full queue drops the
//! record and counts it; the tick never waits). The recorder's own OS thread takes records off the queue,
//! appends one JSON line each to a buffered file, and flushes whenever the queue runs dry and at least every
//! [`FLUSH_EVERY`], so a killed process loses at most about a second (a torn last line is skipped by the
//! reader). It also takes `start_recording` / `stop_recording` commands from the command router.
//!
//! A client names a recording, never a place: `start_recording`'s `dir` is a plain name
//! ([`crate::storage::names`]) of a folder inside the recordings root, and the default name
//! (`recording-<UTC time>`, with `-2`, `-3`, … if taken) is always new. A recording file is never
//! overwritten, neither by a client nor by `pavlov serve --record` ([`Recorder::spawn_new`]); only the
//! experiments, which regenerate their own results, replace one ([`Recorder::spawn`]). A refused start
//! leaves the running recording open.

use std::fs::File;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::time::{Duration, Instant, SystemTime};

use pavlov::record::TickRecord;
use tokio::sync::mpsc;

use crate::command::{Applied, CommandError, Envelope, Inbox, Outcome, RecorderCommand};
use crate::storage::names::{NAME_RULES, check_plain_name};
use crate::storage::recording::{RecordingHeader, TICKS_FILE};
use crate::storage::utc;

/// The longest time written records may stay in the buffer.
pub(crate) const FLUSH_EVERY: Duration = Duration::from_secs(1);

/// The default queue length: 10 s of ticks at 50 Hz.
pub const DEFAULT_CAPACITY: usize = 500;

/// What the server needs to feed a recorder.
#[derive(Debug, Clone)]
pub struct RecorderLink {
    /// The record queue ([`crate::pipeline::feed::TickFeed::with_recorder`]).
    pub(crate) records: mpsc::Sender<Arc<TickRecord>>,
    /// Start/stop commands from the router.
    pub(crate) commands: mpsc::Sender<Envelope<RecorderCommand>>,
}

/// What the recorder did, returned when its thread ends.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RecorderReport {
    /// Records written, over every recording.
    pub written: u64,
    /// Records received while no recording was open.
    pub(crate) discarded: u64,
    /// The recordings written, in order.
    pub files: Vec<PathBuf>,
    /// Write errors (the recording is closed after the first one).
    pub errors: Vec<String>,
}

/// A running recorder thread.
pub struct Recorder {
    /// Connect this to the server.
    pub link: RecorderLink,
    thread: std::thread::JoinHandle<RecorderReport>,
}

impl Recorder {
    /// Starts the recorder thread. With `dir`, recording into `dir/ticks.jsonl` starts at once,
    /// replacing a recording already there (for experiments, which regenerate their own results);
    /// `root` is the folder `start_recording` creates its recordings in.
    pub fn spawn(
        header: RecordingHeader,
        dir: Option<PathBuf>,
        root: PathBuf,
        capacity: usize,
    ) -> std::io::Result<Recorder> {
        Self::spawn_with(header, dir, Existing::Replace, root, capacity)
    }

    /// Like [`Recorder::spawn`], but refuses (an `AlreadyExists` error naming the file) to start when
    /// `dir` already holds a recording: for `pavlov serve --record DIR`.
    pub fn spawn_new(
        header: RecordingHeader,
        dir: Option<PathBuf>,
        root: PathBuf,
        capacity: usize,
    ) -> std::io::Result<Recorder> {
        Self::spawn_with(header, dir, Existing::Refuse, root, capacity)
    }

    fn spawn_with(
        header: RecordingHeader,
        dir: Option<PathBuf>,
        existing: Existing,
        root: PathBuf,
        capacity: usize,
    ) -> std::io::Result<Recorder> {
        let (records_tx, records_rx) = mpsc::channel(capacity.max(1));
        let (commands_tx, commands_rx) = mpsc::channel(8);
        let mut writer = Writer {
            header,
            root,
            open: None,
            report: RecorderReport::default(),
        };
        if let Some(d) = dir {
            writer.open(&d, existing)?;
        }
        let thread = std::thread::Builder::new()
            .name("pavlov-recorder".into())
            .spawn(move || writer.run(records_rx, commands_rx))?;
        Ok(Recorder {
            link: RecorderLink {
                records: records_tx,
                commands: commands_tx,
            },
            thread,
        })
    }

    /// Waits for the thread to finish (it does once every sender of the record queue is gone, i.e. after
    /// the server has shut down and been dropped) and returns its report.
    pub fn join(self) -> RecorderReport {
        drop(self.link);
        self.thread.join().unwrap_or_else(|_| RecorderReport {
            errors: vec!["the recorder thread panicked".into()],
            ..RecorderReport::default()
        })
    }
}

/// What opening a recording does to one already there.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Existing {
    Replace,
    Refuse,
}

struct OpenFile {
    out: BufWriter<File>,
    path: PathBuf,
    dirty: bool,
    last_flush: Instant,
}

struct Writer {
    header: RecordingHeader,
    root: PathBuf,
    open: Option<OpenFile>,
    report: RecorderReport,
}

impl Writer {
    /// Opens a recording in `dir` and only then closes the one open (a refused open leaves it running).
    fn open(&mut self, dir: &Path, existing: Existing) -> std::io::Result<PathBuf> {
        std::fs::create_dir_all(dir)?;
        let path = dir.join(TICKS_FILE);
        let file = match existing {
            Existing::Replace => File::create(&path),
            Existing::Refuse => File::options()
                .write(true)
                .create_new(true)
                .open(&path)
                .map_err(|e| match e.kind() {
                    std::io::ErrorKind::AlreadyExists => std::io::Error::new(
                        e.kind(),
                        format!(
                            "{} already holds a recording, and a recording is never overwritten",
                            path.display()
                        ),
                    ),
                    _ => e,
                }),
        }?;
        let mut out = BufWriter::with_capacity(256 * 1024, file);
        let header = serde_json::to_string(&self.header).map_err(std::io::Error::other)?;
        out.write_all(header.as_bytes())?;
        out.write_all(b"\n")?;
        out.flush()?;
        self.close();
        self.report.files.push(path.clone());
        self.open = Some(OpenFile {
            out,
            path: path.clone(),
            dirty: false,
            last_flush: Instant::now(),
        });
        Ok(path)
    }

    fn close(&mut self) {
        if let Some(mut f) = self.open.take()
            && let Err(e) = f.out.flush()
        {
            self.report
                .errors
                .push(format!("{}: {e}", f.path.display()));
        }
    }

    fn write(&mut self, record: &TickRecord) {
        let Some(f) = self.open.as_mut() else {
            self.report.discarded += 1;
            return;
        };
        let result = serde_json::to_writer(&mut f.out, record)
            .map_err(std::io::Error::other)
            .and_then(|()| f.out.write_all(b"\n"));
        match result {
            Ok(()) => {
                self.report.written += 1;
                f.dirty = true;
            }
            Err(e) => {
                let msg = format!("{}: {e}", f.path.display());
                tracing::error!("recording stopped: {msg}");
                self.report.errors.push(msg);
                self.open = None;
            }
        }
    }

    fn flush(&mut self, force: bool) {
        let Some(f) = self.open.as_mut() else { return };
        if f.dirty && (force || f.last_flush.elapsed() >= FLUSH_EVERY) {
            if let Err(e) = f.out.flush() {
                self.report
                    .errors
                    .push(format!("{}: {e}", f.path.display()));
            }
            f.dirty = false;
            f.last_flush = Instant::now();
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
                self.open(&dir, Existing::Refuse)
                    .map(|p| Applied::Recording {
                        recording: p.display().to_string(),
                    })
                    .map_err(|e| CommandError::Rejected(format!("start_recording: {e}")))
            }
            RecorderCommand::StopRecording {} => match self.open.as_ref().map(|f| f.path.clone()) {
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

    fn run(
        mut self,
        mut records: mpsc::Receiver<Arc<TickRecord>>,
        mut commands: Inbox<RecorderCommand>,
    ) -> RecorderReport {
        loop {
            let record = match records.try_recv() {
                Ok(r) => r,
                Err(mpsc::error::TryRecvError::Empty) => {
                    // The queue ran dry: flush before waiting, so a kill loses nothing already taken.
                    self.flush(true);
                    match records.blocking_recv() {
                        Some(r) => r,
                        None => break,
                    }
                }
                Err(mpsc::error::TryRecvError::Disconnected) => break,
            };
            // A command sent before this record arrived applies to it; one that arrives while these are being
            // applied waits for the next record.
            for _ in 0..commands.len() {
                if let Ok(Envelope { command, reply }) = commands.try_recv() {
                    let _ = reply.send(self.command(command));
                }
            }
            self.write(&record);
            self.flush(false);
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
    use pavlov::config::Config;
    use pavlov::control::Mode;
    use tokio::sync::oneshot;

    fn record(seq: u64) -> Arc<TickRecord> {
        Arc::new(TickRecord {
            obs: vec![0.5],
            ..TickRecord::at_rest(seq, seq as f64 * 20.0, Mode::Pavlovian)
        })
    }

    fn header() -> RecordingHeader {
        let cfg = Config::from_toml(include_str!("../../../config/stall.toml")).unwrap();
        RecordingHeader::new(&cfg, "unit")
    }

    #[test]
    fn records_are_written_and_read_back_in_order() {
        let dir = std::env::temp_dir().join(format!("pavlov-rec-{}", std::process::id()));
        let rec = Recorder::spawn(header(), Some(dir.clone()), dir.clone(), 16).unwrap();
        for i in 0..10 {
            rec.link.records.blocking_send(record(i)).unwrap();
        }
        let report = rec.join();
        assert_eq!(report.written, 10);
        assert!(report.errors.is_empty());
        let back = crate::storage::recording::load(&dir).unwrap();
        assert_eq!(back.records.len(), 10);
        assert_eq!(back.records[9], *record(9));
        assert_eq!(back.header.label, "unit");
        let _ = std::fs::remove_dir_all(&dir);
    }

    #[test]
    fn start_and_stop_commands_open_and_close_recordings() {
        let root = std::env::temp_dir().join(format!("pavlov-rec-cmd-{}", std::process::id()));
        let rec = Recorder::spawn(header(), None, root.clone(), 16).unwrap();
        let RecorderLink { records, commands } = rec.link.clone();
        let (tx, rx) = oneshot::channel();
        let dir = root.join("a");
        commands
            .blocking_send(Envelope {
                command: RecorderCommand::StartRecording {
                    dir: Some("a".into()),
                },
                reply: tx,
            })
            .unwrap();
        // Commands are taken before the next record.
        records.blocking_send(record(1)).unwrap();
        assert!(rx.blocking_recv().unwrap().is_ok());
        records.blocking_send(record(2)).unwrap();
        let (tx, rx) = oneshot::channel();
        commands
            .blocking_send(Envelope {
                command: RecorderCommand::StopRecording {},
                reply: tx,
            })
            .unwrap();
        records.blocking_send(record(3)).unwrap();
        assert!(rx.blocking_recv().unwrap().is_ok());
        drop((records, commands));
        let report = rec.join();
        assert_eq!(report.files, vec![dir.join(TICKS_FILE)]);
        let back = crate::storage::recording::load(&dir).unwrap();
        let seqs: Vec<u64> = back.records.iter().map(|r| r.seq).collect();
        // Record 1 followed the start; record 3 followed the stop; record 2 raced the stop.
        assert_eq!(seqs.first(), Some(&1), "{report:?}");
        assert!(!seqs.contains(&3));
        assert_eq!(report.written + report.discarded, 3);
        let _ = std::fs::remove_dir_all(&root);
    }

    fn writer(root: &Path) -> Writer {
        Writer {
            header: header(),
            root: root.to_path_buf(),
            open: None,
            report: RecorderReport::default(),
        }
    }

    fn start(w: &mut Writer, dir: Option<&str>) -> Outcome {
        w.command(RecorderCommand::StartRecording {
            dir: dir.map(str::to_string),
        })
    }

    #[test]
    fn default_names_are_new_even_twice_in_a_second() {
        let root = std::env::temp_dir().join(format!("pavlov-rec-default-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let mut w = writer(&root);
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
        let root = std::env::temp_dir().join(format!("pavlov-rec-keep-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&root);
        let mut w = writer(&root);
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
}

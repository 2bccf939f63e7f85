//! The recorder: writes a run's ticks and events to a recording on a dedicated thread.
//!
//! The tick feed and the event log hand everything to the recorder's one bounded queue with `try_send` (a
//! full queue drops the item and counts it; the tick never waits). The recorder's own OS thread takes them
//! off the queue and writes them as MCAP (`writer`; serialising and compressing happen here, never on
//! the tick path), finishing a chunk when it is full and at least every `FLUSH_EVERY`, so a killed
//! process loses at most about a second (the reader reads every complete chunk of a cut file). It also
//! takes `start_recording` / `stop_recording` commands from the command router.
//!
//! A recording opens with the run's state at that moment ([`crate::storage::recording::StartState`]):
//! the recorder asks the learning actor for a snapshot of the learner between two ticks, and then writes
//! only the ticks after it and the events made after it. So a recording replays exactly whether it began
//! with the run (`pavlov serve --record`, the experiments), after `--resume`, or from the dashboard mid-run.
//! Until the server has attached the learner to the recorder ([`RecorderInput::Attach`]), a recording asked
//! for at spawn waits.
//!
//! A client names a recording, never a place: `start_recording`'s `dir` is a plain name
//! (`crate::storage::names`) of a folder inside the recordings root, and the default name
//! (`recording-<UTC time>`, with `-2`, `-3`, … if taken) is always new. A recording file is never
//! overwritten, neither by a client, nor by `pavlov serve --record`, nor by the experiments
//! ([`Recorder::spawn_new`]; an experiment's run records beside a folder that holds one). A refused start
//! leaves the running recording open.

mod writer;

use std::path::PathBuf;
use std::time::Duration;

use tokio::sync::mpsc;

pub use crate::bus::recorder_queue::RecorderInput;
pub(crate) use crate::bus::recorder_queue::SnapshotSource;
use crate::command::{Envelope, RecorderCommand};
use crate::storage::recording::RecordingHeader;
use writer::{Existing, Writer};

/// The longest time a written record may wait in the open chunk before it is on disk.
pub(crate) const FLUSH_EVERY: Duration = Duration::from_secs(1);

/// The default queue length: 10 s of ticks at 50 Hz.
pub const DEFAULT_CAPACITY: usize = 500;

/// What the server needs to feed a recorder.
#[derive(Debug, Clone)]
pub struct RecorderLink {
    /// The queue of ticks, events and the attachment.
    pub(crate) input: mpsc::Sender<RecorderInput>,
    /// Start/stop commands from the router.
    pub(crate) commands: mpsc::Sender<Envelope<RecorderCommand>>,
}

/// What the recorder did, returned when its thread ends.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct RecorderReport {
    /// Records written, over every recording.
    pub written: u64,
    /// Events written, over every recording.
    pub events: u64,
    /// Records received while no recording was open (or from before it began).
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
    /// Starts the recorder thread. With `dir`, recording into `dir/recording.mcap` starts as soon as the
    /// server is attached, replacing a recording already there (in either format: an older `ticks.jsonl`
    /// is deleted); `root` is the folder `start_recording` creates its recordings in.
    pub fn spawn(
        header: RecordingHeader,
        dir: Option<PathBuf>,
        root: PathBuf,
        capacity: usize,
    ) -> std::io::Result<Recorder> {
        Self::spawn_with(header, dir, Existing::Replace, root, capacity)
    }

    /// Like [`Recorder::spawn`], but refuses (an `AlreadyExists` error naming the file) to start when
    /// `dir` already holds a recording: for `pavlov serve --record DIR` and the experiments.
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
        let (input_tx, input_rx) = mpsc::channel(capacity.max(1));
        let (commands_tx, commands_rx) = mpsc::channel(8);
        let mut writer = Writer::new(header, root);
        if let Some(d) = dir {
            // The file is created now, so a bad place is an error here; it opens once the learner's
            // state is known.
            writer.reserve(&d, existing)?;
        }
        let thread = std::thread::Builder::new()
            .name("pavlov-recorder".into())
            .spawn(move || writer.run(input_rx, commands_rx))?;
        Ok(Recorder {
            link: RecorderLink {
                input: input_tx,
                commands: commands_tx,
            },
            thread,
        })
    }

    /// Waits for the thread to finish (it does once every sender of its queue is gone, i.e. after the
    /// server has shut down and been dropped) and returns its report.
    pub fn join(self) -> RecorderReport {
        drop(self.link);
        self.thread.join().unwrap_or_else(|_| RecorderReport {
            errors: vec!["the recorder thread panicked".into()],
            ..RecorderReport::default()
        })
    }
}

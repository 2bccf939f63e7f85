//! The file a download of the recording sends: the recording being written, finished with its summary
//! and footer ([`crate::storage::recording::finish`]) into a temporary file that has no name (it is
//! removed as soon as it is open, and readable by its owner only while it had one), so it is gone when the
//! download ends, whatever happens. Runs on a blocking thread: it reads and compresses the whole
//! recording, and may wait for the recorder's next flush.

use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicU64, Ordering};
use std::time::Duration;

use crate::storage::recording::finish::{Copied, FinishError, Wait, finish_copy};

/// The longest a download waits for the ticks made before it to reach the disk. The recorder finishes a
/// chunk at least every [`crate::storage::recorder::FLUSH_EVERY`] (1 s); this leaves room for a
/// backlog in its queue on a loaded machine.
pub(crate) const PATIENCE: Duration = Duration::from_secs(10);
/// How often the recording's length is looked at while waiting.
const POLL: Duration = Duration::from_millis(50);

/// Why the copy could not be made.
#[derive(Debug, thiserror::Error)]
pub(crate) enum PrepareError {
    /// No temporary file.
    #[error("cannot make a temporary file in {dir}: {source}")]
    Temporary {
        /// The folder.
        dir: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The recording could not be copied.
    #[error(transparent)]
    Finish(#[from] FinishError),
    /// The copy could not be read back.
    #[error("cannot read back the copy: {0}")]
    Rewind(std::io::Error),
}

/// A finished copy, ready to send.
#[derive(Debug)]
pub(crate) struct Prepared {
    /// The copy, at its start.
    pub(crate) file: File,
    /// Its length, bytes.
    pub(crate) len: u64,
    /// What it holds.
    pub(crate) copied: Copied,
}

/// A new temporary file, open for reading and writing, already without a name.
fn temporary() -> Result<File, PrepareError> {
    static NEXT: AtomicU64 = AtomicU64::new(0);
    let dir = std::env::temp_dir();
    let failed = |source| PrepareError::Temporary {
        dir: dir.clone(),
        source,
    };
    loop {
        let n = NEXT.fetch_add(1, Ordering::Relaxed);
        let path = dir.join(format!("pavlov-download-{}-{n}.mcap", std::process::id()));
        let mut options = File::options();
        options.read(true).write(true).create_new(true);
        #[cfg(unix)]
        std::os::unix::fs::OpenOptionsExt::mode(&mut options, 0o600);
        match options.open(&path) {
            Ok(file) => {
                // Unix keeps an open file whose name is removed; elsewhere it stays until removed later.
                let _ = std::fs::remove_file(&path);
                return Ok(file);
            }
            Err(e) if e.kind() == std::io::ErrorKind::AlreadyExists && n < u64::MAX => continue,
            Err(e) => return Err(failed(e)),
        }
    }
}

/// Finishes a copy of the recording `live` holding every tick up to `through_tick` (waiting at most
/// [`PATIENCE`] for them to reach the disk; `stop` ends the wait).
pub(crate) fn prepare(
    live: &Path,
    through_tick: Option<u64>,
    stop: &dyn Fn() -> bool,
) -> Result<Prepared, PrepareError> {
    let wait = Wait {
        through_tick,
        patience: PATIENCE,
        poll: POLL,
    };
    let out = BufWriter::with_capacity(64 * 1024, temporary()?);
    let (out, copied) = finish_copy(live, out, &wait, stop)?;
    let mut file = out
        .into_inner()
        .map_err(|e| PrepareError::Rewind(e.into_error()))?;
    let len = file.seek(SeekFrom::End(0)).map_err(PrepareError::Rewind)?;
    file.seek(SeekFrom::Start(0))
        .map_err(PrepareError::Rewind)?;
    Ok(Prepared { file, len, copied })
}

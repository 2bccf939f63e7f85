//! [`PacedFile`]: a large file written a step at a time, each step on the disk before the next is
//! written, so that writing it never becomes a burst the rest of the process feels.
//!
//! Written the plain way, a Horde checkpoint of a few hundred megabytes sits dirty in the page cache and
//! reaches the disk in one `fsync` at the end; measured with `pavlov bench --horde` (11,892 predictions,
//! 276 MB), that burst raised the tick → command p99 of the whole server from 0.19 ms to 1.3 ms, while
//! copying the same weights without writing them did not. Here every [`STEP`] bytes are flushed with
//! `fdatasync` by the writing thread itself (which runs under `SCHED_IDLE`) and then dropped from the
//! page cache (`POSIX_FADV_DONTNEED`), so the disk sees a steady stream of small writes, and the file
//! does not push anything else out of memory.

use std::fs::File;
use std::io::Write;

use nix::fcntl::{PosixFadviseAdvice, posix_fadvise};

/// Bytes written between two flushes to the disk.
pub(crate) const STEP: u64 = 4 << 20;

/// See the module documentation.
pub(crate) struct PacedFile {
    file: File,
    step: u64,
    written: u64,
    settled: u64,
}

impl PacedFile {
    /// `file`, flushed every `step` bytes.
    pub(crate) fn new(file: File, step: u64) -> Self {
        PacedFile {
            file,
            step: step.max(1),
            written: 0,
            settled: 0,
        }
    }

    /// The bytes written so far.
    #[cfg(test)]
    pub(crate) fn written(&self) -> u64 {
        self.written
    }

    /// The file, every byte written to it (the caller `fsync`s it whole at the end).
    pub(crate) fn into_file(self) -> File {
        self.file
    }

    /// Flushes what was written since the last step to the disk and drops it from the page cache.
    fn settle(&mut self) -> std::io::Result<()> {
        self.file.sync_data()?;
        let (from, len) = (self.settled, self.written - self.settled);
        if let (Ok(from), Ok(len)) = (i64::try_from(from), i64::try_from(len)) {
            // Advice only: a file system that keeps the pages anyway loses nothing but memory.
            let _ = posix_fadvise(
                &self.file,
                from,
                len,
                PosixFadviseAdvice::POSIX_FADV_DONTNEED,
            );
        }
        self.settled = self.written;
        Ok(())
    }
}

impl Write for PacedFile {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.file.write(buf)?;
        self.written += n as u64;
        if self.written - self.settled >= self.step {
            self.settle()?;
        }
        Ok(n)
    }

    fn flush(&mut self) -> std::io::Result<()> {
        self.file.flush()
    }
}

#[cfg(test)]
mod tests {
    use std::io::Read;

    use super::*;

    #[test]
    fn every_byte_arrives_in_order_across_steps() {
        let dir = std::env::temp_dir().join(format!("pavlov-paced-{}", std::process::id()));
        std::fs::create_dir_all(&dir).expect("temp dir");
        let path = dir.join("paced.bin");
        let bytes: Vec<u8> = (0..100_000u32).map(|i| (i % 251) as u8).collect();
        let mut out = PacedFile::new(File::create(&path).expect("create"), 4096);
        for chunk in bytes.chunks(3000) {
            out.write_all(chunk).expect("write");
        }
        assert_eq!(out.written(), bytes.len() as u64);
        // Settled once at least 4 KiB wait: every second write of 3,000 bytes, up to 96,000.
        assert_eq!(out.settled, 96_000);
        out.into_file().sync_all().expect("sync");
        let mut back = Vec::new();
        File::open(&path)
            .expect("open")
            .read_to_end(&mut back)
            .expect("read");
        assert_eq!(back, bytes);
        let _ = std::fs::remove_dir_all(&dir);
    }
}

//! Reads a recording file into memory, refusing what is not a regular file (a FIFO would block the read
//! for ever, `/dev/zero` would feed it for ever) and any file over [`MAX_FILE`] bytes.
//!
//! The path is checked before it is opened (opening a serial device or a FIFO can itself have effects or
//! block), opened without blocking and without becoming a controlling terminal, and checked again on the
//! open file (it may have been replaced in between). The read itself stops one byte past the limit, so a
//! file that grows while it is read is refused too.

use std::fs::{File, FileType, OpenOptions};
use std::io::Read;
use std::os::unix::fs::{FileTypeExt, OpenOptionsExt};
use std::path::Path;

use super::RecordingError;

/// The largest recording file read (2 GiB): read whole into memory, it is about ten days of ticks at
/// 50 Hz as the recorder compresses them (about 50 bytes a tick).
pub const MAX_FILE: u64 = 2 << 30;

/// What a file that is not a regular file is, in words.
fn kind(t: FileType) -> Option<&'static str> {
    if t.is_file() {
        None
    } else if t.is_dir() {
        Some("a directory")
    } else if t.is_fifo() {
        Some("a FIFO (named pipe)")
    } else if t.is_char_device() {
        Some("a character device")
    } else if t.is_block_device() {
        Some("a block device")
    } else if t.is_socket() {
        Some("a socket")
    } else {
        Some("not a regular file")
    }
}

/// The bytes of the regular file `path` (symbolic links followed), at most [`MAX_FILE`] of them.
pub(crate) fn read(path: &Path) -> Result<Vec<u8>, RecordingError> {
    read_at_most(path, MAX_FILE)
}

/// [`read`] with a limit of `allowed` bytes.
fn read_at_most(path: &Path, allowed: u64) -> Result<Vec<u8>, RecordingError> {
    let io = |source| RecordingError::Io {
        path: path.to_path_buf(),
        source,
    };
    let check = |t: FileType, size: u64| match kind(t) {
        Some(kind) => Err(RecordingError::NotAFile {
            path: path.to_path_buf(),
            kind,
        }),
        None if size > allowed => Err(RecordingError::TooLarge {
            path: path.to_path_buf(),
            size,
            allowed,
        }),
        None => Ok(size),
    };
    let meta = std::fs::metadata(path).map_err(io)?;
    check(meta.file_type(), meta.len())?;
    let file: File = OpenOptions::new()
        .read(true)
        .custom_flags(libc::O_NONBLOCK | libc::O_NOCTTY)
        .open(path)
        .map_err(io)?;
    let meta = file.metadata().map_err(io)?;
    let size = check(meta.file_type(), meta.len())?;
    // At most `allowed`, which is at most MAX_FILE: it fits a usize on the 64-bit targets we build.
    let mut bytes = Vec::with_capacity(usize::try_from(size).unwrap_or(0));
    file.take(allowed.saturating_add(1))
        .read_to_end(&mut bytes)
        .map_err(io)?;
    let read = bytes.len() as u64;
    if read > allowed {
        return Err(RecordingError::TooLarge {
            path: path.to_path_buf(),
            size: read,
            allowed,
        });
    }
    Ok(bytes)
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(name: &str) -> std::path::PathBuf {
        let d = std::env::temp_dir().join(format!("pavlov-bounded-{name}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&d);
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn a_fifo_a_device_and_a_directory_are_refused_by_what_they_are() {
        let d = dir("kinds");
        let fifo = d.join("fifo");
        nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).unwrap();
        let zero = d.join("zero");
        std::os::unix::fs::symlink("/dev/zero", &zero).unwrap();
        for (path, want) in [
            (&fifo, "a FIFO"),
            (&zero, "a character device"),
            (&d, "a directory"),
        ] {
            let err = read(path).unwrap_err();
            assert!(matches!(err, RecordingError::NotAFile { .. }), "{err}");
            assert!(err.to_string().contains(want), "{err}");
        }
        std::fs::remove_dir_all(&d).unwrap();
    }

    #[test]
    fn a_file_over_the_limit_is_refused_with_its_size() {
        let d = dir("size");
        let path = d.join("big");
        std::fs::write(&path, [7u8; 101]).unwrap();
        assert_eq!(read_at_most(&path, 101).unwrap().len(), 101);
        let err = read_at_most(&path, 100).unwrap_err();
        assert!(
            matches!(
                err,
                RecordingError::TooLarge {
                    size: 101,
                    allowed: 100,
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("is 101 bytes"), "{err}");
        std::fs::remove_dir_all(&d).unwrap();
    }
}

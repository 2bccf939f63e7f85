//! Horde checkpoints: `horde-<tick>.bin`, beside the run's `checkpoint-<tick>.json` of the same tick.
//!
//! A Horde at nexting scale holds 10⁷–10⁸ weights; as JSON numbers that would be gigabytes and minutes,
//! so its weights are written as they are in memory. The file is:
//!
//! ```text
//! "PAVLOV-HORDE\n"                  13 bytes, the magic
//! version                           u32, little-endian (1)
//! header length                     u64
//! header                            JSON: tick, precision, families, stopped, and each trace group's
//!                                   exact state without its weights (traces, epochs, previous tick)
//! weights                           each group's, feature-major, f32 or f64 little-endian (an
//!                                   Autostep group's weights, step sizes, h and v, a prediction at a
//!                                   time: `GroupState::value_count`)
//! checksum                          u64, FNV-1a of every byte before it
//! ```
//!
//! It is written to a hidden temporary file a few megabytes at a time (`super::paced_file`), fsynced
//! and renamed, so a crash leaves the old file or the
//! new one; a write that fails (a full disk) removes its temporary file again. A file cut short,
//! corrupted, of another precision or holding a non-finite weight is refused with a precise error.

use std::io::{BufReader, BufWriter, Read, Write};
use std::path::{Path, PathBuf};

use pavlov::learn::group::{GroupState, Weight};
use pavlov::learn::{FamilySpec, HordeSnapshot};
use serde::{Deserialize, Serialize};

use super::paced_file::{self, PacedFile};

const MAGIC: &[u8; 13] = b"PAVLOV-HORDE\n";
const VERSION: u32 = 1;
/// The largest header accepted (the families and each group's small state): 256 MiB.
const MAX_HEADER: u64 = 256 << 20;

/// Why a Horde checkpoint could not be read or written.
#[derive(Debug, thiserror::Error)]
pub enum HordeFileError {
    #[error("{0}")]
    Io(#[from] std::io::Error),
    #[error("not a Horde checkpoint (no PAVLOV-HORDE magic)")]
    NotAHordeFile,
    #[error("Horde checkpoint format {0} is not the {VERSION} this version reads")]
    Version(u32),
    #[error("Horde checkpoint header: {0}")]
    Header(String),
    #[error("the Horde checkpoint is cut short")]
    Truncated,
    #[error("the Horde checkpoint's checksum does not match: the file is corrupted")]
    Checksum,
    #[error("the Horde checkpoint holds {file} weights, this Horde {expected}")]
    Precision {
        file: String,
        expected: &'static str,
    },
    #[error("the Horde checkpoint holds a weight that is not finite")]
    NonFinite,
}

#[derive(Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Header {
    tick: u64,
    precision: String,
    families: Vec<FamilySpec>,
    stopped: u64,
    groups: Vec<GroupState>,
}

/// FNV-1a, 64 bits: a checksum against torn and corrupted files (not against tampering).
struct Fnv(u64);

impl Fnv {
    fn new() -> Self {
        Fnv(0xcbf2_9ce4_8422_2325)
    }
    fn update(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.0 ^= u64::from(b);
            self.0 = self.0.wrapping_mul(0x0100_0000_01b3);
        }
    }
}

/// A writer that checksums what passes through.
struct Summed<T> {
    inner: T,
    sum: Fnv,
}

impl<T: Write> Write for Summed<T> {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        let n = self.inner.write(buf)?;
        self.sum.update(&buf[..n]);
        Ok(n)
    }
    fn flush(&mut self) -> std::io::Result<()> {
        self.inner.flush()
    }
}

/// The file name of the Horde checkpoint of lifelong tick `tick`.
pub(crate) fn file_name(tick: u64) -> String {
    format!("horde-{tick}.bin")
}

/// Writes `snapshot` of tick `tick` into `dir` atomically and returns its path.
pub fn write_atomic<W: Weight>(
    dir: &Path,
    tick: u64,
    snapshot: &HordeSnapshot<W>,
) -> Result<PathBuf, HordeFileError> {
    if snapshot
        .groups
        .iter()
        .any(|(_, w)| !w.iter().all(|v| v.finite()))
    {
        return Err(HordeFileError::NonFinite);
    }
    std::fs::create_dir_all(dir)?;
    let path = dir.join(file_name(tick));
    let tmp = dir.join(format!(".{}.tmp", file_name(tick)));
    let written = write_temporary(&tmp, tick, snapshot).and_then(|()| {
        std::fs::rename(&tmp, &path)?;
        Ok(())
    });
    if let Err(e) = written {
        match std::fs::remove_file(&tmp) {
            Ok(()) => {}
            Err(r) if r.kind() == std::io::ErrorKind::NotFound => {}
            Err(r) => tracing::warn!("cannot remove {}: {r}", tmp.display()),
        }
        return Err(e);
    }
    std::fs::File::open(dir)?.sync_all()?;
    Ok(path)
}

/// Writes `snapshot` of tick `tick` to `tmp` and fsyncs it.
fn write_temporary<W: Weight>(
    tmp: &Path,
    tick: u64,
    snapshot: &HordeSnapshot<W>,
) -> Result<(), HordeFileError> {
    let header = Header {
        tick,
        precision: W::NAME.into(),
        families: snapshot.families.clone(),
        stopped: snapshot.stopped,
        groups: snapshot.groups.iter().map(|(s, _)| s.clone()).collect(),
    };
    let json = serde_json::to_vec(&header).map_err(|e| HordeFileError::Header(e.to_string()))?;
    let file = PacedFile::new(std::fs::File::create(tmp)?, paced_file::STEP);
    let mut out = Summed {
        inner: BufWriter::with_capacity(1 << 20, file),
        sum: Fnv::new(),
    };
    out.write_all(MAGIC)?;
    out.write_all(&VERSION.to_le_bytes())?;
    out.write_all(&(json.len() as u64).to_le_bytes())?;
    out.write_all(&json)?;
    let mut chunk = Vec::with_capacity(1 << 20);
    for (_, weights) in &snapshot.groups {
        for block in weights.chunks((1 << 20) / W::BYTES) {
            chunk.clear();
            block.iter().for_each(|w| w.put_le(&mut chunk));
            out.write_all(&chunk)?;
        }
    }
    let sum = out.sum.0;
    let mut inner = out.inner;
    inner.write_all(&sum.to_le_bytes())?;
    let file = inner.into_inner().map_err(|e| e.into_error())?.into_file();
    file.sync_all()?;
    Ok(())
}

/// Reads exactly `buf.len()` bytes into the checksum, or says the file was cut short.
fn read_summed(r: &mut impl Read, sum: &mut Fnv, buf: &mut [u8]) -> Result<(), HordeFileError> {
    r.read_exact(buf).map_err(|e| match e.kind() {
        std::io::ErrorKind::UnexpectedEof => HordeFileError::Truncated,
        _ => HordeFileError::Io(e),
    })?;
    sum.update(buf);
    Ok(())
}

/// Reads a Horde checkpoint of weights `W`: its tick and snapshot (restore checks it fits the Horde).
pub fn read<W: Weight>(path: &Path) -> Result<(u64, HordeSnapshot<W>), HordeFileError> {
    let mut r = BufReader::with_capacity(1 << 20, std::fs::File::open(path)?);
    let mut sum = Fnv::new();
    let mut magic = [0; 13];
    read_summed(&mut r, &mut sum, &mut magic).map_err(|_| HordeFileError::NotAHordeFile)?;
    if &magic != MAGIC {
        return Err(HordeFileError::NotAHordeFile);
    }
    let mut word = [0; 4];
    read_summed(&mut r, &mut sum, &mut word)?;
    let version = u32::from_le_bytes(word);
    if version != VERSION {
        return Err(HordeFileError::Version(version));
    }
    let mut long = [0; 8];
    read_summed(&mut r, &mut sum, &mut long)?;
    let len = u64::from_le_bytes(long);
    if len > MAX_HEADER {
        return Err(HordeFileError::Header(format!(
            "{len} bytes is more than {MAX_HEADER}"
        )));
    }
    let mut json = vec![0; len as usize];
    read_summed(&mut r, &mut sum, &mut json)?;
    let header: Header =
        serde_json::from_slice(&json).map_err(|e| HordeFileError::Header(e.to_string()))?;
    if header.precision != W::NAME {
        return Err(HordeFileError::Precision {
            file: header.precision,
            expected: W::NAME,
        });
    }
    let mut groups = Vec::with_capacity(header.groups.len());
    let mut chunk = vec![0u8; 1 << 20];
    for state in header.groups {
        // The weights, and an Autostep group's step sizes, h and v.
        let count = state.value_count();
        let mut weights = Vec::with_capacity(count.min(1 << 28));
        let mut left = count;
        while left > 0 {
            let n = left.min(chunk.len() / W::BYTES);
            let bytes = &mut chunk[..n * W::BYTES];
            read_summed(&mut r, &mut sum, bytes)?;
            weights.extend(bytes.chunks_exact(W::BYTES).map(W::get_le));
            left -= n;
        }
        if !weights.iter().all(|w| w.finite()) {
            return Err(HordeFileError::NonFinite);
        }
        groups.push((state, weights));
    }
    let expected = sum.0;
    let mut stored = [0; 8];
    r.read_exact(&mut stored)
        .map_err(|_| HordeFileError::Truncated)?;
    if u64::from_le_bytes(stored) != expected {
        return Err(HordeFileError::Checksum);
    }
    let mut rest = [0; 1];
    if r.read(&mut rest)? != 0 {
        return Err(HordeFileError::Checksum);
    }
    Ok((
        header.tick,
        HordeSnapshot {
            families: header.families,
            groups,
            stopped: header.stopped,
        },
    ))
}

/// The Horde checkpoints in `dir`, oldest first.
pub(crate) fn list(dir: &Path) -> std::io::Result<Vec<(u64, PathBuf)>> {
    let mut found: Vec<(u64, PathBuf)> = Vec::new();
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let name = entry.file_name();
        let tick = name
            .to_str()
            .and_then(|n| n.strip_prefix("horde-")?.strip_suffix(".bin"))
            .filter(|t| !t.is_empty() && t.bytes().all(|b| b.is_ascii_digit()))
            .and_then(|t| t.parse().ok());
        if let Some(tick) = tick {
            found.push((tick, entry.path()));
        }
    }
    found.sort();
    Ok(found)
}

/// The newest Horde checkpoint in `dir` (the folder of a run), if any.
pub(crate) fn newest_in(dir: &Path) -> Option<PathBuf> {
    list(dir).ok()?.pop().map(|(_, path)| path)
}

/// Deletes this run's Horde checkpoints beyond the newest `keep`.
pub(crate) fn prune(dir: &Path, keep: usize) -> std::io::Result<()> {
    let found = list(dir)?;
    let excess = found.len().saturating_sub(keep.max(1));
    for (_, path) in found.into_iter().take(excess) {
        std::fs::remove_file(path)?;
    }
    Ok(())
}

#[cfg(test)]
mod tests;

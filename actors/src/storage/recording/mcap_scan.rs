//! Walks the records of an MCAP file held in memory, trusting none of its lengths: every record length,
//! every chunk's sizes and what its compressed bytes actually inflate to are checked against the file
//! and against the limits below before anything is allocated or decompressed.
//!
//! The layout read (MCAP's): the magic, then records, each a 1-byte opcode, a `u64` little-endian
//! length and the body. A chunk's body is its message start and end times (`u64` each), its
//! uncompressed size (`u64`) and CRC (`u32`), its compression (a `u32`-prefixed string) and its records
//! (`u64`-prefixed bytes), which hold records laid out the same way. After the footer comes the magic
//! again.
//!
//! A file that ends early — inside a record, or before the footer and the closing magic — is torn, not
//! an error: a recorder killed mid-write leaves one, and every complete chunk before the cut is read.
//! A length no writer of ours could have written (over [`MAX_RECORD`]) is not a cut but damage or a
//! crafted file, and is refused, as is a chunk that claims more than [`MAX_CHUNK`] uncompressed, one
//! whose claims would take the file past its decompression budget ([`decompression_budget`]), one whose
//! compressed bytes inflate to more (or less) than it claims, or one whose CRC does not match.
//!
//! The limits are far above what the recorder writes (chunks of about 256 KiB, the largest single
//! record the learner's state, a few MiB at most) and low enough that reading a crafted file of a few
//! kilobytes never needs more than a few hundred MiB.

use std::fmt;
use std::io::Read;

use super::RecordingError;
use super::mcap_fields::{FieldError, Fields};

/// The largest record body accepted (256 MiB): in the file, and inside a chunk. A record that claims
/// more is refused without reading further; one that claims no more but runs past the file's end is a
/// cut.
pub const MAX_RECORD: u64 = 256 << 20;
/// The largest uncompressed size a chunk may claim (256 MiB; the recorder writes 256 KiB).
pub const MAX_CHUNK: u64 = 256 << 20;
/// The decompression ratio a whole file may reach: its chunks may claim at most this many times the
/// file's length, uncompressed, plus [`RATIO_ALLOWANCE`].
pub const MAX_RATIO: u64 = 1024;
/// What the chunks of any file may claim beyond [`MAX_RATIO`] times its length (64 MiB): a small
/// recording whose learner state is mostly zeros compresses better than 1024:1 (zstd packs 16 MB of
/// `0.0,` into 1.5 kB), and is still read.
pub const RATIO_ALLOWANCE: u64 = 64 << 20;

/// The largest zstd window a chunk's frames may ask the decoder to allocate: 2^24 bytes (16 MiB), where
/// zstd's own default would allow 128 MiB. The recorder's level 1 uses 2^19; zstd's levels up to 19 stay
/// within 2^23.
pub const MAX_WINDOW_LOG: u32 = 24;

/// The MCAP magic, at both ends of a file.
pub(crate) const MAGIC: &[u8; 8] = b"\x89MCAP0\r\n";

/// The opcodes the reader acts on.
pub(crate) mod op {
    /// The footer: the last record before the closing magic.
    pub const FOOTER: u8 = 0x02;
    /// A channel: its id and topic.
    pub const CHANNEL: u8 = 0x04;
    /// A message on a channel.
    pub const MESSAGE: u8 = 0x05;
    /// A chunk of (compressed) records.
    pub const CHUNK: u8 = 0x06;
    /// A named map of strings.
    pub const METADATA: u8 = 0x0C;
}

/// The bytes of all chunks of a file of `file_len` bytes may claim uncompressed, together:
/// [`MAX_RATIO`] times its length, plus [`RATIO_ALLOWANCE`].
pub fn decompression_budget(file_len: usize) -> u64 {
    (file_len as u64)
        .saturating_mul(MAX_RATIO)
        .saturating_add(RATIO_ALLOWANCE)
}

/// Where a record begins: its opcode's byte offset in the file, or in the records of a chunk.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Place {
    /// At this byte offset of the file.
    File(u64),
    /// At byte `at` of the (decompressed) records of the chunk whose opcode is at byte `chunk`.
    Chunk {
        /// The chunk's offset in the file.
        chunk: u64,
        /// The offset inside its records.
        at: u64,
    },
}

impl fmt::Display for Place {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            Place::File(at) => write!(f, "byte {at}"),
            Place::Chunk { chunk, at } => {
                write!(f, "byte {at} of the records of the chunk at byte {chunk}")
            }
        }
    }
}

/// One record handed to the caller: its opcode, body and place.
pub(crate) struct RawRecord<'a> {
    /// The opcode.
    pub opcode: u8,
    /// The body (the length checked).
    pub body: &'a [u8],
    /// Where it begins.
    pub at: Place,
}

/// How the file ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum End {
    /// With its footer and closing magic.
    Whole,
    /// Early: inside a record, or before the footer (the writer was stopped).
    Torn,
}

/// The opcode and length of each record, and the record header's size.
const RECORD_HEAD: usize = 1 + 8;

/// A record's opcode and claimed body length, if `bytes` holds a whole record head.
fn head(bytes: &[u8]) -> Option<(u8, u64)> {
    let head = bytes.get(..RECORD_HEAD)?;
    let mut len = [0; 8];
    len.copy_from_slice(&head[1..]);
    Some((head[0], u64::from_le_bytes(len)))
}

fn malformed(at: Place, opcode: u8, message: impl ToString) -> RecordingError {
    RecordingError::Malformed {
        at,
        opcode,
        message: message.to_string(),
    }
}

fn field(at: Place, opcode: u8) -> impl Fn(FieldError) -> RecordingError {
    move |e| malformed(at, opcode, e)
}

/// Hands every record of the MCAP file `bytes` to `visit`, in file order, opening each chunk (the
/// records inside it are handed over once the whole chunk is checked, never a chunk's first records
/// before its CRC). Stops at the first error, of the file or of `visit`.
pub(crate) fn scan(
    bytes: &[u8],
    mut visit: impl FnMut(RawRecord<'_>) -> Result<(), RecordingError>,
) -> Result<End, RecordingError> {
    if !bytes.starts_with(MAGIC) {
        return Err(RecordingError::BadMcap(
            "the file does not begin with the MCAP magic".into(),
        ));
    }
    let mut budget = Budget {
        left: decompression_budget(bytes.len()),
        allowed: decompression_budget(bytes.len()),
    };
    let mut pos = MAGIC.len();
    loop {
        let rest = &bytes[pos..];
        let at = Place::File(pos as u64);
        let Some((opcode, len)) = head(rest) else {
            return Ok(End::Torn);
        };
        if len > MAX_RECORD {
            return Err(RecordingError::RecordTooLarge {
                at,
                opcode,
                claimed: len,
                allowed: MAX_RECORD,
            });
        }
        // At most MAX_RECORD, so it fits a usize.
        let len = len as usize;
        let Some(body) = rest[RECORD_HEAD..].get(..len) else {
            return Ok(End::Torn);
        };
        match opcode {
            op::CHUNK => chunk(body, at, &mut budget, &mut visit)?,
            op::FOOTER => {
                let after = &rest[RECORD_HEAD + len..];
                return match after.get(..MAGIC.len()) {
                    None if MAGIC.starts_with(after) => Ok(End::Torn),
                    Some(m) if m == MAGIC => Ok(End::Whole),
                    _ => Err(malformed(
                        at,
                        opcode,
                        "the footer is not followed by the MCAP magic",
                    )),
                };
            }
            _ => visit(RawRecord { opcode, body, at })?,
        }
        pos += RECORD_HEAD + len;
    }
}

/// What the chunks read so far have left of the file's decompression budget.
struct Budget {
    left: u64,
    allowed: u64,
}

/// Checks and opens one chunk, and hands its records to `visit`.
fn chunk(
    body: &[u8],
    at: Place,
    budget: &mut Budget,
    visit: &mut impl FnMut(RawRecord<'_>) -> Result<(), RecordingError>,
) -> Result<(), RecordingError> {
    let Place::File(chunk_at) = at else {
        return Err(malformed(at, op::CHUNK, "a chunk inside a chunk"));
    };
    let mut f = Fields::new(body);
    let err = field(at, op::CHUNK);
    f.u64("message start time").map_err(&err)?;
    f.u64("message end time").map_err(&err)?;
    let claimed = f.u64("uncompressed size").map_err(&err)?;
    let crc = f.u32("uncompressed CRC").map_err(&err)?;
    let compression = f.bytes_u32("compression").map_err(&err)?;
    let stored = f.bytes_u64("records").map_err(&err)?;
    if claimed > MAX_CHUNK {
        return Err(RecordingError::ChunkTooLarge {
            at,
            claimed,
            allowed: MAX_CHUNK,
        });
    }
    if claimed > budget.left {
        return Err(RecordingError::DecompressionBudget {
            at,
            claimed,
            left: budget.left,
            allowed: budget.allowed,
        });
    }
    budget.left -= claimed;
    let inflated;
    let records: &[u8] = match compression {
        b"" => {
            if stored.len() as u64 != claimed {
                return Err(malformed(
                    at,
                    op::CHUNK,
                    format!(
                        "an uncompressed chunk of {} bytes claims {claimed}",
                        stored.len()
                    ),
                ));
            }
            stored
        }
        b"zstd" => {
            inflated = unzstd(stored, claimed, at)?;
            &inflated
        }
        other => {
            let name: String = String::from_utf8_lossy(other).chars().take(32).collect();
            return Err(malformed(
                at,
                op::CHUNK,
                format!("unsupported compression `{name}` (pavlov writes zstd)"),
            ));
        }
    };
    if crc != 0 {
        let calculated = crc32fast::hash(records);
        if calculated != crc {
            return Err(malformed(
                at,
                op::CHUNK,
                format!("its records' CRC is {calculated:08x}, but the chunk says {crc:08x}"),
            ));
        }
    }
    let mut pos = 0;
    while pos < records.len() {
        let rest = &records[pos..];
        let inner = Place::Chunk {
            chunk: chunk_at,
            at: pos as u64,
        };
        let Some((opcode, len)) = head(rest) else {
            return Err(malformed(
                inner,
                0,
                format!(
                    "the chunk's records end {} bytes into a record's head",
                    rest.len()
                ),
            ));
        };
        let left = (rest.len() - RECORD_HEAD) as u64;
        if len > left {
            return Err(RecordingError::RecordTooLarge {
                at: inner,
                opcode,
                claimed: len,
                allowed: left,
            });
        }
        // At most what is left of the chunk, so it fits a usize.
        let len = len as usize;
        if opcode == op::CHUNK {
            return Err(malformed(inner, opcode, "a chunk inside a chunk"));
        }
        let body = &rest[RECORD_HEAD..RECORD_HEAD + len];
        visit(RawRecord {
            opcode,
            body,
            at: inner,
        })?;
        pos += RECORD_HEAD + len;
    }
    Ok(())
}

/// Inflates a zstd chunk's records through a reader that stops one byte past what the chunk claims, so a
/// small file that inflates to gigabytes costs at most `claimed + 1` bytes (already checked against the
/// limits) before it is refused. The buffer grows with what actually comes out, never from the claim
/// alone.
fn unzstd(compressed: &[u8], claimed: u64, at: Place) -> Result<Vec<u8>, RecordingError> {
    let zstd = |e: std::io::Error| malformed(at, op::CHUNK, format!("zstd: {e}"));
    let mut decoder = zstd::stream::read::Decoder::with_buffer(compressed).map_err(zstd)?;
    decoder.window_log_max(MAX_WINDOW_LOG).map_err(zstd)?;
    // A first guess from the bytes in hand; reading grows it as the output arrives.
    let guess = claimed.min(
        (compressed.len() as u64)
            .saturating_mul(8)
            .saturating_add(4096),
    );
    let mut out = Vec::with_capacity(usize::try_from(guess).unwrap_or(0));
    decoder
        .take(claimed.saturating_add(1))
        .read_to_end(&mut out)
        .map_err(zstd)?;
    let got = out.len() as u64;
    if got > claimed {
        return Err(RecordingError::Inflates { at, claimed });
    }
    if got < claimed {
        return Err(malformed(
            at,
            op::CHUNK,
            format!("its records inflate to {got} bytes, not the {claimed} it claims"),
        ));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A zstd frame asking for a window of 2^`log` bytes, holding `n` zeros in one RLE block.
    fn frame(log: u32, n: u32) -> Vec<u8> {
        let mut out = vec![0x28, 0xb5, 0x2f, 0xfd, 0x00, ((log - 10) << 3) as u8];
        out.extend_from_slice(&(1 | (1 << 1) | (n << 3)).to_le_bytes()[..3]);
        out.push(0);
        out
    }

    #[test]
    fn a_frame_asking_for_a_window_over_the_limit_is_refused_before_it_is_allocated() {
        let at = Place::File(8);
        assert_eq!(
            unzstd(&frame(MAX_WINDOW_LOG, 100), 100, at).unwrap(),
            [0; 100]
        );
        let err = unzstd(&frame(MAX_WINDOW_LOG + 3, 100), 100, at).unwrap_err();
        assert!(
            matches!(
                err,
                RecordingError::Malformed {
                    opcode: op::CHUNK,
                    ..
                }
            ),
            "{err}"
        );
        assert!(err.to_string().contains("zstd"), "{err}");
    }

    #[test]
    fn a_chunk_inflating_past_its_claim_or_short_of_it_is_refused() {
        let at = Place::File(8);
        assert!(matches!(
            unzstd(&frame(20, 1000), 999, at),
            Err(RecordingError::Inflates { claimed: 999, .. })
        ));
        let err = unzstd(&frame(20, 1000), 1001, at).unwrap_err();
        assert!(
            err.to_string()
                .contains("inflate to 1000 bytes, not the 1001"),
            "{err}"
        );
    }

    #[test]
    fn the_budget_grows_with_the_file() {
        assert_eq!(decompression_budget(0), RATIO_ALLOWANCE);
        assert_eq!(
            decompression_budget(1000),
            1000 * MAX_RATIO + RATIO_ALLOWANCE
        );
        assert_eq!(decompression_budget(usize::MAX), u64::MAX);
    }
}

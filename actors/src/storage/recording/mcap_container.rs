//! The MCAP container of a recording, written record by record: the same bytes the `mcap` crate's
//! writer gives for the options a recording is written with (zstd chunks finished whole and never
//! seeked back into, no message indexes, every summary group, every CRC), without its per-message
//! cost.
//!
//! Why not the `mcap` crate's writer: it writes a message as seven small writes through a CRC counter
//! into zstd's streaming compressor, and keeps its statistics in maps, which cost the recorder thread
//! more than compressing the bytes does (an experiment records about 50 000 ticks a second). Here a
//! message is appended to the open chunk's buffer (its body encoded in place by the caller), and the
//! chunk is compressed in one pass when it is finished; zstd is fed the same bytes with the same
//! parameters and no flush between them, so it writes the same frame. The test at the end writes a
//! recording both ways and compares every byte; the reader is `super::mcap_scan` (and any MCAP tool).
//!
//! The layout (<https://mcap.dev/spec>): the magic, a Header record, then the data section: chunks
//! (each holding schema, channel and message records) and Metadata records between them, then a
//! DataEnd record with the CRC of everything before it; then the summary section (every schema and
//! channel again, the Statistics, the chunk and metadata indexes, and the offsets of those groups),
//! the Footer with the summary's CRC, and the magic again. Every integer is little-endian; a string is
//! its length (u32) and its bytes; a map is its length in bytes (u32) and its entries.

use std::collections::BTreeMap;
use std::io::{self, Write};

use zstd::stream::raw::{CParameter, Encoder, InBuffer, Operation, OutBuffer};

/// The magic that opens and closes an MCAP file.
const MAGIC: &[u8] = &[0x89, b'M', b'C', b'A', b'P', 0x30, b'\r', b'\n'];

/// Record opcodes.
mod op {
    pub const HEADER: u8 = 0x01;
    pub const FOOTER: u8 = 0x02;
    pub const SCHEMA: u8 = 0x03;
    pub const CHANNEL: u8 = 0x04;
    pub const MESSAGE: u8 = 0x05;
    pub const CHUNK: u8 = 0x06;
    pub const CHUNK_INDEX: u8 = 0x08;
    pub const STATISTICS: u8 = 0x0B;
    pub const METADATA: u8 = 0x0C;
    pub const METADATA_INDEX: u8 = 0x0D;
    pub const SUMMARY_OFFSET: u8 = 0x0E;
    pub const DATA_END: u8 = 0x0F;
}

/// The compression named in every chunk.
const COMPRESSION: &str = "zstd";
/// A message record's header: channel (u16), sequence (u32), log and publish time (u64 each).
const MESSAGE_HEADER_LEN: u64 = 2 + 4 + 8 + 8;

fn put_u16(buf: &mut Vec<u8>, v: u16) {
    buf.extend_from_slice(&v.to_le_bytes());
}

fn put_u32(buf: &mut Vec<u8>, v: u32) {
    buf.extend_from_slice(&v.to_le_bytes());
}

fn put_u64(buf: &mut Vec<u8>, v: u64) {
    buf.extend_from_slice(&v.to_le_bytes());
}

/// A string's length, as MCAP writes it (u32).
fn str_len(s: &str) -> io::Result<u32> {
    u32::try_from(s.len())
        .map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "string too long"))
}

fn put_str(buf: &mut Vec<u8>, s: &str) -> io::Result<()> {
    put_u32(buf, str_len(s)?);
    buf.extend_from_slice(s.as_bytes());
    Ok(())
}

fn put_string_map(buf: &mut Vec<u8>, map: &BTreeMap<String, String>) -> io::Result<()> {
    let bytes: usize = map.iter().map(|(k, v)| 8 + k.len() + v.len()).sum();
    let bytes = u32::try_from(bytes)
        .map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "map too long"))?;
    put_u32(buf, bytes);
    for (k, v) in map {
        put_str(buf, k)?;
        put_str(buf, v)?;
    }
    Ok(())
}

/// Appends a record: its opcode, its length (u64) and the body `body` appends.
fn put_record(
    buf: &mut Vec<u8>,
    opcode: u8,
    body: impl FnOnce(&mut Vec<u8>) -> io::Result<()>,
) -> io::Result<()> {
    buf.push(opcode);
    let at = buf.len();
    put_u64(buf, 0);
    body(buf)?;
    let len = (buf.len() - at - 8) as u64;
    buf[at..at + 8].copy_from_slice(&len.to_le_bytes());
    Ok(())
}

/// A schema as written.
struct Schema {
    id: u16,
    name: String,
    encoding: String,
    data: Vec<u8>,
}

impl Schema {
    fn put(&self, buf: &mut Vec<u8>) -> io::Result<()> {
        put_record(buf, op::SCHEMA, |b| {
            put_u16(b, self.id);
            put_str(b, &self.name)?;
            put_str(b, &self.encoding)?;
            let len = u32::try_from(self.data.len())
                .map_err(|_| io::Error::new(io::ErrorKind::InvalidInput, "schema too long"))?;
            put_u32(b, len);
            b.extend_from_slice(&self.data);
            Ok(())
        })
    }
}

/// A channel as written.
struct Channel {
    id: u16,
    schema_id: u16,
    topic: String,
    message_encoding: String,
    metadata: BTreeMap<String, String>,
    /// Messages written on it.
    messages: u64,
}

impl Channel {
    fn put(&self, buf: &mut Vec<u8>) -> io::Result<()> {
        put_record(buf, op::CHANNEL, |b| {
            put_u16(b, self.id);
            put_u16(b, self.schema_id);
            put_str(b, &self.topic)?;
            put_str(b, &self.message_encoding)?;
            put_string_map(b, &self.metadata)
        })
    }
}

/// A finished chunk, as the summary indexes it.
struct ChunkIndex {
    bounds: (u64, u64),
    start: u64,
    length: u64,
    compressed_size: u64,
    uncompressed_size: u64,
}

/// A Metadata record, as the summary indexes it.
struct MetadataIndex {
    offset: u64,
    length: u64,
    name: String,
}

/// Widens `bounds` to take in `t`.
fn widen(bounds: &mut Option<(u64, u64)>, t: u64) {
    *bounds = Some(match *bounds {
        None => (t, t),
        Some((start, end)) => (start.min(t), end.max(t)),
    });
}

/// An MCAP file being written to `W`.
pub(crate) struct Container<W: Write> {
    /// The file (`None` once finished and handed back).
    out: Option<W>,
    /// Bytes written to `out` so far (where the next record starts).
    position: u64,
    /// The CRC of every byte of the data section so far (the magic included).
    data_crc: crc32fast::Hasher,
    /// The open chunk's records, uncompressed (`None`: no chunk is open).
    chunk: Option<OpenChunk>,
    /// The chunk buffer, kept between chunks.
    spare: Vec<u8>,
    /// The finished chunk's record, kept between chunks.
    record: Vec<u8>,
    /// The zstd context, kept between chunks (`None` before the first).
    zstd: Option<Encoder<'static>>,
    level: i32,
    /// A chunk is finished before a message once it holds more than this many bytes.
    chunk_size: u64,
    schemas: Vec<Schema>,
    channels: Vec<Channel>,
    chunk_indexes: Vec<ChunkIndex>,
    metadata_indexes: Vec<MetadataIndex>,
    /// The earliest and latest message log time.
    bounds: Option<(u64, u64)>,
    /// A write failed: the file is left as it is.
    failed: bool,
    /// The summary and footer are written.
    finished: bool,
}

/// The open chunk.
struct OpenChunk {
    /// Where the chunk's record will start in the file.
    start: u64,
    records: Vec<u8>,
    /// The earliest and latest message log time in it.
    bounds: Option<(u64, u64)>,
}

impl<W: Write> Container<W> {
    /// Starts a file on `out` (at offset `position` of it) with the magic and a Header record naming
    /// `profile` and `library`.
    pub(crate) fn create(
        out: W,
        position: u64,
        profile: &str,
        library: &str,
        chunk_size: u64,
        level: i32,
    ) -> io::Result<Self> {
        let mut c = Container {
            out: Some(out),
            position,
            data_crc: crc32fast::Hasher::new(),
            chunk: None,
            spare: Vec::new(),
            record: Vec::new(),
            zstd: None,
            level,
            chunk_size,
            schemas: Vec::new(),
            channels: Vec::new(),
            chunk_indexes: Vec::new(),
            metadata_indexes: Vec::new(),
            bounds: None,
            failed: false,
            finished: false,
        };
        let mut head = MAGIC.to_vec();
        put_record(&mut head, op::HEADER, |b| {
            put_str(b, profile)?;
            put_str(b, library)
        })?;
        c.write_data(&head)?;
        Ok(c)
    }

    /// The file, unless a write failed or the file is finished.
    fn out(&mut self) -> io::Result<&mut W> {
        match &mut self.out {
            Some(out) if !self.failed && !self.finished => Ok(out),
            _ => Err(failed_earlier()),
        }
    }

    /// Writes `bytes` to the file; after a failure, nothing more is written.
    fn write_out(&mut self, bytes: &[u8]) -> io::Result<()> {
        let result = self.out()?.write_all(bytes);
        self.failed = result.is_err();
        result
    }

    /// Writes `bytes` of the data section to the file.
    fn write_data(&mut self, bytes: &[u8]) -> io::Result<()> {
        self.write_out(bytes)?;
        self.data_crc.update(bytes);
        self.position += bytes.len() as u64;
        Ok(())
    }

    /// The open chunk, opened here if none is.
    fn chunk(&mut self) -> io::Result<&mut OpenChunk> {
        self.out()?;
        let start = self.position;
        let spare = &mut self.spare;
        Ok(self.chunk.get_or_insert_with(|| {
            let mut records = std::mem::take(spare);
            records.clear();
            OpenChunk {
                start,
                records,
                bounds: None,
            }
        }))
    }

    /// Adds a schema (into the open chunk, and the summary) and returns its id (1, 2, …).
    pub(crate) fn add_schema(
        &mut self,
        name: &str,
        encoding: &str,
        data: &[u8],
    ) -> io::Result<u16> {
        let schema = Schema {
            id: self.schemas.len() as u16 + 1,
            name: name.to_string(),
            encoding: encoding.to_string(),
            data: data.to_vec(),
        };
        schema.put(&mut self.chunk()?.records)?;
        let id = schema.id;
        self.schemas.push(schema);
        Ok(id)
    }

    /// Adds a channel without metadata (into the open chunk, and the summary) and returns its id
    /// (1, 2, …).
    pub(crate) fn add_channel(
        &mut self,
        schema_id: u16,
        topic: &str,
        message_encoding: &str,
    ) -> io::Result<u16> {
        let channel = Channel {
            id: self.channels.len() as u16 + 1,
            schema_id,
            topic: topic.to_string(),
            message_encoding: message_encoding.to_string(),
            metadata: BTreeMap::new(),
            messages: 0,
        };
        channel.put(&mut self.chunk()?.records)?;
        let id = channel.id;
        self.channels.push(channel);
        Ok(id)
    }

    /// Writes a Metadata record (after finishing the open chunk).
    pub(crate) fn write_metadata(
        &mut self,
        name: &str,
        metadata: &BTreeMap<String, String>,
    ) -> io::Result<()> {
        self.finish_chunk()?;
        let mut rec = Vec::new();
        put_record(&mut rec, op::METADATA, |b| {
            put_str(b, name)?;
            put_string_map(b, metadata)
        })?;
        let offset = self.position;
        self.write_data(&rec)?;
        self.metadata_indexes.push(MetadataIndex {
            offset,
            length: rec.len() as u64,
            name: name.to_string(),
        });
        Ok(())
    }

    /// Appends a message on `channel` (an id [`Container::add_channel`] returned) to the open chunk,
    /// its data appended by `data` (finishing the chunk first if it is full).
    pub(crate) fn message(
        &mut self,
        channel: u16,
        sequence: u32,
        log_time: u64,
        publish_time: u64,
        data: impl FnOnce(&mut Vec<u8>),
    ) -> io::Result<()> {
        let Some(c) = self.channels.get_mut(usize::from(channel).wrapping_sub(1)) else {
            return Err(io::Error::new(
                io::ErrorKind::InvalidInput,
                format!("message {sequence} on channel {channel}, which was never added"),
            ));
        };
        c.messages += 1;
        widen(&mut self.bounds, log_time);
        if self
            .chunk
            .as_ref()
            .is_some_and(|c| c.records.len() as u64 > self.chunk_size)
        {
            self.finish_chunk()?;
        }
        let chunk = self.chunk()?;
        widen(&mut chunk.bounds, log_time);
        let buf = &mut chunk.records;
        buf.push(op::MESSAGE);
        let at = buf.len();
        put_u64(buf, 0);
        put_u16(buf, channel);
        put_u32(buf, sequence);
        put_u64(buf, log_time);
        put_u64(buf, publish_time);
        let body = buf.len();
        data(buf);
        let len = MESSAGE_HEADER_LEN + (buf.len() - body) as u64;
        buf[at..at + 8].copy_from_slice(&len.to_le_bytes());
        Ok(())
    }

    /// Compresses the open chunk, if any, and writes its record whole.
    fn finish_chunk(&mut self) -> io::Result<()> {
        let Some(chunk) = self.chunk.take() else {
            return Ok(());
        };
        let result = self.write_chunk(&chunk);
        self.spare = chunk.records;
        // A chunk that could not be compressed or written is lost: nothing is written after it.
        self.failed |= result.is_err();
        result
    }

    /// Compresses `chunk` into its Chunk record (a zstd frame of its records, behind the header with
    /// its time bounds, sizes and the CRC of the uncompressed records), writes the record whole and
    /// indexes it for the summary.
    fn write_chunk(&mut self, chunk: &OpenChunk) -> io::Result<()> {
        let encoder = match &mut self.zstd {
            // Reset for a new frame, with the parameters kept.
            Some(e) => {
                e.reinit()?;
                e
            }
            None => {
                let mut e = Encoder::with_dictionary(self.level, &[])?;
                // Compressed on this thread.
                e.set_parameter(CParameter::NbWorkers(0))?;
                self.zstd.insert(e)
            }
        };
        let data = &chunk.records;
        let bounds = chunk.bounds.unwrap_or((0, 0));
        let mut rec = std::mem::take(&mut self.record);
        rec.clear();
        rec.push(op::CHUNK);
        put_u64(&mut rec, 0);
        put_u64(&mut rec, bounds.0);
        put_u64(&mut rec, bounds.1);
        put_u64(&mut rec, data.len() as u64);
        put_u32(&mut rec, crc32fast::hash(data));
        put_str(&mut rec, COMPRESSION)?;
        let size_at = rec.len();
        put_u64(&mut rec, 0);
        let frame = rec.len();
        // The whole chunk as one input without a flush, then the end of the frame: zstd compresses
        // full blocks as its window fills, whether the input comes in one piece or in many.
        rec.reserve(zstd::zstd_safe::compress_bound(data.len()) + 64);
        let mut input = InBuffer::around(data);
        while input.pos < data.len() {
            // The output goes after what `rec` holds, and `rec` grows to its end.
            let len = rec.len();
            encoder.run(&mut input, &mut OutBuffer::around_pos(&mut rec, len))?;
            if rec.capacity() - rec.len() < 1024 {
                rec.reserve(64 * 1024);
            }
        }
        loop {
            let len = rec.len();
            let remaining = encoder.finish(&mut OutBuffer::around_pos(&mut rec, len), false)?;
            if remaining == 0 {
                break;
            }
            rec.reserve(remaining.max(64 * 1024));
        }
        let compressed = (rec.len() - frame) as u64;
        rec[size_at..size_at + 8].copy_from_slice(&compressed.to_le_bytes());
        let record_len = (rec.len() - 9) as u64;
        rec[1..9].copy_from_slice(&record_len.to_le_bytes());
        let result = self.write_data(&rec);
        self.chunk_indexes.push(ChunkIndex {
            bounds,
            start: chunk.start,
            length: rec.len() as u64,
            compressed_size: compressed,
            uncompressed_size: data.len() as u64,
        });
        self.record = rec;
        result
    }

    /// Finishes the open chunk and flushes the file.
    pub(crate) fn flush(&mut self) -> io::Result<()> {
        self.finish_chunk()?;
        let result = self.out()?.flush();
        self.failed = result.is_err();
        result
    }

    /// Finishes the file and returns what it was written to.
    pub(crate) fn finish(mut self) -> io::Result<W> {
        self.close()?;
        self.out.take().ok_or_else(failed_earlier)
    }

    /// Finishes the open chunk, writes the DataEnd record, the summary, the footer and the closing
    /// magic, and flushes.
    fn close(&mut self) -> io::Result<()> {
        self.finish_chunk()?;
        let mut tail = Vec::new();
        let data_crc = self.data_crc.clone().finalize();
        put_record(&mut tail, op::DATA_END, |b| {
            put_u32(b, data_crc);
            Ok(())
        })?;
        let summary_start = self.position + tail.len() as u64;
        let mut offsets = Vec::new();
        let mut group = |tail: &mut Vec<u8>, opcode: u8, start: usize| {
            offsets.push((opcode, start, tail.len() - start));
        };
        let at = |tail: &Vec<u8>| tail.len();
        // Every schema and channel again.
        if !self.schemas.is_empty() {
            let start = at(&tail);
            for s in &self.schemas {
                s.put(&mut tail)?;
            }
            group(&mut tail, op::SCHEMA, start);
        }
        if !self.channels.is_empty() {
            let start = at(&tail);
            for c in &self.channels {
                c.put(&mut tail)?;
            }
            group(&mut tail, op::CHANNEL, start);
        }
        let start = at(&tail);
        let (first, last) = self.bounds.unwrap_or((0, 0));
        let counted: Vec<&Channel> = self.channels.iter().filter(|c| c.messages > 0).collect();
        put_record(&mut tail, op::STATISTICS, |b| {
            put_u64(b, counted.iter().map(|c| c.messages).sum());
            put_u16(b, self.schemas.len() as u16);
            put_u32(b, self.channels.len() as u32);
            // Attachments.
            put_u32(b, 0);
            put_u32(b, self.metadata_indexes.len() as u32);
            put_u32(b, self.chunk_indexes.len() as u32);
            put_u64(b, first);
            put_u64(b, last);
            put_u32(b, (counted.len() * (2 + 8)) as u32);
            for c in &counted {
                put_u16(b, c.id);
                put_u64(b, c.messages);
            }
            Ok(())
        })?;
        group(&mut tail, op::STATISTICS, start);
        if !self.chunk_indexes.is_empty() {
            let start = at(&tail);
            for i in &self.chunk_indexes {
                put_record(&mut tail, op::CHUNK_INDEX, |b| {
                    put_u64(b, i.bounds.0);
                    put_u64(b, i.bounds.1);
                    put_u64(b, i.start);
                    put_u64(b, i.length);
                    // No message indexes: an empty map, and their length 0.
                    put_u32(b, 0);
                    put_u64(b, 0);
                    put_str(b, COMPRESSION)?;
                    put_u64(b, i.compressed_size);
                    put_u64(b, i.uncompressed_size);
                    Ok(())
                })?;
            }
            group(&mut tail, op::CHUNK_INDEX, start);
        }
        if !self.metadata_indexes.is_empty() {
            let start = at(&tail);
            for i in &self.metadata_indexes {
                put_record(&mut tail, op::METADATA_INDEX, |b| {
                    put_u64(b, i.offset);
                    put_u64(b, i.length);
                    put_str(b, &i.name)
                })?;
            }
            group(&mut tail, op::METADATA_INDEX, start);
        }
        // Offsets in the file of what `tail` holds.
        let base = self.position;
        let summary_offset_start = base + at(&tail) as u64;
        for (opcode, start, length) in offsets {
            put_record(&mut tail, op::SUMMARY_OFFSET, |b| {
                b.push(opcode);
                put_u64(b, base + start as u64);
                put_u64(b, length as u64);
                Ok(())
            })?;
        }
        tail.push(op::FOOTER);
        put_u64(&mut tail, 8 + 8 + 4);
        put_u64(&mut tail, summary_start);
        put_u64(&mut tail, summary_offset_start);
        // The summary's CRC covers the summary and the footer up to the CRC itself.
        let summary_from = (summary_start - base) as usize;
        let summary_crc = crc32fast::hash(&tail[summary_from..]);
        put_u32(&mut tail, summary_crc);
        tail.extend_from_slice(MAGIC);
        self.write_out(&tail)?;
        let out = self.out()?;
        let result = out.flush();
        self.failed = result.is_err();
        self.finished = true;
        result
    }
}

/// A file dropped unfinished is finished, as the `mcap` crate's writer does (unless a write failed).
impl<W: Write> Drop for Container<W> {
    fn drop(&mut self) {
        if !self.finished && !self.failed && self.out.is_some() {
            let _ = self.close();
        }
    }
}

/// The error of every write after one failed.
fn failed_earlier() -> io::Error {
    io::Error::other("an earlier write to the recording failed")
}

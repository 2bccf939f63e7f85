//! Finishes a copy of a recording that may still be being written: every record of its complete chunks,
//! rewritten with the summary and footer that indexed readers (the `mcap` Python package's
//! `make_reader`, Foxglove) need.
//!
//! The live file is read linearly from its start, as far as it is on disk ([`super::mcap_read`] tolerates a
//! cut in the same way): a chunk is taken only once it is whole and its CRC matches, so the part of a
//! chunk the recorder is writing now is left out, never half-copied. The copy's schemas, channels,
//! metadata and messages are those of the live file, in its order; its chunks are compressed again by an
//! [`mcap::Writer`], which writes the summary (schemas, channels, statistics, chunk indexes) and the
//! footer. A live file that is already finished (its recording stopped) is copied up to the end of its
//! data section.
//!
//! [`Wait`] asks for the ticks up to a given one: while the file holds fewer, the copy waits for the
//! recorder's next flush (polling the file's length) for at most its patience, and then finishes with
//! what there is and says so ([`Copied::reached`]). The copy never writes to the live file and holds
//! no lock the recorder takes: the recorder never waits for it.

use std::collections::HashMap;
use std::fs::File;
use std::io::{Read, Seek, Write};
use std::path::{Path, PathBuf};
use std::time::{Duration, Instant};

use mcap::records::{MessageHeader, Record};
use mcap::sans_io::{LinearReadEvent, LinearReader, LinearReaderOptions};
use mcap::{Compression, McapError, WriteOptions};

use super::mcap_write::{CHUNK_SIZE, ZSTD_LEVEL};
use super::schema::{METADATA_NAME, TICKS};

/// The longest record (or decompressed chunk) the copy accepts: far above anything the recorder
/// writes (chunks of [`CHUNK_SIZE`], a learner's state of a few MB), and a bound on what one record can
/// make the copy allocate.
pub(crate) const RECORD_LIMIT: usize = 1 << 30;

/// Why a copy could not be finished.
#[derive(Debug, thiserror::Error)]
pub enum FinishError {
    /// The live file could not be opened or read.
    #[error("cannot read the recording {path}: {source}")]
    Read {
        /// The live file.
        path: PathBuf,
        /// The cause.
        source: std::io::Error,
    },
    /// The live file became shorter while it was read (it was replaced).
    #[error("the recording {0} became shorter while it was copied (was it replaced?)")]
    Shrank(PathBuf),
    /// The live file is damaged before its end, or is not MCAP.
    #[error("the recording {path} is not readable MCAP: {source}")]
    Damaged {
        /// The live file.
        path: PathBuf,
        /// What the reader found.
        source: McapError,
    },
    /// Writing the copy failed.
    #[error("cannot write the copy: {0}")]
    Write(McapError),
}

/// Which ticks the copy must hold, and how long it may wait for them.
#[derive(Debug, Clone, Copy)]
pub struct Wait {
    /// Every tick up to this one (`None`: whatever is on disk now).
    pub through_tick: Option<u64>,
    /// The longest wait for them to reach the disk.
    pub patience: Duration,
    /// How often the file's length is looked at while waiting.
    pub poll: Duration,
}

impl Wait {
    /// Only what is on disk now.
    #[cfg(test)]
    pub fn none() -> Self {
        Wait {
            through_tick: None,
            patience: Duration::ZERO,
            poll: Duration::ZERO,
        }
    }
}

/// What a finished copy holds.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct Copied {
    /// Tick messages.
    pub ticks: u64,
    /// Messages of every channel.
    pub messages: u64,
    /// The newest tick's `seq` (`None`: no tick).
    pub last_tick: Option<u64>,
    /// The last tick before the recording (its metadata's `start_after`; `None`: it began with the run).
    pub start_after: Option<u64>,
    /// Whether the live file was already finished (its recording had stopped).
    pub finished: bool,
    /// Whether the copy holds every tick [`Wait::through_tick`] asked for.
    pub reached: bool,
    /// Bytes of the live file read.
    pub read_bytes: u64,
}

impl Copied {
    /// Whether every tick up to `through` is in the copy (or was before the recording began).
    fn holds(&self, through: Option<u64>) -> bool {
        let Some(t) = through else { return true };
        self.finished
            || self.last_tick.is_some_and(|l| l >= t)
            || self.start_after.is_some_and(|a| a >= t)
    }
}

/// Just the `seq` field of a `pavlov.Tick` (prost skips the others).
#[derive(Clone, PartialEq, prost::Message)]
struct TickSeq {
    #[prost(uint64, tag = "1")]
    seq: u64,
}

/// The copy being written.
struct Copy<W: Write + Seek> {
    /// The output, until the live file's header says which profile the copy has.
    out: Option<W>,
    writer: Option<mcap::Writer<W>>,
    /// Live schema id → copy's.
    schemas: HashMap<u16, u16>,
    /// Live channel id → copy's, and whether it is the `ticks` channel.
    channels: HashMap<u16, (u16, bool)>,
    copied: Copied,
}

fn options(profile: &str) -> WriteOptions {
    WriteOptions::new()
        .compression(Some(Compression::Zstd))
        .compression_level(ZSTD_LEVEL)
        .compression_threads(0)
        .chunk_size(Some(CHUNK_SIZE))
        .emit_message_indexes(false)
        .profile(profile)
}

impl<W: Write + Seek> Copy<W> {
    fn writer(&mut self, profile: &str) -> Result<&mut mcap::Writer<W>, McapError> {
        if self.writer.is_none()
            && let Some(out) = self.out.take()
        {
            self.writer = Some(options(profile).create(out)?);
        }
        self.writer.as_mut().ok_or_else(|| McapError::UnexpectedEof)
    }

    /// Copies one record of the live file's data section; `false` at its end.
    fn take(&mut self, record: Record<'_>) -> Result<bool, McapError> {
        match record {
            Record::Header(h) => {
                self.writer(&h.profile)?;
            }
            // A schema or channel seen before (the same id) is not added twice.
            Record::Schema { header, data } if !self.schemas.contains_key(&header.id) => {
                let id = self
                    .writer("")?
                    .add_schema(&header.name, &header.encoding, &data)?;
                self.schemas.insert(header.id, id);
            }
            Record::Channel(c) if !self.channels.contains_key(&c.id) => {
                let schema = match c.schema_id {
                    0 => 0,
                    id => *self
                        .schemas
                        .get(&id)
                        .ok_or(McapError::UnknownSchema(c.topic.clone(), id))?,
                };
                let id = self.writer("")?.add_channel(
                    schema,
                    &c.topic,
                    &c.message_encoding,
                    &c.metadata,
                )?;
                self.channels.insert(c.id, (id, c.topic == TICKS));
            }
            Record::Message { header, data } => {
                let &(id, is_tick) =
                    self.channels
                        .get(&header.channel_id)
                        .ok_or(McapError::UnknownChannel(
                            header.sequence,
                            header.channel_id,
                        ))?;
                if is_tick {
                    // A tick that does not decode is copied all the same: the copy is the file, not a
                    // judgement of it.
                    if let Ok(t) = <TickSeq as prost::Message>::decode(data.as_ref()) {
                        self.copied.last_tick = Some(t.seq);
                    }
                    self.copied.ticks += 1;
                }
                self.copied.messages += 1;
                self.writer("")?.write_to_known_channel(
                    &MessageHeader {
                        channel_id: id,
                        ..header
                    },
                    &data,
                )?;
            }
            Record::Metadata(m) => {
                if m.name == METADATA_NAME {
                    self.copied.start_after =
                        m.metadata.get("start_after").and_then(|a| a.parse().ok());
                }
                self.writer("")?.write_metadata(&m)?;
            }
            Record::DataEnd(_) => {
                self.copied.finished = true;
                return Ok(false);
            }
            // Chunks arrive opened (their messages one by one); indexes and statistics are the
            // writer's to make; attachments are not in recordings.
            _ => {}
        }
        Ok(true)
    }

    /// Writes the summary and footer; returns the output.
    fn finish(mut self) -> Result<(W, Copied), McapError> {
        self.writer("pavlov")?;
        let Some(mut writer) = self.writer.take() else {
            return Err(McapError::UnexpectedEof);
        };
        writer.finish()?;
        let mut out = writer.into_inner();
        out.flush()?;
        Ok((out, self.copied))
    }
}

/// Copies the recording `live` (as far as it is on disk, or until it holds what `wait` asks for) to
/// `out` as a finished MCAP file. `stop` is asked while waiting: `true` ends the wait at once.
pub fn finish_copy<W: Write + Seek>(
    live: &Path,
    out: W,
    wait: &Wait,
    stop: &dyn Fn() -> bool,
) -> Result<(W, Copied), FinishError> {
    let read_err = |source| FinishError::Read {
        path: live.to_path_buf(),
        source,
    };
    let damaged = |source| FinishError::Damaged {
        path: live.to_path_buf(),
        source,
    };
    let mut file = File::open(live).map_err(read_err)?;
    let length = |file: &File| file.metadata().map(|m| m.len()).map_err(read_err);
    let mut available = length(&file)?;
    let mut reader = LinearReader::new_with_options(
        LinearReaderOptions::default()
            .with_prevalidate_chunk_crcs(true)
            .with_record_length_limit(RECORD_LIMIT),
    );
    let mut copy = Copy {
        out: Some(out),
        writer: None,
        schemas: HashMap::new(),
        channels: HashMap::new(),
        copied: Copied::default(),
    };
    let began = Instant::now();
    let mut fed: u64 = 0;
    while let Some(event) = reader.next_event() {
        match event.map_err(damaged)? {
            LinearReadEvent::ReadRequest(want) => {
                if fed < available {
                    let n = usize::try_from(available - fed).map_or(want, |left| left.min(want));
                    file.read_exact(reader.insert(n))
                        .map_err(|e| match e.kind() {
                            std::io::ErrorKind::UnexpectedEof => {
                                FinishError::Shrank(live.to_path_buf())
                            }
                            _ => read_err(e),
                        })?;
                    reader.notify_read(n);
                    fed += n as u64;
                    continue;
                }
                // Everything on disk is read: done, or wait for the recorder's next flush.
                if copy.copied.holds(wait.through_tick)
                    || began.elapsed() >= wait.patience
                    || stop()
                {
                    break;
                }
                std::thread::sleep(wait.poll.min(wait.patience.saturating_sub(began.elapsed())));
                available = length(&file)?;
                if available < fed {
                    return Err(FinishError::Shrank(live.to_path_buf()));
                }
            }
            LinearReadEvent::Record { opcode, data } => {
                let record = mcap::parse_record(opcode, data).map_err(damaged)?;
                if !copy.take(record).map_err(FinishError::Write)? {
                    break;
                }
            }
        }
    }
    // Reached only at the end of the data: the summary of a finished file is not copied.
    let reached = copy.copied.holds(wait.through_tick);
    let (out, mut copied) = copy.finish().map_err(FinishError::Write)?;
    copied.reached = reached;
    copied.read_bytes = fed;
    Ok((out, copied))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::storage::recording::mcap_write::McapSink;
    use crate::storage::recording::{RecordingHeader, StartState, parse_mcap};
    use pavlov::agent::LearningStage;
    use pavlov::config::Config;
    use pavlov::control::Mode;
    use pavlov::event::{Event, EventKind};
    use pavlov::record::TickRecord;
    use std::io::Cursor;

    fn header() -> RecordingHeader {
        let config = Config::from_toml(include_str!("../../../../config/stall.toml")).unwrap();
        let mut h = RecordingHeader::new(&config, "finish");
        h.start = Some(StartState {
            after: Some(9),
            events_before: 0,
            learner: LearningStage::new(&config).unwrap().stage_snapshot(),
        });
        h
    }

    /// A live recording of ticks 10..10+n in `path`, a chunk finished every 25 ticks, never finished;
    /// returns the file's length after each flush.
    fn live(path: &Path, n: u64) -> Vec<u64> {
        let file = std::io::BufWriter::new(File::create(path).unwrap());
        let mut sink = McapSink::create(file, &header()).unwrap();
        let mut ends = vec![std::fs::metadata(path).unwrap().len()];
        for seq in 10..10 + n {
            sink.tick(&TickRecord::at_rest(
                seq,
                seq as f64 * 20.0,
                Mode::Pavlovian,
            ))
            .unwrap();
            if seq % 7 == 0 {
                let e = Event {
                    id: seq,
                    after: Some(seq),
                    kind: EventKind::WeightsReset,
                };
                sink.event(&e).unwrap();
            }
            if seq % 25 == 24 {
                sink.flush().unwrap();
                ends.push(std::fs::metadata(path).unwrap().len());
            }
        }
        // Dropped unfinished: the open chunk is lost, as in a kill.
        std::mem::forget(sink);
        ends
    }

    fn tmp(name: &str) -> PathBuf {
        std::env::temp_dir().join(format!("pavlov-finish-{name}-{}.mcap", std::process::id()))
    }

    fn copy(path: &Path, wait: &Wait) -> (Vec<u8>, Copied) {
        let (out, copied) = finish_copy(path, Cursor::new(Vec::new()), wait, &|| false).unwrap();
        (out.into_inner(), copied)
    }

    #[test]
    fn a_live_file_becomes_a_finished_copy_of_its_complete_chunks() {
        let path = tmp("live");
        let ends = live(&path, 100);
        let (bytes, copied) = copy(&path, &Wait::none());
        // The ticks of every flushed chunk: 10..=99 (the last 10 were never flushed).
        assert_eq!(copied.ticks, 90);
        assert_eq!(copied.last_tick, Some(99));
        assert_eq!(copied.start_after, Some(9));
        assert!(!copied.finished);
        assert!(copied.reached);
        assert_eq!(copied.read_bytes, *ends.last().unwrap());
        let rec = parse_mcap(&bytes).unwrap();
        assert!(!rec.torn_tail, "the copy has its footer");
        assert_eq!(rec.records.len(), 90);
        assert_eq!(rec.header.label, "finish");
        assert_eq!(rec.events.len(), 13);
        // The summary an indexed reader needs.
        let summary = mcap::read::Summary::read(&bytes).unwrap().unwrap();
        let stats = summary.stats.unwrap();
        assert_eq!(stats.message_count, 90 + 13 + 2);
        assert_eq!(summary.channels.len(), 4);
        assert!(!summary.chunk_indexes.is_empty());
        let _ = std::fs::remove_file(&path);
    }

    #[test]
    fn a_file_cut_inside_a_chunk_gives_the_chunks_before_it() {
        let path = tmp("cut");
        let ends = live(&path, 100);
        let whole = std::fs::read(&path).unwrap();
        // Cut in the middle of the third chunk of ticks.
        let cut = ((ends[2] + ends[3]) / 2) as usize;
        std::fs::write(&path, &whole[..cut]).unwrap();
        let (bytes, copied) = copy(&path, &Wait::none());
        assert_eq!(copied.ticks, 40, "ticks 10..=49");
        assert_eq!(copied.last_tick, Some(49));
        let rec = parse_mcap(&bytes).unwrap();
        assert!(!rec.torn_tail);
        assert_eq!(rec.records.last().map(|r| r.seq), Some(49));
        let _ = std::fs::remove_file(&path);
    }

    #[test]
    fn a_copy_waits_for_the_tick_it_needs_but_not_beyond_its_patience() {
        let path = tmp("wait");
        let ends = live(&path, 100);
        let whole = std::fs::read(&path).unwrap();
        // On disk: up to tick 49; tick 80 comes with the flushes written while the copy waits.
        std::fs::write(&path, &whole[..ends[2] as usize]).unwrap();
        let writer = {
            let path = path.clone();
            std::thread::spawn(move || {
                std::thread::sleep(Duration::from_millis(50));
                let mut f = File::options().append(true).open(&path).unwrap();
                f.write_all(&whole[ends[2] as usize..]).unwrap();
            })
        };
        let wait = Wait {
            through_tick: Some(80),
            patience: Duration::from_secs(60),
            poll: Duration::from_millis(5),
        };
        let (_, copied) = copy(&path, &wait);
        writer.join().unwrap();
        assert!(copied.reached);
        assert!(copied.last_tick.unwrap() >= 80, "{copied:?}");
        // A tick that never comes: the copy ends after its patience with what there is.
        let wait = Wait {
            through_tick: Some(1_000),
            patience: Duration::from_millis(30),
            poll: Duration::from_millis(5),
        };
        let (bytes, copied) = copy(&path, &wait);
        assert!(!copied.reached);
        assert_eq!(copied.last_tick, Some(99));
        assert!(!parse_mcap(&bytes).unwrap().torn_tail);
        let _ = std::fs::remove_file(&path);
    }

    #[test]
    fn a_finished_file_is_copied_to_the_end_of_its_data() {
        let path = tmp("finished");
        let file = std::io::BufWriter::new(File::create(&path).unwrap());
        let mut sink = McapSink::create(file, &header()).unwrap();
        for seq in 10..60 {
            sink.tick(&TickRecord::at_rest(
                seq,
                seq as f64 * 20.0,
                Mode::Pavlovian,
            ))
            .unwrap();
        }
        sink.finish().unwrap();
        let wait = Wait {
            through_tick: Some(1_000),
            patience: Duration::from_secs(60),
            poll: Duration::from_millis(5),
        };
        let (bytes, copied) = copy(&path, &wait);
        assert!(copied.finished);
        assert!(
            copied.reached,
            "a stopped recording has all it will ever have"
        );
        assert_eq!(copied.ticks, 50);
        let rec = parse_mcap(&bytes).unwrap();
        assert!(!rec.torn_tail);
        assert_eq!(rec.records.len(), 50);
        let _ = std::fs::remove_file(&path);
    }

    /// A measurement, not a check: copies the recording in `PAVLOV_FINISH_FILE` (cut by a byte, so it is
    /// read as a live file) into a temporary file and prints what the copy holds and how long it took.
    /// Run it under `/usr/bin/time -v` for the process's CPU time and peak memory:
    /// `PAVLOV_FINISH_FILE=… cargo test -p pavlov-actors --lib finish::tests::measure -- --ignored`.
    #[test]
    #[ignore = "a measurement: needs PAVLOV_FINISH_FILE"]
    fn measure_a_copy_of_a_long_recording() {
        let Some(source) = std::env::var_os("PAVLOV_FINISH_FILE") else {
            return;
        };
        let bytes = std::fs::read(&source).unwrap();
        let path = tmp("measure");
        std::fs::write(&path, &bytes[..bytes.len() - 1]).unwrap();
        drop(bytes);
        let out = std::io::BufWriter::new(File::create(tmp("measure-out")).unwrap());
        let began = Instant::now();
        let (out, copied) = finish_copy(&path, out, &Wait::none(), &|| false).unwrap();
        let took = began.elapsed();
        let len = out.into_inner().unwrap().metadata().unwrap().len();
        eprintln!(
            "copied {} ticks, {} messages, {} of {} bytes read, {len} bytes written in {took:?}",
            copied.ticks,
            copied.messages,
            copied.read_bytes,
            std::fs::metadata(&path).unwrap().len()
        );
        let _ = std::fs::remove_file(&path);
        let _ = std::fs::remove_file(tmp("measure-out"));
    }

    #[test]
    fn a_file_that_is_not_mcap_is_an_error_naming_it() {
        let path = tmp("not-mcap");
        std::fs::write(&path, b"{\"format\":\"pavlov-recording/2\"}\n").unwrap();
        let err =
            finish_copy(&path, Cursor::new(Vec::new()), &Wait::none(), &|| false).unwrap_err();
        assert!(matches!(err, FinishError::Damaged { .. }), "{err}");
        assert!(err.to_string().contains("not-mcap"), "{err}");
        let _ = std::fs::remove_file(&path);
    }
}

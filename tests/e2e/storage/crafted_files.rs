//! Crafted recordings against `pavlov replay` and `pavlov convert`, each run under a 256 MiB address-space
//! limit: a chunk claiming 6 GiB uncompressed, a record length of u64::MAX, a 32 KB zstd bomb that
//! inflates to 1 GiB (claiming its true size, a size under the chunk limit but past the file's
//! decompression budget, or a small size it overruns), a few kilobytes of compressed empty messages, a
//! FIFO and a symbolic link to `/dev/zero`. Each must end with a message naming the problem and a
//! non-zero exit status that is neither a panic (101) nor an abort (134); a hang is killed and fails the
//! test. A real recording replays under the same limit.

use std::ffi::OsStr;
use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::{TestDir, stall_config};

const PAVLOV: &str = env!("CARGO_BIN_EXE_pavlov");

/// The address space the commands get (KiB, for `ulimit -v`): 256 MiB.
const ADDRESS_SPACE_KIB: u64 = 256 * 1024;

/// How long a command may take before it is taken to hang (only a hang reaches it, even on a loaded
/// machine: each command reads a file of at most 50 kB).
const HANG: Duration = Duration::from_secs(180);

/// Runs `pavlov ARGS` under the address-space limit; its exit status (`None` when killed by a signal)
/// and its stdout and stderr. A command still running after [`HANG`] is killed and fails the test.
fn pavlov(args: &[&OsStr]) -> (Option<i32>, String) {
    let mut child = Command::new("sh")
        .arg("-c")
        .arg(format!(
            "ulimit -v {ADDRESS_SPACE_KIB} || exit 99; exec \"$0\" \"$@\""
        ))
        .arg(PAVLOV)
        .args(args)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run pavlov");
    let drain = |mut pipe: Box<dyn Read + Send>| {
        std::thread::spawn(move || {
            let mut text = String::new();
            let _ = pipe.read_to_string(&mut text);
            text
        })
    };
    let out = drain(Box::new(child.stdout.take().expect("stdout")));
    let err = drain(Box::new(child.stderr.take().expect("stderr")));
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait for pavlov") {
            break status;
        }
        if started.elapsed() > HANG {
            let _ = child.kill();
            let _ = child.wait();
            panic!("pavlov {args:?} still running after {HANG:?}: it hangs");
        }
        std::thread::sleep(Duration::from_millis(20));
    };
    let text = format!(
        "{}{}",
        out.join().expect("stdout"),
        err.join().expect("stderr")
    );
    (status.code(), text)
}

/// `replay` and `convert --to jsonl` on `path` each fail with a message containing `want`.
fn refused(dir: &Path, path: &Path, want: &str) {
    let out = dir.join(format!(
        "{}.jsonl",
        path.file_name().unwrap().to_string_lossy()
    ));
    let runs: [Vec<&OsStr>; 2] = [
        vec!["replay".as_ref(), path.as_os_str()],
        vec![
            "convert".as_ref(),
            path.as_os_str(),
            "--to".as_ref(),
            "jsonl".as_ref(),
            "--out".as_ref(),
            out.as_os_str(),
        ],
    ];
    for args in runs {
        let (code, text) = pavlov(&args);
        let what = format!("pavlov {args:?}: status {code:?}, output:\n{text}");
        assert!(
            matches!(code, Some(c) if c != 0 && c != 101 && c != 134),
            "{what}"
        );
        assert!(!text.contains("panicked"), "{what}");
        assert!(text.contains(want), "wanted {want:?}; {what}");
    }
    assert!(!out.exists(), "convert wrote {}", out.display());
}

/// A record: opcode, u64 length, body.
fn record(opcode: u8, body: &[u8]) -> Vec<u8> {
    let mut out = vec![opcode];
    out.extend_from_slice(&(body.len() as u64).to_le_bytes());
    out.extend_from_slice(body);
    out
}

fn string(out: &mut Vec<u8>, s: &str) {
    out.extend_from_slice(&(s.len() as u32).to_le_bytes());
    out.extend_from_slice(s.as_bytes());
}

/// The MCAP magic and a header record: how every MCAP file begins.
fn opening() -> Vec<u8> {
    let mut header = Vec::new();
    string(&mut header, "pavlov");
    string(&mut header, "crafted");
    let mut out = b"\x89MCAP0\r\n".to_vec();
    out.extend(record(0x01, &header));
    out
}

/// A chunk record claiming `claimed` bytes uncompressed, holding `records` compressed with zstd (no CRC).
fn zstd_chunk(claimed: u64, records: &[u8]) -> Vec<u8> {
    let mut body = Vec::new();
    body.extend_from_slice(&0u64.to_le_bytes());
    body.extend_from_slice(&0u64.to_le_bytes());
    body.extend_from_slice(&claimed.to_le_bytes());
    body.extend_from_slice(&0u32.to_le_bytes());
    string(&mut body, "zstd");
    body.extend_from_slice(&(records.len() as u64).to_le_bytes());
    body.extend_from_slice(records);
    record(0x06, &body)
}

/// A zstd frame of 8192 RLE blocks of 128 KiB of zeros: 32 774 bytes that inflate to 1 GiB (what zstd
/// itself writes for a long run of one byte, built here directly rather than by compressing a gigabyte).
fn zstd_bomb() -> Vec<u8> {
    const BLOCK: u32 = 128 << 10;
    const BLOCKS: u32 = 8192;
    // Magic; frame header: no content size, not single-segment; window 2^(10+7) = 128 KiB.
    let mut out = vec![0x28, 0xb5, 0x2f, 0xfd, 0x00, 7 << 3];
    for i in 0..BLOCKS {
        let last = u32::from(i + 1 == BLOCKS);
        // Block header: last flag, type 1 (RLE), size; then the one byte repeated.
        let head = last | (1 << 1) | (BLOCK << 3);
        out.extend_from_slice(&head.to_le_bytes()[..3]);
        out.push(0);
    }
    out
}

/// Counts the bytes written to it.
struct Count(u64);

impl std::io::Write for Count {
    fn write(&mut self, buf: &[u8]) -> std::io::Result<usize> {
        self.0 += buf.len() as u64;
        Ok(buf.len())
    }
    fn flush(&mut self) -> std::io::Result<()> {
        Ok(())
    }
}

fn write(dir: &Path, name: &str, bytes: &[u8]) -> PathBuf {
    let path = dir.join(name);
    std::fs::write(&path, bytes).expect("write the crafted file");
    path
}

#[test]
fn crafted_lengths_and_sizes_are_refused_with_the_claim_and_the_limit() {
    let dir = TestDir::new("crafted-lengths");

    // 48 kB of incompressible records in a chunk that claims 6 GiB.
    let mut noise = Vec::with_capacity(48 << 10);
    let mut x = 0x9e37_79b9_7f4a_7c15u64;
    while noise.len() < 48 << 10 {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        noise.extend_from_slice(&x.to_le_bytes());
    }
    let records = zstd::encode_all(&noise[..], 1).expect("compress");
    let mut file = opening();
    file.extend(zstd_chunk(6 << 30, &records));
    let path = write(&dir, "six-gib-chunk.mcap", &file);
    assert!(file.len() > 40_000 && file.len() < 60_000);
    refused(
        &dir,
        &path,
        "claims 6442450944 bytes uncompressed; at most 268435456 are allowed",
    );

    // A message record whose length is u64::MAX.
    let mut file = opening();
    file.push(0x05);
    file.extend_from_slice(&u64::MAX.to_le_bytes());
    file.extend_from_slice(&[0; 64]);
    let path = write(&dir, "u64-max-record.mcap", &file);
    refused(
        &dir,
        &path,
        "(opcode 0x05) claims 18446744073709551615 bytes; at most 268435456 are allowed",
    );
}

#[test]
fn a_few_kilobytes_of_compressed_empty_messages_are_not_read_as_a_million_ticks() {
    let dir = TestDir::new("crafted-flood");
    // A channel `ticks`, then 300 000 empty messages on it: 9.3 MB that zstd packs into a few kB.
    let mut channel = [9, 0, 0, 0].to_vec();
    string(&mut channel, "ticks");
    string(&mut channel, "protobuf");
    channel.extend_from_slice(&0u32.to_le_bytes());
    let mut records = record(0x04, &channel);
    let message = record(
        0x05,
        &[
            9, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0, 0,
        ],
    );
    for _ in 0..300_000 {
        records.extend_from_slice(&message);
    }
    let packed = zstd::encode_all(&records[..], 3).expect("compress");
    let mut file = opening();
    file.extend(zstd_chunk(records.len() as u64, &packed));
    assert!(file.len() < 20_000, "{} bytes", file.len());
    let path = write(&dir, "flood.mcap", &file);
    refused(
        &dir,
        &path,
        &format!("is one too many: a file of {} bytes may hold", file.len()),
    );
}

#[test]
fn a_zstd_bomb_is_refused_whatever_size_its_chunk_claims() {
    let dir = TestDir::new("crafted-bomb");
    let bomb = zstd_bomb();
    assert!(bomb.len() < 33 << 10, "{} bytes", bomb.len());
    let mut inflated = Count(0);
    zstd::stream::copy_decode(&bomb[..], &mut inflated).expect("a valid zstd frame");
    assert_eq!(inflated.0, 1 << 30, "the bomb inflates to 1 GiB");

    // Its true size: over the chunk limit.
    let mut file = opening();
    file.extend(zstd_chunk(1 << 30, &bomb));
    let path = write(&dir, "bomb-honest.mcap", &file);
    refused(
        &dir,
        &path,
        "claims 1073741824 bytes uncompressed; at most 268435456 are allowed",
    );

    // 200 MiB: under the chunk limit, but far past 1024 times the file's 33 kB plus 64 MiB.
    let mut file = opening();
    file.extend(zstd_chunk(200 << 20, &bomb));
    let path = write(&dir, "bomb-200-mib.mcap", &file);
    refused(&dir, &path, "claims 209715200 bytes uncompressed, but only");

    // 1 MiB: within every limit, and inflating past it is caught one byte after the claim.
    let mut file = opening();
    file.extend(zstd_chunk(1 << 20, &bomb));
    let path = write(&dir, "bomb-1-mib.mcap", &file);
    refused(
        &dir,
        &path,
        "inflates to more than the 1048576 bytes it claims",
    );
}

#[test]
fn a_fifo_and_a_link_to_dev_zero_are_refused_without_reading_them() {
    let dir = TestDir::new("crafted-kinds");
    // Named as the recorder names its file, in a recording directory: found, then refused.
    let fifo_dir = dir.join("fifo");
    std::fs::create_dir_all(&fifo_dir).unwrap();
    let fifo = fifo_dir.join("recording.mcap");
    nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).expect("mkfifo");
    refused(&dir, &fifo, "is a FIFO (named pipe), not a regular file");
    refused(
        &dir,
        &fifo_dir,
        "is a FIFO (named pipe), not a regular file",
    );

    let zero = dir.join("zero.mcap");
    std::os::unix::fs::symlink("/dev/zero", &zero).expect("symlink");
    refused(&dir, &zero, "is a character device, not a regular file");
}

#[test]
fn a_real_recording_replays_under_the_same_limit() {
    let dir = TestDir::new("crafted-control");
    let rec = dir.join("rec");
    let mut cfg = stall_config();
    cfg.sim.seed = 22;
    super::fixtures::record_plain(cfg, "control", &rec, 300);
    let (code, text) = pavlov(&["replay".as_ref(), rec.as_os_str()]);
    assert_eq!(code, Some(0), "{text}");
    assert!(text.contains("identical"), "{text}");
}

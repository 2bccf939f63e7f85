//! Shard files are untrusted: generated and mutated shard file bytes, fed to the reader and the merge, give
//! a shard file or an error, never a panic; and the reader refuses what is not a regular file, or is larger
//! than its limit, without blocking or reading it whole. The inputs are drawn from a fixed seed (the
//! crate's own generator, [`pavlov::rng::Rng`]), so a failure reproduces.

use std::path::{Path, PathBuf};

use pavlov::rng::Rng;
use serde_json::{Value, json};

use super::file::read_at_most;
use super::{MergeError, PlannedRun, SHARD_FORMAT, ShardFile, check_plan, merge, parse};

/// A valid shard file's JSON: slice `index` of `count` of 6 planned runs.
fn valid(index: usize, count: usize) -> Value {
    let positions: Vec<usize> = super::Shard { index, count }.range(6).collect();
    json!({
        "format": SHARD_FORMAT,
        "experiment": "stall",
        "shard": { "index": index, "count": count },
        "planned_runs": 6,
        "config": { "tick": { "period_ms": 20 } },
        "options": { "seed": 1, "runs_per_policy": 3, "threads": 1 },
        "wall_s": 0.5,
        "runs": positions.iter().map(|p| json!({ "index": p, "seed": 10 + p })).collect::<Vec<_>>(),
        "positions": positions,
    })
}

/// Values that break careless code: extremes of every JSON kind.
fn extreme(rng: &mut Rng) -> Value {
    let all = [
        json!(u64::MAX),
        json!(i64::MIN),
        json!(0),
        json!(-1),
        json!(1e308),
        json!(usize::MAX / 2),
        json!(""),
        json!("x".repeat(300)),
        json!(null),
        json!([]),
        json!({}),
        json!([u64::MAX, 0, 1]),
        json!(true),
    ];
    all[rng.below(all.len() as u64) as usize].clone()
}

/// Replaces one node of `v`, chosen at random, with an extreme value.
fn mutate_tree(v: &mut Value, rng: &mut Rng) {
    let children = match v {
        Value::Object(o) => o.len(),
        Value::Array(a) => a.len(),
        _ => 0,
    };
    if children == 0 || rng.chance(0.3) {
        *v = extreme(rng);
        return;
    }
    let k = rng.below(children as u64) as usize;
    let child = match v {
        Value::Object(o) => o.values_mut().nth(k),
        Value::Array(a) => a.get_mut(k),
        _ => None,
    };
    if let Some(c) = child {
        mutate_tree(c, rng);
    }
}

/// Flips, drops, inserts or cuts bytes of `bytes`.
fn mutate_bytes(bytes: &mut Vec<u8>, rng: &mut Rng) {
    for _ in 0..=rng.below(4) {
        if bytes.is_empty() {
            bytes.push(b'{');
        }
        let at = rng.below(bytes.len() as u64) as usize;
        match rng.below(4) {
            0 => bytes[at] ^= 1 << rng.below(8),
            1 => {
                bytes.remove(at);
            }
            2 => {
                let alphabet = b"{}[]\",:0123456789e-.\\u";
                bytes.insert(at, alphabet[rng.below(alphabet.len() as u64) as usize]);
            }
            _ => bytes.truncate(at),
        }
    }
}

/// Parses `bytes` as a shard file and, when it parses, merges it with a valid partner and checks the
/// result against a plan: each step may refuse, none may panic.
fn exercise(bytes: &[u8]) {
    let path = Path::new("fuzz/shard-0-of-2.json");
    let Ok(text) = std::str::from_utf8(bytes) else {
        return;
    };
    let Ok(file) = parse::<Value>(path, text) else {
        return;
    };
    let _ = file.describe();
    let partner: ShardFile<Value> = serde_json::from_value(valid(1, 2)).expect("the valid file");
    let alone = merge("stall", vec![(PathBuf::from("a"), file.clone())]);
    let pair = merge(
        "stall",
        vec![(PathBuf::from("a"), file), (PathBuf::from("b"), partner)],
    );
    for merged in [alone, pair].into_iter().flatten() {
        let key = |r: &Value| PlannedRun {
            index: r.get("index").and_then(Value::as_u64).unwrap_or(0) as usize,
            mode: "reactive",
            seeds: vec![("seed", r.get("seed").and_then(Value::as_u64).unwrap_or(0))],
        };
        let runs = merged
            .options
            .get("runs_per_policy")
            .and_then(Value::as_u64)
            .and_then(|n| usize::try_from(n).ok());
        let _ = check_plan(
            &merged.runs,
            &merged.sources,
            runs.and_then(|n| n.checked_mul(2)),
            "runs_per_policy",
            |i| PlannedRun {
                index: i,
                mode: "reactive",
                seeds: vec![("seed", 10 + i as u64)],
            },
            key,
        );
    }
}

#[test]
fn mutated_and_generated_shard_files_never_panic_the_reader_or_the_merge() {
    let mut rng = Rng::new(22);
    let base = valid(0, 2);
    assert!(
        parse::<Value>(Path::new("x"), &base.to_string()).is_ok(),
        "the base parses"
    );
    for _ in 0..3000 {
        let mut tree = base.clone();
        for _ in 0..=rng.below(3) {
            mutate_tree(&mut tree, &mut rng);
        }
        exercise(tree.to_string().as_bytes());
        let mut bytes = base.to_string().into_bytes();
        mutate_bytes(&mut bytes, &mut rng);
        exercise(&bytes);
        let noise: Vec<u8> = (0..rng.below(64)).map(|_| rng.below(256) as u8).collect();
        exercise(&noise);
    }
}

#[test]
fn a_huge_shard_count_is_refused_without_allocating_by_it() {
    let mut v = valid(0, 2);
    v["shard"]["count"] = json!(u64::MAX);
    let file: ShardFile<Value> = serde_json::from_value(v).expect("parses");
    let e = merge("stall", vec![(PathBuf::from("a"), file)])
        .expect_err("refused")
        .to_string();
    assert!(
        e.contains("missing shard(s) 1, 2, 3")
            && e.contains("more")
            && e.contains("1 shard file(s) given"),
        "{e}"
    );
}

#[test]
fn the_reader_takes_only_regular_files_within_its_limit() {
    let dir = std::env::temp_dir().join(format!("pavlov-shard-read-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("dir");
    let fifo = dir.join("shard-0-of-1.json");
    nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).expect("mkfifo");
    let e = read_at_most(&fifo, 100).expect_err("a FIFO");
    assert!(
        matches!(e, MergeError::NotRegular { kind: "a FIFO", .. }),
        "{e}"
    );
    let zero = dir.join("shard-1-of-2.json");
    std::os::unix::fs::symlink("/dev/zero", &zero).expect("symlink");
    let e = read_at_most(&zero, 100).expect_err("a device").to_string();
    assert!(e.contains("not a regular file (a character device)"), "{e}");
    let big = dir.join("big.json");
    std::fs::write(&big, [b' '; 101]).expect("write");
    let e = read_at_most(&big, 100).expect_err("too large").to_string();
    assert!(
        e.contains("101 bytes") && e.contains("the limit is 100 bytes"),
        "{e}"
    );
    assert_eq!(read_at_most(&big, 101).expect("within").len(), 101);
    let _ = std::fs::remove_dir_all(dir);
}

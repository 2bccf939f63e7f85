//! Sweeps in shards, through the real binary: a short stall study run whole and as 4 shards (one process
//! each, each writing into its own directory), merged with `pavlov experiment merge`, gives the same
//! summary, tables and figures, byte for byte, the wall-clock fields aside; and merge refuses missing,
//! repeated and mismatched shards naming what is wrong.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const PAVLOV: &str = env!("CARGO_BIN_EXE_pavlov");

fn tmp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("pavlov-{name}-{}", std::process::id()))
}

/// Runs `pavlov experiment stall` on the short study (2 runs per policy × 2.6 min: long enough that the
/// Figure 1 excerpt, drawn after 2.5 min, exists), with `extra` arguments.
fn stall(out: &Path, extra: &[&str]) -> Output {
    let run = Command::new(PAVLOV)
        .args([
            "experiment",
            "stall",
            "--runs",
            "2",
            "--minutes",
            "2.6",
            "--seed",
            "11",
            "--no-record",
            "--threads",
            "1",
            "--out",
        ])
        .arg(out)
        .args(extra)
        .output()
        .expect("pavlov experiment stall");
    assert!(
        run.status.success(),
        "{}",
        String::from_utf8_lossy(&run.stderr)
    );
    run
}

fn merge(dirs: &[PathBuf], out: &Path) -> Output {
    Command::new(PAVLOV)
        .args(["experiment", "merge"])
        .args(dirs)
        .arg("--out")
        .arg(out)
        .output()
        .expect("pavlov experiment merge")
}

/// summary.json without what differs between any two runs of the same study: wall-clock times and where
/// the results were written.
fn summary_without_wall_clock(dir: &Path) -> serde_json::Value {
    let text = std::fs::read_to_string(dir.join("summary.json")).expect("summary.json");
    let mut v: serde_json::Value = serde_json::from_str(&text).expect("summary parses");
    let o = v.as_object_mut().expect("an object");
    o.remove("wall_s");
    o.remove("speedup");
    let opts = o["options"].as_object_mut().expect("options");
    opts.remove("out");
    for run in o["runs"].as_array_mut().expect("runs") {
        run.as_object_mut().expect("a run").remove("wall_s");
    }
    v
}

#[test]
fn four_shards_merged_equal_the_unsharded_study() {
    let whole = tmp("shards-whole");
    stall(&whole, &[]);
    let shard_dirs: Vec<PathBuf> = (0..4).map(|i| tmp(&format!("shards-{i}"))).collect();
    for (i, dir) in shard_dirs.iter().enumerate() {
        let run = stall(dir, &["--shard", &format!("{i}/4")]);
        assert!(dir.join(format!("shard-{i}-of-4.json")).exists());
        assert!(
            !dir.join("summary.json").exists(),
            "a shard writes no summary"
        );
        assert!(String::from_utf8_lossy(&run.stdout).contains(&format!("shard {i}/4")));
    }
    // Given in another order than the shards' own.
    let mut given = shard_dirs.clone();
    given.reverse();
    let merged = tmp("shards-merged");
    let out = merge(&given, &merged);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );

    let (a, b) = (
        summary_without_wall_clock(&whole),
        summary_without_wall_clock(&merged),
    );
    assert_eq!(a["runs"].as_array().map(Vec::len), Some(4));
    assert_eq!(a, b, "the merged summary is the unsharded one");
    // The same bytes in every table and figure (Figure 1 included: the excerpts travel in the shards).
    for file in [
        "runs.csv",
        "windows.csv",
        "learning_curve.csv",
        "fig1_signals.csv",
        "fig1_push.svg",
        "fig2_bars.svg",
        "fig_learning_curve.svg",
    ] {
        let x = std::fs::read(whole.join(file)).expect(file);
        let y = std::fs::read(merged.join(file)).expect(file);
        assert!(x == y, "{file} differs");
    }
    assert!(
        std::fs::read_to_string(whole.join("fig1_signals.csv"))
            .expect("signals")
            .lines()
            .count()
            > 100,
        "the short study has a Figure 1 excerpt to compare"
    );

    // Refusals, each naming what is wrong.
    let err = |o: Output| {
        assert!(!o.status.success());
        String::from_utf8_lossy(&o.stderr).into_owned()
    };
    let e = err(merge(&shard_dirs[..3], &tmp("shards-bad")));
    assert!(e.contains("missing shard(s) 3 of 4"), "{e}");
    let e = err(merge(
        &[shard_dirs[0].clone(), shard_dirs[0].clone()],
        &tmp("shards-bad"),
    ));
    assert!(e.contains("shard 0/4 given twice"), "{e}");
    // A shard of another study (a different seed) among the right ones.
    let other = tmp("shards-other");
    std::fs::create_dir_all(&other).expect("dir");
    let file = shard_dirs[3].join("shard-3-of-4.json");
    let text = std::fs::read_to_string(&file).expect("shard file");
    let mut v: serde_json::Value = serde_json::from_str(&text).expect("parses");
    v["options"]["seed"] = serde_json::json!(12);
    std::fs::write(other.join("shard-3-of-4.json"), v.to_string()).expect("write");
    let mut mixed = shard_dirs[..3].to_vec();
    mixed.push(other.clone());
    let e = err(merge(&mixed, &tmp("shards-bad")));
    assert!(e.contains("options differ at options.seed"), "{e}");
    assert!(!tmp("shards-bad").join("summary.json").exists());

    for d in shard_dirs.iter().chain([&whole, &merged, &other]) {
        let _ = std::fs::remove_dir_all(d);
    }
}

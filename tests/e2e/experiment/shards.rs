//! Sweeps in shards, through the real binary: a short stall study run whole and as 4 shards, and a short
//! interaction study run whole and as 3 shards (one process each, each writing into its own directory),
//! merged with `pavlov experiment merge`, give the same summary, tables and figures, byte for byte, the
//! wall-clock fields aside; and merge refuses missing, repeated and mismatched shards (another study, another
//! experiment) naming what is wrong.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

const PAVLOV: &str = env!("CARGO_BIN_EXE_pavlov");

fn tmp(name: &str) -> PathBuf {
    std::env::temp_dir().join(format!("pavlov-{name}-{}", std::process::id()))
}

/// Runs `pavlov experiment <args…> --out OUT <extra…>` and checks it succeeded.
fn experiment(args: &[&str], out: &Path, extra: &[&str]) -> Output {
    let run = Command::new(PAVLOV)
        .arg("experiment")
        .args(args)
        .arg("--out")
        .arg(out)
        .args(extra)
        .output()
        .expect("pavlov experiment");
    assert!(
        run.status.success(),
        "{args:?} {extra:?}: {}",
        String::from_utf8_lossy(&run.stderr)
    );
    run
}

/// Runs `pavlov experiment stall` on the short study (2 runs per policy × 2.6 min: long enough that the
/// Figure 1 excerpt, drawn after 2.5 min, exists), with `extra` arguments.
fn stall(out: &Path, extra: &[&str]) -> Output {
    let args = [
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
    ];
    experiment(&args, out, extra)
}

/// Runs `pavlov experiment interaction` on a short study (2 runs per policy × 1 min, half-minute windows of
/// the time course), with `extra` arguments.
fn interaction(out: &Path, extra: &[&str]) -> Output {
    let args = [
        "interaction",
        "--runs",
        "2",
        "--minutes",
        "1",
        "--window",
        "0.5",
        "--seed",
        "4",
        "--no-record",
    ];
    experiment(&args, out, extra)
}

/// Runs `count` shards of a study with `run`, each into its own directory, and checks each wrote its shard
/// file and no summary; returns the directories.
fn run_shards(name: &str, count: usize, run: fn(&Path, &[&str]) -> Output) -> Vec<PathBuf> {
    let dirs: Vec<PathBuf> = (0..count).map(|i| tmp(&format!("{name}-{i}"))).collect();
    for (i, dir) in dirs.iter().enumerate() {
        let out = run(dir, &["--shard", &format!("{i}/{count}")]);
        assert!(dir.join(format!("shard-{i}-of-{count}.json")).exists());
        assert!(
            !dir.join("summary.json").exists(),
            "a shard writes no summary"
        );
        assert!(String::from_utf8_lossy(&out.stdout).contains(&format!("shard {i}/{count}")));
    }
    dirs
}

/// Merges `dirs` (in the reverse of the shards' own order) into a new directory, checks the merged study's
/// summary is `whole`'s but the wall-clock fields and that every one of `files` has the same bytes;
/// returns the merged directory.
fn merged_equals_whole(name: &str, dirs: &[PathBuf], whole: &Path, files: &[&str]) -> PathBuf {
    let mut given = dirs.to_vec();
    given.reverse();
    let merged = tmp(&format!("{name}-merged"));
    let out = merge(&given, &merged);
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let (a, b) = (
        summary_without_wall_clock(whole),
        summary_without_wall_clock(&merged),
    );
    assert_eq!(a["runs"].as_array().map(Vec::len), Some(4));
    assert_eq!(a, b, "the merged summary is the unsharded one");
    for file in files {
        let x = std::fs::read(whole.join(file)).expect(file);
        let y = std::fs::read(merged.join(file)).expect(file);
        assert!(x == y, "{file} differs");
    }
    merged
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
    // Provenance names the process (its command line differs); the configuration hash must not.
    let provenance = o
        .remove("provenance")
        .expect("the summary carries its provenance");
    assert!(
        provenance["commit"].is_string() && provenance["command_line"].is_array(),
        "{provenance}"
    );
    o.insert("config_sha256".into(), provenance["config_sha256"].clone());
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
    let shard_dirs = run_shards("shards", 4, stall);
    // The same bytes in every table and figure (Figure 1 included: the excerpts travel in the shards).
    let files = [
        "runs.csv",
        "windows.csv",
        "learning_curve.csv",
        "fig1_signals.csv",
        "fig1_push.svg",
        "fig2_bars.svg",
        "fig_learning_curve.svg",
        "fig1_push.png",
        "fig2_bars.png",
        "fig_learning_curve.png",
        "table.md",
        "table.csv",
    ];
    let merged = merged_equals_whole("shards", &shard_dirs, &whole, &files);
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

/// How many ticks each run of a shard file keeps for Figure 3.
fn records_kept(file: &Path) -> Vec<usize> {
    let text = std::fs::read_to_string(file).expect("shard file");
    let v: serde_json::Value = serde_json::from_str(&text).expect("parses");
    v["runs"]
        .as_array()
        .expect("runs")
        .iter()
        .map(|r| r["figure3"].as_array().map_or(0, Vec::len))
        .collect()
}

#[test]
fn three_interaction_shards_merged_equal_the_unsharded_study() {
    let whole = tmp("ishards-whole");
    interaction(&whole, &[]);
    let shard_dirs = run_shards("ishards", 3, interaction);
    let file = |i: usize| shard_dirs[i].join(format!("shard-{i}-of-3.json"));
    // 4 runs in 3 slices: runs 0 and 1 (the Figure 3 analogue's, which keep their 3000 ticks), then 2, then
    // 3 (which keep none).
    assert_eq!(records_kept(&file(0)), vec![3000, 3000]);
    assert_eq!(records_kept(&file(1)), vec![0]);
    assert_eq!(records_kept(&file(2)), vec![0]);
    let files = [
        "commands.csv",
        "aligned.csv",
        "curve.csv",
        "fig3_timing.svg",
        "fig4_aligned.svg",
        "fig_curve.svg",
        "fig3_timing.png",
        "fig4_aligned.png",
        "fig_curve.png",
        "table.md",
        "table.csv",
    ];
    let merged = merged_equals_whole("ishards", &shard_dirs, &whole, &files);
    let summary = summary_without_wall_clock(&whole);
    assert!(
        summary["aligned"].as_array().is_some_and(|p| !p.is_empty()),
        "the short study has aligned averages to compare"
    );

    // A stall shard among interaction shards: refused before any run is read, naming both files.
    let stall_dir = tmp("ishards-stall");
    stall(&stall_dir, &["--shard", "0/4"]);
    let bad = tmp("ishards-bad");
    let out = merge(&[shard_dirs[0].clone(), stall_dir.clone()], &bad);
    assert!(!out.status.success());
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(
        e.contains("experiments differ")
            && e.contains(&file(0).display().to_string())
            && e.contains(&stall_dir.join("shard-0-of-4.json").display().to_string()),
        "{e}"
    );
    assert!(!bad.join("summary.json").exists());

    for d in shard_dirs.iter().chain([&whole, &merged, &stall_dir]) {
        let _ = std::fs::remove_dir_all(d);
    }
}

#[test]
fn the_sensitivity_study_is_not_sharded() {
    let out = Command::new(PAVLOV)
        .args([
            "experiment",
            "interaction",
            "--sensitivity",
            "--shard",
            "0/2",
        ])
        .output()
        .expect("pavlov experiment interaction");
    assert!(!out.status.success());
    let e = String::from_utf8_lossy(&out.stderr);
    assert!(e.contains("--shard") && e.contains("--sensitivity"), "{e}");
}

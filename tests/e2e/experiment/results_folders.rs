//! Issue 22: results are never overwritten, through the real binary. A re-run keeps the earlier study (a new
//! default folder each time, `results/stall-latest` pointing to the newer); a non-empty `--out` is refused
//! naming `--force`; with `--force` the study writes only its own files and records beside the earlier
//! recordings, so a user's `runs/01-pavlovian/ticks.jsonl` survives; the shards of one study share a folder
//! but never replace a shard file without `--force`; a merge goes to a new folder too.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use crate::common::TestDir;

const PAVLOV: &str = env!("CARGO_BIN_EXE_pavlov");

/// The tiniest stall study: one run per policy of 3 simulated seconds.
const TINY: [&str; 8] = [
    "--runs",
    "1",
    "--minutes",
    "0.05",
    "--seed",
    "1",
    "--threads",
    "1",
];

/// Runs `pavlov experiment <args…>` in `cwd`.
fn pavlov(cwd: &Path, args: &[&str]) -> Output {
    Command::new(PAVLOV)
        .current_dir(cwd)
        .arg("experiment")
        .args(args)
        .output()
        .expect("pavlov experiment")
}

/// `pavlov experiment stall` on the tiny study with `extra` arguments.
fn stall(cwd: &Path, extra: &[&str]) -> Output {
    let mut args = vec!["stall"];
    args.extend(TINY);
    args.extend(extra);
    pavlov(cwd, &args)
}

fn ok(o: &Output) -> String {
    let stdout = String::from_utf8_lossy(&o.stdout).into_owned();
    assert!(
        o.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&o.stderr)
    );
    stdout
}

fn refused(o: &Output) -> String {
    assert!(!o.status.success(), "accepted");
    assert_eq!(o.status.code(), Some(1), "a clean refusal");
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// The folder a study's terminal output names (`results: DIR`).
fn results_of(stdout: &str) -> PathBuf {
    let line = stdout
        .lines()
        .find_map(|l| l.strip_prefix("results: "))
        .expect("a results line");
    PathBuf::from(line.split(" (").next().unwrap_or(line))
}

#[test]
fn a_rerun_keeps_the_earlier_study_and_latest_points_to_the_newer() {
    let cwd = TestDir::new("rerun");
    let first = results_of(&ok(&stall(&cwd, &["--no-record"])));
    let second_out = ok(&stall(&cwd, &["--no-record"]));
    let second = results_of(&second_out);
    assert_ne!(first, second, "a new folder each time");
    for dir in [&first, &second] {
        assert!(cwd.join(dir).join("summary.json").exists(), "{dir:?}");
        let name = dir.file_name().unwrap_or_default().to_string_lossy();
        assert!(
            name.starts_with("stall-") && name.contains("-seed1"),
            "{name}"
        );
    }
    let link = cwd.join("results").join("stall-latest");
    let target = std::fs::read_link(&link).expect("results/stall-latest is a symbolic link");
    assert!(target.is_relative(), "{target:?}");
    assert_eq!(Some(target.as_os_str()), second.file_name());
    assert!(
        link.join("summary.json").exists(),
        "the link leads to the study"
    );
    assert!(
        second_out.contains("latest: results/stall-latest"),
        "{second_out}"
    );
}

#[test]
fn a_non_empty_out_is_refused_naming_force_and_force_deletes_nothing() {
    let cwd = TestDir::new("force");
    let d = cwd.join("d");
    let d_arg = d.to_string_lossy().into_owned();
    ok(&stall(&cwd, &["--out", &d_arg]));
    let run = d.join("runs").join("01-pavlovian");
    let recording = std::fs::read(run.join("recording.mcap")).expect("the first recording");
    // The user converts a run's recording and keeps notes beside the study.
    std::fs::write(run.join("ticks.jsonl"), "the user's conversion\n").expect("write");
    std::fs::write(d.join("notes.txt"), "mine\n").expect("write");
    let summary = std::fs::read(d.join("summary.json")).expect("summary");

    let e = refused(&stall(&cwd, &["--out", &d_arg]));
    assert!(e.contains("is not empty") && e.contains("--force"), "{e}");
    assert_eq!(std::fs::read(d.join("summary.json")).ok(), Some(summary));

    ok(&stall(&cwd, &["--out", &d_arg, "--force"]));
    assert_eq!(
        std::fs::read_to_string(run.join("ticks.jsonl"))
            .ok()
            .as_deref(),
        Some("the user's conversion\n")
    );
    assert_eq!(
        std::fs::read_to_string(d.join("notes.txt")).ok().as_deref(),
        Some("mine\n")
    );
    assert_eq!(
        std::fs::read(run.join("recording.mcap")).ok(),
        Some(recording),
        "kept"
    );
    // The new study recorded beside, and says where.
    let beside = d.join("runs").join("01-pavlovian-2").join("recording.mcap");
    assert!(beside.exists());
    let v: serde_json::Value =
        serde_json::from_slice(&std::fs::read(d.join("summary.json")).expect("the new summary"))
            .expect("parses");
    assert_eq!(
        v["runs"][1]["recording"].as_str(),
        Some(beside.to_string_lossy().as_ref())
    );
}

#[test]
fn shards_share_a_folder_never_replace_a_shard_file_and_merge_into_a_new_one() {
    let cwd = TestDir::new("shared");
    let s = cwd.join("shards");
    let s_arg = s.to_string_lossy().into_owned();
    let shard = |i: &str, extra: &[&str]| {
        let mut args = vec!["--no-record", "--shard", i, "--out", &s_arg];
        args.extend(extra);
        stall(&cwd, &args)
    };
    ok(&shard("0/2", &[]));
    ok(&shard("1/2", &[]));
    let before = std::fs::read(s.join("shard-0-of-2.json")).expect("shard 0");
    let e = refused(&shard("0/2", &[]));
    assert!(
        e.contains("shard-0-of-2.json exists") && e.contains("--force"),
        "{e}"
    );
    assert_eq!(
        std::fs::read(s.join("shard-0-of-2.json")).ok(),
        Some(before)
    );
    ok(&shard("0/2", &["--force"]));

    // Merging into the non-empty shard folder is refused; by default it goes to a new folder.
    let e = refused(&pavlov(&cwd, &["merge", &s_arg, "--out", &s_arg]));
    assert!(e.contains("is not empty") && e.contains("--force"), "{e}");
    assert!(!s.join("summary.json").exists());
    let out = ok(&pavlov(&cwd, &["merge", &s_arg]));
    let link = cwd.join("results").join("stall-latest");
    assert!(link.join("summary.json").exists(), "{out}");
    assert!(out.contains("latest: results/stall-latest"), "{out}");
}

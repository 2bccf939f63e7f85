//! Issue 22: `experiment merge` on crafted shard files ends with a clear error, never a panic (101), an
//! abort (134) or a hang, within 256 MB of address space: a huge shard count, a FIFO and a link to
//! `/dev/zero` named like shards, and a shard whose run's seed or mode was altered.

use std::path::Path;
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use crate::common::TestDir;

const PAVLOV: &str = env!("CARGO_BIN_EXE_pavlov");

/// How long a merge may take before it is taken for hung and killed (far above what any of these takes;
/// nothing is asserted about the time, it only keeps a hang from hanging the suite).
const HUNG: Duration = Duration::from_secs(300);

/// Runs `pavlov experiment merge <args…>` under a 256 MB address-space limit, killed if it hangs; returns
/// its exit code and stderr, and checks it failed cleanly (not a panic, an abort or a signal).
fn merge_refused(cwd: &Path, args: &[&str]) -> String {
    let mut child = Command::new("sh")
        .current_dir(cwd)
        .arg("-c")
        .arg("ulimit -v 262144 && exec \"$0\" experiment merge \"$@\"")
        .arg(PAVLOV)
        .args(args)
        .stdout(Stdio::null())
        .stderr(Stdio::piped())
        .spawn()
        .expect("sh");
    let started = Instant::now();
    let status = loop {
        if let Some(status) = child.try_wait().expect("wait") {
            break status;
        }
        if started.elapsed() > HUNG {
            let _ = child.kill();
            let _ = child.wait();
            panic!("merge {args:?} hung");
        }
        std::thread::sleep(Duration::from_millis(50));
    };
    let mut stderr = String::new();
    if let Some(mut e) = child.stderr.take() {
        let _ = std::io::Read::read_to_string(&mut e, &mut stderr);
    }
    assert_eq!(status.code(), Some(1), "{args:?}: {status:?}\n{stderr}");
    stderr
}

/// A stall shard file `shard-0-of-1.json` of a tiny study (2 runs), written into `dir`.
fn real_shard(cwd: &Path, dir: &Path) -> serde_json::Value {
    let out = Command::new(PAVLOV)
        .current_dir(cwd)
        .args([
            "experiment",
            "stall",
            "--runs",
            "1",
            "--minutes",
            "0.05",
            "--seed",
            "5",
            "--threads",
            "1",
            "--no-record",
            "--shard",
            "0/1",
            "--out",
        ])
        .arg(dir)
        .output()
        .expect("pavlov");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let text = std::fs::read_to_string(dir.join("shard-0-of-1.json")).expect("the shard");
    serde_json::from_str(&text).expect("parses")
}

#[test]
fn a_huge_shard_count_is_refused_before_anything_is_sized_by_it() {
    let cwd = TestDir::new("merge-count");
    let file = cwd.join("shard-0-of-1.json");
    let crafted = serde_json::json!({
        "format": "pavlov-shard/2",
        "experiment": "stall",
        "shard": { "index": 0, "count": u64::MAX },
        "planned_runs": u64::MAX,
        "config": {},
        "options": {},
        "wall_s": 0.0,
        "positions": [],
        "runs": [],
    });
    std::fs::write(&file, crafted.to_string()).expect("write");
    let e = merge_refused(&cwd, &[&file.to_string_lossy()]);
    assert!(
        e.contains(&format!(
            "missing shard(s) 1, 2, 3, 4, 5, 6, 7, 8, 9, 10, … and {} more of {}",
            u64::MAX - 11,
            u64::MAX
        )) && e.contains("(1 shard file(s) given)"),
        "{e}"
    );
}

#[test]
fn a_fifo_named_like_a_shard_is_refused_not_waited_on() {
    let cwd = TestDir::new("merge-fifo");
    let fifo = cwd.join("shard-0-of-1.json");
    nix::unistd::mkfifo(&fifo, nix::sys::stat::Mode::S_IRWXU).expect("mkfifo");
    let e = merge_refused(&cwd, &[&cwd.to_string_lossy()]);
    assert!(
        e.contains(&format!(
            "{} is not a regular file (a FIFO)",
            fifo.display()
        )),
        "{e}"
    );
}

#[test]
fn a_link_to_dev_zero_named_like_a_shard_is_refused_unread() {
    let cwd = TestDir::new("merge-zero");
    let link = cwd.join("shard-0-of-1.json");
    std::os::unix::fs::symlink("/dev/zero", &link).expect("symlink");
    let e = merge_refused(&cwd, &[&link.to_string_lossy()]);
    assert!(
        e.contains(&format!(
            "{} is not a regular file (a character device)",
            link.display()
        )),
        "{e}"
    );
}

#[test]
fn a_run_with_an_altered_seed_or_mode_is_refused_against_the_plan() {
    let cwd = TestDir::new("merge-plan");
    let good = cwd.join("good");
    let mut shard = real_shard(&cwd, &good);
    let seed = shard["runs"][1]["result"]["seed"].as_u64().expect("a seed");

    let altered = cwd.join("seed");
    std::fs::create_dir_all(&altered).expect("dir");
    let mut v = shard.clone();
    v["runs"][1]["result"]["seed"] = serde_json::json!(seed ^ 1);
    std::fs::write(altered.join("shard-0-of-1.json"), v.to_string()).expect("write");
    let e = merge_refused(&cwd, &[&altered.to_string_lossy()]);
    assert!(
        e.contains(&format!(
            "the run at position 1 has seed {}, but the study's options plan seed {seed} there",
            seed ^ 1
        )),
        "{e}"
    );

    let altered = cwd.join("mode");
    std::fs::create_dir_all(&altered).expect("dir");
    shard["runs"][0]["result"]["mode"] = shard["runs"][1]["result"]["mode"].clone();
    std::fs::write(altered.join("shard-0-of-1.json"), shard.to_string()).expect("write");
    let e = merge_refused(&cwd, &[&altered.to_string_lossy()]);
    assert!(
        e.contains(
            "the run at position 0 has mode pavlovian, but the study's options plan mode reactive"
        ),
        "{e}"
    );
    assert!(!cwd.join("results").exists(), "nothing written");

    // The unaltered shard merges under the same limit.
    let out = Command::new("sh")
        .current_dir(cwd.path())
        .arg("-c")
        .arg("ulimit -v 262144 && exec \"$0\" experiment merge \"$@\"")
        .arg(PAVLOV)
        .arg(&good)
        .output()
        .expect("sh");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
}

//! The stall experiment, short: 2 runs per policy × 1 minute through the real runtime under virtual time.
//! Same seed → same results; every run fully recorded; and the direction of the effects that the simulated
//! physics produces robustly (fewer over-current observations, stall events and less time stalled with the
//! Pavlovian control, at comparable distance).

use crate::common;

use pavlov::control::Mode;
use pavlov_actors::experiment::stall::analysis::TOTALS;
use pavlov_actors::experiment::stall::report::{self, StallStudy};
use pavlov_actors::experiment::stall::{self, StallOptions, plan, run_seed};

fn options(seed: u64, out: &std::path::Path, record: bool) -> StallOptions {
    StallOptions {
        runs_per_policy: 2,
        minutes: 1.0,
        seed,
        record,
        threads: 2,
        out: out.to_path_buf(),
    }
}

fn tmp(name: &str) -> std::path::PathBuf {
    std::env::temp_dir().join(format!("pavlov-{name}-{}", std::process::id()))
}

fn study(seed: u64, out: &std::path::Path, record: bool) -> StallStudy {
    stall::run_study(&common::stall_config(), &options(seed, out, record), false)
        .expect("study runs")
}

#[test]
fn the_plan_interleaves_policies_with_documented_seeds() {
    let specs = plan(&common::stall_config(), &options(9, &tmp("plan"), false));
    assert_eq!(specs.len(), 4);
    let modes: Vec<Mode> = specs.iter().map(|s| s.mode).collect();
    assert_eq!(
        modes,
        vec![
            Mode::Reactive,
            Mode::Pavlovian,
            Mode::Reactive,
            Mode::Pavlovian
        ]
    );
    for s in &specs {
        assert_eq!(s.seed, run_seed(9, s.index));
        assert_eq!(s.ticks, 3000);
    }
    let mut seeds: Vec<u64> = specs.iter().map(|s| s.seed).collect();
    seeds.dedup();
    assert_eq!(seeds.len(), 4, "every run has its own seed");
}

#[test]
fn a_short_study_is_deterministic_recorded_and_shows_the_effect() {
    let out = tmp("stall-a");
    let a = study(5, &out, true);
    let b = study(5, &tmp("stall-b"), false);
    // Same seed, same outcome (wall time aside), with or without recording.
    for (x, y) in a.runs.iter().zip(&b.runs) {
        assert_eq!((x.index, x.mode, x.seed), (y.index, y.mode, y.seed));
        assert_eq!(x.metrics, y.metrics);
        assert_eq!(x.windows, y.windows);
    }
    assert_eq!(a.analysis, b.analysis);

    // Every run recorded completely; nothing dropped or missed.
    for r in &a.runs {
        assert_eq!(r.recorded, 3000, "run {}", r.index);
        assert_eq!((r.recorder_dropped, r.lagged), (0, 0));
        let rec = pavlov_actors::storage::recording::load(r.recording.as_ref().expect("recorded"))
            .expect("recording reads back");
        assert_eq!(rec.records.len(), 3000);
        assert_eq!(rec.header.config.control.mode, r.mode);
        assert_eq!(rec.header.config.sim.seed, r.seed);
        // The metrics recomputed from the recording agree with the live ones.
        let mut m = pavlov::analysis::run_counters::RunCounters::new(20.0);
        rec.records.iter().for_each(|t| m.observe(t));
        assert_eq!(m.totals(), r.metrics);
    }

    // The effect: the Pavlovian control stops before the over-current integrator trips.
    let get = |key: &str| {
        a.analysis
            .comparisons
            .iter()
            .find(|c| c.metric == key)
            .expect("metric")
    };
    assert_eq!(a.analysis.comparisons.len(), TOTALS.len());
    for key in ["overcurrent_observations", "stall_events", "time_stalled_s"] {
        let c = get(key);
        assert!(
            c.pavlovian.mean < c.reactive.mean,
            "{key}: Pavlovian {:?} vs reactive {:?}",
            c.pavlovian,
            c.reactive
        );
    }
    assert!(get("distance_m").reactive.mean > 0.1, "the robot drives");

    // Outputs are written.
    report::write_all(&out, &a).expect("outputs");
    for f in [
        "summary.json",
        "runs.csv",
        "windows.csv",
        "learning_curve.csv",
        "fig2_bars.svg",
        "fig_learning_curve.svg",
    ] {
        let meta = std::fs::metadata(out.join(f)).expect(f);
        assert!(meta.len() > 50, "{f} is empty");
    }
    // Each figure as SVG and as a 300-dpi PNG of the same size, no translucency; the table beside them.
    for stem in ["fig1_push", "fig2_bars", "fig_learning_curve"] {
        super::figures::check_figure(&out, stem);
    }
    super::figures::check_tables(&out);
    let runs_csv = std::fs::read_to_string(out.join("runs.csv")).unwrap();
    assert_eq!(runs_csv.lines().count(), 5);
    let table = report::table(&a);
    assert!(table.contains("over-current observations"));
    // Every row of the comparison table starts its numbers in the same column as the header's "reactive".
    let mut lines = table.lines().skip(1);
    let header = lines.next().expect("header");
    let at = header.find("reactive").expect("reactive column");
    let end = header[..at].chars().count() + "reactive".len();
    for row in lines.take_while(|l| !l.starts_with("spread")) {
        let cells: Vec<char> = row.chars().collect();
        assert!(
            cells[end - 1].is_ascii_digit() && cells[end] == ' ',
            "misaligned row (column {end} of the header {header:?}): {row:?}"
        );
    }
    let _ = std::fs::remove_dir_all(&out);
}

#[test]
fn the_cli_writes_the_results_directory_and_its_recordings_replay() {
    let out = tmp("stall-cli");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_pavlov"))
        .args([
            "experiment",
            "stall",
            "--runs",
            "1",
            "--minutes",
            "0.5",
            "--seed",
            "2",
            "--out",
        ])
        .arg(&out)
        .output()
        .expect("pavlov experiment stall");
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    assert!(stdout.contains("over-current observations"), "{stdout}");
    assert!(out.join("summary.json").exists());
    let replay = std::process::Command::new(env!("CARGO_BIN_EXE_pavlov"))
        .arg("replay")
        .arg(out.join("runs").join("01-pavlovian"))
        .output()
        .expect("pavlov replay");
    assert!(replay.status.success());
    assert!(String::from_utf8_lossy(&replay.stdout).contains("identical"));
    let _ = std::fs::remove_dir_all(&out);
}

/// Issue 14: `--policies reactive,pavlovian,offpolicy` runs the three policies interleaved from one
/// command, writes the tables, and the off-policy run's recording (its gate on the GTD(λ) prediction)
/// replays exactly through the real binary; a bad list is refused with the name.
#[test]
fn the_three_way_study_runs_from_one_command_and_its_off_policy_run_replays() {
    let out = tmp("stall-policies");
    let run = std::process::Command::new(env!("CARGO_BIN_EXE_pavlov"))
        .args([
            "experiment",
            "stall",
            "--policies",
            "reactive,pavlovian,offpolicy",
            "--runs",
            "1",
            "--minutes",
            "0.5",
            "--out",
        ])
        .arg(&out)
        .output()
        .expect("pavlov experiment stall --policies");
    let stdout = String::from_utf8_lossy(&run.stdout);
    assert!(
        run.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&run.stderr)
    );
    for needle in [
        "| metric | reactive | pavlovian | offpolicy |",
        "offpolicy vs pavlovian",
        "RMSE off-policy `stall_pi`",
    ] {
        assert!(stdout.contains(needle), "no {needle:?} in {stdout}");
    }
    let study: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("policies.json")).unwrap()).unwrap();
    let runs = study["runs"].as_array().unwrap();
    let policies: Vec<&str> = runs.iter().map(|r| r["policy"].as_str().unwrap()).collect();
    assert_eq!(policies, ["reactive", "pavlovian", "offpolicy"]);
    // runs.csv names the off-policy runs as such (they share the Pavlovian mode).
    let csv = std::fs::read_to_string(out.join("runs.csv")).unwrap();
    let labels: Vec<&str> = csv
        .lines()
        .skip(1)
        .filter_map(|l| l.split(',').nth(1))
        .collect();
    assert_eq!(labels, ["reactive", "pavlovian", "offpolicy"]);
    assert!(runs.iter().all(|r| r["accuracy"].is_object()));
    let replay = std::process::Command::new(env!("CARGO_BIN_EXE_pavlov"))
        .arg("replay")
        .arg(out.join("runs").join("02-offpolicy"))
        .output()
        .expect("pavlov replay");
    assert!(replay.status.success());
    assert!(String::from_utf8_lossy(&replay.stdout).contains("identical"));
    let _ = std::fs::remove_dir_all(&out);

    let bad = std::process::Command::new(env!("CARGO_BIN_EXE_pavlov"))
        .args(["experiment", "stall", "--policies", "reactive,greedy"])
        .output()
        .expect("pavlov experiment stall --policies");
    assert!(!bad.status.success());
    assert!(
        String::from_utf8_lossy(&bad.stderr).contains("unknown policy `greedy`"),
        "{}",
        String::from_utf8_lossy(&bad.stderr)
    );
}

//! The `pavlov` binary's edge: bad configurations are refused at start-up with a message naming the key,
//! and `--help` explains the commands.

use std::process::Command;

use crate::common::TestDir;

const PAVLOV: &str = env!("CARGO_BIN_EXE_pavlov");

fn stall_toml() -> String {
    std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../config/stall.toml"))
        .expect("config/stall.toml")
}

/// Runs `pavlov serve` on `config`; its exit code (`None` when killed by a signal, e.g. an abort) and stderr.
fn serve_with(config: &str) -> (Option<i32>, String) {
    let dir = TestDir::new(&format!(
        "cli-{:x}",
        config.len() * 31 + config.bytes().map(usize::from).sum::<usize>()
    ));
    let path = dir.join("config.toml");
    std::fs::write(&path, config).expect("write config");
    let out = Command::new(PAVLOV)
        .args(["serve", "--bind", "127.0.0.1:0", "--config"])
        .arg(&path)
        .output()
        .expect("run pavlov");
    (
        out.status.code(),
        String::from_utf8_lossy(&out.stderr).into_owned(),
    )
}

#[test]
fn bad_configurations_name_the_key_and_stop_start_up() {
    let good = stall_toml();
    let cases = [
        ("lambda = 0.5", "lambda = 0.5\nlamda = 0.4", "lamda"),
        ("tau = 25.0", "tau = -3.0", "predictions[0]"),
        ("stream = [6]", "stream = [6, 6, 6]", "robot.stream"),
        ("mode = \"pavlovian\"", "mode = \"psychic\"", "psychic"),
        ("period_ms = 20", "period_ms = \"fast\"", "period_ms"),
        // Values that once made the robot unsafe or the process crash: each names its key and bound,
        // and the process exits with status 1 (a 2000 mm/s speed was clamped, a 4e9-tick timeout
        // disabled the stale-stream stop, 10⁸ tiles aborted with an allocation failure, status 134).
        (
            "default_policy = { kind = \"stall_cycle\" }",
            "default_policy = { kind = \"stall_cycle\", drive_mm_s = 2000 }",
            "control.default_policy.drive_mm_s: 2000 mm/s is outside the Drive Direct range -500..=500",
        ),
        (
            "max_obs_age_ticks = 5",
            "max_obs_age_ticks = 4000000000",
            "safety.max_obs_age_ticks: 4000000000 ticks is outside 1..=50",
        ),
        (
            "max_action_age_ticks = 3",
            "max_action_age_ticks = 4000000000",
            "safety.max_action_age_ticks: 4000000000 ticks is outside 1..=50",
        ),
        (
            "tiles = 10",
            "tiles = 100000000",
            "predictions[0] (stall).features.tiles: 100000000 is outside 1..=1000",
        ),
        (
            "alpha = 0.022727272727272728",
            "alpha = 1.0",
            "predictions[0] (stall).alpha: 1.0 exceeds 1/44 = 0.0227 (α·‖x‖² ≤ 1 with 44 active features)",
        ),
        (
            "alpha = 0.022727272727272728",
            "alpha = 1e308",
            "predictions[0] (stall).alpha: 1e308 exceeds 1/44",
        ),
    ];
    for (from, to, key) in cases {
        let bad = good.replace(from, to);
        assert_ne!(bad, good, "{from} not in stall.toml");
        let (code, stderr) = serve_with(&bad);
        assert_eq!(code, Some(1), "{to}: exit status {code:?}:\n{stderr}");
        assert!(
            stderr.contains(key),
            "{to}: the error does not name `{key}`:\n{stderr}"
        );
    }
}

#[test]
fn help_explains_every_command() {
    let out = Command::new(PAVLOV)
        .arg("--help")
        .output()
        .expect("run pavlov");
    let text = String::from_utf8_lossy(&out.stdout);
    for word in ["serve", "sim", "bench", "RUST_LOG"] {
        assert!(text.contains(word), "--help lacks {word}:\n{text}");
    }
    let out = Command::new(PAVLOV)
        .args(["serve", "--help"])
        .output()
        .expect("run pavlov");
    let text = String::from_utf8_lossy(&out.stdout);
    for flag in ["--config", "--robot", "--model", "--mode", "--seed"] {
        assert!(text.contains(flag), "serve --help lacks {flag}:\n{text}");
    }
}

/// `--version` names the commit and whether the tree was dirty, as every recording does.
#[test]
fn version_names_the_commit_the_build_and_its_features() {
    let out = Command::new(PAVLOV)
        .arg("--version")
        .output()
        .expect("run pavlov");
    let text = String::from_utf8_lossy(&out.stdout);
    let build = pavlov_actors::provenance::BUILD;
    assert!(out.status.success(), "{text}");
    for line in [
        format!("commit: {}", build.commit),
        format!("dirty: {}", build.dirty),
        format!("rustc: {}", build.rustc),
    ] {
        assert!(text.contains(&line), "--version lacks {line:?}:\n{text}");
    }
    assert!(
        build.commit == "unknown" || build.commit.len() == 40,
        "{text}"
    );
    assert_eq!(
        build.features.split(',').any(|f| f == "zenoh"),
        cfg!(feature = "zenoh"),
        "the binary's features are the package's: {text}"
    );
}

/// A build says what it can do: with the `zenoh` feature `serve --zenoh` starts (and is stopped by a bad
/// Zenoh configuration file, which only a Zenoh build reads); without it, `--zenoh` and `fleet` say how
/// to get it, in `--help` and when used.
#[test]
fn a_build_says_whether_it_has_zenoh() {
    let help = Command::new(PAVLOV).arg("--help").output().unwrap();
    let help = String::from_utf8_lossy(&help.stdout);
    let fleet_line = help
        .lines()
        .find(|l| l.trim_start().starts_with("fleet"))
        .unwrap_or_else(|| panic!("--help lists fleet:\n{help}"));
    let dir = crate::common::TestDir::new("zenoh-build");
    let bad = dir.join("zenoh.json5");
    std::fs::write(&bad, "{ this is not json5").unwrap();
    let out = Command::new(PAVLOV)
        .args(["serve", "--bind", "127.0.0.1:0", "--zenoh"])
        .arg(&bad)
        .current_dir(&*dir)
        .output()
        .unwrap();
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success(), "{err}");
    if cfg!(feature = "zenoh") {
        assert!(
            !fleet_line.contains("needs the zenoh feature"),
            "{fleet_line}"
        );
        assert!(
            !err.contains("built without Zenoh"),
            "a Zenoh build reads the file: {err}"
        );
        assert!(err.to_lowercase().contains("zenoh"), "{err}");
    } else {
        assert!(
            fleet_line.contains("needs the zenoh feature"),
            "{fleet_line}"
        );
        assert!(
            err.contains("built without Zenoh") && err.contains("--features zenoh"),
            "{err}"
        );
        let fleet = Command::new(PAVLOV).arg("fleet").output().unwrap();
        let fleet_err = String::from_utf8_lossy(&fleet.stderr);
        assert!(
            !fleet.status.success() && fleet_err.contains("--features zenoh"),
            "{fleet_err}"
        );
    }
}

#[test]
fn studies_that_would_run_nothing_or_forever_are_refused_by_name() {
    let cases: [(&[&str], &str); 6] = [
        (
            &["stall", "--runs", "0"],
            "--runs must be from 1 to 1000, got 0",
        ),
        (&["stall", "--minutes", "0"], "--minutes must be above 0"),
        (&["stall", "--minutes", "NaN"], "--minutes must be above 0"),
        (&["stall", "--minutes", "100000"], "at most 1440"),
        (
            &["interaction", "--runs", "0"],
            "--runs must be from 1 to 100, got 0",
        ),
        (
            &["interaction", "--commands", "0"],
            "--commands must be at least 1",
        ),
    ];
    let out_dir = std::env::temp_dir().join(format!("pavlov-refused-{}", std::process::id()));
    for (args, expected) in cases {
        let out = std::process::Command::new(PAVLOV)
            .arg("experiment")
            .args(args)
            .arg("--out")
            .arg(&out_dir)
            .output()
            .expect("run pavlov");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{args:?} was accepted");
        assert!(stderr.contains(expected), "{args:?}: {stderr}");
        assert!(!out_dir.exists(), "{args:?} wrote {}", out_dir.display());
    }
}

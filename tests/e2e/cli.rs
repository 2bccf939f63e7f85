//! The `pavlov` binary's edge: bad configurations are refused at start-up with a message naming the key,
//! and `--help` explains the commands.

use std::process::Command;

const PAVLOV: &str = env!("CARGO_BIN_EXE_pavlov");

fn stall_toml() -> String {
    std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../config/stall.toml"))
        .expect("config/stall.toml")
}

fn serve_with(config: &str) -> (bool, String) {
    let dir = std::env::temp_dir().join(format!("pavlov-cli-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("temp dir");
    let path = dir.join(format!(
        "{:x}.toml",
        config.len() * 31 + config.bytes().map(usize::from).sum::<usize>()
    ));
    std::fs::write(&path, config).expect("write config");
    let out = Command::new(PAVLOV)
        .args(["serve", "--bind", "127.0.0.1:0", "--config"])
        .arg(&path)
        .output()
        .expect("run pavlov");
    (
        out.status.success(),
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
    ];
    for (from, to, key) in cases {
        let bad = good.replace(from, to);
        assert_ne!(bad, good, "{from} not in stall.toml");
        let (ok, stderr) = serve_with(&bad);
        assert!(!ok, "{to}: the server started");
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

//! No secret in any artifact: the real `pavlov serve --token T --record R` is commanded over its websocket
//! (save the weights, start a second recording), stopped with SIGTERM, its recording converted to JSON
//! Lines, and a study is run on a configuration that holds the same token. Then every byte written — every
//! file in the run's folder, each MCAP file's messages, schemas, metadata and attachments decompressed, and
//! the server's standard output and log — is searched for the token. The commands' own acknowledgements
//! name the files they wrote, so the test knows the search covers them.

use std::io::Read;
use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::Duration;

use futures_util::{SinkExt, StreamExt};
use serde_json::Value;
use tokio_tungstenite::tungstenite::Message;

use crate::common::TestDir;

const PAVLOV: &str = env!("CARGO_BIN_EXE_pavlov");
/// The secret: long and unlike anything else a run writes.
const TOKEN: &str = "Zq7-secret-Token-Kx93vHw2pLm";

/// Every file under `dir`, recursively.
fn files(dir: &Path) -> Vec<PathBuf> {
    let mut out = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap_or_else(|e| panic!("{}: {e}", d.display())) {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                out.push(path);
            }
        }
    }
    out.sort();
    out
}

/// The bytes of `file` as written, and, for an MCAP file, every record's payload decompressed.
fn contents(file: &Path) -> Vec<Vec<u8>> {
    let bytes = std::fs::read(file).unwrap_or_else(|e| panic!("{}: {e}", file.display()));
    let mut parts = vec![bytes.clone()];
    if bytes.starts_with(mcap::MAGIC) {
        let records = mcap::read::ChunkFlattener::new(&bytes).expect("an MCAP file");
        for record in records {
            let record = record.unwrap_or_else(|e| panic!("{}: {e}", file.display()));
            match record {
                mcap::records::Record::Message { data, .. } => parts.push(data.into_owned()),
                mcap::records::Record::Schema { data, header } => {
                    parts.push(data.into_owned());
                    parts.push(header.name.into_bytes());
                }
                mcap::records::Record::Metadata(m) => {
                    for (k, v) in m.metadata {
                        parts.push(k.into_bytes());
                        parts.push(v.into_bytes());
                    }
                }
                mcap::records::Record::Attachment { data, .. } => parts.push(data.into_owned()),
                mcap::records::Record::Channel(c) => {
                    parts.push(c.topic.into_bytes());
                    for (k, v) in c.metadata {
                        parts.push(k.into_bytes());
                        parts.push(v.into_bytes());
                    }
                }
                _ => {}
            }
        }
        assert!(
            parts.len() > 10,
            "{}: the MCAP file was read",
            file.display()
        );
    }
    parts
}

/// Whether `haystack` holds `needle`.
fn holds(haystack: &[u8], needle: &[u8]) -> bool {
    haystack.windows(needle.len()).any(|w| w == needle)
}

/// Sends `cmd` (a JSON object with an `id`) and returns its reply, skipping everything else.
async fn command<S>(ws: &mut S, cmd: Value) -> Value
where
    S: StreamExt<Item = Result<Message, tokio_tungstenite::tungstenite::Error>>
        + SinkExt<Message>
        + Unpin,
    <S as futures_util::Sink<Message>>::Error: std::fmt::Debug,
{
    let id = cmd["id"].as_u64().expect("an id");
    ws.send(Message::Text(cmd.to_string().into()))
        .await
        .expect("send");
    loop {
        let msg = tokio::time::timeout(Duration::from_secs(60), ws.next())
            .await
            .expect("a reply within 60 s")
            .expect("the connection is open")
            .expect("no websocket error");
        if let Message::Text(t) = msg {
            let v: Value = serde_json::from_str(&t).expect("JSON");
            if v["id"].as_u64() == Some(id) && (v["type"] == "ack" || v["type"] == "error") {
                return v;
            }
        }
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn no_artifact_carries_the_token() {
    let dir = TestDir::new("secrets");
    let out = dir.join("out");
    std::fs::create_dir_all(&out).unwrap();
    // The configuration with the token lives outside the searched folder: it is the user's own file.
    let config_dir = TestDir::new("secrets-config");
    let stall =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../config/stall.toml"))
            .unwrap();
    let serve_config = config_dir.join("serve.toml");
    std::fs::write(
        &serve_config,
        format!(
            "{stall}\n[checkpoint]\ndir = \"{}\"\n",
            out.join("weights").display()
        ),
    )
    .unwrap();
    let study_config = config_dir.join("study.toml");
    std::fs::write(
        &study_config,
        format!("{stall}\n[dashboard]\ntoken = \"{TOKEN}\"\n"),
    )
    .unwrap();

    // 1. serve --token, recording, commanded over the websocket.
    let stdout_file = std::fs::File::create(out.join("serve.stdout")).unwrap();
    let stderr_file = std::fs::File::create(out.join("serve.log")).unwrap();
    let mut child = Command::new(PAVLOV)
        .args(["serve", "--bind", "127.0.0.1:0", "--token", TOKEN, "-c"])
        .arg(&serve_config)
        .arg("--record")
        .arg(out.join("rec"))
        .current_dir(&out)
        .env("RUST_LOG", "debug")
        .stdin(Stdio::null())
        .stdout(stdout_file)
        .stderr(stderr_file)
        .spawn()
        .expect("run pavlov serve");
    let addr = {
        let mut found = None;
        for _ in 0..600 {
            let text = std::fs::read_to_string(out.join("serve.stdout")).unwrap_or_default();
            if let Some(line) = text.lines().find_map(|l| l.strip_prefix("dashboard: ")) {
                found = Some(
                    line.trim_start_matches("http://")
                        .trim_end_matches('/')
                        .to_string(),
                );
                break;
            }
            tokio::time::sleep(Duration::from_millis(100)).await;
        }
        found.expect("the server prints its dashboard URL within 60 s")
    };
    let (mut ws, _) = tokio_tungstenite::connect_async(format!("ws://{addr}/ws?token={TOKEN}"))
        .await
        .expect("connect as the operator");
    let saved = command(&mut ws, serde_json::json!({"cmd": "save_weights", "id": 1})).await;
    assert_eq!(saved["type"], "ack", "{saved}");
    let second = command(
        &mut ws,
        serde_json::json!({"cmd": "start_recording", "id": 2, "dir": "second"}),
    )
    .await;
    assert_eq!(second["type"], "ack", "{second}");
    drop(ws);
    // A graceful stop finishes the recordings.
    nix::sys::signal::kill(
        nix::unistd::Pid::from_raw(child.id() as i32),
        nix::sys::signal::Signal::SIGTERM,
    )
    .unwrap();
    let status = tokio::task::spawn_blocking(move || child.wait())
        .await
        .unwrap()
        .unwrap();
    assert!(status.success(), "serve stopped cleanly: {status:?}");

    // 2. convert the first recording.
    let convert = Command::new(PAVLOV)
        .args(["convert", "--to", "jsonl"])
        .arg(out.join("rec"))
        .output()
        .unwrap();
    assert!(convert.status.success(), "{convert:?}");

    // 3. a study on a configuration that holds the token.
    let study = Command::new(PAVLOV)
        .args([
            "experiment",
            "stall",
            "--runs",
            "1",
            "--minutes",
            "0.05",
            "--threads",
            "1",
            "-c",
        ])
        .arg(&study_config)
        .arg("--out")
        .arg(out.join("study"))
        .output()
        .unwrap();
    assert!(study.status.success(), "{study:?}");
    for stream in [
        &study.stdout,
        &study.stderr,
        &convert.stdout,
        &convert.stderr,
    ] {
        assert!(!holds(stream, TOKEN.as_bytes()), "the token was printed");
    }

    // 4. search everything.
    let all = files(&out);
    let names: Vec<String> = all
        .iter()
        .map(|p| p.strip_prefix(&out).unwrap().display().to_string())
        .collect();
    let has = |what: &str| names.iter().any(|n| n.contains(what));
    for expected in [
        "rec/recording.mcap",
        "rec/ticks.jsonl",
        "recording.mcap", // the second recording, under the checkpoint-free recordings folder
        "weights/",
        "study/summary.json",
        "serve.log",
    ] {
        assert!(has(expected), "{expected} was written: {names:?}");
    }
    assert!(
        names
            .iter()
            .filter(|n| n.ends_with("recording.mcap"))
            .count()
            >= 3,
        "two server recordings and the study's: {names:?}"
    );
    let mut searched = 0usize;
    for file in &all {
        for part in contents(file) {
            searched += part.len();
            assert!(
                !holds(&part, TOKEN.as_bytes()),
                "{} holds the token",
                file.display()
            );
        }
    }
    // The recordings do say a token was set, redacted.
    let mut jsonl = String::new();
    std::fs::File::open(out.join("rec/ticks.jsonl"))
        .unwrap()
        .read_to_string(&mut jsonl)
        .unwrap();
    assert!(jsonl.lines().next().unwrap().contains("<redacted>"));
    eprintln!("searched {searched} bytes in {} files", all.len());
}

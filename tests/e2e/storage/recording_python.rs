//! An independent reader opens a recording: Foxglove's `mcap` Python package (with
//! `mcap-protobuf-support`, pinned in tests/python/requirements.txt; tests/run.sh installs them into the
//! venv `target/py-mcap`) lists the channels and their message counts, and decodes every tick from the
//! schema the file carries, with no pavlov code. What it reads must be what the recorder wrote.
//!
//! A missing Python package fails this test with the command that installs it; it is never skipped.

use std::path::PathBuf;
use std::process::Command;

use pavlov_actors::storage::recording::{self, MCAP_FILE};
use serde_json::Value;

use super::fixtures::{fresh_dir, record_with_changes};

/// The venv tests/run.sh makes: `<target>/py-mcap`.
fn venv() -> PathBuf {
    // CARGO_TARGET_TMPDIR is <target>/tmp.
    PathBuf::from(env!("CARGO_TARGET_TMPDIR"))
        .parent()
        .expect("the target directory")
        .join("py-mcap")
}

/// The interpreter in `PAVLOV_PYTHON`, else the venv's.
fn python() -> PathBuf {
    std::env::var_os("PAVLOV_PYTHON")
        .map(PathBuf::from)
        .unwrap_or_else(|| venv().join("bin").join("python"))
}

fn repo_file(path: &str) -> PathBuf {
    PathBuf::from(env!("CARGO_MANIFEST_DIR"))
        .join("..")
        .join(path)
}

fn install_hint() -> String {
    format!(
        "the independent MCAP reader is not installed for {0}: run tests/run.sh, or\n  python3 -m venv {1} && {1}/bin/python -m pip install -q -r {2}\n(or point PAVLOV_PYTHON at a python with those packages)",
        python().display(),
        venv().display(),
        repo_file("tests/python/requirements.txt").display()
    )
}

#[test]
fn the_mcap_python_package_reads_every_channel_and_tick_as_written() {
    let dir = fresh_dir("python-reader");
    let report = record_with_changes(&dir, 3000);
    let file = dir.join(MCAP_FILE);
    let python = python();
    let check = Command::new(&python)
        .args(["-c", "import mcap, mcap_protobuf"])
        .output();
    match check {
        Ok(out) if out.status.success() => {}
        Ok(out) => panic!(
            "{}\n{}",
            install_hint(),
            String::from_utf8_lossy(&out.stderr)
        ),
        Err(e) => panic!("{}\n{}: {e}", install_hint(), python.display()),
    }
    let out = Command::new(&python)
        .arg(repo_file("tests/python/read_mcap.py"))
        .arg(&file)
        .output()
        .expect("run the reader");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let read: Value = serde_json::from_slice(&out.stdout).expect("the reader prints JSON");

    // The channels, their schemas and encodings.
    let channels = &read["channels"];
    for (topic, schema, schema_encoding, encoding) in [
        ("ticks", "pavlov.Tick", "protobuf", "protobuf"),
        ("events", "pavlov.Event", "jsonschema", "json"),
        ("config", "pavlov.Config", "jsonschema", "json"),
        ("learner", "pavlov.StartState", "jsonschema", "json"),
    ] {
        assert_eq!(channels[topic]["schema"], schema, "{channels}");
        assert_eq!(channels[topic]["schema_encoding"], schema_encoding);
        assert_eq!(channels[topic]["message_encoding"], encoding);
    }
    assert_eq!(channels.as_object().unwrap().len(), 4, "{channels}");

    // Message counts: in the summary and counted by reading, equal to what the recorder wrote.
    let written = serde_json::json!({
        "ticks": report.written,
        "events": report.events,
        "config": 1,
        "learner": 1,
    });
    assert_eq!(read["summary_counts"], written);
    assert_eq!(read["counted"], written);
    assert!(report.written >= 3000);
    assert!(report.events >= 7, "{}", report.events);

    // Provenance.
    let meta = &read["metadata"]["pavlov.recording"];
    assert!(meta["program"].as_str().unwrap().starts_with("pavlov "));
    assert_eq!(meta["label"], "with changes");
    assert_eq!(meta["seed"], "12");
    assert_eq!(meta["start_after"], "");
    assert_eq!(read["config_seed"], 12);
    assert_eq!(read["learner_after"], Value::Null);

    // Every tick, decoded by protobuf from the file's own schema, equals pavlov's reading of it.
    let rec = recording::load(&dir).expect("pavlov reads it too");
    let ticks = read["ticks"].as_array().unwrap();
    assert_eq!(ticks.len(), rec.records.len());
    for (row, r) in ticks.iter().zip(&rec.records) {
        assert_eq!(row[0], r.seq);
        assert_eq!(
            row[1].as_u64(),
            Some((r.t_ms * 1e6).round() as u64),
            "log time"
        );
        assert_eq!(row[2].as_f64().map(f64::to_bits), Some(r.t_ms.to_bits()));
        assert_eq!(row[3], r.command.left_mm_s);
        assert_eq!(row[4], r.command.right_mm_s);
        assert_eq!(row[5], r.gate);
        assert_eq!(row[6], r.stimulus);
        let values: Vec<u64> = row[7]
            .as_array()
            .unwrap()
            .iter()
            .map(|v| v.as_f64().unwrap().to_bits())
            .collect();
        let want: Vec<u64> = r.predictions.iter().map(|p| p.value.to_bits()).collect();
        assert_eq!(values, want, "tick {}", r.seq);
        let raw = r.inputs.as_ref().and_then(|i| i.values.as_ref());
        for (id, v) in raw
            .map(|v| v.iter().collect::<Vec<_>>())
            .unwrap_or_default()
        {
            assert_eq!(row[8][usize::from(id)], v, "tick {} packet {id}", r.seq);
        }
        let state = format!("LINK_STATE_{}", r.link.state.name().to_uppercase());
        assert_eq!(row[9], state.as_str());
    }
    let kinds: Vec<&str> = rec.events.iter().map(|e| e.kind.name()).collect();
    assert_eq!(read["events"], serde_json::json!(kinds));
    for kind in [
        "params_set",
        "weights_reset",
        "mode_set",
        "e_stop",
        "recording_stopped",
    ] {
        assert!(kinds.contains(&kind), "no {kind} in {kinds:?}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

//! `start_recording` names a recording inside the recordings root, never a place, and never overwrites
//! one; `pavlov serve --record DIR` refuses a DIR that already holds a recording.

use std::path::Path;

use pavlov_actors::command::{Applied, ControlRequest, Outcome, RecorderCommand};
use pavlov_actors::server::{RobotTarget, Server};
use pavlov_actors::storage::recorder::Recorder;
use pavlov_actors::storage::recording::{MCAP_FILE, RecordingHeader, TICKS_FILE};

use super::fixtures::{fresh_dir, serve, snapshot_files};
use crate::common::stall_config;

async fn start(server: &Server, dir: &str) -> Outcome {
    let (req, reply) = ControlRequest::new(RecorderCommand::StartRecording {
        dir: Some(dir.to_string()),
    });
    server.commands().send(req).await.unwrap();
    reply.await.unwrap()
}

#[tokio::test(start_paused = true)]
async fn start_recording_names_stay_inside_the_root_and_never_overwrite() {
    let base = fresh_dir("recording-names");
    let root = base.join("recordings");
    // An earlier recording, and the one the server records into by itself (--record).
    // An earlier recording in JSON Lines, and one in MCAP (its bytes do not matter here).
    let old = root.join("old");
    std::fs::create_dir_all(&old).unwrap();
    std::fs::write(
        old.join(TICKS_FILE),
        b"{\"format\":\"pavlov-recording/1\"}\n",
    )
    .unwrap();
    let older_mcap = root.join("old-mcap");
    std::fs::create_dir_all(&older_mcap).unwrap();
    std::fs::write(older_mcap.join(MCAP_FILE), b"\x89MCAP0\r\n").unwrap();
    let own = base.join("own");
    let cfg = stall_config();
    let recorder = Recorder::spawn_new(
        RecordingHeader::new(&cfg, "names"),
        Some(own.clone()),
        root.clone(),
        512,
    )
    .unwrap();
    let server = Server::builder(cfg, RobotTarget::Simulated)
        .recorder(recorder.link.clone())
        .start()
        .await
        .unwrap();
    let before = snapshot_files(&root);
    let outside = base.join("outside");
    let escape = format!("../../pavlov-escape-{}", std::process::id());
    let absolute = outside.display().to_string();
    for (name, rule) in [
        (escape.as_str(), "contains a path separator"),
        (absolute.as_str(), "is an absolute path"),
        ("a/b", "contains a path separator"),
        ("..", "contains `..`"),
        (".hidden", "is hidden"),
    ] {
        let msg = start(&server, name).await.unwrap_err().to_string();
        assert!(msg.contains(rule), "{name}: {msg}");
        assert!(msg.contains("plain name"), "{name}: {msg}");
    }
    for (name, file) in [
        ("old", old.join(TICKS_FILE)),
        ("old-mcap", older_mcap.join(MCAP_FILE)),
    ] {
        let msg = start(&server, name).await.unwrap_err().to_string();
        assert!(msg.contains("already holds a recording"), "{msg}");
        assert!(msg.contains(&file.display().to_string()), "{msg}");
    }
    // Nothing was created, and the earlier recording keeps its bytes.
    assert_eq!(snapshot_files(&root), before);
    assert!(!outside.exists());
    assert!(!root.join("a").exists());
    assert!(
        !base
            .parent()
            .unwrap()
            .join(format!("pavlov-escape-{}", std::process::id()))
            .exists()
    );
    // A plain new name records inside the root.
    match start(&server, "fresh").await {
        Ok(Applied::Recording { recording }) => {
            assert_eq!(Path::new(&recording), root.join("fresh").join(MCAP_FILE))
        }
        other => panic!("{other:?}"),
    }
    server.shutdown().await;
    let report = tokio::task::spawn_blocking(move || recorder.join())
        .await
        .unwrap();
    assert!(report.errors.is_empty(), "{:?}", report.errors);
    assert_eq!(
        report.files,
        [own.join(MCAP_FILE), root.join("fresh").join(MCAP_FILE)]
    );
    assert_eq!(
        std::fs::read(old.join(TICKS_FILE)).unwrap(),
        b"{\"format\":\"pavlov-recording/1\"}\n"
    );
    assert_eq!(
        std::fs::read(older_mcap.join(MCAP_FILE)).unwrap(),
        b"\x89MCAP0\r\n"
    );
    let _ = std::fs::remove_dir_all(&base);
}

#[test]
fn serve_record_refuses_a_folder_that_holds_a_recording() {
    let base = fresh_dir("record-exists");
    // A recording of either format: MCAP, or JSON Lines from an earlier version.
    for (name, bytes) in [
        (MCAP_FILE, b"\x89MCAP0\r\n".to_vec()),
        (
            TICKS_FILE,
            b"{\"format\":\"pavlov-recording/1\"}\n{\"seq\":0}\n".to_vec(),
        ),
    ] {
        let rec = base.join(format!("rec-{name}"));
        std::fs::create_dir_all(&rec).unwrap();
        let file = rec.join(name);
        std::fs::write(&file, &bytes).unwrap();
        let rec_arg = rec.display().to_string();
        let out = serve(&base, &["--record", &rec_arg], "pavlov is driving");
        let stderr = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success(), "{stderr}");
        assert!(stderr.contains(&file.display().to_string()), "{stderr}");
        assert!(stderr.contains("already holds a recording"), "{stderr}");
        assert_eq!(std::fs::read(&file).unwrap(), bytes);
        assert_eq!(
            std::fs::read_dir(&rec).unwrap().count(),
            1,
            "nothing beside it"
        );
    }
    let _ = std::fs::remove_dir_all(&base);
}

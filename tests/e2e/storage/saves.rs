//! `save_weights` on a running server: a client names a save, never a place; saves live in
//! `[checkpoint] dir/saved/`, apart from the automatic checkpoints, are never overwritten, never pruned,
//! and held to a quota; every refusal names its rule. A save can be resumed from (`resume_from`).

use std::path::Path;

use pavlov::checkpoint::Checkpoint;
use pavlov_actors::command::{Applied, ControlRequest, LearningCommand, Outcome};
use pavlov_actors::server::{RobotTarget, Server};
use pavlov_actors::storage::checkpoint_files::{SAVED_DIR, list};

use super::fixtures::{config_in, fresh_dir, read};
use crate::common::{collect, init_logging};

async fn save(server: &Server, path: Option<&str>) -> Outcome {
    let (req, reply) = ControlRequest::new(LearningCommand::SaveWeights {
        path: path.map(str::to_string),
    });
    server.commands().send(req).await.unwrap();
    reply.await.unwrap()
}

async fn refused(server: &Server, path: &str) -> String {
    match save(server, Some(path)).await {
        Err(e) => e.to_string(),
        Ok(a) => panic!("save_weights {path} was accepted: {a:?}"),
    }
}

fn saved_path(outcome: Outcome) -> String {
    match outcome {
        Ok(Applied::Saved { path }) => path,
        other => panic!("{other:?}"),
    }
}

#[tokio::test(start_paused = true)]
async fn saves_are_named_not_placed_never_overwritten_never_pruned_and_limited() {
    init_logging();
    let dir = fresh_dir("saves");
    let escape = dir
        .parent()
        .unwrap()
        .join(format!("pavlov-escape-{}", std::process::id()));
    let _ = std::fs::remove_file(&escape);
    let mut cfg = config_in(&dir);
    cfg.checkpoint.every_s = 1;
    cfg.checkpoint.keep = 1;
    cfg.checkpoint.max_saves = 3;
    let server = Server::builder(cfg.clone(), RobotTarget::Simulated)
        .start()
        .await
        .unwrap();
    let run_dir = server.checkpoints().run_dir.clone().unwrap();
    collect(&mut server.feed().subscribe(), 60).await;
    let saved = dir.join(SAVED_DIR);

    // The automatic checkpoints' own names (five of them once made pruning delete every real one).
    for tick in ["99999999990", "99999999991", "1"] {
        let msg = refused(&server, &format!("checkpoint-{tick}.json")).await;
        assert!(msg.contains("reserved"), "{msg}");
        assert!(msg.contains("checkpoint-<tick>.json"), "{msg}");
    }
    let escape_name = format!("../pavlov-escape-{}", std::process::id());
    let absolute = escape.display().to_string();
    for (name, rule) in [
        (escape_name.as_str(), "contains a path separator"),
        (absolute.as_str(), "is an absolute path"),
        ("/tmp/x", "is an absolute path"),
        (".hidden", "is hidden"),
        ("..", "contains `..`"),
    ] {
        let msg = refused(&server, name).await;
        assert!(msg.contains(rule), "{name}: {msg}");
        assert!(msg.contains("plain name"), "{name}: {msg}");
    }
    let long = "w".repeat(101);
    let msg = refused(&server, &long).await;
    assert!(msg.contains("more than 100"), "{msg}");

    // A save is a whole checkpoint of this configuration, in saved/.
    let w = saved_path(save(&server, Some("w.json")).await);
    assert_eq!(Path::new(&w), saved.join("w.json"));
    let bytes = std::fs::read(&w).unwrap();
    let cp: Checkpoint = serde_json::from_slice(&bytes).unwrap();
    cp.check_against(&cfg).unwrap();
    // Never overwritten.
    let msg = refused(&server, "w.json").await;
    assert!(
        msg.contains("never overwrites") && msg.contains("w.json"),
        "{msg}"
    );
    assert_eq!(std::fs::read(&w).unwrap(), bytes);
    // The default name is the server's own, and new.
    let default = saved_path(save(&server, None).await);
    assert!(Path::new(&default).starts_with(&saved), "{default}");
    assert_ne!(default, w);
    // The quota: max_saves = 3.
    saved_path(save(&server, Some("b.json")).await);
    let msg = refused(&server, "c.json").await;
    assert!(msg.contains("quota [checkpoint] max_saves = 3"), "{msg}");
    assert!(!saved.join("c.json").exists());

    // Many automatic checkpoints later (keep = 1), every save is still there.
    collect(&mut server.feed().subscribe(), 300).await;
    server.shutdown().await;
    assert_eq!(
        list(&run_dir).unwrap().len(),
        1,
        "the run's checkpoints were pruned"
    );
    let mut names: Vec<String> = std::fs::read_dir(&saved)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    assert_eq!(names.len(), 3, "{names:?}");
    assert!(names.contains(&"w.json".into()) && names.contains(&"b.json".into()));
    assert_eq!(std::fs::read(&w).unwrap(), bytes);
    // Nothing was written anywhere else.
    assert!(!escape.exists());
    assert!(!dir.join(".hidden").exists() && !saved.join(".hidden").exists());
    let top: Vec<String> = std::fs::read_dir(&dir)
        .unwrap()
        .flatten()
        .map(|e| e.file_name().to_string_lossy().into_owned())
        .collect();
    assert_eq!(top.len(), 2, "only runs/ and saved/: {top:?}");

    // A save can be resumed from.
    let mut from_save = cfg.clone();
    from_save.checkpoint.autosave = false;
    from_save.checkpoint.resume_from = Some(w.clone());
    let server = Server::builder(from_save, RobotTarget::Simulated)
        .start()
        .await
        .unwrap();
    let resumed = server.checkpoints().resumed.as_ref().unwrap();
    assert_eq!(resumed.path, Path::new(&w));
    assert_eq!(resumed.tick, read(Path::new(&w)).created_tick);
    server.shutdown().await;
    let _ = std::fs::remove_dir_all(&dir);
}

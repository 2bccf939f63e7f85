//! Helpers of the storage tests: fresh folders, checkpoint configurations, checkpoint files of a fresh
//! stall learner (valid, of another configuration, with a NaN, torn), and running `pavlov serve`.

use std::path::{Path, PathBuf};
use std::process::{Child, Command, Output, Stdio};
use std::time::{Duration, Instant};

use pavlov::agent::LearningStage;
use pavlov::checkpoint::Checkpoint;
use pavlov::config::Config;
use pavlov_actors::storage::checkpoint_files::write_atomic;

use crate::common::{TestDir, stall_config};

/// A fresh, empty directory for one test, removed when dropped.
pub fn fresh_dir(name: &str) -> TestDir {
    TestDir::new(&format!("storage-{name}"))
}

/// The stall configuration checkpointing into `dir` every 2 s of ticks, keeping 2.
pub fn config_in(dir: &Path) -> Config {
    let mut cfg = stall_config();
    cfg.checkpoint.dir = dir.display().to_string();
    cfg.checkpoint.every_s = 2;
    cfg.checkpoint.keep = 2;
    cfg.checkpoint.autosave = true;
    cfg
}

/// Reads a checkpoint file.
pub fn read(path: &Path) -> Checkpoint {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

/// A checkpoint of a fresh learner of `cfg` at `tick`.
pub fn fresh_checkpoint(cfg: &Config, tick: u64) -> Checkpoint {
    let stage = LearningStage::new(cfg).unwrap();
    Checkpoint::new(cfg, tick, stage.snapshot()).unwrap()
}

/// Writes a checkpoint of a fresh stall learner into `dir` (as `checkpoint-<tick>.json`).
pub fn write_stall_checkpoint(dir: &Path, tick: u64) -> PathBuf {
    write_atomic(dir, &fresh_checkpoint(&stall_config(), tick)).unwrap()
}

/// Writes `checkpoint` into `dir` with prediction 0's weight `index` replaced by `null`: what serde_json
/// makes of a NaN, i.e. what an older server wrote for NaN weights.
pub fn write_with_nan_weight(dir: &Path, checkpoint: &Checkpoint, index: usize) -> PathBuf {
    let mut value = serde_json::to_value(checkpoint).unwrap();
    value["state"]["predictions"][0]["weights"][index] = serde_json::Value::Null;
    std::fs::create_dir_all(dir).unwrap();
    let path = dir.join(format!("checkpoint-{}.json", checkpoint.created_tick));
    std::fs::write(&path, serde_json::to_vec(&value).unwrap()).unwrap();
    path
}

/// Writes the first half of `checkpoint`'s JSON into `dir`: a write cut short.
pub fn write_torn(dir: &Path, checkpoint: &Checkpoint) -> PathBuf {
    let json = serde_json::to_vec(checkpoint).unwrap();
    std::fs::create_dir_all(dir).unwrap();
    let path = dir.join(format!("checkpoint-{}.json", checkpoint.created_tick));
    std::fs::write(&path, &json[..json.len() / 2]).unwrap();
    path
}

/// Every file under `dir` with its bytes, sorted by path.
pub fn snapshot_files(dir: &Path) -> Vec<(PathBuf, Vec<u8>)> {
    let mut out = Vec::new();
    let mut todo = vec![dir.to_path_buf()];
    while let Some(d) = todo.pop() {
        for e in std::fs::read_dir(&d).unwrap().flatten() {
            let p = e.path();
            if p.is_dir() {
                todo.push(p);
            } else {
                out.push((p.clone(), std::fs::read(&p).unwrap()));
            }
        }
    }
    out.sort();
    out
}

/// Kills a `pavlov` process if the test fails before it ends.
pub struct Running(pub Child);

impl Drop for Running {
    fn drop(&mut self) {
        let _ = self.0.kill();
        let _ = self.0.wait();
    }
}

/// Runs `pavlov serve <args>` in `cwd` on an ephemeral port until it prints `until` on stdout (then it
/// is killed) or exits by itself; returns its output. Panics after 30 s.
pub fn serve(cwd: &Path, args: &[&str], until: &str) -> Output {
    use std::io::Read;
    let child = Command::new(env!("CARGO_BIN_EXE_pavlov"))
        .arg("serve")
        .args(["--bind", "127.0.0.1:0"])
        .args(args)
        .current_dir(cwd)
        .stdin(Stdio::null())
        .stdout(Stdio::piped())
        .stderr(Stdio::piped())
        .spawn()
        .expect("run pavlov serve");
    let mut running = Running(child);
    let mut stdout = running.0.stdout.take().unwrap();
    let mut stderr = running.0.stderr.take().unwrap();
    let err_reader = std::thread::spawn(move || {
        let mut s = Vec::new();
        let _ = stderr.read_to_end(&mut s);
        s
    });
    let (tx, rx) = std::sync::mpsc::channel();
    let marker = until.to_string();
    let out_reader = std::thread::spawn(move || {
        use std::io::BufRead;
        let mut all = Vec::new();
        for line in std::io::BufReader::new(&mut stdout)
            .lines()
            .map_while(Result::ok)
        {
            let done = line.contains(&marker);
            all.extend_from_slice(line.as_bytes());
            all.push(b'\n');
            if done {
                let _ = tx.send(());
            }
        }
        all
    });
    let deadline = Instant::now() + Duration::from_secs(30);
    loop {
        if rx.try_recv().is_ok() {
            let _ = running.0.kill();
            break;
        }
        if running.0.try_wait().unwrap().is_some() {
            break;
        }
        assert!(
            Instant::now() < deadline,
            "pavlov serve {args:?} neither printed `{until}` nor exited"
        );
        std::thread::sleep(Duration::from_millis(20));
    }
    let status = running.0.wait().unwrap();
    Output {
        status,
        stdout: out_reader.join().unwrap(),
        stderr: err_reader.join().unwrap(),
    }
}

/// Records `ticks` ticks of the stall configuration (seed 12) from the run's start into `dir` under the
/// paused clock, with changes made while it runs: learning parameters, a weight reset, a mode switch,
/// and an e-stop latched and released. Returns the recorder's report.
pub fn record_with_changes(
    dir: &Path,
    ticks: usize,
) -> pavlov_actors::storage::recorder::RecorderReport {
    use pavlov::control::Mode;
    use pavlov_actors::command::{
        ControlCommand, ControlRequest, GatingCommand, LatchCommand, LearningCommand,
    };
    use pavlov_actors::server::Server;

    async fn send(server: &Server, command: impl Into<ControlCommand>) {
        let (req, reply) = ControlRequest::new(command);
        server.commands().send(req).await.expect("router up");
        let outcome = reply.await.expect("a reply");
        assert!(outcome.is_ok(), "{outcome:?}");
    }
    let mut cfg = stall_config();
    cfg.sim.seed = 12;
    let body = async |server: &Server| {
        let mut rx = server.feed().subscribe();
        let step = ticks / 6;
        crate::common::collect(&mut rx, step).await;
        let params = LearningCommand::SetParams {
            prediction: None,
            alpha: Some(0.01),
            lambda: Some(0.9),
            threshold: Some(0.3),
        };
        send(server, params).await;
        crate::common::collect(&mut rx, step).await;
        send(server, LearningCommand::ResetWeights {}).await;
        crate::common::collect(&mut rx, step).await;
        let reactive = GatingCommand::SetMode {
            mode: Mode::Reactive,
        };
        send(server, reactive).await;
        crate::common::collect(&mut rx, step).await;
        send(server, LatchCommand::Estop {}).await;
        crate::common::collect(&mut rx, step).await;
        send(server, LatchCommand::Release {}).await;
        crate::common::collect(&mut rx, ticks - 5 * step).await;
    };
    let ((), report) = with_recorded_server(cfg, "with changes", Some(dir), dir, ticks + 64, body);
    report
}

/// Records the first `ticks` ticks of `cfg` into `dir` (labelled `label`) under the paused clock, with
/// nothing changed while it runs; returns what the feed streamed, once the recorder has finished cleanly.
pub fn record_plain(
    cfg: Config,
    label: &str,
    dir: &Path,
    ticks: usize,
) -> Vec<pavlov::record::TickRecord> {
    use pavlov_actors::server::Server;

    let body = async |server: &Server| {
        let mut rx = server.feed().subscribe();
        crate::common::collect(&mut rx, ticks).await
    };
    let (streamed, _) = with_recorded_server(cfg, label, Some(dir), dir, ticks + 64, body);
    streamed
}

/// Runs `cfg` on the simulated robot under the paused clock with a recorder beside it (its header
/// labelled `label`; recording from the start into `from_start` if given, else when `body` starts one under
/// `root`; room for `capacity` queued ticks), calls `body` with the server, shuts the server down and waits
/// for the recorder, which must have finished cleanly. Returns what `body` returned and the recorder's
/// report.
pub fn with_recorded_server<T>(
    cfg: Config,
    label: &str,
    from_start: Option<&Path>,
    root: &Path,
    capacity: usize,
    body: impl AsyncFnOnce(&pavlov_actors::server::Server) -> T,
) -> (T, pavlov_actors::storage::recorder::RecorderReport) {
    use pavlov_actors::server::{RobotTarget, Server};
    use pavlov_actors::storage::recorder::Recorder;
    use pavlov_actors::storage::recording::RecordingHeader;

    let recorder = Recorder::spawn(
        RecordingHeader::new(&cfg, label),
        from_start.map(Path::to_path_buf),
        root.to_path_buf(),
        capacity,
    )
    .expect("recorder");
    let rt = tokio::runtime::Builder::new_current_thread()
        .enable_all()
        .start_paused(true)
        .build()
        .unwrap();
    let link = recorder.link.clone();
    let out = rt.block_on(async move {
        let server = Server::builder(cfg, RobotTarget::Simulated)
            .recorder(link)
            .start()
            .await
            .expect("server");
        let out = body(&server).await;
        server.shutdown().await;
        out
    });
    drop(rt);
    let report = recorder.join();
    assert!(report.errors.is_empty(), "{:?}", report.errors);
    (out, report)
}

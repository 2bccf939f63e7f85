//! `pavlov replay DIR`: runs a recording back through the core and fails unless it is reproduced exactly.
//!
//! Its exit status says which way it failed ([`Status`]), so a script can tell a recording that differs
//! from one cut short or one that cannot be read. The statuses are listed in `pavlov replay --help`.

use std::io::Write as _;
use std::path::PathBuf;

use anyhow::Result;
use pavlov_actors::storage::{recording, replay};

/// The exit statuses, for `--help`.
const STATUSES: &str = "Exit status:
  0  the recording was reproduced exactly
  1  the replay differs from the recording (the differences are printed)
  2  the command line is wrong
  3  the recording is torn: it ends early (cut by a crash, or copied while it was being written);
     nothing was replayed. --allow-torn replays the complete ticks it holds
  4  the recording cannot be read or replayed (not a recording, damaged before its end, a configuration
     or start state that does not build a learner, ticks without replay inputs)
  5  the recording holds no tick: there is nothing to replay";

/// `pavlov replay`'s arguments.
#[derive(clap::Args, Debug, Clone)]
#[command(after_help = STATUSES)]
pub struct ReplayArgs {
    /// A recording directory (with recording.mcap, or ticks.jsonl) or a recording file (.mcap or .jsonl).
    #[arg(value_name = "DIR")]
    pub path: PathBuf,
    /// Replay a torn recording (one that ends early, e.g. cut by a crash) up to its last complete tick
    /// instead of failing with status 3.
    #[arg(long)]
    pub allow_torn: bool,
}

/// How `pavlov replay` ends (its exit status).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
enum Status {
    /// Reproduced exactly.
    Identical = 0,
    /// The replay differs from the recording.
    Differs = 1,
    /// The recording ends early and `--allow-torn` was not given.
    Torn = 3,
    /// The recording cannot be read or replayed.
    Unreadable = 4,
    /// The recording holds no tick.
    Empty = 5,
}

/// Writes a line to stderr, ignoring a closed stderr.
fn complain(text: &str) {
    let _ = writeln!(std::io::stderr(), "{text}");
}

/// Replays, prints the summary (or the reason it could not) and ends the process with its [`Status`].
pub fn run(args: ReplayArgs) -> Result<()> {
    let status = replay_and_tell(&args);
    let _ = std::io::stdout().flush();
    if status == Status::Identical {
        return Ok(());
    }
    // The status is the answer: `main`'s error report would make every failure status 1.
    std::process::exit(status as i32)
}

fn replay_and_tell(args: &ReplayArgs) -> Status {
    let rec = match recording::load(&args.path) {
        Ok(rec) => rec,
        Err(e) => {
            complain(&format!("error: {e}"));
            return Status::Unreadable;
        }
    };
    if rec.torn_tail {
        if !args.allow_torn {
            complain(&format!(
                "error: the recording {} is torn: it ends early (cut by a crash, or copied while it was being written); \
                 its {} complete ticks were not replayed. Pass --allow-torn to replay them.",
                args.path.display(),
                rec.records.len()
            ));
            return Status::Torn;
        }
        complain(&format!(
            "note: the recording ends early (torn); replaying the {} complete ticks it holds (--allow-torn)",
            rec.records.len()
        ));
    }
    if let Some(p) = &rec.header.provenance
        && let Some(other) = p.other_commit()
    {
        complain(&format!(
            "warning: the recording was made by commit {other} ({}), this pavlov is commit {}: a difference \
             may come from the code, not the run",
            p.program,
            pavlov_actors::provenance::BUILD.commit
        ));
    }
    if rec.records.is_empty() {
        complain(&format!(
            "error: the recording {} holds no tick: there is nothing to replay",
            args.path.display()
        ));
        return Status::Empty;
    }
    let report = match replay::replay(&rec) {
        Ok(report) => report,
        Err(e) => {
            complain(&format!(
                "error: cannot replay {}: {e}",
                args.path.display()
            ));
            return Status::Unreadable;
        }
    };
    say!("{}", replay::describe(&report));
    if report.exact() {
        Status::Identical
    } else {
        complain("error: the replay differs from the recording");
        Status::Differs
    }
}

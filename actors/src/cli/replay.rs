//! `pavlov replay DIR`: runs a recording back through the core and fails unless it is reproduced exactly.

use std::path::PathBuf;

use anyhow::Result;
use pavlov_actors::storage::{recording, replay};

/// `pavlov replay`'s arguments.
#[derive(clap::Args, Debug, Clone)]
pub struct ReplayArgs {
    /// A recording directory (with recording.mcap, or ticks.jsonl) or a recording file (.mcap or .jsonl).
    #[arg(value_name = "DIR")]
    pub path: PathBuf,
}

/// Replays and prints the summary; an inexact replay is an error.
pub fn run(args: ReplayArgs) -> Result<()> {
    let rec = recording::load(&args.path)?;
    if rec.torn_tail {
        tracing::warn!(
            "note: the recording ends early (the recorder was killed); replaying the {} ticks it holds",
            rec.records.len()
        );
    }
    if let Some(p) = &rec.header.provenance
        && let Some(other) = p.other_commit()
    {
        tracing::warn!(
            "the recording was made by commit {other} ({}), this pavlov is commit {}: a difference may come \
             from the code, not the run",
            p.program,
            pavlov_actors::provenance::BUILD.commit
        );
    }
    let report = replay::replay(&rec)?;
    say!("{}", replay::describe(&report));
    anyhow::ensure!(report.exact(), "the replay differs from the recording");
    Ok(())
}

//! `pavlov convert PATH --to jsonl|mcap`: rewrites a recording in the other format (MCAP, what the
//! recorder writes, or JSON Lines, for `jq`, `grep` and `pandas`). Replay reads both.

use std::fs::File;
use std::io::BufWriter;
use std::path::PathBuf;

use anyhow::{Context, Result};
use pavlov_actors::storage::recording::{self, MCAP_FILE, TICKS_FILE};

/// The formats a recording can be written in.
#[derive(clap::ValueEnum, Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// JSON Lines: a header line, then one tick or event per line.
    Jsonl,
    /// MCAP, as the recorder writes it.
    Mcap,
}

/// `pavlov convert`'s arguments.
#[derive(clap::Args, Debug, Clone)]
pub struct ConvertArgs {
    /// A recording directory (with recording.mcap or ticks.jsonl) or a recording file of either format.
    #[arg(value_name = "PATH")]
    pub path: PathBuf,
    /// The format to write.
    #[arg(long, value_enum)]
    pub to: Format,
    /// Where to write (default: ticks.jsonl or recording.mcap beside the recording read). An existing
    /// file is never overwritten.
    #[arg(long, value_name = "FILE")]
    pub out: Option<PathBuf>,
}

/// Reads the recording and writes it in the format asked for.
pub fn run(args: ConvertArgs) -> Result<()> {
    let input = recording::recording_file(&args.path);
    let rec = recording::load(&args.path)
        .with_context(|| format!("cannot read the recording {}", input.display()))?;
    if rec.torn_tail {
        say!(
            "note: {} ends early (the recorder was killed); converting the {} ticks it holds",
            input.display(),
            rec.records.len()
        );
    }
    let out = args.out.unwrap_or_else(|| {
        input.with_file_name(match args.to {
            Format::Jsonl => TICKS_FILE,
            Format::Mcap => MCAP_FILE,
        })
    });
    let file = File::options()
        .write(true)
        .create_new(true)
        .open(&out)
        .with_context(|| {
            format!(
                "cannot create {} (an existing file is never overwritten)",
                out.display()
            )
        })?;
    let mut writer = BufWriter::new(file);
    match args.to {
        Format::Jsonl => recording::jsonl::write(&rec, &mut writer)
            .with_context(|| format!("cannot write {}", out.display()))?,
        Format::Mcap => {
            recording::write_recording(&rec, writer)
                .with_context(|| format!("cannot write {}", out.display()))?;
        }
    }
    say!(
        "wrote {} ticks and {} events to {}",
        rec.records.len(),
        rec.events.len(),
        out.display()
    );
    Ok(())
}

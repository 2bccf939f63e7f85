//! A rule table on the real runtime (`config/rules.toml`: the paper's 0.5 s stall rule and a 2 s stall
//! rule with its own response): both rules fire, at different times, each tick's command is the
//! response of the rule it names, and the recording replays exactly, the rule included.

use pavlov::config::Config;
use pavlov::control::{Action, Mode};
use pavlov::record::TickRecord;
use pavlov_actors::storage::recording;
use pavlov_actors::storage::replay;

const TICKS: usize = 12_000;

fn rules_config() -> Config {
    let text =
        std::fs::read_to_string(concat!(env!("CARGO_MANIFEST_DIR"), "/../config/rules.toml"))
            .expect("config/rules.toml");
    let mut cfg = Config::from_toml(&text).expect("valid rules config");
    cfg.sim.seed = 11;
    cfg
}

fn record_run(cfg: Config, dir: &std::path::Path) -> Vec<TickRecord> {
    super::fixtures::record_plain(cfg, "rules", dir, TICKS)
}

fn ticks_of<'a>(records: &'a [TickRecord], rule: &str) -> Vec<&'a TickRecord> {
    records
        .iter()
        .filter(|r| r.rule.as_deref() == Some(rule))
        .collect()
}

#[test]
fn two_rules_fire_at_different_times_and_replay_exactly() {
    let cfg = rules_config();
    assert_eq!(cfg.control.mode, Mode::Pavlovian);
    let ahead_response = cfg.rules[1].response;
    let dir = std::env::temp_dir().join(format!("pavlov-rules-{}", std::process::id()));
    let streamed = record_run(cfg, &dir);
    let rec = recording::load(&dir).expect("reads back");
    for (a, b) in streamed.iter().zip(&rec.records) {
        assert_eq!(a.rule, b.rule, "tick {}", a.seq);
    }
    let stall = ticks_of(&rec.records, "stall");
    let ahead = ticks_of(&rec.records, "stall_ahead");
    let stimulus = ticks_of(&rec.records, "stimulus");
    eprintln!(
        "{} ticks: stall {}, stall_ahead {}, stimulus {}",
        rec.records.len(),
        stall.len(),
        ahead.len(),
        stimulus.len()
    );
    assert!(!stall.is_empty() && !ahead.is_empty(), "both rules fire");
    // Each names its own prediction above its own threshold, and acts with its own response.
    for r in &ahead {
        assert!(r.predictions[1].value > 0.3, "tick {}", r.seq);
        assert!(
            r.predictions[0].value <= 0.5,
            "the stop rule outranks it: tick {}",
            r.seq
        );
        if r.safety_stop.is_none() {
            assert_eq!(r.command, ahead_response.action(r.seq), "tick {}", r.seq);
        }
    }
    for r in &stall {
        assert!(r.predictions[0].value > 0.5, "tick {}", r.seq);
        assert_eq!(r.command, Action::STOP, "tick {}", r.seq);
    }
    // The gate engaged exactly on the ticks that name what engaged it.
    assert!(rec.records.iter().all(|r| r.gate == r.rule.is_some()));
    let report = replay::replay(&rec).expect("replay");
    assert!(report.exact(), "{}", replay::describe(&report));
    assert_eq!(report.rules_compared, rec.records.len());
    // A tick recorded with another rule is a mismatch naming the field.
    let mut swapped = rec.clone();
    let at = rec
        .records
        .iter()
        .position(|r| r.seq == ahead[0].seq)
        .unwrap();
    swapped.records[at].rule = Some("stall".into());
    let report = replay::replay(&swapped).unwrap();
    assert_eq!(report.mismatch_count, 1, "{}", replay::describe(&report));
    assert_eq!(report.mismatches[0].field, "rule");
    // A recording made before the rule table (no rule anywhere) still replays, without the rule check.
    let mut older = rec.clone();
    for r in &mut older.records {
        r.rule = None;
    }
    let report = replay::replay(&older).unwrap();
    assert!(report.exact(), "{}", replay::describe(&report));
    assert_eq!(report.rules_compared, 0);
    let _ = std::fs::remove_dir_all(&dir);
}

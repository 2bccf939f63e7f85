//! Issue 24, item 1: the robustness study through the real binary, tiny (`--runs 1 --minutes 0.1`): it
//! writes its table (Markdown, CSV, JSON) and forest plot (SVG and PNG) into a new results folder, one row per
//! variation, each variation named with its source or marked an estimate; one run per policy prints no
//! interval; the flag refuses the options it cannot take.

use std::process::Command;

use pavlov_actors::experiment::stall::variations::{Basis, VARIATIONS};

use crate::common::TestDir;

const PAVLOV: &str = env!("CARGO_BIN_EXE_pavlov");

#[test]
fn a_tiny_robustness_study_writes_one_row_per_variation_and_a_forest_plot() {
    let dir = TestDir::new("variations");
    let out = Command::new(PAVLOV)
        .current_dir(dir.path())
        .args(["experiment", "stall", "--variations"])
        .args(["--runs", "1", "--minutes", "0.1", "--threads", "2"])
        .output()
        .expect("pavlov experiment stall --variations");
    let stdout = String::from_utf8_lossy(&out.stdout);
    assert!(
        out.status.success(),
        "{stdout}\n{}",
        String::from_utf8_lossy(&out.stderr)
    );
    let folder = dir.path().join("results").join("stall-variations-latest");
    for f in [
        "variations.md",
        "variations.csv",
        "variations.json",
        "fig_variations.svg",
        "fig_variations.png",
    ] {
        let len = std::fs::metadata(folder.join(f)).map_or(0, |m| m.len());
        assert!(len > 0, "{f} written");
    }

    // Markdown: a header, then one row per variation, in order; the same on the terminal.
    let md = std::fs::read_to_string(folder.join("variations.md")).unwrap();
    let rows: Vec<&str> = md.lines().filter(|l| l.starts_with("| ")).skip(1).collect();
    assert_eq!(rows.len(), VARIATIONS.len(), "{md}");
    for (row, v) in rows.iter().zip(&VARIATIONS) {
        assert!(
            row.starts_with(&format!("| {} | {} |", v.name, v.group)),
            "{row}"
        );
        let basis = match v.basis {
            Basis::Source(_) => "| source: ",
            Basis::Estimate(_) => "| estimate: ",
        };
        assert!(row.contains(basis), "{row}");
        assert!(row.ends_with("| 1 + 1 |"), "{row}");
        // One run per policy: no spread, so no interval.
        assert_eq!(row.matches("(no interval)").count(), 2, "{row}");
        assert!(stdout.contains(&format!("| {} |", v.name)));
    }
    assert!(md.contains("fewer over-current observations") && md.contains("higher efficiency"));

    // CSV: a header and one line per variation with its basis kind and both effects.
    let csv = std::fs::read_to_string(folder.join("variations.csv")).unwrap();
    let lines: Vec<&str> = csv.lines().collect();
    assert_eq!(lines.len(), 1 + VARIATIONS.len());
    assert!(lines[0].starts_with("variation,group,change,basis,"));
    assert!(lines[0].contains("overcurrent_change") && lines[0].contains("efficiency_ci_hi"));
    for (line, v) in lines[1..].iter().zip(&VARIATIONS) {
        assert!(line.starts_with(v.name), "{line}");
        assert!(
            line.contains(",source,") || line.contains(",estimate,"),
            "{line}"
        );
    }

    // The forest plot: an SVG and a 300-dpi PNG in the print style of every figure, naming every
    // variation, both panels.
    super::figures::check_figure(&folder, "fig_variations");
    let svg = std::fs::read_to_string(folder.join("fig_variations.svg")).unwrap();
    assert!(svg.starts_with("<svg") || svg.contains("<svg"));
    assert!(svg.contains("over-current observations") && svg.contains("efficiency (m/kJ)"));
    for v in &VARIATIONS {
        let name = v.name.replace('&', "&amp;");
        assert!(svg.contains(&name), "{} in the plot", v.name);
    }

    // The JSON names the seeds every variation shares.
    let json: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(folder.join("variations.json")).unwrap())
            .unwrap();
    assert_eq!(
        json["rows"].as_array().map(Vec::len),
        Some(VARIATIONS.len())
    );
    assert_eq!(json["seeds"].as_array().map(Vec::len), Some(2));
}

#[test]
fn variations_refuse_policies_and_shards() {
    let dir = TestDir::new("variations-refused");
    for extra in [["--policies", "reactive,pavlovian"], ["--shard", "0/2"]] {
        let out = Command::new(PAVLOV)
            .current_dir(dir.path())
            .args(["experiment", "stall", "--variations", "--runs", "1"])
            .args(extra)
            .output()
            .unwrap();
        assert!(!out.status.success(), "{extra:?}");
        assert!(String::from_utf8_lossy(&out.stderr).contains("cannot be used with"));
    }
}

//! Checking merged runs against the plan: the study's options define every run (its index, its policy and
//! its seeds), so a merged run must be the run its position plans, not merely a run at that position. A
//! run altered in its file, or taken from another study, is refused naming the file, the position and the
//! field ([`MergeError::OffPlan`]), and a set whose runs the options do not plan in number is refused before
//! the plan is drawn ([`MergeError::PlanSize`]), so a count stated in a file never sizes anything.

use std::ops::Range;
use std::path::PathBuf;

use super::MergeError;

/// What the plan says of one run (and what a merged run says of itself).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct PlannedRun {
    /// Its index in the study.
    pub index: usize,
    /// Its policy's name.
    pub mode: &'static str,
    /// Its seeds, each with its name ("seed", "robot seed", …).
    pub seeds: Vec<(&'static str, u64)>,
}

/// Checks that `runs` (in planned order, from `sources`) are the `planned` runs: their number first
/// (`planned` is `None` when the options' count overflows; `options` says which options decide it), then
/// each run against `plan(position)`.
pub fn check_plan<R>(
    runs: &[R],
    sources: &[(Range<usize>, PathBuf)],
    planned: Option<usize>,
    options: &str,
    plan: impl Fn(usize) -> PlannedRun,
    found: impl Fn(&R) -> PlannedRun,
) -> Result<(), MergeError> {
    if planned != Some(runs.len()) {
        return Err(MergeError::PlanSize {
            found: runs.len(),
            planned: planned.map_or_else(
                || "more than the machine can count".to_string(),
                |n| n.to_string(),
            ),
            options: options.to_string(),
        });
    }
    for (position, run) in runs.iter().enumerate() {
        let (want, got) = (plan(position), found(run));
        let off = |what, expected: String, found: String| MergeError::OffPlan {
            path: sources
                .iter()
                .find(|(r, _)| r.contains(&position))
                .map_or_else(PathBuf::new, |(_, p)| p.clone()),
            position,
            what,
            expected,
            found,
        };
        if want.index != got.index {
            return Err(off("index", want.index.to_string(), got.index.to_string()));
        }
        if want.mode != got.mode {
            return Err(off("mode", want.mode.into(), got.mode.into()));
        }
        for (&(name, w), &(_, g)) in want.seeds.iter().zip(&got.seeds) {
            if w != g {
                return Err(off(name, w.to_string(), g.to_string()));
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn planned(p: usize) -> PlannedRun {
        PlannedRun {
            index: p,
            mode: if p % 2 == 0 { "reactive" } else { "pavlovian" },
            seeds: vec![("seed", 100 + p as u64)],
        }
    }

    #[test]
    fn runs_off_their_plan_are_refused_naming_file_position_and_field() {
        let sources = vec![
            (0..2, PathBuf::from("a.json")),
            (2..4, PathBuf::from("b.json")),
        ];
        let mut runs: Vec<PlannedRun> = (0..4).map(planned).collect();
        let check = |runs: &[PlannedRun], n| {
            check_plan(
                runs,
                &sources,
                n,
                "runs_per_policy 2",
                planned,
                Clone::clone,
            )
        };
        assert!(check(&runs, Some(4)).is_ok());
        let e = check(&runs, Some(6)).unwrap_err().to_string();
        assert!(e.contains("hold 4 runs") && e.contains("plan 6"), "{e}");
        let e = check(&runs, None).unwrap_err().to_string();
        assert!(e.contains("more than the machine can count"), "{e}");
        runs[3].seeds[0].1 = 7;
        let e = check(&runs, Some(4)).unwrap_err().to_string();
        assert!(
            e.contains("b.json: the run at position 3 has seed 7") && e.contains("plan seed 103"),
            "{e}"
        );
        runs[1].mode = "reactive";
        let e = check(&runs, Some(4)).unwrap_err().to_string();
        assert!(
            e.contains("a.json: the run at position 1 has mode reactive")
                && e.contains("plan mode pavlovian"),
            "{e}"
        );
        runs[0].index = 9;
        let e = check(&runs, Some(4)).unwrap_err().to_string();
        assert!(e.contains("position 0 has index 9"), "{e}");
    }
}

//! The `--learners` tables: `learners.md` (three Markdown tables: when anticipation starts, the leads, the
//! anticipated excess and false starts), `learners.csv` (one row per learner, every figure) and the terminal
//! summary (the first table).

use std::fmt::Write as _;

use pavlov::analysis::bootstrap::MeanDifference;

use super::metrics::{BLOCK, FIRST_MIN, LEAD_WINDOW_MIN, LearnerRow, MedianInterval};
use crate::experiment::interaction::InteractionOptions;

fn num(x: f64, decimals: usize) -> String {
    if x.is_infinite() {
        "never".into()
    } else if x.is_nan() {
        "–".into()
    } else {
        format!("{x:.decimals$}")
    }
}

/// `median [lo, hi]` (never = not in the run), with the pairs where it never happened.
fn median(m: &MedianInterval, decimals: usize) -> String {
    let never = if m.never > 0 {
        format!(" ({} of {} never)", m.never, m.n)
    } else {
        String::new()
    };
    format!(
        "{} [{}, {}]{never}",
        num(m.median, decimals),
        num(m.lo, decimals),
        num(m.hi, decimals)
    )
}

fn ci(d: Option<MeanDifference>, scale: f64, decimals: usize) -> String {
    d.map_or("–".into(), |d| {
        format!(
            "{:+.decimals$} [{:+.decimals$}, {:+.decimals$}]",
            d.difference * scale,
            d.lo * scale,
            d.hi * scale
        )
    })
}

/// The heading shared by the tables: what was run.
fn heading(o: &InteractionOptions) -> String {
    format!(
        "{} pairs × {} min per learner, seed {} (pair k answers the same simulated operator for every learner, \
         in both its runs); medians over pairs [95 % bootstrap interval over pairs]; leads and excesses: mean \
         over pairs of the within-pair difference [95 % paired bootstrap interval]",
        o.runs_per_policy, o.minutes, o.seed
    )
}

/// The first table: when anticipation starts, in commands and minutes.
pub fn onset_table(rows: &[LearnerRow], o: &InteractionOptions) -> String {
    let mut t = String::new();
    let _ = writeln!(t, "{}\n", heading(o));
    let _ = writeln!(
        t,
        "| learner | commands/min | first anticipated: command | first anticipated: min | holds from: command | holds from: min |"
    );
    let _ = writeln!(t, "|---|---|---|---|---|---|");
    for r in rows {
        let _ = writeln!(
            t,
            "| {} | {:.1} | {} | {} | {} | {} |",
            r.learner,
            r.commands_per_min,
            median(&r.first_commands, 0),
            median(&r.first_min, 1),
            median(&r.holds_commands, 0),
            median(&r.holds_min, 1),
        );
    }
    t
}

/// The second table: the decision and current leads at each moment.
pub fn lead_table(rows: &[LearnerRow]) -> String {
    let mut t = String::new();
    let moments: Vec<f64> = rows
        .first()
        .map(|r| r.leads.iter().map(|l| l.at_min).collect())
        .unwrap_or_default();
    let window = |m: f64| format!("{:.0}–{:.0} min", (m - LEAD_WINDOW_MIN).max(0.0), m);
    let _ = write!(t, "| learner |");
    for &m in &moments {
        let _ = write!(t, " decision lead {} |", window(m));
    }
    for &m in &moments {
        let _ = write!(t, " current lead {} |", window(m));
    }
    let _ = writeln!(t);
    let _ = writeln!(t, "|---|{}", "---|".repeat(2 * moments.len()));
    for r in rows {
        let _ = write!(t, "| {} |", r.learner);
        for l in &r.leads {
            let _ = write!(t, " {} |", ci(l.decision, 1.0, 0));
        }
        for l in &r.leads {
            let _ = write!(t, " {} |", ci(l.current, 1.0, 0));
        }
        let _ = writeln!(t);
    }
    t
}

/// The third table: anticipated excess over the reactive baseline and false starts.
pub fn cost_table(rows: &[LearnerRow]) -> String {
    let mut t = String::new();
    let f = FIRST_MIN;
    let _ = writeln!(
        t,
        "| learner | anticipated − reactive, 0–{f:.0} min (pp) | anticipated − reactive, whole run (pp) | \
         Pavlovian false starts/min, 0–{f:.0} min | excess over reactive, 0–{f:.0} min | Pavlovian false starts/min, whole run | excess over reactive, whole run |"
    );
    let _ = writeln!(t, "|---|---|---|---|---|---|---|");
    for r in rows {
        let _ = writeln!(
            t,
            "| {} | {} | {} | {:.2} | {} | {:.2} | {} |",
            r.learner,
            ci(r.anticipated_first, 100.0, 1),
            ci(r.anticipated, 100.0, 1),
            r.false_starts_first.pavlovian_per_min,
            ci(r.false_starts_first.excess, 1.0, 2),
            r.false_starts.pavlovian_per_min,
            ci(r.false_starts.excess, 1.0, 2),
        );
    }
    t
}

/// `learners.md`: the three tables with the definitions.
pub fn markdown(rows: &[LearnerRow], o: &InteractionOptions) -> String {
    format!(
        "{}\nAnticipated command: the Pavlovian run decided before the true onset and before the reactive run \
         of the same pair. Anticipation holds from the first command from which every block of {BLOCK} \
         consecutive commands has a positive mean decision lead (reactive − Pavlovian).\n\n{}\n{}",
        onset_table(rows, o),
        lead_table(rows),
        cost_table(rows)
    )
}

/// `learners.csv`: one row per learner.
pub fn csv(rows: &[LearnerRow]) -> String {
    let m = |x: &MedianInterval| format!("{},{},{},{}", x.median, x.lo, x.hi, x.never);
    let d = |x: Option<MeanDifference>| {
        x.map_or(",,".to_string(), |x| {
            format!("{},{},{}", x.difference, x.lo, x.hi)
        })
    };
    let moments: Vec<f64> = rows
        .first()
        .map(|r| r.leads.iter().map(|l| l.at_min).collect())
        .unwrap_or_default();
    let mut c = String::from(
        "learner,pairs,commands_per_min,first_command,lo,hi,never,first_min,lo,hi,never,\
         holds_command,lo,hi,never,holds_min,lo,hi,never",
    );
    for t in &moments {
        let _ = write!(c, ",decision_lead_{t}min,lo,hi,current_lead_{t}min,lo,hi");
    }
    c.push_str(
        ",anticipated_excess_first,lo,hi,anticipated_excess,lo,hi,false_starts_first,excess,lo,hi,\
         false_starts,excess,lo,hi\n",
    );
    for r in rows {
        let _ = write!(
            c,
            "{},{},{},{},{},{},{}",
            r.learner,
            r.pairs,
            r.commands_per_min,
            m(&r.first_commands),
            m(&r.first_min),
            m(&r.holds_commands),
            m(&r.holds_min)
        );
        for l in &r.leads {
            let _ = write!(c, ",{},{}", d(l.decision), d(l.current));
        }
        let _ = writeln!(
            c,
            ",{},{},{},{},{},{}",
            d(r.anticipated_first),
            d(r.anticipated),
            r.false_starts_first.pavlovian_per_min,
            d(r.false_starts_first.excess),
            r.false_starts.pavlovian_per_min,
            d(r.false_starts.excess)
        );
    }
    c
}

//! `fig_learners.{svg,png}`: the decision lead and the battery current's lead (reactive − Pavlovian onset,
//! ms) against commands given, one line per learner, each point the mean over pairs of a block of
//! [`FIG_BLOCK`] commands (drawn at the block's last command).

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::metrics::{FIG_BLOCK, LearnerRow};
use crate::experiment::interaction::plots::{GREEN, Series, lines_panel};
use crate::experiment::plot_style::{
    self as ps, DARK, Dash, Figure, Io, ONE_COLUMN_IN, PAVLOVIAN, REACTIVE, Style,
};

/// A fifth colour, apart from the others.
const PURPLE: RGBColor = RGBColor(130, 60, 160);

/// The colour and dash of the i-th learner.
fn style(i: usize) -> (RGBColor, Dash) {
    const COLOURS: [RGBColor; 5] = [DARK, PAVLOVIAN, REACTIVE, GREEN, PURPLE];
    const DASHES: [Dash; 3] = [Dash::Solid, Dash::Dashed, Dash::Dotted];
    (COLOURS[i % COLOURS.len()], DASHES[i % DASHES.len()])
}

struct FigLearners<'a> {
    rows: &'a [LearnerRow],
    caption: String,
}

impl Figure for FigLearners<'_> {
    fn size_in(&self) -> (f64, f64) {
        (ONE_COLUMN_IN, 4.8)
    }

    fn caption(&self) -> String {
        self.caption.clone()
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>, st: &Style) -> Io {
        let panels = root.split_evenly((2, 1));
        let last = self
            .rows
            .iter()
            .flat_map(|r| r.by_command.last().map(|b| b.0))
            .max()
            .unwrap_or(FIG_BLOCK) as f64;
        let series = |pick: fn(&(usize, f64, f64)) -> f64| -> Vec<Series> {
            self.rows
                .iter()
                .enumerate()
                .map(|(i, r)| {
                    let (c, d) = style(i);
                    let pts = r.by_command.iter().map(|b| (b.0 as f64, pick(b))).collect();
                    (r.learner.clone(), c, d, pts)
                })
                .collect()
        };
        if let Some(a) = panels.first() {
            lines_panel(
                a,
                st,
                "Decision lead (reactive − Pavlovian gate onset)",
                0.0..last,
                None,
                &series(|b| b.1),
                &[0.0],
                ("", "lead (ms)"),
            )?;
        }
        if let Some(a) = panels.get(1) {
            lines_panel(
                a,
                st,
                "Battery-current lead",
                0.0..last,
                None,
                &series(|b| b.2),
                &[0.0],
                ("commands given", "lead (ms)"),
            )?;
        }
        Ok(())
    }
}

/// Writes `fig_learners.{svg,png}` into `dir`; `pairs` and `minutes` go into the caption.
pub(crate) fn fig_learners(dir: &Path, rows: &[LearnerRow], pairs: usize, minutes: f64) -> Io {
    let caption = format!(
        "Mean over {pairs} operators (pairs of runs, {minutes} min each) of each block of {FIG_BLOCK} commands' \
         mean lead, drawn at the block's last command; positive = the Pavlovian run earlier."
    );
    ps::save(dir, "fig_learners", &FigLearners { rows, caption })
}

//! The robustness study's forest plot (`fig_variations.{svg,png}`), in the print style of every experiment
//! figure (`plot_style`): one row per variation, grouped (a light rule between groups), two panels — the
//! relative change in over-current observations and in efficiency, Pavlovian against reactive — each a
//! marker with its 95 % interval. The baseline is a square, every variation a circle (shape as well as
//! colour); the solid grey line at no change and the dashed one at the paper's value are reference lines,
//! named in the caption, not in a legend.

use std::path::Path;

use plotters::coord::Shift;
use plotters::prelude::*;

use super::analysis::Comparison;
use super::variations::{Row, VariationsStudy};
use crate::experiment::plot_style::{
    self as ps, Dash, Figure, Io, PAVLOVIAN, REACTIVE, REFERENCE, Style, TWO_COLUMNS_IN, err,
};

/// The paper's over-current change, percent.
const PAPER_OVERCURRENT: f64 = -41.0;
/// The paper's efficiency change, percent.
const PAPER_EFFICIENCY: f64 = 10.0;
/// Height of one row, inches.
const ROW_IN: f64 = 0.16;
/// Room for the title, the axes and the caption, inches.
const FRAME_IN: f64 = 1.25;
/// Width of the row names, pt.
const NAMES_PT: f64 = 118.0;

/// Point and interval of a change, percent (the interval only with two runs per policy or more).
fn effect(c: &Comparison) -> Option<(f64, Option<(f64, f64)>)> {
    let r = c.relative_change.filter(|r| r.is_finite())?;
    let ci = c
        .relative_change_ci
        .filter(|(lo, hi)| lo.is_finite() && hi.is_finite())
        .filter(|_| c.reactive.n > 1 && c.pavlovian.n > 1)
        .map(|(lo, hi)| (lo * 100.0, hi * 100.0));
    Some((r * 100.0, ci))
}

/// The x range of a panel: every point and interval, 0 and the paper's value, with a margin.
fn x_range(rows: &[Row], pick: fn(&Row) -> &Comparison, paper: f64) -> std::ops::Range<f64> {
    let mut lo: f64 = paper.min(0.0);
    let mut hi: f64 = paper.max(0.0);
    for r in rows {
        if let Some((p, ci)) = effect(pick(r)) {
            let (a, b) = ci.unwrap_or((p, p));
            lo = lo.min(a).min(p);
            hi = hi.max(b).max(p);
        }
    }
    let pad = ((hi - lo) * 0.06).max(1.0);
    (lo - pad)..(hi + pad)
}

struct Forest<'a> {
    study: &'a VariationsStudy,
}

impl Forest<'_> {
    fn panel<DB: DrawingBackend>(
        &self,
        area: &DrawingArea<DB, Shift>,
        st: &Style,
        pick: fn(&Row) -> &Comparison,
        (title, x_desc): (&str, &str),
        paper: f64,
        names: bool,
    ) -> Io {
        let rows = &self.study.rows;
        let n = rows.len().max(1);
        let body = ps::panel_header(area, st, title, &[])?;
        let names_owned: Vec<String> = rows.iter().map(|r| r.name.clone()).collect();
        let label = move |y: &f64| -> String {
            let i = y.round();
            if !names || (y - i).abs() > 1e-6 || i < 0.0 {
                return String::new();
            }
            names_owned.get(i as usize).cloned().unwrap_or_default()
        };
        let mut ch = ChartBuilder::on(&body)
            .margin_top(st.px(2.0))
            .margin_right(st.px(8.0))
            .margin_left(st.px(2.0))
            .x_label_area_size(st.px(8.0 * 2.9))
            .y_label_area_size(st.px(if names { NAMES_PT } else { 3.0 }))
            .build_cartesian_2d(x_range(rows, pick, paper), (n as f64 - 0.5)..-0.5f64)
            .map_err(err)?;
        ch.configure_mesh()
            .disable_y_mesh()
            .max_light_lines(0)
            .bold_line_style(st.line(ps::GRID, 0.5))
            .axis_style(st.line(BLACK, 0.75))
            .set_all_tick_mark_size(st.px(2.5))
            .label_style(st.text(8.0))
            .axis_desc_style(st.text(8.0))
            .x_labels(6)
            .y_labels(n + 1)
            .x_desc(x_desc)
            .x_label_formatter(&ps::tick_label)
            .y_label_formatter(&label)
            .draw()
            .map_err(err)?;
        let (top, bottom) = (-0.5, n as f64 - 0.5);
        let (x0, x1) = (ch.x_range().start, ch.x_range().end);
        // A light rule between groups.
        for (i, pair) in rows.windows(2).enumerate() {
            if let [a, b] = pair
                && a.group != b.group
            {
                let y = i as f64 + 0.5;
                ps::line(&mut ch, st, &[(x0, y), (x1, y)], ps::GRID, Dash::Solid, 0.5)?;
            }
        }
        // Reference lines: no change (solid) and the paper's value (dashed); no legend entry.
        ps::line(
            &mut ch,
            st,
            &[(0.0, top), (0.0, bottom)],
            REFERENCE,
            Dash::Solid,
            0.75,
        )?;
        ps::line(
            &mut ch,
            st,
            &[(paper, top), (paper, bottom)],
            REFERENCE,
            Dash::Dashed,
            0.75,
        )?;
        let r = st.px(2.1);
        for (i, row) in rows.iter().enumerate() {
            let Some((p, ci)) = effect(pick(row)) else {
                continue;
            };
            let y = i as f64;
            let baseline = i == 0;
            let c = if baseline { REACTIVE } else { PAVLOVIAN };
            if let Some((lo, hi)) = ci {
                ps::line(&mut ch, st, &[(lo, y), (hi, y)], c, Dash::Solid, 1.0)?;
                for x in [lo, hi] {
                    ch.draw_series(std::iter::once(
                        EmptyElement::at((x, y))
                            + PathElement::new(vec![(0, -r), (0, r)], st.line(c, 1.0)),
                    ))
                    .map_err(err)?;
                }
            }
            if baseline {
                ch.draw_series(std::iter::once(
                    EmptyElement::at((p, y)) + Rectangle::new([(-r, -r), (r, r)], c.filled()),
                ))
                .map_err(err)?;
            } else {
                ch.draw_series(std::iter::once(Circle::new((p, y), r, c.filled())))
                    .map_err(err)?;
            }
        }
        Ok(())
    }
}

impl Figure for Forest<'_> {
    fn size_in(&self) -> (f64, f64) {
        let rows = self.study.rows.len().max(1) as f64;
        (TWO_COLUMNS_IN, FRAME_IN + ROW_IN * rows)
    }

    fn caption(&self) -> String {
        let o = &self.study.options;
        let paper = |x: f64| ps::signed(&format!("{x:+.0} %"));
        format!(
            "Marker: relative change of the mean, (Pavlovian \u{2212} reactive) / reactive; bar: its 95 % \
             bootstrap interval (ratio of means); n = {} reactive + {} Pavlovian interleaved runs \u{d7} {} \
             min per variation, the same run seeds in every variation. Square: the baseline \
             (config/stall.toml); solid grey line: no change; dashed: the paper's value ({}, {}).",
            o.runs_per_policy,
            o.runs_per_policy,
            o.minutes,
            paper(PAPER_OVERCURRENT),
            paper(PAPER_EFFICIENCY)
        )
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>, st: &Style) -> Io {
        let (w, _) = root.dim_in_pixel();
        let names_px = st.px(NAMES_PT);
        let left_w = names_px + (w as i32 - names_px) / 2;
        let (left, right) = root.split_horizontally(left_w);
        self.panel(
            &left,
            st,
            |r| &r.overcurrent,
            (
                "Over-current observations",
                "relative change in over-current observations, %",
            ),
            PAPER_OVERCURRENT,
            true,
        )?;
        self.panel(
            &right,
            st,
            |r| &r.efficiency,
            ("Efficiency", "relative change in efficiency (m/kJ), %"),
            PAPER_EFFICIENCY,
            false,
        )
    }
}

/// Draws the forest plot of `study` as `fig_variations.svg` and `fig_variations.png` (300 dpi) in `dir`.
pub(crate) fn forest(dir: &Path, study: &VariationsStudy) -> Io {
    ps::save(dir, "fig_variations", &Forest { study })
}

//! The robustness study's forest plot (`fig_variations.svg`): one row per variation, two panels — the
//! relative change in over-current observations and in efficiency, Pavlovian against reactive — each a
//! point with its 95 % interval, a line at no change and, dashed, the paper's value.

use std::path::Path;

use plotters::prelude::*;

use super::analysis::Comparison;
use super::variations::{Row, VariationsStudy};
use crate::experiment::plot_style::tick_label;

type Io = std::io::Result<()>;

fn err<E: std::fmt::Display>(e: E) -> std::io::Error {
    std::io::Error::other(e.to_string())
}

const ROW_PX: u32 = 24;
const POINT: RGBColor = RGBColor(40, 100, 200);
const BASELINE: RGBColor = RGBColor(200, 80, 40);

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
fn x_range(rows: &[Row], pick: fn(&Row) -> &Comparison, paper: f64) -> (f64, f64) {
    let mut lo: f64 = paper.min(0.0);
    let mut hi: f64 = paper.max(0.0);
    for r in rows {
        if let Some((p, ci)) = effect(pick(r)) {
            let (a, b) = ci.unwrap_or((p, p));
            lo = lo.min(a).min(p);
            hi = hi.max(b).max(p);
        }
    }
    let pad = ((hi - lo) * 0.08).max(1.0);
    (lo - pad, hi + pad)
}

fn panel(
    area: &DrawingArea<SVGBackend, plotters::coord::Shift>,
    rows: &[Row],
    pick: fn(&Row) -> &Comparison,
    title: &str,
    paper: f64,
    names: bool,
) -> Io {
    let n = rows.len().max(1);
    let (x0, x1) = x_range(rows, pick, paper);
    let names_owned: Vec<String> = rows.iter().map(|r| r.name.clone()).collect();
    let label = move |y: &f64| -> String {
        if !names {
            return String::new();
        }
        let i = y.round();
        if (y - i).abs() > 1e-6 || i < 0.0 {
            return String::new();
        }
        names_owned.get(i as usize).cloned().unwrap_or_default()
    };
    let mut ch = ChartBuilder::on(area)
        .caption(title, (crate::experiment::plot_style::FONT, 16))
        .margin(10)
        .x_label_area_size(40)
        .y_label_area_size(if names { 170 } else { 10 })
        .build_cartesian_2d(x0..x1, (n as f64 - 0.5)..-0.5f64)
        .map_err(err)?;
    ch.configure_mesh()
        .disable_y_mesh()
        .light_line_style(TRANSPARENT)
        .bold_line_style(BLACK.mix(0.12))
        .y_labels(n + 1)
        .y_label_formatter(&label)
        .x_label_formatter(&tick_label)
        .x_desc("change, Pavlovian vs reactive (%)")
        .axis_desc_style((crate::experiment::plot_style::FONT, 13))
        .label_style((crate::experiment::plot_style::FONT, 12))
        .draw()
        .map_err(err)?;
    let top = -0.5;
    let bottom = n as f64 - 0.5;
    ch.draw_series(std::iter::once(PathElement::new(
        vec![(0.0, top), (0.0, bottom)],
        BLACK.stroke_width(1),
    )))
    .map_err(err)?;
    // The paper's value, dashed.
    let mut y = top;
    let mut dashes = Vec::new();
    while y < bottom {
        dashes.push(PathElement::new(
            vec![(paper, y), (paper, (y + 0.25).min(bottom))],
            RGBColor(120, 120, 120).stroke_width(1),
        ));
        y += 0.45;
    }
    ch.draw_series(dashes).map_err(err)?;
    for (i, r) in rows.iter().enumerate() {
        let Some((p, ci)) = effect(pick(r)) else {
            continue;
        };
        let y = i as f64;
        let c = if i == 0 { BASELINE } else { POINT };
        if let Some((lo, hi)) = ci {
            ch.draw_series([
                PathElement::new(vec![(lo, y), (hi, y)], c.stroke_width(2)),
                PathElement::new(vec![(lo, y - 0.2), (lo, y + 0.2)], c.stroke_width(2)),
                PathElement::new(vec![(hi, y - 0.2), (hi, y + 0.2)], c.stroke_width(2)),
            ])
            .map_err(err)?;
        }
        ch.draw_series(std::iter::once(Circle::new((p, y), 4, c.filled())))
            .map_err(err)?;
    }
    Ok(())
}

/// Draws the forest plot of `study` into `path`.
pub(crate) fn forest(path: &Path, study: &VariationsStudy) -> Io {
    crate::experiment::plot_style::register_font();
    let rows = &study.rows;
    let height = 150 + ROW_PX * rows.len().max(1) as u32;
    let root = SVGBackend::new(path, (1100, height)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let o = &study.options;
    let (head, body) = root.split_vertically(50);
    head.draw(&Text::new(
        format!(
            "Pavlovian vs reactive under variation: point = relative change, bar = 95 % bootstrap interval, \
             n = {} + {} runs × {} min each; dashed = the paper's value; first row (orange) = baseline",
            o.runs_per_policy, o.runs_per_policy, o.minutes
        ),
        (10, 18),
        (crate::experiment::plot_style::FONT, 13),
    ))
    .map_err(err)?;
    let (left, right) = body.split_horizontally(620);
    panel(
        &left,
        rows,
        |r| &r.overcurrent,
        "over-current observations",
        -41.0,
        true,
    )?;
    panel(
        &right,
        rows,
        |r| &r.efficiency,
        "efficiency (m/kJ)",
        10.0,
        false,
    )?;
    root.present().map_err(err)
}

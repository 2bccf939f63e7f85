//! The interaction experiment's figures: analogues of the paper's Figure 3 (signals around a command after
//! 2.5 min, per policy) and Figure 4 (battery current and rotation averaged over commands, aligned on the
//! observed command onset).

use std::path::Path;
use std::sync::Arc;

use pavlov::control::Mode;
use pavlov::record::TickRecord;
use plotters::prelude::*;

use super::InteractionStudy;
use super::analysis::AlignedPoint;
use super::run::{self as interaction, InteractionRun};
use crate::experiment::mode_name;
use pavlov::analysis::stats::Describe;

fn err<E: std::fmt::Display>(e: E) -> std::io::Error {
    std::io::Error::other(e.to_string())
}

type Series = (String, RGBColor, Vec<(f64, f64)>);
/// A shaded band (x, low, high) in a series' colour: the 95 % confidence interval of a mean.
type Band = (RGBColor, Vec<(f64, f64, f64)>);

fn panel(
    area: &DrawingArea<SVGBackend, plotters::coord::Shift>,
    title: &str,
    x: std::ops::Range<f64>,
    series: &[Series],
    bands: &[Band],
    x_desc: &str,
) -> std::io::Result<()> {
    let ys = series.iter().flat_map(|s| s.2.iter().map(|p| p.1)).chain(
        bands
            .iter()
            .flat_map(|b| b.1.iter().flat_map(|p| [p.1, p.2])),
    );
    let (lo, hi) = ys
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
            (l.min(v), h.max(v))
        });
    let (lo, hi) = if lo.is_finite() { (lo, hi) } else { (0.0, 1.0) };
    let pad = ((hi - lo) * 0.08).max(1e-6);
    let mut ch = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 14))
        .margin(6)
        .x_label_area_size(28)
        .y_label_area_size(50)
        .build_cartesian_2d(x, (lo - pad)..(hi + pad))
        .map_err(err)?;
    ch.configure_mesh().x_desc(x_desc).draw().map_err(err)?;
    for (color, pts) in bands {
        let outline: Vec<(f64, f64)> = pts
            .iter()
            .map(|p| (p.0, p.2))
            .chain(pts.iter().rev().map(|p| (p.0, p.1)))
            .filter(|p| p.1.is_finite())
            .collect();
        if outline.len() > 2 {
            ch.draw_series(std::iter::once(Polygon::new(outline, color.mix(0.18))))
                .map_err(err)?;
        }
    }
    for (label, color, pts) in series {
        let c = *color;
        ch.draw_series(LineSeries::new(pts.iter().copied(), c.stroke_width(2)))
            .map_err(err)?
            .label(label.as_str())
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], c));
    }
    ch.configure_series_labels()
        .background_style(WHITE.mix(0.8))
        .border_style(BLACK)
        .draw()
        .map_err(err)?;
    Ok(())
}

const RED: RGBColor = RGBColor(200, 80, 40);
const BLUE: RGBColor = RGBColor(40, 100, 200);
const GREY: RGBColor = RGBColor(90, 90, 90);

/// Ten seconds after 2.5 min of each policy's first run, centred on an observed command onset.
fn excerpt(r: &InteractionRun) -> &[Arc<TickRecord>] {
    let from = 150 * 50;
    let onset = r
        .aligned_onsets
        .iter()
        .map(|&i| i as usize)
        .find(|&i| i >= from + 250)
        .unwrap_or(from + 250);
    let start = onset.saturating_sub(250);
    r.records
        .get(start..(start + 500).min(r.records.len()))
        .unwrap_or(&[])
}

/// Figure 3: elbow angle, prediction, current and command around a command, one column per policy.
pub(crate) fn fig3(path: &Path, s: &InteractionStudy) -> std::io::Result<()> {
    let root = SVGBackend::new(path, (1000, 800)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let root = root
        .titled(
            "Fig. 3 analogue: timing of signals after 2.5 min (10 s around a command)",
            ("sans-serif", 18),
        )
        .map_err(err)?;
    let firsts: Vec<&InteractionRun> = [Mode::Reactive, Mode::Pavlovian]
        .iter()
        .filter_map(|m| s.runs.iter().find(|r| r.mode == *m))
        .collect();
    let cols = root.split_evenly((1, firsts.len().max(1)));
    for (r, col) in firsts.iter().zip(cols.iter()) {
        let recs = excerpt(r);
        let t0 = recs.first().map_or(0.0, |x| x.t_ms);
        let t = |x: &TickRecord| (x.t_ms - t0) / 1000.0;
        let span = 0.0..10.0;
        let c = if r.mode == Mode::Pavlovian { BLUE } else { RED };
        let rows = col.split_evenly((4, 1));
        let elbow: Vec<(f64, f64)> = recs
            .iter()
            .filter_map(|x| x.elbow.as_ref().and_then(|e| e.left).map(|a| (t(x), a)))
            .collect();
        let ninety: Vec<(f64, f64)> = vec![(0.0, 90.0), (10.0, 90.0)];
        let pred: Vec<(f64, f64)> = recs
            .iter()
            .filter_map(|x| x.predictions.first().map(|p| (t(x), p.value)))
            .collect();
        let theta: Vec<(f64, f64)> = recs
            .iter()
            .filter_map(|x| x.predictions.first().map(|p| (t(x), p.threshold)))
            .collect();
        let stim: Vec<(f64, f64)> = recs
            .iter()
            .map(|x| (t(x), if x.stimulus { 1.0 } else { 0.0 }))
            .collect();
        let current: Vec<(f64, f64)> = recs
            .iter()
            .filter_map(|x| x.sensors.battery_current_ma.map(|i| (t(x), f64::from(i))))
            .collect();
        let right_cmd: Vec<(f64, f64)> = recs
            .iter()
            .map(|x| (t(x), f64::from(x.command.right_mm_s)))
            .collect();
        let name = mode_name(r.mode);
        let panels: [(String, Vec<Series>); 4] = [
            (
                format!("{name}: left elbow angle, °"),
                vec![("angle".into(), c, elbow), ("90°".into(), GREY, ninety)],
            ),
            (
                "prediction, threshold, stimulus E".into(),
                vec![
                    ("prediction".into(), c, pred),
                    ("threshold".into(), BLACK, theta),
                    ("E".into(), GREY, stim),
                ],
            ),
            (
                "battery current, mA".into(),
                vec![("current".into(), c, current)],
            ),
            (
                "right wheel command, mm/s (spin left)".into(),
                vec![("command".into(), c, right_cmd)],
            ),
        ];
        for (area, (title, series)) in rows.iter().zip(panels.iter()) {
            panel(area, title, span.clone(), series, &[], "time, s")?;
        }
    }
    root.present().map_err(err)
}

/// Figure 4: current and rotation aligned on the observed command onset, both policies.
pub(crate) fn fig4(path: &Path, s: &InteractionStudy) -> std::io::Result<()> {
    let root = SVGBackend::new(path, (1000, 420)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let cols = root.split_evenly((1, 2));
    let x = |p: &AlignedPoint| p.offset as f64 * 0.02;
    let span = (-interaction::BEFORE_TICKS as f64 * 0.02)..(interaction::AFTER_TICKS as f64 * 0.02);
    let cur: Vec<Series> = vec![
        (
            "reactive".into(),
            RED,
            s.aligned
                .iter()
                .map(|p| (x(p), p.current_reactive.mean))
                .collect(),
        ),
        (
            "Pavlovian".into(),
            BLUE,
            s.aligned
                .iter()
                .map(|p| (x(p), p.current_pavlovian.mean))
                .collect(),
        ),
    ];
    let ang: Vec<Series> = vec![
        (
            "reactive".into(),
            RED,
            s.aligned
                .iter()
                .map(|p| (x(p), p.angle_reactive.mean))
                .collect(),
        ),
        (
            "Pavlovian".into(),
            BLUE,
            s.aligned
                .iter()
                .map(|p| (x(p), p.angle_pavlovian.mean))
                .collect(),
        ),
    ];
    // 95 % confidence bands of each mean (±1.96 standard errors).
    let band = |color: RGBColor, d: fn(&AlignedPoint) -> &Describe| -> Band {
        (
            color,
            s.aligned
                .iter()
                .map(|p| {
                    let v = d(p);
                    (x(p), v.mean - 1.96 * v.se, v.mean + 1.96 * v.se)
                })
                .collect(),
        )
    };
    let cur_bands = [
        band(RED, |p| &p.current_reactive),
        band(BLUE, |p| &p.current_pavlovian),
    ];
    let ang_bands = [
        band(RED, |p| &p.angle_reactive),
        band(BLUE, |p| &p.angle_pavlovian),
    ];
    if let Some(a) = cols.first() {
        panel(
            a,
            "battery current, mA, aligned on the observed command (95 % CI)",
            span.clone(),
            &cur,
            &cur_bands,
            "time from the command onset, s",
        )?;
    }
    if let Some(a) = cols.get(1) {
        panel(
            a,
            "rotation from odometry, °/tick (95 % CI)",
            span,
            &ang,
            &ang_bands,
            "time from the command onset, s",
        )?;
    }
    root.present().map_err(err)
}

//! The interaction experiment's figures: analogues of the paper's Figure 3 (signals around a command, per
//! policy, at the study's stated moment: when anticipation first holds, or the end of the run), Figure 4
//! (battery current and rotation averaged over commands, aligned on the observed command onset), and the time
//! course (lead, anticipated fraction and false starts against minutes of learning, with 95 % intervals).

use std::path::Path;
use std::sync::Arc;

use pavlov::control::Mode;
use pavlov::record::TickRecord;
use plotters::prelude::*;

use crate::experiment::plot_style::{draw_legend, tick_label, with_legend_room};

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
    let top = with_legend_room(lo - pad, hi + pad, series.len(), area.dim_in_pixel().1);
    let mut ch = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 14))
        .margin(6)
        .x_label_area_size(40)
        .y_label_area_size(50)
        .build_cartesian_2d(x, (lo - pad)..top)
        .map_err(err)?;
    ch.configure_mesh()
        .x_desc(x_desc)
        .y_label_formatter(&tick_label)
        .x_label_formatter(&tick_label)
        .draw()
        .map_err(err)?;
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
    draw_legend(&mut ch).map_err(err)?;
    Ok(())
}

const RED: RGBColor = RGBColor(200, 80, 40);
const BLUE: RGBColor = RGBColor(40, 100, 200);
const GREY: RGBColor = RGBColor(90, 90, 90);
const BLACK_ISH: RGBColor = RGBColor(30, 30, 30);

/// Ten seconds of a run centred on its first observed command onset at or after `at_min` minutes (the last
/// one whose ten seconds fit, when none comes later).
fn excerpt(r: &InteractionRun, at_min: f64) -> &[Arc<TickRecord>] {
    let half = 250usize;
    let fits: Vec<usize> = interaction::observed_onsets(&r.records)
        .into_iter()
        .map(|i| i as usize)
        .filter(|&i| i >= half && i + half <= r.records.len())
        .collect();
    let at_ms = at_min * 60_000.0;
    let onset = fits
        .iter()
        .copied()
        .find(|&i| r.records.get(i).is_some_and(|x| x.t_ms >= at_ms))
        .or_else(|| fits.last().copied())
        .unwrap_or(half);
    let start = onset.saturating_sub(half);
    r.records
        .get(start..(start + 2 * half).min(r.records.len()))
        .unwrap_or(&[])
}

/// Figure 3: elbow angle, prediction, current and command around a command, one column per policy.
pub(crate) fn fig3(path: &Path, s: &InteractionStudy) -> std::io::Result<()> {
    let root = SVGBackend::new(path, (1000, 800)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let title = format!(
        "Fig. 3 analogue: timing of signals at {:.1} min ({}; 10 s around a command)",
        s.fig3_at_min,
        if s.holds_from_window.is_some() {
            "middle of the first window from which anticipation holds"
        } else {
            "end of run: anticipation never held"
        }
    );
    let root = root.titled(&title, ("sans-serif", 18)).map_err(err)?;
    let firsts: Vec<&InteractionRun> = [Mode::Reactive, Mode::Pavlovian]
        .iter()
        .filter_map(|m| s.runs.iter().find(|r| r.mode == *m))
        .collect();
    let cols = root.split_evenly((1, firsts.len().max(1)));
    for (r, col) in firsts.iter().zip(cols.iter()) {
        let recs = excerpt(r, s.fig3_at_min);
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

/// The time course: current and motion lead, anticipated fraction, false starts per minute, against
/// minutes of learning, with 95 % intervals.
pub(crate) fn fig_curve(path: &Path, s: &InteractionStudy) -> std::io::Result<()> {
    use pavlov::analysis::bootstrap::MeanDifference;
    let root = SVGBackend::new(path, (900, 900)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let title = format!(
        "Time course: {} run(s) per policy × {} min, {}-min windows",
        s.options.runs_per_policy, s.options.minutes, s.options.window_min
    );
    let root = root.titled(&title, ("sans-serif", 18)).map_err(err)?;
    let rows = root.split_evenly((3, 1));
    let mid = |p: &pavlov::analysis::interaction::curve::CurvePoint| (p.from_min + p.to_min) / 2.0;
    let span = 0.0..s.curve.last().map_or(1.0, |p| p.to_min);
    let diff_series =
        |label: &str,
         color: RGBColor,
         pick: fn(&pavlov::analysis::interaction::curve::CurvePoint) -> Option<MeanDifference>,
         scale: f64|
         -> (Series, Band) {
            let pts: Vec<(f64, MeanDifference)> = s
                .curve
                .iter()
                .filter_map(|p| pick(p).map(|d| (mid(p), d)))
                .collect();
            (
                (
                    label.to_string(),
                    color,
                    pts.iter()
                        .map(|(x, d)| (*x, d.difference * scale))
                        .collect(),
                ),
                (
                    color,
                    pts.iter()
                        .map(|(x, d)| (*x, d.lo * scale, d.hi * scale))
                        .collect(),
                ),
            )
        };
    let zero: Series = ("0".into(), GREY, vec![(span.start, 0.0), (span.end, 0.0)]);
    let (dec, dec_band) = diff_series("decision (gate)", BLACK_ISH, |p| p.decision_lead, 1.0);
    let (cur, cur_band) = diff_series("battery current", BLUE, |p| p.current_lead, 1.0);
    let (mot, mot_band) = diff_series("motion", RED, |p| p.motion_lead, 1.0);
    if let Some(a) = rows.first() {
        panel(
            a,
            "anticipation lead, ms: reactive − Pavlovian onset (95 % bootstrap CI)",
            span.clone(),
            &[dec, cur, mot, zero.clone()],
            &[dec_band, cur_band, mot_band],
            "minutes of learning",
        )?;
    }
    let (excess, excess_band) = diff_series(
        "Pavlovian − reactive",
        BLUE,
        |p| p.anticipated_difference,
        100.0,
    );
    let reactive: Series = (
        "reactive (noise baseline)".into(),
        RED,
        s.curve
            .iter()
            .map(|p| (mid(p), p.anticipated_reactive * 100.0))
            .collect(),
    );
    if let Some(a) = rows.get(1) {
        panel(
            a,
            "commands anticipated by the decision, % (excess over the reactive baseline, 95 % CI)",
            span.clone(),
            &[excess, reactive, zero],
            &[excess_band],
            "minutes of learning",
        )?;
    }
    let rate = |label: &str,
                color: RGBColor,
                pick: fn(
        &pavlov::analysis::interaction::curve::CurvePoint,
    ) -> pavlov::analysis::interaction::curve::Rate|
     -> (Series, Band) {
        (
            (
                label.to_string(),
                color,
                s.curve
                    .iter()
                    .map(|p| (mid(p), pick(p).per_minute))
                    .collect(),
            ),
            (
                color,
                s.curve
                    .iter()
                    .map(|p| (mid(p), pick(p).lo, pick(p).hi))
                    .collect(),
            ),
        )
    };
    let (fp, fp_band) = rate("Pavlovian", BLUE, |p| p.false_starts_pavlovian);
    let (fr, fr_band) = rate("reactive", RED, |p| p.false_starts_reactive);
    if let Some(a) = rows.get(2) {
        panel(
            a,
            "false starts per minute (95 % CI)",
            span,
            &[fp, fr],
            &[fp_band, fr_band],
            "minutes of learning",
        )?;
    }
    root.present().map_err(err)
}

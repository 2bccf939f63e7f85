//! The interaction experiment's figures (SVG and 300-dpi PNG, in the style of `plot_style`): analogues of
//! the paper's Figure 3 (signals around a command, per policy, at the study's stated moment: when
//! anticipation first holds, or the end of the run), Figure 4 (battery current and rotation averaged over
//! commands, aligned on the observed command onset), and the time course (lead, anticipated fraction and
//! false starts against minutes of learning, with 95 % intervals).

use std::path::Path;

use pavlov::analysis::bootstrap::MeanDifference;
use pavlov::analysis::interaction::curve::{CurvePoint, Rate};
use pavlov::analysis::stats::Describe;
use pavlov::control::Mode;
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::experiment::plot_style::{
    self as ps, DARK, Dash, Entry, Figure, Io, ONE_COLUMN_IN, PAVLOVIAN, REACTIVE, REFERENCE,
    Style, TWO_COLUMNS_IN, UNIT,
};

use super::InteractionStudy;
use super::analysis::AlignedPoint;
use super::reduce::{Fig3Tick, observed_onsets};
use super::run::{self as interaction, InteractionRun};

/// A policy's band (x, low, high) in its colour, with its dash for the mean line.
type PolicyBand = (RGBColor, Dash, Vec<(f64, f64, f64)>);

/// A series: legend label, colour, dash, points.
type Series = (String, RGBColor, Dash, Vec<(f64, f64)>);

/// A green for the third lead (motion), apart from the policies' red and blue.
const GREEN: RGBColor = RGBColor(0, 135, 80);

fn policy_style(mode: Mode) -> (RGBColor, Dash) {
    if mode == Mode::Pavlovian {
        (PAVLOVIAN, Dash::Solid)
    } else {
        (REACTIVE, Dash::Dashed)
    }
}

/// A panel of line series over `x`, with `references` (horizontal lines at these y values, no legend entry)
/// and the y range fitted to the data unless `y` is given.
#[allow(clippy::too_many_arguments)]
fn lines_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    st: &Style,
    title: &str,
    x: std::ops::Range<f64>,
    y: Option<std::ops::Range<f64>>,
    series: &[Series],
    references: &[f64],
    (x_desc, y_desc): (&str, &str),
) -> Io {
    let legend: Vec<Entry> = if series.len() > 1 {
        series
            .iter()
            .map(|(l, c, d, _)| (l.clone(), *c, *d))
            .collect()
    } else {
        Vec::new()
    };
    let body = ps::panel_header(area, st, title, &legend)?;
    let y = y.unwrap_or_else(|| {
        ps::padded_range(
            series
                .iter()
                .flat_map(|s| s.3.iter().map(|p| p.1))
                .chain(references.iter().copied()),
        )
    });
    let mut ch = ps::chart(&body, st, x.clone(), y)?;
    ps::mesh(&mut ch, st, x_desc, y_desc)?;
    for r in references {
        ps::line(
            &mut ch,
            st,
            &[(x.start, *r), (x.end, *r)],
            REFERENCE,
            Dash::Solid,
            0.75,
        )?;
    }
    for (_, c, d, pts) in series {
        ps::line(&mut ch, st, pts, *c, *d, 1.25)?;
    }
    Ok(())
}

/// Ten seconds of a run centred on its first observed command onset at or after `at_min` minutes (the last
/// one whose ten seconds fit, when none comes later).
fn excerpt(r: &InteractionRun, at_min: f64) -> &[Fig3Tick] {
    let half = 250usize;
    let fits: Vec<usize> = observed_onsets(&r.figure3, |x| (x.t_ms, x.stimulus))
        .into_iter()
        .map(|i| i as usize)
        .filter(|&i| i >= half && i + half <= r.figure3.len())
        .collect();
    let at_ms = at_min * 60_000.0;
    let onset = fits
        .iter()
        .copied()
        .find(|&i| r.figure3.get(i).is_some_and(|x| x.t_ms >= at_ms))
        .or_else(|| fits.last().copied())
        .unwrap_or(half);
    let start = onset.saturating_sub(half);
    r.figure3
        .get(start..(start + 2 * half).min(r.figure3.len()))
        .unwrap_or(&[])
}

struct Fig3<'a> {
    s: &'a InteractionStudy,
}

impl Figure for Fig3<'_> {
    fn size_in(&self) -> (f64, f64) {
        (TWO_COLUMNS_IN, 6.4)
    }

    fn caption(&self) -> String {
        format!(
            "One run per policy, 10 s around a command at {:.1} min ({}). Grey line: 90°.",
            self.s.fig3_at_min,
            if self.s.holds_from_window.is_some() {
                "the middle of the first window from which anticipation holds"
            } else {
                "the end of the run: anticipation never held"
            }
        )
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>, st: &Style) -> Io {
        let s = self.s;
        let firsts: Vec<&InteractionRun> = [Mode::Reactive, Mode::Pavlovian]
            .iter()
            .filter_map(|m| s.runs.iter().find(|r| r.mode == *m))
            .collect();
        let cols = root.split_evenly((1, firsts.len().max(1)));
        for (r, col) in firsts.iter().zip(cols.iter()) {
            let recs = excerpt(r, s.fig3_at_min);
            let t0 = recs.first().map_or(0.0, |x| x.t_ms);
            let t = |x: &Fig3Tick| (x.t_ms - t0) / 1000.0;
            let span = 0.0..10.0;
            let (c, _) = policy_style(r.mode);
            let rows = col.split_evenly((4, 1));
            let elbow: Vec<(f64, f64)> = recs
                .iter()
                .filter_map(|x| x.elbow_left.map(|a| (t(x), a)))
                .collect();
            let pred: Vec<(f64, f64)> = recs
                .iter()
                .filter_map(|x| x.prediction.map(|(v, _)| (t(x), v.clamp(0.0, 1.0))))
                .collect();
            let theta: Vec<(f64, f64)> = recs
                .iter()
                .filter_map(|x| x.prediction.map(|(_, th)| (t(x), th)))
                .collect();
            let stim: Vec<(f64, f64)> = recs
                .iter()
                .map(|x| (t(x), if x.stimulus { 1.0 } else { 0.0 }))
                .collect();
            let current: Vec<(f64, f64)> = recs
                .iter()
                .filter_map(|x| x.current_ma.map(|i| (t(x), f64::from(i))))
                .collect();
            let right_cmd: Vec<(f64, f64)> = recs
                .iter()
                .map(|x| (t(x), f64::from(x.right_mm_s)))
                .collect();
            let name = ps::policy_label(r.mode);
            if let Some(a) = rows.first() {
                lines_panel(
                    a,
                    st,
                    &format!("{name}: left elbow angle"),
                    span.clone(),
                    None,
                    &[("angle".into(), c, Dash::Solid, elbow)],
                    &[90.0],
                    ("", "angle (°)"),
                )?;
            }
            if let Some(a) = rows.get(1) {
                lines_panel(
                    a,
                    st,
                    "prediction, threshold, stimulus E",
                    span.clone(),
                    Some(UNIT),
                    &[
                        ("E".into(), REFERENCE, Dash::Dotted, stim),
                        ("threshold".into(), DARK, Dash::Dashed, theta),
                        ("prediction".into(), c, Dash::Solid, pred),
                    ],
                    &[],
                    ("", "prediction, E"),
                )?;
            }
            if let Some(a) = rows.get(2) {
                lines_panel(
                    a,
                    st,
                    "battery current",
                    span.clone(),
                    None,
                    &[("current".into(), c, Dash::Solid, current)],
                    &[],
                    ("", "current (mA)"),
                )?;
            }
            if let Some(a) = rows.get(3) {
                lines_panel(
                    a,
                    st,
                    "right wheel command (spin left)",
                    span.clone(),
                    None,
                    &[("command".into(), c, Dash::Solid, right_cmd)],
                    &[],
                    ("time (s)", "command (mm/s)"),
                )?;
            }
        }
        Ok(())
    }
}

/// Figure 3: elbow angle, prediction, current and command around a command, one column per policy, as
/// `fig3_timing.{svg,png}`.
pub(crate) fn fig3(dir: &Path, s: &InteractionStudy) -> Io {
    ps::save(dir, "fig3_timing", &Fig3 { s })
}

struct Fig4<'a> {
    s: &'a InteractionStudy,
}

impl Figure for Fig4<'_> {
    fn size_in(&self) -> (f64, f64) {
        (ONE_COLUMN_IN, 4.4)
    }

    fn caption(&self) -> String {
        let n = |d: fn(&AlignedPoint) -> &Describe| {
            self.s.aligned.iter().map(|p| d(p).n).max().unwrap_or(0)
        };
        format!(
            "Lines: mean over n = {} reactive and {} Pavlovian commands (the last {} of each run); \
             bands: 95 % CI of the mean (±1.96 SE).",
            n(|p| &p.current_reactive),
            n(|p| &p.current_pavlovian),
            self.s.options.aligned_commands
        )
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>, st: &Style) -> Io {
        let s = self.s;
        let rows = root.split_evenly((2, 1));
        let x = |p: &AlignedPoint| p.offset as f64 * 0.02;
        let span =
            (-interaction::BEFORE_TICKS as f64 * 0.02)..(interaction::AFTER_TICKS as f64 * 0.02);
        type Pick = fn(&AlignedPoint) -> &Describe;
        let panels: [(&str, &str, Pick, Pick); 2] = [
            (
                "Battery current, aligned on the command",
                "current (mA)",
                |p| &p.current_reactive,
                |p| &p.current_pavlovian,
            ),
            (
                "Rotation from odometry",
                "rotation (°/tick)",
                |p| &p.angle_reactive,
                |p| &p.angle_pavlovian,
            ),
        ];
        for (area, (title, y_desc, pr, pp)) in rows.iter().zip(panels) {
            let modes = [(Mode::Reactive, pr), (Mode::Pavlovian, pp)];
            let legend: Vec<Entry> = modes
                .iter()
                .map(|(m, _)| {
                    let (c, d) = policy_style(*m);
                    (ps::policy_label(*m).to_string(), c, d)
                })
                .collect();
            let body = ps::panel_header(area, st, title, &legend)?;
            let bands: Vec<PolicyBand> = modes
                .iter()
                .map(|(m, pick)| {
                    let (c, d) = policy_style(*m);
                    let pts = s
                        .aligned
                        .iter()
                        .map(|p| {
                            let v = pick(p);
                            (x(p), v.mean - 1.96 * v.se, v.mean + 1.96 * v.se)
                        })
                        .collect();
                    (c, d, pts)
                })
                .collect();
            let y = ps::padded_range(
                bands
                    .iter()
                    .flat_map(|b| b.2.iter().flat_map(|p| [p.1, p.2])),
            );
            let mut ch = ps::chart(&body, st, span.clone(), y)?;
            ps::mesh(&mut ch, st, "time from the command onset (s)", y_desc)?;
            for (c, _, pts) in &bands {
                ps::band(&mut ch, st, pts, *c, true)?;
            }
            for (c, d, pts) in &bands {
                ps::band(&mut ch, st, pts, *c, false)?;
                let mean: Vec<(f64, f64)> = pts.iter().map(|p| (p.0, (p.1 + p.2) / 2.0)).collect();
                ps::line(&mut ch, st, &mean, *c, *d, 1.25)?;
            }
        }
        Ok(())
    }
}

/// Figure 4: current and rotation aligned on the observed command onset, both policies, as
/// `fig4_aligned.{svg,png}`.
pub(crate) fn fig4(dir: &Path, s: &InteractionStudy) -> Io {
    ps::save(dir, "fig4_aligned", &Fig4 { s })
}

/// A series with 95 % intervals at the windows' middles: label, colour, dash, (x, value, lo, hi).
type WithBars = (String, RGBColor, Dash, Vec<(f64, f64, f64, f64)>);

/// A panel of series with error bars, each series a little apart from the next so no bar hides another,
/// drawn in order (the last on top), and a zero line without a legend entry.
fn bars_panel<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    st: &Style,
    title: &str,
    x: std::ops::Range<f64>,
    series: &[WithBars],
    (x_desc, y_desc): (&str, &str),
) -> Io {
    let legend: Vec<Entry> = series
        .iter()
        .map(|(l, c, d, _)| (l.clone(), *c, *d))
        .collect();
    let body = ps::panel_header(area, st, title, &legend)?;
    let y = ps::padded_range(
        series
            .iter()
            .flat_map(|s| s.3.iter().flat_map(|p| [p.1, p.2, p.3]))
            .chain([0.0]),
    );
    let mut ch = ps::chart(&body, st, x.clone(), y)?;
    ps::mesh(&mut ch, st, x_desc, y_desc)?;
    ps::line(
        &mut ch,
        st,
        &[(x.start, 0.0), (x.end, 0.0)],
        REFERENCE,
        Dash::Solid,
        0.75,
    )?;
    let width = x.end - x.start;
    let k = series.len() as f64;
    for (i, (_, c, d, pts)) in series.iter().enumerate() {
        let shift = (i as f64 - (k - 1.0) / 2.0) * width * 0.008;
        for (x, _, lo, hi) in pts {
            ps::error_bar(&mut ch, st, x + shift, (*lo, *hi), width * 0.006, *c)?;
        }
        let line: Vec<(f64, f64)> = pts.iter().map(|p| (p.0 + shift, p.1)).collect();
        ps::line(&mut ch, st, &line, *c, *d, 1.25)?;
        ch.draw_series(
            line.iter()
                .filter(|p| p.1.is_finite())
                .map(|p| Circle::new(*p, st.px(1.4), c.filled())),
        )
        .map_err(ps::err)?;
    }
    Ok(())
}

struct FigCurve<'a> {
    s: &'a InteractionStudy,
}

impl Figure for FigCurve<'_> {
    fn size_in(&self) -> (f64, f64) {
        (ONE_COLUMN_IN, 6.6)
    }

    fn caption(&self) -> String {
        let o = &self.s.options;
        format!(
            "{} run(s) per policy × {} min, {}-min windows. Error bars: 95 % two-stage \
             bootstrap intervals (runs, then commands); false starts: normal \
             approximation to the Poisson count.",
            o.runs_per_policy, o.minutes, o.window_min
        )
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>, st: &Style) -> Io {
        let s = self.s;
        let rows = root.split_evenly((3, 1));
        let mid = |p: &CurvePoint| (p.from_min + p.to_min) / 2.0;
        let span = 0.0..s.curve.last().map_or(1.0, |p| p.to_min);
        let diff = |label: &str,
                    color: RGBColor,
                    dash: Dash,
                    pick: fn(&CurvePoint) -> Option<MeanDifference>,
                    scale: f64|
         -> WithBars {
            (
                label.to_string(),
                color,
                dash,
                s.curve
                    .iter()
                    .filter_map(|p| pick(p).map(|d| (mid(p), d)))
                    .map(|(x, d)| (x, d.difference * scale, d.lo * scale, d.hi * scale))
                    .collect(),
            )
        };
        let x_desc = "minutes of learning";
        if let Some(a) = rows.first() {
            bars_panel(
                a,
                st,
                "Anticipation lead (reactive − Pavlovian onset)",
                span.clone(),
                &[
                    diff("motion", GREEN, Dash::Dotted, |p| p.motion_lead, 1.0),
                    diff(
                        "battery current",
                        PAVLOVIAN,
                        Dash::Dashed,
                        |p| p.current_lead,
                        1.0,
                    ),
                    diff(
                        "decision (gate)",
                        DARK,
                        Dash::Solid,
                        |p| p.decision_lead,
                        1.0,
                    ),
                ],
                ("", "lead (ms)"),
            )?;
        }
        if let Some(a) = rows.get(1) {
            let reactive: WithBars = (
                "reactive (noise baseline)".into(),
                REACTIVE,
                Dash::Dashed,
                s.curve
                    .iter()
                    .map(|p| {
                        let v = p.anticipated_reactive * 100.0;
                        (mid(p), v, v, v)
                    })
                    .collect(),
            );
            bars_panel(
                a,
                st,
                "Commands anticipated by the decision",
                span.clone(),
                &[
                    reactive,
                    diff(
                        "Pavlovian − reactive",
                        PAVLOVIAN,
                        Dash::Solid,
                        |p| p.anticipated_difference,
                        100.0,
                    ),
                ],
                ("", "anticipated (%)"),
            )?;
        }
        let rate = |label: &str, mode: Mode, pick: fn(&CurvePoint) -> Rate| -> WithBars {
            let (c, d) = policy_style(mode);
            (
                label.to_string(),
                c,
                d,
                s.curve
                    .iter()
                    .map(|p| {
                        let r = pick(p);
                        (mid(p), r.per_minute, r.lo, r.hi)
                    })
                    .collect(),
            )
        };
        if let Some(a) = rows.get(2) {
            bars_panel(
                a,
                st,
                "False starts",
                span,
                &[
                    rate("reactive", Mode::Reactive, |p| p.false_starts_reactive),
                    rate("Pavlovian", Mode::Pavlovian, |p| p.false_starts_pavlovian),
                ],
                (x_desc, "false starts per min"),
            )?;
        }
        Ok(())
    }
}

/// The time course: current and motion lead, anticipated fraction, false starts per minute, against
/// minutes of learning, with 95 % intervals, as `fig_curve.{svg,png}`.
pub(crate) fn fig_curve(dir: &Path, s: &InteractionStudy) -> Io {
    ps::save(dir, "fig_curve", &FigCurve { s })
}

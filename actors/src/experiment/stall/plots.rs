//! Figures drawn with plotters (SVG and 300-dpi PNG, in the style of `plot_style`), analogues of the paper's
//! Figures 1 and 2 plus the learning curve.
//!
//! - Figure 1: a 10 s excerpt after 2.5 min of learning that ends with the robot pushing against a wall,
//!   for each policy: the prediction and its threshold, the over-current flag, the wheel command.
//! - Figure 2: over-current observations and efficiency per policy, mean with standard-error bars.
//! - Learning curve: over-current observations per window, mean ± SE over runs, per policy.

use std::path::Path;

use pavlov::control::Mode;
use pavlov::record::TickRecord;
use plotters::coord::Shift;
use plotters::prelude::*;

use crate::experiment::plot_style::{
    self as ps, DARK, Dash, Figure, Io, ONE_COLUMN_IN, PAVLOVIAN, REACTIVE, Style, TWO_COLUMNS_IN,
    UNIT, err,
};

use super::WINDOW_S;
use super::analysis::Analysis;

fn color(mode: Mode) -> RGBColor {
    if mode == Mode::Pavlovian {
        PAVLOVIAN
    } else {
        REACTIVE
    }
}

/// The policy's dash: the reactive policy dashed, the Pavlovian one solid.
fn dash(mode: Mode) -> Dash {
    if mode == Mode::Pavlovian {
        Dash::Solid
    } else {
        Dash::Dashed
    }
}

/// The `len`-tick window of `records` that ends where a drive phase of the default policy (both wheels
/// the same non-zero speed) with an over-current observation ends, i.e. with the robot pushing against a
/// wall: the first such phase that ends at least `len` ticks into `records`. The first `len` records if
/// there is none.
pub(crate) fn push_window(records: &[TickRecord], len: usize) -> &[TickRecord] {
    let driving = |r: &TickRecord| {
        let a = r.default_action;
        a.left_mm_s == a.right_mm_s && a.left_mm_s != 0
    };
    let mut i = 0;
    while let Some(r) = records.get(i) {
        let phase = r.default_action;
        let end = records
            .iter()
            .skip(i)
            .position(|x| x.default_action != phase)
            .map_or(records.len(), |k| i + k);
        let pushed = records.get(i..end).is_some_and(|p| {
            p.iter()
                .any(|x| x.sensors.overcurrent_left || x.sensors.overcurrent_right)
        });
        if driving(r) && pushed && end >= len && end < records.len() {
            return records.get(end - len..end).unwrap_or(&[]);
        }
        i = end.max(i + 1);
    }
    records.get(..len.min(records.len())).unwrap_or(&[])
}

struct Fig1<'a> {
    excerpts: &'a [(Mode, &'a [TickRecord])],
}

impl Figure for Fig1<'_> {
    fn size_in(&self) -> (f64, f64) {
        (TWO_COLUMNS_IN, 5.0)
    }

    fn caption(&self) -> String {
        "One run per policy: the 10 s that end where a drive of the default policy pushes against a wall, \
         after 2.5 min of learning. Threshold: the gate's threshold on the prediction."
            .into()
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>, st: &Style) -> Io {
        let cols = root.split_evenly((1, self.excerpts.len().max(1)));
        for ((mode, recs), col) in self.excerpts.iter().zip(cols.iter()) {
            let rows = col.split_evenly((3, 1));
            let t0 = recs.first().map_or(0.0, |r| r.t_ms / 1000.0);
            let t1 = recs.last().map_or(10.0, |r| r.t_ms / 1000.0).max(t0 + 0.02);
            let t = |r: &TickRecord| r.t_ms / 1000.0 - t0;
            let span = 0.0..(t1 - t0);
            let c = color(*mode);
            let name = ps::policy_label(*mode);
            if let Some(area) = rows.first() {
                let body = ps::panel_header(
                    area,
                    st,
                    &format!("{name}: prediction and threshold"),
                    &[
                        ("prediction".into(), c, Dash::Solid),
                        ("threshold".into(), DARK, Dash::Dashed),
                    ],
                )?;
                let mut ch = ps::chart(&body, st, span.clone(), UNIT)?;
                ps::mesh(&mut ch, st, "", "prediction")?;
                let pred: Vec<(f64, f64)> = recs
                    .iter()
                    .filter_map(|r| {
                        r.predictions
                            .first()
                            .map(|p| (t(r), p.value.clamp(0.0, 1.0)))
                    })
                    .collect();
                let theta: Vec<(f64, f64)> = recs
                    .iter()
                    .filter_map(|r| r.predictions.first().map(|p| (t(r), p.threshold)))
                    .collect();
                ps::line(&mut ch, st, &theta, DARK, Dash::Dashed, 1.0)?;
                ps::line(&mut ch, st, &pred, c, Dash::Solid, 1.25)?;
            }
            if let Some(area) = rows.get(1) {
                let body = ps::panel_header(area, st, "over-current flag (either wheel)", &[])?;
                let mut ch = ps::chart(&body, st, span.clone(), UNIT)?;
                ps::mesh(&mut ch, st, "", "over-current (0/1)")?;
                let oc: Vec<(f64, f64)> = recs
                    .iter()
                    .map(|r| {
                        let oc = r.sensors.overcurrent_left || r.sensors.overcurrent_right;
                        (t(r), if oc { 1.0 } else { 0.0 })
                    })
                    .collect();
                ps::line(&mut ch, st, &oc, c, Dash::Solid, 1.0)?;
            }
            if let Some(area) = rows.get(2) {
                let body = ps::panel_header(
                    area,
                    st,
                    "wheel commands",
                    &[
                        ("left".into(), c, Dash::Solid),
                        ("right".into(), DARK, Dash::Dotted),
                    ],
                )?;
                let mut ch = ps::chart(&body, st, span.clone(), -330.0..330.0)?;
                ps::mesh(&mut ch, st, "time (s)", "command (mm/s)")?;
                let left: Vec<(f64, f64)> = recs
                    .iter()
                    .map(|r| (t(r), f64::from(r.command.left_mm_s)))
                    .collect();
                let right: Vec<(f64, f64)> = recs
                    .iter()
                    .map(|r| (t(r), f64::from(r.command.right_mm_s)))
                    .collect();
                ps::line(&mut ch, st, &left, c, Dash::Solid, 1.25)?;
                ps::line(&mut ch, st, &right, DARK, Dash::Dotted, 1.25)?;
            }
        }
        Ok(())
    }
}

/// Figure 1: signals of a push against a wall, one column per policy, as `fig1_push.{svg,png}` in `dir`.
pub(crate) fn fig1_push(dir: &Path, excerpts: &[(Mode, &[TickRecord])]) -> Io {
    ps::save(dir, "fig1_push", &Fig1 { excerpts })
}

/// "n = 10 runs per policy", or both counts when they differ.
fn runs_phrase(reactive: usize, pavlovian: usize) -> String {
    if reactive == pavlovian {
        format!("n = {reactive} runs per policy")
    } else {
        format!("n = {reactive} reactive and {pavlovian} Pavlovian runs")
    }
}

fn bar_panel<DB: DrawingBackend>(
    body: &DrawingArea<DB, Shift>,
    st: &Style,
    y_desc: &str,
    bars: [(f64, f64); 2],
) -> Io {
    let top = bars
        .iter()
        .map(|(m, se)| m + se)
        .filter(|v| v.is_finite())
        .fold(0.0f64, f64::max)
        .max(1e-9)
        * 1.1;
    let mut ch = ChartBuilder::on(body)
        .margin_top(st.px(ps::Y_TITLE_ROOM_PT))
        .margin_left(st.px(3.0))
        .margin_right(st.px(6.0))
        .x_label_area_size(st.px(4.0))
        .y_label_area_size(st.px(8.0 * 4.4))
        .build_cartesian_2d(-0.5f64..1.5f64, 0f64..top)
        .map_err(err)?;
    ch.configure_mesh()
        .disable_x_mesh()
        .max_light_lines(0)
        .bold_line_style(st.line(ps::GRID, 0.5))
        .axis_style(st.line(BLACK, 0.75))
        .set_all_tick_mark_size(st.px(2.5))
        .label_style(st.text(8.0))
        .axis_desc_style(st.text(8.0))
        .y_labels(5)
        .y_label_formatter(&ps::tick_label)
        .x_labels(0)
        .draw()
        .map_err(err)?;
    ps::y_title(&ch, st, y_desc)?;
    for (i, ((mean, se), c)) in bars.iter().zip([REACTIVE, PAVLOVIAN]).enumerate() {
        let x = i as f64;
        if !mean.is_finite() {
            continue;
        }
        ch.draw_series([
            Rectangle::new(
                [(x - 0.3, 0.0), (x + 0.3, *mean)],
                ps::tint(c, 0.45).filled(),
            ),
            Rectangle::new([(x - 0.3, 0.0), (x + 0.3, *mean)], st.line(c, 0.75)),
        ])
        .map_err(err)?;
        ps::error_bar(&mut ch, st, x, (mean - se, mean + se), 0.08, BLACK)?;
    }
    Ok(())
}

struct Fig2<'a> {
    a: &'a Analysis,
}

impl Figure for Fig2<'_> {
    fn size_in(&self) -> (f64, f64) {
        (ONE_COLUMN_IN, 2.4)
    }

    fn caption(&self) -> String {
        let n = self
            .a
            .comparisons
            .first()
            .map_or((0, 0), |c| (c.reactive.n, c.pavlovian.n));
        format!(
            "Bars: mean over {}; error bars: ±1 standard error.",
            runs_phrase(n.0, n.1)
        )
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>, st: &Style) -> Io {
        let legend: Vec<ps::Entry> = [Mode::Reactive, Mode::Pavlovian]
            .into_iter()
            .map(|m| (ps::policy_label(m).to_string(), color(m), Dash::Solid))
            .collect();
        let root = ps::panel_header(root, st, "", &legend)?;
        let panels = root.split_evenly((1, 2));
        let find = |key: &str| self.a.comparisons.iter().find(|c| c.metric == key);
        for ((area, key), (short, quantity)) in panels
            .iter()
            .zip(["overcurrent_observations", "efficiency_m_per_kj"])
            .zip([
                ("Over-current", "observations"),
                ("Efficiency", "efficiency"),
            ])
        {
            if let Some(c) = find(key) {
                let change = c.relative_change.map_or(String::new(), |r| {
                    ps::signed(&format!(" ({:+.0} %)", r * 100.0))
                });
                let body = ps::panel_header(area, st, &format!("{short}{change}"), &[])?;
                bar_panel(
                    &body,
                    st,
                    &format!("{quantity} ({})", c.unit),
                    [
                        (c.reactive.mean, c.reactive.se),
                        (c.pavlovian.mean, c.pavlovian.se),
                    ],
                )?;
            }
        }
        Ok(())
    }
}

/// Figure 2: over-current observations and efficiency, mean ± SE per policy, as `fig2_bars.{svg,png}`.
pub(crate) fn fig2_bars(dir: &Path, a: &Analysis) -> Io {
    ps::save(dir, "fig2_bars", &Fig2 { a })
}

struct LearningCurve<'a> {
    a: &'a Analysis,
}

impl Figure for LearningCurve<'_> {
    fn size_in(&self) -> (f64, f64) {
        (ONE_COLUMN_IN, 2.5)
    }

    fn caption(&self) -> String {
        let n = self
            .a
            .learning_curve
            .first()
            .map_or((0, 0), |p| (p.reactive.n, p.pavlovian.n));
        format!(
            "Lines: mean over {} per {WINDOW_S} s window; error bars: ±1 standard error.",
            runs_phrase(n.0, n.1)
        )
    }

    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>, st: &Style) -> Io {
        let a = self.a;
        let n = a.learning_curve.len().max(1) as f64;
        let top = a
            .learning_curve
            .iter()
            .flat_map(|p| {
                [
                    p.reactive.mean + p.reactive.se,
                    p.pavlovian.mean + p.pavlovian.se,
                ]
            })
            .filter(|v| v.is_finite())
            .fold(1.0f64, f64::max)
            * 1.08;
        let legend: Vec<ps::Entry> = [Mode::Reactive, Mode::Pavlovian]
            .into_iter()
            .map(|m| (ps::policy_label(m).to_string(), color(m), dash(m)))
            .collect();
        let body = ps::panel_header(
            root,
            st,
            "Over-current observations while learning",
            &legend,
        )?;
        let x_max = n * WINDOW_S / 60.0;
        let mut ch = ps::chart(&body, st, 0f64..x_max, 0f64..top)?;
        ps::mesh(
            &mut ch,
            st,
            "time (min, window centres)",
            &format!("observations per {WINDOW_S} s"),
        )?;
        // The two policies' error bars sit a little apart so that neither hides the other.
        let dodge = x_max * 0.006;
        for (mode, shift) in [(Mode::Reactive, -dodge), (Mode::Pavlovian, dodge)] {
            let c = color(mode);
            let pts: Vec<(f64, f64, f64)> = a
                .learning_curve
                .iter()
                .map(|p| {
                    let d = if mode == Mode::Pavlovian {
                        p.pavlovian
                    } else {
                        p.reactive
                    };
                    ((p.start_s + WINDOW_S / 2.0) / 60.0 + shift, d.mean, d.se)
                })
                .filter(|(_, m, _)| m.is_finite())
                .collect();
            for (x, m, se) in &pts {
                ps::error_bar(&mut ch, st, *x, (m - se, m + se), x_max * 0.008, c)?;
            }
            let line: Vec<(f64, f64)> = pts.iter().map(|(x, m, _)| (*x, *m)).collect();
            ps::line(&mut ch, st, &line, c, dash(mode), 1.25)?;
        }
        Ok(())
    }
}

/// The learning curve: over-current observations per window, mean ± SE per policy, as
/// `fig_learning_curve.{svg,png}`.
pub(crate) fn learning_curve(dir: &Path, a: &Analysis) -> Io {
    ps::save(dir, "fig_learning_curve", &LearningCurve { a })
}

#[cfg(test)]
mod tests {
    use super::*;
    use pavlov::control::Action;
    use pavlov::record::{LinkStatus, SensorReadings};

    fn rec(seq: u64, default_action: Action, oc: bool) -> TickRecord {
        TickRecord {
            seq,
            t_ms: seq as f64 * 20.0,
            mode: Mode::Reactive,
            obs_age_ticks: Some(0),
            sensors: SensorReadings {
                overcurrent_left: oc,
                ..SensorReadings::default()
            },
            obs: Vec::new(),
            elbow: None,
            stimulus: false,
            predictions: Vec::new(),
            gate: false,
            rule: None,
            default_action,
            command: default_action,
            safety_stop: None,
            estop: false,
            lateness_us: 0,
            link: LinkStatus::default(),
            ..TickRecord::at_rest(seq, seq as f64 * 20.0, Mode::Reactive)
        }
    }

    #[test]
    fn the_push_window_ends_with_the_drive_phase_that_hit_a_wall() {
        let turn = Action::new(100, -100);
        let drive = Action::new(200, 200);
        // turn 0..10 (over-current while turning: ignored), drive 10..30 (clean), turn 30..40,
        // drive 40..60 with over-current at 55, turn 60..70.
        let records: Vec<TickRecord> = (0..70u64)
            .map(|i| {
                let a = match i {
                    0..10 | 30..40 | 60..70 => turn,
                    _ => drive,
                };
                rec(i, a, i == 3 || i == 55)
            })
            .collect();
        let w = push_window(&records, 15);
        assert_eq!(w.first().map(|r| r.seq), Some(45));
        assert_eq!(w.last().map(|r| r.seq), Some(59));
        // No over-current while driving: the first records.
        let quiet: Vec<TickRecord> = (0..20u64).map(|i| rec(i, drive, false)).collect();
        assert_eq!(push_window(&quiet, 5).len(), 5);
        assert!(push_window(&[], 5).is_empty());
    }
}

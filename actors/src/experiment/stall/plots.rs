//! SVG figures drawn with plotters, analogues of the paper's Figures 1 and 2 plus the learning curve.
//!
//! - Figure 1: a 10 s excerpt after 2.5 min of learning that ends with the robot pushing against a wall,
//!   for each policy: the prediction and its threshold, the over-current flag, the wheel command.
//! - Figure 2: over-current observations and efficiency per policy, mean with standard-error bars.
//! - Learning curve: over-current observations per window, mean ± SE over runs, per policy.

use std::path::Path;

use pavlov::control::Mode;
use pavlov::record::TickRecord;
use plotters::prelude::*;

use crate::experiment::plot_style::{draw_legend, tick_label, with_legend_room};

use super::WINDOW_S;
use super::analysis::Analysis;
use crate::experiment::mode_name;

type Io = std::io::Result<()>;

fn err<E: std::fmt::Display>(e: E) -> std::io::Error {
    std::io::Error::other(e.to_string())
}

const REACTIVE: RGBColor = RGBColor(200, 80, 40);
const PAVLOVIAN: RGBColor = RGBColor(40, 100, 200);

fn color(mode: Mode) -> RGBColor {
    if mode == Mode::Pavlovian {
        PAVLOVIAN
    } else {
        REACTIVE
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

/// Figure 1: signals of a push against a wall, one column per policy.
pub(crate) fn fig1_push(path: &Path, excerpts: &[(Mode, &[TickRecord])]) -> Io {
    let root = SVGBackend::new(path, (1000, 700)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let root = root
        .titled(
            "Fig. 1 analogue: 10 s ending in a push against a wall, after 2.5 min of learning",
            ("sans-serif", 18),
        )
        .map_err(err)?;
    let cols = root.split_evenly((1, excerpts.len().max(1)));
    for ((mode, recs), col) in excerpts.iter().zip(cols.iter()) {
        let rows = col.split_evenly((3, 1));
        let t0 = recs.first().map_or(0.0, |r| r.t_ms / 1000.0);
        let t1 = recs.last().map_or(10.0, |r| r.t_ms / 1000.0).max(t0 + 0.02);
        let t = |r: &TickRecord| r.t_ms / 1000.0 - t0;
        let span = 0.0..(t1 - t0);
        let c = color(*mode);
        let values = recs
            .iter()
            .filter_map(|r| r.predictions.first().map(|p| p.value))
            .filter(|v| v.is_finite());
        let (v_lo, v_hi) = values.fold((-0.1f64, 1.1f64), |(lo, hi), v| (lo.min(v), hi.max(v)));
        let (v_lo, v_hi) = (v_lo - 0.05, v_hi + 0.05);
        if let Some(area) = rows.first() {
            let v_hi = with_legend_room(v_lo, v_hi, 2, area.dim_in_pixel().1);
            let mut ch = ChartBuilder::on(area)
                .caption(
                    format!("{}: prediction and threshold", mode_name(*mode)),
                    ("sans-serif", 14),
                )
                .margin(6)
                .x_label_area_size(24)
                .y_label_area_size(40)
                .build_cartesian_2d(span.clone(), v_lo..v_hi)
                .map_err(err)?;
            ch.configure_mesh()
                .y_label_formatter(&tick_label)
                .x_label_formatter(&tick_label)
                .draw()
                .map_err(err)?;
            ch.draw_series(LineSeries::new(
                recs.iter()
                    .map(|r| (t(r), r.predictions.first().map_or(0.0, |p| p.value))),
                c.stroke_width(2),
            ))
            .map_err(err)?
            .label("prediction")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], c));
            ch.draw_series(LineSeries::new(
                recs.iter()
                    .map(|r| (t(r), r.predictions.first().map_or(0.0, |p| p.threshold))),
                BLACK.stroke_width(1),
            ))
            .map_err(err)?
            .label("threshold")
            .legend(|(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], BLACK));
            draw_legend(&mut ch).map_err(err)?;
        }
        if let Some(area) = rows.get(1) {
            let mut ch = ChartBuilder::on(area)
                .caption("over-current flag (either wheel)", ("sans-serif", 14))
                .margin(6)
                .x_label_area_size(24)
                .y_label_area_size(40)
                .build_cartesian_2d(span.clone(), -0.1f64..1.1f64)
                .map_err(err)?;
            ch.configure_mesh()
                .y_label_formatter(&tick_label)
                .x_label_formatter(&tick_label)
                .draw()
                .map_err(err)?;
            ch.draw_series(LineSeries::new(
                recs.iter().map(|r| {
                    let oc = r.sensors.overcurrent_left || r.sensors.overcurrent_right;
                    (t(r), if oc { 1.0 } else { 0.0 })
                }),
                c.stroke_width(1),
            ))
            .map_err(err)?;
        }
        if let Some(area) = rows.get(2) {
            let w_top = with_legend_room(-300.0, 300.0, 2, area.dim_in_pixel().1);
            let mut ch = ChartBuilder::on(area)
                .caption("wheel commands, mm/s", ("sans-serif", 14))
                .margin(6)
                .x_label_area_size(30)
                .y_label_area_size(40)
                .build_cartesian_2d(span.clone(), -300f64..w_top)
                .map_err(err)?;
            ch.configure_mesh()
                .x_desc("time, s")
                .y_label_formatter(&tick_label)
                .x_label_formatter(&tick_label)
                .draw()
                .map_err(err)?;
            ch.draw_series(LineSeries::new(
                recs.iter().map(|r| (t(r), f64::from(r.command.left_mm_s))),
                c.stroke_width(2),
            ))
            .map_err(err)?
            .label("left")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], c));
            let grey = RGBColor(90, 90, 90);
            ch.draw_series(LineSeries::new(
                recs.iter().map(|r| (t(r), f64::from(r.command.right_mm_s))),
                grey.stroke_width(1),
            ))
            .map_err(err)?
            .label("right")
            .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], grey));
            draw_legend(&mut ch).map_err(err)?;
        }
    }
    root.present().map_err(err)
}

fn bar_panel(
    area: &DrawingArea<SVGBackend, plotters::coord::Shift>,
    title: &str,
    bars: [(f64, f64); 2],
) -> Io {
    let top = bars
        .iter()
        .map(|(m, se)| m + se)
        .fold(0.0f64, f64::max)
        .max(1e-9)
        * 1.2;
    let mut ch = ChartBuilder::on(area)
        .caption(title, ("sans-serif", 16))
        .margin(10)
        .x_label_area_size(30)
        .y_label_area_size(60)
        .build_cartesian_2d(-0.5f64..1.5f64, 0f64..top)
        .map_err(err)?;
    ch.configure_mesh()
        .y_label_formatter(&tick_label)
        .disable_x_mesh()
        .x_labels(3)
        .x_label_formatter(&|x| match x.round() as i64 {
            0 => "reactive".into(),
            1 => "Pavlovian".into(),
            _ => String::new(),
        })
        .draw()
        .map_err(err)?;
    for (i, ((mean, se), c)) in bars.iter().zip([REACTIVE, PAVLOVIAN]).enumerate() {
        let x = i as f64;
        ch.draw_series(std::iter::once(Rectangle::new(
            [(x - 0.3, 0.0), (x + 0.3, *mean)],
            c.mix(0.8).filled(),
        )))
        .map_err(err)?;
        let (lo, hi) = (mean - se, mean + se);
        ch.draw_series([
            PathElement::new(vec![(x, lo), (x, hi)], BLACK.stroke_width(2)),
            PathElement::new(vec![(x - 0.08, lo), (x + 0.08, lo)], BLACK.stroke_width(2)),
            PathElement::new(vec![(x - 0.08, hi), (x + 0.08, hi)], BLACK.stroke_width(2)),
        ])
        .map_err(err)?;
    }
    Ok(())
}

/// Figure 2: over-current observations and efficiency, mean ± SE per policy.
pub(crate) fn fig2_bars(path: &Path, a: &Analysis) -> Io {
    let root = SVGBackend::new(path, (900, 420)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
    let panels = root.split_evenly((1, 2));
    let find = |key: &str| a.comparisons.iter().find(|c| c.metric == key);
    for (area, key) in panels
        .iter()
        .zip(["overcurrent_observations", "efficiency_m_per_kj"])
    {
        if let Some(c) = find(key) {
            let change = c
                .relative_change
                .map_or(String::new(), |r| format!(" ({:+.0}%)", r * 100.0));
            bar_panel(
                area,
                &format!("{} per run, {}{change}", c.label, c.unit),
                [
                    (c.reactive.mean, c.reactive.se),
                    (c.pavlovian.mean, c.pavlovian.se),
                ],
            )?;
        }
    }
    root.present().map_err(err)
}

/// The learning curve: over-current observations per window, mean ± SE per policy.
pub(crate) fn learning_curve(path: &Path, a: &Analysis) -> Io {
    let root = SVGBackend::new(path, (900, 450)).into_drawing_area();
    root.fill(&WHITE).map_err(err)?;
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
        * 1.05;
    let top = with_legend_room(0.0, top, 2, root.dim_in_pixel().1);
    let mut ch = ChartBuilder::on(&root)
        .caption(
            format!("Over-current observations per {WINDOW_S} s window (mean ± SE over runs)"),
            ("sans-serif", 16),
        )
        .margin(10)
        .x_label_area_size(36)
        .y_label_area_size(50)
        .build_cartesian_2d(0f64..n * WINDOW_S / 60.0, 0f64..top)
        .map_err(err)?;
    ch.configure_mesh()
        .x_desc("time, min (window centres)")
        .y_label_formatter(&tick_label)
        .x_label_formatter(&tick_label)
        .y_desc("over-current observations")
        .draw()
        .map_err(err)?;
    for mode in [Mode::Reactive, Mode::Pavlovian] {
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
                ((p.start_s + WINDOW_S / 2.0) / 60.0, d.mean, d.se)
            })
            .filter(|(_, m, _)| m.is_finite())
            .collect();
        ch.draw_series(LineSeries::new(
            pts.iter().map(|(x, m, _)| (*x, *m)),
            c.stroke_width(2),
        ))
        .map_err(err)?
        .label(mode_name(mode))
        .legend(move |(x, y)| PathElement::new(vec![(x, y), (x + 16, y)], c));
        ch.draw_series(
            pts.iter()
                .map(|(x, m, se)| PathElement::new(vec![(*x, m - se), (*x, m + se)], c)),
        )
        .map_err(err)?;
    }
    draw_legend(&mut ch).map_err(err)?;
    root.present().map_err(err)
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
            inputs: None,
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

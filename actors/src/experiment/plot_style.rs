//! What every experiment figure shares so it reads cleanly: axis labels without a "−0.0" or a row of
//! needless decimals, and a legend that sits in room kept above the data instead of on top of it.

use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;

/// An axis tick's label: at most two decimals, trailing zeros dropped, and never a negative zero
/// (`0.0`, `-0.0` and `-1e-17` all print `0`; `300.0` prints `300`; `0.25` prints `0.25`).
pub(crate) fn tick_label(v: &f64) -> String {
    if !v.is_finite() {
        return String::new();
    }
    let s = format!("{v:.2}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { s.into() }
}

/// The top of a y range from `lo` to `hi` raised so that a legend of `entries` lines fits above the data in
/// a chart area `area_px` pixels high (its caption and axis take about 60 of them).
pub(crate) fn with_legend_room(lo: f64, hi: f64, entries: usize, area_px: u32) -> f64 {
    let legend_px = 14.0 + 16.0 * entries as f64;
    let plot_px = (f64::from(area_px) - 60.0).max(40.0);
    let frac = (legend_px / plot_px).min(0.6);
    hi + (hi - lo).max(1e-9) * frac / (1.0 - frac)
}

/// Draws the chart's legend in its upper right corner, in the room [`with_legend_room`] kept.
pub(crate) fn draw_legend<'a, DB: DrawingBackend + 'a>(
    ch: &mut ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
) -> Result<(), DrawingAreaErrorKind<DB::ErrorType>> {
    ch.configure_series_labels()
        .position(SeriesLabelPosition::UpperRight)
        .background_style(WHITE.mix(0.85))
        .border_style(BLACK)
        .draw()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn labels_never_show_a_negative_zero_or_needless_decimals() {
        assert_eq!(tick_label(&-0.0), "0");
        assert_eq!(tick_label(&-1e-17), "0");
        assert_eq!(tick_label(&-0.004), "0");
        assert_eq!(tick_label(&300.0), "300");
        assert_eq!(tick_label(&0.25), "0.25");
        assert_eq!(tick_label(&-0.2), "-0.2");
        assert_eq!(tick_label(&1.5), "1.5");
    }

    #[test]
    fn the_legend_gets_room_above_the_data() {
        // Two entries in a 200-pixel area: 46 of 140 plot pixels are kept free above the data.
        let top = with_legend_room(0.0, 1.0, 2, 200);
        let free = (top - 1.0) / top;
        assert!((free - 46.0 / 140.0).abs() < 1e-12, "{free}");
        // More entries, more room; never more than 60 % of the plot.
        assert!(with_legend_room(0.0, 1.0, 3, 200) > top);
        assert!(with_legend_room(0.0, 1.0, 50, 100) <= 1.0 + 1.5 + 1e-9);
    }
}

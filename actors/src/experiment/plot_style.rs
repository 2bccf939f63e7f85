//! What every experiment figure shares, so that each prints cleanly in a paper and looks the same in every
//! renderer.
//!
//! - **Sizes in inches, type in points.** A figure is drawn for its printed width (one column, 3.3 in, or
//!   two, 7 in) and drawn twice: as SVG at 96 px per inch (CSS pixels, so the SVG's natural size is its
//!   printed size) and as PNG at 300 px per inch. Tick labels and axis titles are 8 pt, panel titles 8.5
//!   pt, the caption line and legends 7.5 pt at that width.
//! - **One bundled font.** DejaVu Sans (from the `dejavu` crate; its licence is the Bitstream Vera / Arev
//!   licence shipped in that crate) is registered for plotters' `ab_glyph` text, so PNGs never depend on
//!   the fonts a machine has. The SVG names that one family and no fallback list: ImageMagick's own SVG
//!   reader cannot parse a list (`DejaVu Sans, sans-serif` in any spelling, or a `<style>` rule with
//!   one) and draws every text in its heavy default font instead; rsvg and browsers find DejaVu Sans where
//!   it is installed (Debian's `fonts-dejavu-core`) and use their default font where it is not.
//! - **Renderer-proof.** Solid colours only (no opacity anywhere): light grey major grid lines, no minor
//!   grid, light solid fills for bands and bars; no rotated text (the y axis's title is written
//!   horizontally above the plot); lines broken where they turn back sharply (plotters' bitmap mitres
//!   would draw spikes there). Chromium, rsvg and ImageMagick then agree with the PNG.
//! - **Distinguishable series.** Each series has a colour and a dash pattern; reference lines (zero, 90°)
//!   are drawn without a legend entry.
//! - **Legends outside the data**, in a row under the panel title; a caption line under the figure says
//!   what the bars, bands and error bars are and n.

use std::path::Path;
use std::sync::Once;

use plotters::coord::Shift;
use plotters::coord::types::RangedCoordf64;
use plotters::prelude::*;
use plotters::style::FontStyle;
use plotters::style::text_anchor::{HPos, Pos, VPos};

pub(crate) type Io = std::io::Result<()>;

/// The family name the bundled font is registered under and written into the SVGs.
pub(crate) const FONT: &str = "DejaVu Sans";

/// Pixels per inch of the PNGs.
pub(crate) const PNG_DPI: f64 = 300.0;
/// Pixels per inch of the SVGs (CSS pixels).
pub(crate) const SVG_DPI: f64 = 96.0;
/// One column of a two-column paper, inches.
pub(crate) const ONE_COLUMN_IN: f64 = 3.3;
/// Both columns, inches.
pub(crate) const TWO_COLUMNS_IN: f64 = 7.0;

/// Tick labels and axis titles, pt.
const TICK_PT: f64 = 8.0;
/// Panel titles, pt.
const TITLE_PT: f64 = 8.5;
/// The caption line and legends, pt.
const SMALL_PT: f64 = 7.5;

/// Light grey of the major grid.
pub(crate) const GRID: RGBColor = RGBColor(222, 222, 222);
/// The reactive policy.
pub(crate) const REACTIVE: RGBColor = RGBColor(200, 80, 40);
/// The Pavlovian policy.
pub(crate) const PAVLOVIAN: RGBColor = RGBColor(30, 90, 190);
/// A third series, thresholds and the stimulus.
pub(crate) const DARK: RGBColor = RGBColor(40, 40, 40);
/// Reference lines.
pub(crate) const REFERENCE: RGBColor = RGBColor(130, 130, 130);

/// `c` mixed with white: a solid light tint (`amount` 0 = white, 1 = `c`), for bars and bands.
pub(crate) fn tint(c: RGBColor, amount: f64) -> RGBColor {
    let m = |x: u8| {
        (255.0 - (255.0 - f64::from(x)) * amount)
            .round()
            .clamp(0.0, 255.0) as u8
    };
    RGBColor(m(c.0), m(c.1), m(c.2))
}

/// Registers the bundled font under [`FONT`] (once): every figure calls it before it draws.
pub(crate) fn register_font() {
    static ONCE: Once = Once::new();
    ONCE.call_once(|| {
        // The crate's bytes are a valid TrueType file; a failure would only leave text unrendered.
        let _ = plotters::style::register_font(FONT, FontStyle::Normal, dejavu::sans::regular());
    });
}

/// The dash pattern of a series.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Dash {
    Solid,
    Dashed,
    Dotted,
}

impl Dash {
    /// (dash, gap) in pt, or None for a solid line.
    fn pattern_pt(self) -> Option<(f64, f64)> {
        match self {
            Dash::Solid => None,
            Dash::Dashed => Some((4.0, 2.5)),
            Dash::Dotted => Some((1.5, 3.0)),
        }
    }
}

/// One legend entry: label, colour, dash.
pub(crate) type Entry = (String, RGBColor, Dash);

/// The drawing scale: how many pixels one printed point is.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Style {
    px_per_pt: f64,
}

impl Style {
    pub(crate) fn at_dpi(dpi: f64) -> Self {
        Self {
            px_per_pt: dpi / 72.0,
        }
    }

    /// `pt` points in pixels, at least 1.
    pub(crate) fn px(&self, pt: f64) -> i32 {
        ((pt * self.px_per_pt).round() as i32).max(1)
    }

    fn upx(&self, pt: f64) -> u32 {
        self.px(pt).unsigned_abs()
    }

    /// A text style of `pt` points (plotters' SVG writes a size s as font-size s / 1.24).
    pub(crate) fn text(&self, pt: f64) -> TextStyle<'static> {
        (FONT, pt * self.px_per_pt * 1.24).into_font().color(&BLACK)
    }

    /// A line of `pt` points in `c`.
    pub(crate) fn line(&self, c: RGBColor, pt: f64) -> ShapeStyle {
        c.stroke_width(self.upx(pt))
    }
}

/// A figure: its printed size and how it draws itself on any backend.
pub(crate) trait Figure {
    /// Width and height, inches.
    fn size_in(&self) -> (f64, f64);
    /// The caption line under the figure: what the bars, bands and error bars are, and n.
    fn caption(&self) -> String;
    /// Draws the figure (without its caption) on `root`.
    fn draw<DB: DrawingBackend>(&self, root: &DrawingArea<DB, Shift>, st: &Style) -> Io;
}

/// The pixel size of a figure of `size_in` inches at `dpi`.
pub(crate) fn pixels(size_in: (f64, f64), dpi: f64) -> (u32, u32) {
    let p = |x: f64| (x * dpi).round() as u32;
    (p(size_in.0), p(size_in.1))
}

pub(crate) fn err<E: std::fmt::Display>(e: E) -> std::io::Error {
    std::io::Error::other(e.to_string())
}

/// `text` broken into lines no wider than `width` pixels in `style` (at explicit line breaks, then between
/// words).
fn wrap<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    style: &TextStyle<'_>,
    text: &str,
    width: u32,
) -> Vec<String> {
    let fits = |s: &str| {
        area.estimate_text_size(s, style)
            .map_or(true, |(w, _)| w <= width)
    };
    let mut lines = Vec::new();
    for para in text.lines() {
        let mut line = String::new();
        for word in para.split_whitespace() {
            let candidate = if line.is_empty() {
                word.to_string()
            } else {
                format!("{line} {word}")
            };
            if fits(&candidate) || line.is_empty() {
                line = candidate;
            } else {
                lines.push(std::mem::replace(&mut line, word.to_string()));
            }
        }
        lines.push(line);
    }
    lines
}

fn draw_whole<DB: DrawingBackend, F: Figure>(
    root: DrawingArea<DB, Shift>,
    st: &Style,
    fig: &F,
) -> Io {
    root.fill(&WHITE).map_err(err)?;
    let style = st.text(SMALL_PT);
    let (w, h) = root.dim_in_pixel();
    let lines = wrap(
        &root,
        &style,
        &fig.caption(),
        w.saturating_sub(st.upx(10.0)),
    );
    let line_px = st.px(SMALL_PT * 1.3);
    let cap_px = line_px * lines.len() as i32 + st.px(5.0);
    let (body, foot) = root.split_vertically(h as i32 - cap_px);
    for (i, line) in lines.into_iter().enumerate() {
        foot.draw(&Text::new(
            line,
            (st.px(5.0), st.px(3.0) + line_px * i as i32),
            style.clone(),
        ))
        .map_err(err)?;
    }
    fig.draw(&body, st)?;
    root.present().map_err(err)
}

/// Writes `fig` as `<stem>.svg` (96 px per inch) and `<stem>.png` (300 px per inch, with the resolution
/// recorded in the PNG) into `dir`.
pub(crate) fn save<F: Figure>(dir: &Path, stem: &str, fig: &F) -> Io {
    register_font();
    let mut svg = String::new();
    draw_whole(
        SVGBackend::with_string(&mut svg, pixels(fig.size_in(), SVG_DPI)).into_drawing_area(),
        &Style::at_dpi(SVG_DPI),
        fig,
    )?;
    std::fs::write(dir.join(format!("{stem}.svg")), for_every_renderer(&svg))?;
    let png = dir.join(format!("{stem}.png"));
    draw_whole(
        BitMapBackend::new(&png, pixels(fig.size_in(), PNG_DPI)).into_drawing_area(),
        &Style::at_dpi(PNG_DPI),
        fig,
    )?;
    let bytes = std::fs::read(&png)?;
    std::fs::write(&png, with_phys(&bytes, PNG_DPI))?;
    Ok(())
}

/// plotters' SVG made to render the same in browsers, rsvg and ImageMagick's own SVG reader, which fills a
/// `fill="none"` polyline black when an `opacity` attribute follows, closes polylines, ignores a text's
/// `dy` and outlines text with a stroke (bold-looking type) unless told not to: every `opacity="1"` (the
/// default) is dropped, polylines are written as paths, each text's `dy` (in em or ex of its font size) is
/// folded into its `y` (in its own coordinates, so a rotated label moves as before), and every text
/// without a stroke says `stroke="none"`.
pub(crate) fn for_every_renderer(svg: &str) -> String {
    let svg = polylines_as_paths(&svg.replace(" opacity=\"1\"", ""));
    let mut out = String::with_capacity(svg.len());
    let mut rest = svg.as_str();
    while let Some(at) = rest.find("<text ") {
        let (before, tag_on) = rest.split_at(at);
        out.push_str(before);
        let end = tag_on.find('>').map_or(tag_on.len(), |e| e + 1);
        let (tag, after) = tag_on.split_at(end);
        let tag = fold_dy(tag);
        if tag.contains(" stroke=\"") {
            out.push_str(&tag);
        } else {
            out.push_str(&tag.replacen("<text ", "<text stroke=\"none\" ", 1));
        }
        rest = after;
    }
    out.push_str(rest);
    out
}

/// Every `<polyline ... points="a b c"` as `<path ... d="Ma Lb Mb Lc"`: one two-point subpath per segment,
/// with round caps where there are several (so the segments meet as round joins). ImageMagick's reader
/// closes a polyline back to its first point, and at a density above its default (`-density 300`, how a
/// figure is rasterised for print) also a path of three points or more: a stray straight line from a
/// series' first point to its last, seen on `fig_curve`'s lines. A two-point subpath has nothing to close.
fn polylines_as_paths(svg: &str) -> String {
    let mut out = String::with_capacity(svg.len());
    let mut rest = svg;
    while let Some(at) = rest.find("<polyline ") {
        let (before, tag_on) = rest.split_at(at);
        out.push_str(before);
        let end = tag_on.find('>').map_or(tag_on.len(), |e| e + 1);
        let (tag, after) = tag_on.split_at(end);
        let converted = tag.find(" points=\"").and_then(|p| {
            let v0 = p + " points=\"".len();
            let len = tag[v0..].find('"')?;
            let pts: Vec<&str> = tag[v0..v0 + len].split_whitespace().collect();
            let d = match pts.as_slice() {
                [only] => format!("M{only}"),
                _ => pts
                    .windows(2)
                    .map(|w| format!("M{} L{}", w[0], w[1]))
                    .collect::<Vec<_>>()
                    .join(" "),
            };
            let caps = if pts.len() > 2 {
                " stroke-linecap=\"round\""
            } else {
                ""
            };
            Some(format!(
                "<path {}{caps} d=\"{d}\"{}",
                &tag["<polyline ".len()..p],
                &tag[v0 + len + 1..]
            ))
        });
        out.push_str(converted.as_deref().unwrap_or(tag));
        rest = after;
    }
    out.push_str(rest);
    out
}

/// One `<text ...>` start tag with its `dy` folded into `y`.
fn fold_dy(tag: &str) -> String {
    let attr = |name: &str| -> Option<(usize, usize, &str)> {
        let key = format!(" {name}=\"");
        let start = tag.find(&key)?;
        let v0 = start + key.len();
        let len = tag[v0..].find('"')?;
        Some((start, v0 + len + 1, &tag[v0..v0 + len]))
    };
    let (Some(y), Some(dy), Some(size)) = (attr("y"), attr("dy"), attr("font-size")) else {
        return tag.to_string();
    };
    let (Ok(y_px), Ok(size_px)) = (y.2.parse::<f64>(), size.2.parse::<f64>()) else {
        return tag.to_string();
    };
    // An ex is taken as half an em (what rsvg and plotters' own layout assume).
    let shift = if let Some(em) = dy.2.strip_suffix("em") {
        em.parse::<f64>().map(|e| e * size_px)
    } else if let Some(ex) = dy.2.strip_suffix("ex") {
        ex.parse::<f64>().map(|e| e * size_px * 0.5)
    } else {
        dy.2.parse::<f64>()
    };
    let Ok(shift) = shift else {
        return tag.to_string();
    };
    let new_y = format!(" y=\"{}\"", ((y_px + shift) * 100.0).round() / 100.0);
    // Replace the later attribute first so the earlier one's offsets stay valid.
    let mut t = tag.to_string();
    let (first, second) = if y.0 < dy.0 { (y, dy) } else { (dy, y) };
    let replace = |t: &mut String, a: (usize, usize, &str)| {
        let with = if a.0 == y.0 {
            new_y.clone()
        } else {
            String::new()
        };
        t.replace_range(a.0..a.1, &with);
    };
    replace(&mut t, second);
    replace(&mut t, first);
    t
}

/// The PNG `bytes` with a `pHYs` chunk saying `dpi` pixels per inch inserted after the header (unchanged
/// if it is not a PNG or already has one).
pub(crate) fn with_phys(bytes: &[u8], dpi: f64) -> Vec<u8> {
    const SIG: usize = 8;
    const IHDR_END: usize = SIG + 8 + 13 + 4;
    let is_png = bytes.starts_with(b"\x89PNG\r\n\x1a\n") && bytes.get(12..16) == Some(b"IHDR");
    if !is_png || bytes.len() < IHDR_END || bytes.windows(4).any(|w| w == b"pHYs") {
        return bytes.to_vec();
    }
    let per_m = (dpi / 0.0254).round() as u32;
    let mut body = Vec::with_capacity(13);
    body.extend_from_slice(b"pHYs");
    body.extend_from_slice(&per_m.to_be_bytes());
    body.extend_from_slice(&per_m.to_be_bytes());
    body.push(1); // unit: metre
    let mut out = Vec::with_capacity(bytes.len() + 21);
    out.extend_from_slice(&bytes[..IHDR_END]);
    out.extend_from_slice(&9u32.to_be_bytes());
    out.extend_from_slice(&body);
    out.extend_from_slice(&crc32fast::hash(&body).to_be_bytes());
    out.extend_from_slice(&bytes[IHDR_END..]);
    out
}

/// The policy's name as a figure shows it: "reactive", "Pavlovian", "manual".
pub(crate) fn policy_label(mode: pavlov::control::Mode) -> &'static str {
    match mode {
        pavlov::control::Mode::Pavlovian => "Pavlovian",
        pavlov::control::Mode::Reactive => "reactive",
        pavlov::control::Mode::Manual => "manual",
    }
}

/// A signed number with a true minus sign (U+2212), as type should print it.
pub(crate) fn signed(s: &str) -> String {
    s.replace('-', "\u{2212}")
}

/// An axis tick's label: at most two decimals, trailing zeros dropped, and never a negative zero
/// (`0.0`, `-0.0` and `-1e-17` all print `0`; `300.0` prints `300`; `0.25` prints `0.25`).
pub(crate) fn tick_label(v: &f64) -> String {
    if !v.is_finite() {
        return String::new();
    }
    let s = format!("{v:.2}");
    let s = s.trim_end_matches('0').trim_end_matches('.');
    if s == "-0" { "0".into() } else { signed(s) }
}

/// Splits a panel into its header (title, then the legend's entries in rows as wide as the panel) and the
/// chart area, and draws the header.
pub(crate) fn panel_header<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    st: &Style,
    title: &str,
    legend: &[Entry],
) -> Result<DrawingArea<DB, Shift>, std::io::Error> {
    let title_px = if title.is_empty() {
        st.px(2.0)
    } else {
        st.px(TITLE_PT * 1.7)
    };
    let row_px = st.px(SMALL_PT * 1.5);
    let text = st.text(SMALL_PT).pos(Pos::new(HPos::Left, VPos::Center));
    // Each entry's place: (row, x). Laid out in points, with every label measured at the PNG's scale
    // (type does not measure exactly in proportion to its size), so that the SVG (96 px per inch) and the
    // PNG (300) break the legend into the same rows.
    let width_pt = f64::from(area.dim_in_pixel().0) / st.px_per_pt;
    let measure = Style::at_dpi(PNG_DPI);
    let measured = measure.text(SMALL_PT);
    let mut places = Vec::with_capacity(legend.len());
    let (mut row, mut x_pt) = (0i32, 10.0);
    for (label, _, _) in legend {
        let text_pt = area
            .estimate_text_size(label, &measured)
            .map_or(label.len() as f64 * 4.0, |s| {
                f64::from(s.0) / measure.px_per_pt
            });
        let w_pt = 20.0 + text_pt;
        if x_pt + w_pt > width_pt && x_pt > 10.0 {
            row += 1;
            x_pt = 10.0;
        }
        places.push((row, st.px(x_pt)));
        x_pt += w_pt + 10.0;
    }
    let rows = if legend.is_empty() { 0 } else { row + 1 };
    let (head, body) = area.split_vertically(title_px + rows * row_px);
    head.draw(&Text::new(
        title.to_string(),
        (st.px(4.0), st.px(3.5)),
        st.text(TITLE_PT),
    ))
    .map_err(err)?;
    for ((label, c, dash), (row, x)) in legend.iter().zip(places) {
        let y = title_px + row * row_px + row_px / 2;
        legend_sample(&head, st, (x, y), *c, *dash)?;
        head.draw(&Text::new(
            label.clone(),
            (x + st.px(20.0), y),
            text.clone(),
        ))
        .map_err(err)?;
    }
    Ok(body)
}

/// A legend's sample of a line: 16 pt of it in its colour and dash, starting at `at`.
fn legend_sample<DB: DrawingBackend>(
    area: &DrawingArea<DB, Shift>,
    st: &Style,
    at: (i32, i32),
    c: RGBColor,
    dash: Dash,
) -> Io {
    let (x, y) = at;
    let len = 16.0;
    let segs: Vec<(f64, f64)> = match dash.pattern_pt() {
        None => vec![(0.0, len)],
        Some((d, g)) => {
            let mut v = Vec::new();
            let mut s = 0.0;
            while s < len {
                v.push((s, (s + d).min(len)));
                s += d + g;
            }
            v
        }
    };
    for (a, b) in segs {
        area.draw(&PathElement::new(
            vec![(x + st.px(a) - 1, y), (x + st.px(b), y)],
            st.line(c, 1.5),
        ))
        .map_err(err)?;
    }
    Ok(())
}

/// The chart's mesh: axis titles with units (the y title horizontal, [`y_title`]), tick labels, a light
/// major grid, no minor grid.
pub(crate) fn mesh<DB: DrawingBackend>(
    ch: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    st: &Style,
    x_desc: &str,
    y_desc: &str,
) -> Io {
    ch.configure_mesh()
        .max_light_lines(0)
        .bold_line_style(st.line(GRID, 0.5))
        .axis_style(st.line(BLACK, 0.75))
        .set_all_tick_mark_size(st.px(2.5))
        .label_style(st.text(TICK_PT))
        .axis_desc_style(st.text(TICK_PT))
        .x_labels(6)
        .y_labels(5)
        .x_desc(x_desc)
        .x_label_formatter(&tick_label)
        .y_label_formatter(&tick_label)
        .draw()
        .map_err(err)?;
    y_title(ch, st, y_desc)
}

/// Room above a chart's plot for its [`y_title`], pt.
pub(crate) const Y_TITLE_ROOM_PT: f64 = TICK_PT * 1.6;

/// The y axis's title (quantity and unit), written horizontally above the plot's top left corner, where
/// the chart leaves [`Y_TITLE_ROOM_PT`] for it. Not rotated: ImageMagick's own SVG reader drops a text
/// rotated about a point (`rotate(270, x, y)`, what plotters writes) and mirrors one rotated after a
/// translation, so a rotated axis title is the one thing the three renderers cannot agree on.
pub(crate) fn y_title<DB: DrawingBackend, X, Y>(
    ch: &ChartContext<'_, DB, Cartesian2d<X, Y>>,
    st: &Style,
    text: &str,
) -> Io
where
    X: plotters::coord::ranged1d::Ranged,
    Y: plotters::coord::ranged1d::Ranged,
{
    if text.is_empty() {
        return Ok(());
    }
    let plot = ch.plotting_area().strip_coord_spec();
    plot.draw(&Text::new(
        text.to_string(),
        (-st.px(TICK_PT * 2.2), -st.px(3.0)),
        st.text(TICK_PT).pos(Pos::new(HPos::Left, VPos::Bottom)),
    ))
    .map_err(err)
}

/// A chart on `area` with room for tick labels and axis titles in `st`.
pub(crate) fn chart<'a, DB: DrawingBackend>(
    area: &'a DrawingArea<DB, Shift>,
    st: &Style,
    x: std::ops::Range<f64>,
    y: std::ops::Range<f64>,
) -> Result<ChartContext<'a, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>, std::io::Error> {
    ChartBuilder::on(area)
        .margin_top(st.px(Y_TITLE_ROOM_PT))
        .margin_right(st.px(12.0))
        .margin_left(st.px(2.0))
        .x_label_area_size(st.px(TICK_PT * 2.9))
        .y_label_area_size(st.px(TICK_PT * 4.4))
        .build_cartesian_2d(x, y)
        .map_err(err)
}

/// The largest change of direction, degrees, that a line keeps as one joined path. plotters' bitmap
/// backend turns a wide path into a polygon with mitred joins and caps only the outer side of a join: at a
/// near-reversal (a one-tick spike of the over-current flag, a step of a wheel command) the inner mitre
/// point lies (w/2)/sin(θ/2) from the vertex, θ the angle between the segments, and the PNG showed
/// stray spikes tens of pixels long above and below the panel. Breaking the path where it turns by more
/// than 120° (θ < 60°) bounds every mitre by the stroke's width; the pieces meet end to end, so the line
/// looks the same.
const MAX_TURN_DEG: f64 = 120.0;

/// `pts` (data coordinates) cut into pieces at every vertex where the line, in the pixel coordinates
/// `px` of the same points, turns by more than [`MAX_TURN_DEG`]; each piece ends at the vertex the next
/// one starts from. Points at the same pixel as the one before are kept (plotters skips them) and do not
/// count as a direction.
pub(crate) fn pieces_without_sharp_turns(
    pts: &[(f64, f64)],
    px: &[(i32, i32)],
) -> Vec<Vec<(f64, f64)>> {
    let cos_max = MAX_TURN_DEG.to_radians().cos();
    let mut out = Vec::new();
    let mut piece: Vec<(f64, f64)> = Vec::new();
    // The last pixel seen and the direction that led to it.
    let mut last: Option<(i32, i32)> = None;
    let mut dir: Option<(f64, f64)> = None;
    for (&p, &q) in pts.iter().zip(px) {
        if let Some(l) = last
            && l != q
        {
            let d = (f64::from(q.0 - l.0), f64::from(q.1 - l.1));
            if let Some(prev) = dir {
                let cos = (prev.0 * d.0 + prev.1 * d.1) / (prev.0.hypot(prev.1) * d.0.hypot(d.1));
                if cos < cos_max
                    && let Some(&vertex) = piece.last()
                {
                    out.push(std::mem::replace(&mut piece, vec![vertex]));
                }
            }
            dir = Some(d);
        }
        last = Some(q);
        piece.push(p);
    }
    if piece.len() > 1 {
        out.push(piece);
    }
    out
}

/// Draws a line through `pts` in `c` with `dash`, `width_pt` wide, as one path or, where it turns
/// sharply, several ([`pieces_without_sharp_turns`]).
pub(crate) fn line<DB: DrawingBackend>(
    ch: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    st: &Style,
    pts: &[(f64, f64)],
    c: RGBColor,
    dash: Dash,
    width_pt: f64,
) -> Io {
    let pts: Vec<(f64, f64)> = pts
        .iter()
        .copied()
        .filter(|p| p.0.is_finite() && p.1.is_finite())
        .collect();
    let px: Vec<(i32, i32)> = pts.iter().map(|p| ch.backend_coord(p)).collect();
    for piece in pieces_without_sharp_turns(&pts, &px) {
        match dash.pattern_pt() {
            None => {
                ch.draw_series(LineSeries::new(piece, st.line(c, width_pt)))
                    .map_err(err)?;
            }
            Some((d, g)) => {
                ch.draw_series(DashedLineSeries::new(
                    piece,
                    st.px(d),
                    st.px(g),
                    st.line(c, width_pt),
                ))
                .map_err(err)?;
            }
        }
    }
    Ok(())
}

/// A vertical error bar at `x` from `lo` to `hi` with caps `cap` (x units) wide.
pub(crate) fn error_bar<DB: DrawingBackend>(
    ch: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    st: &Style,
    x: f64,
    (lo, hi): (f64, f64),
    cap: f64,
    c: RGBColor,
) -> Io {
    if !(lo.is_finite() && hi.is_finite()) || hi <= lo {
        return Ok(());
    }
    let s = st.line(c, 0.9);
    ch.draw_series([
        PathElement::new(vec![(x, lo), (x, hi)], s),
        PathElement::new(vec![(x - cap, lo), (x + cap, lo)], s),
        PathElement::new(vec![(x - cap, hi), (x + cap, hi)], s),
    ])
    .map_err(err)?;
    Ok(())
}

/// A band from `lo` to `hi` over x, filled with a light solid tint of `c` and edged with thin lines of
/// `c`, so that a band drawn over another still shows the other's edges.
pub(crate) fn band<DB: DrawingBackend>(
    ch: &mut ChartContext<'_, DB, Cartesian2d<RangedCoordf64, RangedCoordf64>>,
    st: &Style,
    pts: &[(f64, f64, f64)],
    c: RGBColor,
    fill: bool,
) -> Io {
    let pts: Vec<(f64, f64, f64)> = pts
        .iter()
        .copied()
        .filter(|p| p.0.is_finite() && p.1.is_finite() && p.2.is_finite())
        .collect();
    if pts.len() < 2 {
        return Ok(());
    }
    if fill {
        let outline: Vec<(f64, f64)> = pts
            .iter()
            .map(|p| (p.0, p.2))
            .chain(pts.iter().rev().map(|p| (p.0, p.1)))
            .collect();
        ch.draw_series(std::iter::once(Polygon::new(outline, tint(c, 0.18))))
            .map_err(err)?;
    }
    for edge in [
        pts.iter().map(|p| (p.0, p.1)).collect::<Vec<_>>(),
        pts.iter().map(|p| (p.0, p.2)).collect(),
    ] {
        line(ch, st, &edge, tint(c, 0.55), Dash::Solid, 0.5)?;
    }
    Ok(())
}

/// The range from the smallest to the largest finite value, padded by 8 % (0..1 when there is none).
pub(crate) fn padded_range(values: impl Iterator<Item = f64>) -> std::ops::Range<f64> {
    let (lo, hi) = values
        .filter(|v| v.is_finite())
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(l, h), v| {
            (l.min(v), h.max(v))
        });
    let (lo, hi) = if lo.is_finite() { (lo, hi) } else { (0.0, 1.0) };
    // A flat series still gets an axis with distinct ticks.
    let pad = if hi - lo > 1e-9 {
        (hi - lo) * 0.08
    } else {
        (lo.abs() * 0.1).max(1.0)
    };
    (lo - pad)..(hi + pad)
}

/// The y range of a quantity in [0, 1]: the unit interval with a small margin so that values at 0 and 1
/// stay off the axis lines.
pub(crate) const UNIT: std::ops::Range<f64> = -0.04..1.04;

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
        assert_eq!(tick_label(&-0.2), "\u{2212}0.2");
        assert_eq!(tick_label(&1.5), "1.5");
    }

    #[test]
    fn type_is_at_least_seven_points_at_print_size() {
        // One column at 96 px/in: an 8 pt tick label is 10.7 CSS px (plotters writes size / 1.24).
        let st = Style::at_dpi(SVG_DPI);
        let written = st.text(TICK_PT).font.get_size() / 1.24;
        assert!((written - 8.0 * 96.0 / 72.0).abs() < 1e-9);
        for pt in [TICK_PT, TITLE_PT, SMALL_PT] {
            assert!(pt >= 7.0);
        }
        assert_eq!(pixels((ONE_COLUMN_IN, 2.0), PNG_DPI), (990, 600));
        assert_eq!(pixels((TWO_COLUMNS_IN, 2.0), SVG_DPI), (672, 192));
    }

    #[test]
    fn tints_are_solid_and_light() {
        assert_eq!(tint(RGBColor(0, 0, 0), 0.0), RGBColor(255, 255, 255));
        assert_eq!(tint(RGBColor(0, 100, 255), 1.0), RGBColor(0, 100, 255));
        let t = tint(REACTIVE, 0.2);
        assert!(t.0 > 230 && t.1 > 200 && t.2 > 200, "{t:?}");
    }

    #[test]
    fn the_svg_has_no_opacity_no_relative_text_offsets_and_no_path_to_close() {
        let svg = r##"<svg><polyline fill="none" opacity="1" stroke="#000" points="1,2 3,4 "/><polyline fill="none" stroke="#000" points="1,2 3,4 5,2 "/><text x="8" y="10" dy="0.76em" text-anchor="start" font-size="10" opacity="1" fill="#000">a</text><text x="1" y="20" dy="-0.5ex" font-size="10" transform="rotate(270, 1, 20)">b</text></svg>"##;
        let out = for_every_renderer(svg);
        assert_eq!(
            out,
            r##"<svg><path fill="none" stroke="#000" d="M1,2 L3,4"/><path fill="none" stroke="#000" stroke-linecap="round" d="M1,2 L3,4 M3,4 L5,2"/><text stroke="none" x="8" y="17.6" text-anchor="start" font-size="10" fill="#000">a</text><text stroke="none" x="1" y="17.5" font-size="10" transform="rotate(270, 1, 20)">b</text></svg>"##
        );
    }

    #[test]
    fn a_line_is_cut_where_it_turns_back_and_only_there() {
        // A one-tick spike (0 → 1 → 0 three pixels apart, 100 pixels high) and a right-angle step.
        let pts = [(0.0, 0.0), (1.0, 0.0), (2.0, 1.0), (3.0, 0.0), (4.0, 0.0)];
        let px = [(0, 100), (3, 100), (6, 0), (9, 100), (12, 100)];
        let pieces = pieces_without_sharp_turns(&pts, &px);
        assert_eq!(
            pieces,
            vec![
                vec![(0.0, 0.0), (1.0, 0.0), (2.0, 1.0)],
                vec![(2.0, 1.0), (3.0, 0.0), (4.0, 0.0)],
            ],
            "cut at the spike's tip, nowhere else"
        );
        // A step (90° turns) and a gentle curve stay one path; a repeated pixel is no direction.
        let step = [(0, 0), (0, 0), (10, 0), (10, 10), (20, 10), (30, 14)];
        let pts: Vec<(f64, f64)> = step
            .iter()
            .map(|&(x, y)| (f64::from(x), f64::from(y)))
            .collect();
        assert_eq!(pieces_without_sharp_turns(&pts, &step), vec![pts.clone()]);
        // An exact reversal along one line is cut too.
        let back = [(0, 0), (0, 50), (0, 10)];
        let pts: Vec<(f64, f64)> = back
            .iter()
            .map(|&(x, y)| (f64::from(x), f64::from(y)))
            .collect();
        assert_eq!(pieces_without_sharp_turns(&pts, &back).len(), 2);
        assert!(pieces_without_sharp_turns(&pts[..1], &back[..1]).is_empty());
    }

    #[test]
    fn the_png_says_300_dpi() {
        // A minimal PNG header: signature and IHDR (the rest is not read).
        let mut png = b"\x89PNG\r\n\x1a\n".to_vec();
        png.extend_from_slice(&13u32.to_be_bytes());
        png.extend_from_slice(b"IHDR");
        png.extend_from_slice(&[0; 13]);
        png.extend_from_slice(&[0; 4]);
        png.extend_from_slice(b"rest");
        let out = with_phys(&png, 300.0);
        let at = out.windows(4).position(|w| w == b"pHYs").expect("pHYs");
        assert_eq!(at, 33 + 4);
        assert_eq!(&out[at + 4..at + 8], &11811u32.to_be_bytes());
        assert!(out.ends_with(b"rest"));
        // Idempotent, and not applied to what is not a PNG.
        assert_eq!(with_phys(&out, 300.0), out);
        assert_eq!(with_phys(b"GIF89a", 300.0), b"GIF89a");
    }
}

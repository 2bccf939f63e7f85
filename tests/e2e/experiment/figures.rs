//! What every figure a study writes must be: an SVG and a 300-dpi PNG of the same printed size, one or two
//! columns of a paper wide, with no opacity anywhere, no relative text offsets, no rotated text and one
//! font family (so ImageMagick renders it as browsers and rsvg do), and every printed table beside them as
//! Markdown and CSV.

use std::path::Path;

/// One column (3.3 in) or both (7 in) at 300 px per inch.
const WIDTHS_PX: [u32; 2] = [990, 2100];

/// The PNG's width and height (from its IHDR) and its pixels per metre (from its pHYs, if any).
fn png_size(bytes: &[u8]) -> ((u32, u32), Option<(u32, u32)>) {
    assert!(bytes.starts_with(b"\x89PNG\r\n\x1a\n"), "not a PNG");
    let be = |at: usize| u32::from_be_bytes(bytes[at..at + 4].try_into().unwrap());
    assert_eq!(&bytes[12..16], b"IHDR");
    let size = (be(16), be(20));
    let phys = bytes
        .windows(4)
        .position(|w| w == b"pHYs")
        .map(|at| (be(at + 4), be(at + 8)));
    (size, phys)
}

/// The SVG's width and height attributes.
fn svg_size(svg: &str) -> (u32, u32) {
    let attr = |name: &str| -> u32 {
        let key = format!(" {name}=\"");
        let at = svg.find(&key).expect(name) + key.len();
        svg[at..]
            .split('"')
            .next()
            .and_then(|v| v.parse().ok())
            .expect(name)
    };
    (attr("width"), attr("height"))
}

/// Every `opacity`, `fill-opacity` and `stroke-opacity` value in `svg`.
fn opacities(svg: &str) -> Vec<f64> {
    let mut out = Vec::new();
    for key in ["opacity=\"", "opacity:"] {
        let mut rest = svg;
        while let Some(at) = rest.find(key) {
            rest = &rest[at + key.len()..];
            let v: String = rest
                .chars()
                .take_while(|c| c.is_ascii_digit() || *c == '.')
                .collect();
            out.push(v.parse().unwrap_or(f64::NAN));
        }
    }
    out
}

/// Checks `<stem>.svg` and `<stem>.png` in `dir`.
pub(super) fn check_figure(dir: &Path, stem: &str) {
    let svg = std::fs::read_to_string(dir.join(format!("{stem}.svg"))).expect(stem);
    let png = std::fs::read(dir.join(format!("{stem}.png"))).expect(stem);
    let ((w, h), phys) = png_size(&png);
    assert!(
        WIDTHS_PX.contains(&w),
        "{stem}.png is {w} px wide: not one or two columns at 300 dpi"
    );
    assert!(h >= 600, "{stem}.png is {h} px high");
    assert_eq!(
        phys,
        Some((11811, 11811)),
        "{stem}.png records 300 dpi (11811 px/m)"
    );
    // The SVG at 96 px per inch: the same printed size.
    let (sw, sh) = svg_size(&svg);
    let inches = |px: u32, dpi: f64| f64::from(px) / dpi;
    assert!(
        (inches(sw, 96.0) - inches(w, 300.0)).abs() < 0.02,
        "{stem}: {sw} vs {w}"
    );
    assert!(
        (inches(sh, 96.0) - inches(h, 300.0)).abs() < 0.02,
        "{stem}: {sh} vs {h}"
    );
    // No opacity at all (ImageMagick fills a polyline black when one follows fill="none", and draws a
    // translucent grid as black), and text placed by y alone (ImageMagick ignores dy).
    let o = opacities(&svg);
    assert!(
        o.is_empty(),
        "{stem}.svg has opacities: {:?}",
        &o[..o.len().min(5)]
    );
    assert!(!svg.contains(" dy=\""), "{stem}.svg offsets text with dy");
    // Lines as paths of two-point subpaths (ImageMagick closes a polyline back to its start, and at
    // print density any path of three points or more).
    assert!(!svg.contains("<polyline"), "{stem}.svg has polylines");
    for d in svg.split(" d=\"").skip(1) {
        let d = d.split('"').next().unwrap_or("");
        for sub in d.split('M').skip(1) {
            assert!(
                sub.matches('L').count() <= 1,
                "{stem}.svg has a path M{sub}"
            );
        }
    }
    // Text in the bundled font, named alone (ImageMagick cannot read a list of families); 8 pt ticks are
    // 10.7 CSS px, nothing smaller than 7 pt (9.3 px).
    assert!(svg.contains("font-family=\"DejaVu Sans\""), "{stem}");
    assert!(
        !svg.contains("sans-serif"),
        "{stem}.svg names a list of fonts"
    );
    // No rotated text: ImageMagick drops a text rotated about a point and mirrors one rotated otherwise;
    // and no text outlined (ImageMagick strokes text unless told not to).
    assert!(!svg.contains("rotate("), "{stem}.svg rotates text");
    assert_eq!(
        svg.matches("<text ").count(),
        svg.matches("<text stroke=\"none\" ").count(),
        "{stem}.svg has text without stroke=\"none\""
    );
    for part in svg.split("font-size=\"").skip(1) {
        let size: f64 = part.split('"').next().and_then(|v| v.parse().ok()).unwrap();
        assert!(size >= 9.3 - 1e-6, "{stem}.svg has {size} px text");
    }
}

/// Checks `table.md` and `table.csv` in `dir`: a Markdown table, and a CSV whose rows all have the header's
/// number of cells (no cell here holds a comma).
pub(super) fn check_tables(dir: &Path) {
    let md = std::fs::read_to_string(dir.join("table.md")).expect("table.md");
    assert!(md.contains("|---|"), "{md}");
    let csv = std::fs::read_to_string(dir.join("table.csv")).expect("table.csv");
    let mut lines = csv.lines();
    let cols = lines.next().expect("header").split(',').count();
    let mut rows = 0;
    for l in lines {
        assert_eq!(l.split(',').count(), cols, "{l}");
        rows += 1;
    }
    assert!(rows >= 2, "{csv}");
}

#[test]
fn opacities_are_found_in_attributes_and_styles() {
    let svg = r#"<svg width="317" height="238"><line opacity="1" fill-opacity="0.1"/><p style="opacity:0.5"/>"#;
    assert_eq!(opacities(svg), vec![1.0, 0.1, 0.5]);
    assert_eq!(svg_size(svg), (317, 238));
}

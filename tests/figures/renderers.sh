#!/usr/bin/env bash
# Do the renderers agree on the figures? For every <stem>.svg beside a <stem>.png (the 300-dpi PNG that
# plotters drew) in the folders given, renders the SVG at 300 dpi with rsvg-convert, with ImageMagick's own
# SVG reader and, if installed, with Chromium, and compares each rendering with the PNG: both are blurred
# and shrunk to 24 dpi (so antialiasing, hinting and the SVG's whole-pixel coordinates wash out) and the
# pixels that differ by more than 30 % of the range are counted. A missing axis title, a stray line, a lost
# series or another font changes well over 1 % of the pixels; the same drawing stays under it. Prints one line per figure and renderer, writes a
# side-by-side picture (PNG | rsvg | ImageMagick [| Chromium]) as <stem>.renderers.png into OUT, and exits 1
# if any rendering differs by more than the limit.
#
#   bash tests/figures/renderers.sh [--out DIR] [--limit PERCENT] FOLDER...
#
# Needs rsvg-convert and ImageMagick (Debian: `apt-get install librsvg2-bin imagemagick`); Chromium is
# optional. Not part of tests/run.sh: a check to run on freshly written figures, e.g.
# `bash tests/figures/renderers.sh results/stall-latest results/interaction-curve-latest`.
set -euo pipefail

out=""
limit="1"
folders=()
while [ $# -gt 0 ]; do
  case "$1" in
    --out) out="$2"; shift 2 ;;
    --limit) limit="$2"; shift 2 ;;
    -h | --help) sed -n '2,15p' "$0"; exit 0 ;;
    *) folders+=("$1"); shift ;;
  esac
done
[ "${#folders[@]}" -gt 0 ] || { echo "usage: $0 [--out DIR] [--limit PERCENT] FOLDER..." >&2; exit 2; }

if command -v magick >/dev/null 2>&1; then
  IM=(magick); ID=(magick identify); CMP=(magick compare)
else
  IM=(convert); ID=(identify); CMP=(compare)
fi
command -v "${IM[0]}" >/dev/null 2>&1 || { echo "ImageMagick is not installed (apt-get install imagemagick)" >&2; exit 2; }
command -v rsvg-convert >/dev/null 2>&1 || { echo "rsvg-convert is not installed (apt-get install librsvg2-bin)" >&2; exit 2; }
CHROMIUM=""
for c in chromium chromium-browser; do
  if command -v "$c" >/dev/null 2>&1; then CHROMIUM="$c"; break; fi
done

tmp="$(mktemp -d)"
trap 'rm -rf "$tmp"' EXIT
[ -n "$out" ] && mkdir -p "$out"

# The percentage of pixels that differ by more than 25 % between $1 and $2 at 75 dpi.
differ() {
  local w h
  read -r w h < <("${ID[@]}" -format '%w %h\n' "$1")
  "${IM[@]}" "$1" -background white -flatten -blur 0x2 -resize 8% "$tmp/a.png"
  "${IM[@]}" "$2" -background white -flatten -resize "${w}x${h}!" -blur 0x2 -resize 8% "$tmp/b.png"
  local ae total
  ae="$("${CMP[@]}" -metric AE -fuzz 30% "$tmp/a.png" "$tmp/b.png" null: 2>&1 || true)"
  read -r total < <("${ID[@]}" -format '%[fx:w*h]\n' "$tmp/a.png")
  awk -v ae="${ae%% *}" -v t="$total" 'BEGIN { printf "%.3f", 100 * ae / t }'
}

fail=0
for folder in "${folders[@]}"; do
  for svg in "$folder"/*.svg; do
    [ -e "$svg" ] || continue
    stem="$(basename "$svg" .svg)"
    png="$folder/$stem.png"
    [ -e "$png" ] || { echo "$stem: no $stem.png beside the SVG"; fail=1; continue; }
    read -r w h < <("${ID[@]}" -format '%w %h\n' "$png")
    rsvg-convert --width "$w" --height "$h" --background-color white "$svg" -o "$tmp/rsvg.png"
    "${IM[@]}" -density 300 -background white "MSVG:$svg" -flatten -resize "${w}x${h}!" "$tmp/im.png"
    shots=("$png" "$tmp/rsvg.png" "$tmp/im.png")
    names=(rsvg imagemagick)
    if [ -n "$CHROMIUM" ]; then
      # The SVG at its CSS size, scaled by the device pixel ratio to the PNG's width.
      sw="$(sed -n 's/^<svg width="\([0-9]*\)".*/\1/p' "$svg" | head -n 1)"
      sh="$(sed -n 's/^<svg width="[0-9]*" height="\([0-9]*\)".*/\1/p' "$svg" | head -n 1)"
      scale="$(awk -v a="$w" -v b="$sw" 'BEGIN { printf "%.4f", a / b }')"
      "$CHROMIUM" --headless=new --no-sandbox --disable-gpu --hide-scrollbars \
        --force-device-scale-factor="$scale" --window-size="$sw,$sh" \
        --screenshot="$tmp/chromium.png" "file://$(realpath "$svg")" >/dev/null 2>&1 || true
      if [ -s "$tmp/chromium.png" ]; then
        shots+=("$tmp/chromium.png")
        names+=(chromium)
      fi
    fi
    line="$stem:"
    for i in "${!names[@]}"; do
      pct="$(differ "$png" "${shots[$((i + 1))]}")"
      line="$line ${names[$i]} ${pct} %"
      if awk -v p="$pct" -v l="$limit" 'BEGIN { exit !(p > l) }'; then
        line="$line (over $limit %)"
        fail=1
      fi
    done
    echo "$line"
    if [ -n "$out" ]; then
      parts=()
      for i in "${!shots[@]}"; do
        "${IM[@]}" "${shots[$i]}" -background white -flatten -resize "${w}x${h}!" "$tmp/part$i.png"
        parts+=("$tmp/part$i.png")
      done
      "${IM[@]}" "${parts[@]}" +append -resize 50% "$out/$stem.renderers.png"
    fi
  done
done
exit "$fail"

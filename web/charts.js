// The dashboard's strip charts (uPlot): built from the timeline (timeline.js), with a window of 10 s to
// 10 min (the gesture experiment's elbow chart among them, once the ticks carry elbow angles), pause (the charts freeze while data keeps coming in), drag-to-zoom on time (all charts together,
// double-click to go back), a shared hover readout in each chart's legend, dashed vertical markers with a
// short label where an event took effect (laid out so that none overlaps; their legend and hover text say
// what each kind means), and gaps where ticks are missing or the robot link was down. Every time chart of
// the page (the learning view's too) has the same y-axis width, so their plot areas share one left edge.

import {
  MARKER_KINDS, columns, layoutMarkerLabels, markerColor, markerKind, redrawIntervalMs, sensorsLive,
} from './lib.js';
import { COMMAND_DEG, ELBOW_SERIES } from './elbow.js';

const CHART_HEIGHT = 175;
const COLORS = ['#2563eb', '#d97706', '#059669', '#7c3aed', '#db2777', '#0891b2'];
/** The lanes of the Events chart (legend and hover); the axis shows them shorter (`LANE_TICKS`). */
const EVENT_LANES = ['over-current R', 'over-current L', 'e-stop', 'gate', 'stimulus'];
const LANE_TICKS = ['OC right', 'OC left', 'e-stop', 'gate', 'stimulus'];
/** Every chart's cursor moves together (the strip charts, the elbow chart and the learning view's). */
export const SYNC_KEY = 'pavlov';
/**
 * The width of every time chart's y axis, px (its numbers and its title): the same for all, so one instant
 * is at the same x in every chart of the page, their plot areas starting at the same left edge.
 */
export const Y_AXIS_SIZE = 64;
const AXIS_FONT = '11px system-ui, sans-serif';
/** Rows of marker labels at the top of a chart. */
const LABEL_ROWS = 3;
const LABEL_ROW_PX = 15;

/** A uPlot axis in the page's style; `size` is `Y_AXIS_SIZE` unless `extra` says otherwise. */
export function axis(label, extra = {}) {
  return {
    label, labelSize: 16, size: Y_AXIS_SIZE, stroke: '#5b6474', font: AXIS_FONT,
    labelFont: AXIS_FONT, grid: { stroke: '#eef1f5', width: 1 }, ticks: { stroke: '#d9dee7' }, ...extra,
  };
}

/** The x axis of every time chart: seconds of run time. */
export const timeAxis = () => axis('', { size: 28, values: (u, v) => v.map((s) => `${s}s`) });

let measureCtx = null;
/** A label's width in CSS pixels, in the labels' font, with its padding. */
function labelWidth(text) {
  if (!measureCtx) {
    measureCtx = document.createElement('canvas').getContext('2d');
    measureCtx.font = AXIS_FONT;
  }
  return Math.ceil(measureCtx.measureText(text).width) + 8;
}

/**
 * A marker label's hover text: its text and when, the markers it stands for (when several), and what each
 * of their kinds means with its usual cause.
 */
function labelTitle(p) {
  const ts = p.items.map((m) => m.t);
  const when = ts.length > 1 ? `${ts.length} markers, ${ts[0].toFixed(2)}–${ts[ts.length - 1].toFixed(2)} s`
    : `at ${ts[0].toFixed(2)} s`;
  const counts = new Map();
  for (const m of p.items) counts.set(m.label, (counts.get(m.label) || 0) + 1);
  const lines = [`${p.text} (${when})`];
  if (counts.size > 1) lines.push([...counts].map(([label, n]) => (n > 1 ? `${label} ×${n}` : label)).join(', '));
  const kinds = [...new Set(p.items.map((m) => markerKind(m.kind)))];
  for (const k of kinds) lines.push(k.explain);
  return lines.join('\n');
}

/**
 * A uPlot plugin drawing a dashed vertical line at each event marker inside the x range and, when `labels`,
 * their labels at the top as elements over the plot (with hover text saying what the kind means), laid out
 * by `layoutMarkerLabels`: markers a few pixels apart share a label (`×n`, `+k`), up to three rows, none overlapping; those
 * left out are counted in the chart's `hiddenLabels` (and said in `moreEl`). Every marker drawn is kept on
 * the chart object (`drawnMarkers`), for the tests.
 */
function markersPlugin(chart, markers, labels, moreEl) {
  let layer = null;
  const draw = (u) => {
    const { left, top, width, height } = u.bbox;
    const { min, max } = u.scales.x;
    const dpr = window.devicePixelRatio || 1;
    const ctx = u.ctx;
    const drawn = [];
    const items = [];
    ctx.save();
    ctx.beginPath();
    ctx.rect(left, top, width, height);
    ctx.clip();
    for (const m of markers()) {
      if (min == null || m.t < min || m.t > max) continue;
      const x = Math.round(u.valToPos(m.t, 'x', true)) + 0.5;
      ctx.strokeStyle = markerColor(m.kind);
      ctx.lineWidth = Math.max(1, dpr);
      ctx.setLineDash([4 * dpr, 3 * dpr]);
      ctx.beginPath();
      ctx.moveTo(x, top);
      ctx.lineTo(x, top + height);
      ctx.stroke();
      drawn.push(m.label);
      items.push({
        x: u.valToPos(m.t, 'x'), label: m.label, kind: m.kind, t: m.t,
      });
    }
    ctx.restore();
    chart.drawnMarkers = drawn;
    if (!labels) return;
    if (!layer) {
      layer = document.createElement('div');
      layer.className = 'marker-labels';
      u.over.append(layer);
    }
    const { placed, hidden } = layoutMarkerLabels(items, labelWidth, { rows: LABEL_ROWS, plotWidth: u.over.clientWidth });
    while (layer.children.length > placed.length) layer.lastChild.remove();
    while (layer.children.length < placed.length) layer.append(document.createElement('span'));
    placed.forEach((p, i) => {
      const el = layer.children[i];
      el.className = 'marker-label';
      el.textContent = p.text;
      el.title = labelTitle(p);
      el.dataset.kind = markerKind(p.items[0].kind).key;
      el.style.left = `${p.left}px`;
      el.style.top = `${2 + p.row * LABEL_ROW_PX}px`;
      el.style.width = `${p.width}px`;
      el.style.color = markerColor(p.items[0].kind);
    });
    chart.hiddenLabels = hidden;
    if (moreEl) {
      moreEl.hidden = hidden === 0;
      moreEl.textContent = `${hidden} marker label${hidden === 1 ? '' : 's'} left out here: zoom in (drag) to read them`;
    }
  };
  return { hooks: { draw: [draw] } };
}

/** Fills `el` with the legend of the marker kinds, each with its meaning and usual cause on hover. */
export function renderMarkerLegend(el) {
  el.replaceChildren(...MARKER_KINDS.map((k) => {
    const item = document.createElement('span');
    item.className = 'marker-key';
    item.dataset.kind = k.key;
    item.title = k.explain;
    const swatch = document.createElement('i');
    swatch.style.borderColor = k.color;
    item.append(swatch, k.name);
    return item;
  }));
}

const fmtReadout = (digits) => (u, v) => (v == null ? '—' : Number(v).toFixed(digits));
const laneReadout = (u, v) => (v == null ? '—' : (v % 1 > 0.5 ? 'on' : 'off'));

/**
 * The charts of the page: `view` holds the window, pause and zoom; `timeline` the data; `periodS` the tick
 * period; `onView` is called whenever the view changes (to update the toolbar).
 */
export class Charts {
  constructor(timeline, onView) {
    this.timeline = timeline;
    this.onView = onView;
    this.list = [];
    this.periodS = 0.02;
    this.predictionNames = [];
    this.view = { seconds: 30, paused: false, pausedBy: null, to: null, zoom: null };
    this.lastDraw = 0;
    this.dirty = false;
  }

  /** (Re)builds the four charts for `predictionNames`. */
  build(predictionNames, periodS) {
    for (const c of this.list) c.u.destroy();
    this.list = [];
    this.predictionNames = predictionNames;
    this.periodS = periodS;
    if (typeof window.uPlot !== 'function') return;
    const live = (f) => (s) => (sensorsLive(s) ? f(s) : null);
    const predSeries = [];
    const predValues = [];
    predictionNames.forEach((name, i) => {
      const color = COLORS[i % COLORS.length];
      predSeries.push({ label: name, stroke: color, width: 2, value: fmtReadout(3) });
      predSeries.push({ label: `θ ${name}`, stroke: color, width: 1, dash: [6, 4], value: fmtReadout(3) });
      predValues.push(live((s) => (s.preds[i] ? s.preds[i][0] : null)), (s) => (s.preds[i] ? s.preds[i][1] : null));
    });
    const lane = (i, color) => ({
      label: EVENT_LANES[i], stroke: color, width: 1.5, fill: `${color}40`, fillTo: () => i,
      paths: window.uPlot.paths.stepped({ align: 1 }), value: laneReadout,
    });
    const flag = (lane, on) => lane + (on ? 0.8 : 0);
    const specs = [
      {
        id: 'chart-pred', labels: true, more: 'markers-more', series: predSeries, values: predValues,
        y: { range: (u, lo, hi) => [Math.min(0, lo ?? 0), Math.max(1, hi ?? 1)] },
      },
      {
        id: 'chart-events',
        series: [lane(0, '#ea580c'), lane(1, '#f59e0b'), lane(2, '#111827'), lane(3, '#2563eb'), lane(4, '#dc2626')],
        values: [live((s) => flag(0, s.ocR)), live((s) => flag(1, s.ocL)), (s) => flag(2, s.estop), (s) => flag(3, s.gate), (s) => flag(4, s.stimulus)],
        y: { range: [-0.2, EVENT_LANES.length] },
        axis: { splits: () => LANE_TICKS.map((_, i) => i + 0.4), values: () => LANE_TICKS, grid: { show: false } },
      },
      {
        id: 'chart-current',
        series: [{ label: 'battery current', stroke: '#0891b2', width: 1.5, fill: '#0891b21a', value: fmtReadout(0) }],
        values: [live((s) => s.current)],
        y: { range: (u, lo, hi) => [Math.min(-500, Math.floor(((lo ?? 0) * 1.1) / 100) * 100), Math.max(0, hi ?? 0)] },
        axis: { label: 'mA' },
      },
      {
        id: 'chart-wheels',
        series: [
          { label: 'left', stroke: '#2563eb', width: 2, value: fmtReadout(0) },
          { label: 'right', stroke: '#d97706', width: 2, value: fmtReadout(0) },
          { label: 'π left', stroke: '#93c5fd', width: 1, dash: [5, 4], value: fmtReadout(0) },
          { label: 'π right', stroke: '#fcd34d', width: 1, dash: [5, 4], value: fmtReadout(0) },
        ],
        values: [(s) => s.cmdL, (s) => s.cmdR, (s) => s.defL, (s) => s.defR],
        y: { range: (u, lo, hi) => [Math.min(-100, lo ?? 0), Math.max(100, hi ?? 0)] },
        axis: { label: 'mm/s' },
      },
    ];
    for (const spec of specs) this.list.push(this.make(spec));
    this.dirty = true;
  }

  /** The gesture experiment's elbow chart: both angles, their moving averages μ and the 90° line. */
  elbowSpec() {
    const angle = (k) => (s) => (s.elbow ? s.elbow[k] : null);
    return {
      id: 'chart-elbow',
      series: ELBOW_SERIES.map((e) => ({ ...e, value: fmtReadout(1) })),
      values: [angle(0), angle(1), angle(2), angle(3), (s) => (s.elbow ? COMMAND_DEG : null)],
      y: { range: [0, 180] },
      axis: { label: '°', splits: () => [0, 45, 90, 135, 180] },
    };
  }

  /** Adds the elbow chart (once a tick or the history carries elbow angles); returns it. */
  addElbow() {
    let chart = this.list.find((c) => c.el.id === 'chart-elbow');
    if (!chart && typeof window.uPlot === 'function' && this.list.length) {
      chart = this.make(this.elbowSpec());
      this.list.push(chart);
      this.draw(true);
    }
    return chart || null;
  }

  make(spec) {
    const el = document.getElementById(spec.id);
    const chart = {
      el, values: spec.values, drawnMarkers: [], hiddenLabels: 0,
    };
    const markers = () => this.timeline.events.filter((e) => e.label);
    const opts = {
      width: Math.max(300, Math.floor(el.getBoundingClientRect().width)),
      height: CHART_HEIGHT,
      cursor: {
        sync: { key: SYNC_KEY, setSeries: false },
        drag: { x: true, y: false, setScale: false },
        bind: { dblclick: () => null },
      },
      legend: { live: true },
      scales: { x: { time: false }, y: spec.y },
      axes: [timeAxis(), axis(spec.axis?.label || '', spec.axis || {})],
      series: [{ label: 't', value: (u, v) => (v == null ? '—' : `${v.toFixed(2)} s`) }, ...spec.series],
      plugins: [markersPlugin(chart, markers, !!spec.labels, spec.more ? document.getElementById(spec.more) : null)],
      hooks: { setSelect: [(u) => this.zoomTo(u)] },
    };
    chart.u = new window.uPlot(opts, [[], ...spec.values.map(() => [])], el);
    chart.u.over.addEventListener('dblclick', () => this.resetZoom());
    return chart;
  }

  /** A drag on a chart: every chart shows the selected time span, and the view pauses. */
  zoomTo(u) {
    const { left, width } = u.select;
    if (width < 3) return;
    const min = u.posToVal(left, 'x');
    const max = u.posToVal(left + width, 'x');
    u.setSelect({ left: 0, width: 0, top: 0, height: 0 }, false);
    if (!this.view.paused) this.pause('zoom');
    this.view.zoom = { min, max };
    for (const c of this.list) c.u.setScale('x', { min, max });
    this.onView();
  }

  /** Double-click: back to the whole window; a pause the zoom made ends with it. */
  resetZoom() {
    if (!this.view.zoom) return;
    this.view.zoom = null;
    if (this.view.pausedBy === 'zoom') this.resume();
    else this.draw(true);
    this.onView();
  }

  pause(by = 'user') {
    if (this.view.paused) return;
    const last = this.timeline.last;
    this.view.paused = true;
    this.view.pausedBy = by;
    this.view.to = last ? last.t : 0;
    this.onView();
  }

  resume() {
    this.view.paused = false;
    this.view.pausedBy = null;
    this.view.zoom = null;
    this.draw(true);
    this.onView();
  }

  setWindow(seconds) {
    this.view.seconds = seconds;
    this.view.zoom = null;
    this.draw(true);
    this.onView();
  }

  /**
   * The time span on screen: the zoom, or the window ending now (or where it was paused); in the run's
   * first seconds, the window from the start.
   */
  visible() {
    if (this.view.zoom) return { ...this.view.zoom };
    const last = this.timeline.last;
    const to = this.view.paused ? this.view.to : (last ? last.t : 0);
    const min = Math.max(0, to - this.view.seconds);
    return { min, max: min + this.view.seconds };
  }

  /**
   * Redraws from the timeline: while live, as often as the window warrants; `force` for a change of view
   * (also while paused: a new window shows the time before the pause).
   */
  draw(force = false) {
    if (!force && (this.view.paused || !this.dirty)) return;
    const now = performance.now();
    if (!force && now - this.lastDraw < redrawIntervalMs(this.view.seconds)) return;
    this.lastDraw = now;
    this.dirty = false;
    const { min, max } = this.visible();
    const samples = this.timeline.between(min, max);
    for (const c of this.list) {
      c.u.batch(() => {
        c.u.setData(columns(samples, c.values, this.periodS));
        c.u.setScale('x', { min, max });
      });
    }
  }

  /** New data arrived. */
  touch() {
    this.dirty = true;
  }

  resize() {
    for (const c of this.list) {
      const r = c.el.getBoundingClientRect();
      c.u.setSize({ width: Math.max(300, Math.floor(r.width)), height: CHART_HEIGHT });
    }
  }
}

// ---------------------------------------------------------------- aligned averages

const ALIGNED_HEIGHT = 160;
const REACTIVE_COLOR = '#d97706';
const PAVLOVIAN_COLOR = '#2563eb';

function makeAlignedChart(el, label, yRange) {
  const rect = el.getBoundingClientRect();
  const opts = {
    width: Math.max(200, Math.floor(rect.width)),
    height: ALIGNED_HEIGHT,
    cursor: { drag: { x: false, y: false } },
    legend: { live: false },
    scales: { x: { time: false }, y: { range: yRange } },
    axes: [axis('', { size: 28, values: (u, v) => v.map((s) => `${s}s`) }), axis(label)],
    series: [
      { label: 'offset' },
      { label: 'reactive', stroke: REACTIVE_COLOR, width: 2, spanGaps: false },
      { label: 'Pavlovian', stroke: PAVLOVIAN_COLOR, width: 2, spanGaps: false },
    ],
  };
  return new window.uPlot(opts, [[], [], []], el);
}

/**
 * The aligned averages (paper, Figure 4): two small charts drawn from `status.interaction.aligned` (as
 * `alignedData` gives them), replaced whole about once a second; hidden when the run has no interaction
 * metrics.
 */
export class AlignedCharts {
  constructor() {
    this.charts = null;
  }

  hide() {
    document.getElementById('aligned-card').hidden = true;
    if (this.charts) {
      this.charts.current.destroy();
      this.charts.rotation.destroy();
      this.charts = null;
    }
  }

  show(data) {
    if (!data) return;
    document.getElementById('aligned-card').hidden = false;
    document.getElementById('aligned-hint').textContent = 'mean per tick, 0 s = stimulus onset · '
      + `reactive (orange): ${data.counts.reactive} · Pavlovian (blue): ${data.counts.pavlovian} commands`;
    if (typeof window.uPlot !== 'function') return;
    if (!this.charts) {
      this.charts = {
        current: makeAlignedChart(document.getElementById('chart-aligned-current'), 'current mA',
          (u, lo, hi) => [Math.min(-500, Math.floor(((lo ?? 0) * 1.1) / 100) * 100), Math.max(0, hi ?? 0)]),
        rotation: makeAlignedChart(document.getElementById('chart-aligned-rotation'), 'rotation °/tick',
          (u, lo, hi) => [Math.min(-1, lo ?? 0), Math.max(1, Math.ceil((hi ?? 0) * 1.1))]),
      };
    }
    this.charts.current.setData(data.current);
    this.charts.rotation.setData(data.rotation);
  }

  resize() {
    if (!this.charts) return;
    for (const [u, id] of [[this.charts.current, 'chart-aligned-current'], [this.charts.rotation, 'chart-aligned-rotation']]) {
      const width = Math.floor(document.getElementById(id).getBoundingClientRect().width);
      u.setSize({ width: Math.max(200, width), height: ALIGNED_HEIGHT });
    }
  }
}

// The dashboard's strip charts (uPlot): built from the timeline (timeline.js), with a window of 10 s to
// 10 min, pause (the charts freeze while data keeps coming in), drag-to-zoom on time (all charts together,
// double-click to go back), a shared hover readout in each chart's legend, dashed vertical markers with a
// short label where an event took effect, and gaps where ticks are missing or the robot link was down.

import {
  columns, markerColor, redrawIntervalMs, sensorsLive,
} from './lib.js';

const CHART_HEIGHT = 175;
const COLORS = ['#2563eb', '#d97706', '#059669', '#7c3aed', '#db2777', '#0891b2'];
const EVENT_LANES = ['over-current R', 'over-current L', 'e-stop', 'gate', 'stimulus'];
const SYNC_KEY = 'pavlov';

function axis(label, extra = {}) {
  return {
    label, labelSize: 16, size: 52, stroke: '#5b6474', font: '11px system-ui, sans-serif',
    labelFont: '11px system-ui, sans-serif', grid: { stroke: '#eef1f5', width: 1 }, ticks: { stroke: '#d9dee7' }, ...extra,
  };
}

/**
 * A uPlot plugin drawing a dashed vertical line at each event marker inside the x range, with its label at
 * the top when `labels` (labels that would overlap go one row down, up to three rows). The labels drawn
 * last are kept on the chart object (`drawnMarkers`), for the tests.
 */
function markersPlugin(chart, markers, labels) {
  const draw = (u) => {
    const { left, top, width, height } = u.bbox;
    const { min, max } = u.scales.x;
    const dpr = window.devicePixelRatio || 1;
    const ctx = u.ctx;
    const rows = [-Infinity, -Infinity, -Infinity];
    const drawn = [];
    ctx.save();
    ctx.beginPath();
    ctx.rect(left, top, width, height);
    ctx.clip();
    ctx.font = `${Math.round(11 * dpr)}px system-ui, sans-serif`;
    ctx.textBaseline = 'top';
    ctx.textAlign = 'left';
    for (const m of markers()) {
      if (min == null || m.t < min || m.t > max) continue;
      const x = Math.round(u.valToPos(m.t, 'x', true)) + 0.5;
      const color = markerColor(m.kind);
      ctx.strokeStyle = color;
      ctx.lineWidth = Math.max(1, dpr);
      ctx.setLineDash([4 * dpr, 3 * dpr]);
      ctx.beginPath();
      ctx.moveTo(x, top);
      ctx.lineTo(x, top + height);
      ctx.stroke();
      drawn.push(m.label);
      if (!labels) continue;
      const w = ctx.measureText(m.label).width + 6 * dpr;
      const row = rows.findIndex((right) => right < x);
      if (row < 0) continue;
      const y = top + 2 * dpr + row * 14 * dpr;
      ctx.fillStyle = 'rgba(255,255,255,0.85)';
      ctx.fillRect(x + 2 * dpr, y, w, 13 * dpr);
      ctx.fillStyle = color;
      ctx.fillText(m.label, x + 5 * dpr, y + 1 * dpr);
      rows[row] = x + w + 4 * dpr;
    }
    ctx.restore();
    chart.drawnMarkers = drawn;
  };
  return { hooks: { draw: [draw] } };
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
        id: 'chart-pred', labels: true, series: predSeries, values: predValues,
        y: { range: (u, lo, hi) => [Math.min(0, lo ?? 0), Math.max(1, hi ?? 1)] },
      },
      {
        id: 'chart-events',
        series: [lane(0, '#ea580c'), lane(1, '#f59e0b'), lane(2, '#111827'), lane(3, '#2563eb'), lane(4, '#dc2626')],
        values: [live((s) => flag(0, s.ocR)), live((s) => flag(1, s.ocL)), (s) => flag(2, s.estop), (s) => flag(3, s.gate), (s) => flag(4, s.stimulus)],
        y: { range: [-0.2, EVENT_LANES.length] },
        axis: { size: 96, splits: () => EVENT_LANES.map((_, i) => i + 0.4), values: () => EVENT_LANES, grid: { show: false } },
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

  make(spec) {
    const el = document.getElementById(spec.id);
    const chart = { el, values: spec.values, drawnMarkers: [] };
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
      axes: [axis('', { size: 28, values: (u, v) => v.map((s) => `${s}s`) }), axis(spec.axis?.label || '', spec.axis || {})],
      series: [{ label: 't', value: (u, v) => (v == null ? '—' : `${v.toFixed(2)} s`) }, ...spec.series],
      plugins: [markersPlugin(chart, markers, !!spec.labels)],
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

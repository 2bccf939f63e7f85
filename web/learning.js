// The learning view (what RLPark's Zephyr showed): for a chosen control prediction, its value against the
// realised return it was predicting (the return drawn at the value's tick, so it arrives a horizon late),
// its TD error δ and running error, and the parameters in force, over the same time span as the strip
// charts (the window selector, pause and zoom; the values from the server's history, δ and the returns from
// its recent `learning` messages); and the Horde: a grid of every prediction's
// current value (a canvas, one cell a prediction), hover for name and value, click to chart it over time.
// The figures come from the server (`learning`, `horde_names`, `horde_values`; see PROTOCOL.md); the pure
// parts are in learnlib.js.

import {
  HordeSeries, LearningStore, OwnRanges, cellAt, colourOf, colourRange, decodeHordeValues, gridLayout, hordeName, sig,
} from './learnlib.js';
import { WINDOWS, fmt, fmtParam, redrawIntervalMs } from './lib.js';
import { SYNC_KEY, axis, timeAxis } from './charts.js';

/** Seconds of learning figures kept: the page's widest window (the charts show the window selected). */
const LEARN_SECONDS = Math.max(...WINDOWS.map((w) => w.seconds));
/** The Horde's values a second the page asks for. */
export const HORDE_HZ = 5;
const COLORS = ['#2563eb', '#d97706', '#059669', '#7c3aed', '#db2777', '#0891b2'];

function readout(digits) {
  return (u, v) => (v == null ? '—' : fmt(v, digits));
}

function chartWidth(el) {
  return Math.max(300, Math.floor(el.getBoundingClientRect().width));
}

/**
 * A small uPlot chart over run time in seconds, with the strip charts' axes (the same y-axis width, so
 * the plot areas line up) and their shared cursor.
 */
function timeChart(el, yLabel, series, height = 170) {
  if (typeof window.uPlot !== 'function') return null;
  return new window.uPlot({
    width: chartWidth(el),
    height,
    scales: { x: { time: false } },
    axes: [timeAxis(), axis(yLabel)],
    legend: { live: true },
    cursor: { drag: { x: false, y: false }, sync: { key: SYNC_KEY, setSeries: false } },
    series: [{ label: 't', value: readout(2) }, ...series],
  }, [[], ...series.map(() => [])], el);
}

/** The learning panel of the control predictions. */
export class LearningView {
  constructor(els) {
    this.els = els;
    this.store = new LearningStore();
    this.periodS = 0.02;
    this.selected = null;
    this.params = {};
    this.charts = null;
    this.dirty = false;
    this.span = null;
    this.lastDraw = 0;
    els.pick.addEventListener('change', () => {
      this.selected = els.pick.value;
      this.dirty = true;
    });
  }

  /** A new connection: the predictions it announces, the tick period. */
  configure(hello) {
    this.periodS = hello.tick_period_ms / 1000;
    this.store = new LearningStore(Math.round(LEARN_SECONDS / this.periodS));
    const names = hello.signals.predictions || [];
    this.els.pick.replaceChildren(...names.map((n) => {
      const o = document.createElement('option');
      o.value = n;
      o.textContent = n;
      return o;
    }));
    this.selected = hello.signals.gate_prediction && names.includes(hello.signals.gate_prediction)
      ? hello.signals.gate_prediction : names[0] || null;
    if (this.selected) this.els.pick.value = this.selected;
    this.els.empty.hidden = names.length > 0;
    if (!this.charts) {
      this.charts = {
        ret: timeChart(this.els.returnChart, 'value / return', [
          { label: 'value v', stroke: '#2563eb', width: 2, value: readout(3) },
          // Spanning gaps: a message may carry every k-th return only (`thinned`).
          {
            label: 'realised return G', stroke: '#d97706', width: 2, dash: [6, 3], spanGaps: true, value: readout(3),
          },
        ]),
        td: timeChart(this.els.tdChart, 'δ / error', [
          { label: 'TD error δ', stroke: '#7c3aed', width: 1, value: readout(4) },
          { label: 'running RMSE', stroke: '#dc2626', width: 2, spanGaps: true, value: readout(4) },
        ], 150),
      };
    }
    this.dirty = true;
  }

  /** A tick: the values of the predictions. */
  tick(t) {
    for (const p of Array.isArray(t.predictions) ? t.predictions : []) this.store.addValue(p.name, t.seq, p.value);
  }

  /** Samples of the `history` (timeline.js): the predictions' values, in the order of `names`. */
  history(samples, names) {
    for (const sample of samples) {
      names.forEach((name, i) => {
        const p = sample.preds[i];
        if (p) this.store.addValue(name, sample.seq, p[0]);
      });
    }
    for (const e of this.store.byName.values()) this.store.prune(e);
    this.dirty = true;
  }

  /** A `learning` message. */
  message(msg) {
    this.store.addMessage(msg);
    this.dirty = true;
  }

  /** The parameters in force (α, λ, θ by prediction, from hello and `params_set`). */
  setParams(params) {
    this.params = params || {};
    this.dirty = true;
  }

  /**
   * Redraws for the time span the strip charts show (`span`: `{ min, max }` in seconds, from the window
   * selector, the pause or the zoom), as often as that window warrants.
   */
  render(span) {
    if (!this.selected) return;
    const moved = span && (!this.span || span.min !== this.span.min || span.max !== this.span.max);
    if (!this.dirty && !moved) return;
    const now = performance.now();
    if (span && now - this.lastDraw < redrawIntervalMs(span.max - span.min)) return;
    this.lastDraw = now;
    this.span = span ? { ...span } : null;
    this.dirty = false;
    const name = this.selected;
    const info = this.store.info(name);
    const p = this.params[name] || {};
    const parts = [
      `α ${fmtParam(p.alpha)}`,
      `λ ${fmtParam(p.lambda)}`,
      `θ ${fmtParam(p.threshold)}`,
      `τ ${info ? fmt(info.tau, 1) : '—'}`,
      `learner ${info && info.learner ? info.learner : '—'}`,
    ];
    this.els.params.textContent = parts.join(' · ');
    const e = info ? info.error : {};
    const f = (v, d) => (typeof v === 'number' ? fmt(v, d) : '—');
    this.els.rmse.textContent = f(e.rmse, 4);
    this.els.mae.textContent = f(e.mean_abs, 4);
    this.els.bias.textContent = f(e.bias, 4);
    this.els.pairs.textContent = e.pairs != null ? String(e.pairs) : '—';
    this.els.horizon.textContent = info
      ? `${info.horizon} ticks (${fmt(info.horizon * this.periodS, 2)} s; truncation ≤ ${fmt(info.tailBound, 3)})` : '—';
    const s = this.store.series(name, this.periodS, span ? span.min : -Infinity, span ? span.max : Infinity);
    let lastTd = null;
    for (let i = s.td.length - 1; i >= 0 && lastTd === null; i -= 1) lastTd = s.td[i];
    this.els.td.textContent = lastTd === null ? '—' : fmt(lastTd, 4);
    const show = (u, data) => {
      if (!u) return;
      u.batch(() => {
        u.setData(data);
        if (span) u.setScale('x', { min: span.min, max: span.max });
      });
    };
    if (this.charts) {
      show(this.charts.ret, [s.t, s.value, s.ret]);
      show(this.charts.td, [s.t, s.td, s.rmse]);
    }
  }
}

/** The Horde panel: the grid of current values and the chart of the predictions clicked. */
export class HordeView {
  constructor(els, send) {
    this.els = els;
    this.send = send;
    this.total = 0;
    this.names = [];
    this.values = null;
    this.from = 0;
    this.seq = null;
    this.periodS = 0.02;
    this.layout = null;
    this.series = new HordeSeries();
    this.chart = null;
    this.dirty = false;
    this.figures = null;
    this.hover = -1;
    this.messages = 0;
    this.ranges = new OwnRanges();
    this.colourBy = els.colourBy.value;
    els.colourBy.addEventListener('change', () => {
      this.colourBy = els.colourBy.value;
      this.dirty = true;
    });
    els.grid.addEventListener('mousemove', (ev) => this.onHover(ev));
    els.grid.addEventListener('mouseleave', () => {
      this.hover = -1;
      this.showHover();
    });
    els.grid.addEventListener('click', (ev) => this.onClick(ev));
  }

  /** A new connection: watch the Horde if there is one. */
  configure(hello) {
    this.periodS = hello.tick_period_ms / 1000;
    this.total = hello.signals.horde_predictions || 0;
    this.names = new Array(this.total).fill('');
    this.values = null;
    this.seq = null;
    this.series.clear();
    this.els.none.hidden = this.total > 0;
    this.els.body.hidden = this.total === 0;
    if (this.total > 0) {
      this.send('horde_watch', { hz: HORDE_HZ });
      if (!this.chart && typeof window.uPlot === 'function') {
        this.chart = timeChart(this.els.chart, 'value', []);
      }
    }
    this.rebuildChart();
    this.dirty = true;
  }

  /** A `horde_names` message. */
  onNames(msg) {
    if (!Array.isArray(msg.names) || !Number.isInteger(msg.from)) return;
    msg.names.forEach((n, i) => {
      if (msg.from + i < this.names.length) this.names[msg.from + i] = n;
    });
  }

  /** A `horde_values` message. */
  onValues(msg) {
    let values;
    try {
      values = decodeHordeValues(msg);
    } catch (e) {
      return;
    }
    this.values = values;
    this.from = msg.from;
    this.seq = msg.seq;
    this.figures = msg.horde || null;
    this.messages += 1;
    this.ranges.update(msg.from, values);
    this.series.push(msg.seq * this.periodS, msg.from, values);
    this.dirty = true;
  }

  onHover(ev) {
    const r = this.els.grid.getBoundingClientRect();
    this.hover = cellAt(this.layout, ev.clientX - r.left, ev.clientY - r.top);
    this.showHover();
  }

  onClick(ev) {
    const r = this.els.grid.getBoundingClientRect();
    const i = cellAt(this.layout, ev.clientX - r.left, ev.clientY - r.top);
    if (i < 0) return;
    this.series.toggle(this.from + i);
    this.rebuildChart();
    this.dirty = true;
  }

  showHover() {
    if (this.hover < 0 || !this.values) {
      this.els.hover.textContent = 'hover a cell for its prediction · click to chart it (again to remove)';
      return;
    }
    const index = this.from + this.hover;
    const name = this.names[index] || `#${index}`;
    const parts = hordeName(name);
    const detail = parts.tau != null ? ` (cumulant ${parts.cumulant}, τ ${parts.tau})` : '';
    const own = `range seen ${sig(this.ranges.lo[this.hover])} … ${sig(this.ranges.hi[this.hover])}`;
    this.els.hover.textContent = `${name}${detail}: ${sig(this.values[this.hover])} (${own})`;
  }

  /** The chart's series follow the predictions picked. */
  rebuildChart() {
    if (!this.chart) return;
    while (this.chart.series.length > 1) this.chart.delSeries(1);
    this.series.picked.forEach((index, k) => {
      this.chart.addSeries({
        label: this.names[index] || `#${index}`, stroke: COLORS[k % COLORS.length], width: 2, value: (u, v) => (v == null ? '—' : sig(v)),
      }, k + 1);
    });
    this.els.chartCard.hidden = this.series.picked.length === 0;
    // Built while hidden (no width): sized to its card once shown.
    if (!this.els.chartCard.hidden) this.chart.setSize({ width: chartWidth(this.els.chartCard), height: this.chart.height });
    this.chart.setData([this.series.t, ...this.series.columns]);
  }

  render() {
    if (!this.dirty || this.total === 0) return;
    this.dirty = false;
    const n = this.values ? this.values.length : 0;
    const f = this.figures;
    this.els.info.textContent = `${this.total} predictions${n && n < this.total ? ` (showing ${this.from}–${this.from + n - 1})` : ''}`
      + (f ? ` · learned ${f.ticks_learned} ticks · skipped ${f.skipped_busy} · step p50 ${f.step_p50_us} µs, p99 ${f.step_p99_us} µs` : '')
      + (this.seq != null ? ` · values of tick ${this.seq}` : ' · waiting for values');
    if (!n) return;
    const width = Math.max(200, Math.floor(this.els.gridBox.getBoundingClientRect().width));
    this.layout = gridLayout(n, width);
    if (this.colourBy === 'own') {
      this.drawGrid((i) => colourOf(this.ranges.fraction(i, this.values[i]), 0, 1));
      this.els.scale.textContent = 'colour: each prediction against the range of its own values seen (dark: its lowest, yellow: its highest)';
    } else {
      const { lo, hi } = colourRange(this.values);
      this.drawGrid((i) => colourOf(this.values[i], lo, hi));
      this.els.scale.textContent = `colour: one scale for all, ${sig(lo)} … ${sig(hi)} (2nd–98th percentile)`;
    }
    this.showHover();
    if (this.chart && this.series.picked.length) this.chart.setData([this.series.t, ...this.series.columns]);
  }

  /** Draws the grid, cell `i` in `colourAt(i)`. */
  drawGrid(colourAt) {
    const { cols, rows, cell } = this.layout;
    const canvas = this.els.grid;
    const dpr = window.devicePixelRatio || 1;
    canvas.style.width = `${cols * cell}px`;
    canvas.style.height = `${rows * cell}px`;
    canvas.width = Math.round(cols * cell * dpr);
    canvas.height = Math.round(rows * cell * dpr);
    // One pixel a cell, then scaled up without smoothing: 10⁴ cells are one small image.
    const img = new ImageData(cols, rows);
    for (let i = 0; i < this.values.length; i += 1) {
      const [r, g, b] = colourAt(i);
      img.data.set([r, g, b, 255], i * 4);
    }
    const off = document.createElement('canvas');
    off.width = cols;
    off.height = rows;
    off.getContext('2d').putImageData(img, 0, 0);
    const ctx = canvas.getContext('2d');
    ctx.imageSmoothingEnabled = false;
    ctx.clearRect(0, 0, canvas.width, canvas.height);
    ctx.drawImage(off, 0, 0, canvas.width, canvas.height);
    // Cell borders when cells are big enough to see them, and a ring round the charted ones.
    const px = cell * dpr;
    if (cell >= 8) {
      ctx.strokeStyle = 'rgba(255,255,255,0.6)';
      ctx.lineWidth = 1;
      for (let c = 1; c < cols; c += 1) {
        ctx.beginPath();
        ctx.moveTo(c * px, 0);
        ctx.lineTo(c * px, rows * px);
        ctx.stroke();
      }
      for (let r = 1; r < rows; r += 1) {
        ctx.beginPath();
        ctx.moveTo(0, r * px);
        ctx.lineTo(cols * px, r * px);
        ctx.stroke();
      }
    }
    this.series.picked.forEach((index, k) => {
      const i = index - this.from;
      if (i < 0 || i >= this.values.length) return;
      ctx.strokeStyle = COLORS[k % COLORS.length];
      ctx.lineWidth = Math.max(2, dpr * 2);
      ctx.strokeRect((i % cols) * px + 1, Math.floor(i / cols) * px + 1, px - 2, px - 2);
    });
  }
}

// The gesture experiment's panel of the dashboard: a strip chart of both elbow angles with their moving
// averages μ and the 90° command line, the skeleton's status (tracked / stale / none) in the "Now" card, and a
// warning banner when no skeleton has been tracked for a while. Shown only when the ticks carry `elbow`
// (PROTOCOL.md: the left-elbow stimulus). app.js creates one ElbowPanel and feeds it every tick.
//
// The pure helpers (elbowRow, skeletonWarning) have no DOM and are unit-tested under Node.

/** The newest `capacity` rows of a few series, as uPlot's columns (x first). */
class RollingWindow {
  constructor(series, capacity) {
    this.capacity = capacity;
    this.columns = Array.from({ length: series + 1 }, () => []);
  }

  push(x, values) {
    this.columns[0].push(x);
    for (let i = 1; i < this.columns.length; i++) {
      const v = values[i - 1];
      this.columns[i].push(v === undefined || v === null || Number.isNaN(v) ? null : v);
    }
    // Trim in batches, so the copy happens once every `slack` rows rather than on every row.
    const slack = Math.max(1, Math.floor(this.capacity / 10));
    if (this.columns[0].length > this.capacity + slack) {
      const excess = this.columns[0].length - this.capacity;
      for (const c of this.columns) c.splice(0, excess);
    }
  }

  data() {
    const extra = this.columns[0].length - this.capacity;
    return extra <= 0 ? this.columns : this.columns.map((c) => c.slice(extra));
  }
}

/** The angle below which the left elbow is a command, degrees (the paper's 90°). */
export const COMMAND_DEG = 90;

/** How long the skeleton may be untracked before the banner warns, ms (a few dropped frames are normal). */
export const WARN_AFTER_MS = 1000;

const SERIES = [
  { label: 'left', stroke: '#2563eb', width: 2 },
  { label: 'left μ', stroke: '#93c5fd', width: 1.5, dash: [6, 4] },
  { label: 'right', stroke: '#d97706', width: 2 },
  { label: 'right μ', stroke: '#fcd34d', width: 1.5, dash: [6, 4] },
  { label: '90°', stroke: '#6b7280', width: 1 },
];

/** One chart row from a tick's `elbow`: left, left μ, right, right μ (degrees, null when invalid) and 90. */
export function elbowRow(elbow) {
  const v = (x) => (typeof x === 'number' && Number.isFinite(x) ? x : null);
  const e = elbow || {};
  return [v(e.left), v(e.left_avg), v(e.right), v(e.right_avg), COMMAND_DEG];
}

/**
 * The banner text when the skeleton has not been tracked for `untrackedMs` (null when tracked, or not for
 * long enough to worry about).
 */
export function skeletonWarning(status, untrackedMs) {
  if (status === 'tracked' || !(untrackedMs >= WARN_AFTER_MS)) return null;
  const seconds = (untrackedMs / 1000).toFixed(1);
  if (status === 'stale') {
    return `Skeleton stale for ${seconds} s: joints stopped arriving, so no elbow command can be seen.`;
  }
  return `No skeleton for ${seconds} s: nobody is tracked, so no elbow command can be seen. Check the depth `
    + 'sensor and its OSC stream (config [skeleton]).';
}

/** The panel: give it the page's elements; configure on hello, push every tick, render once a frame. */
export class ElbowPanel {
  constructor({ card, chart, status, banner, windowSeconds = 30, height = 175 }) {
    this.card = card;
    this.chartEl = chart;
    this.statusEl = status;
    this.banner = banner;
    this.windowSeconds = windowSeconds;
    this.height = height;
    this.u = null;
    this.win = null;
    this.periodMs = 20;
    this.lastStatus = null;
    this.untrackedSinceS = null;
    this.lastT = 0;
    this.dirty = false;
  }

  /** A new connection: forget the old data; the card shows once a tick carries `elbow`. */
  configure(hello) {
    this.periodMs = (hello && hello.tick_period_ms) || 20;
    this.win = new RollingWindow(SERIES.length, Math.round((this.windowSeconds * 1000) / this.periodMs));
    if (this.u) {
      this.u.destroy();
      this.u = null;
    }
    this.card.hidden = true;
    this.banner.hidden = true;
    this.lastStatus = null;
    this.untrackedSinceS = null;
  }

  push(t) {
    if (!t.elbow || !this.win) return;
    this.win.push(t.t, elbowRow(t.elbow));
    const status = t.elbow.skeleton || 'none';
    if (status === 'tracked') this.untrackedSinceS = null;
    else if (this.untrackedSinceS === null) this.untrackedSinceS = t.t;
    this.lastStatus = status;
    this.lastT = t.t;
    this.dirty = true;
  }

  /** The milliseconds the skeleton has been untracked at the newest tick. */
  untrackedMs() {
    return this.untrackedSinceS === null ? 0 : Math.round((this.lastT - this.untrackedSinceS) * 1000);
  }

  render() {
    if (!this.dirty) return;
    this.dirty = false;
    if (this.card.hidden) {
      this.card.hidden = false;
      this.build();
    }
    if (this.u) this.u.setData(this.win.data());
    this.statusEl.textContent = this.lastStatus;
    this.statusEl.className = this.lastStatus === 'tracked' ? 'on' : 'alarm';
    const warning = skeletonWarning(this.lastStatus, this.untrackedMs());
    this.banner.hidden = !warning;
    if (warning) this.banner.textContent = warning;
  }

  build() {
    if (typeof window.uPlot !== 'function') return;
    const axis = (label, extra = {}) => ({
      label, labelSize: 16, size: 52, stroke: '#5b6474', font: '11px system-ui, sans-serif',
      labelFont: '11px system-ui, sans-serif', grid: { stroke: '#eef1f5', width: 1 }, ticks: { stroke: '#d9dee7' }, ...extra,
    });
    const opts = {
      width: Math.max(300, Math.floor(this.chartEl.getBoundingClientRect().width)),
      height: this.height,
      cursor: { drag: { x: false, y: false } },
      legend: { live: false },
      scales: { x: { time: false }, y: { range: [0, 180] } },
      axes: [axis('', { size: 28, values: (u, v) => v.map((s) => `${s}s`) }), axis('°', { splits: () => [0, 45, 90, 135, 180] })],
      series: [{ label: 't' }, ...SERIES.map((s) => ({ ...s, spanGaps: false }))],
    };
    this.u = new window.uPlot(opts, this.win.data(), this.chartEl);
  }

  resize() {
    if (this.u) this.u.setSize({ width: Math.max(300, Math.floor(this.chartEl.getBoundingClientRect().width)), height: this.height });
  }
}

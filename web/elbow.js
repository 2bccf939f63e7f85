// The gesture experiment's panel of the dashboard: the card of the strip chart of both elbow angles with
// their moving averages μ and the 90° command line (the chart itself is one of charts.js's, drawn from the
// timeline like the others), the skeleton's status (tracked / stale / none) in the "Now" card, and a
// warning banner when no skeleton has been tracked for a while. Shown only when the ticks carry `elbow`
// (PROTOCOL.md: the left-elbow stimulus). app.js creates one ElbowPanel and feeds it every sample and tick.
//
// The pure helper (skeletonWarning) has no DOM and is unit-tested under Node.

/** The angle below which the left elbow is a command, degrees (the paper's 90°). */
export const COMMAND_DEG = 90;

/** How long the skeleton may be untracked before the banner warns, ms (a few dropped frames are normal). */
export const WARN_AFTER_MS = 1000;

/** The elbow chart's series (charts.js): the columns of a sample's `elbow`, then the 90° line. */
export const ELBOW_SERIES = [
  { label: 'left', stroke: '#2563eb', width: 2 },
  { label: 'left μ', stroke: '#93c5fd', width: 1.5, dash: [6, 4] },
  { label: 'right', stroke: '#d97706', width: 2 },
  { label: 'right μ', stroke: '#fcd34d', width: 1.5, dash: [6, 4] },
  { label: '90°', stroke: '#6b7280', width: 1 },
];

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

/**
 * The panel: give it the page's elements and `showChart`, which adds the elbow chart to the page's charts
 * (charts.js: the same window, time axis and history as the others) and returns it; configure on hello,
 * `see` every sample (history or live), push every tick, render once a frame.
 */
export class ElbowPanel {
  constructor({
    card, status, banner, showChart,
  }) {
    this.card = card;
    this.statusEl = status;
    this.banner = banner;
    this.showChart = showChart;
    this.chart = null;
    this.lastStatus = null;
    this.untrackedSinceS = null;
    this.lastT = 0;
    this.dirty = false;
  }

  /** A new connection: the card shows once a sample carries `elbow`. */
  configure() {
    this.card.hidden = true;
    this.banner.hidden = true;
    this.lastStatus = null;
    this.untrackedSinceS = null;
  }

  /** A sample of the timeline (history or live): the first with elbow angles shows the card and its chart. */
  see(sample) {
    if (!sample || !sample.elbow || !this.card.hidden) return;
    this.card.hidden = false;
    this.chart = this.showChart();
  }

  /** A live tick: the skeleton's status. */
  push(t) {
    if (!t.elbow) return;
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

  /** The chart's columns (x, left, left μ, right, right μ, 90°), or null before it shows. */
  data() {
    return this.chart ? this.chart.u.data : null;
  }

  render() {
    if (!this.dirty) return;
    this.dirty = false;
    this.statusEl.textContent = this.lastStatus;
    this.statusEl.className = this.lastStatus === 'tracked' ? 'on' : 'alarm';
    const warning = skeletonWarning(this.lastStatus, this.untrackedMs());
    this.banner.hidden = !warning;
    if (warning) this.banner.textContent = warning;
  }
}

// The dashboard's data, without DOM or network (so Node can test it): samples from ticks and from the
// server's history, the timeline that keeps them and the events, chart columns with gaps, the CSV of a
// window, and the labels of the event markers. PROTOCOL.md describes the messages these read.

/** The chart windows the page offers, in seconds. */
export const WINDOWS = [
  { seconds: 10, label: '10 s' },
  { seconds: 30, label: '30 s' },
  { seconds: 60, label: '1 min' },
  { seconds: 300, label: '5 min' },
  { seconds: 600, label: '10 min' },
];

const num = (v) => (typeof v === 'number' && Number.isFinite(v) ? v : null);

/**
 * A tick's elbow angles as `[left, left μ, right, right μ]` (degrees, null when invalid), or null when the
 * tick carried none (every experiment but the gesture one).
 */
export function elbowAngles(elbow) {
  if (!elbow || typeof elbow !== 'object') return null;
  if (Array.isArray(elbow)) return [0, 1, 2, 3].map((k) => num(elbow[k]));
  return [num(elbow.left), num(elbow.left_avg), num(elbow.right), num(elbow.right_avg)];
}

/** A sample: what the charts and the CSV use of one tick. */
export function sampleFromTick(t) {
  const s = t.sensors || {};
  const link = t.link || {};
  return {
    seq: t.seq,
    t: t.t,
    mode: t.mode,
    stimulus: !!t.stimulus,
    gate: !!t.gate,
    estop: !!t.estop,
    safety: t.safety_stop ?? null,
    ocL: !!s.overcurrent_left,
    ocR: !!s.overcurrent_right,
    current: num(s.battery_current_ma),
    cmdL: num(t.command && t.command.left),
    cmdR: num(t.command && t.command.right),
    defL: num(t.default && t.default.left),
    defR: num(t.default && t.default.right),
    link: link.state || (link.up ? 'up' : 'down'),
    preds: (t.predictions || []).map((p) => [num(p.value), num(p.threshold)]),
    elbow: elbowAngles(t.elbow),
  };
}

/** The samples of a `history` message, read by the names in its `fields`. */
export function samplesFromHistory(msg) {
  const fields = Array.isArray(msg.fields) ? msg.fields : [];
  const at = Object.fromEntries(fields.map((f, i) => [f, i]));
  const rows = Array.isArray(msg.rows) ? msg.rows : [];
  return rows.filter(Array.isArray).map((r) => {
    const get = (f) => r[at[f]];
    const preds = Array.isArray(get('predictions')) ? get('predictions') : [];
    return {
      seq: get('seq'),
      t: get('t'),
      mode: get('mode'),
      stimulus: !!get('stimulus'),
      gate: !!get('gate'),
      estop: !!get('estop'),
      safety: get('safety_stop') ?? null,
      ocL: !!get('overcurrent_left'),
      ocR: !!get('overcurrent_right'),
      current: num(get('battery_current_ma')),
      cmdL: num(get('command_left')),
      cmdR: num(get('command_right')),
      defL: num(get('default_left')),
      defR: num(get('default_right')),
      link: get('link') || 'down',
      preds: preds.map((p) => (Array.isArray(p) ? [num(p[0]), num(p[1])] : [null, null])),
      elbow: elbowAngles(get('elbow')),
    };
  }).filter((s) => Number.isInteger(s.seq) && typeof s.t === 'number');
}

/**
 * Whether a sample's robot readings are real: the link is up (or tripped: frames still come). While it is
 * stale, reconnecting or down, the readings are old, so the charts leave a gap instead of a flat line.
 */
export function sensorsLive(s) {
  return s.link === 'up' || s.link === 'tripped';
}

/** The first index of `samples` (sorted by t) with t ≥ `t`. */
function lowerBound(samples, t) {
  let lo = 0;
  let hi = samples.length;
  while (lo < hi) {
    const mid = (lo + hi) >> 1;
    if (samples[mid].t < t) lo = mid + 1;
    else hi = mid;
  }
  return lo;
}

/**
 * The samples and events of the last `keepSeconds`: ticks appended in order (a repeated or older `seq` is
 * ignored), history merged in (it replaces what the page had from its first `seq` on), events by id.
 */
export class Timeline {
  constructor(keepSeconds) {
    this.keepSeconds = keepSeconds;
    this.samples = [];
    this.events = [];
    this.eventIds = new Set();
  }
  get last() {
    return this.samples.length ? this.samples[this.samples.length - 1] : null;
  }
  clear() {
    this.samples = [];
    this.events = [];
    this.eventIds.clear();
  }
  /** Appends `sample` unless it is not newer than the last one; returns whether it was kept. */
  push(sample) {
    const last = this.last;
    if (last && sample.seq <= last.seq) return false;
    this.samples.push(sample);
    this.trim();
    return true;
  }
  /** Merges a run of history samples (sorted): what the page had from their first `seq` on is replaced. */
  merge(samples) {
    if (!samples.length) return;
    const first = samples[0].seq;
    let cut = this.samples.length;
    while (cut > 0 && this.samples[cut - 1].seq >= first) cut -= 1;
    this.samples.length = cut;
    for (const s of samples) this.push(s);
  }
  /** Adds an event (once per id), kept in time order; returns whether it was new. */
  addEvent(event) {
    if (this.eventIds.has(event.id)) return false;
    this.eventIds.add(event.id);
    let i = this.events.length;
    while (i > 0 && this.events[i - 1].t > event.t) i -= 1;
    this.events.splice(i, 0, event);
    return true;
  }
  /** Lets go of what is older than `keepSeconds` before the newest sample, in batches. */
  trim() {
    const last = this.last;
    if (!last) return;
    const from = last.t - this.keepSeconds;
    if (this.samples[0].t >= from) return;
    const cut = lowerBound(this.samples, from);
    // Batches of a tenth, so that the copy happens once in a while, not on every tick.
    if (cut >= Math.max(1, this.samples.length / 10)) this.samples.splice(0, cut);
    while (this.events.length && this.events[0].t < from) {
      this.eventIds.delete(this.events[0].id);
      this.events.shift();
    }
  }
  /** The samples with `from` ≤ t ≤ `to`. */
  between(from, to) {
    return this.samples.slice(lowerBound(this.samples, from), lowerBound(this.samples, to + 1e-9));
  }
  /** The events with `from` ≤ t ≤ `to`. */
  eventsBetween(from, to) {
    return this.events.filter((e) => e.t >= from && e.t <= to);
  }
}

/**
 * uPlot columns for `samples`: x (t, s), then one column per extractor (a function of a sample giving a
 * number or null). Where ticks are missing (`seq` jumps by more than `stride`) a row of nulls is put in
 * just after the last tick before the hole, so every line breaks there instead of bridging it.
 */
export function columns(samples, extractors, periodS, stride = 1) {
  const cols = [[], ...extractors.map(() => [])];
  let prev = null;
  for (const s of samples) {
    if (prev && s.seq > prev.seq + stride) {
      cols[0].push(prev.t + periodS / 2);
      for (let k = 1; k < cols.length; k++) cols[k].push(null);
    }
    cols[0].push(s.t);
    extractors.forEach((f, k) => {
      const v = f(s);
      cols[k + 1].push(typeof v === 'number' && Number.isFinite(v) ? v : null);
    });
    prev = s;
  }
  return cols;
}

const csvCell = (v) => {
  if (v === null || v === undefined) return '';
  if (typeof v === 'boolean') return v ? '1' : '0';
  const s = String(v);
  return /[",\n\r]/.test(s) ? `"${s.replace(/"/g, '""')}"` : s;
};

/**
 * The CSV of `samples` (one row a tick), with each prediction's value and threshold under its name, and in
 * the last column the labels of the `events` that take effect on that tick.
 */
export function toCsv(samples, predictionNames, events = []) {
  const byT = new Map();
  for (const e of events) {
    if (!e.label) continue;
    const key = e.t.toFixed(6);
    byT.set(key, byT.has(key) ? `${byT.get(key)}; ${e.label}` : e.label);
  }
  const head = ['seq', 't_s', 'mode', ...predictionNames.flatMap((n) => [n, `${n}_threshold`]),
    'stimulus', 'gate', 'estop', 'safety_stop', 'overcurrent_left', 'overcurrent_right', 'battery_current_ma',
    'command_left', 'command_right', 'default_left', 'default_right', 'link', 'events'];
  const lines = [head.map(csvCell).join(',')];
  for (const s of samples) {
    const preds = predictionNames.flatMap((_, k) => (s.preds[k] ? s.preds[k] : [null, null]));
    const row = [s.seq, s.t, s.mode, ...preds, s.stimulus, s.gate, s.estop, s.safety, s.ocL, s.ocR, s.current,
      s.cmdL, s.cmdR, s.defL, s.defR, s.link, byT.get(s.t.toFixed(6)) ?? null];
    lines.push(row.map(csvCell).join(','));
  }
  return `${lines.join('\n')}\n`;
}

/** A learning parameter, short: three significant digits. */
export function fmtParam(v) {
  return typeof v === 'number' && Number.isFinite(v) ? String(Number(v.toPrecision(3))) : '—';
}

const PARAM_SYMBOLS = [['alpha', 'α'], ['lambda', 'λ'], ['threshold', 'θ']];

/**
 * The short label of an event's marker (`null`: no marker, e.g. teleop). For `params_set`, the values that
 * changed from `before` (the parameters in force before it, if known), or all of them.
 */
export function markerLabel(event, before = null) {
  switch (event.kind) {
    case 'params_set': {
      const changed = PARAM_SYMBOLS.filter(([k]) => !before || before[k] !== event[k]);
      const shown = changed.length ? changed : PARAM_SYMBOLS;
      return shown.map(([k, sym]) => `${sym}=${fmtParam(event[k])}`).join(' ');
    }
    case 'mode_set': return `mode→${event.mode}`;
    case 'e_stop': return event.latched ? 'e-stop' : 'e-stop released';
    case 'rearm': return 're-arm';
    case 'human_request': return 'request';
    case 'weights_reset': return 'weights reset';
    case 'weights_saved': return 'weights saved';
    case 'recording_started': return 'recording ●';
    case 'recording_stopped': return event.reason ? 'recording ■ failed' : 'recording ■';
    case 'checkpoint_failed': return 'checkpoint failed';
    case 'link': return `link→${event.state}${event.trip ? ` (${event.trip})` : ''}`;
    case 'pipeline_stall': return 'pipeline stall';
    case 'teleop': return null;
    default: return String(event.kind || 'event');
  }
}

/**
 * The parameters in force, by prediction, after `event` (the map `params` is not changed): `params_set`
 * replaces its prediction's α, λ, θ.
 */
export function applyParams(params, event) {
  if (event.kind !== 'params_set') return params;
  const next = { ...params };
  next[event.prediction] = { prediction: event.prediction, alpha: event.alpha, lambda: event.lambda, threshold: event.threshold };
  return next;
}

/** How often the charts may be redrawn for a window of `seconds`: a pixel is about that much time anyway. */
export function redrawIntervalMs(seconds) {
  return Math.min(1000, Math.max(0, seconds * 2));
}

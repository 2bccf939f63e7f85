// Pure helpers of the learning view (learning.js), tested in tests/learnlib.test.mjs: the store of the
// `learning` messages and the tick values they pair with, the decoding of the Horde's values (bfloat16,
// base64), the Horde grid's layout, colours and hit test, and the Horde series a click adds to a chart.

/**
 * Every control prediction's learning figures by tick: its value (from the ticks), its TD error and its
 * realised return (from the `learning` messages, the return arriving a horizon later), and the running error
 * at each message. Keeps the newest `keepTicks` ticks.
 */
export class LearningStore {
  constructor(keepTicks = 1500) {
    this.keepTicks = keepTicks;
    this.byName = new Map();
  }

  clear() {
    this.byName.clear();
  }

  entry(name) {
    let e = this.byName.get(name);
    if (!e) {
      e = {
        rows: new Map(), newest: -1, info: null, errors: [],
      };
      this.byName.set(name, e);
    }
    return e;
  }

  row(e, seq) {
    let r = e.rows.get(seq);
    if (!r) {
      r = {
        value: null, ret: null, td: null, complete: null,
      };
      e.rows.set(seq, r);
      if (seq > e.newest) e.newest = seq;
    }
    return r;
  }

  prune(e) {
    const oldest = e.newest - this.keepTicks;
    for (const seq of e.rows.keys()) if (seq < oldest) e.rows.delete(seq);
    while (e.errors.length && e.errors[0].seq < oldest) e.errors.shift();
  }

  /** A tick's value of prediction `name`. */
  addValue(name, seq, value) {
    if (!Number.isInteger(seq)) return;
    const e = this.entry(name);
    this.row(e, seq).value = Number.isFinite(value) ? value : null;
  }

  /** A `learning` message. */
  addMessage(msg) {
    if (!msg || !Array.isArray(msg.predictions)) return;
    for (const p of msg.predictions) {
      if (typeof p.name !== 'string') continue;
      const e = this.entry(p.name);
      for (const [seq, td] of Array.isArray(p.td) ? p.td : []) {
        if (Number.isInteger(seq)) this.row(e, seq).td = typeof td === 'number' ? td : null;
      }
      for (const [seq, value, ret, complete] of Array.isArray(p.realised) ? p.realised : []) {
        if (!Number.isInteger(seq)) continue;
        const r = this.row(e, seq);
        if (r.value === null && typeof value === 'number') r.value = value;
        r.ret = typeof ret === 'number' ? ret : null;
        r.complete = complete === 1;
      }
      e.info = {
        tau: p.tau,
        learner: typeof p.learner === 'string' ? p.learner : null,
        horizon: p.horizon,
        tailBound: p.tail_bound,
        error: p.error || {},
        dropped: p.dropped || 0,
        seq: msg.seq,
      };
      if (Number.isInteger(msg.seq) && p.error && typeof p.error.rmse === 'number') {
        e.errors.push({ seq: msg.seq, rmse: p.error.rmse, meanAbs: p.error.mean_abs });
      }
      this.prune(e);
    }
  }

  names() {
    return [...this.byName.keys()].filter((n) => this.byName.get(n).info);
  }

  /** The newest figures of `name` (tau, horizon, tailBound, error, dropped, seq), or null. */
  info(name) {
    const e = this.byName.get(name);
    return e ? e.info : null;
  }

  /**
   * Columns for a chart of `name` over its kept ticks, at `periodS` seconds a tick: `t`, `value`, `ret`,
   * `td`, `rmse` (the running RMSE at each message's tick, null elsewhere), oldest first, one per tick from
   * the oldest kept to the newest (null where a tick has no figure); only the ticks from `fromS` to `toS`
   * seconds when given (the time span the page's charts show).
   */
  series(name, periodS, fromS = -Infinity, toS = Infinity) {
    const e = this.byName.get(name);
    const out = {
      t: [], value: [], ret: [], td: [], rmse: [],
    };
    if (!e || e.newest < 0) return out;
    let first = e.newest;
    for (const seq of e.rows.keys()) if (seq < first) first = seq;
    first = Math.max(first, Math.ceil(fromS / periodS - 1e-9));
    const last = Math.min(e.newest, Math.floor(toS / periodS + 1e-9));
    const rmse = new Map(e.errors.map((x) => [x.seq, x.rmse]));
    for (let seq = first; seq <= last; seq += 1) {
      const r = e.rows.get(seq);
      out.t.push(seq * periodS);
      out.value.push(r ? r.value : null);
      out.ret.push(r ? r.ret : null);
      out.td.push(r ? r.td : null);
      out.rmse.push(rmse.has(seq) ? rmse.get(seq) : null);
    }
    return out;
  }
}

/** Bytes of standard base64 (with or without padding). */
export function base64Bytes(text) {
  const digits = 'ABCDEFGHIJKLMNOPQRSTUVWXYZabcdefghijklmnopqrstuvwxyz0123456789+/';
  const clean = String(text).replace(/=+$/, '');
  const out = new Uint8Array(Math.floor((clean.length * 3) / 4));
  let bits = 0;
  let n = 0;
  let o = 0;
  for (let i = 0; i < clean.length; i += 1) {
    const d = digits.indexOf(clean[i]);
    if (d < 0) throw new Error(`not base64 at ${i}`);
    n = (n << 6) | d;
    bits += 6;
    if (bits >= 8) {
      bits -= 8;
      out[o] = (n >> bits) & 0xff;
      o += 1;
    }
  }
  return out;
}

/** The values of a `horde_values` message (`bf16le-base64`) as a Float32Array of `msg.count` values. */
export function decodeHordeValues(msg) {
  if (!msg || msg.encoding !== 'bf16le-base64') throw new Error(`unknown encoding ${msg && msg.encoding}`);
  const bytes = base64Bytes(msg.values);
  const n = Math.floor(bytes.length / 2);
  const words = new Uint32Array(n);
  for (let i = 0; i < n; i += 1) words[i] = ((bytes[2 * i + 1] << 8) | bytes[2 * i]) << 16;
  const values = new Float32Array(words.buffer);
  if (values.length !== msg.count) throw new Error(`expected ${msg.count} values, got ${values.length}`);
  return values;
}

/**
 * The Horde grid: `n` square cells in rows, as many columns as make the grid about as wide as `width` and
 * as tall as `maxHeight` allow, cells at least 2 px.
 */
export function gridLayout(n, width, maxHeight = 420) {
  if (n <= 0 || width <= 0) {
    return {
      n: 0, cols: 0, rows: 0, cell: 0, width: 0, height: 0,
    };
  }
  let cell = Math.max(2, Math.floor(Math.sqrt((width * maxHeight) / n)));
  let cols = Math.max(1, Math.floor(width / cell));
  while (cell > 2 && Math.ceil(n / cols) * cell > maxHeight) {
    cell -= 1;
    cols = Math.max(1, Math.floor(width / cell));
  }
  cell = Math.min(cell, 48);
  cols = Math.min(n, Math.max(1, Math.floor(width / cell)));
  const rows = Math.ceil(n / cols);
  return {
    n, cols, rows, cell, width: cols * cell, height: rows * cell,
  };
}

/** The prediction under (x, y) (CSS pixels from the grid's top left), or -1. */
export function cellAt(layout, x, y) {
  if (!layout || layout.cell <= 0 || x < 0 || y < 0) return -1;
  const col = Math.floor(x / layout.cell);
  const row = Math.floor(y / layout.cell);
  if (col >= layout.cols || row >= layout.rows) return -1;
  const i = row * layout.cols + col;
  return i < layout.n ? i : -1;
}

/** The range the grid's colours span: the 2nd to 98th percentile of the finite values (never empty). */
export function colourRange(values) {
  const finite = Array.from(values).filter(Number.isFinite).sort((a, b) => a - b);
  if (!finite.length) return { lo: 0, hi: 1 };
  const at = (q) => finite[Math.min(finite.length - 1, Math.max(0, Math.round(q * (finite.length - 1))))];
  let lo = at(0.02);
  let hi = at(0.98);
  if (!(hi > lo)) {
    lo -= 0.5;
    hi += 0.5;
  }
  return { lo, hi };
}

/**
 * Each prediction's own range of values seen (for colouring each cell against itself, when the predictions'
 * scales differ by orders of magnitude, as a cumulant in mAh and one in [0, 1] do).
 */
export class OwnRanges {
  constructor() {
    this.from = -1;
    this.lo = new Float32Array(0);
    this.hi = new Float32Array(0);
  }

  /** One sample of predictions `from … from + values.length − 1`; a new window starts afresh. */
  update(from, values) {
    if (from !== this.from || values.length !== this.lo.length) {
      this.from = from;
      this.lo = new Float32Array(values.length).fill(Infinity);
      this.hi = new Float32Array(values.length).fill(-Infinity);
    }
    for (let i = 0; i < values.length; i += 1) {
      const v = values[i];
      if (!Number.isFinite(v)) continue;
      if (v < this.lo[i]) this.lo[i] = v;
      if (v > this.hi[i]) this.hi[i] = v;
    }
  }

  /** `values[i]` as a fraction of its own range seen (0.5 while the range is a point; NaN stays NaN). */
  fraction(i, v) {
    if (!Number.isFinite(v)) return NaN;
    const span = this.hi[i] - this.lo[i];
    return span > 0 ? (v - this.lo[i]) / span : 0.5;
  }
}

/** A number with `digits` significant digits (no thousands separators, exponent when very large or small). */
export function sig(v, digits = 4) {
  if (typeof v !== 'number' || Number.isNaN(v)) return '—';
  if (v === 0 || !Number.isFinite(v)) return String(v);
  const a = Math.abs(v);
  return a >= 1e6 || a < 1e-4 ? v.toExponential(digits - 1) : String(Number(v.toPrecision(digits)));
}

// A perceptual sequential scale (viridis, 9 stops).
const VIRIDIS = [
  [68, 1, 84], [72, 40, 120], [62, 74, 137], [49, 104, 142], [38, 130, 142],
  [31, 158, 137], [53, 183, 121], [110, 206, 88], [253, 231, 37],
];

/** The colour [r, g, b] of `value` on [lo, hi] (clamped); grey for a value that is not finite. */
export function colourOf(value, lo, hi) {
  if (!Number.isFinite(value)) return [150, 150, 150];
  const f = Math.min(1, Math.max(0, (value - lo) / (hi - lo || 1))) * (VIRIDIS.length - 1);
  const i = Math.min(VIRIDIS.length - 2, Math.floor(f));
  const w = f - i;
  return VIRIDIS[i].map((c, k) => Math.round(c + w * (VIRIDIS[i + 1][k] - c)));
}

/** The parts of a Horde prediction's name `family/kind/signal@tau` (null parts when it is not one). */
export function hordeName(name) {
  const m = /^([^/]+)\/(.+)@([0-9.eE+-]+)$/.exec(String(name));
  if (!m) return { family: null, cumulant: null, tau: null };
  return { family: m[1], cumulant: m[2], tau: Number(m[3]) };
}

/**
 * The Horde predictions a click put on the chart (at most `max`, the oldest dropped), each with its values
 * over time (at most `keep` points).
 */
export class HordeSeries {
  constructor(max = 6, keep = 1200) {
    this.max = max;
    this.keep = keep;
    this.picked = [];
    this.t = [];
    this.columns = [];
  }

  /** Adds prediction `index` (a no-op when already there); returns whether it is now charted. */
  toggle(index) {
    const at = this.picked.indexOf(index);
    if (at >= 0) {
      this.picked.splice(at, 1);
      this.columns.splice(at, 1);
      return false;
    }
    if (this.picked.length >= this.max) {
      this.picked.shift();
      this.columns.shift();
    }
    this.picked.push(index);
    this.columns.push(this.t.map(() => null));
    return true;
  }

  /** One `horde_values` sample at time `t` (s): `values` starts at prediction `from`. */
  push(t, from, values) {
    if (!this.picked.length) return;
    this.t.push(t);
    this.picked.forEach((index, k) => {
      const i = index - from;
      const v = i >= 0 && i < values.length ? values[i] : NaN;
      this.columns[k].push(Number.isFinite(v) ? v : null);
    });
    while (this.t.length > this.keep) {
      this.t.shift();
      for (const c of this.columns) c.shift();
    }
  }

  clear() {
    this.picked = [];
    this.t = [];
    this.columns = [];
  }
}

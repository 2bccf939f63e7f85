// Pure helpers of the dashboard (no DOM, no network), shared by the page's modules and the Node unit tests;
// the data of the charts (samples, timeline, gaps, CSV, markers) is in timeline.js, re-exported here.

export * from './timeline.js';

/** The websocket subprotocol of PROTOCOL.md. */
export const SUBPROTOCOL = 'pavlov.v1';

/** Characters allowed in a Sec-WebSocket-Protocol value (RFC 7230 token). */
const TOKEN_CHARS = /^[!#$%&'*+\-.^_`|~0-9A-Za-z]+$/;

/** The access token from a URL fragment like `#token=abc` (fragments never reach the server's logs). */
export function tokenFromHash(hash) {
  const params = new URLSearchParams(String(hash || '').replace(/^#/, ''));
  const t = params.get('token');
  return t ? t : null;
}

/**
 * Where and how to open the websocket for a page at `location`: the token goes in the subprotocol list
 * when it is made of token characters, and in the query string otherwise.
 */
export function connectionTarget(location, token) {
  const scheme = location.protocol === 'https:' ? 'wss:' : 'ws:';
  let url = `${scheme}//${location.host}/ws`;
  const protocols = [SUBPROTOCOL];
  if (token) {
    if (TOKEN_CHARS.test(token)) protocols.push(`token.${token}`);
    else url += `?token=${encodeURIComponent(token)}`;
  }
  return { url, protocols };
}

/** Reconnect delays: 0.5 s doubling to 8 s; `reset()` after a successful connection. */
export class Backoff {
  constructor(firstMs = 500, maxMs = 8000) {
    this.firstMs = firstMs;
    this.maxMs = maxMs;
    this.nextMs = firstMs;
  }
  next() {
    const d = this.nextMs;
    this.nextMs = Math.min(this.maxMs, this.nextMs * 2);
    return d;
  }
  reset() {
    this.nextMs = this.firstMs;
  }
}

/** Wheel speeds for the teleop keys held (`up`, `down`, `left`, `right`) at `speed` mm/s. */
export function teleopWheels(held, speed) {
  const fwd = (held.has('up') ? 1 : 0) - (held.has('down') ? 1 : 0);
  const turn = (held.has('left') ? 1 : 0) - (held.has('right') ? 1 : 0);
  let left;
  let right;
  if (fwd === 0) {
    // Turn in place: left wheel back, right wheel forward turns left (counter-clockwise).
    left = -turn * speed;
    right = turn * speed;
  } else {
    const inner = Math.round(speed * 0.4);
    left = fwd * (turn > 0 ? inner : speed);
    right = fwd * (turn < 0 ? inner : speed);
  }
  const clamp = (v) => Math.max(-500, Math.min(500, Math.round(v))) || 0;
  return { left_mm_s: clamp(left), right_mm_s: clamp(right) };
}

/** Counts ticks that never arrived, from the sequence numbers that did (`stride` = requested decimation). */
export class GapCounter {
  constructor() {
    this.last = null;
    this.missing = 0;
  }
  see(seq, stride = 1) {
    if (this.last !== null && seq > this.last + stride) this.missing += seq - this.last - stride;
    this.last = seq;
  }
}

/** Formats a number for a counter, with a unit; `—` for missing values. */
export function fmt(value, digits = 0, unit = '') {
  if (value === null || value === undefined || Number.isNaN(value)) return '—';
  const s = Number(value).toLocaleString('en-US', {
    minimumFractionDigits: digits,
    maximumFractionDigits: digits,
  });
  return unit ? `${s} ${unit}` : s;
}

/**
 * Formats when a response began relative to the command that called for it, from its lead in ms (command
 * onset − response onset): `120 ms after` for a lead of −120 (a lag), `40 ms before` for +40, `at the command`
 * for 0, `—` when missing. Words, not a sign: in the study tables a positive lead means the Pavlovian
 * response came earlier than the reactive one, which a signed single-run figure would blur.
 */
export function fmtOnset(ms) {
  if (ms === null || ms === undefined || Number.isNaN(ms)) return '—';
  const r = Math.round(ms);
  if (r === 0) return 'at the command';
  return `${Math.abs(r).toLocaleString('en-US')} ms ${r > 0 ? 'before' : 'after'}`;
}

/**
 * The Now card's Gate row: `default π` while the gate is off, else the response with what engaged it (a
 * `[[rules]]` rule's name, or `stimulus`); a server without a rule table sends none.
 */
export function gateText(tick) {
  if (!tick.gate) return 'default π';
  return tick.rule ? `ϱ · ${tick.rule}` : 'response ϱ';
}

/** Formats seconds as `m:ss` or `h:mm:ss`. */
export function fmtDuration(seconds) {
  if (seconds === null || seconds === undefined || Number.isNaN(seconds)) return '—';
  const s = Math.floor(seconds);
  const h = Math.floor(s / 3600);
  const m = Math.floor((s % 3600) / 60);
  const ss = String(s % 60).padStart(2, '0');
  return h > 0 ? `${h}:${String(m).padStart(2, '0')}:${ss}` : `${m}:${ss}`;
}

/**
 * Parses a learning-parameter field: a finite number, or `undefined` when empty, or an error message.
 * The value must lie in [lo, hi]; with `loOpen` it must also be above `lo` (α > 0).
 */
export function parseParam(text, name, lo, hi, loOpen = false) {
  const t = String(text ?? '').trim();
  if (t === '') return { value: undefined };
  const v = Number(t);
  if (!Number.isFinite(v)) return { error: `${name} must be a number` };
  if (v < lo || v > hi || (loOpen && v <= lo)) {
    return { error: loOpen ? `${name} must be above ${lo} and at most ${hi}` : `${name} must be between ${lo} and ${hi}` };
  }
  return { value: v };
}

/**
 * The limits of the learning form for prediction `name`, from `hello.signals.bounds` (PROTOCOL.md): the
 * bounds the server checks. α in (0, max_alpha] (α·‖x‖² ≤ 1 with ‖x‖² = active_features), λ in
 * [min_lambda, max_lambda], θ finite (the form keeps it within ±1e6). Without bounds for `name` (an
 * older server), α in (0, 1] and λ in [0, 1]; the server still has the last word.
 */
export function paramLimits(bounds, name) {
  const list = bounds && Array.isArray(bounds.predictions) ? bounds.predictions : [];
  const p = list.find((b) => b && b.name === name);
  const num = (v, d) => (typeof v === 'number' && Number.isFinite(v) ? v : d);
  const maxAlpha = num(p && p.max_alpha, 1);
  const active = p && Number.isInteger(p.active_features) ? p.active_features : null;
  return {
    alpha: {
      lo: 0, hi: maxAlpha, loOpen: true,
      hint: active ? `0 < α ≤ 1/${active} = ${Number(maxAlpha.toPrecision(3))} (α·‖x‖² ≤ 1, ${active} active features)` : '0 < α ≤ 1',
    },
    lambda: { lo: num(p && p.min_lambda, 0), hi: num(p && p.max_lambda, 1), loOpen: false, hint: '0 ≤ λ ≤ 1' },
    threshold: { lo: -1e6, hi: 1e6, loOpen: false, hint: 'any number' },
  };
}

/**
 * The uPlot data of the aligned averages (`status.interaction.aligned`, PROTOCOL.md): x in seconds from the
 * command onset, then the reactive and the Pavlovian means; a mode with no commands yet is all gaps (null).
 * Returns null when `aligned` is missing or malformed.
 */
export function alignedData(aligned) {
  if (!aligned || !Array.isArray(aligned.offsets_ms)) return null;
  const n = aligned.offsets_ms.length;
  const xs = aligned.offsets_ms.map((ms) => ms / 1000);
  const curve = (mode, key) => {
    const values = mode && Array.isArray(mode[key]) ? mode[key] : [];
    return Array.from({ length: n }, (_, k) => (typeof values[k] === 'number' ? values[k] : null));
  };
  const { reactive, pavlovian } = aligned;
  return {
    current: [xs, curve(reactive, 'current_ma'), curve(pavlovian, 'current_ma')],
    rotation: [xs, curve(reactive, 'rotation_deg'), curve(pavlovian, 'rotation_deg')],
    counts: { reactive: (reactive && reactive.commands) || 0, pavlovian: (pavlovian && pavlovian.commands) || 0 },
  };
}

/**
 * What the recording card shows: the badge (`on` while a recording is written; `stopped` when the last one
 * stopped because writing it failed, with that reason; else `off`) and the notice under it.
 */
export function recordingView(recording, failure) {
  if (recording) return { badge: 'on', alarm: false, notice: null };
  if (failure) return { badge: 'stopped', alarm: true, notice: `Recording stopped: ${failure}` };
  return { badge: 'off', alarm: false, notice: null };
}

/**
 * How storage events change what the page shows about storage, as `{ recordingFailure, checkpointFailure }`
 * (the reasons of the latest failures; `null`: none in force): a `recording_stopped` with a `reason` sets
 * the first, a `recording_started` clears it; `checkpoint_failed` sets the second, `weights_saved` clears it.
 */
export function applyStorageEvent(storage, event) {
  switch (event.kind) {
    case 'recording_started': return { ...storage, recordingFailure: null };
    case 'recording_stopped':
      return event.reason ? { ...storage, recordingFailure: String(event.reason) } : { ...storage, recordingFailure: null };
    case 'checkpoint_failed': return { ...storage, checkpointFailure: String(event.reason || 'unknown error') };
    case 'weights_saved': return { ...storage, checkpointFailure: null };
    default: return storage;
  }
}

// ---------------------------------------------------------------- event markers: legend and labels

/**
 * The kinds of event marker the charts draw, as the legend shows them: a colour, the event kinds of the
 * protocol it covers (`event.kind`), the labels it puts on the charts, and what it means with its usual
 * cause (the legend's and every label's hover text).
 */
export const MARKER_KINDS = [
  {
    key: 'stall', name: 'pipeline stall', color: '#db2777', kinds: ['pipeline_stall'],
    explain: 'pipeline stall: actuation stopped the wheels because no decision arrived within the configured '
      + 'ticks ([safety] max_action_age_ticks). Usually host load (other programs, a slow disk or a busy CPU '
      + 'kept the server from running on time), not the robot.',
  },
  {
    key: 'link', name: 'link→…, re-arm', color: '#d97706', kinds: ['link', 'rearm'],
    explain: 'link→stale: no sensor frame for longer than the stale limit (150 ms); usually host load delaying '
      + 'the server, not the robot, and it comes back up by itself. link→reconnecting/down: the serial port '
      + 'went away (cable, power). link→tripped: the robot dropped to Passive by itself (wheel drop, cliff) '
      + 'until the operator re-arms. link→up: frames flow again. re-arm: the operator re-armed after a trip.',
  },
  {
    key: 'estop', name: 'e-stop', color: '#dc2626', kinds: ['e_stop'],
    explain: 'e-stop / e-stop released: the operator latched or released the emergency stop; the wheels stay '
      + 'stopped while it is latched.',
  },
  {
    key: 'control', name: 'mode, request', color: '#2563eb', kinds: ['mode_set', 'human_request'],
    explain: 'mode→…: the operator switched the control mode (reactive, Pavlovian, manual). request: the '
      + 'stimulus was forced on for a moment (the Request button or a client\'s human_request).',
  },
  {
    key: 'learning', name: 'α λ θ, weights', color: '#7c3aed', kinds: ['params_set', 'weights_reset', 'weights_saved'],
    explain: 'α=… λ=… θ=…: the operator changed a prediction\'s learning parameters (the label shows what '
      + 'changed). weights reset / saved: every weight went back to its initial value, or was written to a file.',
  },
  {
    key: 'storage', name: 'recording, checkpoint', color: '#059669',
    kinds: ['recording_started', 'recording_stopped', 'checkpoint_failed'],
    explain: 'recording ● / ■: a recording started or stopped ("failed": writing it failed, e.g. a full disk). '
      + 'checkpoint failed: a checkpoint or a save could not be written; the previous file is unchanged.',
  },
];

const OTHER_MARKER = { key: 'other', name: 'other', color: '#6b7280', kinds: [], explain: 'an event of a kind this page does not know' };

/** The legend entry of an event kind (`other` for a kind this page does not know). */
export function markerKind(kind) {
  return MARKER_KINDS.find((k) => k.kinds.includes(kind)) || OTHER_MARKER;
}

/** The marker's colour by event kind. */
export function markerColor(kind) {
  return markerKind(kind).color;
}

/**
 * Where the labels of the markers go so that none overlaps another: `items` are `{ x, label }` (x in
 * pixels within a plot `plotWidth` wide), `width(text)` a label's width in pixels. Markers closer than
 * `merge` pixels to the first of their run share one label: `label ×n` when they all say the same, else the
 * first one's `label +k` (k the others); each label goes right of its marker (left of it when it would leave
 * the plot) in the first of `rows` rows where it keeps `gap` pixels from the label before it; a label that
 * fits in no row is left out. Returns the labels placed (`{ left, row, width, text, items }`, `items` the
 * markers they stand for) and how many markers have none.
 */
export function layoutMarkerLabels(items, width, {
  rows = 3, gap = 4, plotWidth = Infinity, merge = 12,
} = {}) {
  const sorted = [...items].sort((a, b) => a.x - b.x);
  const groups = [];
  for (const item of sorted) {
    const g = groups[groups.length - 1];
    if (g && item.x - g.x <= merge) g.items.push(item);
    else groups.push({ x: item.x, items: [item] });
  }
  const ends = new Array(rows).fill(-Infinity);
  const placed = [];
  let hidden = 0;
  for (const g of groups) {
    const first = g.items[0].label;
    const same = g.items.every((m) => m.label === first);
    const n = g.items.length;
    const text = n === 1 ? first : (same ? `${first} ×${n}` : `${first} +${n - 1}`);
    const w = width(text);
    let left = g.x + 2;
    if (left + w > plotWidth) left = Math.max(0, g.x - 2 - w);
    const row = ends.findIndex((end) => left >= end + gap);
    if (row < 0) {
      hidden += g.items.length;
      continue;
    }
    ends[row] = left + w;
    placed.push({ left, row, width: w, text, items: g.items });
  }
  return { placed, hidden };
}

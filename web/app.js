// The pavlov dashboard: connects to /ws (PROTOCOL.md), keeps the run's recent past (timeline.js: the
// server's history on connect, then every tick and event), draws it (charts.js), shows the run counters,
// tick health and what is in force, and sends commands (controls.js). When the connection is lost the page
// says so everywhere (greyed panels, a banner, an E-STOP that says it cannot send) and reconnects by itself.

import {
  Backoff, GapCounter, Timeline, WINDOWS, applyParams, applyStorageEvent, connectionTarget, fmt, markerLabel,
  paramLimits, sampleFromTick, samplesFromHistory, toCsv, tokenFromHash,
} from './lib.js';
import { ElbowPanel } from './elbow.js';
import { AlignedCharts, Charts, renderMarkerLegend } from './charts.js';
import { wireControls } from './controls.js';
import { HordeView, LearningView } from './learning.js';
import {
  applyLimits, labelRequest, renderCheckpoint, renderInForce, renderNow, renderRecording, renderStatus, robotText,
  showParamsError,
} from './panels.js';

/** Seconds of data the page keeps: the widest window. */
const KEEP_SECONDS = Math.max(...WINDOWS.map((w) => w.seconds));

const $ = (id) => document.getElementById(id);

const timeline = new Timeline(KEEP_SECONDS);
const state = {
  ws: null,
  hello: null,
  run: null,
  limits: paramLimits(null, null),
  canCommand: false,
  connected: false,
  live: false,
  nextId: 1,
  pending: new Map(),
  ticks: 0,
  last: null,
  gaps: new GapCounter(),
  stride: 1,
  dirty: false,
  mode: null,
  estop: false,
  params: {},
  historyParams: {},
  historyDone: false,
  recording: null,
  // The reasons of the latest storage failures still in force (lib.js applyStorageEvent).
  storage: { recordingFailure: null, checkpointFailure: null },
  held: new Set(),
  teleopTimer: null,
  backoff: new Backoff(),
  timeline,
};

// The learning view (learning.js): value against realised return, δ, running error; the Horde's grid.
state.learning = new LearningView({
  pick: $('learn-pick'), params: $('learn-params'), empty: $('learn-empty'), rmse: $('learn-rmse'), mae: $('learn-mae'),
  bias: $('learn-bias'), pairs: $('learn-pairs'), td: $('learn-td'), horizon: $('learn-horizon'),
  returnChart: $('chart-learn-return'), tdChart: $('chart-learn-td'),
});
state.horde = new HordeView({
  none: $('horde-none'), body: $('horde-body'), info: $('horde-info'), grid: $('horde-grid'), gridBox: $('horde-grid-box'),
  hover: $('horde-hover'), scale: $('horde-scale'), colourBy: $('horde-colour'), chart: $('chart-horde'), chartCard: $('horde-chart-card'),
}, (cmd, args) => send(cmd, args));
const charts = new Charts(timeline, renderView);
const aligned = new AlignedCharts();
// The gesture experiment's elbow card and skeleton status (elbow.js); its chart is one of `charts`.
state.elbow = new ElbowPanel({
  card: $('elbow-card'), status: $('now-skeleton'), banner: $('skeleton-banner'), showChart: () => charts.addElbow(),
});
state.view = charts.view;
Object.defineProperty(state, 'charts', { get: () => charts.list });
// Exposed for the end-to-end tests and for poking around in the console.
window.pavlov = state;

// ---------------------------------------------------------------- log

function log(text, kind = 'info') {
  const li = document.createElement('li');
  li.className = kind;
  const time = new Date().toLocaleTimeString('en-GB', { hour12: false });
  li.innerHTML = '<time></time><span></span>';
  li.firstChild.textContent = time;
  li.lastChild.textContent = text;
  const list = $('log');
  list.prepend(li);
  while (list.children.length > 60) list.lastChild.remove();
}

// ---------------------------------------------------------------- connection

function setConn(s, text) {
  $('conn').dataset.state = s;
  $('conn-state').textContent = text;
}

/** What a watcher's command buttons say (they are disabled: the server would refuse them). */
const NEEDS_TOKEN = 'needs the operator\'s token';

/**
 * Whether this page may command: live, and either the operator (the token) or not yet told. The E-STOP,
 * Re-arm, Release and every other command button are disabled otherwise, saying why, and the banners never
 * tell a watcher to do what only the operator can.
 */
function renderAuthority() {
  const { live } = state;
  const watcher = live && !state.canCommand;
  const estop = $('estop');
  estop.disabled = !live || watcher;
  $('estop-note').textContent = !live ? 'cannot send: not connected' : (watcher ? NEEDS_TOKEN : '');
  estop.title = !live ? 'Not connected to the server: this button cannot reach the robot'
    : (watcher ? `Watch-only: the E-STOP ${NEEDS_TOKEN} (open the page with #token=…)`
      : 'Emergency stop (Esc): stops the wheels until released');
  for (const b of document.querySelectorAll('.mode, #request, #release, #rearm, .key, .card button, #p-apply')) {
    b.disabled = watcher;
    if (watcher) b.title = `Watch-only: ${NEEDS_TOKEN}`;
    else if (b.dataset.title !== undefined) b.title = b.dataset.title;
  }
  $('rearm').textContent = watcher ? `Re-arm (${NEEDS_TOKEN})` : 'Re-arm';
  $('release').textContent = watcher ? `Release (${NEEDS_TOKEN})` : 'Release';
  $('trip-who').textContent = watcher ? 'control resumes when the operator re-arms.' : 'control resumes only when you re-arm.';
  $('estop-who').textContent = watcher ? ' until the operator releases it.' : '.';
}

/** Live (a `hello` came on an open socket) or not: everything that acts or shows live data says which. */
function setLive(live, why = '') {
  state.live = live;
  renderAuthority();
  const lost = !live && why !== 'connecting';
  document.body.classList.toggle('disconnected', lost);
  $('disconnect-banner').hidden = !lost;
  if (lost) $('disconnect-why').textContent = why;
}

function connect() {
  const token = tokenFromHash(window.location.hash);
  const { url, protocols } = connectionTarget(window.location, token);
  setConn('connecting', 'connecting…');
  let ws;
  try {
    ws = new WebSocket(url, protocols);
  } catch (e) {
    log(`cannot open the websocket: ${e.message}`, 'error');
    scheduleReconnect();
    return;
  }
  state.ws = ws;
  ws.onopen = () => {
    state.connected = true;
    state.backoff.reset();
  };
  ws.onmessage = (ev) => {
    let msg;
    try {
      msg = JSON.parse(ev.data);
    } catch (e) {
      log(`unreadable message from the server: ${e.message}`, 'error');
      return;
    }
    onMessage(msg);
  };
  ws.onclose = (ev) => {
    const wasLive = state.live;
    state.connected = false;
    state.ws = null;
    failPending('the connection closed');
    if (ev.code !== 1000 && ev.code !== 1005) log(`connection closed (${ev.code}${ev.reason ? `: ${ev.reason}` : ''})`, 'warn');
    // The banner keeps the time the page lost the server, across the reconnect attempts.
    if (!document.body.classList.contains('disconnected')) {
      const since = new Date().toLocaleTimeString('en-GB', { hour12: false });
      setLive(false, wasLive ? `since ${since}` : `no answer since ${since}`);
    }
    scheduleReconnect();
  };
}

function scheduleReconnect() {
  const delay = state.backoff.next();
  let left = Math.ceil(delay / 1000);
  const say = () => {
    setConn('down', `disconnected — retrying in ${left} s`);
    $('disconnect-retry').textContent = `Reconnecting in ${left} s…`;
  };
  say();
  const timer = setInterval(() => {
    left -= 1;
    if (left > 0) say();
  }, 1000);
  setTimeout(() => {
    clearInterval(timer);
    $('disconnect-retry').textContent = 'Reconnecting…';
    connect();
  }, delay);
}

function send(cmd, args = {}) {
  if (!state.ws || state.ws.readyState !== WebSocket.OPEN) {
    log(`not connected: ${cmd} not sent`, 'error');
    return null;
  }
  const id = state.nextId++;
  state.pending.set(id, cmd);
  state.ws.send(JSON.stringify({ cmd, id, ...args }));
  return id;
}

function failPending(why) {
  for (const cmd of state.pending.values()) log(`${cmd}: no answer (${why})`, 'warn');
  state.pending.clear();
}

// ---------------------------------------------------------------- messages

function onMessage(msg) {
  switch (msg.type) {
    case 'hello': return onHello(msg);
    case 'history': return onHistory(msg);
    case 'event': return onEvent(msg, false);
    case 'tick': return onTick(msg);
    case 'status': return renderStatus(state, msg, aligned);
    case 'learning': return state.learning.message(msg);
    case 'horde_names': return state.horde.onNames(msg);
    case 'horde_values': return state.horde.onValues(msg);
    case 'ack': return onAck(msg);
    case 'error': return onError(msg);
    default: return undefined;
  }
}

function onHello(h) {
  if (state.run !== h.run) timeline.clear();
  state.run = h.run;
  state.hello = h;
  state.canCommand = h.can_command;
  state.gaps = new GapCounter();
  state.stride = 1;
  state.historyDone = false;
  state.historyParams = {};
  const cfg = h.config || {};
  const model = (h.robot && h.robot.model) || (cfg.robot ? cfg.robot.model : '');
  const where = robotText(h.robot);
  $('robot-name').textContent = `${h.server} · ${model ? `${model} · ` : ''}${where ? `${where} · ` : ''}${h.tick_period_ms} ms ticks`;
  $('robot-badge').textContent = h.robot && h.robot.link === 'serial' ? `ROBOT · ${h.robot.port || 'serial'}` : (where || '').toUpperCase();
  $('robot-badge').dataset.link = (h.robot && h.robot.link) || '';
  $('robot-badge').hidden = !where;
  $('learn-target').textContent = h.signals.gate_prediction ? `gate: “${h.signals.gate_prediction}”` : '';
  applyLimits(state, paramLimits(h.signals.bounds, h.signals.gate_prediction));
  // The counters count stimulus onsets and time with the stimulus on: stalls, or gesture commands.
  const kind = cfg.control && cfg.control.stimulus ? cfg.control.stimulus.kind : 'stall';
  const stall = kind === 'stall';
  $('c-stalls-label').textContent = stall ? 'Stall events' : 'Stimulus onsets';
  $('c-stalled-label').textContent = stall ? 'Time stalled' : 'Time with stimulus';
  labelRequest(kind);
  $('watch-banner').hidden = h.can_command;
  document.body.classList.toggle('watch-only', !h.can_command);
  renderAuthority();
  const inForce = h.in_force || {};
  state.params = Object.fromEntries((inForce.params || []).map((p) => [p.prediction, p]));
  state.recording = inForce.recording ?? null;
  renderInForce(state);
  renderRecording(state);
  setConn('live', h.can_command ? `live · ${h.rate_hz} Hz` : `live · ${h.rate_hz} Hz · watch-only`);
  setLive(true);
  charts.build(h.signals.predictions, h.tick_period_ms / 1000);
  state.elbow.configure(h);
  state.learning.configure(h);
  state.learning.setParams(state.params);
  state.horde.configure(h);
  log(`connected to ${h.server} (protocol ${h.protocol})`);
}

function onHistory(msg) {
  const samples = samplesFromHistory(msg);
  timeline.merge(samples);
  state.elbow.see(samples.find((x) => x.elbow));
  state.learning.history(samples, state.hello ? state.hello.signals.predictions : []);
  for (const e of Array.isArray(msg.events) ? msg.events : []) onEvent(e, true);
  charts.touch();
  if (msg.more === false) {
    state.historyDone = true;
    const [first, last] = [timeline.samples[0], timeline.last];
    if (first && last) log(`history: ${fmt(last.t - first.t, 0)} s before connecting`);
  }
}

/** An event: a marker on the charts, and, live, what is in force. History events are labelled on their own. */
function onEvent(e, fromHistory) {
  if (typeof e.t !== 'number' || typeof e.id !== 'number') return;
  const known = fromHistory ? state.historyParams : state.params;
  const label = markerLabel(e, e.prediction ? known[e.prediction] || null : null);
  const after = applyParams(known, e);
  if (fromHistory) state.historyParams = after;
  else state.params = after;
  if (!timeline.addEvent({ ...e, label })) return;
  charts.touch();
  // A storage failure in the history still shows (the recording in force came with hello).
  const storage = applyStorageEvent(state.storage, e);
  if (storage !== state.storage) {
    state.storage = storage;
    renderRecording(state);
    renderCheckpoint(state);
  }
  if (fromHistory) return;
  if (e.kind === 'recording_stopped' && e.reason) log(`recording stopped: ${e.reason}`, 'error');
  if (e.kind === 'checkpoint_failed') log(`checkpoint not written: ${e.reason}`, 'error');
  if (e.kind === 'params_set') {
    renderInForce(state);
    state.learning.setParams(state.params);
  }
  if (e.kind === 'recording_started') state.recording = e.path;
  if (e.kind === 'recording_stopped') state.recording = null;
  if (e.kind.startsWith('recording_')) renderRecording(state);
  if (label) log(`⚑ ${label}${e.prediction ? ` (${e.prediction})` : ''}`);
}

function onTick(t) {
  state.ticks += 1;
  state.gaps.see(t.seq, state.stride);
  state.last = t;
  state.dirty = true;
  const sample = sampleFromTick(t);
  if (timeline.push(sample)) charts.touch();
  state.elbow.see(sample);
  state.elbow.push(t);
  state.learning.tick(t);
  if (state.mode !== t.mode) {
    state.mode = t.mode;
    for (const b of document.querySelectorAll('.mode')) {
      const on = b.dataset.mode === t.mode;
      b.classList.toggle('active', on);
      b.setAttribute('aria-checked', String(on));
    }
    document.body.classList.toggle('manual', t.mode === 'manual');
    $('teleop-hint').textContent = t.mode === 'manual' ? 'driving enabled' : 'switch to Manual to drive';
  }
  if (state.estop !== t.estop) {
    state.estop = t.estop;
    $('estop-banner').hidden = !t.estop;
    document.body.classList.toggle('estopped', t.estop);
  }
}

function onAck(a) {
  state.pending.delete(a.id);
  if (a.cmd === 'set_params') showParamsError(null);
  if (a.cmd === 'teleop') return;
  const detail = a.result && Object.keys(a.result).length ? ` ${JSON.stringify(a.result)}` : '';
  log(`✓ ${a.cmd}${detail}`, 'ok');
}

function onError(e) {
  const cmd = state.pending.get(e.id);
  state.pending.delete(e.id);
  // The server's refusal (e.g. α beyond α·‖x‖² ≤ 1) is shown next to the form; nothing was changed.
  if (cmd === 'set_params') showParamsError(`refused: ${e.message}`);
  log(`✗ ${cmd ? `${cmd}: ` : ''}${e.message}`, 'error');
}

// ---------------------------------------------------------------- the charts' toolbar

/** The toolbar says what the charts show: live or paused, the window, the zoom. */
function renderView() {
  const v = charts.view;
  $('pause').textContent = v.paused ? 'Resume' : 'Pause';
  $('pause').setAttribute('aria-pressed', String(v.paused));
  for (const b of document.querySelectorAll('.window')) b.classList.toggle('active', Number(b.dataset.seconds) === v.seconds);
  $('zoom-reset').hidden = !v.zoom;
  const span = charts.visible();
  const range = `${fmt(span.min, 1)}–${fmt(span.max, 1)} s`;
  $('view-state').textContent = v.zoom ? `zoomed ${range} · paused` : (v.paused ? `paused at ${fmt(v.to, 1)} s` : 'live');
  document.body.classList.toggle('paused', v.paused);
}

/** Downloads the ticks (and event labels) of the time span on screen as CSV, made in the page. */
function downloadCsv() {
  const { min, max } = charts.visible();
  const names = state.hello ? state.hello.signals.predictions : [];
  const csv = toCsv(timeline.between(min, max), names, timeline.eventsBetween(min, max));
  const url = URL.createObjectURL(new Blob([csv], { type: 'text/csv' }));
  const a = document.createElement('a');
  a.href = url;
  a.download = `pavlov-${Math.max(0, min).toFixed(1)}-${max.toFixed(1)}s.csv`;
  document.body.append(a);
  a.click();
  a.remove();
  setTimeout(() => URL.revokeObjectURL(url), 10000);
  log(`CSV of ${fmt(min, 1)}–${fmt(max, 1)} s downloaded`);
}

// ---------------------------------------------------------------- start

function frame() {
  charts.draw();
  state.learning.render(charts.visible());
  state.horde.render();
  if (state.dirty) {
    state.dirty = false;
    state.elbow.render();
    renderNow(state);
  }
  requestAnimationFrame(frame);
}

if (typeof window.uPlot !== 'function') {
  const b = $('vendor-banner');
  b.hidden = false;
  b.textContent = 'Charts unavailable: the server could not serve the uPlot library (web/node_modules is missing). '
    + 'Run `npm ci --prefix web` in the repository and restart the server.';
  for (const el of document.querySelectorAll('.chart')) el.classList.add('unavailable');
}
/** The first-run note: shown until dismissed once (remembered in this browser's localStorage). */
const FIRST_RUN_KEY = 'pavlov.firstRunNoteDismissed';
function firstRunNote() {
  let dismissed = false;
  try {
    dismissed = window.localStorage.getItem(FIRST_RUN_KEY) === '1';
  } catch (e) {
    dismissed = false;
  }
  $('first-run').hidden = dismissed;
  $('first-run-close').addEventListener('click', () => {
    $('first-run').hidden = true;
    try {
      window.localStorage.setItem(FIRST_RUN_KEY, '1');
    } catch (e) {
      // Storage refused (a private window): the note goes for this visit only.
    }
  });
}

for (const b of document.querySelectorAll('.mode, #request, #release, #rearm, .key, .card button, #p-apply')) {
  b.dataset.title = b.title;
}
renderMarkerLegend($('marker-legend'));
firstRunNote();
wireControls({
  state, send, log, charts, aligned, downloadCsv, showParamsError,
});
renderView();
setLive(false, 'connecting');
connect();
requestAnimationFrame(frame);

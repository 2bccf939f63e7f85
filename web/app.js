// The pavlov dashboard: connects to /ws (PROTOCOL.md), draws live strip charts with uPlot, shows the
// run counters and tick health, and sends commands (mode, e-stop, teleop, request, learning, recording).

import {
  Backoff, GapCounter, Window, alignedData, connectionTarget, fmt, fmtDuration, fmtLead, paramLimits, parseParam, teleopWheels, tokenFromHash,
} from './lib.js';
import { ElbowPanel } from './elbow.js';

const WINDOW_SECONDS = 30;
const TELEOP_REPEAT_MS = 200;
const CHART_HEIGHT = 175;
const ALIGNED_HEIGHT = 160;
const REACTIVE_COLOR = '#d97706';
const PAVLOVIAN_COLOR = '#2563eb';
const COLORS = ['#2563eb', '#d97706', '#059669', '#7c3aed', '#db2777', '#0891b2'];

const $ = (id) => document.getElementById(id);

const state = {
  ws: null,
  hello: null,
  limits: paramLimits(null, null),
  canCommand: false,
  connected: false,
  nextId: 1,
  pending: new Map(),
  ticks: 0,
  last: null,
  gaps: new GapCounter(),
  stride: 1,
  charts: [],
  aligned: null,
  dirty: false,
  mode: null,
  estop: false,
  held: new Set(),
  teleopTimer: null,
  backoff: new Backoff(),
};
// The gesture experiment's elbow chart and skeleton status (elbow.js).
state.elbow = new ElbowPanel({
  card: $('elbow-card'), chart: $('chart-elbow'), status: $('now-skeleton'), banner: $('skeleton-banner'),
  windowSeconds: WINDOW_SECONDS, height: CHART_HEIGHT,
});
// Exposed for the end-to-end test and for poking around in the console.
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
    state.connected = false;
    state.ws = null;
    failPending('the connection closed');
    if (ev.code !== 1000 && ev.code !== 1005) log(`connection closed (${ev.code}${ev.reason ? `: ${ev.reason}` : ''})`, 'warn');
    scheduleReconnect();
  };
}

function scheduleReconnect() {
  const delay = state.backoff.next();
  let left = Math.ceil(delay / 1000);
  setConn('down', `disconnected — retrying in ${left} s`);
  const timer = setInterval(() => {
    left -= 1;
    if (left > 0) setConn('down', `disconnected — retrying in ${left} s`);
  }, 1000);
  setTimeout(() => {
    clearInterval(timer);
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
    case 'tick': return onTick(msg);
    case 'status': return onStatus(msg);
    case 'ack': return onAck(msg);
    case 'error': return onError(msg);
    default: return undefined;
  }
}

function onHello(h) {
  state.hello = h;
  state.canCommand = h.can_command;
  state.gaps = new GapCounter();
  state.stride = 1;
  const cfg = h.config || {};
  const model = cfg.robot ? cfg.robot.model : '';
  $('robot-name').textContent = `${h.server} · ${model ? `${model} · ` : ''}${h.tick_period_ms} ms ticks`;
  $('learn-target').textContent = h.signals.gate_prediction ? `prediction “${h.signals.gate_prediction}”` : '';
  applyLimits(paramLimits(h.signals.bounds, h.signals.gate_prediction));
  // The counters count stimulus onsets and time with the stimulus on: stalls, or gesture commands.
  const stall = !(cfg.control && cfg.control.stimulus && cfg.control.stimulus.kind !== 'stall');
  $('c-stalls-label').textContent = stall ? 'Stall events' : 'Stimulus onsets';
  $('c-stalled-label').textContent = stall ? 'Time stalled' : 'Time with stimulus';
  $('watch-banner').hidden = h.can_command;
  document.body.classList.toggle('watch-only', !h.can_command);
  setConn('live', h.can_command ? `live · ${h.rate_hz} Hz` : `live · ${h.rate_hz} Hz · watch-only`);
  buildCharts(h.signals.predictions);
  state.elbow.configure(h);
  log(`connected to ${h.server} (protocol ${h.protocol})`);
}

/** The learning form uses the server's bounds (hello.signals.bounds): input min/max and a hint. */
function applyLimits(limits) {
  state.limits = limits;
  for (const [key, id] of [['alpha', 'p-alpha'], ['lambda', 'p-lambda'], ['threshold', 'p-threshold']]) {
    const input = $(id);
    input.min = String(limits[key].lo);
    input.max = String(limits[key].hi);
    input.title = limits[key].hint;
  }
  $('params-bounds').textContent = `${limits.alpha.hint} · ${limits.lambda.hint}`;
  showParamsError(null);
}

function showParamsError(message) {
  const el = $('params-error');
  el.hidden = !message;
  el.textContent = message || '';
  el.style.color = message ? 'var(--alarm)' : '';
}

function onTick(t) {
  state.ticks += 1;
  state.gaps.see(t.seq, state.stride);
  state.last = t;
  state.dirty = true;
  pushCharts(t);
  state.elbow.push(t);
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

function renderNow() {
  const t = state.last;
  if (!t) return;
  $('seq').textContent = fmt(t.seq);
  $('runtime').textContent = fmtDuration(t.t);
  $('now-mode').textContent = t.mode;
  $('now-gate').textContent = t.gate ? 'response ϱ' : 'default π';
  $('now-gate').className = t.gate ? 'on' : '';
  $('now-stimulus').textContent = t.stimulus ? 'ON' : 'off';
  $('now-stimulus').className = t.stimulus ? 'alarm' : '';
  $('now-command').textContent = `${t.command.left} / ${t.command.right} mm/s`;
  $('now-safety').textContent = t.safety_stop ? t.safety_stop.replace(/_/g, ' ') : 'none';
  $('now-safety').className = t.safety_stop ? 'alarm' : '';
  $('tick-count').textContent = fmt(state.ticks);
  $('h-frames').textContent = `${fmt(t.link.good_frames)} / ${fmt(t.link.bad_frames)}`;
  renderLink(t.link);
}

const OI_MODES = ['Off', 'Passive', 'Safe', 'Full'];
const LINK_WORDS = {
  stale: 'Robot stream stale — wheels stopped, re-sending Start and Stream.',
  reconnecting: 'Robot link lost — wheels stopped, reopening the port.',
  down: 'Robot link down.',
};

function renderLink(link) {
  const st = link.state || (link.up ? 'up' : 'down');
  $('h-link').textContent = st === 'up' ? `up · ${fmt(link.skipped_bytes)} B skipped` : st.toUpperCase();
  $('h-link').className = st === 'up' ? '' : 'alarm';
  $('h-mode').textContent = link.mode == null ? '—' : (OI_MODES[link.mode] || String(link.mode));
  $('h-reconnects').textContent = `${fmt(link.stale_events || 0)} / ${fmt(link.reconnects || 0)}`;
  const tripped = st === 'tripped';
  $('trip-banner').hidden = !tripped;
  if (tripped) $('trip-cause').textContent = (link.trip || 'unknown').replace(/_/g, ' ');
  const words = LINK_WORDS[st];
  $('link-banner').hidden = !words;
  if (words) $('link-banner').textContent = words;
}

function onStatus(s) {
  const h = s.health;
  const c = s.counters;
  $('c-overcurrent').textContent = fmt(c.overcurrent_observations);
  $('c-stalls').textContent = fmt(c.stall_events);
  $('c-stalled').textContent = fmt(c.time_stalled_s, 1, 's');
  $('c-distance').textContent = fmt(c.distance_m, 2, 'm');
  $('c-energy').textContent = fmt(c.energy_j, 0, 'J');
  $('c-efficiency').textContent = fmt(c.efficiency_m_per_kj, 2, 'm/kJ');
  $('h-lateness').textContent = `${fmt(h.lateness_p50_us)} / ${fmt(h.lateness_p99_us)} µs`;
  $('h-lateness-max').textContent = fmt(h.lateness_max_us, 0, 'µs');
  $('h-skipped').textContent = `${fmt(h.ticks_skipped)} of ${fmt(h.ticks_fired + h.ticks_skipped)}`;
  $('h-skipped').className = h.ticks_skipped > 0 ? 'warn' : '';
  $('h-t2c').textContent = fmt(h.tick_to_command_p99_us, 0, 'µs');
  $('h-missed').textContent = `${fmt(state.gaps.missing)} / ${fmt(s.clients)}`;
  const i = s.interaction;
  $('commands-group').hidden = !i;
  if (i) {
    $('i-commands').textContent = `${fmt(i.commands)} (${fmt(i.missed)} missed)`;
    $('i-early').textContent = fmt(i.early);
    $('i-lead').textContent = fmtLead(i.mean_lead_ms);
    $('i-current-lead').textContent = fmtLead(i.mean_current_lead_ms);
    $('i-motion-lead').textContent = fmtLead(i.mean_motion_lead_ms);
    $('i-false-starts').textContent = fmt(i.false_starts);
  }
  if (!i) hideAligned();
  else if (i.aligned) showAligned(alignedData(i.aligned));
}

function onAck(a) {
  state.pending.delete(a.id);
  if (a.cmd === 'set_params') showParamsError(null);
  if (a.cmd === 'start_recording') $('rec-state').textContent = 'on';
  if (a.cmd === 'stop_recording') $('rec-state').textContent = 'off';
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

// ---------------------------------------------------------------- charts

function axis(label, extra = {}) {
  return {
    label, labelSize: 16, size: 52, stroke: '#5b6474', font: '11px system-ui, sans-serif',
    labelFont: '11px system-ui, sans-serif', grid: { stroke: '#eef1f5', width: 1 }, ticks: { stroke: '#d9dee7' }, ...extra,
  };
}

function makeChart(el, series, yOpts = {}, axisOpts = {}) {
  const rect = el.getBoundingClientRect();
  const opts = {
    width: Math.max(300, Math.floor(rect.width)),
    height: CHART_HEIGHT,
    cursor: { drag: { x: false, y: false } },
    legend: { live: false },
    scales: { x: { time: false }, y: yOpts },
    axes: [axis('', { size: 28, values: (u, v) => v.map((s) => `${s}s`) }), axis(axisOpts.label || '', axisOpts)],
    series: [{ label: 't' }, ...series],
  };
  const capacity = Math.round((WINDOW_SECONDS * 1000) / ((state.hello && state.hello.tick_period_ms) || 20));
  const win = new Window(series.length, capacity);
  const u = new window.uPlot(opts, win.data(), el);
  return { u, win, el };
}

const EVENT_LANES = ['over-current R', 'over-current L', 'e-stop', 'gate', 'stimulus'];

function buildCharts(predictionNames) {
  for (const c of state.charts) c.u.destroy();
  state.charts = [];
  if (typeof window.uPlot !== 'function') return;
  const predSeries = [];
  predictionNames.forEach((name, i) => {
    const color = COLORS[i % COLORS.length];
    predSeries.push({ label: name, stroke: color, width: 2 });
    predSeries.push({ label: `θ ${name}`, stroke: color, width: 1, dash: [6, 4] });
  });
  const lane = (i, color) => ({
    label: EVENT_LANES[i], stroke: color, width: 1.5, fill: `${color}40`, fillTo: () => i, paths: window.uPlot.paths.stepped({ align: 1 }),
  });
  state.charts = [
    { kind: 'pred', ...makeChart($('chart-pred'), predSeries, { range: (u, lo, hi) => [Math.min(0, lo ?? 0), Math.max(1, hi ?? 1)] }) },
    {
      kind: 'events',
      ...makeChart($('chart-events'), [lane(0, '#ea580c'), lane(1, '#f59e0b'), lane(2, '#111827'), lane(3, '#2563eb'), lane(4, '#dc2626')],
        { range: [-0.2, EVENT_LANES.length] },
        { size: 96, splits: () => EVENT_LANES.map((_, i) => i + 0.4), values: () => EVENT_LANES, grid: { show: false } }),
    },
    { kind: 'current', ...makeChart($('chart-current'), [{ label: 'battery current', stroke: '#0891b2', width: 1.5, fill: '#0891b21a' }],
      { range: (u, lo, hi) => [Math.min(-500, Math.floor(((lo ?? 0) * 1.1) / 100) * 100), Math.max(0, hi ?? 0)] }, { label: 'mA' }) },
    {
      kind: 'wheels',
      ...makeChart($('chart-wheels'), [
        { label: 'left', stroke: '#2563eb', width: 2 },
        { label: 'right', stroke: '#d97706', width: 2 },
        { label: 'π left', stroke: '#93c5fd', width: 1, dash: [5, 4] },
        { label: 'π right', stroke: '#fcd34d', width: 1, dash: [5, 4] },
      ], { range: (u, lo, hi) => [Math.min(-100, lo ?? 0), Math.max(100, hi ?? 0)] }, { label: 'mm/s' }),
    },
  ];
}

// The aligned averages (paper, Figure 4): two small charts drawn from `interaction.aligned`, replaced whole
// about once a second; hidden when the run has no interaction metrics.

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

function hideAligned() {
  $('aligned-card').hidden = true;
  if (state.aligned) {
    state.aligned.current.destroy();
    state.aligned.rotation.destroy();
    state.aligned = null;
  }
}

function showAligned(data) {
  if (!data) return;
  $('aligned-card').hidden = false;
  $('aligned-hint').textContent = `mean per tick, 0 s = stimulus onset · reactive (orange): ${fmt(data.counts.reactive)} · `
    + `Pavlovian (blue): ${fmt(data.counts.pavlovian)} commands`;
  if (typeof window.uPlot !== 'function') return;
  if (!state.aligned) {
    state.aligned = {
      current: makeAlignedChart($('chart-aligned-current'), 'current mA',
        (u, lo, hi) => [Math.min(-500, Math.floor(((lo ?? 0) * 1.1) / 100) * 100), Math.max(0, hi ?? 0)]),
      rotation: makeAlignedChart($('chart-aligned-rotation'), 'rotation °/tick',
        (u, lo, hi) => [Math.min(-1, lo ?? 0), Math.max(1, Math.ceil((hi ?? 0) * 1.1))]),
    };
  }
  state.aligned.current.setData(data.current);
  state.aligned.rotation.setData(data.rotation);
}

function pushCharts(t) {
  if (state.charts.length === 0) return;
  const flag = (lane, on) => lane + (on ? 0.8 : 0);
  for (const c of state.charts) {
    switch (c.kind) {
      case 'pred':
        c.win.push(t.t, t.predictions.flatMap((p) => [p.value, p.threshold]));
        break;
      case 'events':
        c.win.push(t.t, [
          flag(0, t.sensors.overcurrent_right), flag(1, t.sensors.overcurrent_left),
          flag(2, t.estop), flag(3, t.gate), flag(4, t.stimulus),
        ]);
        break;
      case 'current':
        c.win.push(t.t, [t.sensors.battery_current_ma]);
        break;
      case 'wheels':
        c.win.push(t.t, [t.command.left, t.command.right, t.default.left, t.default.right]);
        break;
      default:
    }
  }
}

function frame() {
  if (state.dirty) {
    state.dirty = false;
    for (const c of state.charts) c.u.setData(c.win.data());
    state.elbow.render();
    renderNow();
  }
  requestAnimationFrame(frame);
}

function resizeCharts() {
  state.elbow.resize();
  for (const c of state.charts) {
    const r = c.el.getBoundingClientRect();
    c.u.setSize({ width: Math.max(300, Math.floor(r.width)), height: CHART_HEIGHT });
  }
  if (state.aligned) {
    for (const [u, id] of [[state.aligned.current, 'chart-aligned-current'], [state.aligned.rotation, 'chart-aligned-rotation']]) {
      u.setSize({ width: Math.max(200, Math.floor($(id).getBoundingClientRect().width)), height: ALIGNED_HEIGHT });
    }
  }
}

// ---------------------------------------------------------------- controls

function teleopUpdate() {
  if (state.held.size === 0) {
    clearInterval(state.teleopTimer);
    state.teleopTimer = null;
    if (state.mode === 'manual') send('teleop', { left_mm_s: 0, right_mm_s: 0 });
    return;
  }
  if (state.mode !== 'manual') {
    log('teleop needs Manual mode', 'warn');
    state.held.clear();
    return;
  }
  const speed = Number($('speed').value);
  const tick = () => send('teleop', teleopWheels(state.held, speed));
  tick();
  if (!state.teleopTimer) state.teleopTimer = setInterval(tick, TELEOP_REPEAT_MS);
}

function hold(dir, on) {
  if (dir === 'stop') {
    state.held.clear();
    teleopUpdate();
    return;
  }
  const had = state.held.has(dir);
  if (on && !had) state.held.add(dir);
  else if (!on && had) state.held.delete(dir);
  else return;
  if (state.teleopTimer) {
    clearInterval(state.teleopTimer);
    state.teleopTimer = null;
  }
  teleopUpdate();
}

const KEYS = { ArrowUp: 'up', ArrowDown: 'down', ArrowLeft: 'left', ArrowRight: 'right' };

function wireControls() {
  $('estop').addEventListener('click', () => send('estop'));
  $('release').addEventListener('click', () => send('release'));
  $('rearm').addEventListener('click', () => send('rearm'));
  $('request').addEventListener('click', () => send('human_request', { duration_ms: 500 }));
  for (const b of document.querySelectorAll('.mode')) {
    b.addEventListener('click', () => send('set_mode', { mode: b.dataset.mode }));
  }
  for (const k of document.querySelectorAll('.key')) {
    const dir = k.dataset.dir;
    k.addEventListener('pointerdown', (e) => { e.preventDefault(); hold(dir, true); });
    for (const ev of ['pointerup', 'pointerleave', 'pointercancel']) k.addEventListener(ev, () => hold(dir, false));
  }
  document.addEventListener('keydown', (e) => {
    if (e.target instanceof HTMLInputElement) return;
    if (e.key === 'Escape') { send('estop'); e.preventDefault(); return; }
    const dir = KEYS[e.key];
    if (dir) { e.preventDefault(); if (!e.repeat) hold(dir, true); }
  });
  document.addEventListener('keyup', (e) => {
    const dir = KEYS[e.key];
    if (dir) hold(dir, false);
  });
  window.addEventListener('blur', () => { if (state.held.size) { state.held.clear(); teleopUpdate(); } });
  $('speed').addEventListener('input', () => { $('speed-value').textContent = `${$('speed').value} mm/s`; });
  $('params').addEventListener('submit', (e) => {
    e.preventDefault();
    const l = state.limits;
    const field = (key, id, name) => [key, parseParam($(id).value, name, l[key].lo, l[key].hi, l[key].loOpen)];
    const fields = [field('alpha', 'p-alpha', 'α'), field('lambda', 'p-lambda', 'λ'), field('threshold', 'p-threshold', 'θ')];
    const bad = fields.find(([, r]) => r.error);
    if (bad) { showParamsError(bad[1].error); log(bad[1].error, 'error'); return; }
    const args = Object.fromEntries(fields.filter(([, r]) => r.value !== undefined).map(([k, r]) => [k, r.value]));
    if (Object.keys(args).length === 0) { log('enter α, λ or θ first', 'warn'); return; }
    send('set_params', args);
  });
  $('reset-weights').addEventListener('click', () => {
    if (window.confirm('Reset every prediction’s weights to their initial values?')) send('reset_weights');
  });
  $('save-weights').addEventListener('click', () => send('save_weights'));
  $('rec-start').addEventListener('click', () => send('start_recording'));
  $('rec-stop').addEventListener('click', () => send('stop_recording'));
  let resizeTimer = null;
  window.addEventListener('resize', () => { clearTimeout(resizeTimer); resizeTimer = setTimeout(resizeCharts, 100); });
}

// ---------------------------------------------------------------- start

if (typeof window.uPlot !== 'function') {
  const b = $('vendor-banner');
  b.hidden = false;
  b.textContent = 'Charts unavailable: the server could not serve the uPlot library (web/node_modules is missing). '
    + 'Run `npm ci --prefix web` in the repository and restart the server.';
  for (const el of document.querySelectorAll('.chart')) el.classList.add('unavailable');
}
wireControls();
connect();
requestAnimationFrame(frame);

// The dashboard's controls: the E-STOP (button and Esc), the mode switch, teleop by buttons and arrow keys,
// the request button, the learning form, weights and recording buttons, and the charts' toolbar (pause,
// window, zoom reset, CSV). Each sends a command through `send` (app.js) or changes the charts' view.

import { WINDOWS, parseParam, teleopWheels } from './lib.js';

const TELEOP_REPEAT_MS = 200;
const KEYS = { ArrowUp: 'up', ArrowDown: 'down', ArrowLeft: 'left', ArrowRight: 'right' };

const $ = (id) => document.getElementById(id);

/**
 * Wires every control. `ctx` holds the page's `state`, `send(cmd, args)`, `log(text, kind)`, the `charts`
 * and the `aligned` charts, `downloadCsv()` and `showParamsError(message)`.
 */
export function wireControls(ctx) {
  const { state, send, log, charts } = ctx;

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
    if (e.key === 'Escape') {
      e.preventDefault();
      if (state.live && !state.canCommand) log('E-STOP: needs the operator\'s token (this page only watches)', 'warn');
      else send('estop');
      return;
    }
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
    if (bad) { ctx.showParamsError(bad[1].error); log(bad[1].error, 'error'); return; }
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

  // The charts' toolbar.
  $('pause').addEventListener('click', () => (charts.view.paused ? charts.resume() : charts.pause()));
  $('zoom-reset').addEventListener('click', () => charts.resetZoom());
  $('csv').addEventListener('click', () => ctx.downloadCsv());
  const windows = $('windows');
  for (const w of WINDOWS) {
    const b = document.createElement('button');
    b.type = 'button';
    b.className = 'window';
    b.dataset.seconds = String(w.seconds);
    b.textContent = w.label;
    b.addEventListener('click', () => charts.setWindow(w.seconds));
    windows.append(b);
  }

  let resizeTimer = null;
  window.addEventListener('resize', () => {
    clearTimeout(resizeTimer);
    resizeTimer = setTimeout(() => {
      charts.resize();
      charts.draw(true);
      ctx.aligned.resize();
    }, 100);
  });
}

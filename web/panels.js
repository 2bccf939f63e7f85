// The dashboard's panels: the header (which robot), the Now, Counters, Tick health and Learning cards,
// the recording card (and a storage failure's reason), and the link banners, drawn from the messages app.js
// receives (PROTOCOL.md).

import {
  alignedData, fmt, fmtDuration, fmtOnset, fmtParam, gateText, recordingView, tokenFromHash,
} from './lib.js';

const $ = (id) => document.getElementById(id);

const ROBOT_LINKS = { simulated: 'simulated robot', external: 'external link' };

export function robotText(robot) {
  if (!robot) return '';
  if (robot.link === 'serial') return `serial port ${robot.port || '?'}`;
  return ROBOT_LINKS[robot.link] || robot.link || '';
}


/**
 * The Request button forces the stimulus on, as a human request would. In the gesture experiment that is a
 * human command; anywhere else it forces what the stimulus stands for (a stall), so it must not say
 * "human".
 */
export function labelRequest(kind) {
  const b = $('request');
  if (kind === 'left_elbow') {
    b.textContent = 'Request';
    b.title = 'Inject a human command request for 0.5 s, as if the gesture had been seen';
  } else {
    b.textContent = 'Force stimulus';
    b.title = `Force the stimulus (${kind}) on for 0.5 s: the response runs as if it had been detected`;
  }
}


/** The learning form uses the server's bounds (hello.signals.bounds): input min/max and a hint. */
export function applyLimits(state, limits) {
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

export function showParamsError(message) {
  const el = $('params-error');
  el.hidden = !message;
  el.textContent = message || '';
  el.style.color = message ? 'var(--alarm)' : '';
}

/** The Learning card's table of the parameters in force, one row per prediction (the gate's marked). */
export function renderInForce(state) {
  const body = $('inforce-body');
  body.replaceChildren();
  const gate = state.hello ? state.hello.signals.gate_prediction : null;
  for (const p of Object.values(state.params)) {
    const tr = document.createElement('tr');
    tr.className = p.prediction === gate ? 'gate' : '';
    for (const text of [p.prediction, fmtParam(p.alpha), fmtParam(p.lambda), fmtParam(p.threshold)]) {
      const td = document.createElement('td');
      td.textContent = text;
      tr.append(td);
    }
    body.append(tr);
  }
  const g = state.params[gate];
  if (g) {
    $('p-alpha').placeholder = fmtParam(g.alpha);
    $('p-lambda').placeholder = fmtParam(g.lambda);
    $('p-threshold').placeholder = fmtParam(g.threshold);
  }
}

/**
 * The recording badge (on, off, or stopped by a failure to write it, with the reason under it), and the
 * download link for an operator while one is being written.
 */
export function renderRecording(state) {
  const view = recordingView(state.recording, state.storage ? state.storage.recordingFailure : null);
  const badge = $('rec-state');
  badge.textContent = view.badge;
  badge.classList.toggle('alarm', view.alarm);
  const notice = $('rec-error');
  notice.hidden = !view.notice;
  notice.textContent = view.notice || '';
  const a = $('rec-download');
  const show = !!state.recording && state.canCommand;
  a.hidden = !show;
  if (show) {
    const token = tokenFromHash(window.location.hash);
    a.href = token ? `/recording?token=${encodeURIComponent(token)}` : '/recording';
  }
}

/** The reason the latest checkpoint or save could not be written, under the weights buttons, until one is. */
export function renderCheckpoint(state) {
  const failure = state.storage ? state.storage.checkpointFailure : null;
  const notice = $('weights-error');
  notice.hidden = !failure;
  notice.textContent = failure ? `Checkpoint not written: ${failure}` : '';
}

export function renderNow(state) {
  const t = state.last;
  if (!t || !t.link) return;
  $('seq').textContent = fmt(t.seq);
  $('runtime').textContent = fmtDuration(t.t);
  $('now-mode').textContent = t.mode;
  $('now-gate').textContent = gateText(t);
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

export function renderStatus(state, s, aligned) {
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
    $('i-lead').textContent = fmtOnset(i.mean_lead_ms);
    $('i-current-lead').textContent = fmtOnset(i.mean_current_lead_ms);
    $('i-motion-lead').textContent = fmtOnset(i.mean_motion_lead_ms);
    $('i-false-starts').textContent = fmt(i.false_starts);
  }
  if (!i) aligned.hide();
  else if (i.aligned) aligned.show(alignedData(i.aligned));
}

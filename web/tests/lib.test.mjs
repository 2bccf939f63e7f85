// Unit tests of the dashboard's pure helpers (web/lib.js): `npm test --prefix web`.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import {
  Backoff, GapCounter, SUBPROTOCOL, Timeline, WINDOWS, alignedData, applyParams, applyStorageEvent, columns, connectionTarget, fmt, fmtDuration,
  fmtOnset, fmtParam, gateText, markerLabel, paramLimits, parseParam, redrawIntervalMs, sampleFromTick, samplesFromHistory, sensorsLive,
  recordingView, teleopWheels, toCsv, tokenFromHash, MARKER_KINDS, elbowAngles, layoutMarkerLabels, markerColor, markerKind,
} from '../lib.js';

test('the token comes from the URL fragment', () => {
  assert.equal(tokenFromHash('#token=abc123'), 'abc123');
  assert.equal(tokenFromHash('#x=1&token=a%2Fb'), 'a/b');
  assert.equal(tokenFromHash(''), null);
  assert.equal(tokenFromHash('#token='), null);
});

test('the websocket target follows the page and carries the token safely', () => {
  const page = { protocol: 'http:', host: '127.0.0.1:8080' };
  assert.deepEqual(connectionTarget(page, null), { url: 'ws://127.0.0.1:8080/ws', protocols: [SUBPROTOCOL] });
  assert.deepEqual(connectionTarget(page, 'k3y-_.'), { url: 'ws://127.0.0.1:8080/ws', protocols: [SUBPROTOCOL, 'token.k3y-_.'] });
  // Characters a subprotocol cannot carry go in the query string instead.
  assert.deepEqual(connectionTarget(page, 'a b/c'), { url: 'ws://127.0.0.1:8080/ws?token=a%20b%2Fc', protocols: [SUBPROTOCOL] });
  assert.equal(connectionTarget({ protocol: 'https:', host: 'lab:443' }, null).url, 'wss://lab:443/ws');
});

test('reconnect delays double up to the cap and reset', () => {
  const b = new Backoff(500, 4000);
  assert.deepEqual([b.next(), b.next(), b.next(), b.next(), b.next()], [500, 1000, 2000, 4000, 4000]);
  b.reset();
  assert.equal(b.next(), 500);
});

test('teleop keys become wheel speeds', () => {
  const s = (...k) => new Set(k);
  assert.deepEqual(teleopWheels(s(), 200), { left_mm_s: 0, right_mm_s: 0 });
  assert.deepEqual(teleopWheels(s('up'), 200), { left_mm_s: 200, right_mm_s: 200 });
  assert.deepEqual(teleopWheels(s('down'), 200), { left_mm_s: -200, right_mm_s: -200 });
  assert.deepEqual(teleopWheels(s('left'), 150), { left_mm_s: -150, right_mm_s: 150 });
  assert.deepEqual(teleopWheels(s('right'), 150), { left_mm_s: 150, right_mm_s: -150 });
  assert.deepEqual(teleopWheels(s('up', 'left'), 200), { left_mm_s: 80, right_mm_s: 200 });
  assert.deepEqual(teleopWheels(s('up', 'down'), 200), { left_mm_s: 0, right_mm_s: 0 });
  assert.deepEqual(teleopWheels(s('up'), 9000), { left_mm_s: 500, right_mm_s: 500 });
});

test('gaps in the tick sequence are counted, allowing for the stride', () => {
  const g = new GapCounter();
  for (const seq of [1, 2, 3, 6, 7]) g.see(seq);
  assert.equal(g.missing, 2);
  const d = new GapCounter();
  for (const seq of [0, 5, 10, 20]) d.see(seq, 5);
  assert.equal(d.missing, 5);
});

test('formatting', () => {
  assert.equal(fmt(1234.567, 1, 'm'), '1,234.6 m');
  assert.equal(fmt(null), '—');
  assert.equal(fmt(Number.NaN, 2), '—');
  assert.equal(fmtDuration(65), '1:05');
  assert.equal(fmtDuration(3725), '1:02:05');
  assert.equal(fmtDuration(undefined), '—');
});

test('learning parameters are checked before they are sent', () => {
  assert.deepEqual(parseParam('', 'α', 0, 1), { value: undefined });
  assert.deepEqual(parseParam(' 0.1 ', 'α', 0, 1), { value: 0.1 });
  assert.match(parseParam('abc', 'α', 0, 1).error, /number/);
  assert.match(parseParam('2', 'λ', 0, 1).error, /between 0 and 1/);
  // An open lower bound: α > 0.
  assert.match(parseParam('0', 'α', 0, 0.5, true).error, /above 0 and at most 0.5/);
  assert.deepEqual(parseParam('0.5', 'α', 0, 0.5, true), { value: 0.5 });
});

test('the form takes its limits from the server\'s bounds', () => {
  const bounds = {
    predictions: [{ name: 'stall', active_features: 44, features: 440, max_alpha: 1 / 44, min_lambda: 0, max_lambda: 1 }],
    max_request_ms: 10000,
  };
  const l = paramLimits(bounds, 'stall');
  assert.equal(l.alpha.hi, 1 / 44);
  assert.equal(l.alpha.loOpen, true);
  assert.match(l.alpha.hint, /1\/44 = 0.0227/);
  // α = 1 and α = 1e308 are refused before they are sent; α at the bound is not.
  assert.ok(parseParam('1', 'α', l.alpha.lo, l.alpha.hi, l.alpha.loOpen).error);
  assert.ok(parseParam('1e308', 'α', l.alpha.lo, l.alpha.hi, l.alpha.loOpen).error);
  assert.deepEqual(parseParam(String(1 / 44), 'α', l.alpha.lo, l.alpha.hi, l.alpha.loOpen), { value: 1 / 44 });
  assert.deepEqual([l.lambda.lo, l.lambda.hi], [0, 1]);
  // Another prediction, or no bounds at all: α in (0, 1].
  assert.equal(paramLimits(bounds, 'other').alpha.hi, 1);
  assert.equal(paramLimits(undefined, 'stall').alpha.hi, 1);
  assert.equal(paramLimits({ predictions: [{ name: 'stall', max_alpha: 'x' }] }, 'stall').alpha.hi, 1);
});

test('response onsets are said in words: before or after the command, never a bare sign', () => {
  assert.equal(fmtOnset(120.4), '120 ms before');
  assert.equal(fmtOnset(-1500), '1,500 ms after');
  assert.equal(fmtOnset(0.2), 'at the command');
  assert.equal(fmtOnset(null), '—');
});

test('aligned averages become uPlot data with gaps for missing points and modes', () => {
  const aligned = {
    offsets_ms: [-20, 0, 20],
    reactive: { commands: 2, current_ma: [-150, null, -600], rotation_deg: [0, 1.5, 2] },
    pavlovian: { commands: 0, current_ma: [null, null, null], rotation_deg: [null, null, null] },
  };
  const d = alignedData(aligned);
  assert.deepEqual(d.current, [[-0.02, 0, 0.02], [-150, null, -600], [null, null, null]]);
  assert.deepEqual(d.rotation[1], [0, 1.5, 2]);
  assert.deepEqual(d.counts, { reactive: 2, pavlovian: 0 });
  // A mode missing from the message, or curves shorter than the offsets, leave gaps.
  const partial = alignedData({ offsets_ms: [0, 20], reactive: { commands: 1, current_ma: [-300] } });
  assert.deepEqual(partial.current[1], [-300, null]);
  assert.deepEqual(partial.rotation[2], [null, null]);
  assert.deepEqual(partial.counts, { reactive: 1, pavlovian: 0 });
  assert.equal(alignedData(undefined), null);
  assert.equal(alignedData({}), null);
});

// ---------------------------------------------------------------- timeline.js

const tick = (seq, extra = {}) => ({
  type: 'tick', seq, t: seq * 0.02, mode: 'pavlovian', stimulus: false, gate: seq % 2 === 0, estop: false, safety_stop: null,
  predictions: [{ name: 'stall', value: seq / 1000, threshold: 0.5 }],
  command: { left: 200, right: 200 }, default: { left: 200, right: 200 },
  sensors: { overcurrent_left: false, overcurrent_right: true, battery_current_ma: -300 },
  link: { up: true, state: 'up' }, ...extra,
});

const FIELDS = ['seq', 't', 'mode', 'stimulus', 'gate', 'estop', 'safety_stop', 'overcurrent_left', 'overcurrent_right',
  'battery_current_ma', 'command_left', 'command_right', 'default_left', 'default_right', 'link', 'predictions'];

test('a tick and a history row become the same sample', () => {
  const fromTick = sampleFromTick(tick(10));
  const row = [10, 0.2, 'pavlovian', 0, 1, 0, null, 0, 1, -300, 200, 200, 200, 200, 'up', [[0.01, 0.5]]];
  const [fromRow] = samplesFromHistory({ type: 'history', fields: FIELDS, rows: [row] });
  assert.deepEqual(fromRow, fromTick);
  assert.equal(fromTick.ocR, true);
  assert.deepEqual(fromTick.preds, [[0.01, 0.5]]);
  // Fields are read by name, whatever their order; malformed rows are left out.
  const reversed = [...FIELDS].reverse();
  const [again] = samplesFromHistory({ fields: reversed, rows: [[...row].reverse(), 'junk', [null]] });
  assert.deepEqual(again, fromTick);
  assert.deepEqual(samplesFromHistory({}), []);
});

test('the timeline keeps ticks in order, merges history over what it had, and lets old ones go', () => {
  const tl = new Timeline(10);
  for (let s = 0; s < 100; s++) assert.ok(tl.push(sampleFromTick(tick(s))));
  assert.equal(tl.push(sampleFromTick(tick(50))), false, 'an older tick is ignored');
  assert.equal(tl.last.seq, 99);
  // A history from tick 90 to 200 (a reconnect): what the page had from 90 on is replaced.
  const history = Array.from({ length: 111 }, (_, k) => sampleFromTick(tick(90 + k, { mode: 'reactive' })));
  tl.merge(history);
  assert.equal(tl.samples[89].mode, 'pavlovian');
  assert.equal(tl.samples[90].mode, 'reactive');
  assert.equal(tl.last.seq, 200);
  assert.equal(new Set(tl.samples.map((x) => x.seq)).size, tl.samples.length, 'no tick twice');
  // 10 s kept: 500 ticks (trimmed in batches of a tenth).
  for (let s = 201; s < 2000; s++) tl.push(sampleFromTick(tick(s)));
  assert.ok(tl.samples.length >= 500 && tl.samples.length <= 560, `${tl.samples.length}`);
  assert.ok(tl.samples[0].t >= tl.last.t - 10 - 1.2);
  assert.deepEqual(tl.between(30, 30.1).map((x) => x.seq), [1500, 1501, 1502, 1503, 1504, 1505]);
});

test('events are kept once each, in time order, and go with the samples', () => {
  const tl = new Timeline(10);
  tl.push(sampleFromTick(tick(0)));
  assert.ok(tl.addEvent({ id: 2, t: 5, kind: 'mode_set' }));
  assert.ok(tl.addEvent({ id: 1, t: 1, kind: 'e_stop' }));
  assert.equal(tl.addEvent({ id: 2, t: 5, kind: 'mode_set' }), false);
  assert.deepEqual(tl.events.map((e) => e.id), [1, 2]);
  assert.deepEqual(tl.eventsBetween(2, 6).map((e) => e.id), [2]);
  for (let s = 1; s <= 1000; s++) tl.push(sampleFromTick(tick(s)));
  assert.deepEqual(tl.events, [], 'older than the 10 s kept');
  assert.ok(tl.addEvent({ id: 1, t: 19.9, kind: 'e_stop' }), 'an id let go may come back (a new run)');
  tl.clear();
  assert.equal(tl.samples.length + tl.events.length, 0);
});

test('chart columns break at missing ticks and where the link was down', () => {
  const samples = [0, 1, 2, 5, 6].map((s) => sampleFromTick(tick(s, s === 6 ? { link: { up: false, state: 'reconnecting' } } : {})));
  const live = (f) => (s) => (sensorsLive(s) ? f(s) : null);
  const [x, current, cmd] = columns(samples, [live((s) => s.current), (s) => s.cmdL], 0.02);
  assert.deepEqual(x, [0, 0.02, 0.04, 0.05, 0.1, 0.12]);
  assert.deepEqual(current, [-300, -300, -300, null, -300, null]);
  assert.deepEqual(cmd, [200, 200, 200, null, 200, 200]);
  assert.equal(sensorsLive({ link: 'tripped' }), true);
  assert.equal(sensorsLive({ link: 'stale' }), false);
  assert.deepEqual(columns([], [(s) => s.cmdL], 0.02), [[], []]);
  // Non-finite values are gaps too.
  assert.deepEqual(columns([sampleFromTick(tick(0))], [() => NaN], 0.02)[1], [null]);
});

test('the CSV has a row per tick, named prediction columns, event labels, and quotes what needs it', () => {
  const samples = [0, 1, 2].map((s) => sampleFromTick(tick(s)));
  samples[1].safety = 'e_stop';
  samples[2].current = null;
  const csv = toCsv(samples, ['stall'], [{ t: 0.02, label: 'α=0.01' }, { t: 0.02, label: 'mode→"x",y' }, { t: 1, label: null }]);
  const lines = csv.trimEnd().split('\n');
  assert.equal(lines.length, 4);
  assert.equal(lines[0], 'seq,t_s,mode,stall,stall_threshold,stimulus,gate,estop,safety_stop,overcurrent_left,overcurrent_right,'
    + 'battery_current_ma,command_left,command_right,default_left,default_right,link,events');
  assert.equal(lines[1], '0,0,pavlovian,0,0.5,0,1,0,,0,1,-300,200,200,200,200,up,');
  assert.equal(lines[2], '1,0.02,pavlovian,0.001,0.5,0,0,0,e_stop,0,1,-300,200,200,200,200,up,"α=0.01; mode→""x"",y"');
  assert.ok(lines[3].includes(',,200,'), lines[3]);
});

test('markers say what changed, briefly', () => {
  const before = { prediction: 'stall', alpha: 0.0136, lambda: 0.9, threshold: 0.5 };
  const set = { kind: 'params_set', prediction: 'stall', alpha: 0.01, lambda: 0.9, threshold: 0.5 };
  assert.equal(markerLabel(set, before), 'α=0.01');
  assert.equal(markerLabel({ ...set, threshold: 0.4 }, before), 'α=0.01 θ=0.4');
  assert.equal(markerLabel(set, null), 'α=0.01 λ=0.9 θ=0.5', 'all values when what came before is unknown');
  assert.equal(markerLabel(set, set), 'α=0.01 λ=0.9 θ=0.5', 'all values when nothing changed');
  assert.equal(markerLabel({ kind: 'mode_set', mode: 'reactive' }), 'mode→reactive');
  assert.equal(markerLabel({ kind: 'e_stop', latched: true }), 'e-stop');
  assert.equal(markerLabel({ kind: 'e_stop', latched: false }), 'e-stop released');
  assert.equal(markerLabel({ kind: 'link', state: 'tripped', trip: 'cliff' }), 'link→tripped (cliff)');
  assert.equal(markerLabel({ kind: 'teleop', action: {} }), null, 'no marker for teleop');
  assert.equal(markerLabel({ kind: 'something_new' }), 'something_new');
  assert.equal(fmtParam(0.022727272727), '0.0227');
  assert.equal(fmtParam(undefined), '—');
  const params = { stall: before };
  const after = applyParams(params, set);
  assert.equal(after.stall.alpha, 0.01);
  assert.equal(params.stall.alpha, 0.0136, 'the map given is not changed');
  assert.equal(applyParams(params, { kind: 'mode_set' }), params);
});

test('windows go from 10 s to 10 min and wide ones redraw less often', () => {
  assert.deepEqual(WINDOWS.map((w) => w.seconds), [10, 30, 60, 300, 600]);
  assert.equal(redrawIntervalMs(10), 20);
  assert.equal(redrawIntervalMs(600), 1000);
});

test('the Gate row names the rule that engaged the gate', () => {
  assert.equal(gateText({ gate: false, rule: null }), 'default π');
  assert.equal(gateText({ gate: true, rule: 'stall_ahead' }), 'ϱ · stall_ahead');
  assert.equal(gateText({ gate: true, rule: 'stimulus' }), 'ϱ · stimulus');
  assert.equal(gateText({ gate: true }), 'response ϱ', 'a server without rules');
});

test('a storage failure shows until what failed works again', () => {
  const none = { recordingFailure: null, checkpointFailure: null };
  const full = 'No space left on device (os error 28)';
  let s = applyStorageEvent(none, { kind: 'recording_started', path: 'r' });
  assert.deepEqual(s, none);
  s = applyStorageEvent(s, { kind: 'recording_stopped', path: 'r' });
  assert.deepEqual(s, none, 'a stop asked for is no failure');
  s = applyStorageEvent(s, { kind: 'recording_stopped', path: 'r', reason: full });
  assert.equal(s.recordingFailure, full);
  s = applyStorageEvent(s, { kind: 'checkpoint_failed', path: 'w', reason: full });
  assert.equal(s.checkpointFailure, full);
  assert.equal(applyStorageEvent(s, { kind: 'mode_set', mode: 'manual' }), s, 'other events change nothing');
  s = applyStorageEvent(s, { kind: 'weights_saved', path: 'w' });
  assert.equal(s.checkpointFailure, null);
  s = applyStorageEvent(s, { kind: 'recording_started', path: 'r2' });
  assert.equal(s.recordingFailure, null);
  assert.deepEqual(recordingView('r2', null), { badge: 'on', alarm: false, notice: null });
  assert.deepEqual(recordingView(null, null), { badge: 'off', alarm: false, notice: null });
  assert.deepEqual(recordingView(null, full), { badge: 'stopped', alarm: true, notice: `Recording stopped: ${full}` });
  assert.equal(markerLabel({ kind: 'recording_stopped', reason: full }), 'recording ■ failed');
  assert.equal(markerLabel({ kind: 'recording_stopped' }), 'recording ■');
  assert.equal(markerLabel({ kind: 'checkpoint_failed', reason: full }), 'checkpoint failed');
});

test('marker labels never overlap: neighbours share one, the rest fill three rows, what fits nowhere is counted', () => {
  const width = (text) => text.length * 6;
  const boxes = (placed) => placed.map((p) => ({ left: p.left, right: p.left + p.width, row: p.row }));
  const apart = (placed, gap) => boxes(placed).every((a, i, all) => all.every((b, j) => i === j || a.row !== b.row
    || a.right + gap <= b.left || b.right + gap <= a.left));
  // A burst: thirty markers within a few pixels share one label.
  const burst = Array.from({ length: 30 }, (_, i) => ({ x: 100 + i * 0.1, label: ['mode→reactive', 'request', 'α=0.01'][i % 3] }));
  const one = layoutMarkerLabels(burst, width, { plotWidth: 900 });
  assert.deepEqual(one.placed.map((p) => [p.text, p.items.length]), [['mode→reactive +29', 30]]);
  assert.equal(one.hidden, 0);
  const same = layoutMarkerLabels([{ x: 10, label: 'pipeline stall' }, { x: 20, label: 'pipeline stall' }], width);
  assert.deepEqual(same.placed.map((p) => p.text), ['pipeline stall ×2']);
  // Many markers spread over a narrow plot: none overlaps, three rows at most, the others are counted.
  const spread = Array.from({ length: 200 }, (_, i) => ({ x: i * 30, label: `link→stale ${i}` }));
  const many = layoutMarkerLabels(spread, width, { plotWidth: 6000 });
  assert.ok(apart(many.placed, 4));
  assert.ok(many.placed.every((p) => p.row >= 0 && p.row < 3 && p.left >= 0 && p.left + p.width <= 6000));
  assert.equal(many.placed.reduce((n, p) => n + p.items.length, 0) + many.hidden, 200);
  assert.ok(many.hidden > 0 && many.placed.length > 50);
  // A label that would leave the plot goes left of its marker.
  const edge = layoutMarkerLabels([{ x: 295, label: 'e-stop' }], width, { plotWidth: 300 });
  assert.equal(edge.placed[0].left, 295 - 2 - 36);
});

test('every marker kind has a colour and an explanation; stalls and stale links name host load', () => {
  assert.equal(markerKind('pipeline_stall').key, 'stall');
  assert.equal(markerKind('link').key, 'link');
  assert.equal(markerKind('something_new').key, 'other');
  assert.match(markerKind('pipeline_stall').explain, /host load/);
  assert.match(markerKind('link').explain, /link→stale: .*host load/);
  assert.equal(markerColor('e_stop'), '#dc2626');
  for (const k of MARKER_KINDS) assert.ok(k.explain.length > 40 && /^#[0-9a-f]{6}$/.test(k.color), k.key);
});

test('samples carry the elbow angles of a tick or a history row, null without them', () => {
  const tick = { seq: 1, t: 0.02, elbow: { left: 72.5, left_avg: 101, right: null, right_avg: 160.2, skeleton: 'tracked' } };
  assert.deepEqual(sampleFromTick(tick).elbow, [72.5, 101, null, 160.2]);
  assert.equal(sampleFromTick({ seq: 1, t: 0.02, elbow: null }).elbow, null);
  assert.deepEqual(elbowAngles([80, null, Number.NaN, 120]), [80, null, null, 120]);
  const [row] = samplesFromHistory({ fields: ['seq', 't', 'elbow'], rows: [[4, 0.08, [85.5, 120, null, 170.25]]] });
  assert.deepEqual(row.elbow, [85.5, 120, null, 170.25]);
});

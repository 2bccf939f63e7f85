// Unit tests of the dashboard's pure helpers (web/lib.js): `npm test --prefix web`.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import {
  Backoff, GapCounter, SUBPROTOCOL, Window, alignedData, connectionTarget, fmt, fmtDuration, fmtLead, paramLimits, parseParam, teleopWheels, tokenFromHash,
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

test('the chart window keeps the newest rows and maps bad numbers to gaps', () => {
  const w = new Window(2, 100);
  for (let i = 0; i < 1000; i++) w.push(i * 0.02, [i, i % 3 === 0 ? NaN : -i]);
  const [x, a, b] = w.data();
  assert.equal(x.length, 100);
  assert.equal(w.length, 100);
  assert.equal(a[0], 900);
  assert.equal(a[99], 999);
  assert.equal(b[99], 999 % 3 === 0 ? null : -999);
  assert.ok(b.includes(null));
  assert.ok(w.columns[0].length <= 110, 'trimmed in batches');
  w.clear();
  assert.equal(w.length, 0);
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

test('response leads show their sign: + before the command, − after', () => {
  assert.equal(fmtLead(120.4), '+120 ms');
  assert.equal(fmtLead(-1500), '−1,500 ms');
  assert.equal(fmtLead(0.2), '0 ms');
  assert.equal(fmtLead(null), '—');
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

// Unit tests of the learning view's pure helpers (web/learnlib.js): `npm test --prefix web`.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import {
  HordeSeries, LearningStore, OwnRanges, base64Bytes, cellAt, colourOf, colourRange, decodeHordeValues, gridLayout, hordeName, sig,
} from '../learnlib.js';

test('the store pairs tick values with TD errors and returns that arrive later', () => {
  const s = new LearningStore(100);
  for (let seq = 0; seq <= 10; seq += 1) s.addValue('stall', seq, seq / 10);
  s.addMessage({
    type: 'learning',
    seq: 10,
    predictions: [{
      name: 'stall', learner: 'xent', tau: 25, horizon: 113, tail_bound: 0.0099,
      td: [[9, -0.02], [10, null]],
      realised: [[2, 0.2, 0.9216, 1], [3, 0.3, 0.96, 1]],
      error: { pairs: 2, rmse: 0.7, mean_abs: 0.69, bias: -0.69 },
      dropped: 0,
    }],
  });
  assert.deepEqual(s.names(), ['stall']);
  assert.equal(s.info('stall').horizon, 113);
  assert.equal(s.info('stall').learner, 'xent');
  const c = s.series('stall', 0.02);
  assert.equal(c.t.length, 11);
  assert.ok(Math.abs(c.t[10] - 0.2) < 1e-12);
  assert.equal(c.value[3], 0.3);
  assert.equal(c.ret[2], 0.9216);
  assert.equal(c.ret[4], null);
  assert.equal(c.td[9], -0.02);
  assert.equal(c.td[10], null);
  assert.equal(c.rmse[10], 0.7);
  assert.equal(c.rmse[9], null);
});

test('the store keeps only its window of ticks', () => {
  const s = new LearningStore(10);
  for (let seq = 0; seq < 50; seq += 1) s.addValue('p', seq, 1);
  s.addMessage({ seq: 49, predictions: [{ name: 'p', td: [[49, 0.1]], realised: [], error: {} }] });
  const c = s.series('p', 1);
  assert.equal(c.t[0], 39);
  assert.equal(c.t.length, 11);
  // Garbage is ignored, not thrown on.
  s.addMessage({ predictions: [{ name: 5 }, { name: 'q', td: 'x', realised: null }] });
  s.addMessage(null);
  assert.deepEqual(s.series('nobody', 1).t, []);
});

test('base64 and bfloat16 decode to the values the server encoded', () => {
  assert.deepEqual(Array.from(base64Bytes('Zm9vYmE=')), Array.from(Buffer.from('fooba')));
  assert.deepEqual(Array.from(base64Bytes('Zg==')), [0x66]);
  // 1.0 = 0x3F80, −2.0 = 0xC000, 0.5 = 0x3F00, NaN = 0x7FC0, little-endian.
  const bytes = Buffer.from([0x80, 0x3f, 0x00, 0xc0, 0x00, 0x3f, 0xc0, 0x7f]);
  const msg = {
    type: 'horde_values', encoding: 'bf16le-base64', count: 4, values: bytes.toString('base64'),
  };
  const v = decodeHordeValues(msg);
  assert.deepEqual(Array.from(v.slice(0, 3)), [1, -2, 0.5]);
  assert.ok(Number.isNaN(v[3]));
  assert.throws(() => decodeHordeValues({ ...msg, count: 5 }), /expected 5 values/);
  assert.throws(() => decodeHordeValues({ ...msg, encoding: 'f64' }), /unknown encoding/);
});

test('the grid fits ten thousand cells and the hit test finds each one', () => {
  const g = gridLayout(10000, 600, 420);
  assert.ok(g.cols * g.rows >= 10000);
  assert.ok(g.width <= 600 && g.height <= 420, JSON.stringify(g));
  assert.ok(g.cell >= 2);
  const small = gridLayout(132, 600, 420);
  assert.ok(small.cell >= 20 && small.cell <= 48, JSON.stringify(small));
  assert.equal(cellAt(small, 0, 0), 0);
  assert.equal(cellAt(small, small.cell * 2 + 1, small.cell + 1), small.cols + 2);
  assert.equal(cellAt(small, small.width + 1, 0), -1);
  assert.equal(cellAt(small, -1, 0), -1);
  // Five cells in two columns: the last row has one, and the place beside it is no cell.
  const five = gridLayout(5, 100, 420);
  assert.deepEqual([five.cols, five.rows, five.cell], [2, 3, 48]);
  assert.equal(cellAt(five, 1, 2 * 48 + 1), 4);
  assert.equal(cellAt(five, 48 + 1, 2 * 48 + 1), -1);
  assert.equal(gridLayout(0, 600).cols, 0);
});

test('colours span the bulk of the values and mark what is not finite', () => {
  const values = Array.from({ length: 100 }, (_, i) => i);
  values.push(1e9);
  const r = colourRange(values);
  assert.ok(r.hi < 1000, JSON.stringify(r));
  assert.deepEqual(colourRange([3, 3]), { lo: 2.5, hi: 3.5 });
  assert.deepEqual(colourOf(r.lo, r.lo, r.hi), [68, 1, 84]);
  assert.deepEqual(colourOf(1e9, r.lo, r.hi), [253, 231, 37]);
  assert.deepEqual(colourOf(NaN, 0, 1), [150, 150, 150]);
});

test('a Horde name gives its family, cumulant and timescale', () => {
  assert.deepEqual(hordeName('nexting/obs/bump_left@10'), { family: 'nexting', cumulant: 'obs/bump_left', tau: 10 });
  assert.deepEqual(hordeName('odd'), { family: null, cumulant: null, tau: null });
});

test('clicked predictions are charted from their next sample, at most six', () => {
  const h = new HordeSeries(2, 3);
  h.push(0, 0, [1, 2, 3]);
  assert.equal(h.t.length, 0);
  assert.equal(h.toggle(1), true);
  h.push(1, 0, [1, 2, 3]);
  assert.equal(h.toggle(2), true);
  h.push(2, 0, [4, 5, 6]);
  assert.deepEqual(h.columns, [[2, 5], [null, 6]]);
  // A third pushes out the oldest; a window that misses it gives null.
  h.toggle(0);
  assert.deepEqual(h.picked, [2, 0]);
  h.push(3, 1, [7, 8]);
  h.push(4, 0, [9, 9, 9]);
  assert.deepEqual(h.t, [2, 3, 4]);
  assert.deepEqual(h.columns, [[6, 8, 9], [null, null, 9]]);
  // A second click takes it off.
  assert.equal(h.toggle(2), false);
  assert.deepEqual(h.picked, [0]);
});

test('each cell can be coloured against its own range', () => {
  const r = new OwnRanges();
  r.update(10, [1, 100, 5]);
  assert.equal(r.fraction(0, 1), 0.5);
  r.update(10, [3, 300, NaN]);
  assert.equal(r.fraction(0, 2), 0.5);
  assert.equal(r.fraction(1, 300), 1);
  assert.equal(r.fraction(1, 100), 0);
  assert.equal(r.fraction(2, 5), 0.5);
  assert.ok(Number.isNaN(r.fraction(0, NaN)));
  // Another window starts afresh.
  r.update(0, [7, 7, 7]);
  assert.equal(r.fraction(1, 7), 0.5);
});

test('numbers are shown with significant digits', () => {
  assert.equal(sig(135168), '135200');
  assert.equal(sig(0.0227272), '0.02273');
  assert.equal(sig(-1568), '-1568');
  assert.equal(sig(2.5e7), '2.500e+7');
  assert.equal(sig(NaN), '—');
  assert.equal(sig(0), '0');
});

// Unit tests of the elbow panel's pure helpers (web/elbow.js): `npm test --prefix web`.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import { COMMAND_DEG, WARN_AFTER_MS, elbowRow, skeletonWarning } from '../elbow.js';

test('a chart row holds both angles, their averages and the 90° line; invalid angles are gaps', () => {
  assert.deepEqual(
    elbowRow({ left: 72.5, left_avg: 101, right: null, right_avg: 160.2, skeleton: 'tracked' }),
    [72.5, 101, null, 160.2, COMMAND_DEG],
  );
  assert.deepEqual(elbowRow({ left: Number.NaN }), [null, null, null, null, 90]);
  assert.deepEqual(elbowRow(null), [null, null, null, null, 90]);
});

test('the warning waits a second and says whether the skeleton is stale or absent', () => {
  assert.equal(skeletonWarning('tracked', 60000), null);
  assert.equal(skeletonWarning('none', WARN_AFTER_MS - 1), null);
  assert.match(skeletonWarning('none', 2500), /^No skeleton for 2\.5 s/);
  assert.match(skeletonWarning('stale', 1000), /^Skeleton stale for 1\.0 s/);
  assert.equal(skeletonWarning('none', Number.NaN), null);
});

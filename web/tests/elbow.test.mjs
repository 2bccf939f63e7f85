// Unit tests of the elbow panel's pure helpers (web/elbow.js): `npm test --prefix web`.
import assert from 'node:assert/strict';
import { test } from 'node:test';

import { WARN_AFTER_MS, skeletonWarning } from '../elbow.js';

test('the warning waits a second and says whether the skeleton is stale or absent', () => {
  assert.equal(skeletonWarning('tracked', 60000), null);
  assert.equal(skeletonWarning('none', WARN_AFTER_MS - 1), null);
  assert.match(skeletonWarning('none', 2500), /^No skeleton for 2\.5 s/);
  assert.match(skeletonWarning('stale', 1000), /^Skeleton stale for 1\.0 s/);
  assert.equal(skeletonWarning('none', Number.NaN), null);
});

// The volume labels the viewer draws (markers, table, tooltips): an incomplete event's volume is
// marked as such and shown without an interval, since its interval is no 95 % bound (SPEC.md §1
// "Change of any depth"); a complete one keeps its ± half-width.

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { volumeLabel } from '../src/format.js';

test('a complete event shows its 95 % interval', () => {
  assert.equal(volumeLabel(-15.003, 0.25, true), '\u221215.0 ± 0.3 m³');
  assert.equal(volumeLabel(2.5, 0.3), volumeLabel(2.5, 0.3, true));
});

test('an incomplete event is marked and shows no interval', () => {
  const s = volumeLabel(-15.003, 0.008, false);
  assert.doesNotMatch(s, /±/);
  assert.equal(s, '\u221215.0 m³ (incomplete)');
});

// loadTerrain (src/data.js) in Node, against a fetch that serves files in chunks: a whole
// terrain.bin, or a pair's distances with the positions of the file view.json `positions` names
// (resolved here: the server refuses `..`), the progress over both downloads, and the errors.
// No Cache Storage in Node: every call downloads (the browser test covers the cache).

import { test, beforeEach } from 'node:test';
import assert from 'node:assert/strict';
import { loadTerrain, setBase } from '../src/data.js';

const N = 1000;
const ORIGIN = 'http://127.0.0.1:8123';
globalThis.location = { origin: ORIGIN };

/** Float32 bytes of `count` values f(k). */
const f32 = (count, f) => new Uint8Array(Float32Array.from({ length: count }, (_, k) => f(k)).buffer);
const concat = (a, b) => { const c = new Uint8Array(a.length + b.length); c.set(a); c.set(b, a.length); return c; };
const POS = f32(3 * N, (k) => k * 0.25);
const FIRST = concat(POS, f32(N, (k) => k * 0.001)); // the first pair's whole terrain.bin
const SECOND = f32(N, (k) => -k * 0.002); // a later pair's distances alone

let files; // path → bytes
let fetched;
let honourAbort; // false: the body keeps coming after the reader aborted (worst case)
let slow; // paths whose chunks come 10 ms apart
beforeEach(() => {
  honourAbort = true;
  slow = new Set();
  files = new Map([
    ['/data/pairs/A_B/terrain.bin', FIRST],
    ['/data/pairs/B_C/terrain.bin', SECOND],
    ['/data/terrain.bin', FIRST],
  ]);
  fetched = [];
  setBase('/data/');
});

// Each file in 8 chunks, a macrotask apart, so two downloads interleave.
globalThis.fetch = async (input, init = {}) => {
  const path = new URL(String(input), ORIGIN).pathname;
  fetched.push(path);
  const bytes = files.get(path);
  if (!bytes) return new Response('not found', { status: 404 });
  const size = Math.ceil(bytes.length / 8);
  let at = 0;
  const body = new ReadableStream({
    async pull(ctl) {
      await new Promise((r) => setTimeout(r, slow.has(path) ? 10 : 1));
      if (honourAbort && init.signal?.aborted) { ctl.error(new Error('aborted')); return; }
      if (at >= bytes.length) { ctl.close(); return; }
      ctl.enqueue(bytes.slice(at, at + size));
      at += size;
    },
  });
  return new Response(body, { headers: { 'content-length': String(bytes.length) } });
};

const view = (extra = {}) => ({ points: N, terrain: 'terrain.bin', positions: null, ...extra });
const floats = (bytes) => new Float32Array(bytes.buffer, bytes.byteOffset, bytes.byteLength / 4);

function recorder() {
  const seen = [];
  const fn = (p) => seen.push(p);
  fn.seen = seen;
  return fn;
}

function assertProgress(seen, calls) {
  assert.equal(seen.length, calls, `${seen}`);
  assert.deepEqual(seen, [...seen].sort((a, b) => a - b), `not monotone: ${seen}`);
  assert.equal(seen.at(-1), 1);
}

test('a whole terrain.bin: positions then distances, as before', async () => {
  const progress = recorder();
  const t = await loadTerrain(view(), progress);
  assert.deepEqual(Array.from(t.positions), Array.from(floats(POS)));
  assert.deepEqual(Array.from(t.distances), Array.from(floats(FIRST.subarray(12 * N))));
  assertProgress(progress.seen, 8);
  assert.deepEqual(fetched, ['/data/terrain.bin']);
});

test('positions: the first 12n bytes of the named file, the distances of its own', async () => {
  setBase('/data/pairs/B_C/');
  const progress = recorder();
  const t = await loadTerrain(view({ positions: '../A_B/terrain.bin' }), progress);
  assert.equal(t.positions.length, 3 * N);
  assert.equal(t.distances.length, N);
  assert.deepEqual(Array.from(t.positions), Array.from(floats(POS)));
  assert.deepEqual(Array.from(t.distances), Array.from(floats(SECOND)));
  assert.deepEqual(fetched.sort(), ['/data/pairs/A_B/terrain.bin', '/data/pairs/B_C/terrain.bin']);
  // One progress over both downloads (16n + 4n bytes), to the end, never back.
  assertProgress(progress.seen, 16);
  // And without a progress callback.
  assert.deepEqual(Array.from((await loadTerrain(view({ positions: '../A_B/terrain.bin' }))).distances), Array.from(floats(SECOND)));
});

test('a positions file shorter than 16n bytes is refused, naming both files', async () => {
  files.set('/data/pairs/A_B/positions.bin', POS); // 12n: positions without distances
  setBase('/data/pairs/B_C/');
  await assert.rejects(loadTerrain(view({ positions: '../A_B/positions.bin' }), () => {}), (e) => {
    assert.match(e.message, /^pairs\/A_B\/positions\.bin \(the terrain positions of pairs\/B_C\/terrain\.bin\): 12000 bytes, expected 16 × 1000 points/);
    return true;
  });
  // A file that is missing, too.
  await assert.rejects(loadTerrain(view({ positions: '../X_Y/terrain.bin' })), /pairs\/X_Y\/terrain\.bin \(the terrain positions of pairs\/B_C\/terrain\.bin\): HTTP 404/);
});

test('with positions, the own file must hold the distances alone (4n bytes)', async () => {
  files.set('/data/pairs/B_C/terrain.bin', FIRST);
  setBase('/data/pairs/B_C/');
  await assert.rejects(loadTerrain(view({ positions: '../A_B/terrain.bin' })),
    /^Error: pairs\/B_C\/terrain\.bin: 16000 bytes, expected 4 × 1000 points: the distances alone, as view\.json names its positions \(pairs\/A_B\/terrain\.bin\)/);
  // Without positions, a distances-only file is refused as ever.
  files.set('/data/pairs/B_C/terrain.bin', SECOND);
  await assert.rejects(loadTerrain(view()), /^Error: pairs\/B_C\/terrain\.bin: 4000 bytes, expected 16 × 1000 points$/);
});

test('once one download fails, the progress stops: the error stays on screen', async () => {
  files.set('/data/pairs/A_B/terrain.bin', FIRST.subarray(0, 100)); // fails at its end, early
  setBase('/data/pairs/B_C/');
  honourAbort = false;
  slow.add('/data/pairs/B_C/terrain.bin');
  const progress = recorder();
  await assert.rejects(loadTerrain(view({ positions: '../A_B/terrain.bin' }), progress), /100 bytes, expected 16/);
  const after = progress.seen.length;
  await new Promise((r) => setTimeout(r, 150));
  assert.equal(progress.seen.length, after, 'progress reported after the error');
});

test('a pair served alone: its positions are outside, and the error says what to open', async () => {
  // `talus view DIR/pairs/B_C`: the pair is /data/, its positions ../A_B/ are not served.
  await assert.rejects(loadTerrain(view({ positions: '../A_B/terrain.bin' })), (e) => {
    assert.match(e.message, /terrain positions are in the campaign's first pair/);
    assert.match(e.message, /Open the campaign folder \(talus view CAMPAIGN_DIR\) instead of this pair alone/);
    return true;
  });
  assert.deepEqual(fetched, []);
});

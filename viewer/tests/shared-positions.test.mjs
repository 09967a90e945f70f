// Browser test of a campaign whose pairs share their core points: view.json `positions` names the
// first pair's terrain.bin (its first 12n bytes), the pair's own terrain.bin holds its n
// distances alone. A synthetic campaign (make-fixture.mjs: pairs full, shared, shared, full),
// served by `talus view DIR --port 0`. Expected values are read from the fixture's files here in
// Node, never from the viewer's code.
//
// TALUS_BIN: the talus binary (default target/debug/talus).

import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { copyFileSync, existsSync, mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import { launchBrowser, serveTalus, stopServer } from './browser.mjs';
import { makeCampaignFixture } from './make-fixture.mjs';

const HERE = dirname(fileURLToPath(import.meta.url));
const REPO = resolve(HERE, '..', '..');
const TALUS = process.env.TALUS_BIN || join(process.env.CARGO_TARGET_DIR || join(REPO, 'target'), 'debug', 'talus');

let tmp;
let context;
const servers = [];
const consoleErrors = [];
const failedRequests = [];
let good; // { dir, url, labels, points }
let bad; // the same, its pairs broken in one way each

const readJson = (p) => JSON.parse(readFileSync(p, 'utf8'));
const floats = (path, offset, count) => {
  const b = readFileSync(path);
  return new Float32Array(b.buffer.slice(b.byteOffset + offset, b.byteOffset + offset + 4 * count));
};

async function serve(dir) {
  const { child, url } = await serveTalus(TALUS, dir, REPO);
  servers.push(child);
  return url;
}

/**
 * A new tab (its own session) recording its terrain.bin requests (paths) and the loading
 * progress shown (percentages of each page load); `strict` counts its errors as the test's.
 */
async function newPage(strict = true) {
  const page = await context.newPage();
  const terrainRequests = [];
  if (strict) {
    page.on('console', (m) => { if (m.type() === 'error') consoleErrors.push(m.text()); });
    page.on('pageerror', (e) => consoleErrors.push(String(e)));
    page.on('requestfailed', (r) => failedRequests.push(`${r.url()}: ${r.failure()?.errorText}`));
    page.on('response', (r) => { if (r.status() >= 400) failedRequests.push(`${r.url()}: HTTP ${r.status()}`); });
  }
  page.on('request', (r) => {
    const path = new URL(r.url()).pathname;
    if (path.endsWith('.bin')) terrainRequests.push(decodeURIComponent(path));
  });
  await page.addInitScript(() => {
    window.__progress = [];
    new MutationObserver(() => {
      const m = /Loading terrain… (\d+) %/.exec(document.getElementById('loading')?.textContent || '');
      if (m && window.__progress.at(-1) !== Number(m[1])) window.__progress.push(Number(m[1]));
    }).observe(document, { subtree: true, childList: true, characterData: true });
  });
  return { page, terrainRequests };
}

/** Wait until the page shows pair `label`, ready, or has failed: the error (or null). */
async function settle(page, label) {
  await page.waitForFunction(
    (l) => window.__talus && (window.__talus.error || (window.__talus.ready && (!l || window.__talus.campaign?.pair === l))),
    label, { timeout: 120_000 },
  );
  return page.evaluate(() => window.__talus.error);
}

async function showing(page, label) {
  assert.equal(await settle(page, label), null);
}

/**
 * The terrain drawn on `page` is the points of `posFile` (its first 12n bytes) with the
 * distances of `distFile` (its last 4n bytes), point for point, in whatever order it is drawn.
 */
async function assertTerrain(page, n, posFile, distFile) {
  const pos = floats(posFile, 0, 3 * n);
  const size = readFileSync(distFile).length;
  const dist = floats(distFile, size - 4 * n, n);
  const want = new Map();
  for (let k = 0; k < n; k++) want.set(`${pos[3 * k]},${pos[3 * k + 1]},${pos[3 * k + 2]}`, dist[k]);
  assert.equal(want.size, n, 'the fixture\'s points are distinct');
  const got = await page.evaluate(() => {
    const t = window.__talus.terrainArrays();
    return { positions: Array.from(t.positions), distances: Array.from(t.distances) };
  });
  assert.equal(got.distances.length, n);
  assert.equal(got.positions.length, 3 * n);
  const seen = new Set();
  let nan = 0;
  for (let i = 0; i < n; i++) {
    const key = `${got.positions[3 * i]},${got.positions[3 * i + 1]},${got.positions[3 * i + 2]}`;
    assert.ok(want.has(key), `drawn point ${i} (${key}) is not one of ${posFile}`);
    seen.add(key);
    const d = got.distances[i];
    if (Number.isNaN(want.get(key))) {
      assert.ok(Number.isNaN(d), `point ${key}: ${d}, expected no distance`);
      nan++;
    } else {
      assert.equal(d, want.get(key), `point ${key}`);
    }
  }
  assert.equal(seen.size, n);
  assert.ok(nan > 0 && nan < n / 2, `${nan} points without a distance`);
}

const pairFile = (c, i, name = 'terrain.bin') => join(c.dir, 'pairs', c.labels[i], name);

before(async () => {
  assert.ok(existsSync(TALUS), `${TALUS} is missing: build it with cargo build`);
  tmp = mkdtempSync(join(tmpdir(), 'talus-viewer-positions-'));
  good = { dir: join(tmp, 'good'), ...makeCampaignFixture(join(tmp, 'good')) };
  // A bad campaign: pair 1 names a positions file of 12n bytes (positions without distances), pair
  // 2 keeps its whole terrain.bin while naming positions, pair 3 names a file that is not there.
  bad = { dir: join(tmp, 'bad'), ...makeCampaignFixture(join(tmp, 'bad'), ['full', 'shared', 'shared', 'shared']) };
  const n = bad.points;
  writeFileSync(pairFile(bad, 0, 'positions-only.bin'), readFileSync(pairFile(bad, 0)).subarray(0, 12 * n));
  const setPositions = (i, path) => {
    const view = readJson(pairFile(bad, i, 'view.json'));
    view.positions = path;
    writeFileSync(pairFile(bad, i, 'view.json'), JSON.stringify(view));
  };
  setPositions(1, `../${bad.labels[0]}/positions-only.bin`);
  copyFileSync(pairFile(bad, 0), pairFile(bad, 2));
  setPositions(3, '../19990101_19990201/terrain.bin');
  [good.url, bad.url] = await Promise.all([serve(good.dir), serve(bad.dir)]);
  context = await launchBrowser(join(tmp, 'profile'));
});

after(async () => {
  await context?.close();
  servers.forEach(stopServer);
  if (tmp) rmSync(tmp, { recursive: true, force: true });
});

test('the fixture: pairs 1 and 2 keep only their distances and name pair 0\'s terrain', () => {
  const n = good.points;
  assert.deepEqual(good.labels.map((_, i) => readFileSync(pairFile(good, i)).length), [16 * n, 4 * n, 4 * n, 16 * n]);
  assert.deepEqual(good.labels.map((_, i) => readJson(pairFile(good, i, 'view.json')).positions ?? null),
    [null, `../${good.labels[0]}/terrain.bin`, `../${good.labels[0]}/terrain.bin`, null]);
  // Their distances differ, their points do not.
  assert.notDeepEqual(floats(pairFile(good, 1), 0, n), floats(pairFile(good, 0), 12 * n, n));
  assert.deepEqual(floats(pairFile(good, 3), 0, 3 * n), floats(pairFile(good, 0), 0, 3 * n));
});

test('a pair naming positions draws the first pair\'s core points with its own distances', async () => {
  const { page, terrainRequests } = await newPage();
  await page.goto(`${good.url}#pair=${good.labels[1]}`);
  await showing(page, good.labels[1]);
  assert.equal(await page.evaluate(() => window.__talus.terrainPoints), good.points);
  await assertTerrain(page, good.points, pairFile(good, 0), pairFile(good, 1));
  // Fetched through /data/, resolved here: the server refuses `..`.
  assert.deepEqual(terrainRequests.sort(), [`/data/pairs/${good.labels[0]}/terrain.bin`, `/data/pairs/${good.labels[1]}/terrain.bin`].sort());
  // The progress follows both downloads to the end, never backwards.
  const progress = await page.evaluate(() => window.__progress);
  assert.deepEqual(progress, [...progress].sort((a, b) => a - b), `${progress}`);
  assert.equal(progress.at(-1), 100, `${progress}`);
  await page.close();
});

test('old-style pairs (no positions) still load, in the same campaign', async () => {
  for (const i of [0, 3]) {
    const { page } = await newPage();
    await page.goto(`${good.url}#pair=${good.labels[i]}`);
    await showing(page, good.labels[i]);
    await assertTerrain(page, good.points, pairFile(good, i), pairFile(good, i));
    await page.close();
  }
});

test('switching pairs downloads the shared positions once', async () => {
  const { page, terrainRequests } = await newPage();
  const file = (i) => `/data/pairs/${good.labels[i]}/terrain.bin`;
  const count = (i) => terrainRequests.filter((p) => p === file(i)).length;
  await page.goto(`${good.url}#pair=${good.labels[0]}`);
  await showing(page, good.labels[0]);
  assert.equal(count(0), 1);
  // Pair 0's own terrain.bin had the positions: pairs 1 and 2 take them from the tab's cache.
  for (const i of [1, 2, 1]) {
    await page.selectOption('#pair', good.labels[i]);
    await showing(page, good.labels[i]);
    await assertTerrain(page, good.points, pairFile(good, 0), pairFile(good, i));
    const progress = await page.evaluate(() => window.__progress);
    assert.equal(progress.at(-1), 100, `pair ${i}: ${progress}`);
  }
  assert.equal(count(0), 1, terrainRequests.join('\n'));
  assert.equal(count(1), 2);
  assert.equal(count(2), 1);
  // An old-style pair downloads its own, as before.
  await page.selectOption('#pair', good.labels[3]);
  await showing(page, good.labels[3]);
  assert.equal(count(3), 1);
  await page.close();

  // A new tab opened on a sharing pair downloads the shared file once, then no more.
  const other = await newPage();
  await other.page.goto(`${good.url}#pair=${good.labels[2]}`);
  await showing(other.page, good.labels[2]);
  await other.page.selectOption('#pair', good.labels[1]);
  await showing(other.page, good.labels[1]);
  await assertTerrain(other.page, good.points, pairFile(good, 0), pairFile(good, 1));
  assert.deepEqual([...other.terrainRequests].sort(), [file(0), file(1), file(2)].sort(), other.terrainRequests.join('\n'));
  await other.page.close();
});

test('a positions file of the wrong size, or missing, is refused naming both files', async () => {
  const n = bad.points;
  const cases = [
    [1, [`pairs/${bad.labels[0]}/positions-only.bin`, `${12 * n} bytes, expected 16 × ${n} points`, `pairs/${bad.labels[1]}/terrain.bin`]],
    [2, [`pairs/${bad.labels[2]}/terrain.bin: ${16 * n} bytes, expected 4 × ${n} points`, `pairs/${bad.labels[0]}/terrain.bin`]],
    [3, ['pairs/19990101_19990201/terrain.bin', 'HTTP 404', `pairs/${bad.labels[3]}/terrain.bin`]],
  ];
  for (const [i, parts] of cases) {
    const { page } = await newPage(false);
    await page.goto(`${bad.url}#pair=${bad.labels[i]}`);
    const error = await settle(page, bad.labels[i]);
    assert.ok(error, `pair ${i} loaded`);
    for (const p of parts) assert.ok(error.includes(p), `pair ${i}: "${error}" does not say "${p}"`);
    assert.match(await page.textContent('#loading'), /Could not load the result/);
    await page.close();
  }
});

test('a sharing pair served alone says to open the campaign folder', async () => {
  const url = await serve(join(good.dir, 'pairs', good.labels[1]));
  const { page } = await newPage(false);
  await page.goto(url);
  const error = await settle(page, null);
  assert.ok(error, 'the pair loaded without its positions');
  assert.match(error, /terrain positions are in the campaign's first pair/);
  assert.match(error, /Open the campaign folder/);
  assert.match(await page.textContent('#loading'), /Open the campaign folder/);
  await page.close();
  // An old-style pair alone is a comparison result like any.
  const alone = await serve(join(good.dir, 'pairs', good.labels[3]));
  const ok = await newPage();
  await ok.page.goto(alone);
  await showing(ok.page, null);
  await assertTerrain(ok.page, good.points, pairFile(good, 3), pairFile(good, 3));
  await ok.page.close();
});

test('no console errors, no failed requests on the pages that should load', () => {
  assert.deepEqual(consoleErrors, []);
  assert.deepEqual(failedRequests, []);
});

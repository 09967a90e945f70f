// Browser test of the viewer on a REAL result: `talus synth spheres` then `talus compare`
// (default parameters), served by `talus view DIR --port 0`. The expected events are read from
// the result's events.geojson and the planted volumes from truth.json, never from the viewer.

import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import { existsSync, mkdirSync, mkdtempSync, readFileSync, rmSync, writeFileSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import { launchBrowser, serveTalus, stopServer } from './browser.mjs';

const HERE = dirname(fileURLToPath(import.meta.url));
const REPO = resolve(HERE, '..', '..');
const ARTIFACTS = join(HERE, '..', 'test-artifacts');
const TALUS = process.env.TALUS_BIN || join(process.env.CARGO_TARGET_DIR || join(REPO, 'target'), 'debug', 'talus');

let tmp;
let events;
let truth;
let server;
let context;
let page;
const consoleErrors = [];
const failedRequests = [];
const foreignRequests = [];

before(async () => {
  assert.ok(existsSync(TALUS), `${TALUS} is missing: build it with cargo build`);
  tmp = mkdtempSync(join(tmpdir(), 'talus-viewer-real-'));
  const scene = join(tmp, 'scene');
  const res = join(tmp, 'res');
  execFileSync(TALUS, ['synth', 'spheres', '--out', scene], { stdio: 'ignore' });
  execFileSync(TALUS, ['compare', join(scene, 'before.laz'), join(scene, 'after.laz'), '--out', res], { stdio: 'ignore' });
  events = JSON.parse(readFileSync(join(res, 'events.geojson'), 'utf8')).features;
  truth = JSON.parse(readFileSync(join(scene, 'truth.json'), 'utf8')).events;

  const { child, url } = await serveTalus(TALUS, res, REPO);
  server = child;
  assert.match(url, /^http:\/\/127\.0\.0\.1:\d+\/$/);

  context = await launchBrowser(join(tmp, 'profile'));
  page = context.pages()[0] || (await context.newPage());
  page.on('console', (m) => { if (m.type() === 'error') consoleErrors.push(m.text()); });
  page.on('pageerror', (e) => consoleErrors.push(String(e)));
  page.on('requestfailed', (r) => failedRequests.push(`${r.url()}: ${r.failure()?.errorText}`));
  page.on('response', (r) => { if (r.status() >= 400) failedRequests.push(`${r.url()}: HTTP ${r.status()}`); });
  page.on('request', (r) => { if (!r.url().startsWith(url) && !r.url().startsWith('data:') && !r.url().startsWith('blob:')) foreignRequests.push(r.url()); });
  await page.goto(url);
  await page.waitForFunction(() => window.__talus && (window.__talus.ready || window.__talus.error), null, { timeout: 120_000 });
});

after(async () => {
  await context?.close();
  stopServer(server);
  if (tmp) rmSync(tmp, { recursive: true, force: true });
});

test('a real compare result loads: every event has a marker and a row, with its volume', async () => {
  const t = await page.evaluate(() => ({ error: window.__talus.error, ready: window.__talus.ready, markers: window.__talus.markers, n: window.__talus.events.length }));
  assert.equal(t.error, null);
  assert.equal(t.ready, true);
  assert.equal(events.length, truth.length, 'the spheres scene finds one event per planted change');
  assert.equal(t.n, events.length);
  assert.equal(t.markers, events.length);
  const ids = await page.$$eval('#events tbody tr', (trs) => trs.map((tr) => Number(tr.dataset.id)));
  assert.deepEqual(ids.sort((a, b) => a - b), events.map((f) => f.properties.id).sort((a, b) => a - b));
  for (const f of events) {
    const p = f.properties;
    await page.locator(`#events tbody tr[data-id="${p.id}"]`).click();
    const shown = Number((await page.textContent('#panel [data-field="volume_m3"]')).replace(/\u2212/g, '-').replace(/[^0-9eE+\-.]/g, ''));
    assert.ok(Math.abs(shown - p.volume_m3) < 0.006, `event ${p.id}: panel ${shown} vs ${p.volume_m3}`);
    // And the volume is the planted one within 2 % (the nearest planted change of that kind).
    const near = truth
      .filter((e) => e.kind === p.kind)
      .sort((a, b) => Math.hypot(a.centre[0] - f.geometry.coordinates[0], a.centre[1] - f.geometry.coordinates[1])
        - Math.hypot(b.centre[0] - f.geometry.coordinates[0], b.centre[1] - f.geometry.coordinates[1]))[0];
    assert.ok(Math.abs(p.volume_m3 - near.volume_m3) <= 0.02 * Math.abs(near.volume_m3), `event ${p.id}: ${p.volume_m3} vs planted ${near.volume_m3}`);
  }
  mkdirSync(ARTIFACTS, { recursive: true });
  writeFileSync(join(ARTIFACTS, 'real-result.png'), await page.screenshot());
});

test('no console errors, no failed requests, nothing fetched from elsewhere', async () => {
  assert.deepEqual(consoleErrors, []);
  assert.deepEqual(failedRequests, []);
  assert.deepEqual(foreignRequests, []);
});

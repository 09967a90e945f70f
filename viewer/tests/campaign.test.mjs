// Browser test of the viewer on a REAL campaign: `talus synth campaign --epochs 4`, then
// `talus campaign` over its surveys, served by `talus view DIR --port 0` (the viewer built into
// the binary). The pair selector, the time slider and the campaign table switch pairs; events of
// one pair or of all, coloured by kind, pair or track; value labels never overlap. With the St
// Leonards surveys (tests/data/st-leonards) also a campaign of their first two, a pair of 49
// events. Expected values are read from the campaign's files, never from the viewer.
//
// TALUS_BIN: the talus binary (default target/debug/talus). Screenshots: viewer/tests/out/.

import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { execFile } from 'node:child_process';
import { existsSync, mkdirSync, mkdtempSync, readFileSync, readdirSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import { promisify } from 'node:util';
import { decodePng } from './png.mjs';
import { launchBrowser, serveTalus, stopServer } from './browser.mjs';

const HERE = dirname(fileURLToPath(import.meta.url));
const REPO = resolve(HERE, '..', '..');
const OUT = join(HERE, 'out');
const TALUS = process.env.TALUS_BIN || join(process.env.CARGO_TARGET_DIR || join(REPO, 'target'), 'debug', 'talus');
const LEO = resolve(REPO, 'tests', 'data', 'st-leonards');
const run = promisify(execFile);

let tmp;
let context;
const servers = [];
const consoleErrors = [];
const failedRequests = [];
const foreignRequests = [];
let synth; // { dir, url, table, events }
let leo; // the same for St Leonards, or null

const readJson = (p) => JSON.parse(readFileSync(p, 'utf8'));

/** A campaign result: its directory, the table and the events, as files say. */
function campaignFiles(dir) {
  return {
    dir,
    table: readJson(join(dir, 'campaign.json')).pairs,
    events: readJson(join(dir, 'events.geojson')).features.map((f) => f.properties),
    pairEvents: (label) => readJson(join(dir, 'pairs', label, 'events.geojson')).features.map((f) => f.properties),
  };
}

async function serve(dir) {
  const { child, url } = await serveTalus(TALUS, dir, REPO);
  servers.push(child);
  return url;
}

async function newPage(url) {
  const page = await context.newPage();
  page.on('console', (m) => { if (m.type() === 'error') consoleErrors.push(m.text()); });
  page.on('pageerror', (e) => consoleErrors.push(String(e)));
  page.on('requestfailed', (r) => failedRequests.push(`${r.url()}: ${r.failure()?.errorText}`));
  page.on('response', (r) => { if (r.status() >= 400) failedRequests.push(`${r.url()}: HTTP ${r.status()}`); });
  page.on('request', (r) => { if (!r.url().startsWith(url) && !r.url().startsWith('data:') && !r.url().startsWith('blob:')) foreignRequests.push(r.url()); });
  return page;
}

/** Wait until the page shows pair `label` (after a switch: a new page load), ready. */
async function showing(page, label) {
  await page.waitForFunction(
    (l) => window.__talus && (window.__talus.error || (window.__talus.ready && window.__talus.campaign?.pair === l)),
    label, { timeout: 120_000 },
  );
  assert.equal(await page.evaluate(() => window.__talus.error), null);
}

/** Ask for a frame and wait until it (and the compositor's next one) has been drawn. */
async function nextFrames(page) {
  const start = await page.evaluate(() => { window.__talus.render(); return window.__talus.frames; });
  await page.waitForFunction((s) => window.__talus.frames > s, start, { timeout: 10_000 });
  await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(() => r()))));
}

/** The value labels drawn (not hidden by the declutter, the filter or the frustum), with rects. */
const drawnLabels = (page) => page.$$eval('.event-label', (els) => els
  .filter((e) => e.parentElement.style.display !== 'none' && getComputedStyle(e).visibility !== 'hidden')
  .map((e) => {
    const r = e.getBoundingClientRect();
    return { id: Number(e.dataset.id), text: e.textContent, l: r.left, t: r.top, r: r.right, b: r.bottom };
  }));

const overlapping = (labels) => {
  const bad = [];
  for (let i = 0; i < labels.length; i++) {
    for (let j = i + 1; j < labels.length; j++) {
      const [a, b] = [labels[i], labels[j]];
      if (a.l < b.r && b.l < a.r && a.t < b.b && b.t < a.b) bad.push(`${a.text} / ${b.text}`);
    }
  }
  return bad;
};

const rowIds = (page) => page.$$eval('#events tbody tr', (trs) => trs.map((tr) => Number(tr.dataset.id)));

before(async () => {
  assert.ok(existsSync(TALUS), `${TALUS} is missing: build it with cargo build`);
  tmp = mkdtempSync(join(tmpdir(), 'talus-viewer-campaign-'));
  const surveys = join(tmp, 'surveys');
  await run(TALUS, ['synth', 'campaign', '--out', surveys, '--epochs', '4']);
  const files = readdirSync(surveys).filter((f) => /^survey_\d{8}\.laz$/.test(f)).sort().map((f) => join(surveys, f));
  assert.equal(files.length, 4);
  const jobs = [run(TALUS, ['campaign', ...files, '--out', join(tmp, 'synth')])];
  // Its first two surveys: the pair with the most events (49), at a third of the campaign's time.
  const leoFiles = readdirSync(LEO).filter((f) => f.endsWith('.laz')).sort().slice(0, 2).map((f) => join(LEO, f));
  assert.equal(leoFiles.length, 2, `the St Leonards surveys in ${LEO}`);
  jobs.push(run(TALUS, ['campaign', ...leoFiles, '--out', join(tmp, 'leo')]));
  await Promise.all(jobs);
  synth = campaignFiles(join(tmp, 'synth'));
  synth.url = await serve(synth.dir);
  if (leoFiles.length) {
    leo = campaignFiles(join(tmp, 'leo'));
    leo.url = await serve(leo.dir);
  }
  context = await launchBrowser(join(tmp, 'profile'));
});

after(async () => {
  await context?.close();
  servers.forEach(stopServer);
  if (tmp) rmSync(tmp, { recursive: true, force: true });
});

test('a campaign opens on its first pair, with the campaign table', async () => {
  const page = await newPage(synth.url);
  await page.goto(synth.url);
  const first = synth.table[0];
  await showing(page, first.label);
  const t = await page.evaluate(() => ({ campaign: window.__talus.campaign, events: window.__talus.events.map((e) => [e.id, e.kind, e.volume_m3, e.track_id]) }));
  assert.deepEqual(t.campaign.pairs, synth.table.map((p) => p.label));
  const want = synth.pairEvents(first.label);
  assert.deepEqual(t.events.map((e) => e.slice(0, 3)), want.map((e) => [e.id, e.kind, e.volume_m3]));
  // Their tracks are the campaign's.
  for (const [id, , , track] of t.events) {
    assert.equal(track, synth.events.find((e) => e.pair === first.label && e.id === id).track_id);
  }
  assert.deepEqual(await rowIds(page), want.map((e) => e.id));
  // The table: a row per pair with its dates, days, events and volumes; the shown pair marked.
  const rows = await page.$$eval('#campaign-table tbody tr', (trs) => trs.map((tr) => ({
    pair: tr.dataset.pair, selected: tr.classList.contains('selected'), cells: [...tr.cells].map((c) => c.textContent.trim()),
  })));
  assert.equal(rows.length, synth.table.length);
  const num = (s) => Number(s.replace(/\u2212/g, '-'));
  rows.forEach((r, i) => {
    const p = synth.table[i];
    assert.equal(r.pair, p.label);
    assert.equal(r.selected, i === 0);
    assert.equal(r.cells[0], `${p.before_date} → ${p.after_date}`);
    assert.equal(num(r.cells[1]), p.days);
    assert.equal(num(r.cells[2]), p.events);
    assert.ok(Math.abs(num(r.cells[3]) - p.gain_m3) < 0.051, `${r.cells[3]} vs ${p.gain_m3}`);
    assert.ok(Math.abs(num(r.cells[4]) - p.loss_m3) < 0.051, `${r.cells[4]} vs ${p.loss_m3}`);
    assert.ok(Math.abs(num(r.cells[5]) - p.net_m3) < 0.051, `${r.cells[5]} vs ${p.net_m3}`);
  });
  assert.match(await page.textContent('#meta'), new RegExp(`campaign of 4 surveys · pair 1 of 3: ${first.before_date} → ${first.after_date}`));
  await page.close();
});

test('the selector, the time slider and the table switch pairs, keeping the camera', async () => {
  const page = await newPage(synth.url);
  await page.goto(synth.url);
  const [p0, p1, p2] = synth.table;
  await showing(page, p0.label);
  // Move the camera off its home pose: the next pair must keep it (the pairs share the site).
  await page.mouse.move(400, 400);
  await page.mouse.wheel(0, -400);
  await page.waitForTimeout(300);
  const pose = await page.evaluate(() => window.__talus.camera());

  await page.selectOption('#pair', p1.label);
  await showing(page, p1.label);
  const at1 = await page.evaluate(() => ({ ids: window.__talus.events.map((e) => e.id), camera: window.__talus.camera(), points: window.__talus.terrainPoints }));
  assert.deepEqual(at1.ids, synth.pairEvents(p1.label).map((e) => e.id));
  assert.equal(at1.points, readJson(join(synth.dir, 'pairs', p1.label, 'view.json')).points);
  for (const k of ['position', 'target']) {
    at1.camera[k].forEach((v, a) => assert.ok(Math.abs(v - pose[k][a]) < 1e-6, `${k}: ${at1.camera[k]} vs ${pose[k]}`));
  }
  assert.equal(await page.$eval('#campaign-table tr.selected', (tr) => tr.dataset.pair), p1.label);
  assert.equal(await page.$eval('#pair-slider', (s) => s.value), '1');

  // The time slider: its last step.
  await page.$eval('#pair-slider', (s) => { s.value = '2'; s.dispatchEvent(new Event('input')); s.dispatchEvent(new Event('change')); });
  await showing(page, p2.label);
  assert.deepEqual(await rowIds(page), synth.pairEvents(p2.label).map((e) => e.id));
  // A row of the campaign table.
  await page.click(`#campaign-table tr[data-pair="${p0.label}"]`);
  await showing(page, p0.label);
  // And the browser's back button returns to the pair before.
  await page.goBack();
  await showing(page, p2.label);
  await page.close();
});

test('events of all pairs, coloured by pair or by track', async () => {
  const page = await newPage(synth.url);
  await page.goto(synth.url);
  await showing(page, synth.table[0].label);
  await page.selectOption('#scope', 'all');
  await page.waitForFunction(() => window.__talus?.ready && window.__talus.campaign?.scope === 'all', null, { timeout: 120_000 });
  const order = synth.table.map((p) => p.label);
  const want = [...synth.events].sort((a, b) => order.indexOf(a.pair) - order.indexOf(b.pair) || a.id - b.id);
  const got = await page.evaluate(() => window.__talus.events.map((e) => ({ id: e.id, pair: e.pair, event_id: e.event_id, track: e.track_id, volume: e.volume_m3, vegetation: e.vegetation })));
  // Vegetation events stay green under any colouring (they belong to no track).
  const vegetation = new Set(got.filter((e) => e.vegetation).map((e) => e.id));
  assert.deepEqual(got.map((e) => [e.pair, e.event_id, e.track, e.volume]), want.map((e) => [e.pair, e.id, e.track_id, e.volume_m3]));
  assert.deepEqual(got.map((e) => e.id), want.map((_, i) => i + 1));
  assert.equal(await page.evaluate(() => window.__talus.markers), want.length);
  assert.deepEqual(await page.$$eval('#events th', (ths) => ths.map((th) => th.textContent)).then((h) => h.slice(0, 4)), ['#', 'Kind', 'Pair', 'Track']);

  const colours = async (mode) => {
    await page.selectOption('#colour', mode);
    await page.waitForFunction((m) => window.__talus?.ready && window.__talus.campaign?.colour === m, mode, { timeout: 120_000 });
    return page.evaluate(() => window.__talus.markerColours);
  };
  // By track: one colour per track, different tracks apart (fewer tracks than colours here).
  const byTrack = await colours('track');
  const trackOf = new Map(got.map((e) => [e.id, e.track]));
  const perTrack = new Map();
  for (const [id, c] of Object.entries(byTrack)) {
    if (vegetation.has(Number(id))) { assert.equal(c, 0x4daf4a, `vegetation event ${id}`); continue; }
    const t = trackOf.get(Number(id));
    if (perTrack.has(t)) assert.equal(c, perTrack.get(t), `track ${t}`);
    perTrack.set(t, c);
  }
  assert.ok(perTrack.size > 3);
  assert.equal(new Set(perTrack.values()).size, perTrack.size);
  // The recurring track (events in several pairs) is what the colouring is for.
  assert.ok([...perTrack.keys()].some((t) => got.filter((e) => e.track === t).length > 1), 'no track recurs');
  assert.match(await page.textContent('#legend'), /track 1/);
  // The colour reaches the screen: the marker of the largest event, sampled on the canvas.
  const big = [...got].sort((a, b) => Math.abs(b.volume) - Math.abs(a.volume))[0];
  const p = await page.evaluate((id) => window.__talus.project(id), big.id);
  const style = await page.addStyleTag({ content: '#legend,#readout,#hud,#labels{visibility:hidden!important}' });
  await nextFrames(page);
  const canvas = page.locator('#view canvas');
  const box = await canvas.boundingBox();
  const px = decodePng(await canvas.screenshot());
  await style.evaluate((el) => el.remove());
  const o = 4 * (Math.round(p.y - box.y) * px.w + Math.round(p.x - box.x));
  const seen = [px.data[o], px.data[o + 1], px.data[o + 2]];
  const c = byTrack[big.id];
  const expect = [(c >> 16) & 255, (c >> 8) & 255, c & 255];
  assert.ok(seen.every((v, k) => Math.abs(v - expect[k]) < 45), `marker ${seen} vs track colour ${expect}`);

  // By pair: one colour per pair, in time order.
  const byPair = await colours('pair');
  const pairOf = new Map(got.map((e) => [e.id, e.pair]));
  const perPair = new Map();
  for (const [id, col] of Object.entries(byPair)) {
    if (vegetation.has(Number(id))) { assert.equal(col, 0x4daf4a, `vegetation event ${id}`); continue; }
    const q = pairOf.get(Number(id));
    if (perPair.has(q)) assert.equal(col, perPair.get(q));
    perPair.set(q, col);
  }
  assert.equal(new Set(perPair.values()).size, synth.table.length);
  assert.match(await page.textContent('#legend'), new RegExp(`${synth.table[0].before_date} → ${synth.table[0].after_date}`));
  await page.close();
});

/** On `page` (ready): drawn labels never overlap, some were hidden, hover brings one back. */
async function labelsDeclutter(page, name) {
  await nextFrames(page);
  const counts = await page.evaluate(() => window.__talus.labels);
  const drawn = await drawnLabels(page);
  assert.deepEqual(overlapping(drawn), [], `${name}: overlapping labels`);
  assert.equal(drawn.length, counts.shown);
  assert.ok(counts.hidden > 0, `${name}: no label was crowded out (${JSON.stringify(counts)}): the test shows nothing`);
  // Nor do they cover the panels over the canvas.
  for (const id of ['hud', 'legend', 'readout']) {
    const r = await page.locator(`#${id}`).boundingBox();
    const under = drawn.filter((l) => l.l < r.x + r.width && r.x < l.r && l.t < r.y + r.height && r.y < l.b);
    assert.deepEqual(under.map((l) => l.text), [], `${name}: labels under #${id}`);
  }
  // Hovering the marker of a hidden label shows that label (and still nothing overlaps).
  const shownIds = new Set(drawn.map((l) => l.id));
  const inView = await page.evaluate(() => {
    const r = document.querySelector('#view canvas').getBoundingClientRect();
    return window.__talus.events.map((e) => ({ id: e.id, p: window.__talus.project(e.id) }))
      .filter(({ p }) => p.x > r.left + 20 && p.x < r.right - 20 && p.y > r.top + 150 && p.y < r.bottom - 150);
  });
  const hidden = inView.find((e) => !shownIds.has(e.id));
  assert.ok(hidden, `${name}: no hidden label with its marker in view`);
  await page.mouse.move(hidden.p.x, hidden.p.y);
  await page.waitForFunction((id) => window.__talus.hovered?.kind === 'event', hidden.id, { timeout: 5000 });
  const hoveredId = await page.evaluate(() => window.__talus.hovered.id);
  await nextFrames(page);
  const after = await drawnLabels(page);
  assert.ok(after.some((l) => l.id === hoveredId), `${name}: the hovered event's label is not shown`);
  assert.deepEqual(overlapping(after), [], `${name}: overlapping labels on hover`);
  await page.mouse.move(2, 2);
  return drawn.length;
}

test('value labels never overlap: the crowded ones wait for hover or selection', async () => {
  const page = await newPage(synth.url);
  // All pairs: the recurring track's events lie on top of each other.
  await page.goto(`${synth.url}#pair=${synth.table[1].label}&events=all&colour=track`);
  await showing(page, synth.table[1].label);
  await labelsDeclutter(page, 'synthetic campaign, all pairs');
  mkdirSync(OUT, { recursive: true });
  await page.screenshot({ path: join(OUT, 'campaign-synth.png') });
  await page.close();
});

test('St Leonards: a 49-event pair has readable labels', async () => {
  const page = await newPage(leo.url);
  await page.goto(leo.url);
  const first = leo.table[0];
  await showing(page, first.label);
  assert.equal(await page.evaluate(() => window.__talus.events.length), first.events);
  assert.ok(first.events > 40, `the first pair has ${first.events} events`);
  const shown = await labelsDeclutter(page, 'St Leonards');
  assert.ok(shown >= 10, `only ${shown} labels shown`);
  // A selected event's label is shown whatever it overlapped.
  const hiddenId = await page.evaluate(() => {
    const ids = new Set([...document.querySelectorAll('.event-label.crowded')].map((e) => Number(e.dataset.id)));
    return [...ids][0];
  });
  await page.locator(`#events tbody tr[data-id="${hiddenId}"]`).click();
  await page.waitForFunction((id) => window.__talus.selected === id && !window.__talus.flying, hiddenId, { timeout: 10_000 });
  await nextFrames(page);
  const drawn = await drawnLabels(page);
  assert.ok(drawn.some((l) => l.id === hiddenId), 'the selected event has no label');
  assert.deepEqual(overlapping(drawn), []);
  await page.click('#reset');
  await page.waitForFunction(() => !window.__talus.flying, null, { timeout: 10_000 });
  await page.keyboard.press('Escape');
  await nextFrames(page);
  mkdirSync(OUT, { recursive: true });
  await page.screenshot({ path: join(OUT, 'campaign-st-leonards.png') });
  await page.close();
});

/** The ramp's half-width the legend should show for range [lo, hi]: the larger |end| rounded up
 * to 1, 1.5, 2, 2.5, 3, 4, 5, 6, 8 × 10^k (viewer/README.md), computed here from the files. */
function niceHalf([lo, hi]) {
  const r = Math.max(Math.abs(lo), Math.abs(hi));
  const p = 10 ** Math.floor(Math.log10(r));
  return [1, 1.5, 2, 2.5, 3, 4, 5, 6, 8, 10].find((m) => m * p >= r * (1 - 1e-9)) * p;
}

test('every pair is coloured on one scale, the campaign\'s, so pairs compare by eye', async () => {
  const own = synth.table.map((p) => readJson(join(synth.dir, 'pairs', p.label, 'view.json')).distance_range);
  const widest = own.reduce((a, b) => [Math.min(a[0], b[0]), Math.max(a[1], b[1])]);
  assert.deepEqual(readJson(join(synth.dir, 'campaign.json')).distance_range, widest);
  // The pairs' own scales differ (else the test shows nothing).
  assert.ok(new Set(own.map(niceHalf)).size > 1, `pairs' own scales ${own.map(niceHalf)}`);
  const want = niceHalf(widest);
  for (const p of synth.table) {
    // A page of its own per pair (a hash change on one page reloads it: campaign.js).
    const page = await newPage(synth.url);
    await page.goto(`${synth.url}#pair=${encodeURIComponent(p.label)}`);
    await showing(page, p.label);
    assert.equal(await page.evaluate(() => window.__talus.rampHalf), want, p.label);
    const ticks = await page.$$eval('#legend .ticks span', (s) => s.map((x) => x.textContent));
    assert.equal(ticks.at(-1), `+${Number(want.toPrecision(3))}`, `${p.label}: ${ticks}`);
    assert.match(await page.textContent('#legend .title'), /the same scale for every pair/);
    await page.close();
  }
});

test('the events table fits its panel, with every column of all pairs', async () => {
  const page = await newPage(synth.url);
  await page.goto(`${synth.url}#pair=${encodeURIComponent(synth.table[0].label)}&events=all&colour=track`);
  await page.waitForFunction(() => window.__talus?.ready && window.__talus.campaign?.scope === 'all', null, { timeout: 120_000 });
  const fit = await page.$eval('#table-wrap', (w) => ({ scroll: w.scrollWidth, client: w.clientWidth, cols: w.querySelectorAll('#events th').length }));
  assert.ok(fit.cols >= 8, `${fit.cols} columns`);
  assert.ok(fit.scroll <= fit.client, `the table is ${fit.scroll} px wide in a panel of ${fit.client}`);
  // An event in no track (vegetation) shows none, not track 0.
  const tracks = await page.$$eval('#events tbody tr', (trs) => trs.map((tr) => tr.children[3].textContent));
  assert.ok(!tracks.includes('0'), `${tracks}`);
  await page.close();
});

test('no console errors, no failed requests, nothing fetched from elsewhere', async () => {
  assert.deepEqual(consoleErrors, []);
  assert.deepEqual(failedRequests, []);
  assert.deepEqual(foreignRequests, []);
});

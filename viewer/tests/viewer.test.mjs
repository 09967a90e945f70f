// Browser test of the viewer: the real server (examples/view_server, or $TALUS_VIEW_CMD) on a
// synthetic result with known events, driven by headless Debian Chromium via playwright-core.
//
// The expected values come from the fixture generator (make-fixture.mjs) and from reading
// terrain.bin here in Node, never from the viewer's own code.
//
// TALUS_VIEW_CMD: a command that serves a result dir and prints its URL on stdout; "{dir}" in it
// is replaced by the directory, else the directory is appended, e.g.
//   TALUS_VIEW_CMD="target/debug/talus view {dir} --port 0"

import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { spawn } from 'node:child_process';
import { existsSync, mkdirSync, mkdtempSync, readFileSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import { launchBrowser } from './browser.mjs';
import { makeFixture } from './make-fixture.mjs';
import { decodePng } from './png.mjs';

const HERE = dirname(fileURLToPath(import.meta.url));
const REPO = resolve(HERE, '..', '..');
const ARTIFACTS = join(HERE, '..', 'test-artifacts');
const BACKGROUND = [0x2b, 0x30, 0x37];

let tmp;
let fixture;
let terrain; // { pos: Float32Array, dist: Float32Array } read back from the fixture file
let server;
let context;
let page;
const consoleErrors = [];
const failedRequests = [];
const requestUrls = [];

function serverCommand(dir) {
  const custom = process.env.TALUS_VIEW_CMD;
  if (custom && custom.trim()) {
    const parts = custom.trim().split(/\s+/);
    return parts.includes('{dir}') ? parts.map((p) => (p === '{dir}' ? dir : p)) : [...parts, dir];
  }
  const bin = join(process.env.CARGO_TARGET_DIR || join(REPO, 'target'), 'debug', 'examples', 'view_server');
  if (existsSync(bin)) return [bin, dir];
  return ['cargo', 'run', '--quiet', '--example', 'view_server', '--', dir];
}

/** Spawn the server and resolve with the first http:// URL it prints on stdout. */
function startServer(dir) {
  const [cmd, ...args] = serverCommand(dir);
  // Own process group, so a `cargo run` wrapper and its child are stopped together.
  const child = spawn(cmd, args, { cwd: REPO, detached: true, stdio: ['ignore', 'pipe', 'pipe'] });
  let stderr = '';
  child.stderr.on('data', (d) => { stderr += d; });
  const url = new Promise((res, rej) => {
    let out = '';
    const timer = setTimeout(() => rej(new Error(`server printed no URL in 180 s\n${stderr}`)), 180_000);
    child.stdout.on('data', (d) => {
      out += d;
      for (const line of out.split('\n')) {
        const m = /http:\/\/[^\s]+/.exec(line);
        if (m) { clearTimeout(timer); res(m[0]); return; }
      }
    });
    child.on('exit', (code) => { clearTimeout(timer); rej(new Error(`server exited (${code}):\n${stderr}`)); });
  });
  return { child, url };
}

/** Ask for a frame and wait until it (and the compositor's next one) has been drawn. */
async function nextFrames() {
  const start = await page.evaluate(() => { window.__talus.render(); return window.__talus.frames; });
  await page.waitForFunction((s) => window.__talus.frames > s, start, { timeout: 10_000 });
  await page.evaluate(() => new Promise((r) => requestAnimationFrame(() => requestAnimationFrame(() => r()))));
}

/** The canvas alone (overlays hidden) as RGBA pixels, decoded by the browser's PNG decoder. */
async function canvasPixels() {
  const style = await page.addStyleTag({ content: '#legend,#readout,#hud,#labels{visibility:hidden!important}' });
  await nextFrames();
  const canvas = page.locator('#view canvas');
  const box = await canvas.boundingBox();
  const png = await canvas.screenshot();
  await style.evaluate((el) => el.remove());
  const decoded = decodePng(png);
  return { ...decoded, box };
}

/** Mean colour of the (2r+1)² window around client point p. */
function colourAt(px, p, r = 2) {
  const cx = Math.round(p.x - px.box.x);
  const cy = Math.round(p.y - px.box.y);
  const sum = [0, 0, 0];
  let n = 0;
  for (let y = cy - r; y <= cy + r; y++) {
    for (let x = cx - r; x <= cx + r; x++) {
      if (x < 0 || y < 0 || x >= px.w || y >= px.h) continue;
      const o = 4 * (y * px.w + x);
      for (let c = 0; c < 3; c++) sum[c] += px.data[o + c];
      n++;
    }
  }
  return sum.map((s) => s / n);
}

const setChecked = async (id, on) => page.locator(`#${id}`).setChecked(on);
const signedVolume = (v, d) => `${v < 0 ? '\u2212' : '+'}${Math.abs(v).toFixed(d)}`;
const parseNum = (s) => Number(s.replace(/\u2212/g, '-').replace(/[^0-9eE+\-.]/g, ''));
const rowIds = () => page.$$eval('#events tbody tr', (trs) => trs.map((tr) => Number(tr.dataset.id)));
const visibleLabels = () => page.$$eval('.event-label', (els) => els.filter((e) => e.parentElement.style.display !== 'none').map((e) => e.textContent));

before(async () => {
  tmp = mkdtempSync(join(tmpdir(), 'talus-viewer-'));
  const dir = join(tmp, 'result');
  fixture = makeFixture(dir);
  const bin = readFileSync(join(dir, 'terrain.bin'));
  const buf = bin.buffer.slice(bin.byteOffset, bin.byteOffset + bin.byteLength);
  terrain = { pos: new Float32Array(buf, 0, 3 * fixture.points), dist: new Float32Array(buf, 12 * fixture.points) };

  server = startServer(dir);
  const url = await server.url;
  assert.match(url, /^http:\/\/127\.0\.0\.1:\d+\/$/);

  context = await launchBrowser(join(tmp, 'profile'));
  page = context.pages()[0] || (await context.newPage());
  page.on('console', (m) => { if (m.type() === 'error') consoleErrors.push(m.text()); });
  page.on('pageerror', (e) => consoleErrors.push(String(e)));
  page.on('request', (r) => requestUrls.push(r.url()));
  page.on('requestfailed', (r) => failedRequests.push(`${r.url()}: ${r.failure()?.errorText}`));
  page.on('response', (r) => { if (r.status() >= 400) failedRequests.push(`${r.url()}: HTTP ${r.status()}`); });
  await page.goto(url);
  await page.waitForFunction(() => window.__talus && (window.__talus.ready || window.__talus.error), null, { timeout: 120_000 });
});

after(async () => {
  await context?.close();
  if (server?.child?.pid) {
    try { process.kill(-server.child.pid, 'SIGTERM'); } catch { /* already gone */ }
  }
  if (tmp) rmSync(tmp, { recursive: true, force: true });
});

test('loads the result into a WebGL2 scene', async () => {
  const t = await page.evaluate(() => ({ ...window.__talus, hasGl: !!document.querySelector('#view canvas').getContext('webgl2') }));
  assert.equal(t.error, null);
  assert.equal(t.ready, true);
  assert.equal(t.webgl2, true);
  assert.equal(t.hasGl, true);
  assert.equal(t.terrainPoints, fixture.points);
  assert.deepEqual(t.origin, fixture.origin);
  assert.equal(t.crs, 'EPSG:32633');
  assert.deepEqual(
    t.events.map((e) => [e.id, e.kind, e.volume_m3]),
    fixture.events.map((e) => [e.id, e.kind, e.volume_m3]),
  );
  // Events without the vegetation properties (an older result) read as not vegetation, not judged.
  assert.deepEqual(
    t.events.map((e) => [e.id, e.vegetation, e.vegetation_fraction]),
    fixture.events.map((e) => [e.id, e.vegetation, e.vegetation_fraction]),
  );
  const meta = await page.textContent('#meta');
  assert.match(meta, /5 events, 1 of them vegetation/);
  assert.match(meta, /EPSG:32633/);
  assert.match(meta, /slope_2021\.laz → slope_2023\.laz/);
  assert.match(meta, /0\.1\.0-fixture/);
});

test('one marker, one label and one table row per event', async () => {
  assert.equal(await page.evaluate(() => window.__talus.markers), fixture.events.length);
  assert.deepEqual(await rowIds(), fixture.events.map((e) => e.id));
  await nextFrames();
  const expected = fixture.events.map((e) => `${signedVolume(e.volume_m3, 1)} ± ${e.volume_uncertainty_m3.toFixed(1)} m³`);
  assert.deepEqual((await visibleLabels()).sort(), expected.sort());
});

test('the legend says the colour convention (the report uses the same)', async () => {
  const text = await page.$eval('#legend', (el) => el.textContent);
  assert.match(text, /gain \(red: material added\)/);
  assert.match(text, /loss \(blue: material removed\)/);
  assert.match(text, /vegetation \(not in totals\)/);
});

test('the legend shows the small outlined dots on the terrain: the events\' markers', async () => {
  // The markers are disks with a white rim (events.js), the smallest ones small dots.
  const keys = await page.$$eval('#legend .dot', (ds) => ds.map((d) => ({
    rim: getComputedStyle(d).borderTopColor, width: getComputedStyle(d).borderTopWidth, text: d.parentElement.textContent,
  })));
  assert.ok(keys.length >= 4, JSON.stringify(keys));
  for (const k of keys) {
    assert.match(k.rim, /rgba?\(255, 255, 255/, JSON.stringify(k));
    assert.notEqual(k.width, '0px', JSON.stringify(k));
  }
  assert.match(await page.textContent('#legend'), /an event's marker, at its centre: size ∝ ∛\|volume\| \(the smallest events are the small dots\)/);
});

test('the events table fits its panel', async () => {
  const fit = await page.$eval('#table-wrap', (w) => ({ scroll: w.scrollWidth, client: w.clientWidth }));
  assert.ok(fit.scroll <= fit.client, `the table is ${fit.scroll} px wide in a panel of ${fit.client}`);
});

test('a vegetation event is green whatever its kind, on its marker too', async () => {
  const colours = await page.evaluate(() => window.__talus.markerColours);
  for (const e of fixture.events) {
    const want = e.vegetation ? 0x4daf4a : e.kind === 'gain' ? 0xe4573d : 0x3d8fe0;
    assert.equal(colours[e.id], want, `event ${e.id} (${e.kind}${e.vegetation ? ', vegetation' : ''})`);
  }
  const veg = fixture.events.find((e) => e.vegetation);
  assert.equal(veg.kind, 'gain');
  // The colour reaches the screen: the marker's centre on the canvas (alone: no labels or panels).
  await setChecked('show-labels', false);
  const px = await canvasPixels();
  const [r, g, b] = colourAt(px, await page.evaluate((id) => window.__talus.project(id), veg.id), 1);
  assert.ok(g > r + 40 && g > b + 40, `vegetation marker colour ${[r, g, b]}`);
  // Its label is green-rimmed too, not the gain's red.
  const label = await page.$eval(`.event-label[data-id="${veg.id}"]`, (el) => ({ cls: el.className, colour: getComputedStyle(el).borderTopColor }));
  assert.match(label.cls, /\bvegetation\b/);
  assert.match(label.colour, /rgba?\(77, 175, 74/);
  await setChecked('show-labels', true);
  await nextFrames();
});

test('the canvas shows the terrain coloured by distance: red on gains, blue on losses', async () => {
  for (const id of ['show-markers', 'show-labels', 'show-before', 'show-after']) await setChecked(id, false);
  const px = await canvasPixels();
  const n = px.w * px.h;
  let nonBackground = 0;
  const colours = new Set();
  for (let o = 0; o < px.data.length; o += 4) {
    const [r, g, b] = [px.data[o], px.data[o + 1], px.data[o + 2]];
    colours.add((r << 16) | (g << 8) | b);
    if (Math.abs(r - BACKGROUND[0]) + Math.abs(g - BACKGROUND[1]) + Math.abs(b - BACKGROUND[2]) > 12) nonBackground++;
  }
  assert.ok(nonBackground > 0.2 * n, `only ${nonBackground} of ${n} pixels are not background`);
  assert.ok(colours.size > 100, `only ${colours.size} distinct colours`);

  // The surface at each event centre: red where the fixture's distances are positive, blue
  // where negative; far from any event (distance ≈ 0) near-white.
  const at = async (local) => colourAt(px, await page.evaluate((l) => window.__talus.projectLocal(l), local));
  for (const e of fixture.events.slice(0, 2)) {
    const local = e.centroid.map((c, a) => c - fixture.origin[a]);
    const [r, g, b] = await at(local);
    if (e.kind === 'gain') assert.ok(r > g + 60 && r > b + 60, `event ${e.id} (gain) colour ${[r, g, b]}`);
    else assert.ok(b > r + 60 && b > g + 20, `event ${e.id} (loss) colour ${[r, g, b]}`);
  }
  const [r, g, b] = await at([20, 85, 0.25 * 85 + 3 * Math.sin(20 / 15)]);
  assert.ok(Math.min(r, g, b) > 170 && Math.max(r, g, b) - Math.min(r, g, b) < 30, `no-change colour ${[r, g, b]}`);

  // With every layer off only the background is left: the counts above came from the scene.
  await setChecked('show-terrain', false);
  const empty = await canvasPixels();
  let left = 0;
  for (let o = 0; o < empty.data.length; o += 4) {
    if (Math.abs(empty.data[o] - BACKGROUND[0]) + Math.abs(empty.data[o + 1] - BACKGROUND[1]) + Math.abs(empty.data[o + 2] - BACKGROUND[2]) > 12) left++;
  }
  assert.equal(left, 0);
  for (const id of ['show-terrain', 'show-markers', 'show-labels', 'show-before', 'show-after']) await setChecked(id, true);
  await nextFrames();
});

test('hovering a marker shows the event centre in global CRS coordinates', async () => {
  for (const e of fixture.events) {
    const p = await page.evaluate((id) => window.__talus.project(id), e.id);
    await page.mouse.move(p.x, p.y);
    await page.waitForFunction((id) => window.__talus.hovered?.id === id, e.id, { timeout: 5000 });
    const text = await page.textContent('#readout');
    assert.match(text, new RegExp(`Event #${e.id} \\(${e.kind}\\)`));
    const m = /centre x (\S+)\s+y (\S+)\s+z (\S+)/.exec(text);
    assert.ok(m, text);
    for (let a = 0; a < 3; a++) assert.ok(Math.abs(parseNum(m[a + 1]) - e.centroid[a]) < 6e-4, `${text} vs ${e.centroid}`);
    assert.match(text, /EPSG:32633/);
  }
});

test('hovering the terrain shows a real point in global coordinates with its distance', async () => {
  // A point away from every event; the readout must name a point of terrain.bin (to the
  // displayed millimetre) near it: global = origin + local has to be computed in f64.
  const k = 150 * 250 + 200;
  const target = [terrain.pos[3 * k], terrain.pos[3 * k + 1], terrain.pos[3 * k + 2]];
  const p = await page.evaluate((l) => window.__talus.projectLocal(l), target);
  await page.mouse.move(p.x, p.y);
  await page.waitForFunction(() => window.__talus.hovered?.kind === 'point', null, { timeout: 5000 });
  const text = await page.textContent('#readout');
  const m = /x (\S+)\s+y (\S+)\s+z (\S+) · [^·]*EPSG:32633[^·]* · M3C2 (\S+) m/.exec(text);
  assert.ok(m, text);
  const g = [1, 2, 3].map((i) => parseNum(m[i]));
  let match = -1;
  for (let i = 0; i < fixture.points; i++) {
    if ([0, 1, 2].every((a) => Math.abs(fixture.origin[a] + terrain.pos[3 * i + a] - g[a]) < 6e-4)) { match = i; break; }
  }
  assert.ok(match >= 0, `${text}: no terrain point there`);
  const dx = [0, 1, 2].map((a) => terrain.pos[3 * match + a] - target[a]);
  assert.ok(Math.hypot(...dx) < 2, `picked point ${match} is ${Math.hypot(...dx)} m from the cursor's`);
  assert.ok(Math.abs(parseNum(m[4]) - terrain.dist[match]) < 6e-4, `${text} vs ${terrain.dist[match]}`);
  await page.mouse.move(5, 5);
});

test('filters hide rows, markers and labels', async () => {
  const check = async (min, kind) => {
    await page.fill('#min-volume', String(min));
    await page.selectOption('#kind', kind);
    await nextFrames();
    const want = fixture.events
      .filter((e) => Math.abs(e.volume_m3) >= min && (kind === 'all' || e.kind === kind))
      .map((e) => e.id);
    assert.deepEqual(await rowIds(), want, `rows for min ${min}, ${kind}`);
    assert.equal(await page.evaluate(() => window.__talus.markers), want.length);
    assert.equal((await visibleLabels()).length, want.length);
    return want;
  };
  assert.deepEqual(await check(10, 'all'), [1, 2]);
  assert.deepEqual(await check(0, 'loss'), [2, 4]);
  assert.deepEqual(await check(2, 'gain'), [1, 3]);
  assert.deepEqual(await check(1000, 'all'), []);
  await check(0, 'all');
});

test('the vegetation filter: show, hide or only the vegetation events', async () => {
  const check = async (veg, kind = 'all') => {
    await page.selectOption('#vegetation', veg);
    await page.selectOption('#kind', kind);
    await nextFrames();
    const want = fixture.events
      .filter((e) => (veg === 'hide' ? !e.vegetation : veg === 'only' ? e.vegetation : true))
      .filter((e) => kind === 'all' || e.kind === kind)
      .map((e) => e.id);
    assert.deepEqual(await rowIds(), want, `rows for vegetation ${veg}, ${kind}`);
    assert.equal(await page.evaluate(() => window.__talus.markers), want.length);
    assert.deepEqual(await page.evaluate(() => window.__talus.visibleEventIds), want);
    assert.equal((await visibleLabels()).length, want.length);
    return want;
  };
  assert.equal(await page.inputValue('#vegetation'), 'show');
  assert.deepEqual(await check('hide'), [1, 2, 3, 4]);
  assert.deepEqual(await check('only'), [5]);
  assert.deepEqual(await check('only', 'loss'), []);
  assert.deepEqual(await check('show'), [1, 2, 3, 4, 5]);
  // Hidden, its marker is gone from the canvas as well (the terrain is under it again).
  await setChecked('show-labels', false);
  const veg = fixture.events.find((e) => e.vegetation);
  const at = async () => {
    const px = await canvasPixels();
    return colourAt(px, await page.evaluate((id) => window.__talus.project(id), veg.id), 1);
  };
  const shown = await at();
  await page.selectOption('#vegetation', 'hide');
  const hidden = await at();
  assert.ok(shown[1] > shown[0] + 40, `shown: ${shown}`);
  assert.ok(!(hidden[1] > hidden[0] + 40 && hidden[1] > hidden[2] + 40), `hidden, still green: ${hidden}`);
  await page.selectOption('#vegetation', 'show');
  await setChecked('show-labels', true);
  await nextFrames();
});

test('sorting by volume', async () => {
  const th = page.locator('th[data-key="volume_m3"]');
  const volumes = () => page.$$eval('#events tbody td[data-value]', (tds) => tds.map((td) => Number(td.dataset.value)));
  const all = fixture.events.map((e) => e.volume_m3);
  await th.click();
  const first = await th.getAttribute('aria-sort');
  const desc = [...all].sort((a, b) => b - a);
  const asc = [...all].sort((a, b) => a - b);
  assert.deepEqual(await volumes(), first === 'descending' ? desc : asc);
  await th.click();
  assert.equal(await th.getAttribute('aria-sort'), first === 'descending' ? 'ascending' : 'descending');
  assert.deepEqual(await volumes(), first === 'descending' ? asc : desc);
  await page.locator('th[data-key="id"]').click();
  assert.deepEqual(await rowIds(), fixture.events.map((e) => e.id));
});

test('clicking a row flies to the event and shows its properties', async () => {
  for (const e of [fixture.events[1], fixture.events[0]]) {
    await page.locator(`#events tbody tr[data-id="${e.id}"]`).click();
    await page.waitForFunction((id) => window.__talus.selected === id && !window.__talus.flying, e.id, { timeout: 10_000 });
    assert.match(await page.textContent('#panel h2'), new RegExp(`Event #${e.id}\\b`));
    const vol = parseNum(await page.textContent('#panel [data-field="volume_m3"]'));
    assert.ok(Math.abs(vol - e.volume_m3) < 0.005 + 1e-9, `panel volume ${vol} vs ${e.volume_m3}`);
    const unc = parseNum(await page.textContent('#panel [data-field="volume_uncertainty_m3"]'));
    assert.ok(Math.abs(unc - e.volume_uncertainty_m3) < 0.005 + 1e-9);
    // The camera now looks at the event: its centre is in the middle of the canvas.
    const box = await page.locator('#view canvas').boundingBox();
    const p = await page.evaluate((id) => window.__talus.project(id), e.id);
    assert.ok(Math.abs(p.x - (box.x + box.width / 2)) < 3 && Math.abs(p.y - (box.y + box.height / 2)) < 3, JSON.stringify(p));
  }
  // Event 1 carries the optional gain/loss split.
  assert.match(await page.textContent('#panel [data-field="gain_m3"]'), /\+120\.50/);

  // No vegetation line for an event not judged (event 1: an older result's properties).
  assert.equal(await page.locator('#panel [data-field="vegetation"]').count(), 0);

  await page.click('#reset');
  await page.waitForFunction(() => !window.__talus.flying, null, { timeout: 10_000 });
  await nextFrames();
  mkdirSync(ARTIFACTS, { recursive: true });
  await page.screenshot({ path: join(ARTIFACTS, 'viewer.png') });
});

test('the panel, the row and the read-out say what share of its points look like vegetation', async () => {
  const veg = fixture.events.find((e) => e.vegetation);
  const row = page.locator(`#events tbody tr[data-id="${veg.id}"]`);
  assert.match(await row.textContent(), /vegetation \(80 %\)/);
  assert.equal(await row.getAttribute('title'), 'vegetation (80 % of its points)');
  await row.click();
  await page.waitForFunction((id) => window.__talus.selected === id && !window.__talus.flying, veg.id, { timeout: 10_000 });
  assert.match(await page.textContent('#panel h2'), new RegExp(`Event #${veg.id}\\b.*vegetation`));
  assert.equal(await page.textContent('#panel [data-field="vegetation"]'), 'vegetation (80 % of its points)');
  // Hovering its marker says it too.
  const p = await page.evaluate((id) => window.__talus.project(id), veg.id);
  await page.mouse.move(p.x, p.y);
  await page.waitForFunction((id) => window.__talus.hovered?.id === id, veg.id, { timeout: 5000 });
  assert.match(await page.textContent('#readout'), new RegExp(`Event #${veg.id} \\(gain\\) .*vegetation \\(80 % of its points\\)`));
  await page.mouse.move(5, 5);
  // An event judged not vegetation: its fraction, in the panel and the row's tooltip.
  const judged = fixture.events.find((e) => !e.vegetation && e.vegetation_fraction != null);
  const jrow = page.locator(`#events tbody tr[data-id="${judged.id}"]`);
  assert.doesNotMatch(await jrow.textContent(), /vegetation/);
  assert.equal(await jrow.getAttribute('title'), 'vegetation-like points: 12 %');
  await jrow.click();
  await page.waitForFunction((id) => window.__talus.selected === id && !window.__talus.flying, judged.id, { timeout: 10_000 });
  assert.equal(await page.textContent('#panel [data-field="vegetation"]'), 'vegetation-like points: 12 %');
  assert.doesNotMatch(await page.textContent('#panel h2'), /vegetation/);
  await page.click('#reset');
  await page.waitForFunction(() => !window.__talus.flying, null, { timeout: 10_000 });
});

test('no console errors, no failed requests, nothing but 127.0.0.1', async () => {
  assert.deepEqual(consoleErrors, []);
  assert.deepEqual(failedRequests, []);
  const foreign = requestUrls.filter((u) => !u.startsWith('data:') && new URL(u).hostname !== '127.0.0.1');
  assert.deepEqual(foreign, []);
  for (const path of ['/data/view.json', '/data/events.geojson', '/data/terrain.bin', '/data/meshes/event_0001_after.ply']) {
    assert.ok(requestUrls.some((u) => new URL(u).pathname === path), `${path} was not requested`);
  }
});

// Browser test of the campaign report page: `cargo run --example campaign_report` writes
// report.html from its built-in sample data; headless Debian Chromium (via playwright-core)
// opens it from a file:// URL. The page must fetch nothing, draw its four figures and
// render without errors; a full-page screenshot goes to viewer/tests/out/report.png.
//
// The expected counts come from the page's own table and the example's data as written
// (5 pairs), never from the report code.

import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import { existsSync, mkdirSync, mkdtempSync, readFileSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath, pathToFileURL } from 'node:url';
import { chromium } from 'playwright-core';

const HERE = dirname(fileURLToPath(import.meta.url));
const REPO = resolve(HERE, '..', '..');
const OUT = join(HERE, 'out');
const CHROMIUM = process.env.CHROMIUM || '/usr/bin/chromium';
const PAIRS = 5;

let tmp;
let html;
let context;
let page;
const consoleErrors = [];
const requests = [];

before(async () => {
  // Fail loudly: a missing browser is an error, not a skip (run.sh installs it).
  assert.ok(existsSync(CHROMIUM), `${CHROMIUM} is missing: install Debian's chromium (viewer/tests/run.sh does)`);
  tmp = mkdtempSync(join(tmpdir(), 'talus-report-'));
  const file = join(tmp, 'report.html');
  execFileSync('cargo', ['run', '--quiet', '--example', 'campaign_report', '--', file], {
    cwd: REPO,
    stdio: ['ignore', 'ignore', 'inherit'],
  });
  html = readFileSync(file, 'utf8');

  context = await chromium.launchPersistentContext(join(tmp, 'profile'), {
    executablePath: CHROMIUM,
    headless: true,
    viewport: { width: 1200, height: 900 },
    deviceScaleFactor: 1,
    args: [
      '--headless', '--no-sandbox', '--disable-gpu', '--disable-quic', '--no-first-run',
      '--disable-background-networking', '--disable-component-update', '--disable-sync',
    ],
  });
  page = context.pages()[0] || (await context.newPage());
  page.on('console', (m) => { if (m.type() === 'error') consoleErrors.push(m.text()); });
  page.on('pageerror', (e) => consoleErrors.push(String(e)));
  // Every request the page makes; the navigation to the file itself is the only one allowed.
  const url = pathToFileURL(file).href;
  page.on('request', (r) => { if (r.url() !== url) requests.push(r.url()); });
  await page.goto(url, { waitUntil: 'load' });
});

after(async () => {
  await context?.close();
  if (tmp) rmSync(tmp, { recursive: true, force: true });
});

test('renders without console errors and fetches nothing', async () => {
  assert.deepEqual(consoleErrors, []);
  assert.deepEqual(requests, []);
  assert.doesNotMatch(html, /https?:\/\//);
  assert.equal(await page.title(), 'Val Ferret rock slope — monitoring campaign 2023–2024 — campaign report');
});

test('the campaign table has one row per pair and a totals row', async () => {
  const rows = await page.$$eval('#campaign-table tbody tr', (trs) => trs.map((tr) => tr.querySelector('th').textContent));
  assert.equal(rows.length, PAIRS);
  assert.deepEqual(rows, [
    '20230314_20230620', '20230620_20230912', '20230912_20231205', '20231205_20240319', '20240319_20240611',
  ]);
  const foot = await page.$$eval('#campaign-table tfoot tr', (trs) => trs.map((tr) => tr.textContent));
  assert.equal(foot.length, 1);
  assert.match(foot[0], /^Total/);
  // 14 cells in every row: the pair, before and after (survey over date), then 11 numbers.
  const cells = await page.$$eval('#campaign-table tbody tr', (trs) => trs.map((tr) => tr.children.length));
  assert.deepEqual(cells, Array(PAIRS).fill(14));
  // The table fits the page: no horizontal scrolling.
  const [scroll, client] = await page.$eval('#campaign-table .scroll', (d) => [d.scrollWidth, d.clientWidth]);
  assert.ok(scroll <= client, `table ${scroll} px wide in ${client} px`);
  // Days sum to the campaign's span, 2023-03-14 to 2024-06-11.
  const days = await page.$$eval('#campaign-table tbody tr', (trs) => trs.map((tr) => Number(tr.children[3].textContent)));
  assert.equal(days.reduce((a, b) => a + b, 0), 455);
});

test('four figure sections, every SVG drawn with a nonzero size', async () => {
  const sections = await page.$$eval('main > section', (ss) => ss.map((s) => [s.id, s.querySelectorAll('svg').length]));
  assert.deepEqual(sections, [['campaign-table', 0], ['cumulative', 1], ['magnitude-frequency', 1], ['maps', PAIRS]]);
  const sizes = await page.$$eval('svg', (svgs) => svgs.map((s) => { const r = s.getBoundingClientRect(); return [r.width, r.height]; }));
  assert.equal(sizes.length, 2 + PAIRS);
  for (const [w, h] of sizes) assert.ok(w > 100 && h > 100, `svg of ${w} × ${h}`);
  const labelled = await page.$$eval('svg', (svgs) => svgs.every((s) => s.getAttribute('role') === 'img' && s.querySelector('title')?.textContent.length > 0));
  assert.ok(labelled);
});

test('the cumulative chart has its three series, one mark per survey', async () => {
  const series = await page.$$eval('#cumulative polyline.series', (ps) => ps.map((p) => [p.dataset.series, p.points.length]));
  assert.deepEqual(series, [['gain', PAIRS + 1], ['loss', PAIRS + 1], ['net', PAIRS + 1]]);
  const text = await page.textContent('#cumulative svg');
  assert.match(text, /Cumulative volume \(m³\)/);
  assert.match(text, /Survey date/);
  // Gain ends above the zero line and loss below it (SVG y grows downwards).
  const ends = await page.$$eval('#cumulative polyline.series', (ps) => ps.map((p) => p.points.getItem(p.points.length - 1).y));
  const start = await page.$eval('#cumulative polyline.series', (p) => p.points.getItem(0).y);
  assert.ok(ends[0] < start && ends[1] > start, `gain ${ends[0]}, loss ${ends[1]}, zero ${start}`);
});

test('the magnitude–frequency plot has its marks and both fit lines', async () => {
  const fits = await page.$$eval('#magnitude-frequency line.fit', (ls) => ls.map((l) => {
    const b = l.getBoundingClientRect();
    return [l.dataset.kind, b.width];
  }));
  assert.deepEqual(fits.map((f) => f[0]), ['gain', 'loss']);
  for (const [, w] of fits) assert.ok(w > 20, `fit line ${w} px wide`);
  const marks = await page.$$eval('#magnitude-frequency g.marks', (gs) => gs.map((g) => [g.dataset.kind, g.children.length]));
  assert.equal(marks.length, 2);
  for (const [, n] of marks) assert.ok(n >= 10, `${n} marks`);
  const legend = await page.$$eval('#magnitude-frequency text.fit-legend', (ts) => ts.map((t) => t.textContent));
  assert.equal(legend.length, 2);
  for (const l of legend) assert.match(l, /^α = \d\.\d\d ± \d\.\d\d$/);
});

test('each pair has a map with its event polygons, a scale bar and a north arrow', async () => {
  const maps = await page.$$eval('#maps figure svg', (svgs) => svgs.map((s) => ({
    events: s.querySelectorAll('path.event').length,
    context: s.querySelectorAll('path.context').length,
    scale: s.querySelectorAll('.scale-bar').length,
    north: s.querySelectorAll('.north').length,
    width: s.getBoundingClientRect().width,
    height: s.getBoundingClientRect().height,
  })));
  assert.equal(maps.length, PAIRS);
  const counts = await page.$$eval('#campaign-table tbody tr', (trs) => trs.map((tr) => Number(tr.children[6].textContent)));
  assert.deepEqual(maps.map((m) => m.events), counts);
  for (const m of maps) {
    assert.equal(m.context, 1);
    assert.equal(m.scale, 1);
    assert.equal(m.north, 1);
  }
  // The same extent and scale everywhere: equal panel sizes.
  assert.ok(maps.every((m) => m.width === maps[0].width && m.height === maps[0].height));
  // Track labels never overlap within a panel.
  const overlaps = await page.$$eval('#maps figure svg', (svgs) => svgs.map((s) => {
    const boxes = [...s.querySelectorAll('text.track')].map((t) => t.getBoundingClientRect());
    let n = 0;
    for (let i = 0; i < boxes.length; i++) {
      for (let j = i + 1; j < boxes.length; j++) {
        const [a, b] = [boxes[i], boxes[j]];
        if (a.left < b.right && b.left < a.right && a.top < b.bottom && b.top < a.bottom) n++;
      }
    }
    return [boxes.length, n];
  }));
  assert.ok(overlaps.some(([n]) => n > 0), 'no track labels at all');
  assert.ok(overlaps.every(([, n]) => n === 0), JSON.stringify(overlaps));
});

test('no text overflows its SVG', async () => {
  const outside = await page.$$eval('svg', (svgs) => svgs.flatMap((s, k) => {
    const r = s.getBoundingClientRect();
    return [...s.querySelectorAll('text')]
      .map((t) => [t.textContent, t.getBoundingClientRect()])
      .filter(([, b]) => b.left < r.left - 0.5 || b.right > r.right + 0.5 || b.top < r.top - 0.5 || b.bottom > r.bottom + 0.5)
      .map(([text]) => `svg ${k}: ${text}`);
  }));
  assert.deepEqual(outside, []);
});

test('full-page screenshot', async () => {
  mkdirSync(OUT, { recursive: true });
  const png = await page.screenshot({ path: join(OUT, 'report.png'), fullPage: true });
  assert.ok(png.length > 10_000);
});

// Browser test of the viewer's first view of a steep face (issue 43, item 6): a face scanned
// alone from 300 m (`talus synth face`), compared with defaults and served by `talus view`. The
// first view must look at the face along its mean normal (view.json `facing`), and that normal
// must face the scanner whose position truth.json gives (written by the scene, not the viewer).

import { test, before, after } from 'node:test';
import assert from 'node:assert/strict';
import { execFileSync } from 'node:child_process';
import { existsSync, mkdtempSync, readFileSync, rmSync } from 'node:fs';
import { tmpdir } from 'node:os';
import { dirname, join, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';
import { openResult, stopServer } from './browser.mjs';

const HERE = dirname(fileURLToPath(import.meta.url));
const REPO = resolve(HERE, '..', '..');
const TALUS = process.env.TALUS_BIN || join(process.env.CARGO_TARGET_DIR || join(REPO, 'target'), 'debug', 'talus');

let tmp;
let view;
let truth;
let server;
let context;
let page;

before(async () => {
  assert.ok(existsSync(TALUS), `${TALUS} is missing: build it with cargo build`);
  tmp = mkdtempSync(join(tmpdir(), 'talus-viewer-face-'));
  const scene = join(tmp, 'scene');
  const res = join(tmp, 'res');
  execFileSync(TALUS, ['synth', 'face', '--points', '20000', '--out', scene], { stdio: 'ignore' });
  execFileSync(TALUS, ['compare', join(scene, 'before.laz'), join(scene, 'after.laz'), '--out', res], { stdio: 'ignore' });
  view = JSON.parse(readFileSync(join(res, 'view.json'), 'utf8'));
  truth = JSON.parse(readFileSync(join(scene, 'truth.json'), 'utf8'));
  ({ server, context, page } = await openResult(TALUS, res, REPO, tmp));
});

after(async () => {
  await context?.close();
  stopServer(server);
  if (tmp) rmSync(tmp, { recursive: true, force: true });
});

test('the first view of a face scanned alone looks at the face, from the scanner\'s side', async () => {
  const t = await page.evaluate(() => ({ error: window.__talus.error, camera: window.__talus.camera() }));
  assert.equal(t.error, null);
  const f = view.facing;
  assert.ok(Array.isArray(f) && f.length === 3, `view.json facing: ${JSON.stringify(f)}`);
  // A 70° face: its mean normal is far from the vertical.
  assert.ok(f[2] < Math.SQRT1_2, `facing ${f} is not steep`);
  // It faces the scanner: the horizontal direction from the view's centre to the scanner.
  const [px, py, pz] = t.camera.position;
  const [tx, ty, tz] = t.camera.target;
  const toScanner = [truth.scanner[0] - (tx + view.origin[0]), truth.scanner[1] - (ty + view.origin[1])];
  const h = Math.hypot(...toScanner);
  const cosScanner = (f[0] * toScanner[0] + f[1] * toScanner[1]) / (h * Math.hypot(f[0], f[1]));
  assert.ok(cosScanner > Math.cos((20 * Math.PI) / 180), `facing ${f} is ${Math.acos(cosScanner)} rad from the scanner's bearing`);
  // The camera looks along it.
  const d = [px - tx, py - ty, pz - tz];
  const len = Math.hypot(...d);
  const cos = (d[0] * f[0] + d[1] * f[1] + d[2] * f[2]) / len;
  assert.ok(cos > 0.999, `camera direction ${d.map((v) => v / len)} vs facing ${f}`);
});

// The three.js files built into talus (viewer/vendor/three/, embedded by build.rs) are exact
// copies of the npm package at the version viewer/package-lock.json locks, and exactly the
// modules the page imports (no more, no fewer). After `npm install three@NEW` in viewer/, copy
// the files this test names from node_modules/three/ to vendor/three/ (same paths).

import { test } from 'node:test';
import assert from 'node:assert/strict';
import { readFileSync, readdirSync, statSync } from 'node:fs';
import { dirname, join, relative, resolve } from 'node:path';
import { fileURLToPath } from 'node:url';

const VIEWER = resolve(dirname(fileURLToPath(import.meta.url)), '..');
const VENDOR = join(VIEWER, 'vendor', 'three');
const NPM = join(VIEWER, 'node_modules', 'three');

function files(dir) {
  return readdirSync(dir).flatMap((name) => {
    const p = join(dir, name);
    return statSync(p).isDirectory() ? files(p) : [p];
  });
}

test('the vendored three is the locked npm version, byte for byte', () => {
  const lock = JSON.parse(readFileSync(join(VIEWER, 'package-lock.json'), 'utf8'));
  const locked = lock.packages['node_modules/three'].version;
  const installed = JSON.parse(readFileSync(join(NPM, 'package.json'), 'utf8')).version;
  assert.equal(installed, locked, 'node_modules/three is not the locked version: run `npm ci` in viewer/');
  const vendored = files(VENDOR).map((p) => relative(VENDOR, p)).sort();
  assert.ok(vendored.includes('LICENSE'), 'three.js is MIT: its LICENSE must sit beside the copy');
  for (const rel of vendored) {
    assert.ok(
      readFileSync(join(VENDOR, rel)).equals(readFileSync(join(NPM, rel))),
      `viewer/vendor/three/${rel} differs from node_modules/three/${rel} (three ${locked})`,
    );
  }
});

/** The static imports of an ES module's source. */
function imports(source) {
  return [...source.matchAll(/(?:^|[\s;}])(?:import|export)\s[^'"]*?from\s*['"]([^'"]+)['"]/g)].map((m) => m[1]);
}

test('the vendored three files are exactly what the page imports', () => {
  const html = readFileSync(join(VIEWER, 'index.html'), 'utf8');
  const map = JSON.parse(/<script type="importmap">([\s\S]*?)<\/script>/.exec(html)[1]).imports;
  // Resolve a specifier the way the browser does with this import map, to a path under viewer/.
  const resolveSpec = (spec, fromDir) => {
    if (spec.startsWith('.')) return relative(VIEWER, resolve(fromDir, spec));
    const key = Object.keys(map).find((k) => (k.endsWith('/') ? spec.startsWith(k) : spec === k));
    assert.ok(key, `import '${spec}' is not in the import map`);
    const target = map[key] + spec.slice(key.length);
    return target.replace(/^\//, '');
  };
  const seen = new Set();
  const queue = files(join(VIEWER, 'src')).filter((p) => p.endsWith('.js')).map((p) => relative(VIEWER, p));
  while (queue.length) {
    const rel = queue.pop();
    if (seen.has(rel)) continue;
    seen.add(rel);
    const source = readFileSync(join(VIEWER, rel), 'utf8');
    for (const spec of imports(source)) queue.push(resolveSpec(spec, dirname(join(VIEWER, rel))));
  }
  const reached = [...seen].filter((p) => p.startsWith('vendor/three/')).sort();
  const vendored = files(VENDOR)
    .map((p) => relative(VIEWER, p))
    .filter((p) => p.endsWith('.js'))
    .sort();
  assert.deepEqual(vendored, reached);
});

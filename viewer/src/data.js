// Loading a talus result directory, served under /data/ (contract: view.json, events.geojson,
// terrain.bin, meshes/*.ply, optional summary.json). Everything is shifted into the local frame
// (global − origin) here, in f64, before it becomes float32 for the GPU.
//
// A campaign pair's view.json may name `positions`: another pair's full terrain.bin whose first
// 12n bytes are this pair's core points (every pair of a campaign has the same ones, in the same
// order, with the same origin); its own terrain file then holds only the n distances.

import { parsePly } from './ply.js';

/** Where `talus view` serves the directory it was given. */
const ROOT = '/data/';
let DATA = ROOT;

/**
 * Where the result's files are: `/data/` for a comparison, `/data/pairs/<label>/` for a pair of
 * a campaign (each pair directory is a comparison result).
 */
export function setBase(base) {
  DATA = base;
}

async function fetchOk(path, signal) {
  const res = await fetch(DATA + path, { signal });
  if (!res.ok) throw new Error(`${path}: HTTP ${res.status}`);
  return res;
}

function isVec3(v) {
  return Array.isArray(v) && v.length >= 2 && v.slice(0, 3).every(Number.isFinite);
}

/** view.json, checked: the rest of the viewer relies on these fields. */
export async function loadView() {
  const view = await (await fetchOk('view.json')).json();
  if (!isVec3(view.origin) || view.origin.length !== 3) throw new Error('view.json: origin must be [x, y, z]');
  if (!Number.isInteger(view.points) || view.points < 0) throw new Error('view.json: points must be a count');
  view.crs = typeof view.crs === 'string' && view.crs ? view.crs : 'unknown';
  view.units = typeof view.units === 'string' ? view.units : 'm';
  view.terrain = typeof view.terrain === 'string' ? view.terrain : 'terrain.bin';
  if (view.positions != null && (typeof view.positions !== 'string' || !view.positions)) {
    throw new Error('view.json: positions must be the path of a terrain file');
  }
  view.positions = view.positions || null;
  view.meshes = view.meshes && typeof view.meshes === 'object' ? view.meshes : {};
  return view;
}

/** summary.json is optional: `null` when absent or unreadable. */
export async function loadSummary(base = DATA) {
  try {
    const res = await fetch(base + 'summary.json');
    return res.ok ? await res.json() : null;
  } catch {
    return null;
  }
}

/**
 * events.geojson → [{ ...properties, centroid (global f64), local [3] }], plus the collection's
 * crs_name (or null). `vegetation` is always a boolean and `vegetation_fraction` a number in
 * 0..1 or null: results written before talus judged vegetation lack both, and read as "not
 * vegetation, not judged".
 */
export async function loadEvents(origin) {
  return parseEvents(await (await fetchOk('events.geojson')).json(), origin, 'events.geojson');
}

/** An events FeatureCollection (`name` for messages) → what [`loadEvents`] returns. */
export function parseEvents(fc, origin, name) {
  if (!fc || !Array.isArray(fc.features)) throw new Error(`${name}: not a FeatureCollection`);
  const events = [];
  for (const f of fc.features) {
    const p = { ...(f.properties || {}) };
    const c = f.geometry && f.geometry.coordinates;
    if (!Number.isInteger(p.id) || !isVec3(c)) continue;
    const centroid = [c[0], c[1], Number.isFinite(c[2]) ? c[2] : (p.obb?.center?.[2] ?? origin[2])];
    p.kind = p.kind === 'loss' || (p.kind !== 'gain' && p.volume_m3 < 0) ? 'loss' : 'gain';
    p.vegetation = p.vegetation === true;
    p.vegetation_fraction = Number.isFinite(p.vegetation_fraction) ? p.vegetation_fraction : null;
    p.centroid = centroid;
    p.local = centroid.map((v, a) => v - origin[a]);
    events.push(p);
  }
  return { events, crsName: typeof fc.crs_name === 'string' ? fc.crs_name : null };
}

/**
 * A path of view.json (relative to the result directory shown) resolved here, as the server
 * refuses `..` segments: { url (an absolute path to fetch), name (for messages: the path within
 * the served directory), inside (false when it leads out of the served directory) }.
 */
function locate(path) {
  const url = new URL(path, location.origin + DATA);
  const inside = url.origin === location.origin && url.pathname.startsWith(ROOT);
  let name = path;
  if (inside) {
    try {
      name = decodeURIComponent(url.pathname.slice(ROOT.length));
    } catch {
      name = url.pathname.slice(ROOT.length);
    }
  }
  return { url: url.pathname, name, inside };
}

/**
 * The body of `res` as an ArrayBuffer, each chunk's size passed to `onBytes` as it arrives;
 * `expected` bytes are allocated when no Content-Length says better.
 */
async function readBody(res, expected, onBytes) {
  if (!res.body || !onBytes) {
    const buf = await res.arrayBuffer();
    onBytes?.(buf.byteLength);
    return buf;
  }
  let bytes = new Uint8Array(Number(res.headers.get('content-length')) || expected);
  const rd = res.body.getReader();
  let got = 0;
  for (;;) {
    const { done, value } = await rd.read();
    if (done) break;
    if (got + value.length > bytes.length) {
      // Longer than announced: keep reading, the size check after says what is wrong.
      const grown = new Uint8Array(Math.max(2 * bytes.length, got + value.length));
      grown.set(bytes.subarray(0, got));
      bytes = grown;
    }
    bytes.set(value, got);
    got += value.length;
    onBytes(value.length);
  }
  return got === bytes.length ? bytes.buffer : bytes.buffer.slice(0, got);
}

/**
 * Progress over several downloads: `part(bytes)` adds one expected to bring `bytes`, and returns
 * its `onBytes`; `onProgress` is told the fraction of all of them received (never above 1)
 * until `stop()` (one failed: the others must not write over its error).
 */
function progressOver(onProgress) {
  if (!onProgress) return { part: () => undefined, stop() {} };
  let total = 0;
  let got = 0;
  let stopped = false;
  return {
    part(bytes) {
      total += bytes;
      return (k) => {
        got += k;
        if (!stopped) onProgress(Math.min(1, got / Math.max(total, 1)));
      };
    },
    stop() {
      stopped = true;
    },
  };
}

// The positions a campaign's pairs share (view.json `positions`), by resolved URL (12n bytes),
// kept for the next pair: switching pairs loads the page again, so they live in Cache Storage,
// for this tab's session (sessionStorage names it: a campaign written again is read again in a
// new tab), one file at a time (a campaign shares one). A campaign pair with a whole terrain.bin
// keeps its positions too, as the next pair may name its file. Cache Storage exists in secure
// contexts only (http://127.0.0.1 and localhost are, a LAN address is not): there, and where
// storage is refused, every pair downloads the shared file.
const CACHE_NAME = 'talus-shared-positions';
const SESSION_KEY = 'talus-shared-positions-session';
const pendingWrites = new Set();

/** This tab session's Cache Storage key for `url`, with the cache; null when there is none. */
async function sessionCache(url) {
  try {
    if (!globalThis.caches || !globalThis.sessionStorage) return null;
    let id = sessionStorage.getItem(SESSION_KEY);
    if (!id) {
      id = `${Date.now().toString(36)}-${Math.random().toString(36).slice(2)}`;
      sessionStorage.setItem(SESSION_KEY, id);
    }
    const key = new URL(`${url}?session=${encodeURIComponent(id)}`, location.origin).href;
    return { cache: await caches.open(CACHE_NAME), key };
  } catch {
    return null; // storage refused (private mode, policy): download instead
  }
}

/** The shared positions of `url` (n points) kept in this tab's session, or null. */
async function cachedPositions(url, n) {
  const c = await sessionCache(url);
  if (!c) return null;
  try {
    const res = await c.cache.match(c.key);
    if (!res) return null;
    const buf = await res.arrayBuffer();
    return buf.byteLength === 12 * n ? new Float32Array(buf) : null;
  } catch {
    return null;
  }
}

/** Keep `positions` (the first 12n bytes of the file at `url`) for this tab's next pairs. */
function keepPositions(url, positions) {
  const write = (async () => {
    const c = await sessionCache(url);
    if (!c) return;
    // Response copies the bytes (a view into the whole terrain file, maybe).
    const body = new Uint8Array(positions.buffer, positions.byteOffset, positions.byteLength);
    await c.cache.put(c.key, new Response(body, { headers: { 'content-type': 'application/octet-stream' } }));
    for (const req of await c.cache.keys()) {
      if (req.url !== c.key) await c.cache.delete(req);
    }
  })().catch((e) => console.warn(`terrain positions not kept for the next pair: ${e.message}`));
  pendingWrites.add(write);
  write.finally(() => pendingWrites.delete(write));
}

/**
 * Settles once the positions being kept are written: the page waits for it before it is ready,
 * so that a switch to the next pair finds them.
 */
export function positionsKept() {
  return Promise.all([...pendingWrites]);
}

/**
 * terrain.bin → { positions: Float32Array(3n) local, distances: Float32Array(n) }.
 *
 * Without `view.positions` the file holds both: 12n bytes of positions, then 4n of distances.
 * With it, the file holds the n distances alone and the positions are the first 12n bytes of the
 * file `view.positions` names (a full terrain.bin of exactly 16n bytes), downloaded once per tab
 * session. `onProgress(fraction)` follows every download this takes. `share` (a campaign
 * pair): keep the positions of a whole terrain.bin too, as the next pair may name it.
 */
export async function loadTerrain(view, onProgress, { share = false } = {}) {
  const n = view.points;
  const own = locate(view.terrain);
  const progress = progressOver(onProgress);
  if (!view.positions) {
    const buf = await readBody(await fetchOk(view.terrain), 16 * n, progress.part(16 * n));
    if (buf.byteLength !== 16 * n) {
      throw new Error(`${own.name}: ${buf.byteLength} bytes, expected 16 × ${n} points`);
    }
    const positions = new Float32Array(buf, 0, 3 * n);
    if (share && own.inside) keepPositions(own.url, positions);
    return { positions, distances: new Float32Array(buf, 12 * n, n) };
  }
  const shared = locate(view.positions);
  if (!shared.inside) {
    throw new Error(
      `${own.name} holds only this pair's M3C2 distances: its terrain positions are in the `
      + `campaign's first pair (view.json "positions": ${view.positions}), outside the folder being `
      + 'served. Open the campaign folder (talus view CAMPAIGN_DIR) instead of this pair alone.',
    );
  }
  const cached = await cachedPositions(shared.url, n);
  const sharedBytes = cached ? null : progress.part(16 * n);
  const ownBytes = progress.part(4 * n);
  // Both at once; when one fails, the other is cancelled.
  const abort = new AbortController();
  try {
    const [positions, distances] = await Promise.all([
      cached ?? downloadPositions(shared, own, n, sharedBytes, abort.signal),
      (async () => {
        const buf = await readBody(await fetchOk(view.terrain, abort.signal), 4 * n, ownBytes);
        if (buf.byteLength !== 4 * n) {
          throw new Error(
            `${own.name}: ${buf.byteLength} bytes, expected 4 × ${n} points: the distances alone, `
            + `as view.json names its positions (${shared.name})`,
          );
        }
        return new Float32Array(buf);
      })(),
    ]);
    return { positions, distances };
  } catch (e) {
    progress.stop();
    abort.abort();
    throw e;
  }
}

/** The first 12n bytes of the full terrain `shared` that `own` takes its positions from. */
async function downloadPositions(shared, own, n, onBytes, signal) {
  const what = `${shared.name} (the terrain positions of ${own.name})`;
  let res;
  try {
    res = await fetch(shared.url, { signal });
  } catch (e) {
    throw new Error(`${what}: ${e.message}`);
  }
  if (!res.ok) throw new Error(`${what}: HTTP ${res.status}`);
  const buf = await readBody(res, 16 * n, onBytes);
  if (buf.byteLength !== 16 * n) {
    throw new Error(
      `${what}: ${buf.byteLength} bytes, expected 16 × ${n} points, a full terrain file with `
      + `as many points as ${own.name}`,
    );
  }
  const positions = new Float32Array(buf, 0, 3 * n);
  keepPositions(shared.url, positions);
  return positions;
}

/** The mesh paths of one event, whatever spelling of its id view.json uses as key. */
export function meshPaths(view, id) {
  return view.meshes[String(id)] || view.meshes[String(id).padStart(4, '0')] || null;
}

/** One PLY solid in local coordinates. */
export async function loadMesh(path, origin) {
  const buf = await (await fetchOk(path)).arrayBuffer();
  try {
    return parsePly(buf, origin);
  } catch (e) {
    throw new Error(`${path}: ${e.message}`);
  }
}

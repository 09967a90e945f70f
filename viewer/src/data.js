// Loading a talus result directory, served under /data/ (contract: view.json, events.geojson,
// terrain.bin, meshes/*.ply, optional summary.json). Everything is shifted into the local frame
// (global − origin) here, in f64, before it becomes float32 for the GPU.

import { parsePly } from './ply.js';

let DATA = '/data/';

/**
 * Where the result's files are: `/data/` for a comparison, `/data/pairs/<label>/` for a pair of
 * a campaign (each pair directory is a comparison result).
 */
export function setBase(base) {
  DATA = base;
}

async function fetchOk(path) {
  const res = await fetch(DATA + path);
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

/** terrain.bin → { positions: Float32Array(3n) local, distances: Float32Array(n) }. */
export async function loadTerrain(view, onProgress) {
  const res = await fetchOk(view.terrain);
  const total = Number(res.headers.get('content-length')) || 16 * view.points;
  let buf;
  if (res.body && onProgress) {
    const bytes = new Uint8Array(total);
    const rd = res.body.getReader();
    let got = 0;
    for (;;) {
      const { done, value } = await rd.read();
      if (done) break;
      if (got + value.length > bytes.length) throw new Error('terrain.bin: larger than announced');
      bytes.set(value, got);
      got += value.length;
      onProgress(got / total);
    }
    buf = bytes.buffer.slice(0, got);
  } else {
    buf = await res.arrayBuffer();
  }
  const n = view.points;
  if (buf.byteLength !== 16 * n) {
    throw new Error(`terrain.bin: ${buf.byteLength} bytes, expected 16 × ${n} points`);
  }
  return {
    positions: new Float32Array(buf, 0, 3 * n),
    distances: new Float32Array(buf, 12 * n, n),
  };
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

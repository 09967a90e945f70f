// Writes a synthetic talus result directory in the viewer's input contract (view.json,
// events.geojson, terrain.bin, meshes/*.ply, summary.json) with known answers:
// box-shaped solids whose volumes are exact (footprint × height difference), UTM-sized
// coordinates, and a 50k-point terrain whose M3C2 distances are positive around the gain events
// and negative around the loss events. Event 5 is a vegetation event (vegetation_fraction 0.8,
// vegetation true), event 3 was judged and is not (fraction 0.12); the others carry neither
// property, as results written before talus judged vegetation.
//
// makeCampaignFixture writes a campaign of such results (pairs/<before>_<after>/, the same core
// points in every pair), some of whose pairs name the first pair's terrain in view.json
// `positions` and keep only their distances.
//
// Usage: node make-fixture.mjs DIR [scale]   (or import { makeFixture } and call it)

import { mkdirSync, readFileSync, writeFileSync } from 'node:fs';
import { join } from 'node:path';
import { fileURLToPath } from 'node:url';

/** Global coordinates of local 0, as a writer would choose (UTM zone 33N-sized values). */
export const ORIGIN = [500_100.0, 5_000_050.0, 120.0];

// Terrain: by default a 250 × 200 grid at 0.5 m spacing = 50,000 points over 125 m × 100 m, a
// slope with a gentle wave. `scale` multiplies the density per axis (scale 6.4 ≈ 2M points, the
// most a writer produces) over the same extent.
const surface = (x, y) => 0.25 * y + 3 * Math.sin(x / 15); // local z at local (x, y)

// The events: local footprint centre, footprint w × d (m), solid heights before/after (m)
// above a base 1 m under the surface, distance bump amplitude (m) and its sigma (m).
// volume = w·d·(hAfter − hBefore), exactly, for the closed boxes written below.
const SPECS = [
  { id: 1, cx: 30, cy: 30, w: 10, d: 8, hBefore: 1.0, hAfter: 2.5, amp: 1.5, sigma: 6, unc: 6.4 },
  { id: 2, cx: 90, cy: 60, w: 9, d: 6, hBefore: 1.9, hAfter: 1.0, amp: -0.9, sigma: 5, unc: 3.1 },
  { id: 3, cx: 65, cy: 80, w: 4, d: 4, hBefore: 1.0, hAfter: 1.3, amp: 0.3, sigma: 2.5, unc: 0.9 },
  { id: 4, cx: 105, cy: 20, w: 3, d: 2.5, hBefore: 1.2, hAfter: 1.0, amp: -0.2, sigma: 2, unc: 0.4 },
  // A small gain (|volume| < 2 m³, so the volume filters keep their answers) of vegetation.
  { id: 5, cx: 45, cy: 60, w: 3, d: 2, hBefore: 1.0, hAfter: 1.25, amp: 0.4, sigma: 2.5, unc: 0.5 },
];

/** The vegetation judgement of an event, by id (absent: not judged, an older result). */
const VEGETATION = {
  3: { vegetation_fraction: 0.12, vegetation: false },
  5: { vegetation_fraction: 0.8, vegetation: true },
};

/** A deterministic pseudo-random sequence (mulberry32), so the fixture is the same every run. */
function rng(seed) {
  let a = seed >>> 0;
  return () => {
    a = (a + 0x6d2b79f5) >>> 0;
    let t = a;
    t = Math.imul(t ^ (t >>> 15), t | 1);
    t ^= t + Math.imul(t ^ (t >>> 7), t | 61);
    return ((t ^ (t >>> 14)) >>> 0) / 4294967296;
  };
}

/** A closed box (8 vertices, 12 outward-facing triangles) as binary little-endian PLY. */
function boxPly(min, max) {
  const header =
    'ply\nformat binary_little_endian 1.0\ncomment talus test fixture\n' +
    'element vertex 8\nproperty double x\nproperty double y\nproperty double z\n' +
    'element face 12\nproperty list uchar int vertex_indices\nend_header\n';
  const v = [];
  for (let i = 0; i < 8; i++) {
    v.push([i & 1 ? max[0] : min[0], i & 2 ? max[1] : min[1], i & 4 ? max[2] : min[2]]);
  }
  // Counter-clockwise seen from outside.
  const faces = [
    [0, 2, 3], [0, 3, 1], // z min
    [4, 5, 7], [4, 7, 6], // z max
    [0, 1, 5], [0, 5, 4], // y min
    [2, 6, 7], [2, 7, 3], // y max
    [0, 4, 6], [0, 6, 2], // x min
    [1, 3, 7], [1, 7, 5], // x max
  ];
  const head = Buffer.from(header, 'ascii');
  const body = Buffer.alloc(8 * 24 + 12 * 13);
  let o = 0;
  for (const p of v) for (const c of p) { body.writeDoubleLE(c, o); o += 8; }
  for (const f of faces) {
    body.writeUInt8(3, o); o += 1;
    for (const i of f) { body.writeInt32LE(i, o); o += 4; }
  }
  return Buffer.concat([head, body]);
}

function percentile(sorted, p) {
  const i = Math.min(sorted.length - 1, Math.max(0, Math.round((p / 100) * (sorted.length - 1))));
  return sorted[i];
}

/**
 * Write the fixture into `dir` and return what a reader should find:
 * { origin, points, events: [{ id, kind, volume_m3, volume_uncertainty_m3, centroid,
 * vegetation_fraction (or null), vegetation }], range }. `shift` (m) is added to every
 * distance: a campaign's pairs differ by it, their core points do not.
 */
export function makeFixture(dir, scale = 1, { shift = 0 } = {}) {
  const NX = Math.round(250 * scale);
  const NY = Math.round(200 * scale);
  const STEP = 125 / NX;
  mkdirSync(join(dir, 'meshes'), { recursive: true });
  const rand = rng(42);
  const n = NX * NY;
  const pos = new Float32Array(3 * n);
  const dist = new Float32Array(n);
  let k = 0;
  for (let j = 0; j < NY; j++) {
    for (let i = 0; i < NX; i++) {
      const x = i * STEP + (rand() - 0.5) * 0.4 * STEP;
      const y = j * STEP + (rand() - 0.5) * 0.4 * STEP;
      let d = (rand() - 0.5) * 0.04;
      for (const s of SPECS) {
        const r2 = (x - s.cx) ** 2 + (y - s.cy) ** 2;
        d += s.amp * Math.exp(-r2 / (2 * s.sigma * s.sigma));
      }
      pos[3 * k] = x;
      pos[3 * k + 1] = y;
      pos[3 * k + 2] = surface(x, y) + Math.max(d, 0);
      // M3C2 is not computed near the scan border (no neighbours on one side).
      dist[k] = x < 2 ? NaN : d + shift;
      k++;
    }
  }
  const terrain = Buffer.alloc(16 * n);
  Buffer.from(pos.buffer).copy(terrain, 0);
  Buffer.from(dist.buffer).copy(terrain, 12 * n);
  writeFileSync(join(dir, 'terrain.bin'), terrain);

  const finite = Array.from(dist).filter(Number.isFinite).sort((a, b) => a - b);
  const range = [percentile(finite, 2), percentile(finite, 98)];

  const features = [];
  const meshes = {};
  const expected = [];
  for (const s of SPECS) {
    const volume = s.w * s.d * (s.hAfter - s.hBefore);
    const kind = volume > 0 ? 'gain' : 'loss';
    const base = surface(s.cx, s.cy) - 1;
    const hMax = Math.max(s.hBefore, s.hAfter);
    const local = [s.cx, s.cy, base + hMax / 2];
    const centroid = local.map((c, a) => ORIGIN[a] + c);
    const min = [ORIGIN[0] + s.cx - s.w / 2, ORIGIN[1] + s.cy - s.d / 2, ORIGIN[2] + base];
    const maxB = [ORIGIN[0] + s.cx + s.w / 2, ORIGIN[1] + s.cy + s.d / 2, ORIGIN[2] + base + s.hBefore];
    const maxA = [maxB[0], maxB[1], ORIGIN[2] + base + s.hAfter];
    const name = `event_${String(s.id).padStart(4, '0')}`;
    writeFileSync(join(dir, 'meshes', `${name}_before.ply`), boxPly(min, maxB));
    writeFileSync(join(dir, 'meshes', `${name}_after.ply`), boxPly(min, maxA));
    meshes[String(s.id)] = {
      before: `meshes/${name}_before.ply`,
      after: `meshes/${name}_after.ply`,
    };
    const properties = {
      id: s.id,
      kind,
      volume_m3: volume,
      volume_uncertainty_m3: s.unc,
      n_points: Math.round(s.w * s.d * 4),
      area_m2: s.w * s.d,
      mean_distance_m: s.hAfter - s.hBefore,
      max_abs_distance_m: Math.abs(s.amp),
      mean_lod95_m: 0.05,
      obb: {
        center: centroid,
        axes: [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
        half_extents: [s.w / 2, s.d / 2, hMax / 2],
      },
    };
    if (s.id === 1) {
      // The optional split of a mixed event.
      properties.gain_m3 = volume + 0.5;
      properties.loss_m3 = -0.5;
    }
    Object.assign(properties, VEGETATION[s.id]);
    features.push({ type: 'Feature', geometry: { type: 'Point', coordinates: centroid }, properties });
    const veg = VEGETATION[s.id] || { vegetation_fraction: null, vegetation: false };
    expected.push({ id: s.id, kind, volume_m3: volume, volume_uncertainty_m3: s.unc, centroid, ...veg });
  }
  writeFileSync(
    join(dir, 'events.geojson'),
    JSON.stringify({ type: 'FeatureCollection', crs_name: 'WGS 84 / UTM zone 33N', features }, null, 1),
  );
  writeFileSync(
    join(dir, 'view.json'),
    JSON.stringify({
      version: 1,
      crs: 'EPSG:32633',
      units: 'm',
      origin: ORIGIN,
      points: n,
      distance_range: range,
      terrain: 'terrain.bin',
      meshes,
    }, null, 1),
  );
  writeFileSync(
    join(dir, 'summary.json'),
    JSON.stringify({
      version: '0.1.0-fixture',
      inputs: [
        { path: '/surveys/slope_2021.laz', points: n },
        { path: '/surveys/slope_2023.laz', points: n },
      ],
    }, null, 1),
  );
  return { origin: ORIGIN, points: n, events: expected, range };
}

/**
 * A campaign in `dir` (summary.json, campaign.json, events.geojson, pairs/<label>/) of
 * `layout.length` pairs of consecutive epochs, each a [`makeFixture`] result (density `scale`)
 * with the same core points and its own distances (shifted by 0.1 m per pair). A pair whose
 * layout is 'shared' names the first pair's terrain.bin in view.json `positions` and keeps only
 * its n distances (4n bytes); a 'full' one (the first must be) keeps its whole terrain.bin.
 * Returns { labels, points, origin }.
 */
export function makeCampaignFixture(dir, layout = ['full', 'shared', 'shared', 'full'], scale = 0.4) {
  if (layout[0] !== 'full') throw new Error('the first pair keeps its whole terrain');
  const epochs = Array.from({ length: layout.length + 1 }, (_, i) => {
    const date = new Date(Date.UTC(2021, 2 + 3 * i, 1)).toISOString().slice(0, 10);
    return { label: date.replaceAll('-', ''), date };
  });
  const labels = layout.map((_, i) => `${epochs[i].label}_${epochs[i + 1].label}`);
  const rows = [];
  const features = [];
  let range = null;
  let fixture;
  layout.forEach((kind, i) => {
    const pairDir = join(dir, 'pairs', labels[i]);
    fixture = makeFixture(pairDir, scale, { shift: 0.1 * i });
    const n = fixture.points;
    if (kind === 'shared') {
      const full = readFileSync(join(pairDir, 'terrain.bin'));
      writeFileSync(join(pairDir, 'terrain.bin'), full.subarray(12 * n));
      const view = JSON.parse(readFileSync(join(pairDir, 'view.json'), 'utf8'));
      view.positions = `../${labels[0]}/terrain.bin`;
      writeFileSync(join(pairDir, 'view.json'), JSON.stringify(view, null, 1));
    }
    range = range ? [Math.min(range[0], fixture.range[0]), Math.max(range[1], fixture.range[1])] : fixture.range;
    const [before, after] = [epochs[i], epochs[i + 1]];
    const sum = (f) => fixture.events.filter(f).reduce((s, e) => s + e.volume_m3, 0);
    rows.push({
      label: labels[i], before: before.label, after: after.label,
      before_date: before.date, after_date: after.date, days: 92,
      core_points: n, events: fixture.events.length,
      gain_m3: sum((e) => e.volume_m3 > 0), loss_m3: sum((e) => e.volume_m3 < 0), net_m3: sum(() => true),
    });
    for (const e of fixture.events) {
      features.push({
        type: 'Feature',
        geometry: { type: 'Point', coordinates: e.centroid },
        properties: {
          pair: labels[i], before_date: before.date, after_date: after.date,
          track_id: e.vegetation ? null : e.id, id: e.id, kind: e.kind,
          volume_m3: e.volume_m3, volume_uncertainty_m3: e.volume_uncertainty_m3,
          vegetation: e.vegetation,
        },
      });
    }
  });
  writeFileSync(join(dir, 'summary.json'), JSON.stringify({
    tool: 'talus',
    version: '0.1.0-fixture',
    epochs: epochs.map((e) => ({ label: e.label, date: e.date })),
    pairs: rows.map((r) => ({ label: r.label, events: r.events })),
    core_points: fixture.points,
  }, null, 1));
  writeFileSync(join(dir, 'campaign.json'), JSON.stringify({
    pairs: rows,
    epochs: epochs.map((e) => ({ label: e.label, date: e.date })),
    distance_range: range,
  }, null, 1));
  writeFileSync(join(dir, 'events.geojson'), JSON.stringify({
    type: 'FeatureCollection', crs_name: 'WGS 84 / UTM zone 33N', features,
  }, null, 1));
  return { labels, points: fixture.points, origin: ORIGIN };
}

if (process.argv[1] === fileURLToPath(import.meta.url)) {
  const dir = process.argv[2];
  const scale = Number(process.argv[3] || 1);
  if (!dir || !(scale > 0)) {
    console.error('usage: node make-fixture.mjs DIR [density-scale]');
    process.exit(2);
  }
  const f = makeFixture(dir, scale);
  console.log(`wrote ${f.points} points and ${f.events.length} events to ${dir}`);
}

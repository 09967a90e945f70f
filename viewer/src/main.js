// talus viewer: a comparison result in 3-D. Loads /data/ (view.json, events.geojson,
// terrain.bin, meshes), draws the terrain coloured by M3C2 distance, each event's solids,
// marker and label, and wires the table, filters, panel and hover read-out.
//
// Everything is drawn in the local frame (global − origin): UTM-sized coordinates in float32
// would jitter by decimetres. Coordinates shown to the user are origin + local, added in f64.
//
// The terrain is shaded with Eye-Dome Lighting (edl.js) so relief reads without normals.
//
// Rendering is on demand (controls, hover, filters request a frame), so an idle page costs
// nothing even with 2M points.
//
// A campaign directory (campaign.js) shows one of its pairs at a time, with the campaign's
// selector, time slider and table.

import * as THREE from 'three';
import { OrbitControls } from 'three/addons/controls/OrbitControls.js';
import { CSS2DRenderer } from 'three/addons/renderers/CSS2DRenderer.js';
import { loadView, loadEvents, loadTerrain, loadSummary, loadMesh, meshPaths, setBase, positionsKept } from './data.js';
import { loadCampaign, readState, goTo, savedCamera, sceneEvents, colouring, drawCampaign, colourKeys } from './campaign.js';
import { distanceColors, rampHalfWidth } from './colormap.js';
import { Terrain, interleaveTerrain } from './terrain.js';
import { EyeDome } from './edl.js';
import { EventLayer } from './events.js';
import { EventTable, showEvent, drawLegend, drawMeta } from './ui.js';
import { coords, signed, volumeLabel, vegetationText } from './format.js';

const $ = (id) => document.getElementById(id);

/** State exposed for the browser tests (and for poking at from the console). */
const T = (window.__talus = {
  ready: false,
  error: null,
  webgl2: false,
  events: [],
  markers: 0,
  rows: 0,
  terrainPoints: 0,
  selected: null,
  hovered: null,
  frames: 0,
  flying: false,
});

main().catch((err) => {
  T.error = String(err?.message || err);
  const el = $('loading');
  el.hidden = false;
  el.classList.add('error');
  el.textContent = `Could not load the result:\n${T.error}`;
  console.error(err);
});

async function main() {
  const t0 = performance.now();
  const ms = () => Math.round(performance.now() - t0);
  T.timings = {};
  const loading = $('loading');
  // A campaign's summary.json lists its pairs; a comparison's does not (or there is none).
  const top = await loadSummary();
  const campaign = await loadCampaign(top);
  const state = campaign ? readState(campaign) : null;
  if (campaign) {
    $('app').classList.add('campaign');
    setBase(`/data/pairs/${encodeURIComponent(state.pair)}/`);
    window.addEventListener('hashchange', () => location.reload());
  }
  const view = await loadView();
  const [loaded, summary] = await Promise.all([loadEvents(view.origin), campaign ? loadSummary() : top]);
  const { crsName } = loaded;
  const events = campaign ? sceneEvents(campaign, state, view.origin, loaded.events) : loaded.events;
  const origin = view.origin;
  // A campaign's pairs may share their core points (view.json `positions`): `share` keeps this
  // pair's for the next one.
  const raw = await loadTerrain(view, (p) => {
    loading.textContent = `Loading terrain… ${Math.round(p * 100)} %`;
  }, { share: Boolean(campaign) });
  loading.textContent = 'Preparing…';
  T.timings.loaded = ms();
  const terrainData = interleaveTerrain(raw.positions, raw.distances);

  // --- scene -------------------------------------------------------------------------------
  const container = $('view');
  const renderer = new THREE.WebGLRenderer({ antialias: true, powerPreference: 'high-performance' });
  renderer.setPixelRatio(Math.min(window.devicePixelRatio || 1, 2));
  container.prepend(renderer.domElement);
  const canvas = renderer.domElement;
  T.webgl2 = renderer.getContext() instanceof WebGL2RenderingContext;
  const labelRenderer = new CSS2DRenderer();
  labelRenderer.domElement.id = 'labels';
  canvas.after(labelRenderer.domElement);

  const scene = new THREE.Scene();
  scene.background = new THREE.Color(0x2b3037);
  const camera = new THREE.PerspectiveCamera(45, 1, 0.1, 1000);
  camera.up.set(0, 0, 1); // survey data: z is up
  const hemi = new THREE.HemisphereLight(0xffffff, 0x3a3f46, 1.6);
  hemi.position.set(0, 0, 1);
  const sun = new THREE.DirectionalLight(0xffffff, 1.8);
  sun.position.set(0.6, -0.8, 1.4);
  scene.add(hemi, sun);

  // A campaign draws every pair on one scale (campaign.js), a comparison on its own range.
  const half = rampHalfWidth(campaign?.distanceRange ?? view.distance_range);
  T.rampHalf = half;
  const terrain = new Terrain(terrainData.positions, distanceColors(terrainData.distances, half));
  scene.add(terrain.points);
  T.terrainPoints = terrain.count;
  T.timings.prepared = ms();

  // Scene extent: the terrain, or the events when there is no terrain.
  const box = terrain.count ? terrain.box.clone() : new THREE.Box3();
  for (const e of events) box.expandByPoint(new THREE.Vector3().fromArray(e.local));
  if (box.isEmpty()) box.set(new THREE.Vector3(-5, -5, -5), new THREE.Vector3(5, 5, 5));
  const diag = Math.max(box.getSize(new THREE.Vector3()).length(), 1);
  const centre = box.getCenter(new THREE.Vector3());

  const layer = new EventLayer(events, campaign ? colouring(campaign, state) : null);
  scene.add(layer.group);
  const byId = new Map(events.map((e) => [e.id, e]));

  const edl = new EyeDome();
  let shading = true;

  const controls = new OrbitControls(camera, canvas);
  controls.screenSpacePanning = true;
  controls.zoomToCursor = true;
  controls.addEventListener('change', requestRender);

  // While the camera moves, big clouds draw an interleaved prefix sized to keep frames near 30 ms;
  // the full cloud comes back as soon as the motion stops.
  let moving = 0;
  let detail = 1;
  let lastMoveFrame = 0;
  const adaptive = terrain.count > 300_000;
  const startMove = () => { moving++; lastMoveFrame = 0; };
  const endMove = () => {
    moving = Math.max(0, moving - 1);
    if (!moving && terrain.detail !== 1) {
      terrain.setDetail(1);
      requestRender();
    }
  };
  controls.addEventListener('start', startMove);
  controls.addEventListener('end', endMove);
  function adaptDetail() {
    if (!adaptive || !moving) return;
    const now = performance.now();
    if (lastMoveFrame) {
      const dt = now - lastMoveFrame;
      if (dt > 45) detail = Math.max(0.05, detail * 0.7);
      else if (dt < 20) detail = Math.min(1, detail * 1.25);
    }
    lastMoveFrame = now;
    terrain.setDetail(detail);
  }

  // Panels over the canvas: labels under them are hidden like labels under labels.
  const overlays = ['hud', 'legend', 'readout'].map($);

  // --- rendering on demand ------------------------------------------------------------------
  let framePending = false;
  function requestRender() {
    if (framePending) return;
    framePending = true;
    requestAnimationFrame(renderNow);
  }
  function renderNow() {
    framePending = false;
    // Depth range follows the view distance, so close-ups of small events keep depth precision.
    const dist = camera.position.distanceTo(controls.target);
    camera.near = Math.max(dist / 1000, diag * 1e-6);
    camera.far = dist + diag * 4;
    camera.updateProjectionMatrix();
    adaptDetail();
    if (shading) edl.render(renderer, scene, camera);
    else renderer.render(scene, camera);
    labelRenderer.render(scene, camera);
    T.labels = layer.declutter(overlays.map((el) => el.getBoundingClientRect()));
    T.frames++;
  }

  function resize() {
    const w = Math.max(1, container.clientWidth);
    const h = Math.max(1, container.clientHeight);
    renderer.setSize(w, h);
    labelRenderer.setSize(w, h);
    const px = renderer.getDrawingBufferSize(new THREE.Vector2());
    edl.setSize(px.x, px.y, renderer.getPixelRatio());
    camera.aspect = w / h;
    camera.updateProjectionMatrix();
    terrain.setViewport(camera, h * renderer.getPixelRatio(), renderer.getPixelRatio());
    layer.setViewport(camera, h);
    requestRender();
  }
  new ResizeObserver(resize).observe(container);
  resize();

  // --- camera moves -----------------------------------------------------------------------------
  const tanHalf = Math.tan(THREE.MathUtils.degToRad(camera.fov) / 2);
  // A steep face (its mean normal more than 45° from the vertical: a face scanned alone) is
  // looked at along that normal, not down on from the south.
  const facing = Array.isArray(view.facing) && view.facing.length === 3 && view.facing.every(Number.isFinite)
    ? new THREE.Vector3().fromArray(view.facing).normalize()
    : null;
  const steep = facing !== null && facing.z < Math.SQRT1_2;
  function homePose() {
    // From the south, 40° above the horizon, the whole scene in view; a steep face from the
    // front.
    const dir = steep ? facing.clone() : new THREE.Vector3(0, -1, 0.85).normalize();
    const dist = (diag / 2 / tanHalf) * 0.95;
    return { target: centre.clone(), position: centre.clone().addScaledVector(dir, dist) };
  }
  let flight = 0;
  function flyTo(pose, ms = 650) {
    const id = ++flight;
    const p0 = camera.position.clone();
    const t0 = controls.target.clone();
    const start = performance.now();
    if (!T.flying) startMove();
    T.flying = true;
    const step = (now) => {
      if (id !== flight) return; // a newer flight took over
      const u = Math.min(1, (now - start) / ms);
      const k = u < 0.5 ? 4 * u * u * u : 1 - (-2 * u + 2) ** 3 / 2; // ease in-out cubic
      camera.position.lerpVectors(p0, pose.position, k);
      controls.target.lerpVectors(t0, pose.target, k);
      controls.update();
      renderNow();
      if (u < 1) requestAnimationFrame(step);
      else {
        T.flying = false;
        endMove();
      }
    };
    requestAnimationFrame(step);
  }
  function eventPose(id) {
    const e = byId.get(id);
    const target = new THREE.Vector3().fromArray(e.local);
    let dir = camera.position.clone().sub(controls.target);
    if (dir.lengthSq() < 1e-12) dir = new THREE.Vector3(0, -1, 0.85);
    dir.normalize();
    const dist = Math.max((layer.extent(id) / tanHalf) * 4, diag * 0.02);
    return { target, position: target.clone().addScaledVector(dir, dist) };
  }
  // A campaign's pairs share the site: switching pairs keeps the camera where it was.
  const saved = campaign ? savedCamera() : null;
  const home = saved
    ? { position: new THREE.Vector3().fromArray(saved.position), target: new THREE.Vector3().fromArray(saved.target) }
    : homePose();
  camera.position.copy(home.position);
  controls.target.copy(home.target);
  controls.update();
  $('reset').addEventListener('click', () => flyTo(homePose()));

  // --- side panel ---------------------------------------------------------------------------------
  const panel = $('panel');
  let pinned = null;
  function select(id, fly) {
    if (!byId.has(id)) return;
    pinned = id;
    T.selected = id;
    layer.select(id);
    table.select(id);
    showEvent(panel, byId.get(id), view.units);
    if (fly) flyTo(eventPose(id));
    requestRender();
  }
  const extraColumns = campaign
    ? [...(state.scope === 'all' ? [{ key: 'pair', label: 'Pair' }] : []), { key: 'track_id', label: 'Track', num: true }]
    : [];
  const table = new EventTable($('events'), $('table-note'), events, (id) => select(id, true), extraColumns);

  function applyFilter() {
    const min = Math.max(0, Number($('min-volume').value) || 0);
    const kind = $('kind').value;
    // Vegetation events are listed apart from ground change: show them, hide them, or only them.
    const veg = $('vegetation').value;
    const vegOk = (e) => (veg === 'hide' ? !e.vegetation : veg === 'only' ? e.vegetation : true);
    const pred = (e) => Math.abs(e.volume_m3) >= min && (kind === 'all' || e.kind === kind) && vegOk(e);
    layer.setFilter(pred);
    table.setFilter(pred);
    table.select(pinned);
    T.markers = layer.visibleMarkers();
    T.rows = table.rowCount();
    T.visibleEventIds = events.filter(pred).map((e) => e.id);
    requestRender();
  }
  $('min-volume').addEventListener('input', applyFilter);
  $('kind').addEventListener('change', applyFilter);
  $('vegetation').addEventListener('change', applyFilter);
  const layerToggle = (el, name) => el.addEventListener('change', () => {
    layer.setLayer(name, el.checked);
    T.markers = layer.visibleMarkers();
    requestRender();
  });
  layerToggle($('show-before'), 'before');
  layerToggle($('show-after'), 'after');
  layerToggle($('show-markers'), 'markers');
  layerToggle($('show-labels'), 'labels');
  $('shading').addEventListener('change', (ev) => {
    shading = ev.target.checked;
    requestRender();
  });
  $('show-terrain').addEventListener('change', (ev) => {
    terrain.points.visible = ev.target.checked;
    requestRender();
  });
  const sizeInput = $('point-size');
  terrain.setSizeFactor(Number(sizeInput.value));
  sizeInput.addEventListener('input', () => {
    terrain.setSizeFactor(Number(sizeInput.value));
    requestRender();
  });

  // The vegetation key once the result judges vegetation (older results never do).
  const judged = events.some((e) => e.vegetation || e.vegetation_fraction != null);
  drawLegend($('legend'), half, view.units, campaign ? colourKeys(campaign, state, events) : null, judged,
    campaign?.distanceRange ? 'the same scale for every pair' : '');
  drawMeta($('meta'), view, crsName, events.length, summary, events.filter((e) => e.vegetation).length);
  /** The marker colour of every event (0xRRGGBB), by id. */
  T.markerColours = Object.fromEntries(events.map((e) => [e.id, layer.markerColour(e)]));
  if (campaign) {
    const pose = () => ({ position: camera.position.toArray(), target: controls.target.toArray() });
    drawCampaign($('campaign'), campaign, state, (next) => goTo(next, pose()));
    const p = campaign.pairs[state.index];
    const line = document.createElement('div');
    line.id = 'campaign-line';
    line.textContent = `campaign of ${campaign.epochs?.length ?? '?'} surveys · pair ${state.index + 1} of ${campaign.pairs.length}: `
      + `${p.before_date ?? p.before} → ${p.after_date ?? p.after}` + (state.scope === 'all' ? ' · events of all pairs' : '');
    $('meta').prepend(line);
    T.campaign = { ...state, pairs: campaign.pairs.map((q) => q.label) };
  }

  // --- hover and click ----------------------------------------------------------------------------
  const readout = $('readout');
  const crsText = crsName && crsName !== view.crs ? `${view.crs}, ${crsName}` : view.crs;
  const idleText = `CRS ${crsText} · drag to orbit, right-drag to pan, wheel to zoom`;
  readout.textContent = idleText;
  const raycaster = new THREE.Raycaster();
  const ndc = new THREE.Vector2();

  /** What is under CSS pixel (x, y) of the canvas: an event, a terrain point, or nothing. */
  function pickAt(x, y) {
    const w = canvas.clientWidth;
    const h = canvas.clientHeight;
    ndc.set((x / w) * 2 - 1, -(y / h) * 2 + 1);
    raycaster.setFromCamera(ndc, camera);
    const { markers, solids } = layer.pickables();
    // Markers are drawn over everything, so they win over whatever lies in front of them.
    const m = raycaster.intersectObjects(markers, false)[0];
    if (m) return { kind: 'event', id: m.object.userData.eventId };
    const s = raycaster.intersectObjects(solids, false)[0];
    const i = terrain.pick(renderer, camera, x, y, w, h);
    if (s && (i < 0 || s.distance <= pointDistance(i))) {
      return { kind: 'event', id: s.object.userData.eventId, local: s.point.toArray() };
    }
    if (i >= 0) return { kind: 'point', index: i };
    return null;
  }
  function pointDistance(i) {
    const p = terrain.positions;
    return camera.position.distanceTo(new THREE.Vector3(p[3 * i], p[3 * i + 1], p[3 * i + 2]));
  }
  const toGlobal = (local) => local.map((v, a) => origin[a] + v); // f64

  function describe(hit) {
    if (!hit) return idleText;
    if (hit.kind === 'event') {
      const e = byId.get(hit.id);
      const where = hit.local ? `surface ${coords(toGlobal(hit.local))}` : `centre ${coords(e.centroid)}`;
      const veg = e.vegetation ? ` · ${vegetationText(e)}` : '';
      return `Event #${e.id} (${e.kind}) ${volumeLabel(e.volume_m3, e.volume_uncertainty_m3, e.complete)}${veg} · ${where} · ${crsText}`;
    }
    const p = terrain.positions;
    const i = hit.index;
    const g = toGlobal([p[3 * i], p[3 * i + 1], p[3 * i + 2]]);
    const d = terrainData.distances[i];
    const dText = Number.isFinite(d) ? `M3C2 ${signed(d, 3)} ${view.units}` : 'M3C2 not computed';
    return `${coords(g)} · ${crsText} · ${dText}`;
  }

  let pointer = null;
  let hoverQueued = false;
  function hover() {
    hoverQueued = false;
    if (!pointer || pointer.buttons) return; // never pick while orbiting: keep dragging smooth
    const t = performance.now();
    const hit = pickAt(pointer.x, pointer.y);
    T.timings.lastPick = performance.now() - t;
    T.hovered = hit;
    const hoveredEvent = hit?.kind === 'event' ? hit.id : null;
    if (hoveredEvent !== layer.hovered) {
      layer.hover(hoveredEvent);
      requestRender();
    }
    readout.textContent = describe(hit);
    canvas.style.cursor = hit?.kind === 'event' ? 'pointer' : '';
    if (pinned == null) showEvent(panel, hit?.kind === 'event' ? byId.get(hit.id) : null, view.units);
  }
  canvas.addEventListener('pointermove', (ev) => {
    pointer = { x: ev.offsetX, y: ev.offsetY, buttons: ev.buttons };
    if (!hoverQueued) {
      hoverQueued = true;
      requestAnimationFrame(hover);
    }
  });
  canvas.addEventListener('pointerleave', () => {
    pointer = null;
    T.hovered = null;
    if (layer.hovered != null) {
      layer.hover(null);
      requestRender();
    }
    readout.textContent = idleText;
  });
  let down = null;
  canvas.addEventListener('pointerdown', (ev) => { down = { x: ev.offsetX, y: ev.offsetY, button: ev.button }; });
  canvas.addEventListener('pointerup', (ev) => {
    if (!down || down.button !== 0 || Math.hypot(ev.offsetX - down.x, ev.offsetY - down.y) > 4) return;
    const hit = pickAt(ev.offsetX, ev.offsetY);
    if (hit?.kind === 'event') select(hit.id, false);
  });

  window.addEventListener('keydown', (ev) => {
    if (ev.key !== 'Escape' || pinned == null) return;
    pinned = null;
    T.selected = null;
    layer.select(null);
    table.select(null);
    showEvent(panel, null, view.units);
    requestRender();
  });

  // --- go -----------------------------------------------------------------------------------------
  T.events = events;
  T.crs = view.crs;
  T.origin = origin;
  T.flyTo = (id) => select(id, true);
  T.render = requestRender;
  T.camera = () => ({ position: camera.position.toArray(), target: controls.target.toArray() });
  /** Client-pixel position of an event centre in the current view (for tests). */
  T.projectLocal = (local) => {
    const v = new THREE.Vector3().fromArray(local).project(camera);
    const r = canvas.getBoundingClientRect();
    return { x: r.left + ((v.x + 1) / 2) * r.width, y: r.top + ((1 - v.y) / 2) * r.height };
  };
  T.project = (id) => T.projectLocal(byId.get(id).local);
  /** The terrain as drawn (interleaved: terrain.js): local positions and distances. */
  T.terrainArrays = () => ({ positions: terrain.positions, distances: terrainData.distances });
  applyFilter();
  loading.hidden = true;
  renderNow();
  T.timings.firstFrame = ms();

  // The solids come last: the terrain and markers are already usable meanwhile.
  await loadSolids(view, events, layer, requestRender);
  T.markers = layer.visibleMarkers();
  renderNow();
  await positionsKept();
  T.timings.ready = ms();
  T.ready = true;
}

/** Fetch every event's two solids, six at a time; a broken mesh is skipped with a warning. */
async function loadSolids(view, events, layer, onLoaded) {
  // A campaign's events of other pairs have no solids here (mesh_id null).
  const meshId = (e) => ('mesh_id' in e ? e.mesh_id : e.id);
  const queue = events.filter((e) => meshId(e) != null && meshPaths(view, meshId(e)));
  const worker = async () => {
    while (queue.length) {
      const e = queue.shift();
      const paths = meshPaths(view, meshId(e));
      try {
        const [before, after] = await Promise.all([
          paths.before ? loadMesh(paths.before, view.origin) : null,
          paths.after ? loadMesh(paths.after, view.origin) : null,
        ]);
        layer.addSolids(e.id, before, after);
        onLoaded();
      } catch (err) {
        console.warn(`event ${e.id}: solids not shown: ${err.message}`);
      }
    }
  };
  await Promise.all(Array.from({ length: 6 }, worker));
}

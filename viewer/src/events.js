// The events in the 3-D scene: per event a marker at its centroid (coloured by kind, or by a
// campaign's pair or track; diameter ∝ ∛|volume|), a label "+12.3 ± 1.1 m³", and its two
// solids: "before" translucent with its edges, "after" opaque.
//
// A vegetation event (most of its points look like vegetation: plants that grew or were cut
// rather than ground that moved) is green whatever its kind or colouring, so it is not read as
// a gain or loss of ground: talus lists it but leaves it out of the totals and of the tracks.
//
// Labels are decluttered in screen space after every frame (`declutter`): the selected and the
// hovered event's label first, then by |volume|; a label that would overlap one already shown
// is hidden (class `crowded`) until the view, the hover or the selection makes room for it.

import * as THREE from 'three';
import { CSS2DObject } from 'three/addons/renderers/CSS2DRenderer.js';
import { volumeLabel } from './format.js';

export const KIND_COLOR = { gain: 0xe4573d, loss: 0x3d8fe0 };
const AFTER_COLOR = { gain: 0xf4a582, loss: 0x92c5de };
/** Vegetation events: the marker (and label rim), and the lighter "after" solid. */
export const VEGETATION_COLOR = 0x4daf4a;
const VEGETATION_AFTER_COLOR = 0xb3e0a6;

/** Labels beyond this many (the largest |volume| first) are not drawn: DOM cost and clutter. */
const MAX_LABELS = 150;

/** Marker diameters in CSS pixels: the largest event, and the floor that keeps tiny ones visible. */
const MAX_PX = 34;
const MIN_PX = 9;

/** A round marker texture: a disk of `fill` with a rim; `ring` draws the selection ring. */
function markerTexture(fill, ring) {
  const n = 128;
  const c = document.createElement('canvas');
  c.width = c.height = n;
  const g = c.getContext('2d');
  const hex = `#${fill.toString(16).padStart(6, '0')}`;
  g.beginPath();
  g.arc(n / 2, n / 2, n / 2 - (ring ? 14 : 6), 0, 2 * Math.PI);
  g.fillStyle = hex;
  g.globalAlpha = 0.88;
  g.fill();
  g.globalAlpha = 1;
  g.lineWidth = ring ? 14 : 8;
  g.strokeStyle = ring ? '#f2c14e' : 'rgba(255,255,255,0.9)';
  g.stroke();
  const t = new THREE.CanvasTexture(c);
  t.colorSpace = THREE.SRGBColorSpace;
  return t;
}

/** Labels closer than this (CSS pixels) count as overlapping. */
const LABEL_GAP = 2;

export class EventLayer {
  /**
   * events: loaded events (with .local); colourOf(e): a marker colour (0xRRGGBB) instead of the
   * kind's, or null.
   */
  constructor(events, colourOf = null) {
    this.group = new THREE.Group();
    this.markerGroup = new THREE.Group();
    this.labelGroup = new THREE.Group();
    this.solidGroup = new THREE.Group();
    this.group.add(this.solidGroup, this.markerGroup, this.labelGroup);
    this.byId = new Map();
    this.layers = { before: true, after: true, markers: true, labels: true };
    this.filter = () => true;
    this.selected = null;
    this.hovered = null;
    this.pxScale = 0.001;
    this.colourOf = colourOf;

    // Markers keep their size on screen (sprites without size attenuation): an event stays
    // findable from afar and does not hide its own solids in a close-up. Diameter ∝ ∛|volume|,
    // so the marker's apparent volume is proportional to the event's.
    const vmax = Math.max(1e-9, ...events.map((e) => Math.abs(e.volume_m3) || 0));
    this.materials = {};
    for (const e of events) {
      const px = Math.max(MIN_PX, MAX_PX * Math.cbrt((Math.abs(e.volume_m3) || 0) / vmax));
      const marker = new THREE.Sprite(this.material(e, false));
      marker.position.fromArray(e.local);
      marker.renderOrder = 10; // drawn over the terrain and solids (depthTest off)
      marker.userData.eventId = e.id;
      this.markerGroup.add(marker);

      const wrap = document.createElement('div');
      const div = document.createElement('div');
      div.className = `event-label ${e.kind}${e.complete === false ? ' incomplete' : ''}${e.vegetation ? ' vegetation' : ''}`;
      div.textContent = volumeLabel(e.volume_m3, e.volume_uncertainty_m3, e.complete);
      const c = e.vegetation ? null : colourOf?.(e); // a vegetation label's rim is green (style.css)
      if (c != null) div.style.borderColor = `#${c.toString(16).padStart(6, '0')}`;
      div.dataset.id = String(e.id);
      div.style.marginBottom = `${Math.round(px / 2 + 3)}px`; // sit just above the marker
      wrap.appendChild(div);
      const label = new CSS2DObject(wrap);
      label.position.fromArray(e.local);
      label.center.set(0.5, 1);
      this.labelGroup.add(label);

      this.byId.set(e.id, { event: e, marker, label, px, solids: null });
    }
    this.labelRank = new Map(
      [...events].sort((a, b) => Math.abs(b.volume_m3) - Math.abs(a.volume_m3)).map((e, i) => [e.id, i]),
    );
  }

  /** The marker colour of event `e` (0xRRGGBB): vegetation, else the colouring's, else the kind's. */
  markerColour(e) {
    if (e.vegetation) return VEGETATION_COLOR;
    return this.colourOf?.(e) ?? KIND_COLOR[e.kind];
  }

  /** The marker material of event `e` (selected or not), one per colour. */
  material(e, sel) {
    const c = this.markerColour(e);
    const key = `${c}${sel ? '-sel' : ''}`;
    if (!this.materials[key]) {
      this.materials[key] = new THREE.SpriteMaterial({
        map: markerTexture(c, sel), sizeAttenuation: false,
        depthTest: false, depthWrite: false, transparent: true,
      });
    }
    return this.materials[key];
  }

  /**
   * Sprite scale per CSS pixel for the current camera and view height: a non-attenuated sprite
   * of scale s spans s · P₁₁ · H / 2 pixels (P₁₁ = 1 / tan(fov/2)).
   */
  setViewport(camera, cssHeight) {
    const p11 = 1 / Math.tan(THREE.MathUtils.degToRad(camera.fov) / 2);
    this.pxScale = 2 / (p11 * Math.max(1, cssHeight));
    for (const it of this.byId.values()) it.marker.scale.setScalar(it.px * this.pxScale * (it.event.id === this.selected ? 1.25 : 1));
  }

  /** Attach an event's solids (local positions + triangle indices). */
  addSolids(id, before, after) {
    const item = this.byId.get(id);
    if (!item) return;
    const afterColour = item.event.vegetation ? VEGETATION_AFTER_COLOR : AFTER_COLOR[item.event.kind];
    const geom = (m) => {
      const g = new THREE.BufferGeometry();
      g.setAttribute('position', new THREE.BufferAttribute(m.positions, 3));
      g.setIndex(new THREE.BufferAttribute(m.indices, 1));
      g.computeVertexNormals();
      g.computeBoundingSphere();
      return g;
    };
    const solids = new THREE.Group();
    const parts = {};
    if (after) {
      parts.after = new THREE.Mesh(geom(after), new THREE.MeshStandardMaterial({
        color: afterColour, roughness: 0.8, flatShading: true,
        polygonOffset: true, polygonOffsetFactor: 1, polygonOffsetUnits: 1,
      }));
      parts.after.userData.eventId = id;
      solids.add(parts.after);
    }
    if (before) {
      const g = geom(before);
      const before3 = new THREE.Group();
      const faces = new THREE.Mesh(g, new THREE.MeshStandardMaterial({
        color: 0xdfe6ee, roughness: 0.9, transparent: true, opacity: 0.28, depthWrite: false,
        side: THREE.DoubleSide, flatShading: true,
      }));
      faces.userData.eventId = id;
      const edges = new THREE.LineSegments(
        new THREE.EdgesGeometry(g, 25),
        new THREE.LineBasicMaterial({ color: 0xf5f7fa, transparent: true, opacity: 0.85 }),
      );
      before3.add(faces, edges);
      parts.before = before3;
      solids.add(before3);
    }
    item.solids = parts;
    this.solidGroup.add(solids);
    this.apply();
  }

  /** Show only events for which `pred(event)` holds. */
  setFilter(pred) {
    this.filter = pred;
    this.apply();
  }

  setLayer(name, on) {
    this.layers[name] = on;
    this.apply();
  }

  apply() {
    for (const [id, it] of this.byId) {
      const shown = this.filter(it.event);
      it.marker.visible = shown && this.layers.markers;
      it.label.visible = shown && this.layers.labels && this.labelRank.get(id) < MAX_LABELS;
      if (it.solids?.before) it.solids.before.visible = shown && this.layers.before;
      if (it.solids?.after) it.solids.after.visible = shown && this.layers.after;
    }
  }

  /** Number of markers currently drawn. */
  visibleMarkers() {
    let n = 0;
    for (const it of this.byId.values()) if (it.marker.visible) n++;
    return n;
  }

  /** Objects a ray may hit, markers first (they are drawn on top). */
  pickables() {
    const markers = [];
    const solids = [];
    for (const it of this.byId.values()) {
      if (it.marker.visible) markers.push(it.marker);
      if (it.solids?.after?.visible) solids.push(it.solids.after);
      if (it.solids?.before?.visible) solids.push(it.solids.before.children[0]);
    }
    return { markers, solids };
  }

  select(id) {
    this.selected = id;
    for (const [key, it] of this.byId) {
      const on = key === id;
      it.label.element.firstChild.classList.toggle('selected', on);
      it.marker.material = this.material(it.event, on);
      it.marker.scale.setScalar(it.px * this.pxScale * (on ? 1.25 : 1));
      it.marker.renderOrder = on ? 11 : 10;
    }
  }

  /** The event under the pointer (its label is shown whatever it overlaps), or null. */
  hover(id) {
    this.hovered = id;
  }

  /**
   * Hide labels that would overlap a label shown before them, or one of the `obstacles` (the
   * page's panels over the canvas, DOMRects), in screen space: the selected event's first, then
   * the hovered one's, then by |volume|. Call after the label renderer has placed them. Returns
   * how many labels are shown and how many hidden.
   */
  declutter(obstacles = []) {
    const items = [];
    for (const [id, it] of this.byId) {
      const div = it.label.element.firstChild;
      if (!it.label.visible || it.label.element.style.display === 'none') {
        div.classList.remove('crowded');
        continue;
      }
      const rank = id === this.selected ? -2 : id === this.hovered ? -1 : this.labelRank.get(id);
      items.push({ rank, div });
    }
    items.sort((a, b) => a.rank - b.rank);
    // All reads first (one layout), then the writes: visibility does not move anything.
    const rects = items.map((x) => x.div.getBoundingClientRect());
    const shown = [];
    const taken = [...obstacles];
    let hidden = 0;
    items.forEach((x, k) => {
      const r = rects[k];
      const clash = x.rank >= 0 && taken.some((q) => r.left < q.right + LABEL_GAP && q.left < r.right + LABEL_GAP
        && r.top < q.bottom + LABEL_GAP && q.top < r.bottom + LABEL_GAP);
      x.div.classList.toggle('crowded', clash);
      if (clash) hidden++;
      else {
        shown.push(r);
        taken.push(r);
      }
    });
    this.labelCounts = { shown: shown.length, hidden };
    return this.labelCounts;
  }

  /** Radius (m) that frames an event: its box half extents or its marker. */
  extent(id) {
    const it = this.byId.get(id);
    if (!it) return 1;
    const h = it.event.obb?.half_extents;
    const r = Array.isArray(h) && h.every(Number.isFinite) ? Math.hypot(h[0], h[1], h[2]) : 0;
    return Math.max(r, 1);
  }
}

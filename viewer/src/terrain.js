// The terrain point cloud: one THREE.Points draw call with per-point sRGB bytes, sized in world
// units (so a 2M-point cloud reads as a surface when near and does not blow up when far), and
// GPU picking: the points are drawn once more into a tiny render target with their index encoded
// as colour, around the cursor only (the standard three.js GPU-picking technique). A CPU
// raycast over 2M points would stall every pointer move.

import * as THREE from 'three';

const VERT = /* glsl */ `
uniform float uSize;       // point diameter in world units
uniform float uPxPerUnit;  // pixels per world unit at distance 1
uniform float uMinPx;
attribute vec3 rgb;
varying vec3 vColor;
varying float vRound;
void main() {
  vec4 mv = modelViewMatrix * vec4(position, 1.0);
  gl_Position = projectionMatrix * mv;
  gl_PointSize = clamp(uSize * uPxPerUnit / max(-mv.z, 1e-6), uMinPx, 24.0);
  vRound = gl_PointSize > 3.0 ? 1.0 : 0.0; // round only where a disk has pixels to show it
  // The bytes are sRGB; shaders work in linear light (three converts back on output).
  vColor = mix(rgb / 12.92, pow((rgb + 0.055) / 1.055, vec3(2.4)), step(vec3(0.04045), rgb));
}`;

const FRAG = /* glsl */ `
varying vec3 vColor;
varying float vRound;
void main() {
  vec2 d = gl_PointCoord - 0.5;
  if (vRound > 0.5 && dot(d, d) > 0.25) discard;
  gl_FragColor = vec4(vColor, 1.0);
  #include <colorspace_fragment>
}`;

const PICK_VERT = /* glsl */ `
uniform float uSize;
uniform float uPxPerUnit;
uniform float uMinPx;
flat varying vec4 vId;
void main() {
  vec4 mv = modelViewMatrix * vec4(position, 1.0);
  gl_Position = projectionMatrix * mv;
  gl_PointSize = clamp(uSize * uPxPerUnit / max(-mv.z, 1e-6), uMinPx, 24.0);
  int id = gl_VertexID + 1;  // 0 = background
  vId = vec4(float(id & 255), float((id >> 8) & 255), float((id >> 16) & 255), 255.0) / 255.0;
}`;

const PICK_FRAG = /* glsl */ `
flat varying vec4 vId;
void main() { gl_FragColor = vId; }`;

/** Interleave stride: prime, so a grid whose row length is a multiple of it still mixes. */
const STRIDE = 17;

/**
 * Reorder the points so that any prefix of the arrays is an even sample of the whole cloud:
 * every 17th point first, then the next residue, and so on. While the camera moves, drawing a
 * prefix keeps frames fast (see Terrain.setDetail). Unlike a random shuffle this keeps the
 * writer's spatial order within each pass, which rasterizers (software ones above all) like.
 */
export function interleaveTerrain(positions, distances) {
  const n = distances.length;
  const pos = new Float32Array(3 * n);
  const dist = new Float32Array(n);
  let o = 0;
  for (let r = 0; r < STRIDE; r++) {
    for (let k = r; k < n; k += STRIDE, o++) {
      pos[3 * o] = positions[3 * k];
      pos[3 * o + 1] = positions[3 * k + 1];
      pos[3 * o + 2] = positions[3 * k + 2];
      dist[o] = distances[k];
    }
  }
  return { positions: pos, distances: dist };
}

/** Half-width (pixels) of the picking window around the cursor. */
const PICK_R = 5;

export class Terrain {
  /** positions: Float32Array local xyz; colors: Uint8Array sRGB bytes. */
  constructor(positions, colors) {
    this.positions = positions;
    this.count = positions.length / 3;
    const g = new THREE.BufferGeometry();
    g.setAttribute('position', new THREE.BufferAttribute(positions, 3));
    g.setAttribute('rgb', new THREE.BufferAttribute(colors, 3, true));
    g.computeBoundingBox();
    g.computeBoundingSphere();
    this.geometry = g;
    this.box = g.boundingBox.clone();

    // Mean spacing from the largest face of the bounding box (a cliff is tall, not wide).
    const s = this.box.getSize(new THREE.Vector3());
    const area = Math.max(s.x * s.y, s.x * s.z, s.y * s.z, 1e-6);
    this.spacing = Math.sqrt(area / Math.max(this.count, 1));

    const uniforms = () => ({
      uSize: { value: this.spacing * 1.5 },
      uPxPerUnit: { value: 1 },
      uMinPx: { value: 1.5 },
    });
    this.material = new THREE.ShaderMaterial({ vertexShader: VERT, fragmentShader: FRAG, uniforms: uniforms() });
    this.points = new THREE.Points(g, this.material);
    this.points.frustumCulled = false;

    this.pickMaterial = new THREE.ShaderMaterial({
      vertexShader: PICK_VERT, fragmentShader: PICK_FRAG, uniforms: uniforms(),
    });
    this.pickMaterial.uniforms.uMinPx.value = 3;
    this.pickScene = new THREE.Scene();
    const pickPoints = new THREE.Points(g, this.pickMaterial);
    pickPoints.frustumCulled = false;
    this.pickScene.add(pickPoints);
    const w = 2 * PICK_R + 1;
    this.pickTarget = new THREE.WebGLRenderTarget(w, w);
    this.pickBuf = new Uint8Array(4 * w * w);
  }

  /** Point diameter as a multiple of the mean spacing. */
  setSizeFactor(f) {
    this.sizeFactor = f;
    this.applySize();
  }

  /**
   * Draw only the first `fraction` of the (interleaved) points, with points grown by
   * 1/√fraction so the surface stays closed. 1 = everything.
   */
  setDetail(fraction) {
    const f = Math.min(1, Math.max(0.01, fraction));
    this.detail = f;
    this.geometry.setDrawRange(0, f >= 1 ? Infinity : Math.ceil(this.count * f));
    this.applySize();
  }

  applySize() {
    const size = this.spacing * (this.sizeFactor ?? 1.5) / Math.sqrt(this.detail ?? 1);
    this.material.uniforms.uSize.value = size;
    this.pickMaterial.uniforms.uSize.value = this.spacing * (this.sizeFactor ?? 1.5);
  }

  /** Keep the pixel scale in step with the canvas height (drawing-buffer pixels). */
  setViewport(camera, bufferHeight, pixelRatio) {
    const k = 1 / (2 * Math.tan(THREE.MathUtils.degToRad(camera.fov) / 2));
    this.material.uniforms.uPxPerUnit.value = bufferHeight * k;
    this.material.uniforms.uMinPx.value = 1.5 * pixelRatio;
  }

  /**
   * Index of the visible point nearest to CSS pixel (x, y) of a cssW × cssH view within
   * PICK_R pixels, or −1.
   */
  pick(renderer, camera, x, y, cssW, cssH) {
    if (!this.points.visible) return -1;
    const w = 2 * PICK_R + 1;
    const k = 1 / (2 * Math.tan(THREE.MathUtils.degToRad(camera.fov) / 2));
    this.pickMaterial.uniforms.uPxPerUnit.value = cssH * k;
    const prevColor = renderer.getClearColor(new THREE.Color());
    const prevAlpha = renderer.getClearAlpha();
    camera.setViewOffset(cssW, cssH, Math.round(x) - PICK_R, Math.round(y) - PICK_R, w, w);
    renderer.setRenderTarget(this.pickTarget);
    renderer.setClearColor(0x000000, 0);
    renderer.clear();
    renderer.render(this.pickScene, camera);
    renderer.readRenderTargetPixels(this.pickTarget, 0, 0, w, w, this.pickBuf);
    renderer.setRenderTarget(null);
    renderer.setClearColor(prevColor, prevAlpha);
    camera.clearViewOffset();

    let best = -1;
    let bestD = Infinity;
    for (let py = 0; py < w; py++) {
      for (let px = 0; px < w; px++) {
        const o = 4 * (py * w + px);
        const id = this.pickBuf[o] | (this.pickBuf[o + 1] << 8) | (this.pickBuf[o + 2] << 16);
        if (id === 0) continue;
        // Render-target rows run bottom-up.
        const d = (px - PICK_R) ** 2 + (w - 1 - py - PICK_R) ** 2;
        if (d < bestD) { bestD = d; best = id - 1; }
      }
    }
    return best < this.count ? best : -1;
  }
}

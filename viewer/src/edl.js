// Eye-Dome Lighting (Boucheny, "Visualisation scientifique de grands volumes de données", PhD
// thesis, 2009; the shading used by CloudCompare and Potree): points carry no normals, so the
// surface is shaded from the depth buffer alone. Each pixel darkens by how much nearer its
// neighbours are (in log depth), which outlines edges and brings out relief, at the cost of
// one full-screen pass.

import * as THREE from 'three';

const VERT = /* glsl */ `
varying vec2 vUv;
void main() { vUv = uv; gl_Position = vec4(position.xy, 0.0, 1.0); }`;

const FRAG = /* glsl */ `
uniform sampler2D tColor;
uniform sampler2D tDepth;
uniform vec2 uTexel;
uniform float uNear;
uniform float uFar;
uniform float uRadius;
uniform float uStrength;
varying vec2 vUv;

const float BACKGROUND = -1e6;

// log2 of the view distance at uv, or BACKGROUND.
float logDepth(vec2 uv) {
  float d = texture2D(tDepth, uv).x;
  if (d >= 1.0) return BACKGROUND;
  float z = d * 2.0 - 1.0;
  float lin = (2.0 * uNear * uFar) / (uFar + uNear - z * (uFar - uNear));
  return log2(lin);
}

void main() {
  vec4 c = texture2D(tColor, vUv);
  float ld = logDepth(vUv);
  if (ld > BACKGROUND) {
    float sum = 0.0;
    for (int i = 0; i < 8; i++) {
      float a = float(i) * 0.78539816;
      vec2 o = vec2(cos(a), sin(a)) * uRadius * uTexel;
      float ln = logDepth(vUv + o);
      if (ln > BACKGROUND) sum += max(0.0, ld - ln);
    }
    float shade = exp(-sum / 8.0 * 300.0 * uStrength);
    c.rgb *= shade;
  }
  gl_FragColor = c;
  #include <colorspace_fragment>
}`;

export class EyeDome {
  constructor() {
    this.target = new THREE.WebGLRenderTarget(1, 1, {
      type: THREE.HalfFloatType, // linear light in 8 bits would band in the darks
      samples: 4,
      depthTexture: new THREE.DepthTexture(1, 1),
    });
    this.material = new THREE.ShaderMaterial({
      vertexShader: VERT,
      fragmentShader: FRAG,
      uniforms: {
        tColor: { value: this.target.texture },
        tDepth: { value: this.target.depthTexture },
        uTexel: { value: new THREE.Vector2(1, 1) },
        uNear: { value: 0.1 },
        uFar: { value: 1000 },
        uRadius: { value: 1.4 },
        uStrength: { value: 0.5 },
      },
      depthTest: false,
      depthWrite: false,
    });
    this.quad = new THREE.Mesh(new THREE.PlaneGeometry(2, 2), this.material);
    this.quad.frustumCulled = false;
    this.quadScene = new THREE.Scene();
    this.quadScene.add(this.quad);
    this.quadCamera = new THREE.OrthographicCamera(-1, 1, 1, -1, 0, 1);
  }

  setSize(width, height, pixelRatio) {
    this.target.setSize(width, height);
    this.material.uniforms.uTexel.value.set(1 / width, 1 / height);
    this.material.uniforms.uRadius.value = 1.4 * pixelRatio;
  }

  /** Render `scene` through `camera` with the shading, to the screen. */
  render(renderer, scene, camera) {
    renderer.setRenderTarget(this.target);
    renderer.render(scene, camera);
    renderer.setRenderTarget(null);
    this.material.uniforms.uNear.value = camera.near;
    this.material.uniforms.uFar.value = camera.far;
    renderer.render(this.quadScene, this.quadCamera);
  }
}

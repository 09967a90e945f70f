// Diverging colour ramp for M3C2 distances, centred on 0: blue = loss (surface moved away along
// the normal), white = no change, red = gain. The stops are ColorBrewer RdBu (Brewer, Harrower &
// Penn State, colorbrewer2.org) without its two darkest ends, which vanish on the dark background.

const STOPS = [
  [0x21, 0x66, 0xac], [0x43, 0x93, 0xc3], [0x92, 0xc5, 0xde], [0xd1, 0xe5, 0xf0],
  [0xf7, 0xf7, 0xf7],
  [0xfd, 0xdb, 0xc7], [0xf4, 0xa5, 0x82], [0xd6, 0x60, 0x4d], [0xb2, 0x18, 0x2b],
];

/** Colour of points where M3C2 was not computed (NaN). */
export const NO_DATA = [0x80, 0x86, 0x8f];

/** The ramp's colour at t ∈ [−1, 1] as [r, g, b] bytes. */
export function rampAt(t) {
  const x = (Math.min(1, Math.max(-1, t)) + 1) / 2 * (STOPS.length - 1);
  const i = Math.min(STOPS.length - 2, Math.floor(x));
  const f = x - i;
  const a = STOPS[i];
  const b = STOPS[i + 1];
  return [0, 1, 2].map((c) => Math.round(a[c] + (b[c] - a[c]) * f));
}

/**
 * Symmetric half-width of the ramp from the writer's robust range [lo, hi], rounded up to a
 * "nice" number (1, 1.5, 2, 2.5, 3, 4, 5, 6, 8 × 10^k) so the legend ticks read cleanly.
 */
export function rampHalfWidth(range) {
  const r = Array.isArray(range) ? Math.max(Math.abs(range[0]), Math.abs(range[1])) : NaN;
  if (!(Number.isFinite(r) && r > 0)) return 1;
  const p = 10 ** Math.floor(Math.log10(r));
  const m = [1, 1.5, 2, 2.5, 3, 4, 5, 6, 8, 10].find((s) => s * p >= r * (1 - 1e-9));
  return m * p;
}

/**
 * Per-point sRGB bytes for distances `d` (Float32Array) on the ramp ±`half`. A 512-entry table
 * keeps this at a few milliseconds for 2M points.
 */
export function distanceColors(d, half) {
  const LUT = 512;
  const lut = new Uint8Array(3 * LUT);
  for (let i = 0; i < LUT; i++) lut.set(rampAt((i / (LUT - 1)) * 2 - 1), 3 * i);
  const out = new Uint8Array(3 * d.length);
  const scale = (LUT - 1) / (2 * half);
  for (let i = 0; i < d.length; i++) {
    const v = d[i];
    let r, g, b;
    if (v !== v) {
      [r, g, b] = NO_DATA;
    } else {
      let j = Math.round((v + half) * scale);
      j = j < 0 ? 0 : j >= LUT ? LUT - 1 : j;
      r = lut[3 * j]; g = lut[3 * j + 1]; b = lut[3 * j + 2];
    }
    out[3 * i] = r; out[3 * i + 1] = g; out[3 * i + 2] = b;
  }
  return out;
}

/** CSS linear-gradient of the whole ramp, for the legend. */
export function rampCss() {
  const parts = STOPS.map((c, i) => `rgb(${c.join(',')}) ${((i / (STOPS.length - 1)) * 100).toFixed(1)}%`);
  return `linear-gradient(to right, ${parts.join(', ')})`;
}

// Number formatting for labels, the table and the panel. Negative numbers use the typographic
// minus sign (U+2212), which reads better next to "+" in tabular figures.

const MINUS = '\u2212';

/** "+12.3" / "−0.85": always signed, `digits` decimals. */
export function signed(v, digits) {
  if (!Number.isFinite(v)) return '–';
  const s = Math.abs(v).toFixed(digits);
  if (Number(s) === 0) return s;
  return (v < 0 ? MINUS : '+') + s;
}

/** Decimals that keep about three significant figures for volumes of ordinary size. */
function volumeDigits(v) {
  const a = Math.abs(v);
  return a >= 1 ? 1 : 2;
}

/** The marker label: "+12.3 ± 1.1 m³". */
export function volumeLabel(v, u, complete = true) {
  const d = volumeDigits(v);
  // An incomplete event's volume counts the measured part only: its interval is no 95 % bound,
  // so none is shown beside it (SPEC.md §1 "Change of any depth").
  if (complete === false) return `${signed(v, d)} m³ (incomplete)`;
  const unc = Number.isFinite(u) ? ` ± ${Math.abs(u).toFixed(d)}` : '';
  return `${signed(v, d)}${unc} m³`;
}

/** Plain fixed-point number, "–" when missing. */
export function fixed(v, digits) {
  return Number.isFinite(v) ? v.toFixed(digits).replace('-', MINUS) : '–';
}

/** A global coordinate triple in the input CRS (millimetres are meaningful in f64). */
export function coords(p, digits = 3) {
  return `x ${fixed(p[0], digits)}  y ${fixed(p[1], digits)}  z ${fixed(p[2], digits)}`;
}

/** "80 %": a fraction 0..1 as a whole percentage. */
export function percent(f) {
  return `${Math.round(f * 100)} %`;
}

/**
 * What an event's points say about vegetation: "vegetation (80 % of its points)" for an event
 * judged vegetation (listed, but outside the totals), "vegetation-like points: 12 %" for one
 * judged otherwise, null when not judged (older results, or no fraction).
 */
export function vegetationText(e) {
  const f = Number.isFinite(e.vegetation_fraction) ? e.vegetation_fraction : null;
  if (e.vegetation === true) return f == null ? 'vegetation' : `vegetation (${percent(f)} of its points)`;
  return f == null ? null : `vegetation-like points: ${percent(f)}`;
}

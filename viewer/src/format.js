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

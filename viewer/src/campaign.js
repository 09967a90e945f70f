// A campaign directory (`talus campaign ... --out DIR`, SPEC.md §5): DIR/summary.json lists the
// epochs and pairs, DIR/campaign.json holds the table (one row per pair), DIR/events.geojson
// every pair's events with `pair`, `before_date`, `after_date` and `track_id`, and each
// DIR/pairs/<before>_<after>/ is a comparison result the viewer shows as it shows any.
//
// The viewer shows one pair at a time (its terrain, solids, events), chosen with a selector, a
// time slider or a row of the campaign table; the events drawn are the pair's or every pair's,
// coloured by kind, by pair (early → late) or by track. The choice lives in the URL's hash
// (#pair=…&events=…&colour=…), so it survives a reload and the browser's back button; a change
// loads the page again for that pair, keeping the camera where it was (the pairs share one site
// and one local frame).

import { parseEvents } from './data.js';

const CAMERA_KEY = 'talus-campaign-camera';

/**
 * The campaign of the top-level summary.json (`top`), or null when the directory is a
 * comparison: { pairs: [{label, before, after, before_date, after_date, ...row}], rows,
 * fc (events.geojson), power_law }.
 */
export async function loadCampaign(top) {
  if (!top || !Array.isArray(top.pairs) || !Array.isArray(top.epochs)) return null;
  const get = async (path) => {
    const res = await fetch('/data/' + path);
    if (!res.ok) throw new Error(`${path}: HTTP ${res.status}`);
    return res.json();
  };
  const [table, fc] = await Promise.all([get('campaign.json'), get('events.geojson')]);
  if (!table || !Array.isArray(table.pairs) || !table.pairs.length) throw new Error('campaign.json: no pairs');
  const pairs = table.pairs.filter((p) => typeof p.label === 'string' && p.label);
  // One colour scale for every pair, so that pairs compare by eye: campaign.json's
  // distance_range (the widest of the pairs'); a campaign written before it had one takes the
  // widest of its pairs' view.json ranges.
  let range = validRange(table.distance_range);
  if (!range) {
    const views = await Promise.all(pairs.map((p) => get(`pairs/${encodeURIComponent(p.label)}/view.json`).catch(() => null)));
    range = views.map((v) => validRange(v?.distance_range)).filter(Boolean)
      .reduce((a, b) => (a ? [Math.min(a[0], b[0]), Math.max(a[1], b[1])] : b), null);
  }
  return { pairs, epochs: table.epochs || top.epochs, fc, summary: top, distanceRange: range };
}

/** `r` when it is [lo, hi] of finite numbers, else null. */
function validRange(r) {
  return Array.isArray(r) && r.length === 2 && r.every(Number.isFinite) ? r : null;
}

/** The choice in the URL's hash, completed with defaults (the first pair, its events, by kind). */
export function readState(campaign) {
  const h = new URLSearchParams(location.hash.replace(/^#/, ''));
  const labels = campaign.pairs.map((p) => p.label);
  const pair = labels.includes(h.get('pair')) ? h.get('pair') : labels[0];
  const scope = h.get('events') === 'all' ? 'all' : 'pair';
  const colour = ['pair', 'track'].includes(h.get('colour')) ? h.get('colour') : 'kind';
  return { pair, scope, colour, index: labels.indexOf(pair) };
}

/** Go to `state` (a new history entry; the hashchange reloads the page). */
export function goTo(state, camera) {
  if (camera) sessionStorage.setItem(CAMERA_KEY, JSON.stringify(camera));
  const h = new URLSearchParams({ pair: state.pair, events: state.scope, colour: state.colour });
  location.hash = h.toString();
}

/** The camera pose saved by the last [`goTo`] (taken once), or null. */
export function savedCamera() {
  const s = sessionStorage.getItem(CAMERA_KEY);
  sessionStorage.removeItem(CAMERA_KEY);
  try {
    const c = s && JSON.parse(s);
    const ok = (v) => Array.isArray(v) && v.length === 3 && v.every(Number.isFinite);
    return c && ok(c.position) && ok(c.target) ? c : null;
  } catch {
    return null;
  }
}

/**
 * The events to draw: the pair's own (`pairEvents`, ids as in its meshes) with their campaign
 * properties (track, dates), or every pair's with ids 1..n in date order (`event_id` keeps the
 * pair's id, `mesh_id` names the solids of the pair shown, the other pairs have none).
 */
export function sceneEvents(campaign, state, origin, pairEvents) {
  const all = parseEvents(campaign.fc, origin, 'events.geojson').events;
  const key = (e) => `${e.pair}/${e.id}`;
  const byKey = new Map(all.map((e) => [key(e), e]));
  if (state.scope === 'pair') {
    return pairEvents.map((e) => {
      const c = byKey.get(`${state.pair}/${e.id}`);
      const extra = c ? { pair: c.pair, before_date: c.before_date, after_date: c.after_date, track_id: c.track_id } : { pair: state.pair };
      return { ...e, ...extra };
    });
  }
  const order = new Map(campaign.pairs.map((p, i) => [p.label, i]));
  return all
    .filter((e) => order.has(e.pair))
    .sort((a, b) => order.get(a.pair) - order.get(b.pair) || a.id - b.id)
    .map((e, i) => ({ ...e, event_id: e.id, mesh_id: e.pair === state.pair ? e.id : null, id: i + 1 }));
}

/**
 * n colours from early (violet) to late (yellow), for pairs in time: a viridis-like ramp whose
 * dark end is lifted, so every step stands out on the dark background.
 */
export function timeColours(n) {
  const stops = [[0x8b, 0x6c, 0xf0], [0x3f, 0x9b, 0xe8], [0x2e, 0xc4, 0xa0], [0xa6, 0xd8, 0x54], [0xff, 0xd9, 0x2f]];
  return Array.from({ length: n }, (_, i) => {
    const t = n > 1 ? i / (n - 1) : 0.5;
    const x = t * (stops.length - 1);
    const k = Math.min(stops.length - 2, Math.floor(x));
    const u = x - k;
    const c = stops[k].map((v, j) => Math.round(v + (stops[k + 1][j] - v) * u));
    return (c[0] << 16) | (c[1] << 8) | c[2];
  });
}

/** Distinct colours for tracks (Tableau 10, then round again). */
const TRACK_COLOURS = [0x4e79a7, 0xf28e2b, 0xe15759, 0x76b7b2, 0x59a14f, 0xedc948, 0xb07aa1, 0xff9da7, 0x9c755f, 0xbab0ac];
export const trackColour = (t) => TRACK_COLOURS[((Number(t) || 1) - 1) % TRACK_COLOURS.length];

/** The marker colour of an event under `state.colour`, or null for the kind's colour. */
export function colouring(campaign, state) {
  if (state.colour === 'pair') {
    const colours = timeColours(campaign.pairs.length);
    const index = new Map(campaign.pairs.map((p, i) => [p.label, i]));
    return (e) => colours[index.get(e.pair) ?? 0];
  }
  if (state.colour === 'track') return (e) => (Number.isFinite(e.track_id) ? trackColour(e.track_id) : 0x9aa3ad);
  return null;
}

const hex = (c) => `#${c.toString(16).padStart(6, '0')}`;
const esc = (s) => String(s).replace(/[&<>"]/g, (c) => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;' })[c]);
const MINUS = '\u2212';
const num = (v, d) => (Number.isFinite(v) ? v.toFixed(d).replace('-', MINUS) : '–');
const sgn = (v, d) => (Number.isFinite(v) ? (v > 0 ? '+' : '') + num(v, d) : '–');
const dates = (p) => `${p.before_date ?? p.before} → ${p.after_date ?? p.after}`;

/**
 * The campaign section: pair selector, time slider, events scope and colouring, and the table
 * of campaign.json (a row per pair; a click shows that pair). `go(state)` switches.
 */
export function drawCampaign(el, campaign, state, go) {
  el.hidden = false;
  const { pairs } = campaign;
  const options = pairs
    .map((p, i) => `<option value="${esc(p.label)}"${i === state.index ? ' selected' : ''}>${esc(dates(p))}</option>`)
    .join('');
  const colours = timeColours(pairs.length);
  const rows = pairs.map((p, i) => `
      <tr data-pair="${esc(p.label)}"${i === state.index ? ' class="selected"' : ''}>
        <td><span class="sw" style="background:${hex(colours[i])}"></span>${esc(dates(p))}</td>
        <td class="num">${Number.isFinite(p.days) ? p.days : '–'}</td>
        <td class="num">${Number.isFinite(p.events) ? p.events : '–'}</td>
        <td class="num gain">${sgn(p.gain_m3, 1)}</td>
        <td class="num loss">${sgn(p.loss_m3, 1)}</td>
        <td class="num">${sgn(p.net_m3, 1)}</td>
      </tr>`).join('');
  el.innerHTML = `
    <div class="row">
      <label for="pair">Pair</label>
      <select id="pair">${options}</select>
    </div>
    <div class="row">
      <label for="pair-slider">Time</label>
      <input id="pair-slider" type="range" min="0" max="${pairs.length - 1}" step="1" value="${state.index}">
      <span id="pair-slider-text" class="muted">${state.index + 1} / ${pairs.length}</span>
    </div>
    <div class="row">
      <label for="scope">Events</label>
      <select id="scope">
        <option value="pair"${state.scope === 'pair' ? ' selected' : ''}>this pair</option>
        <option value="all"${state.scope === 'all' ? ' selected' : ''}>all pairs</option>
      </select>
      <label for="colour" class="inline">colour by</label>
      <select id="colour">
        <option value="kind"${state.colour === 'kind' ? ' selected' : ''}>kind</option>
        <option value="pair"${state.colour === 'pair' ? ' selected' : ''}>pair</option>
        <option value="track"${state.colour === 'track' ? ' selected' : ''}>track</option>
      </select>
    </div>
    <table id="campaign-table">
      <thead><tr>
        <th scope="col">Pair</th><th scope="col" class="num">Days</th><th scope="col" class="num">Events</th>
        <th scope="col" class="num">Gain m³</th><th scope="col" class="num">Loss m³</th><th scope="col" class="num">Net m³</th>
      </tr></thead>
      <tbody>${rows}</tbody>
    </table>`;
  const to = (patch) => go({ ...state, ...patch });
  el.querySelector('#pair').addEventListener('change', (ev) => to({ pair: ev.target.value }));
  const slider = el.querySelector('#pair-slider');
  slider.addEventListener('input', () => {
    el.querySelector('#pair-slider-text').textContent = `${Number(slider.value) + 1} / ${pairs.length}: ${dates(pairs[Number(slider.value)])}`;
  });
  slider.addEventListener('change', () => to({ pair: pairs[Number(slider.value)].label }));
  el.querySelector('#scope').addEventListener('change', (ev) => to({ scope: ev.target.value }));
  el.querySelector('#colour').addEventListener('change', (ev) => to({ colour: ev.target.value }));
  el.querySelector('tbody').addEventListener('click', (ev) => {
    const tr = ev.target.closest('tr[data-pair]');
    if (tr && tr.dataset.pair !== state.pair) to({ pair: tr.dataset.pair });
  });
}

/** Legend keys for the colouring: a swatch per pair, or per track (at most 12 listed). */
export function colourKeys(campaign, state, events) {
  if (state.colour === 'pair') {
    const colours = timeColours(campaign.pairs.length);
    return campaign.pairs.map((p, i) => [colours[i], dates(p)]);
  }
  if (state.colour === 'track') {
    const tracks = [...new Set(events.map((e) => e.track_id).filter(Number.isFinite))].sort((a, b) => a - b);
    const keys = tracks.slice(0, 12).map((t) => [trackColour(t), `track ${t}`]);
    if (tracks.length > 12) keys.push([null, `… ${tracks.length} tracks`]);
    return keys;
  }
  return null;
}

// The side panel: the sortable, filterable event table, the property panel of one event, the
// legend and the header line. Plain DOM; the table is rebuilt on sort/filter (events number in
// the hundreds, not millions).

import { fixed, signed, volumeLabel, coords, percent, vegetationText } from './format.js';
import { rampCss, NO_DATA } from './colormap.js';
import { KIND_COLOR, VEGETATION_COLOR } from './events.js';

const hex = (c) => `#${c.toString(16).padStart(6, '0')}`;

export class EventTable {
  /**
   * onPick(id) is called when a row is clicked; `extra` columns ([{ key, label, num }]) follow
   * the kind (a campaign's pair and track).
   */
  constructor(table, note, events, onPick, extra = []) {
    this.table = table;
    this.extra = extra;
    const kindTh = table.querySelector('th[data-key="kind"]');
    for (const c of [...extra].reverse()) {
      const th = document.createElement('th');
      th.dataset.key = c.key;
      th.scope = 'col';
      th.textContent = c.label;
      if (c.num) th.className = 'num';
      kindTh.after(th);
    }
    this.tbody = table.querySelector('tbody');
    this.note = note;
    this.events = events;
    this.sort = { key: 'id', dir: 1 };
    this.filter = () => true;
    this.selected = null;
    for (const th of table.querySelectorAll('th[data-key]')) {
      th.addEventListener('click', () => {
        const key = th.dataset.key;
        // First click on a volume column: largest gains first is less useful than the biggest
        // change, so numbers start descending; ids and kinds ascending.
        const first = key === 'id' || key === 'kind' ? 1 : -1;
        this.sort = this.sort.key === key ? { key, dir: -this.sort.dir } : { key, dir: first };
        this.render();
      });
    }
    this.tbody.addEventListener('click', (ev) => {
      const tr = ev.target.closest('tr[data-id]');
      if (tr) onPick(Number(tr.dataset.id));
    });
  }

  setFilter(pred) {
    this.filter = pred;
    this.render();
  }

  select(id) {
    this.selected = id;
    for (const tr of this.tbody.rows) tr.classList.toggle('selected', Number(tr.dataset.id) === id);
    const row = this.tbody.querySelector(`tr[data-id="${id}"]`);
    if (row) row.scrollIntoView({ block: 'nearest' });
  }

  rowCount() {
    return this.tbody.rows.length;
  }

  render() {
    const { key, dir } = this.sort;
    for (const th of this.table.querySelectorAll('th[data-key]')) {
      if (th.dataset.key === key) th.setAttribute('aria-sort', dir > 0 ? 'ascending' : 'descending');
      else th.removeAttribute('aria-sort');
    }
    const val = (e) => e[key];
    const rows = this.events.filter(this.filter).sort((a, b) => {
      const x = val(a);
      const y = val(b);
      const c = typeof x === 'string' || typeof y === 'string'
        ? String(x).localeCompare(String(y))
        : (Number.isFinite(x) ? x : -Infinity) - (Number.isFinite(y) ? y : -Infinity);
      return c * dir || a.id - b.id;
    });
    const frag = document.createDocumentFragment();
    for (const e of rows) {
      const tr = document.createElement('tr');
      tr.dataset.id = String(e.id);
      if (e.id === this.selected) tr.className = 'selected';
      const cells = [
        [String(e.id), ''],
        [e.kind, `kind ${e.kind}`],
        ...this.extra.map((c) => [e[c.key] == null ? '–' : String(e[c.key]), c.num ? 'num' : '']),
        [volumeLabel(e.volume_m3, e.volume_uncertainty_m3, e.complete).replace(' m³', ''), 'num'],
        [fixed(e.area_m2, 1), 'num'],
        [fixed(e.max_abs_distance_m, 2), 'num'],
        [Number.isFinite(e.n_points) ? String(e.n_points) : '–', 'num'],
      ];
      for (const [text, cls] of cells) {
        const td = document.createElement('td');
        // A long label (a pair's `20210301_20210601`) may break after its '_' so the table fits
        // its panel; the text stays the same (<wbr> adds none).
        const parts = text.split('_');
        parts.forEach((part, i) => {
          if (i) td.append('_', document.createElement('wbr'));
          td.append(part);
        });
        if (cls) td.className = cls;
        tr.appendChild(td);
      }
      tr.children[2 + this.extra.length].dataset.value = String(e.volume_m3);
      // Vegetation is said beside the kind (the kind still sorts the column); the row's tooltip
      // has the whole sentence, and the fraction of an event judged otherwise.
      const veg = vegetationText(e);
      if (veg) tr.title = veg;
      if (e.vegetation) {
        tr.classList.add('vegetation');
        const tag = document.createElement('span');
        tag.className = 'veg';
        tag.textContent = e.vegetation_fraction == null ? 'vegetation' : `vegetation (${percent(e.vegetation_fraction)})`;
        tr.children[1].appendChild(tag);
      }
      frag.appendChild(tr);
    }
    this.tbody.replaceChildren(frag);
    const hidden = this.events.length - rows.length;
    this.note.textContent = `${rows.length} of ${this.events.length} events shown` +
      (hidden ? ` (${hidden} filtered out)` : '');
  }
}

/** Fill the property panel with every property of event `e` (null: the hint). */
export function showEvent(panel, e, units) {
  panel.replaceChildren();
  if (!e) {
    const p = document.createElement('p');
    p.className = 'hint';
    p.textContent = 'Click an event (marker, solid or table row) to see its properties.';
    panel.appendChild(p);
    return;
  }
  const h = document.createElement('h2');
  h.innerHTML = `Event #${e.id} <span class="kind ${e.kind}"></span>`;
  h.querySelector('span').textContent = e.kind;
  if (e.vegetation) {
    const tag = document.createElement('span');
    tag.className = 'veg';
    tag.textContent = ' vegetation';
    h.appendChild(tag);
  }
  panel.appendChild(h);
  const dl = document.createElement('dl');
  const add = (label, text, field, cls) => {
    const dt = document.createElement('dt');
    dt.textContent = label;
    const dd = document.createElement('dd');
    dd.textContent = text;
    if (field) dd.dataset.field = field;
    if (cls) dd.className = cls;
    dl.append(dt, dd);
  };
  const u = units || 'm';
  const veg = vegetationText(e);
  // First: a vegetation event's volume is no ground change (talus leaves it out of the totals).
  if (veg) add('Vegetation', veg, 'vegetation', e.vegetation ? 'veg' : '');
  add('Volume', `${signed(e.volume_m3, 2)} ${u}³`, 'volume_m3', 'big');
  if (e.complete === false) {
    add('Uncertainty', `± ${fixed(e.volume_uncertainty_m3, 2)} ${u}³ of the measured part: not a 95 % bound`,
      'volume_uncertainty_m3');
    add('Incomplete', e.volume_note || 'the volume covers part of the change only', 'volume_note', 'warn');
  } else {
    add('Uncertainty', `± ${fixed(e.volume_uncertainty_m3, 2)} ${u}³`, 'volume_uncertainty_m3');
  }
  if (e.gain_m3 !== undefined) add('Gain part', `${signed(e.gain_m3, 2)} ${u}³`, 'gain_m3');
  if (e.loss_m3 !== undefined) add('Loss part', `${signed(e.loss_m3, 2)} ${u}³`, 'loss_m3');
  add('Core points', Number.isFinite(e.n_points) ? String(e.n_points) : '–', 'n_points');
  add('Area', `${fixed(e.area_m2, 2)} ${u}²`, 'area_m2');
  add('Mean distance', `${signed(e.mean_distance_m, 3)} ${u}`, 'mean_distance_m');
  add('Max |distance|', `${fixed(e.max_abs_distance_m, 3)} ${u}`, 'max_abs_distance_m');
  add('Mean LoD95', `${fixed(e.mean_lod95_m, 3)} ${u}`, 'mean_lod95_m');
  add('Centroid', coords(e.centroid), 'centroid');
  const obb = e.obb;
  if (obb && typeof obb === 'object') {
    if (Array.isArray(obb.center)) add('Box centre', coords(obb.center), 'obb_center');
    if (Array.isArray(obb.half_extents)) {
      add('Box half extents', obb.half_extents.map((v) => fixed(v, 2)).join(' × ') + ` ${u}`, 'obb_half_extents');
    }
    if (Array.isArray(obb.axes)) {
      obb.axes.forEach((a, i) => {
        if (Array.isArray(a)) add(`Box axis ${i + 1}`, a.map((v) => fixed(v, 3)).join(', '), `obb_axis_${i}`);
      });
    }
  }
  // Anything else the writer added, so the panel shows *all* properties.
  const known = new Set(['id', 'kind', 'volume_m3', 'volume_uncertainty_m3', 'gain_m3', 'loss_m3',
    'n_points', 'area_m2', 'mean_distance_m', 'max_abs_distance_m', 'mean_lod95_m', 'obb',
    'centroid', 'local', 'mesh_id', 'volume_note', 'vegetation', 'vegetation_fraction']);
  for (const [k, v] of Object.entries(e)) {
    if (known.has(k)) continue;
    add(k, typeof v === 'number' ? String(v) : JSON.stringify(v), k);
  }
  panel.appendChild(dl);
}

/**
 * The legend: the distance ramp with ticks and units (`scale` says whose: a campaign's one scale
 * for every pair), the event markers as they are drawn (a disk with a white rim, in the kind's
 * colour, sized by volume: the small outlined dots on the terrain), and `vegetation` adds the
 * vegetation events' colour (when the result judges vegetation at all).
 */
export function drawLegend(el, half, units, colourKeys = null, vegetation = false, scale = '') {
  const u = units || 'm';
  // Three significant figures, trailing zeros dropped: "+0.3", "−0.0075", "+150".
  const tick = (v) => (v === 0 ? '0' : (v < 0 ? '\u2212' : '+') + String(Number(Math.abs(v).toPrecision(3))));
  const ticks = [-1, -0.5, 0, 0.5, 1]
    .map((t) => `<span style="left:${(t + 1) * 50}%">${tick(t * half)}</span>`)
    .join('');
  el.innerHTML = `
    <div class="title">M3C2 distance (${u})${scale ? ` <span class="scale">· ${scale}</span>` : ''}</div>
    <div class="ramp" style="background:${rampCss()}"></div>
    <div class="ticks">${ticks}</div>
    <div class="keys">
      <span><span class="sw" style="background:rgb(${NO_DATA.join(',')})"></span>not computed</span>
      ${colourKeys ? '' : `<span><span class="dot marker" style="background:${hex(KIND_COLOR.gain)}"></span>gain (red: material added)</span>
      <span><span class="dot marker" style="background:${hex(KIND_COLOR.loss)}"></span>loss (blue: material removed)</span>`}
      ${vegetation ? `<span><span class="dot marker" style="background:${hex(VEGETATION_COLOR)}"></span>vegetation (not in totals)</span>` : ''}
      <span class="marker-key"><span class="dot marker small"></span><span class="dot marker"></span>an event's marker, at its centre: size ∝ ∛|volume| (the smallest events are the small dots)</span>
    </div>`;
  if (colourKeys) {
    const keys = document.createElement('div');
    keys.className = 'keys colour-keys';
    for (const [c, text] of colourKeys) {
      const span = document.createElement('span');
      if (c != null) {
        const dot = document.createElement('span');
        dot.className = 'dot marker';
        dot.style.background = hex(c);
        span.appendChild(dot);
      }
      span.append(text);
      keys.appendChild(span);
    }
    el.appendChild(keys);
  }
}

/**
 * The header: CRS, counts (`nVegetation` of the events are vegetation), and tool version and
 * inputs from summary.json when present.
 */
export function drawMeta(el, view, crsName, nEvents, summary, nVegetation = 0) {
  const lines = [];
  const crs = crsName && crsName !== view.crs ? `${view.crs} (${crsName})` : view.crs;
  lines.push(`CRS <b></b> · ${view.points.toLocaleString('en-US')} terrain points · ${nEvents} events`
    + (nVegetation ? `, ${nVegetation} of them vegetation` : ''));
  const esc = (s) => String(s).replace(/[&<>"]/g, (c) => ({ '&': '&amp;', '<': '&lt;', '>': '&gt;', '"': '&quot;' })[c]);
  if (summary && typeof summary === 'object') {
    const version = summary.version ?? summary.tool_version ?? summary.tool?.version;
    let inputs = summary.inputs;
    if (inputs && !Array.isArray(inputs) && typeof inputs === 'object') inputs = Object.values(inputs);
    const names = Array.isArray(inputs)
      ? inputs.map((i) => (typeof i === 'string' ? i : i?.path)).filter(Boolean).map((p) => String(p).split(/[\\/]/).pop())
      : [];
    if (names.length) lines.push(`${names.map(esc).join(' → ')}`);
    if (version) lines.push(`talus ${esc(version)}`);
  }
  el.innerHTML = lines.join('<br>');
  el.querySelector('b').textContent = crs;
}

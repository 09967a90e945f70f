// Minimal PLY reader for the event solids (Turk, "The PLY Polygon File Format", 1994): binary
// little- or big-endian, any scalar vertex property types, polygon faces as index lists
// (triangulated as fans). Coordinates are read as f64 and shifted by the origin before they
// become float32, so UTM-sized values keep their precision (three's PLYLoader would round the
// global doubles to float32 first: ~0.5 m steps at 5,000,000).

const SIZES = {
  char: 1, int8: 1, uchar: 1, uint8: 1, short: 2, int16: 2, ushort: 2, uint16: 2,
  int: 4, int32: 4, uint: 4, uint32: 4, float: 4, float32: 4, double: 8, float64: 8,
};

function reader(view, little) {
  return {
    char: (o) => view.getInt8(o), int8: (o) => view.getInt8(o),
    uchar: (o) => view.getUint8(o), uint8: (o) => view.getUint8(o),
    short: (o) => view.getInt16(o, little), int16: (o) => view.getInt16(o, little),
    ushort: (o) => view.getUint16(o, little), uint16: (o) => view.getUint16(o, little),
    int: (o) => view.getInt32(o, little), int32: (o) => view.getInt32(o, little),
    uint: (o) => view.getUint32(o, little), uint32: (o) => view.getUint32(o, little),
    float: (o) => view.getFloat32(o, little), float32: (o) => view.getFloat32(o, little),
    double: (o) => view.getFloat64(o, little), float64: (o) => view.getFloat64(o, little),
  };
}

function parseHeader(bytes) {
  const probe = new TextDecoder('latin1').decode(bytes.subarray(0, Math.min(bytes.length, 65536)));
  const end = probe.indexOf('end_header');
  if (!probe.startsWith('ply') || end < 0) throw new Error('not a PLY file');
  const nl = probe.indexOf('\n', end);
  const lines = probe.slice(0, end).split(/\r?\n/);
  const header = { format: null, elements: [], bodyStart: nl + 1 };
  for (const line of lines) {
    const w = line.trim().split(/\s+/);
    if (w[0] === 'format') header.format = w[1];
    else if (w[0] === 'element') header.elements.push({ name: w[1], count: Number(w[2]), props: [] });
    else if (w[0] === 'property') {
      const el = header.elements[header.elements.length - 1];
      if (!el) throw new Error('PLY property before any element');
      if (w[1] === 'list') el.props.push({ list: true, countType: w[2], type: w[3], name: w[4] });
      else el.props.push({ list: false, type: w[1], name: w[2] });
    }
  }
  for (const el of header.elements) {
    for (const p of el.props) {
      if (!SIZES[p.type] || (p.list && !SIZES[p.countType])) {
        throw new Error(`PLY property type not supported: ${p.type}`);
      }
    }
  }
  return header;
}

/**
 * Parse `buffer` (ArrayBuffer) and return { positions: Float32Array (local = global − origin),
 * indices: Uint32Array (triangles) }.
 */
export function parsePly(buffer, origin) {
  const bytes = new Uint8Array(buffer);
  const header = parseHeader(bytes);
  if (header.format !== 'binary_little_endian' && header.format !== 'binary_big_endian') {
    throw new Error(`PLY format not supported: ${header.format}`);
  }
  const view = new DataView(buffer);
  const read = reader(view, header.format === 'binary_little_endian');
  let o = header.bodyStart;
  let positions = new Float32Array(0);
  const tris = [];
  for (const el of header.elements) {
    if (el.name === 'vertex') {
      positions = new Float32Array(3 * el.count);
      const axis = { x: 0, y: 1, z: 2 };
      for (let i = 0; i < el.count; i++) {
        for (const p of el.props) {
          if (p.list) {
            const n = read[p.countType](o);
            o += SIZES[p.countType] + n * SIZES[p.type];
            continue;
          }
          const a = axis[p.name];
          if (a !== undefined) positions[3 * i + a] = read[p.type](o) - origin[a];
          o += SIZES[p.type];
        }
      }
    } else if (el.name === 'face') {
      for (let i = 0; i < el.count; i++) {
        for (const p of el.props) {
          if (!p.list) { o += SIZES[p.type]; continue; }
          const n = read[p.countType](o);
          o += SIZES[p.countType];
          const sz = SIZES[p.type];
          if (p.name === 'vertex_indices' || p.name === 'vertex_index') {
            const first = read[p.type](o);
            for (let k = 1; k + 1 < n; k++) {
              tris.push(first, read[p.type](o + k * sz), read[p.type](o + (k + 1) * sz));
            }
          }
          o += n * sz;
        }
      }
    } else {
      // Skip elements we do not draw; their size needs each row's list counts.
      for (let i = 0; i < el.count; i++) {
        for (const p of el.props) {
          if (p.list) o += SIZES[p.countType] + read[p.countType](o) * SIZES[p.type];
          else o += SIZES[p.type];
        }
      }
    }
    if (o > bytes.length) throw new Error('PLY file is truncated');
  }
  const nv = positions.length / 3;
  for (const i of tris) if (!(i >= 0 && i < nv)) throw new Error('PLY face index out of range');
  return { positions, indices: Uint32Array.from(tris) };
}

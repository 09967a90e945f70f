//! The codec of format version 1: columns to bytes (byte-shuffled, quantised, zstd-compressed,
//! checksummed: [`encode`]) and back ([`Frame`], [`decode`]), straight into a larger tile's
//! columns when the encoding is one frame of a framed tile.

use super::format::{
    parse_header, Header, FLAG_SHUFFLE, KIND_F32, KIND_F64, KIND_QUANT, KIND_U32, KIND_U8, MAGIC,
    VERSION,
};
use super::{range, Bounds, Column, ColumnData, TileColumns, WriteOptions};

/// Encode columns into the bytes of a tile file (also a frame of a framed tile).
pub(crate) fn encode(cols: &TileColumns, opts: &WriteOptions) -> Result<Vec<u8>, String> {
    encode_with_bounds(cols, opts).map(|(bytes, _)| bytes)
}

/// [`encode`], and the bounds of the points.
pub(crate) fn encode_with_bounds(
    cols: &TileColumns,
    opts: &WriteOptions,
) -> Result<(Vec<u8>, Bounds), String> {
    if let Some(p) = cols.problem() {
        return Err(p);
    }
    let n = cols.len();
    // (name, kind, flags, quantisation (scale, offset, base), prepared bytes)
    type Spec = (String, u8, u8, Option<(f64, f64, i64)>, Vec<u8>);
    let flags = |kind: u8| {
        let on = match kind {
            KIND_F64 => opts.shuffle_f64,
            KIND_F32 => opts.shuffle_f32,
            _ => opts.shuffle_int,
        };
        if on && kind != KIND_U8 {
            FLAG_SHUFFLE
        } else {
            0
        }
    };
    let mut specs: Vec<Spec> = Vec::new();
    let mut b = Bounds {
        min: [f64::INFINITY; 3],
        max: [f64::NEG_INFINITY; 3],
    };
    for (axis, (name, v)) in [("x", &cols.x), ("y", &cols.y), ("z", &cols.z)]
        .into_iter()
        .enumerate()
    {
        let quant = opts.quantise.and_then(|q| {
            let (scale, offset) = (q.scale[axis], q.offset[axis]);
            quantise(v, scale, offset).map(|d| (scale, offset, d))
        });
        match quant {
            Some((scale, offset, (base, top, low))) => {
                let f = flags(KIND_QUANT);
                let raw = u32_bytes(&low, base as u32, f != 0);
                // Every value is scale·q + offset exactly, a map that rounding keeps monotone:
                // the bounds are those of the smallest and largest q.
                if !v.is_empty() {
                    b.min[axis] = scale * (base as f64) + offset;
                    b.max[axis] = scale * (top as f64) + offset;
                }
                specs.push((name.into(), KIND_QUANT, f, Some((scale, offset, base)), raw));
            }
            None => {
                let f = flags(KIND_F64);
                let raw = le_bytes(v.iter().map(|d| d.to_le_bytes()), f != 0);
                (b.min[axis], b.max[axis]) = range(v);
                specs.push((name.into(), KIND_F64, f, None, raw));
            }
        }
    }
    for c in &cols.extra {
        let (kind, raw) = match &c.data {
            ColumnData::F64(v) => {
                let f = flags(KIND_F64) != 0;
                (KIND_F64, le_bytes(v.iter().map(|d| d.to_le_bytes()), f))
            }
            ColumnData::F32(v) => {
                let f = flags(KIND_F32) != 0;
                (KIND_F32, le_bytes(v.iter().map(|d| d.to_le_bytes()), f))
            }
            ColumnData::U32(v) => {
                let f = flags(KIND_U32) != 0;
                (KIND_U32, u32_bytes(v, 0, f))
            }
            ColumnData::U8(v) => (KIND_U8, v.clone()),
        };
        specs.push((c.name.clone(), kind, flags(kind), None, raw));
    }

    let mut stored = Vec::with_capacity(specs.len());
    let mut header = Vec::with_capacity(128);
    header.extend_from_slice(MAGIC);
    header.extend_from_slice(&VERSION.to_le_bytes());
    header.extend_from_slice(&0u32.to_le_bytes()); // header_len, patched below
    header.extend_from_slice(&(n as u64).to_le_bytes());
    header.extend_from_slice(&(specs.len() as u32).to_le_bytes());
    for v in b.min.iter().chain(b.max.iter()) {
        header.extend_from_slice(&v.to_le_bytes());
    }
    let mut payload_crc = crc32fast::Hasher::new();
    let mut payload_len = 0u64;
    for (name, kind, flags, quant, prepared) in specs {
        let column = compress(&prepared, opts.level)?;
        drop(prepared);
        header.extend_from_slice(&(name.len() as u16).to_le_bytes());
        header.extend_from_slice(name.as_bytes());
        header.push(kind);
        header.push(flags);
        if let Some((scale, offset, base)) = quant {
            header.extend_from_slice(&scale.to_le_bytes());
            header.extend_from_slice(&offset.to_le_bytes());
            header.extend_from_slice(&base.to_le_bytes());
        }
        header.extend_from_slice(&(column.len() as u64).to_le_bytes());
        payload_crc.update(&column);
        payload_len += column.len() as u64;
        stored.push(column);
    }
    header.extend_from_slice(&payload_len.to_le_bytes());
    header.extend_from_slice(&payload_crc.finalize().to_le_bytes());
    let header_len = (header.len() + 4) as u32;
    header[12..16].copy_from_slice(&header_len.to_le_bytes());
    let header_crc = crc32fast::hash(&header);
    header.extend_from_slice(&header_crc.to_le_bytes());
    header.reserve_exact(payload_len as usize);
    for column in stored {
        header.extend_from_slice(&column);
    }
    Ok((header, b))
}

thread_local! {
    /// This thread's zstd contexts, kept between calls: creating one per column (a tile file
    /// holds 4 to 15) cost more than decompressing a small column.
    static COMPRESSOR: std::cell::RefCell<Option<(i32, zstd::bulk::Compressor<'static>)>> =
        const { std::cell::RefCell::new(None) };
    static DECOMPRESSOR: std::cell::RefCell<Option<zstd::bulk::Decompressor<'static>>> =
        const { std::cell::RefCell::new(None) };
}

/// `data` as one zstd frame at `level` (the same bytes as `zstd::bulk::compress`).
fn compress(data: &[u8], level: i32) -> Result<Vec<u8>, String> {
    COMPRESSOR.with(|c| {
        let mut c = c.borrow_mut();
        if c.as_ref().is_none_or(|(l, _)| *l != level) {
            let z = zstd::bulk::Compressor::new(level).map_err(|e| format!("zstd: {e}"))?;
            *c = Some((level, z));
        }
        let (_, z) = c.as_mut().ok_or("zstd: no compressor")?;
        z.compress(data)
            .map_err(|e| format!("zstd compression failed: {e}"))
    })
}

/// One zstd frame of at most `capacity` bytes, decompressed.
fn decompress(data: &[u8], capacity: usize) -> std::io::Result<Vec<u8>> {
    DECOMPRESSOR.with(|d| {
        let mut d = d.borrow_mut();
        if d.is_none() {
            *d = Some(zstd::bulk::Decompressor::new()?);
        }
        match d.as_mut() {
            Some(z) => z.decompress(data, capacity),
            None => Err(std::io::Error::other("no decompressor")),
        }
    })
}

/// `Some((smallest q, largest q, the low 32 bits of every q))` when every value is exactly
/// `scale·q + offset` and the span of the q fits u32 (then q − base is the wrapping difference
/// of the low bits).
pub(super) fn quantise(v: &[f64], scale: f64, offset: f64) -> Option<(i64, i64, Vec<u32>)> {
    if !(scale.is_finite() && scale > 0.0 && offset.is_finite()) {
        return None;
    }
    const LIMIT: f64 = (1u64 << 51) as f64;
    // Adding and taking away 1.5·2⁵² rounds to the nearest integer without a library call
    // (`round` is one on baseline x86-64) for |t| < 2⁵¹.
    const MAGIC: f64 = 6_755_399_441_055_744.0;
    let inverse = 1.0 / scale;
    let exact = |q: i64, x: f64| (scale * (q as f64) + offset).to_bits() == x.to_bits();
    let mut low = Vec::with_capacity(v.len());
    let (mut min, mut max) = (i64::MAX, i64::MIN);
    for &x in v {
        let t = (x - offset) * inverse;
        // Also rejects infinities.
        if t.is_nan() || t.abs() >= LIMIT {
            return None;
        }
        let mut q = ((t + MAGIC) - MAGIC) as i64;
        if !exact(q, x) {
            // The reciprocal's rounding can put t next to the integer rather than on it.
            q = [q - 1, q + 1].into_iter().find(|&q| exact(q, x))?;
        }
        min = min.min(q);
        max = max.max(q);
        low.push(q as u32);
    }
    if v.is_empty() {
        return Some((0, 0, low));
    }
    u32::try_from(max - min).ok()?;
    Some((min, max, low))
}

/// The little-endian bytes of `values − base` (wrapping), byte-shuffled when `shuffle` (byte `b`
/// of value `i` at `b·n + i`): four byte planes written in step, which the compiler vectorises.
fn u32_bytes(values: &[u32], base: u32, shuffle: bool) -> Vec<u8> {
    let n = values.len();
    let mut out = vec![0u8; 4 * n];
    if shuffle {
        let (p0, rest) = out.split_at_mut(n);
        let (p1, rest) = rest.split_at_mut(n);
        let (p2, p3) = rest.split_at_mut(n);
        for ((((v, a), b), c), d) in values.iter().zip(p0).zip(p1).zip(p2).zip(p3) {
            let v = v.wrapping_sub(base);
            (*a, *b, *c, *d) = (v as u8, (v >> 8) as u8, (v >> 16) as u8, (v >> 24) as u8);
        }
    } else {
        for (dst, v) in out.chunks_exact_mut(4).zip(values) {
            dst.copy_from_slice(&v.wrapping_sub(base).to_le_bytes());
        }
    }
    out
}

/// The `n` u32 values of `raw` (little-endian, shuffled or not; see [`u32_bytes`]), each
/// through `f`, into `out`.
fn u32_values_into<T>(raw: &[u8], n: usize, shuffled: bool, out: &mut [T], f: impl Fn(u32) -> T) {
    if shuffled {
        let (p0, rest) = raw.split_at(n);
        let (p1, rest) = rest.split_at(n);
        let (p2, p3) = rest.split_at(n);
        for ((((o, a), b), c), d) in out.iter_mut().zip(p0).zip(p1).zip(p2).zip(p3) {
            *o = f(u32::from_le_bytes([*a, *b, *c, *d]));
        }
    } else {
        for (o, b) in out.iter_mut().zip(raw.chunks_exact(4)) {
            *o = f(u32::from_le_bytes([b[0], b[1], b[2], b[3]]));
        }
    }
}

/// The type of a kind's values: f64 for f64 stored raw or quantised, else the kind's own.
fn value_type(kind: u8) -> u8 {
    match kind {
        KIND_QUANT => KIND_F64,
        k => k,
    }
}

fn kind_width(kind: u8) -> usize {
    match kind {
        KIND_F64 => 8,
        KIND_U8 => 1,
        _ => 4, // u32, f32 and quantised deltas
    }
}

/// The little-endian bytes of `values`, byte-shuffled Blosc-style when `shuffle` (byte `b` of
/// value `i` goes to `b·n + i`).
fn le_bytes<const W: usize>(
    values: impl ExactSizeIterator<Item = [u8; W]>,
    shuffle: bool,
) -> Vec<u8> {
    let n = values.len();
    let mut out = vec![0u8; n * W];
    if shuffle {
        // One output stream per byte position, written in step.
        let mut planes: Vec<&mut [u8]> = out.chunks_exact_mut(n.max(1)).collect();
        for (i, value) in values.enumerate() {
            for (plane, &byte) in planes.iter_mut().zip(value.iter()) {
                plane[i] = byte;
            }
        }
    } else {
        for (dst, value) in out.chunks_exact_mut(W).zip(values) {
            dst.copy_from_slice(&value);
        }
    }
    out
}

/// Value `i` of `n` little-endian values of `W` bytes, shuffled (byte `b` at `b·n + i`) or not.
#[inline]
fn value_bytes<const W: usize>(raw: &[u8], n: usize, i: usize, shuffled: bool) -> [u8; W] {
    let mut v = [0u8; W];
    if shuffled {
        for (b, byte) in v.iter_mut().enumerate() {
            *byte = raw[b * n + i];
        }
    } else {
        v.copy_from_slice(&raw[i * W..(i + 1) * W]);
    }
    v
}

/// Decode and verify a whole tile file held in memory.
pub(crate) fn decode(bytes: &[u8]) -> Result<TileColumns, String> {
    let frame = Frame::check(bytes)?;
    let mut out = frame.empty_columns(frame.len());
    frame.decode_into(&mut out.slices())?;
    Ok(out)
}

/// A version-1 encoding whose header and payload checksum were verified: its columns can be
/// decoded straight into their place in a larger tile ([`Frame::decode_into`]; a framed tile's
/// frames go each into its own range of the tile's columns, with no copy in between).
pub(crate) struct Frame<'a> {
    h: Header,
    payload: &'a [u8],
    len: usize,
}

impl<'a> Frame<'a> {
    /// Parse and verify `bytes`, one whole encoding.
    pub(crate) fn check(bytes: &'a [u8]) -> Result<Frame<'a>, String> {
        let h = parse_header(bytes)?;
        let total = (h.header_len as u64).checked_add(h.payload_len);
        match total {
            Some(t) if t == bytes.len() as u64 => {}
            Some(t) if t > bytes.len() as u64 => return Err("file is truncated".into()),
            _ => return Err("file is longer than its header says".into()),
        }
        let payload = &bytes[h.header_len..];
        if crc32fast::hash(payload) != h.payload_crc {
            return Err("payload checksum mismatch".into());
        }
        let len = usize::try_from(h.point_count).map_err(|_| "point count too large")?;
        for spec in &h.columns[..3] {
            if !matches!(spec.kind, KIND_F64 | KIND_QUANT) {
                return Err("coordinate column is not f64".into());
            }
        }
        Ok(Frame { h, payload, len })
    }

    /// Points held.
    pub(crate) fn len(&self) -> usize {
        self.len
    }

    /// Whether `other` holds the same columns (names and value types, in order).
    pub(crate) fn same_columns(&self, other: &Frame) -> bool {
        let (a, b) = (&self.h.columns, &other.h.columns);
        a.len() == b.len()
            && (a.iter().zip(b))
                .all(|(a, b)| a.name == b.name && value_type(a.kind) == value_type(b.kind))
    }

    /// The values of u32 column `name`, the other columns left compressed (a reader after
    /// the keys of many small files decodes a column of fifteen).
    pub(crate) fn u32_column(&self, name: &str) -> Result<Vec<u32>, String> {
        let (h, n) = (&self.h, self.len);
        let mut pos = 0usize;
        for spec in &h.columns {
            let len = usize::try_from(spec.stored_len).map_err(|_| "column too large")?;
            let end = pos
                .checked_add(len)
                .filter(|&e| e <= self.payload.len())
                .ok_or("column lengths exceed the payload")?;
            if spec.name != name {
                pos = end;
                continue;
            }
            if spec.kind != KIND_U32 {
                return Err(format!("column {name:?} is not u32"));
            }
            let raw_len = n.checked_mul(4).ok_or("point count too large")?;
            let raw = decompress(&self.payload[pos..end], raw_len)
                .map_err(|e| format!("column {name:?}: zstd: {e}"))?;
            if raw.len() != raw_len {
                return Err(format!(
                    "column {name:?} holds {} bytes, expected {raw_len}",
                    raw.len()
                ));
            }
            let mut out = vec![0u32; n];
            u32_values_into(&raw, n, spec.flags & FLAG_SHUFFLE != 0, &mut out, |q| q);
            return Ok(out);
        }
        Err(format!("no column {name:?}"))
    }

    /// Columns of this frame's names and types, `n` values each (zeroed: a large block comes
    /// from the system as zero pages, touched only when decoded into).
    pub(crate) fn empty_columns(&self, n: usize) -> TileColumns {
        let mut out = TileColumns {
            x: vec![0.0; n],
            y: vec![0.0; n],
            z: vec![0.0; n],
            extra: Vec::new(),
        };
        for spec in &self.h.columns[3..] {
            let data = match value_type(spec.kind) {
                KIND_F64 => ColumnData::F64(vec![0.0; n]),
                KIND_F32 => ColumnData::F32(vec![0.0; n]),
                KIND_U32 => ColumnData::U32(vec![0; n]),
                _ => ColumnData::U8(vec![0; n]),
            };
            out.extra.push(Column {
                name: spec.name.clone(),
                data,
            });
        }
        out
    }

    /// Decode every column into `out`, whose columns are this frame's ([`Frame::empty_columns`])
    /// and hold exactly [`Frame::len`] values each.
    pub(crate) fn decode_into(&self, out: &mut ColumnSlices) -> Result<(), String> {
        let (h, payload, n) = (&self.h, self.payload, self.len);
        if out.x.len() != n || out.extra.len() + 3 != h.columns.len() {
            return Err("a frame does not fit the columns it is decoded into".into());
        }
        let mut pos = 0usize;
        for (i, spec) in h.columns.iter().enumerate() {
            let len = usize::try_from(spec.stored_len).map_err(|_| "column too large")?;
            let end = pos
                .checked_add(len)
                .filter(|&e| e <= payload.len())
                .ok_or("column lengths exceed the payload")?;
            let width = kind_width(spec.kind);
            let raw_len = n.checked_mul(width).ok_or("point count too large")?;
            let raw = decompress(&payload[pos..end], raw_len)
                .map_err(|e| format!("column {:?}: zstd: {e}", spec.name))?;
            pos = end;
            if raw.len() != raw_len {
                return Err(format!(
                    "column {:?} holds {} bytes, expected {raw_len}",
                    spec.name,
                    raw.len()
                ));
            }
            let shuffled = spec.flags & FLAG_SHUFFLE != 0 && width > 1;
            let dest = match i {
                0 => SliceMut::F64(&mut *out.x),
                1 => SliceMut::F64(&mut *out.y),
                2 => SliceMut::F64(&mut *out.z),
                _ => out.extra[i - 3].reborrow(),
            };
            match (spec.kind, spec.quant, dest) {
                (KIND_QUANT, Some((scale, offset, base)), SliceMut::F64(d)) => {
                    u32_values_into(&raw, n, shuffled, d, |q| {
                        scale * ((base + i64::from(q)) as f64) + offset
                    })
                }
                (KIND_F64, _, SliceMut::F64(d)) => {
                    for (k, v) in d.iter_mut().enumerate() {
                        *v = f64::from_le_bytes(value_bytes(&raw, n, k, shuffled));
                    }
                }
                (KIND_F32, _, SliceMut::F32(d)) => {
                    for (k, v) in d.iter_mut().enumerate() {
                        *v = f32::from_le_bytes(value_bytes(&raw, n, k, shuffled));
                    }
                }
                (KIND_U32, _, SliceMut::U32(d)) => u32_values_into(&raw, n, shuffled, d, |q| q),
                (KIND_U8, _, SliceMut::U8(d)) => d.copy_from_slice(&raw),
                _ => {
                    return Err(format!(
                        "column {:?} changes kind between frames",
                        spec.name
                    ))
                }
            }
        }
        if pos != payload.len() {
            return Err("payload has bytes no column claims".into());
        }
        Ok(())
    }
}

/// Mutable views of a tile's columns (or of one range of them): where a frame is decoded.
pub(crate) struct ColumnSlices<'a> {
    pub(crate) x: &'a mut [f64],
    pub(crate) y: &'a mut [f64],
    pub(crate) z: &'a mut [f64],
    pub(crate) extra: Vec<SliceMut<'a>>,
}

impl<'a> ColumnSlices<'a> {
    /// The first `n` values of every column, and the rest.
    pub(crate) fn split_at(self, n: usize) -> (ColumnSlices<'a>, ColumnSlices<'a>) {
        let (x0, x1) = self.x.split_at_mut(n);
        let (y0, y1) = self.y.split_at_mut(n);
        let (z0, z1) = self.z.split_at_mut(n);
        let (e0, e1) = self.extra.into_iter().map(|c| c.split_at(n)).unzip();
        (
            ColumnSlices {
                x: x0,
                y: y0,
                z: z0,
                extra: e0,
            },
            ColumnSlices {
                x: x1,
                y: y1,
                z: z1,
                extra: e1,
            },
        )
    }
}

/// One extra column's values, mutable.
pub(crate) enum SliceMut<'a> {
    F64(&'a mut [f64]),
    F32(&'a mut [f32]),
    U32(&'a mut [u32]),
    U8(&'a mut [u8]),
}

impl<'a> SliceMut<'a> {
    fn reborrow(&mut self) -> SliceMut<'_> {
        match self {
            SliceMut::F64(v) => SliceMut::F64(v),
            SliceMut::F32(v) => SliceMut::F32(v),
            SliceMut::U32(v) => SliceMut::U32(v),
            SliceMut::U8(v) => SliceMut::U8(v),
        }
    }

    fn split_at(self, n: usize) -> (SliceMut<'a>, SliceMut<'a>) {
        match self {
            SliceMut::F64(v) => {
                let (a, b) = v.split_at_mut(n);
                (SliceMut::F64(a), SliceMut::F64(b))
            }
            SliceMut::F32(v) => {
                let (a, b) = v.split_at_mut(n);
                (SliceMut::F32(a), SliceMut::F32(b))
            }
            SliceMut::U32(v) => {
                let (a, b) = v.split_at_mut(n);
                (SliceMut::U32(a), SliceMut::U32(b))
            }
            SliceMut::U8(v) => {
                let (a, b) = v.split_at_mut(n);
                (SliceMut::U8(a), SliceMut::U8(b))
            }
        }
    }
}

impl TileColumns {
    /// Mutable views of every column.
    pub(crate) fn slices(&mut self) -> ColumnSlices<'_> {
        ColumnSlices {
            x: &mut self.x,
            y: &mut self.y,
            z: &mut self.z,
            extra: (self.extra.iter_mut())
                .map(|c| match &mut c.data {
                    ColumnData::F64(v) => SliceMut::F64(v),
                    ColumnData::F32(v) => SliceMut::F32(v),
                    ColumnData::U32(v) => SliceMut::U32(v),
                    ColumnData::U8(v) => SliceMut::U8(v),
                })
                .collect(),
        }
    }
}

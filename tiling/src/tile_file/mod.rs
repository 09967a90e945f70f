//! Compact immutable tile files: the points of one tile (with its halo) as compressed columns.
//!
//! Layout (all integers and floats little-endian; format version 1):
//!
//! ```text
//! magic        8 bytes  "TALUSTIL"
//! version      u32      1
//! header_len   u32      bytes from the start of the file to the payload
//! point_count  u64
//! column_count u32
//! bounds       6 × f64  min x, y, z, max x, y, z of the points (+inf/-inf when empty)
//! per column:  name_len u16, name (UTF-8), kind u8, flags u8,
//!              [kind 3 only: scale f64, offset f64, base i64], stored_len u64
//! payload_len  u64
//! payload_crc  u32      CRC-32 (IEEE) of the payload
//! header_crc   u32      CRC-32 of every header byte before it
//! payload      the columns' stored bytes, concatenated in header order
//! ```
//!
//! Column kinds: 0 = f64, 1 = u32, 2 = u8, 3 = f64 stored quantised (see [`Quantisation`]),
//! 4 = f32 (added within version 1: a file without it is byte for byte what it was, and a reader
//! that predates it refuses the kind by name rather than misreading it).
//! A column is stored as its little-endian bytes, byte-shuffled when flag bit 0 is set (byte `b`
//! of every value together, as in Blosc's shuffle filter, which lets zstd see the slowly varying
//! high bytes of integers as long runs), then zstd-compressed as one frame.
//!
//! Measured on 1M points of noisy terrain in scan order with LAS-style coordinates (mm lattice;
//! `examples/measure.rs`), bytes per point for x, y, z at zstd level 1: f64 9.9, f64 shuffled
//! 12.7, quantised 6.6, quantised shuffled 3.7 (the defaults: f64 unshuffled, integers shuffled).
//!
//! Files are written atomically (temporary sibling, fsync, rename; see [`crate::atomic`]) and read
//! in full with every check: magic, version, header CRC, exact file length, payload CRC, and each
//! column's decompressed length. Any failure is [`Error::Corrupt`](crate::Error::Corrupt) so the
//! caller rebuilds the tile.
//!
//! Format version 2 ([`crate::framed`]) is a tile written in frames, each frame one encoding of
//! this format; [`read_tile`] and [`read_tile_header`] read both versions.
//!
//! The module's rooms: `format.rs` (version 1's header layout), `codec.rs` (columns to bytes and
//! back), [`framed`] (version 2), `read.rs` and `write.rs`.

mod codec;
mod format;
pub mod framed;
mod read;
mod write;

pub(crate) use codec::{encode_with_bounds, Frame};
pub(crate) use format::{encoded_len, Cursor};
pub use format::{MAGIC, VERSION};
pub use read::{read_tile, read_tile_frames, read_tile_header, read_u32_columns, TileFrames};
use talus_base::geom::Bounds;
pub use write::{encode_tile, write_tile, write_tile_with};
#[cfg(test)]
use {
    crate::error::Error,
    codec::{decode, encode},
    format::{parse_header, KIND_QUANT},
};

/// Values of one column.
#[derive(Clone, Debug, PartialEq)]
pub enum ColumnData {
    F64(Vec<f64>),
    F32(Vec<f32>),
    U32(Vec<u32>),
    U8(Vec<u8>),
}

impl ColumnData {
    /// Number of values.
    pub fn len(&self) -> usize {
        match self {
            ColumnData::F64(v) => v.len(),
            ColumnData::F32(v) => v.len(),
            ColumnData::U32(v) => v.len(),
            ColumnData::U8(v) => v.len(),
        }
    }
    /// True when the column holds no values.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

/// A named extra column.
#[derive(Clone, Debug, PartialEq)]
pub struct Column {
    pub name: String,
    pub data: ColumnData,
}

/// The points of one tile: coordinates plus optional extra columns of the same length.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct TileColumns {
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub z: Vec<f64>,
    pub extra: Vec<Column>,
}

impl TileColumns {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.x.len()
    }
    /// True when there are no points.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }
    /// The extra column called `name`.
    pub fn column(&self, name: &str) -> Option<&ColumnData> {
        self.extra.iter().find(|c| c.name == name).map(|c| &c.data)
    }
    /// Bounds of the coordinates (`min = +inf`, `max = -inf` when empty; NaNs are ignored).
    pub fn bounds(&self) -> Bounds {
        let mut b = Bounds {
            min: [f64::INFINITY; 3],
            max: [f64::NEG_INFINITY; 3],
        };
        for (axis, col) in [&self.x, &self.y, &self.z].into_iter().enumerate() {
            (b.min[axis], b.max[axis]) = range(col);
        }
        b
    }
    /// Why the columns cannot be written, if they cannot.
    fn problem(&self) -> Option<String> {
        let n = self.x.len();
        if self.y.len() != n || self.z.len() != n {
            return Some(format!(
                "x, y, z have different lengths ({}, {}, {})",
                n,
                self.y.len(),
                self.z.len()
            ));
        }
        for (i, c) in self.extra.iter().enumerate() {
            if c.data.len() != n {
                return Some(format!(
                    "column {:?} has {} values, not {n}",
                    c.name,
                    c.data.len()
                ));
            }
            if c.name.len() > usize::from(u16::MAX) || ["x", "y", "z"].contains(&c.name.as_str()) {
                return Some(format!("column name {:?} is reserved or too long", c.name));
            }
            if self.extra[..i].iter().any(|d| d.name == c.name) {
                return Some(format!("column {:?} appears twice", c.name));
            }
        }
        None
    }
}

/// The smallest and largest of `v`, NaNs ignored (+inf/−inf when none). Written as comparisons
/// that a NaN fails rather than with `f64::min`, whose NaN rule keeps the compiler from using
/// vector instructions (the bounds took a quarter of encoding a tile).
fn range(v: &[f64]) -> (f64, f64) {
    const LANES: usize = 8;
    let (mut lo, mut hi) = ([f64::INFINITY; LANES], [f64::NEG_INFINITY; LANES]);
    let mut chunks = v.chunks_exact(LANES);
    for c in &mut chunks {
        for k in 0..LANES {
            lo[k] = if c[k] < lo[k] { c[k] } else { lo[k] };
            hi[k] = if c[k] > hi[k] { c[k] } else { hi[k] };
        }
    }
    let (mut a, mut b) = (f64::INFINITY, f64::NEG_INFINITY);
    for &x in chunks.remainder().iter().chain(&lo) {
        a = if x < a { x } else { a };
    }
    for &x in chunks.remainder().iter().chain(&hi) {
        b = if x > b { x } else { b };
    }
    (a, b)
}

/// Quantised storage of x, y, z: each value is stored as the integer `q` with
/// `value == scale * (q as f64) + offset` **bit for bit** (the exact expression the `las` crate
/// uses to turn LAS integers into coordinates), as an unsigned offset from the column's smallest
/// `q`. Pass the input LAS file's own scale and offset and coordinates read from it are stored
/// exactly. Any column where one value does not round-trip bit-exactly (another transform, NaN,
/// a span over 2³² steps) is stored as plain f64 instead, so this option is never lossy.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Quantisation {
    pub scale: [f64; 3],
    pub offset: [f64; 3],
}

/// How a tile is written.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct WriteOptions {
    /// zstd level. 1 is the default: on the terrain sample of `examples/measure.rs` level 3 saves
    /// under 1 % with quantised coordinates (3.69 vs 3.72 B/point) and ~10 % with f64 ones, at up
    /// to twice the write time.
    pub level: i32,
    /// Byte-shuffle f64 columns. Off by default: on LAS-derived coordinates it hurts (12.7 vs
    /// 9.9 B/point measured), because the decimal lattice repeats multi-byte patterns that zstd
    /// matches only when the bytes of a value stay together.
    pub shuffle_f64: bool,
    /// Byte-shuffle f32 columns. On by default: f32 columns hold measured quantities (M3C2
    /// distances, spreads, normals), not lattice values, and their sign and exponent bytes
    /// vary slowly from value to value.
    pub shuffle_f32: bool,
    /// Byte-shuffle u32 and quantised columns. On by default: 3.7 instead of 6.6 B/point on the
    /// same sample (the high bytes of neighbouring integers are equal).
    pub shuffle_int: bool,
    /// Store coordinates quantised when that is exact.
    pub quantise: Option<Quantisation>,
}

impl Default for WriteOptions {
    fn default() -> Self {
        WriteOptions {
            level: 1,
            shuffle_f64: false,
            shuffle_f32: true,
            shuffle_int: true,
            quantise: None,
        }
    }
}

/// What a tile file's header says.
#[derive(Clone, Debug, PartialEq)]
pub struct TileHeader {
    pub version: u32,
    pub point_count: u64,
    pub bounds: Bounds,
    /// Column names, `x`, `y`, `z` first.
    pub columns: Vec<String>,
}

/// What a writer knows of the file it wrote: its size and the CRC-32 (IEEE) of all its bytes,
/// computed from the bytes in memory (so a record of the file needs no read back).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct FileDigest {
    pub size: u64,
    pub crc32: u32,
}

impl FileDigest {
    /// The digest of `bytes`.
    pub fn of(bytes: &[u8]) -> Self {
        FileDigest {
            size: bytes.len() as u64,
            crc32: crc32fast::hash(bytes),
        }
    }
}

#[cfg(test)]
mod tests;

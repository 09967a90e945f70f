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
//! Column kinds: 0 = f64, 1 = u32, 2 = u8, 3 = f64 stored quantised (see [`Quantisation`]).
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
//! column's decompressed length. Any failure is [`Error::Corrupt`] so the caller rebuilds the tile.
//!
//! Format version 2 ([`crate::framed`]) is a tile written in frames, each frame one encoding of
//! this format; [`read_tile`] and [`read_tile_header`] read both versions.

use crate::atomic::atomic_write;
use crate::error::{Error, Result};
use std::fs::File;
use std::io::{Read, Seek};
use std::path::Path;

/// File signature.
pub const MAGIC: &[u8; 8] = b"TALUSTIL";
/// Current format version.
pub const VERSION: u32 = 1;

/// Values of one column.
#[derive(Clone, Debug, PartialEq)]
pub enum ColumnData {
    F64(Vec<f64>),
    U32(Vec<u32>),
    U8(Vec<u8>),
}

impl ColumnData {
    /// Number of values.
    pub fn len(&self) -> usize {
        match self {
            ColumnData::F64(v) => v.len(),
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
    pub fn bounds(&self) -> Bounds3 {
        let mut b = Bounds3 {
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

/// Axis-aligned 3D bounds.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Bounds3 {
    pub min: [f64; 3],
    pub max: [f64; 3],
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
            shuffle_int: true,
            quantise: None,
        }
    }
}

const KIND_F64: u8 = 0;
const KIND_U32: u8 = 1;
const KIND_U8: u8 = 2;
const KIND_QUANT: u8 = 3;
const FLAG_SHUFFLE: u8 = 1;

/// What a tile file's header says.
#[derive(Clone, Debug, PartialEq)]
pub struct TileHeader {
    pub version: u32,
    pub point_count: u64,
    pub bounds: Bounds3,
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

/// Write `cols` to `path` atomically with the default [`WriteOptions`].
pub fn write_tile(path: &Path, cols: &TileColumns) -> Result<FileDigest> {
    write_tile_with(path, cols, &WriteOptions::default())
}

/// Write `cols` to `path` atomically; returns the written file's digest.
pub fn write_tile_with(path: &Path, cols: &TileColumns, opts: &WriteOptions) -> Result<FileDigest> {
    let bytes = encode(cols, opts).map_err(|p| Error::invalid(path, p))?;
    atomic_write(path, &bytes)?;
    Ok(FileDigest::of(&bytes))
}

/// The bytes of a tile file holding `cols` (what [`write_tile_with`] writes), for a caller that
/// writes the file itself (into a directory it makes durable as a whole, say); the error names
/// what is wrong with the columns.
pub fn encode_tile(cols: &TileColumns, opts: &WriteOptions) -> Result<Vec<u8>, String> {
    encode(cols, opts)
}

/// Read and verify a tile file.
pub fn read_tile(path: &Path) -> Result<TileColumns> {
    let mut bytes = Vec::new();
    File::open(path)
        .and_then(|mut f| f.read_to_end(&mut bytes))
        .map_err(|e| Error::io(path, e))?;
    let decoded = match check_magic_version(&bytes, &[VERSION, crate::framed::VERSION]) {
        Ok(crate::framed::VERSION) => crate::framed::decode(&bytes),
        Ok(_) => decode(&bytes),
        Err(e) => Err(e),
    };
    decoded.map_err(|reason| Error::corrupt(path, reason))
}

/// Read and verify a tile file a frame at a time: `f` gets each frame's columns in order (a
/// version-1 file is one frame), so a reader that keeps only some points holds one frame's
/// worth, not the tile's. Damage anywhere is an error, as with [`read_tile`]; `f` may have seen
/// the frames before the damaged one.
pub fn read_tile_frames(path: &Path, mut f: impl FnMut(TileColumns) -> Result<()>) -> Result<()> {
    let mut frames = TileFrames::open(path)?;
    while let Some(cols) = frames.next_frame()? {
        f(cols)?;
    }
    Ok(())
}

/// A tile file read a frame at a time by a reader that pulls (one that walks another sorted
/// stream beside it); [`read_tile_frames`] is the same for one that is pushed to. Holds one
/// frame's bytes and columns at a time.
#[derive(Debug)]
pub struct TileFrames {
    path: std::path::PathBuf,
    file: File,
    /// A version-1 file: its one frame, until taken.
    whole: Option<TileColumns>,
    /// Every frame given (and a framed file's end checked).
    done: bool,
    /// Frames in the file, and the next to read.
    frames: u32,
    next: u32,
    /// Points read so far, and the header's count.
    points: u64,
    expected: u64,
    bytes: Vec<u8>,
}

impl TileFrames {
    /// Open `path` and read its header.
    pub fn open(path: &Path) -> Result<TileFrames> {
        let mut file = File::open(path).map_err(|e| Error::io(path, e))?;
        let mut fixed = [0u8; 16];
        read_exact_or_corrupt(&mut file, &mut fixed, path)?;
        let version = check_magic_version(&fixed, &[VERSION, crate::framed::VERSION])
            .map_err(|r| Error::corrupt(path, r))?;
        let mut frames = TileFrames {
            path: path.to_path_buf(),
            file,
            whole: None,
            done: false,
            frames: 0,
            next: 0,
            points: 0,
            expected: 0,
            bytes: Vec::new(),
        };
        if version == VERSION {
            let whole = read_tile(path)?;
            frames.expected = whole.len() as u64;
            frames.whole = Some(whole);
            return Ok(frames);
        }
        let mut head = fixed.to_vec();
        head.resize(crate::framed::HEADER_LEN, 0);
        read_exact_or_corrupt(&mut frames.file, &mut head[16..], path)?;
        let h = crate::framed::parse_header(&head).map_err(|r| Error::corrupt(path, r))?;
        frames.frames = h.frames;
        frames.expected = h.point_count;
        Ok(frames)
    }

    /// Points in the file (the header's count).
    pub fn point_count(&self) -> u64 {
        self.expected
    }

    /// The next frame's columns; None after the last (the file's length and count checked).
    pub fn next_frame(&mut self) -> Result<Option<TileColumns>> {
        self.next_frame_where(&|_| true)
    }

    /// The next frame whose bounds `want` accepts; the frames before it that it does not accept
    /// are passed over unread (their points counted from their headers, their payloads neither
    /// decoded nor checked). A version-1 file's one frame is always given. A reader that needs
    /// only the points in some boxes reads only the frames that reach them: a tile's frames hold
    /// its points in the survey's order, which on real and synthetic files alike is a scan's
    /// or a grid's, so a frame covers a strip of the tile, not all of it.
    pub fn next_frame_where(
        &mut self,
        want: &dyn Fn(&Bounds3) -> bool,
    ) -> Result<Option<TileColumns>> {
        if let Some(whole) = self.whole.take() {
            self.done = true;
            return Ok(Some(whole));
        }
        loop {
            if self.done {
                return Ok(None);
            }
            if self.next == self.frames {
                self.done = true;
                return self.check_end().map(|()| None);
            }
            let mut fixed = [0u8; 16];
            read_exact_or_corrupt(&mut self.file, &mut fixed, &self.path)?;
            let fh = read_v1_header(&mut self.file, &self.path, fixed)?;
            if want(&fh.bounds) {
                return self.rest_of_frame(fixed, &fh).map(Some);
            }
            let skip = i64::try_from(fh.payload_len).map_err(|_| {
                Error::corrupt(
                    &self.path,
                    format!("frame {}: payload too large", self.next),
                )
            })?;
            self.file
                .seek(std::io::SeekFrom::Current(skip))
                .map_err(|e| Error::io(&self.path, e))?;
            self.points += fh.point_count;
            self.next += 1;
        }
    }

    /// The frame whose first 16 bytes are `fixed` and header `fh` (read, the file just past it).
    fn rest_of_frame(&mut self, fixed: [u8; 16], fh: &Header) -> Result<TileColumns> {
        let path = self.path.as_path();
        let k = self.next;
        let len = (fh.header_len as u64)
            .checked_add(fh.payload_len)
            .and_then(|l| usize::try_from(l).ok())
            .ok_or_else(|| Error::corrupt(path, format!("frame {k}: payload length too large")))?;
        self.bytes.clear();
        self.bytes.extend_from_slice(&fixed);
        self.bytes.resize(len, 0);
        // Back to the frame's start (the header was read to learn the length), then all of it.
        self.file
            .seek(std::io::SeekFrom::Current(-(fh.header_len as i64 - 16)))
            .map_err(|e| Error::io(path, e))?;
        read_exact_or_corrupt(&mut self.file, &mut self.bytes[16..], path)?;
        let cols =
            decode(&self.bytes).map_err(|r| Error::corrupt(path, format!("frame {k}: {r}")))?;
        self.points += cols.len() as u64;
        self.next += 1;
        Ok(cols)
    }

    /// After the last frame of a framed file: nothing beyond it, and the header's count read
    /// (a version-1 file was checked whole when read, and never gets here).
    fn check_end(&mut self) -> Result<()> {
        let path = self.path.as_path();
        // Where the frames end against the file's length: frames passed over were sought
        // past, not read, so a cut in one shows only here.
        let at = self
            .file
            .stream_position()
            .map_err(|e| Error::io(path, e))?;
        let len = self.file.metadata().map_err(|e| Error::io(path, e))?.len();
        if at != len {
            return Err(Error::corrupt(
                path,
                if at > len {
                    "file is truncated"
                } else {
                    "file is longer than its frames"
                },
            ));
        }
        if self.points != self.expected {
            return Err(Error::corrupt(
                path,
                format!(
                    "frames hold {} points, the header says {}",
                    self.points, self.expected
                ),
            ));
        }
        Ok(())
    }
}

/// Read and verify only a tile file's header (count, bounds, column names).
pub fn read_tile_header(path: &Path) -> Result<TileHeader> {
    let mut f = File::open(path).map_err(|e| Error::io(path, e))?;
    let mut fixed = [0u8; 16];
    read_exact_or_corrupt(&mut f, &mut fixed, path)?;
    let version = check_magic_version(&fixed, &[VERSION, crate::framed::VERSION])
        .map_err(|r| Error::corrupt(path, r))?;
    if version == VERSION {
        let h = read_v1_header(&mut f, path, fixed)?;
        return Ok(TileHeader {
            version,
            point_count: h.point_count,
            bounds: h.bounds,
            columns: h.columns.into_iter().map(|c| c.name).collect(),
        });
    }
    // The framed header, then its first frame's (a version-1 header) for the column names.
    let mut head = fixed.to_vec();
    head.resize(crate::framed::HEADER_LEN, 0);
    read_exact_or_corrupt(&mut f, &mut head[16..], path)?;
    let h = crate::framed::parse_header(&head).map_err(|r| Error::corrupt(path, r))?;
    read_exact_or_corrupt(&mut f, &mut fixed, path)?;
    let first = read_v1_header(&mut f, path, fixed)?;
    Ok(TileHeader {
        version,
        point_count: h.point_count,
        bounds: h.bounds,
        columns: first.columns.into_iter().map(|c| c.name).collect(),
    })
}

/// The version-1 header whose first 16 bytes are `fixed`, the rest read from `f`.
fn read_v1_header(f: &mut File, path: &Path, fixed: [u8; 16]) -> Result<Header> {
    let header_len = u32::from_le_bytes([fixed[12], fixed[13], fixed[14], fixed[15]]) as usize;
    if !(16..=1 << 24).contains(&header_len) {
        return Err(Error::corrupt(
            path,
            format!("implausible header length {header_len}"),
        ));
    }
    let mut head = fixed.to_vec();
    head.resize(header_len, 0);
    read_exact_or_corrupt(f, &mut head[16..], path)?;
    parse_header(&head).map_err(|r| Error::corrupt(path, r))
}

fn read_exact_or_corrupt(f: &mut File, buf: &mut [u8], path: &Path) -> Result<()> {
    f.read_exact(buf).map_err(|e| {
        if e.kind() == std::io::ErrorKind::UnexpectedEof {
            Error::corrupt(path, "file is truncated")
        } else {
            Error::io(path, e)
        }
    })
}

/// Encode columns into the bytes of a tile file (also a frame of a framed tile).
pub(crate) fn encode(cols: &TileColumns, opts: &WriteOptions) -> Result<Vec<u8>, String> {
    encode_with_bounds(cols, opts).map(|(bytes, _)| bytes)
}

/// [`encode`], and the bounds of the points.
pub(crate) fn encode_with_bounds(
    cols: &TileColumns,
    opts: &WriteOptions,
) -> Result<(Vec<u8>, Bounds3), String> {
    if let Some(p) = cols.problem() {
        return Err(p);
    }
    let n = cols.len();
    // (name, kind, flags, quantisation (scale, offset, base), prepared bytes)
    type Spec = (String, u8, u8, Option<(f64, f64, i64)>, Vec<u8>);
    let flags = |kind: u8| {
        let on = if kind == KIND_F64 {
            opts.shuffle_f64
        } else {
            opts.shuffle_int
        };
        if on && kind != KIND_U8 {
            FLAG_SHUFFLE
        } else {
            0
        }
    };
    let mut specs: Vec<Spec> = Vec::new();
    let mut b = Bounds3 {
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

/// The length of the version-1 encoding at the start of `bytes` (its header checked).
pub(crate) fn encoded_len(bytes: &[u8]) -> Result<usize, String> {
    let h = parse_header(bytes)?;
    let len = (h.header_len as u64)
        .checked_add(h.payload_len)
        .ok_or("payload length too large")?;
    if len > bytes.len() as u64 {
        return Err("file is truncated".into());
    }
    Ok(len as usize)
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
fn quantise(v: &[f64], scale: f64, offset: f64) -> Option<(i64, i64, Vec<u32>)> {
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

/// The type of a kind's values: 8 for f64 (stored raw or quantised), 4 for u32, 1 for u8.
fn value_width(kind: u8) -> usize {
    match kind {
        KIND_F64 | KIND_QUANT => 8,
        KIND_U32 => 4,
        _ => 1,
    }
}

fn kind_width(kind: u8) -> usize {
    match kind {
        KIND_F64 => 8,
        KIND_U8 => 1,
        _ => 4, // u32 and quantised deltas
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

struct ColumnSpec {
    name: String,
    kind: u8,
    flags: u8,
    quant: Option<(f64, f64, i64)>,
    stored_len: u64,
}

struct Header {
    header_len: usize,
    point_count: u64,
    bounds: Bounds3,
    columns: Vec<ColumnSpec>,
    payload_len: u64,
    payload_crc: u32,
}

/// Bounds-checked little-endian reader; running out of bytes means the file is truncated.
pub(crate) struct Cursor<'a> {
    pub(crate) bytes: &'a [u8],
    pub(crate) pos: usize,
}

impl<'a> Cursor<'a> {
    pub(crate) fn take(&mut self, n: usize) -> Result<&'a [u8], String> {
        let end = self.pos.checked_add(n).filter(|&e| e <= self.bytes.len());
        match end {
            Some(end) => {
                let s = &self.bytes[self.pos..end];
                self.pos = end;
                Ok(s)
            }
            None => Err("file is truncated".into()),
        }
    }
    pub(crate) fn array<const N: usize>(&mut self) -> Result<[u8; N], String> {
        let mut a = [0u8; N];
        a.copy_from_slice(self.take(N)?);
        Ok(a)
    }
    pub(crate) fn u8(&mut self) -> Result<u8, String> {
        Ok(self.take(1)?[0])
    }
    pub(crate) fn u16(&mut self) -> Result<u16, String> {
        Ok(u16::from_le_bytes(self.array()?))
    }
    pub(crate) fn u32(&mut self) -> Result<u32, String> {
        Ok(u32::from_le_bytes(self.array()?))
    }
    pub(crate) fn u64(&mut self) -> Result<u64, String> {
        Ok(u64::from_le_bytes(self.array()?))
    }
    pub(crate) fn f64(&mut self) -> Result<f64, String> {
        Ok(f64::from_le_bytes(self.array()?))
    }
}

/// Check a tile file's magic and that its format version is one of `allowed`; the version.
fn check_magic_version(fixed: &[u8], allowed: &[u32]) -> Result<u32, String> {
    if fixed.len() < 12 {
        return Err("file is truncated".into());
    }
    if &fixed[..8] != MAGIC {
        return Err("bad magic (not a talus tile file)".into());
    }
    let version = u32::from_le_bytes([fixed[8], fixed[9], fixed[10], fixed[11]]);
    if !allowed.contains(&version) {
        let expected: Vec<String> = allowed.iter().map(|v| v.to_string()).collect();
        return Err(format!(
            "unsupported format version {version} (expected {})",
            expected.join(" or ")
        ));
    }
    Ok(version)
}

/// Parse and CRC-check the header at the start of `bytes`.
fn parse_header(bytes: &[u8]) -> Result<Header, String> {
    check_magic_version(bytes, &[VERSION])?;
    let mut c = Cursor { bytes, pos: 12 };
    let header_len = c.u32()? as usize;
    if header_len < 16 + 4 || header_len > bytes.len() {
        return Err("file is truncated or header length is wrong".into());
    }
    let stored_crc = u32::from_le_bytes(
        bytes[header_len - 4..header_len]
            .try_into()
            .map_err(|_| "header length is wrong".to_string())?,
    );
    if crc32fast::hash(&bytes[..header_len - 4]) != stored_crc {
        return Err("header checksum mismatch".into());
    }
    let point_count = c.u64()?;
    let ncols = c.u32()?;
    let mut bounds = Bounds3 {
        min: [0.0; 3],
        max: [0.0; 3],
    };
    for v in bounds.min.iter_mut().chain(bounds.max.iter_mut()) {
        *v = c.f64()?;
    }
    let mut columns = Vec::new();
    for _ in 0..ncols {
        let name_len = usize::from(c.u16()?);
        let name = String::from_utf8(c.take(name_len)?.to_vec())
            .map_err(|_| "column name is not UTF-8".to_string())?;
        let kind = c.u8()?;
        if kind > KIND_QUANT {
            return Err(format!("unknown column kind {kind}"));
        }
        let flags = c.u8()?;
        let quant = if kind == KIND_QUANT {
            Some((c.f64()?, c.f64()?, i64::from_le_bytes(c.array()?)))
        } else {
            None
        };
        let stored_len = c.u64()?;
        columns.push(ColumnSpec {
            name,
            kind,
            flags,
            quant,
            stored_len,
        });
    }
    let payload_len = c.u64()?;
    let payload_crc = c.u32()?;
    if c.pos + 4 != header_len {
        return Err("header length does not match its content".into());
    }
    let names: Vec<&str> = columns.iter().take(3).map(|c| c.name.as_str()).collect();
    if names != ["x", "y", "z"] {
        return Err("the first columns are not x, y, z".into());
    }
    Ok(Header {
        header_len,
        point_count,
        bounds,
        columns,
        payload_len,
        payload_crc,
    })
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
                .all(|(a, b)| a.name == b.name && value_width(a.kind) == value_width(b.kind))
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
            let data = match value_width(spec.kind) {
                8 => ColumnData::F64(vec![0.0; n]),
                4 => ColumnData::U32(vec![0; n]),
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
    U32(&'a mut [u32]),
    U8(&'a mut [u8]),
}

impl<'a> SliceMut<'a> {
    fn reborrow(&mut self) -> SliceMut<'_> {
        match self {
            SliceMut::F64(v) => SliceMut::F64(v),
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
                    ColumnData::U32(v) => SliceMut::U32(v),
                    ColumnData::U8(v) => SliceMut::U8(v),
                })
                .collect(),
        }
    }
}

#[cfg(test)]
mod tests;

//! Streaming split of an epoch into tile files with halos, in bounded memory (SPEC.md §3, pass 1).
//!
//! Each pushed point goes to every tile whose halo box contains it ([`TileGrid::tiles_touching`]),
//! with an `owned` column (1 in the tile that owns it, 0 where it is only halo). Points wait in
//! per-tile column buffers; when the buffers' allocated bytes exceed the budget, the largest
//! buffers are appended as compressed chunks to per-tile segment files until the buffers use at
//! most half the budget (the hysteresis keeps flushes large). [`TileSplitter::finish`] then
//! builds each tile file from its segment chunks followed by its remaining buffer, one tile at a
//! time, and deletes the segments.
//!
//! Determinism: a tile's points are always flushed all together and chunks are appended in
//! order, so a tile file holds its points in input order, whatever the chunk sizes of `push`, the
//! budget or the flush order.
//!
//! Memory: the buffers' allocated capacity (not just their length) is counted against the budget;
//! a buffer grows by half its size (at least 64 points), so the count overshoots the budget by at
//! most one growth step. `finish` holds at most one tile's points plus the remaining buffers.

use crate::error::{Error, Result};
use crate::grid::{TileGrid, TileId};
use crate::tile_file::{self, Column, ColumnData, FileDigest, TileColumns, WriteOptions};
use std::fs::{self, OpenOptions};
use std::io::{Read, Write};
use std::path::{Path, PathBuf};

/// Name of the per-point ownership column in tile files (u8: 1 owned, 0 halo).
pub const OWNED_COLUMN: &str = "owned";
/// Bytes one buffered point takes: x, y, z as f64 plus the owned flag.
const BYTES_PER_POINT: u64 = 3 * 8 + 1;
/// Smallest buffer growth, in points.
const MIN_GROWTH: usize = 64;

/// Where the tile `id` of a split lives.
pub fn tile_path(dir: &Path, id: TileId) -> PathBuf {
    dir.join(format!("{}.tile", id.name()))
}

#[derive(Default)]
struct Buffer {
    x: Vec<f64>,
    y: Vec<f64>,
    z: Vec<f64>,
    owned: Vec<u8>,
}

impl Buffer {
    fn capacity_bytes(&self) -> u64 {
        self.x.capacity() as u64 * BYTES_PER_POINT
    }
}

/// Splits a stream of points into the tiles of a grid, on disk.
pub struct TileSplitter {
    dir: PathBuf,
    seg_dir: PathBuf,
    grid: TileGrid,
    halo: f64,
    budget: u64,
    opts: WriteOptions,
    /// One buffer per tile, indexed by [`TileGrid::index`].
    buffers: Vec<Buffer>,
    buffered_bytes: u64,
    /// Points already appended to each tile's segment file.
    flushed: Vec<u64>,
}

impl TileSplitter {
    /// A splitter writing tile files `<dir>/t_CCCC_RRRR.tile`, with `memory_budget_bytes` for its
    /// buffers. `dir` belongs to the splitter: it is created if missing, and tile files and
    /// segments left there by an earlier (interrupted) split are removed first, so they can never
    /// be mistaken for this split's output.
    pub fn new(dir: &Path, grid: TileGrid, halo: f64, memory_budget_bytes: u64) -> Result<Self> {
        if !(halo.is_finite() && halo >= 0.0) {
            return Err(Error::Parameter {
                what: "halo",
                problem: format!("must be finite and ≥ 0, got {halo}"),
            });
        }
        fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        let seg_dir = dir.join("segments");
        if seg_dir.exists() {
            fs::remove_dir_all(&seg_dir).map_err(|e| Error::io(&seg_dir, e))?;
        }
        for entry in fs::read_dir(dir).map_err(|e| Error::io(dir, e))? {
            let path = entry.map_err(|e| Error::io(dir, e))?.path();
            let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
            if name.starts_with("t_") && (name.ends_with(".tile") || name.ends_with(".tile.tmp")) {
                fs::remove_file(&path).map_err(|e| Error::io(&path, e))?;
            }
        }
        fs::create_dir_all(&seg_dir).map_err(|e| Error::io(&seg_dir, e))?;
        let n = grid.len();
        Ok(TileSplitter {
            dir: dir.to_path_buf(),
            seg_dir,
            grid,
            halo,
            budget: memory_budget_bytes,
            opts: WriteOptions::default(),
            buffers: (0..n).map(|_| Buffer::default()).collect(),
            buffered_bytes: 0,
            flushed: vec![0; n],
        })
    }

    /// Use these options for the final tile files (e.g. quantised coordinates).
    pub fn with_options(mut self, opts: WriteOptions) -> Self {
        self.opts = opts;
        self
    }

    /// Use these options from now on (for the segments and the final tile files).
    pub fn set_options(&mut self, opts: WriteOptions) {
        self.opts = opts;
    }

    /// The grid being split into.
    pub fn grid(&self) -> &TileGrid {
        &self.grid
    }

    /// Bytes currently allocated by the buffers (what the budget bounds).
    pub fn buffered_bytes(&self) -> u64 {
        self.buffered_bytes
    }

    /// Route points to their tiles (in order), flushing buffers to segments when over budget.
    /// Points outside the grid go where [`TileGrid::owner`] clamps them (NaN x or y counts as the
    /// grid's min edge); callers should drop non-finite points before pushing.
    pub fn push(&mut self, points: &[[f64; 3]]) -> Result<()> {
        let rows = self.grid.rows() as usize;
        for p in points {
            let owner = self.grid.owner(p[0], p[1]);
            let [(c0, c1), (r0, r1)] = self.grid.touching_ranges(p[0], p[1], self.halo);
            for col in c0..=c1 {
                for row in r0..=r1 {
                    let i = col as usize * rows + row as usize;
                    let b = &mut self.buffers[i];
                    if b.x.len() == b.x.capacity() {
                        let before = b.capacity_bytes();
                        let grow = (b.x.len() / 2).max(MIN_GROWTH);
                        b.x.reserve_exact(grow);
                        b.y.reserve_exact(grow);
                        b.z.reserve_exact(grow);
                        b.owned.reserve_exact(grow);
                        self.buffered_bytes += b.capacity_bytes() - before;
                    }
                    b.x.push(p[0]);
                    b.y.push(p[1]);
                    b.z.push(p[2]);
                    b.owned.push(u8::from(owner.col == col && owner.row == row));
                }
            }
            if self.buffered_bytes > self.budget {
                self.flush_largest()?;
            }
        }
        Ok(())
    }

    /// Flush the largest buffers until at most half the budget is allocated.
    fn flush_largest(&mut self) -> Result<()> {
        let mut order: Vec<usize> = (0..self.buffers.len())
            .filter(|&i| !self.buffers[i].x.is_empty())
            .collect();
        // Largest first; ties by tile order so runs are reproducible.
        order.sort_by_key(|&i| (std::cmp::Reverse(self.buffers[i].x.len()), i));
        for i in order {
            if self.buffered_bytes <= self.budget / 2 {
                break;
            }
            self.flush(i)?;
        }
        Ok(())
    }

    fn segment_path(&self, i: usize) -> PathBuf {
        let id = self.id_of(i);
        self.seg_dir.join(format!("{}.seg", id.name()))
    }

    fn id_of(&self, i: usize) -> TileId {
        let rows = self.grid.rows() as usize;
        TileId {
            col: (i / rows) as u32,
            row: (i % rows) as u32,
        }
    }

    /// Append tile `i`'s buffer to its segment file as one chunk: u64 length + encoded columns
    /// (the tile file encoding, so each chunk carries its own checksums).
    fn flush(&mut self, i: usize) -> Result<()> {
        let b = std::mem::take(&mut self.buffers[i]);
        self.buffered_bytes -= b.capacity_bytes();
        let n = b.x.len() as u64;
        let cols = into_columns(b);
        // Segments are temporary: fastest level, the tiles' layout choices (quantised
        // coordinates take a third of the bytes and of the time).
        let seg_opts = WriteOptions {
            level: 1,
            ..self.opts
        };
        let path = self.segment_path(i);
        let bytes = tile_file::encode(&cols, &seg_opts).map_err(|p| Error::invalid(&path, p))?;
        let mut f = OpenOptions::new()
            .create(true)
            .append(true)
            .open(&path)
            .map_err(|e| Error::io(&path, e))?;
        f.write_all(&(bytes.len() as u64).to_le_bytes())
            .and_then(|_| f.write_all(&bytes))
            .map_err(|e| Error::io(&path, e))?;
        self.flushed[i] += n;
        Ok(())
    }

    /// Write every non-empty tile file (segments first, then the buffer, i.e. input order), one
    /// tile at a time, delete the segments, and return the tiles written with their point counts
    /// (halo points included), in tile order.
    pub fn finish(self) -> Result<Vec<(TileId, u64)>> {
        Ok(self
            .finish_with_digests()?
            .into_iter()
            .map(|(id, n, _)| (id, n))
            .collect())
    }

    /// [`TileSplitter::finish`], with each tile file's digest.
    pub fn finish_with_digests(mut self) -> Result<Vec<(TileId, u64, FileDigest)>> {
        let mut written = Vec::new();
        for i in 0..self.buffers.len() {
            let id = self.id_of(i);
            let buffer = std::mem::take(&mut self.buffers[i]);
            self.buffered_bytes -= buffer.capacity_bytes();
            if self.flushed[i] == 0 && buffer.x.is_empty() {
                continue;
            }
            let cols = if self.flushed[i] > 0 {
                let mut cols = empty_columns();
                let seg = self.segment_path(i);
                read_segment(&seg, &mut cols)?;
                if cols.len() as u64 != self.flushed[i] {
                    return Err(Error::corrupt(
                        &seg,
                        "segment holds a different point count",
                    ));
                }
                append(&mut cols, into_columns(buffer));
                cols
            } else {
                // Never flushed: the buffer is the tile.
                into_columns(buffer)
            };
            let path = tile_path(&self.dir, id);
            let digest = tile_file::write_tile_with(&path, &cols, &self.opts)?;
            written.push((id, cols.len() as u64, digest));
            if self.flushed[i] > 0 {
                let seg = self.segment_path(i);
                fs::remove_file(&seg).map_err(|e| Error::io(&seg, e))?;
            }
        }
        fs::remove_dir_all(&self.seg_dir).map_err(|e| Error::io(&self.seg_dir, e))?;
        Ok(written)
    }
}

/// The columns of a tile without points (x, y, z and an empty owned column): what a tile file
/// holds when no point falls in its halo box.
pub fn empty_columns() -> TileColumns {
    TileColumns {
        extra: vec![Column {
            name: OWNED_COLUMN.into(),
            data: ColumnData::U8(Vec::new()),
        }],
        ..TileColumns::default()
    }
}

fn into_columns(b: Buffer) -> TileColumns {
    TileColumns {
        x: b.x,
        y: b.y,
        z: b.z,
        extra: vec![Column {
            name: OWNED_COLUMN.into(),
            data: ColumnData::U8(b.owned),
        }],
    }
}

/// Append `more` (same column layout: x, y, z, owned) to `cols`.
fn append(cols: &mut TileColumns, more: TileColumns) {
    cols.x.extend_from_slice(&more.x);
    cols.y.extend_from_slice(&more.y);
    cols.z.extend_from_slice(&more.z);
    if let (Some(ColumnData::U8(dst)), Some(ColumnData::U8(src))) = (
        cols.extra.first_mut().map(|c| &mut c.data),
        more.extra.first().map(|c| &c.data),
    ) {
        dst.extend_from_slice(src);
    }
}

/// Decode every chunk of a segment file, in order, into `cols`.
fn read_segment(path: &Path, cols: &mut TileColumns) -> Result<()> {
    let mut f = fs::File::open(path).map_err(|e| Error::io(path, e))?;
    let mut len = [0u8; 8];
    loop {
        match f.read_exact(&mut len) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::UnexpectedEof => return Ok(()),
            Err(e) => return Err(Error::io(path, e)),
        }
        let n = u64::from_le_bytes(len);
        let n = usize::try_from(n).map_err(|_| Error::corrupt(path, "chunk too large"))?;
        let mut chunk = Vec::new();
        (&mut f)
            .take(n as u64)
            .read_to_end(&mut chunk)
            .map_err(|e| Error::io(path, e))?;
        if chunk.len() != n {
            return Err(Error::corrupt(path, "segment chunk is truncated"));
        }
        let part = tile_file::decode(&chunk).map_err(|r| Error::corrupt(path, r))?;
        let owned_ok = matches!(part.column(OWNED_COLUMN), Some(ColumnData::U8(_)));
        if !owned_ok || part.extra.len() != 1 {
            return Err(Error::corrupt(path, "segment chunk has unexpected columns"));
        }
        append(cols, part);
    }
}

//! Streaming split of an epoch into tile files with halos, in bounded memory (SPEC.md §3, pass 1).
//!
//! Each pushed point goes to every tile whose halo box contains it ([`TileGrid::tiles_touching`]),
//! with an `owned` column (1 in the tile that owns it, 0 where it is only halo). Points wait in
//! per-tile buffers of one frame each; a full buffer is encoded and appended to its tile's file
//! as a frame ([`crate::framed`]) and emptied. [`TileSplitter::finish`] appends every tile's last,
//! partial frame and writes the tiles' headers. Each point is encoded once.
//!
//! Determinism: a tile's frames hold its points in input order, `frame_points` at a time, so a
//! tile file's bytes depend on the input, the grid, the halo and the frame size only (not on
//! the chunk sizes of `push`); the frame size comes from the budget and the number of tiles.
//!
//! Memory: a buffer is allocated whole (one frame) when its tile gets its first point and kept
//! until the end, so the buffers never hold more than tiles × frame × 25 bytes ≤ the budget.

use crate::error::{Error, Result};
use crate::framed::Framed;
use crate::grid::{TileGrid, TileId};
use crate::tile_file::{Column, ColumnData, FileDigest, TileColumns, WriteOptions};
use std::fs;
use std::path::{Path, PathBuf};

/// Name of the per-point ownership column in tile files (u8: 1 owned, 0 halo).
pub const OWNED_COLUMN: &str = "owned";
/// Bytes one buffered point takes: x, y, z as f64 plus the owned flag.
const BYTES_PER_POINT: u64 = 3 * 8 + 1;
/// The largest frame, in points (25 MiB of buffer): larger ones gain nothing in compression
/// and hold more memory at once while they are encoded.
pub const MAX_FRAME_POINTS: usize = 1 << 20;

/// Where the tile `id` of a split lives.
pub fn tile_path(dir: &Path, id: TileId) -> PathBuf {
    dir.join(format!("{}.tile", id.name()))
}

/// Points per frame for a split into `tiles` tiles with `budget` bytes for its buffers: every
/// tile's buffer at once fits the budget.
pub fn frame_points(budget: u64, tiles: usize) -> usize {
    let per = budget / (tiles.max(1) as u64 * BYTES_PER_POINT);
    (per.min(MAX_FRAME_POINTS as u64) as usize).max(1)
}

#[derive(Default)]
struct Buffer {
    x: Vec<f64>,
    y: Vec<f64>,
    z: Vec<f64>,
    owned: Vec<u8>,
}

/// Splits a stream of points into the tiles of a grid, on disk.
pub struct TileSplitter {
    grid: TileGrid,
    halo: f64,
    frame_points: usize,
    opts: WriteOptions,
    /// One buffer and one file per tile, indexed by [`TileGrid::index`].
    buffers: Vec<Buffer>,
    files: Vec<Framed>,
}

impl TileSplitter {
    /// A splitter writing tile files `<dir>/t_CCCC_RRRR.tile`, with `memory_budget_bytes` for its
    /// buffers (see [`frame_points`]). `dir` belongs to the splitter: it is created if missing,
    /// and tile files and segments left there by an earlier (interrupted) split are removed
    /// first, so they can never be mistaken for this split's output.
    pub fn new(dir: &Path, grid: TileGrid, halo: f64, memory_budget_bytes: u64) -> Result<Self> {
        if !(halo.is_finite() && halo >= 0.0) {
            return Err(Error::Parameter {
                what: "halo",
                problem: format!("must be finite and ≥ 0, got {halo}"),
            });
        }
        fs::create_dir_all(dir).map_err(|e| Error::io(dir, e))?;
        // Segment files of the splitter before framed tiles.
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
        let n = grid.len();
        // In grid index order, as the buffers.
        let files = grid
            .tiles()
            .map(|id| Framed::new(&tile_path(dir, id)))
            .collect();
        Ok(TileSplitter {
            grid,
            halo,
            frame_points: frame_points(memory_budget_bytes, n),
            opts: WriteOptions::default(),
            buffers: (0..n).map(|_| Buffer::default()).collect(),
            files,
        })
    }

    /// Use these options for the tile files (e.g. quantised coordinates).
    pub fn with_options(mut self, opts: WriteOptions) -> Self {
        self.opts = opts;
        self
    }

    /// Use these options from now on (for the frames not yet written).
    pub fn set_options(&mut self, opts: WriteOptions) {
        self.opts = opts;
    }

    /// The grid being split into.
    pub fn grid(&self) -> &TileGrid {
        &self.grid
    }

    /// Route points to their tiles (in order), writing a frame whenever a tile's buffer is full.
    /// Points outside the grid go where [`TileGrid::owner`] clamps them (NaN x or y counts as the
    /// grid's min edge); callers should drop non-finite points before pushing.
    pub fn push(&mut self, points: &[[f64; 3]]) -> Result<()> {
        let rows = self.grid.rows() as usize;
        let frame = self.frame_points;
        for p in points {
            let (owner, [(c0, c1), (r0, r1)]) = self.grid.owner_and_ranges(p[0], p[1], self.halo);
            for col in c0..=c1 {
                for row in r0..=r1 {
                    let i = col as usize * rows + row as usize;
                    let b = &mut self.buffers[i];
                    if b.x.capacity() == 0 {
                        b.x.reserve_exact(frame);
                        b.y.reserve_exact(frame);
                        b.z.reserve_exact(frame);
                        b.owned.reserve_exact(frame);
                    }
                    b.x.push(p[0]);
                    b.y.push(p[1]);
                    b.z.push(p[2]);
                    b.owned.push(u8::from(owner.col == col && owner.row == row));
                    if b.x.len() == frame {
                        self.write_frame(i)?;
                    }
                }
            }
        }
        Ok(())
    }

    /// Write every non-empty tile's last frame and header, and return the tiles written with
    /// their point counts (halo points included), in tile order.
    pub fn finish(self) -> Result<Vec<(TileId, u64)>> {
        Ok(self
            .finish_with_digests()?
            .into_iter()
            .map(|(id, n, _)| (id, n))
            .collect())
    }

    /// [`TileSplitter::finish`], with each tile file's digest.
    pub fn finish_with_digests(self) -> Result<Vec<(TileId, u64, FileDigest)>> {
        let mut written = Vec::new();
        let tiles = self.grid.tiles().zip(self.buffers).zip(self.files);
        for ((id, mut buffer), mut file) in tiles {
            if !buffer.x.is_empty() {
                write_frame(&mut buffer, &mut file, &self.opts)?;
            }
            drop(buffer);
            if file.points() > 0 {
                let n = file.points();
                written.push((id, n, file.finish()?));
            }
        }
        Ok(written)
    }

    fn write_frame(&mut self, i: usize) -> Result<()> {
        write_frame(&mut self.buffers[i], &mut self.files[i], &self.opts)
    }
}

/// Append `b` to `file` as a frame and empty `b` (keeping its allocation for the next frame).
fn write_frame(b: &mut Buffer, file: &mut Framed, opts: &WriteOptions) -> Result<()> {
    let cols = TileColumns {
        x: std::mem::take(&mut b.x),
        y: std::mem::take(&mut b.y),
        z: std::mem::take(&mut b.z),
        extra: vec![Column {
            name: OWNED_COLUMN.into(),
            data: ColumnData::U8(std::mem::take(&mut b.owned)),
        }],
    };
    let written = file.append(&cols, opts);
    let TileColumns { x, y, z, extra } = cols;
    (b.x, b.y, b.z) = (x, y, z);
    if let Some(Column {
        data: ColumnData::U8(o),
        ..
    }) = extra.into_iter().next()
    {
        b.owned = o;
    }
    for v in [&mut b.x, &mut b.y, &mut b.z] {
        v.clear();
    }
    b.owned.clear();
    written
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

#[cfg(test)]
mod tests {
    use super::*;

    /// Every tile's buffer at once (a frame each, the most a split holds) fits the budget.
    #[test]
    fn all_buffers_fit_the_budget() {
        for (budget, tiles) in [
            (4096, 60),
            (50_000, 60),
            (300_000, 60),
            (10_000, 1),
            (1 << 30, 7),
        ] {
            let held = frame_points(budget, tiles) as u64 * BYTES_PER_POINT * tiles as u64;
            assert!(held <= budget, "{held} > {budget} for {tiles} tiles");
        }
    }
}

//! Pass 1: the tile layout of a run and the streaming split of each epoch into tile files.
//!
//! The tile grid is anchored on the core-point grid (its origin and side are whole multiples of
//! `core_spacing`), so a core-point cell never straddles two tiles and a tiled run thins C1 to
//! exactly the core points of a whole-cloud run. A split is one resume unit per epoch, recorded
//! with the checksum of its tile files: a damaged or missing tile makes the split be redone.

use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, Ordering};

use talus_tiling::{BoundsXY, TileGrid, TileId, TileSplitter};

use crate::error::{Error, Result};
use crate::io::{self, Bounds, CloudInfo, Point3};
use crate::params::Params;
use crate::pipeline::progress::Stage;
use crate::pipeline::workdir::WorkDir;
use crate::pipeline::{file_identity, CompareOptions};

/// Resident bytes per input point while its tile is processed: coordinates (24), the column
/// index's copy (24), the owned flag and slack for the per-core-point results and the tile
/// being read meanwhile.
pub const BYTES_PER_POINT: u64 = 72;

/// Map an error of the tiling crate onto talus's.
pub fn tiling_error(e: talus_tiling::Error) -> Error {
    match e {
        talus_tiling::Error::Io { path, source } => Error::output(path, source),
        other => Error::Internal(other.to_string()),
    }
}

/// The grid, halo and core-point anchor of a run.
#[derive(Debug, Clone)]
pub struct Layout {
    pub grid: TileGrid,
    pub halo: f64,
    /// Origin of the core-point grid (global).
    pub anchor: Point3,
    pub core_spacing: f64,
    /// The bounds of every input (both epochs and the core-point file).
    pub extent: Bounds,
}

impl Layout {
    /// Plan the tiles from the inputs' bounds and counts, the halo and the memory budget.
    pub fn plan(
        before: &CloudInfo,
        after: &CloudInfo,
        cores: Option<&CloudInfo>,
        params: &Params,
        tile_size: Option<f64>,
    ) -> Result<Layout> {
        let mut b = Bounds::empty();
        for info in [Some(before), Some(after), cores].into_iter().flatten() {
            b.grow(&info.bounds.min);
            b.grow(&info.bounds.max);
        }
        let c = params.core_spacing.value;
        let anchor = [
            (b.min[0] / c).floor() * c,
            (b.min[1] / c).floor() * c,
            (b.min[2] / c).floor() * c,
        ];
        let halo = tile_halo(params);
        let w = (b.max[0] - anchor[0]).max(c);
        let h = (b.max[1] - anchor[1]).max(c);
        let density = (before.point_count + after.point_count) as f64 / (w * h);
        let side = match tile_size {
            Some(s) if s > 0.0 => s,
            Some(s) => return Err(Error::Usage(format!("tile size must be positive, got {s}"))),
            None => {
                let planned = TileGrid::plan(
                    BoundsXY::new([anchor[0], anchor[1]], [anchor[0] + w, anchor[1] + h]),
                    density,
                    halo,
                    params.memory_bytes.value,
                    BYTES_PER_POINT,
                )
                .map_err(tiling_error)?;
                planned.tile_size()
            }
        };
        // Whole core cells per tile; at least one.
        let side = ((side / c).ceil().max(1.0)) * c;
        let cols = ((w / side).ceil().max(1.0)) as u32;
        let rows = ((h / side).ceil().max(1.0)) as u32;
        let grid = TileGrid::new([anchor[0], anchor[1]], side, cols, rows).map_err(tiling_error)?;
        Ok(Layout {
            grid,
            halo,
            anchor,
            core_spacing: c,
            extent: b,
        })
    }

    /// A stable description for resume keys.
    pub fn key(&self) -> String {
        format!(
            "{:?}|{}|{}|{}|{}|{:?}",
            self.grid.origin(),
            self.grid.tile_size(),
            self.grid.cols(),
            self.grid.rows(),
            self.halo,
            self.anchor
        )
    }
}

/// Where the tiles of each epoch are.
pub struct Tiled {
    pub before: PathBuf,
    pub after: PathBuf,
    /// Hash of the tile sets (inputs of the next stage): made from the inputs' identity and the
    /// layout, not from the files' bytes, so a split redone after damage (identical bytes, the
    /// split is deterministic) does not invalidate the M3C2 units made from it.
    pub hash: String,
    pub reused: bool,
    /// The input each epoch's tiles were cut from (to redo a split found damaged in pass 2).
    pub before_src: PathBuf,
    pub after_src: PathBuf,
    /// Memory for the splitter's buffers.
    pub split_budget: u64,
}

/// One of the two epochs.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Epoch {
    Before,
    After,
}

impl Epoch {
    pub fn name(self) -> &'static str {
        match self {
            Epoch::Before => "before",
            Epoch::After => "after",
        }
    }
}

/// The halo of the tile files: how far beyond its square a tile must hold points so that every
/// neighbourhood pass 2 computes for the core points it owns is the one a whole-cloud run sees
/// (SPEC.md §3). Pass 2 looks at the normal sphere, the M3C2 cylinder (inside its circumscribed
/// sphere), and, for `auto` orientation, the top-surface cells 1..4 × normal_radius away (cells of
/// normal_radius / 2, so a cell reaches another half diagonal, < 0.71 × normal_radius, further).
/// The DBSCAN `eps` is not in it: the events stage clusters the kept core points in memory with
/// its own halo, so a changed `eps` must not cut the epochs again.
pub fn tile_halo(params: &Params) -> f64 {
    let nr = params.normal_radius.value;
    let cyl = (params.cyl_radius.value.powi(2) + params.cyl_halflen.value.powi(2)).sqrt();
    let orient = 4.0 * nr + 0.5 * nr * std::f64::consts::SQRT_2;
    nr.max(cyl).max(orient) + 2.0 * params.core_spacing.value
}

/// Split every epoch into tiles, or reuse a finished split whose files are intact. Epochs to
/// split are cut at the same time, one thread each with half the budget: a split is mostly one
/// thread's work (decoding, bucketing, compressing), so on two cores this halves pass 1.
pub fn tile_epochs(
    wd: &mut WorkDir,
    layout: &Layout,
    opts: &CompareOptions,
    params: &Params,
    stage: &Stage,
) -> Result<Tiled> {
    let mut all = talus_tiling::Fnv64::new();
    let budget = (params.memory_bytes.value / 4).max(16 << 20);
    let epochs = [(Epoch::Before, &opts.before), (Epoch::After, &opts.after)];
    let mut todo = Vec::new();
    for (epoch, src) in epochs {
        let hash = split_hash(layout, src)?;
        all.write_str(&hash);
        if !reusable(wd, layout, epoch, &hash) {
            todo.push((epoch, src.as_path(), hash));
        }
    }
    let reused = todo.is_empty();
    // The old entries go first, then the files: a stale or partial split starts from nothing.
    let mut dirs = Vec::new();
    for (epoch, _, _) in &todo {
        wd.forget(&unit_name(*epoch))?;
        dirs.push(fresh_dir(wd, *epoch)?);
    }
    let share = (budget / todo.len().max(1) as u64).max(8 << 20);
    // A failed split stops the other one: the run fails anyway.
    let failed = AtomicBool::new(false);
    let results: Vec<Result<Option<String>>> = std::thread::scope(|s| {
        let handles: Vec<_> = todo
            .iter()
            .zip(&dirs)
            .map(|((_, src, _), dir)| {
                let failed = &failed;
                s.spawn(move || {
                    let r = cut(dir, layout, src, share, stage, failed);
                    if r.is_err() {
                        failed.store(true, Ordering::Relaxed);
                    }
                    r
                })
            })
            .collect();
        handles
            .into_iter()
            .map(|h| {
                h.join()
                    .unwrap_or_else(|_| Err(Error::Internal("a tiling thread panicked".into())))
            })
            .collect()
    });
    // Record what finished even when the other failed (a rerun then resumes from it). The error
    // reported is the one that stopped the run: the before epoch's when both failed on their own
    // (a split stopped by the other's failure returns no error).
    let mut first_error = None;
    for (((epoch, _, hash), dir), result) in todo.iter().zip(&dirs).zip(results) {
        match result {
            Ok(Some(checksum)) => {
                wd.done(&unit_name(*epoch), &split_file(*epoch), hash, &checksum)?
            }
            Ok(None) => {
                let _ = std::fs::remove_dir_all(dir);
            }
            Err(e) => {
                let _ = std::fs::remove_dir_all(dir);
                first_error.get_or_insert(e);
            }
        }
    }
    if let Some(e) = first_error {
        return Err(e);
    }
    // User core points are not split: they stay in memory with their input order (see
    // `m3c2_pass::UserCores`); their file's identity enters the hash here.
    if let Some(p) = &opts.core_points {
        all.write_str(&file_identity(p)?);
    }
    Ok(Tiled {
        before: wd.work.join(split_file(Epoch::Before)),
        after: wd.work.join(split_file(Epoch::After)),
        hash: all.hex(),
        reused,
        before_src: opts.before.clone(),
        after_src: opts.after.clone(),
        split_budget: budget,
    })
}

/// What a split depends on: its input file (path, size, mtime) and the layout (grid and halo).
pub fn split_hash(layout: &Layout, src: &Path) -> Result<String> {
    let inputs = format!("{}|{}", file_identity(src)?, layout.key());
    Ok(format!("{:016x}", talus_tiling::hash64(inputs.as_bytes())))
}

fn unit_name(epoch: Epoch) -> String {
    format!("tiles:{}", epoch.name())
}

/// True when the manifest records the split of `epoch` as made from `hash` and every tile file
/// still has its recorded checksum.
fn reusable(wd: &WorkDir, layout: &Layout, epoch: Epoch, hash: &str) -> bool {
    let dir = wd.work.join(split_file(epoch));
    wd.intact(&unit_name(epoch), hash, |_| {
        split_checksum(&dir, &layout.grid).ok()
    })
    .is_some()
}

/// The directory of an epoch's split, relative to the work directory.
fn split_file(epoch: Epoch) -> String {
    format!("tiles/{}", epoch.name())
}

/// The split directory of `epoch`, emptied.
fn fresh_dir(wd: &WorkDir, epoch: Epoch) -> Result<PathBuf> {
    let dir = wd.work.join(split_file(epoch));
    if dir.exists() {
        std::fs::remove_dir_all(&dir).map_err(|e| Error::output(&dir, e))?;
    }
    wd.sub(&split_file(epoch))
}

/// Cut `src` into the tiles of `layout` under `tiles/<epoch>` and record the unit (used again
/// by pass 2 when a tile file turns out damaged).
pub fn split(
    wd: &mut WorkDir,
    layout: &Layout,
    epoch: Epoch,
    src: &Path,
    hash: &str,
    budget: u64,
    stage: &Stage,
) -> Result<PathBuf> {
    let unit = unit_name(epoch);
    wd.forget(&unit)?;
    let dir = fresh_dir(wd, epoch)?;
    let checksum = cut(&dir, layout, src, budget, stage, &AtomicBool::new(false))?
        .ok_or_else(|| Error::Internal("a split stopped without a reason".into()))?;
    wd.done(&unit, &split_file(epoch), hash, &checksum)?;
    Ok(dir)
}

/// Write the tile files of `src` into the empty directory `dir`; returns the split's checksum,
/// or None when `stop` was raised (by another split's failure) before the end.
fn cut(
    dir: &Path,
    layout: &Layout,
    src: &Path,
    budget: u64,
    stage: &Stage,
    stop: &AtomicBool,
) -> Result<Option<String>> {
    let mut splitter =
        TileSplitter::new(dir, layout.grid, layout.halo, budget).map_err(tiling_error)?;
    let mut reader = io::open(src)?;
    let mut buf = Vec::new();
    while reader.fill(&mut buf, 1 << 16)? > 0 {
        splitter.push(&buf).map_err(tiling_error)?;
        stage.inc(buf.len() as u64);
        if stop.load(Ordering::Relaxed) {
            return Ok(None);
        }
    }
    let written = splitter.finish().map_err(tiling_error)?;
    // The splitter writes no file for a tile without points; write an empty one, so that every
    // tile of the grid has a file and a missing file always means damage.
    let mut has_file = vec![false; layout.grid.len()];
    for (id, _) in &written {
        has_file[layout.grid.index(*id)] = true;
    }
    for id in layout.grid.tiles() {
        if !has_file[layout.grid.index(id)] {
            let path = talus_tiling::tile_path(dir, id);
            talus_tiling::write_tile(&path, &talus_tiling::empty_columns())
                .map_err(tiling_error)?;
        }
    }
    split_checksum(dir, &layout.grid)
        .map(Some)
        .map_err(tiling_error)
}

/// Checksum of a whole split: FNV-1a over the CRC-32 of every tile file, in grid order. Reading
/// the files back costs one sequential pass over them, small next to pass 2, and catches a
/// damaged or missing tile before any stage reads it.
fn split_checksum(dir: &Path, grid: &TileGrid) -> talus_tiling::Result<String> {
    let mut h = talus_tiling::Fnv64::new();
    for id in grid.tiles() {
        h.write_str(&talus_tiling::file_checksum(&talus_tiling::tile_path(
            dir, id,
        ))?);
    }
    Ok(format!("fnv-crc32:{}", h.hex()))
}

/// The points of one tile: global coordinates, as the columns the tile file holds (no copy into
/// another layout), and whether the tile owns each one.
pub struct TilePoints {
    pub x: Vec<f64>,
    pub y: Vec<f64>,
    pub z: Vec<f64>,
    pub owned: Vec<bool>,
}

impl TilePoints {
    /// Number of points.
    pub fn len(&self) -> usize {
        self.x.len()
    }

    /// True when the tile holds no point.
    pub fn is_empty(&self) -> bool {
        self.x.is_empty()
    }

    /// Point `i`.
    #[inline]
    pub fn point(&self, i: usize) -> Point3 {
        [self.x[i], self.y[i], self.z[i]]
    }
}

/// Read one tile of a split.
pub fn read_tile(dir: &Path, id: TileId) -> Result<TilePoints> {
    read_tile_raw(dir, id).map_err(tiling_error)
}

/// Read one tile of a split with the tiling crate's error, so that the caller can tell damage
/// ([`talus_tiling::Error::Corrupt`], a checksum mismatch) from an I/O failure and redo the split.
pub fn read_tile_raw(dir: &Path, id: TileId) -> talus_tiling::Result<TilePoints> {
    let path = talus_tiling::splitter::tile_path(dir, id);
    let cols = talus_tiling::read_tile(&path)?;
    let owned = match cols.column(talus_tiling::splitter::OWNED_COLUMN) {
        Some(talus_tiling::ColumnData::U8(v)) => v.iter().map(|&o| o == 1).collect(),
        _ => vec![true; cols.len()],
    };
    Ok(TilePoints {
        x: cols.x,
        y: cols.y,
        z: cols.z,
        owned,
    })
}

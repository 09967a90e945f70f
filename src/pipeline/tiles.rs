//! Pass 1: the tile layout of a run and the streaming split of each epoch into tile files.
//!
//! The tile grid is anchored on the core-point grid (its origin and side are whole multiples of
//! `core_spacing`), so a core-point cell never straddles two tiles and a tiled run thins C1 to
//! exactly the core points of a whole-cloud run.

use std::path::{Path, PathBuf};

use talus_tiling::{BoundsXY, TileGrid, TileId, TileSplitter};

use crate::error::{Error, Result};
use crate::io::{self, Bounds, CloudInfo, Point3};
use crate::params::Params;
use crate::pipeline::workdir::WorkDir;
use crate::pipeline::{file_identity, CompareOptions};

/// Resident bytes per input point while its tile is processed: coordinates (24), the kd-tree's
/// copy and index (≈ 32), the owned flag and slack for the per-core-point results.
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
        let halo = params.halo();
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
    /// Hash of the tile sets (inputs of the next stage).
    pub hash: String,
    pub reused: bool,
}

/// Split every epoch (and the core-point file) into tiles, or reuse a finished split.
pub fn tile_epochs(
    wd: &mut WorkDir,
    layout: &Layout,
    opts: &CompareOptions,
    params: &Params,
) -> Result<Tiled> {
    let mut all = talus_tiling::Fnv64::new();
    let mut reused = true;
    let mut split = |wd: &mut WorkDir, name: &str, src: &Path, halo: f64| -> Result<PathBuf> {
        let dir = wd.sub(&format!("tiles/{name}"))?;
        let inputs = format!("{}|{}|{}", file_identity(src)?, layout.key(), halo);
        let hash = talus_tiling::hash64(inputs.as_bytes());
        let hash = format!("{hash:016x}");
        all.write_str(&hash);
        let unit = format!("tiles:{name}");
        if wd.is_done(&unit, &hash) && tiles_present(&dir, &layout.grid) {
            return Ok(dir);
        }
        reused = false;
        // A stale or partial split: start it again from nothing.
        let _ = std::fs::remove_dir_all(&dir);
        let dir = wd.sub(&format!("tiles/{name}"))?;
        let budget = (params.memory_bytes.value / 4).max(16 << 20);
        let mut splitter =
            TileSplitter::new(&dir, layout.grid.clone(), halo, budget).map_err(tiling_error)?;
        let mut reader = io::open(src)?;
        let mut buf = Vec::new();
        while reader.fill(&mut buf, 1 << 16)? > 0 {
            splitter.push(&buf).map_err(tiling_error)?;
        }
        splitter.finish().map_err(tiling_error)?;
        wd.done(&unit, &dir.display().to_string(), &hash)?;
        Ok(dir)
    };
    let before = split(wd, "before", &opts.before, layout.halo)?;
    let after = split(wd, "after", &opts.after, layout.halo)?;
    // User core points are not split: they stay in memory with their input order (see
    // `m3c2_pass::UserCores`); their file's identity enters the hash here.
    if let Some(p) = &opts.core_points {
        all.write_str(&file_identity(p)?);
    }
    Ok(Tiled {
        before,
        after,
        hash: all.hex(),
        reused,
    })
}

fn tiles_present(dir: &Path, grid: &TileGrid) -> bool {
    grid.tiles()
        .all(|id| talus_tiling::splitter::tile_path(dir, id).exists())
}

/// The points of one tile: global coordinates and whether the tile owns each one.
pub struct TilePoints {
    pub points: Vec<Point3>,
    pub owned: Vec<bool>,
}

/// Read one tile of a split. A corrupt file (checksum) is reported as such; the caller redoes the
/// split.
pub fn read_tile(dir: &Path, id: TileId) -> Result<TilePoints> {
    let path = talus_tiling::splitter::tile_path(dir, id);
    let cols = talus_tiling::read_tile(&path).map_err(tiling_error)?;
    let owned = match cols.column(talus_tiling::splitter::OWNED_COLUMN) {
        Some(talus_tiling::ColumnData::U8(v)) => v.iter().map(|&o| o == 1).collect(),
        _ => vec![true; cols.len()],
    };
    let points = (0..cols.len())
        .map(|i| [cols.x[i], cols.y[i], cols.z[i]])
        .collect();
    Ok(TilePoints { points, owned })
}

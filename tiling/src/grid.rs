//! Square XY tiles over the survey bounds, with halos (SPEC.md §3).
//!
//! Ownership: tile (col,row) owns the half-open square
//! `[x0 + col·s, x0 + (col+1)·s) × [y0 + row·s, y0 + (row+1)·s)`, so every point is owned by
//! exactly one tile; the last column and row also own their max edge (and points outside the grid
//! are clamped to the nearest tile) so that the grid's own bounds are fully covered. Square edges
//! are always computed by the same expression `origin + k·s`, and ownership is decided by comparing
//! against those edges (not by a bare `floor`), so a point exactly on an edge goes to the same
//! tile on every run and platform, and [`TileGrid::square`] agrees with [`TileGrid::owner`].
//!
//! Halo: a tile's halo box is its square grown by `halo` on every side, closed on both ends, so
//! every point within distance `halo` of a point the tile owns lies in the box (a superset of the
//! sphere/cylinder neighbourhoods computed inside the tile).

use crate::error::{Error, Result};
use std::fmt;

/// An axis-aligned XY rectangle (closed).
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct BoundsXY {
    pub min: [f64; 2],
    pub max: [f64; 2],
}

impl BoundsXY {
    /// The rectangle with the given corners.
    pub fn new(min: [f64; 2], max: [f64; 2]) -> Self {
        BoundsXY { min, max }
    }

    /// Width and height.
    pub fn extent(&self) -> [f64; 2] {
        [self.max[0] - self.min[0], self.max[1] - self.min[1]]
    }

    /// True when `min ≤ (x,y) ≤ max` on both axes.
    pub fn contains(&self, x: f64, y: f64) -> bool {
        x >= self.min[0] && x <= self.max[0] && y >= self.min[1] && y <= self.max[1]
    }
}

/// A tile's position in the grid. Ordered column-major (by `col`, then `row`), which is also the
/// lexicographic order of [`TileId::name`] while indices stay below 10 000.
#[derive(Clone, Copy, Debug, PartialEq, Eq, PartialOrd, Ord, Hash, serde::Serialize)]
pub struct TileId {
    pub col: u32,
    pub row: u32,
}

impl TileId {
    /// Stable name used for file names and manifest units: `t_<col:04>_<row:04>`, e.g. `t_0003_0012`.
    pub fn name(&self) -> String {
        format!("t_{:04}_{:04}", self.col, self.row)
    }
}

impl fmt::Display for TileId {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "t_{:04}_{:04}", self.col, self.row)
    }
}

/// A grid of `cols × rows` square tiles of side `tile_size` starting at `origin` (min corner).
/// Serializable for summaries and manifests; rebuild one with [`TileGrid::new`], which validates.
#[derive(Clone, Copy, Debug, PartialEq, serde::Serialize)]
pub struct TileGrid {
    origin: [f64; 2],
    tile_size: f64,
    cols: u32,
    rows: u32,
}

/// Share of the memory budget one tile's points (with halo) may take. Pass 2 holds a tile's points
/// plus its kd-trees and per-core-point results, and a bounded channel keeps up to one more tile
/// loaded while another is processed; `bytes_per_point_in_memory` is meant to include the per-point
/// cost of those structures, and a quarter leaves room for two tiles in flight plus allocator slack.
pub const TILE_BUDGET_FRACTION: f64 = 0.25;

impl TileGrid {
    /// A grid with explicit geometry. `tile_size` must be finite and > 0, `cols`, `rows` ≥ 1.
    pub fn new(origin: [f64; 2], tile_size: f64, cols: u32, rows: u32) -> Result<Self> {
        if !(origin[0].is_finite() && origin[1].is_finite()) {
            return Err(param("origin", format!("not finite: {origin:?}")));
        }
        if !(tile_size.is_finite() && tile_size > 0.0) {
            return Err(param(
                "tile_size",
                format!("must be finite and > 0, got {tile_size}"),
            ));
        }
        if cols == 0 || rows == 0 {
            return Err(param(
                "grid",
                format!("needs at least one tile, got {cols}×{rows}"),
            ));
        }
        Ok(TileGrid {
            origin,
            tile_size,
            cols,
            rows,
        })
    }

    /// Choose the tiling for a survey.
    ///
    /// * `bounds`: XY bounds of both epochs together.
    /// * `points_per_area`: estimated point density of both epochs together (points per unit²).
    /// * `halo`: halo width (≥ the largest neighbourhood reach, SPEC.md §3).
    /// * `memory_budget_bytes`, `bytes_per_point_in_memory`: the run's budget and the resident
    ///   cost of one point while its tile is processed (coordinates, kd-tree, results).
    ///
    /// The tile side `s` is chosen so that one tile's points **including its halo**, i.e.
    /// `density · (s + 2·halo)² · bytes_per_point`, stay within [`TILE_BUDGET_FRACTION`] (a quarter)
    /// of the budget. The side is never smaller than `4·halo` (below that the halo dominates and
    /// most work is duplicated; with such a dense cloud the tile then exceeds the fraction, which
    /// the caller can detect with [`TileGrid::tile_bytes_estimate`]). When the whole cloud fits in
    /// that fraction, or one tile of side `s` covers it, the grid is a single tile covering
    /// `bounds`: a small cloud uses the same code path as a large one.
    pub fn plan(
        bounds: BoundsXY,
        points_per_area: f64,
        halo: f64,
        memory_budget_bytes: u64,
        bytes_per_point_in_memory: u64,
    ) -> Result<Self> {
        let finite = bounds
            .min
            .iter()
            .chain(bounds.max.iter())
            .all(|v| v.is_finite());
        let [w, h] = bounds.extent();
        if !finite || w < 0.0 || h < 0.0 {
            return Err(param("bounds", format!("invalid: {bounds:?}")));
        }
        if !(points_per_area.is_finite() && points_per_area >= 0.0) {
            return Err(param(
                "points_per_area",
                format!("invalid: {points_per_area}"),
            ));
        }
        if !(halo.is_finite() && halo >= 0.0) {
            return Err(param("halo", format!("must be finite and ≥ 0, got {halo}")));
        }
        if memory_budget_bytes == 0 || bytes_per_point_in_memory == 0 {
            return Err(param(
                "memory",
                "budget and bytes per point must be > 0".into(),
            ));
        }
        let allowed_points =
            TILE_BUDGET_FRACTION * memory_budget_bytes as f64 / bytes_per_point_in_memory as f64;
        // Side of a square whose halo box holds `allowed_points`.
        let side = if points_per_area > 0.0 {
            (allowed_points / points_per_area).sqrt() - 2.0 * halo
        } else {
            f64::INFINITY
        };
        let side = side.max(4.0 * halo);
        let whole_cloud_points = points_per_area * (w + 2.0 * halo) * (h + 2.0 * halo);
        let largest = w.max(h);
        if whole_cloud_points <= allowed_points || side >= largest {
            // One tile covering the bounds. A degenerate (zero-extent) cloud still needs a
            // positive side; any positive value works since everything is clamped into it.
            let size = if largest > 0.0 { largest } else { 1.0 };
            return TileGrid::new(bounds.min, size, 1, 1);
        }
        let cols = tiles_along(w, side)?;
        let rows = tiles_along(h, side)?;
        TileGrid::new(bounds.min, side, cols, rows)
    }

    /// Estimated resident bytes of one tile with its halo, at the given density (see [`Self::plan`]).
    pub fn tile_bytes_estimate(
        &self,
        points_per_area: f64,
        halo: f64,
        bytes_per_point: u64,
    ) -> f64 {
        let side = self.tile_size + 2.0 * halo;
        points_per_area * side * side * bytes_per_point as f64
    }

    pub fn origin(&self) -> [f64; 2] {
        self.origin
    }
    pub fn tile_size(&self) -> f64 {
        self.tile_size
    }
    pub fn cols(&self) -> u32 {
        self.cols
    }
    pub fn rows(&self) -> u32 {
        self.rows
    }
    /// Number of tiles.
    pub fn len(&self) -> usize {
        self.cols as usize * self.rows as usize
    }
    /// Never true (a grid has at least one tile); present for clippy's `len_without_is_empty`.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// All tiles, in [`TileId`] order.
    pub fn tiles(&self) -> impl Iterator<Item = TileId> + '_ {
        (0..self.cols).flat_map(move |col| (0..self.rows).map(move |row| TileId { col, row }))
    }

    /// Edge `k` along `axis` (0 = x, 1 = y): the single expression all decisions use.
    fn edge(&self, axis: usize, k: u32) -> f64 {
        self.origin[axis] + f64::from(k) * self.tile_size
    }

    /// Index along `axis` of the half-open cell holding `v`, clamped into the grid.
    fn cell(&self, axis: usize, v: f64) -> u32 {
        let n = if axis == 0 { self.cols } else { self.rows };
        let guess = (v - self.origin[axis]) / self.tile_size;
        // NaN and out-of-range guesses clamp; the loops below then fix rounding at edges.
        // Truncation is the floor of the positive guesses that reach it (`floor` is a library
        // call on baseline x86-64, and this runs twice per point of a survey).
        let mut k = if guess.is_nan() || guess <= 0.0 {
            0
        } else if guess >= f64::from(n - 1) {
            n - 1
        } else {
            guess as u32
        };
        while k > 0 && v < self.edge(axis, k) {
            k -= 1;
        }
        while k + 1 < n && v >= self.edge(axis, k + 1) {
            k += 1;
        }
        k
    }

    /// The tile owning `(x, y)` (see the module doc for borders and out-of-grid points).
    pub fn owner(&self, x: f64, y: f64) -> TileId {
        TileId {
            col: self.cell(0, x),
            row: self.cell(1, y),
        }
    }

    /// A tile's own square (half-open except at the grid's max edges).
    pub fn square(&self, id: TileId) -> BoundsXY {
        BoundsXY {
            min: [self.edge(0, id.col), self.edge(1, id.row)],
            max: [self.edge(0, id.col + 1), self.edge(1, id.row + 1)],
        }
    }

    /// A tile's square grown by `halo` on every side (closed).
    pub fn halo_box(&self, id: TileId, halo: f64) -> BoundsXY {
        let s = self.square(id);
        BoundsXY {
            min: [s.min[0] - halo, s.min[1] - halo],
            max: [s.max[0] + halo, s.max[1] + halo],
        }
    }

    /// Range of indices along `axis` whose halo interval `[edge(k) − h, edge(k+1) + h]` contains
    /// `v` clamped onto the grid's extent (clamping changes nothing inside the grid).
    fn halo_range(&self, axis: usize, v: f64, halo: f64) -> (u32, u32) {
        self.halo_range_from(axis, v, halo, self.cell(axis, v))
    }

    /// [`Self::halo_range`] given `own`, the cell of `v` along `axis`.
    fn halo_range_from(&self, axis: usize, v: f64, halo: f64, own: u32) -> (u32, u32) {
        let n = if axis == 0 { self.cols } else { self.rows };
        let v = self.clamp(axis, v);
        // The intervals are ordered and overlap only near edges; walk out from the owner with the
        // exact same predicate `halo_box` uses, so the set matches a brute-force check exactly.
        let inside = |k: u32| v >= self.edge(axis, k) - halo && v <= self.edge(axis, k + 1) + halo;
        let mut lo = own;
        while lo > 0 && inside(lo - 1) {
            lo -= 1;
        }
        let mut hi = own;
        while hi + 1 < n && inside(hi + 1) {
            hi += 1;
        }
        (lo, hi)
    }

    /// Clamp `v` onto the grid's closed extent along `axis` (NaN goes to the min edge).
    fn clamp(&self, axis: usize, v: f64) -> f64 {
        let n = if axis == 0 { self.cols } else { self.rows };
        let (lo, hi) = (self.edge(axis, 0), self.edge(axis, n));
        if v.is_nan() {
            lo
        } else {
            v.clamp(lo, hi)
        }
    }

    /// The point clamped onto the grid's closed extent: itself for every point inside the grid.
    pub fn clamp_point(&self, x: f64, y: f64) -> [f64; 2] {
        [self.clamp(0, x), self.clamp(1, y)]
    }

    /// Every tile whose halo box contains `(x, y)`, in [`TileId`] order. A point outside the grid
    /// is first clamped onto its edge ([`Self::clamp_point`]), like [`Self::owner`] does, so the
    /// set always includes the owner.
    pub fn tiles_touching(&self, x: f64, y: f64, halo: f64) -> impl Iterator<Item = TileId> {
        let [(c0, c1), (r0, r1)] = self.touching_ranges(x, y, halo);
        (c0..=c1).flat_map(move |col| (r0..=r1).map(move |row| TileId { col, row }))
    }

    /// Column and row ranges (inclusive) of [`Self::tiles_touching`].
    pub(crate) fn touching_ranges(&self, x: f64, y: f64, halo: f64) -> [(u32, u32); 2] {
        [self.halo_range(0, x, halo), self.halo_range(1, y, halo)]
    }

    /// [`Self::owner`] and [`Self::touching_ranges`] at once (each cell found once).
    pub(crate) fn owner_and_ranges(&self, x: f64, y: f64, halo: f64) -> (TileId, [(u32, u32); 2]) {
        let (col, row) = (self.cell(0, x), self.cell(1, y));
        (
            TileId { col, row },
            [
                self.halo_range_from(0, x, halo, col),
                self.halo_range_from(1, y, halo, row),
            ],
        )
    }

    /// Position of a tile in [`Self::tiles`] order (`col·rows + row`).
    pub fn index(&self, id: TileId) -> usize {
        id.col as usize * self.rows as usize + id.row as usize
    }
}

fn tiles_along(extent: f64, side: f64) -> Result<u32> {
    // At least one tile; `ceil` leaves the max edge inside the last tile, which also owns it.
    let n = (extent / side).ceil().max(1.0);
    if n > f64::from(u32::MAX / 2) {
        return Err(param(
            "grid",
            format!("{n} tiles along one axis is too many"),
        ));
    }
    Ok(n as u32)
}

fn param(what: &'static str, problem: String) -> Error {
    Error::Parameter { what, problem }
}

#[cfg(test)]
mod tests;

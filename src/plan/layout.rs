//! The tile layout of a run: one grid of square tiles with halos for every survey of the run
//! (SPEC.md §3), anchored on the core-point grid.
//!
//! The grid's origin and side are whole multiples of `core_spacing`, so a core-point cell never
//! straddles two tiles and a tiled run thins C1 to exactly the core points of a whole-cloud run.
//! Its side follows from the memory budget and the densest survey ([`TileGrid::plan`]); its halo
//! holds every neighbourhood a tile's core points need (`tile_halo`).

use serde::{Deserialize, Serialize};
use talus_tiling::grid::TILE_BUDGET_FRACTION;
use talus_tiling::{BoundsXY, TileGrid};

use crate::error::{Error, Result};
use crate::io::{Bounds, Point3};
use crate::params::Params;
use crate::spatial::DensityGrid;

/// The size (input units) of the blocks the core-point lattice is anchored on: large next to a
/// site, so that two runs over it share the anchor, small enough that local coordinates keep
/// their precision (a picometre at 10 km) and Morton keys their 21 bits per axis.
pub(crate) const ANCHOR_BLOCK: f64 = 10_000.0;

/// Resident bytes per point (both epochs, halo included) while a tile is computed: its
/// coordinates and owned flags as read (25), the column index (≈ 40), the per-core-point results
/// (a core point per ≈ 7 points, ≈ 120 each) and the tile file's bytes while decoding. Measured
/// 89–101 bytes per point (unit peak less the process's base, over the tile's points with its
/// halo) on the 5.2M-point cliff's tiles at 300 MiB and 1 GiB. Tiles are sized by it; the M3C2 unit reserves by it.
pub(crate) const BYTES_PER_POINT: u64 = 104;

/// The grid, halo and core-point anchor of a run.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Layout {
    /// Grid origin (min corner), tile side, columns, rows.
    pub origin: [f64; 2],
    pub tile_size: f64,
    pub cols: u32,
    pub rows: u32,
    pub halo: f64,
    /// Origin of the core-point grid (global).
    pub anchor: Point3,
    pub core_spacing: f64,
    /// The bounds of every input (the surveys and the core-point file).
    pub extent: Bounds,
}

impl Layout {
    /// Plan the tiles over the inputs' `bounds`, with `density` points per unit² to hold at once
    /// (both epochs of a pair), the halo and the memory budget; `tile_size` forces the side
    /// (tests of tiling invariance).
    ///
    /// The core-point lattice is anchored at the corner of the `ANCHOR_BLOCK`-sized block
    /// (a power of two of core spacings) holding the minimum of `core` (a campaign's first
    /// survey; a pair's inputs): a corner that depends on the site, not on the files' exact
    /// extents, so a campaign's pairs and a `compare` of the same surveys share one local frame,
    /// one core-point grid and one key order, and their results are the same bits. The grid's
    /// origin is the lattice point just below the inputs.
    pub fn plan(
        bounds: &[Bounds],
        core: &Bounds,
        density: f64,
        params: &Params,
        tile_size: Option<f64>,
    ) -> Result<Layout> {
        let mut b = Bounds::empty();
        for x in bounds {
            b.grow(&x.min);
            b.grow(&x.max);
        }
        let c = params.core_spacing.value;
        let block = c * (ANCHOR_BLOCK / c).log2().ceil().exp2();
        let anchor = [
            (core.min[0] / block).floor() * block,
            (core.min[1] / block).floor() * block,
            (core.min[2] / block).floor() * block,
        ];
        // The lattice point at or just below the inputs' minimum.
        let lattice = |k: usize| anchor[k] + ((b.min[k] - anchor[k]) / c).floor() * c;
        let origin = [lattice(0), lattice(1)];
        let halo = tile_halo(params);
        let w = (b.max[0] - origin[0]).max(c);
        let h = (b.max[1] - origin[1]).max(c);
        let side = match tile_size {
            Some(s) if s > 0.0 => s,
            Some(s) => return Err(Error::Usage(format!("tile size must be positive, got {s}"))),
            None => TileGrid::plan(
                BoundsXY::new(origin, [origin[0] + w, origin[1] + h]),
                density,
                halo,
                params.memory_bytes.value,
                BYTES_PER_POINT,
            )?
            .tile_size(),
        };
        // Whole core cells per tile; at least one.
        let side = ((side / c).ceil().max(1.0)) * c;
        let cols = ((w / side).ceil().max(1.0)) as u32;
        let rows = ((h / side).ceil().max(1.0)) as u32;
        let layout = Layout {
            origin,
            tile_size: side,
            cols,
            rows,
            halo,
            anchor,
            core_spacing: c,
            extent: b,
        };
        layout.grid()?;
        Ok(layout)
    }

    /// The tile grid.
    pub fn grid(&self) -> Result<TileGrid> {
        Ok(TileGrid::new(
            self.origin,
            self.tile_size,
            self.cols,
            self.rows,
        )?)
    }

    /// A stable description for unit keys: everything a tile's content depends on.
    pub(crate) fn key(&self) -> String {
        format!(
            "{:?}|{}|{}|{}|{}|{:?}",
            self.origin, self.tile_size, self.cols, self.rows, self.halo, self.anchor
        )
    }

    /// Number of tiles.
    pub(crate) fn len(&self) -> usize {
        self.cols as usize * self.rows as usize
    }
}

/// The density (points per unit², the surveys held at once) to size tiles by: the one at which
/// a tile's halo box holds what the densest square of its size holds in `grid` (one
/// survey's, scaled to the `held` points a unit holds at once over the surveys it compares), and
/// never below the bounds' `mean`. A tile is then sized for where the points are, not for their average over the
/// bounds; where even the smallest tile (four halos) is denser than the budget allows, the
/// result keeps the tiles at that smallest side and the M3C2 units' check refuses the budget.
pub(crate) fn tile_density(grid: &DensityGrid, held: f64, mean: f64, params: &Params) -> f64 {
    let scale = held / grid.total().max(1) as f64;
    let halo = tile_halo(params);
    let allowed = TILE_BUDGET_FRACTION * params.memory_bytes.value as f64 / BYTES_PER_POINT as f64;
    let holds = |side: f64| scale * grid.densest(side + 2.0 * halo) as f64;
    let box_area = |side: f64| (side + 2.0 * halo).powi(2).max(f64::MIN_POSITIVE);
    // TileGrid::plan's smallest side.
    let least = (4.0 * halo).max(f64::MIN_POSITIVE);
    if held <= allowed {
        return mean; // one tile holds it all
    }
    if holds(least) > allowed {
        return mean.max(holds(least) / box_area(least));
    }
    // The largest side whose box holds no more than allowed: `lo` does, `hi` does not (at the
    // grid's extent a square holds every point, more than allowed).
    let (mut lo, mut hi) = (least, 2.0 * least);
    while holds(hi) <= allowed {
        (lo, hi) = (hi, 2.0 * hi);
    }
    for _ in 0..40 {
        let mid = 0.5 * (lo + hi);
        if holds(mid) <= allowed {
            lo = mid;
        } else {
            hi = mid;
        }
    }
    mean.max(allowed / box_area(lo))
}

/// The halo of the tile files: how far beyond its square a tile must hold points so that every
/// neighbourhood a tile's M3C2 unit computes for the core points it owns is the one a whole-cloud
/// run sees (SPEC.md §3): the normal sphere and the M3C2 cylinder (inside its circumscribed
/// sphere). The orientation field's normals fit within it (`units::field::geometry`). The
/// DBSCAN `eps` is not in it: the events unit clusters the kept core points with its own halo,
/// so a changed `eps` must not cut the surveys again.
pub(crate) fn tile_halo(params: &Params) -> f64 {
    let nr = params.normal_radius.value;
    let cyl = (params.cyl_radius.value.powi(2) + params.cyl_halflen.value.powi(2)).sqrt();
    nr.max(cyl) + 2.0 * params.core_spacing.value
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::params::UserParams;

    /// A 2000 × 500 strip at 4 points per unit² with a 100 × 100 patch fifteen times denser, as
    /// a terrestrial scan's near range is: the tiles sized from the densest square hold no more than
    /// the budget allows there, where tiles sized from the mean would hold several times more.
    #[test]
    fn tiles_are_sized_for_the_densest_square_not_the_mean() {
        let user = UserParams {
            memory: Some("300MiB".into()),
            ..UserParams::default()
        };
        // Radii of a 0.25-unit spacing: a halo of about 8.5 units, the smallest tile 34 wide.
        let params = Params::resolve(&user, 0.25).unwrap();
        let halo = tile_halo(&params);
        let mut rng = crate::rng::Rng::new(1, 0);
        let mut uniform = || rng.uniform();
        let mut points = Vec::new();
        for _ in 0..4_000_000 {
            points.push([2000.0 * uniform(), 500.0 * uniform(), 0.0]);
        }
        for _ in 0..600_000 {
            points.push([1200.0 + 100.0 * uniform(), 200.0 + 100.0 * uniform(), 0.0]);
        }
        let mut b = Bounds::empty();
        b.grow(&[0.0, 0.0, 0.0]);
        b.grow(&[2000.0, 500.0, 1.0]);
        let mut counts = DensityGrid::new(&b);
        counts.add(&points);
        let n = points.len() as f64;
        // Two epochs held at once.
        let mean = 2.0 * n / (2000.0 * 500.0);
        let density = tile_density(&counts, 2.0 * n, mean, &params);
        let layout = Layout::plan(&[b], &b, density, &params, None).unwrap();
        // Sized by the search, not held at the smallest side.
        assert!(layout.tile_size > 4.0 * halo + params.core_spacing.value);
        let allowed =
            TILE_BUDGET_FRACTION * params.memory_bytes.value as f64 / BYTES_PER_POINT as f64;
        // The densest tile's halo box, counted exactly.
        let grid = layout.grid().unwrap();
        let densest = grid
            .tiles()
            .map(|t| {
                let (x0, y0) = (
                    layout.origin[0] + t.col as f64 * layout.tile_size - halo,
                    layout.origin[1] + t.row as f64 * layout.tile_size - halo,
                );
                let side = layout.tile_size + 2.0 * halo;
                let inside =
                    |p: &&Point3| p[0] >= x0 && p[0] < x0 + side && p[1] >= y0 && p[1] < y0 + side;
                2 * points.iter().filter(inside).count()
            })
            .max()
            .unwrap() as f64;
        assert!(
            densest <= allowed,
            "{densest} points in a tile, {allowed} allowed"
        );
        // The mean would have sized tiles that hold far more than allowed over the patch.
        let by_mean = Layout::plan(&[b], &b, mean, &params, None).unwrap();
        let side = by_mean.tile_size + 2.0 * halo;
        assert!(side > 100.0);
        let patch = 2.0 * 600_000.0 + 2.0 * 4.0 * (side * side - 10_000.0);
        assert!(patch > 2.0 * allowed, "{patch} vs {allowed}");
    }
}

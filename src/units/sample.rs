//! M3C2 of a pair of tilings at a sample of points: where the alignment is fitted (a lattice of
//! windows over the first survey, [`super::align`]) and where the user's stable areas are
//! measured (every point of the before survey inside their polygons, [`super::align`] and
//! [`super::stable`]). The sample is the same whatever the tile layout: its points are chosen by
//! where they lie and by hashes of their keys, every tile of the grid computes the ones it owns
//! over the points within reach of them, and the results come back in key order.

use super::{read_tile_near, Ctx, TilePoints};
use crate::error::Result;
use crate::events::stable::Sample;
use crate::geom::Point3;
use crate::m3c2::tile::compute;
use crate::m3c2::{Extent, Reach};
use crate::spatial::areas::Areas;

/// Where the sample's points lie.
pub enum Region<'a> {
    /// Rectangles [x0, y0, x1, y1].
    Windows(Vec<[f64; 4]>),
    /// The user's stable areas.
    Areas(&'a Areas),
}

impl Region<'_> {
    fn contains(&self, p: &Point3) -> bool {
        match self {
            Region::Windows(w) => w
                .iter()
                .any(|w| p[0] >= w[0] && p[0] < w[2] && p[1] >= w[1] && p[1] < w[3]),
            Region::Areas(a) => a.contains(p[0], p[1]),
        }
    }

    fn boxes(&self) -> Vec<[f64; 4]> {
        match self {
            Region::Windows(w) => w.clone(),
            Region::Areas(a) => a.boxes(),
        }
    }
}

/// Which points of the region are sampled.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Picks {
    /// The run's core points (the before survey thinned on the core grid), one in `n` by a
    /// hash of their keys.
    Cores(u64),
    /// Every point of the before survey, one in `n` by a hash of its coordinates (the user's
    /// stable areas: narrow transects hold few core points, and every measured height counts,
    /// as in a DEM of difference).
    Points(u64),
}

/// The key of a before point chosen by [`Picks::Points`]: a hash of its coordinates' bits, the
/// same in every tile that holds it.
fn point_key(p: &Point3) -> u64 {
    crate::rng::SplitMix64::new(
        p[0].to_bits() ^ p[1].to_bits().rotate_left(21) ^ p[2].to_bits().rotate_left(42),
    )
    .next_u64()
}

/// M3C2 between the tilings `tilings` (units holding the before and the after survey's tiles,
/// of surveys `surveys`) at the points `picks` chooses in `region`, with `params`: the samples
/// measured within the cylinder (a walked distance may be finished in another tile, so it is
/// left out), in key order, and how many points were computed.
pub fn sample(
    ctx: &Ctx,
    tilings: [usize; 2],
    surveys: [usize; 2],
    region: &Region,
    picks: Picks,
    params: &crate::m3c2::M3c2Params,
) -> Result<(Vec<Sample>, usize)> {
    let plan = ctx.plan;
    let (m0, m1) = (
        ctx.tiling_meta_of(tilings[0])?,
        ctx.tiling_meta_of(tilings[1])?,
    );
    // The densest tile of the two surveys first, as the M3C2 units check it: a budget that
    // cannot hold it is refused with the same words, whichever unit meets it first.
    let pair_points = super::m3c2::fit::pair_tile_points(plan, &m0, &m1)?;
    super::m3c2::fit::check_tiled(plan, &pair_points)?;
    let counts = [m0.tile_points, m1.tile_points];
    let grid = plan.layout.grid()?;
    let (b, a) = (
        &plan.surveys[surveys[0]].bounds,
        &plan.surveys[surveys[1]].bounds,
    );
    let boxes = region.boxes();
    // Every point a sampled point uses for its normal and its cylinder lies within `reach` of
    // the region: only those points are indexed, and each result is the one the whole tile
    // gives, at a fraction of the indexing.
    let reach = (params.cyl_radius.powi(2) + params.cyl_halflen.powi(2))
        .sqrt()
        .max(params.normal_radius)
        + plan.layout.core_spacing;
    let mut keyed: Vec<(u64, Sample)> = Vec::new();
    let mut computed = 0;
    for tile in grid.tiles() {
        let sq = grid.square(tile);
        // The region's boxes meeting the tile, grown by `reach`.
        let near: Vec<[f64; 4]> = boxes
            .iter()
            .filter(|w| {
                w[0] <= sq.max[0] && sq.min[0] <= w[2] && w[1] <= sq.max[1] && sq.min[1] <= w[3]
            })
            .map(|w| [w[0] - reach, w[1] - reach, w[2] + reach, w[3] + reach])
            .collect();
        let n = counts[0][grid.index(tile)] + counts[1][grid.index(tile)];
        if near.is_empty() || n == 0 {
            continue;
        }
        let _held = ctx.reserve(
            super::m3c2::need(n),
            &format!(
                "a sample of M3C2: tile {} ({n} points with its halo)",
                tile.name()
            ),
        )?;
        // Only the frames that reach the boxes or their neighbourhoods: every point `within`
        // keeps and every point of a core-point cell in a box is in them.
        let reached: Vec<[f64; 4]> = near.iter().chain(&boxes).copied().collect();
        let before = read_tile_near(ctx, tilings[0], tile, &reached)?;
        let after = read_tile_near(ctx, tilings[1], tile, &reached)?;
        let extent = Extent {
            data_min: std::array::from_fn(|k| b.min[k].min(a.min[k])),
            data_max: std::array::from_fn(|k| b.max[k].max(a.max[k])),
            held: super::m3c2::open_box(&grid, tile, plan.layout.halo),
        };
        let cores: Vec<(u64, Point3)> = match picks {
            Picks::Cores(n) => crate::m3c2::core_points::thin(
                before.len(),
                |i| before.point(i),
                &plan.layout.anchor,
                plan.layout.core_spacing,
                |i| before.owned[i],
            )
            .into_iter()
            .map(|(k, i)| (k, before.point(i)))
            .filter(|(k, p)| region.contains(p) && Areas::takes(*k, n))
            .collect(),
            Picks::Points(n) => {
                let mut c: Vec<(u64, Point3)> = (0..before.len())
                    .filter(|&i| before.owned[i])
                    .map(|i| before.point(i))
                    .filter(|p| region.contains(p))
                    .map(|p| (point_key(&p), p))
                    .filter(|(k, _)| Areas::takes(*k, n))
                    .collect();
                // A point held twice (a survey's duplicate) is sampled once.
                c.sort_by(|x, y| {
                    x.0.cmp(&y.0)
                        .then(x.1.map(f64::to_bits).cmp(&y.1.map(f64::to_bits)))
                });
                c.dedup_by_key(|x| x.0);
                c
            }
        };
        if cores.is_empty() {
            continue;
        }
        let (before, after) = (within(&before, &near), within(&after, &near));
        let results = compute(
            &before.epoch(),
            &after.epoch(),
            plan.layout.anchor,
            plan.layout.core_spacing,
            Some(&cores),
            params,
            &extent,
            None,
        );
        computed += results.len();
        keyed.extend(
            results
                .iter()
                .filter(|k| k.r.reach == Reach::Window && k.r.measured().is_finite())
                .map(|k| {
                    (
                        k.key,
                        Sample {
                            xyz: k.xyz,
                            normal: k.r.normal,
                            distance: k.r.measured(),
                            std_dev: [k.r.std_dev1, k.r.std_dev2],
                            lod: k.r.uncertainty,
                        },
                    )
                }),
        );
        crate::interrupt::check()?;
    }
    // Key order: the same whatever order the tiles came in.
    keyed.sort_by_key(|(k, _)| *k);
    Ok((keyed.into_iter().map(|(_, s)| s).collect(), computed))
}

/// The points of `t` inside any of `boxes` ([x0, y0, x1, y1]), in their order.
fn within(t: &TilePoints, boxes: &[[f64; 4]]) -> TilePoints {
    let keep: Vec<usize> = (0..t.len())
        .filter(|&i| {
            let (x, y) = (t.x[i], t.y[i]);
            boxes
                .iter()
                .any(|b| x >= b[0] && x <= b[2] && y >= b[1] && y <= b[3])
        })
        .collect();
    TilePoints {
        x: keep.iter().map(|&i| t.x[i]).collect(),
        y: keep.iter().map(|&i| t.y[i]).collect(),
        z: keep.iter().map(|&i| t.z[i]).collect(),
        owned: keep.iter().map(|&i| t.owned[i]).collect(),
    }
}

//! M3C2 of a pair of tilings at a sample of points: where the alignment is fitted (a lattice of
//! windows over the first survey, [`super::align`]) and where the user's stable areas are
//! measured (every point of the before survey inside their polygons, [`super::align`] and
//! [`super::stable`]). The sample is the same whatever the tile layout: its points are chosen by
//! where they lie and by hashes of their keys, every tile of the grid computes the ones it owns
//! over the points within reach of them, and the results come back in key order.

use super::{read_tile_near, Ctx, TilePoints, Tiles};
use crate::error::Result;
use crate::events::stable::Sample;
use crate::geom::Point3;
use crate::m3c2::{window, Reach};
use crate::spatial::areas::Areas;
use talus_tiling::TileId;

/// Where the sample's points lie.
pub(crate) enum Region<'a> {
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
pub(crate) enum Picks {
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

/// The tiling record of `tiles`, which must hold a survey's tiles.
fn held(ctx: &Ctx, tiles: &Tiles) -> Result<super::tiling::TilingMeta> {
    ctx.tiles_meta(tiles)?
        .ok_or_else(|| crate::error::Error::Internal(format!("units {:?} hold no tiles", tiles.0)))
}

/// M3C2 between the tilings `tilings` (units holding the before and the after survey's tiles) at the points `picks` chooses in `region`, with `params`: the samples
/// measured within the cylinder (a walked distance may be finished in another tile, so it is
/// left out), in key order, and how many points were computed. The before survey's half of it
/// ([`crate::m3c2::window`]) is computed once per process for every after survey sampled against
/// it ([`Reference`]).
pub(crate) fn sample(
    ctx: &Ctx,
    tilings: [&Tiles; 2],
    region: &Region,
    picks: Picks,
    params: &crate::m3c2::M3c2Params,
) -> Result<(Vec<Sample>, usize)> {
    let plan = ctx.plan;
    let (m0, m1) = (held(ctx, tilings[0])?, held(ctx, tilings[1])?);
    // The densest tile of the two surveys first, as the M3C2 units check it: a budget that
    // cannot hold it is refused with the same words, whichever unit meets it first.
    let pair_points = super::m3c2::fit::pair_tile_points(plan, &m0, &m1)?;
    super::m3c2::fit::check_tiled(plan, &pair_points)?;
    let counts = [m0.tile_points, m1.tile_points];
    let reference = Reference::of(ctx, tilings[0], &counts, region, picks, params)?;
    let mut keyed: Vec<(u64, Sample)> = Vec::new();
    let mut computed = 0;
    for part in reference.tiles.iter() {
        let n = counts[0][part.index] + counts[1][part.index];
        let _held = ctx.reserve(
            super::m3c2::need(n),
            &format!(
                "a sample of M3C2: tile {} ({n} points with its halo)",
                part.tile.name()
            ),
        )?;
        let after = read_tile_near(ctx, tilings[1], part.tile, &part.reached)?;
        let after = within(&after, &part.near);
        let results = window::against(&part.half, &after.epoch(), plan.layout.anchor, params);
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

/// The before survey's half of a sample: per tile holding sampled points, its core points'
/// normals and C1 ([`window::BeforeHalf`]), and which of the after survey's points the tile
/// needs. It depends on the before tiling, the region, the picks and the parameters only, so
/// every later survey sampled against the first (`super::align`: one align unit a survey) shares
/// it: the process keeps the last one made ([`MEMO`]), found again by a key of all it depends on.
struct Reference {
    tiles: Vec<ReferenceTile>,
}

struct ReferenceTile {
    tile: TileId,
    /// The tile's index in the grid (its point counts).
    index: usize,
    /// The region's boxes meeting the tile, grown by the reach: the points the sample uses.
    near: Vec<[f64; 4]>,
    /// `near` and the boxes: the frames a read needs.
    reached: Vec<[f64; 4]>,
    half: window::BeforeHalf,
}

/// The [`Reference`]s last used in this process, with their keys, most recent last. A campaign's
/// align units sample every later survey against the first (and, with the user's stable areas,
/// in the areas and in the windows: two references). They outlive the unit that made them, so
/// they are not reserved from the pool: at most [`MEMO_BYTES`] in all (a sample of about
/// [`super::align::SAMPLE_CORES`] core points; a larger one is made again each time, when it is
/// a small part of its survey's M3C2), within what [`crate::memory::BASE`] leaves above the
/// process's measured base.
static MEMO: std::sync::Mutex<Vec<(String, std::sync::Arc<Reference>)>> =
    std::sync::Mutex::new(Vec::new());

/// What [`MEMO`] holds at most.
const MEMO_BYTES: u64 = 4 << 20;

impl Reference {
    /// The reference of before tiling `tiling` (points per tile `counts[0]`) for `region`,
    /// `picks` and `params`: the memo's when it has it, else made (and memoised when small).
    fn of(
        ctx: &Ctx,
        tiling: &Tiles,
        counts: &[Vec<u64>; 2],
        region: &Region,
        picks: Picks,
        params: &crate::m3c2::M3c2Params,
    ) -> Result<std::sync::Arc<Reference>> {
        let plan = ctx.plan;
        let boxes = region.boxes();
        let key = crate::plan::key_of(&[
            &tiling.key(plan),
            &format!("{:?}", plan.layout),
            &format!("{params:?}"),
            &format!("{picks:?}"),
            &format!(
                "{:?}",
                boxes
                    .iter()
                    .flatten()
                    .map(|v| v.to_bits())
                    .collect::<Vec<_>>()
            ),
            &match region {
                Region::Windows(_) => String::new(),
                Region::Areas(_) => super::stable::areas_key(plan),
            },
        ]);
        let memo = || MEMO.lock().unwrap_or_else(|e| e.into_inner());
        {
            let mut m = memo();
            if let Some(at) = m.iter().position(|(k, _)| *k == key) {
                let hit = m.remove(at);
                let r = hit.1.clone();
                m.push(hit);
                return Ok(r);
            }
        }
        let made = std::sync::Arc::new(Self::make(ctx, tiling, counts, region, picks, params)?);
        if made.bytes() <= MEMO_BYTES {
            let mut m = memo();
            // Two units may have made the same one at once: kept once.
            m.retain(|(k, _)| *k != key);
            m.push((key, made.clone()));
            while m.iter().map(|(_, r)| r.bytes()).sum::<u64>() > MEMO_BYTES {
                m.remove(0);
            }
        }
        Ok(made)
    }

    /// What it holds in memory, about.
    fn bytes(&self) -> u64 {
        self.tiles.iter().map(|t| t.half.bytes()).sum()
    }

    fn make(
        ctx: &Ctx,
        tiling: &Tiles,
        counts: &[Vec<u64>; 2],
        region: &Region,
        picks: Picks,
        params: &crate::m3c2::M3c2Params,
    ) -> Result<Reference> {
        let plan = ctx.plan;
        let grid = plan.layout.grid()?;
        let boxes = region.boxes();
        // Every point a sampled point uses for its normal and its cylinder lies within `reach`
        // of the region: only those points are indexed, and each result is the one the whole
        // tile gives, at a fraction of the indexing.
        let reach = (params.cyl_radius.powi(2) + params.cyl_halflen.powi(2))
            .sqrt()
            .max(params.normal_radius)
            + plan.layout.core_spacing;
        let mut tiles = Vec::new();
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
            let index = grid.index(tile);
            let n = counts[0][index] + counts[1][index];
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
            let before = read_tile_near(ctx, tiling, tile, &reached)?;
            let cores = picked(&before, region, picks, plan);
            if cores.is_empty() {
                continue;
            }
            let before = within(&before, &near);
            let half = window::before_half(&before.epoch(), plan.layout.anchor, &cores, params);
            tiles.push(ReferenceTile {
                tile,
                index,
                near,
                reached,
                half,
            });
            crate::interrupt::check()?;
        }
        Ok(Reference { tiles })
    }
}

/// The before points of a tile `picks` chooses in `region`, with their keys.
fn picked(
    before: &TilePoints,
    region: &Region,
    picks: Picks,
    plan: &crate::plan::Plan,
) -> Vec<(u64, Point3)> {
    match picks {
        Picks::Cores(n) => before
            .epoch()
            .core_points(&plan.layout.anchor, plan.layout.core_spacing)
            .into_iter()
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
    }
}

/// The points of `t` inside any of `boxes` ([x0, y0, x1, y1]), in their order.
fn within(t: &TilePoints, boxes: &[[f64; 4]]) -> TilePoints {
    let inside = |b: &[f64; 4], x: f64, y: f64| x >= b[0] && x <= b[2] && y >= b[1] && y <= b[3];
    // A tile's points come in spatially coherent frames: the box that held the last point most
    // often holds the next (the sample's 64 windows, grown by the reach, were tested in turn).
    let mut last = 0;
    let keep: Vec<usize> = (0..t.len())
        .filter(|&i| {
            let (x, y) = (t.x[i], t.y[i]);
            if boxes.get(last).is_some_and(|b| inside(b, x, y)) {
                return true;
            }
            match boxes.iter().position(|b| inside(b, x, y)) {
                Some(k) => {
                    last = k;
                    true
                }
                None => false,
            }
        })
        .collect();
    TilePoints {
        x: keep.iter().map(|&i| t.x[i]).collect(),
        y: keep.iter().map(|&i| t.y[i]).collect(),
        z: keep.iter().map(|&i| t.z[i]).collect(),
        owned: keep.iter().map(|&i| t.owned[i]).collect(),
    }
}

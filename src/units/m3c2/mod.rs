//! An M3C2 unit: normals and M3C2 for the core points one tile owns, for one pair (pass 2 of
//! SPEC.md §3), from the pair's two tilings (and the user's core points, `super::cores`). Results are
//! written as chunk files sorted by core-point key; [`Merged`] streams a pair's results in global
//! key order (a k-way merge over the tiles), so everything downstream is the same whatever the
//! tiling.

use std::path::PathBuf;

use talus_tiling::{Column, ColumnData, TileColumns, TileId};

pub(crate) mod fit;
mod merge;
pub(crate) mod seek;

pub(crate) use merge::merge_need;
pub use merge::Merged;

use super::cores::{ThinnedStage, UserCoresStage};
use super::stage::{Line, Planner, Scope, Stage, Total};
use super::{read_tile, Ctx, TilePoints, Tiles};
use crate::error::{Error, Result};
use crate::io::Point3;
use crate::m3c2::tile::{compute, distances_along, KeyedResult};
use crate::m3c2::{CoreResult, Extent, Reach};
use crate::plan::Spec;
use crate::spatial::Tubes;
use crate::store::UnitWriter;

/// Rows per result chunk file: a merge holds one chunk per tile.
pub(crate) const CHUNK_ROWS: usize = 8192;

/// The file of chunk `k`.
pub(crate) fn chunk_file(k: usize) -> String {
    format!("r_{k:05}.tile")
}

/// Resident bytes per point while a tile is computed: the layout sizes tiles by it.
pub(crate) const BYTES_PER_POINT: u64 = crate::plan::layout::BYTES_PER_POINT;

/// Resident bytes of an M3C2 unit over `points` points.
pub fn need(points: u64) -> u64 {
    points * BYTES_PER_POINT + crate::memory::HEADROOM
}

/// Normals and M3C2 for the core points one tile owns, for one pair.
pub(crate) struct M3c2Stage;

/// What an M3C2 unit records.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub(crate) struct M3c2Meta {
    /// Result chunk files ([`chunk_file`]).
    pub(crate) chunks: usize,
    /// Core points the tile owns (rows over its chunks).
    pub(crate) core_points: u64,
    /// Points the tile owns, both surveys.
    pub(crate) points: u64,
    /// Points of both surveys in the tile's halo box.
    pub(crate) halo_points: u64,
    /// Core points whose walk left the tile, walked again over the points along their axes.
    pub(crate) walked_beyond_tile: usize,
    /// Points gathered along those axes.
    pub(crate) points_along: usize,
    /// Core points whose missing survey was measured beyond the cylinder ([`Reach::Extended`]).
    pub(crate) extended: usize,
    /// Core points whose other survey lies beyond the user's half-length.
    pub(crate) beyond_reach: usize,
}

impl Stage for M3c2Stage {
    const KIND: &'static str = "m3c2";
    const SCOPE: Scope = Scope::Tile;
    const VERSION: u32 = 4;
    const INTERMEDIATE: bool = true;
    const LINE: Line = Line {
        name: "pass 2: normals and M3C2",
        counts: "points",
        total: Total::PairPoints,
    };
    type Meta = M3c2Meta;

    /// An M3C2 unit per pair and tile, reading the pair's two tilings and the run's core points
    /// (the user's, a campaign's, or none: the before survey thinned inside the unit).
    fn plan(p: &mut Planner) -> Result<()> {
        let grid = p.plan.layout.grid()?;
        let m3c2 = format!(
            "{:?}|{}",
            p.plan.params.m3c2(),
            p.plan.params.core_spacing.value
        );
        let core_unit = p.core_unit();
        let cores = cores_key(core_unit);
        for pair in 0..p.plan.pairs.len() {
            fit::check_planned(p.plan, pair)?;
            let (b, a) = (p.plan.pairs[pair].before, p.plan.pairs[pair].after);
            let mut deps = p.survey_tiles(b)?;
            deps.extend(p.survey_tiles(a)?);
            deps.extend(core_unit);
            deps.extend(p.find(&Spec::survey(super::orient::OrientStage::KIND, b)));
            let label = p.plan.pairs[pair].label.clone();
            for t in grid.tiles() {
                p.add(
                    Spec::tile(Self::KIND, pair, t),
                    &format!("{label}-{}", t.name()),
                    &[&m3c2, cores],
                    deps.clone(),
                );
            }
        }
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<M3c2Meta> {
        run(ctx, unit, out)
    }
}

/// Where the core points come from, as the M3C2 and outputs units' keys say it: a core-point
/// unit's (its key is a dependency's), or each M3C2 unit's own thinning of the before survey.
pub(crate) fn cores_key(core_unit: Option<usize>) -> &'static str {
    match core_unit {
        Some(_) => "core-point unit",
        None => "thinned C1",
    }
}

/// Compute unit `unit` (a tile of a pair) into `out`.
fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<M3c2Meta> {
    let plan = ctx.plan;
    let (pair, tile) = (ctx.pair(unit)?, ctx.tile(unit)?);
    let p = &plan.pairs[pair];
    let ((tb, mb), (ta, ma)) = (ctx.tiles(p.before)?, ctx.tiles(p.after)?);
    // The pair's densest tile first: a budget that cannot hold it is refused by whichever M3C2
    // unit runs first, not after the tiles before it.
    let points = fit::pair_tile_points(plan, &mb, &ma)?;
    fit::check_tiled(plan, &points)?;
    let halo_points = points[plan.layout.grid()?.index(tile)];
    let _held = ctx.reserve(
        need(halo_points),
        &format!("tile {} ({halo_points} points with its halo)", tile.name()),
    )?;
    let (before, after) = std::thread::scope(|s| {
        // Both epochs at once: decompressing a tile is one thread's work.
        let a = s.spawn(|| read_tile(ctx, &ta, tile));
        let b = read_tile(ctx, &tb, tile);
        let a = a
            .join()
            .unwrap_or_else(|_| Err(Error::Internal("a tile reader panicked".into())));
        (b, a)
    });
    let (before, after) = (before?, after?);
    let core_unit = ctx
        .dep::<UserCoresStage>(unit)
        .or_else(|| ctx.dep::<ThinnedStage>(unit));
    let user_cores = match core_unit {
        Some(c) => Some(super::cores::read(ctx, c, tile)?),
        None => None,
    };
    let extent = tile_extent(plan, pair, tile)?;
    let params = plan.params.m3c2();
    let field = super::orient::read_near(ctx, pair, extent.held, plan.layout.anchor)?;
    let mut results = compute(
        &before.epoch(),
        &after.epoch(),
        plan.layout.anchor,
        plan.layout.core_spacing,
        user_cores.as_deref(),
        &params,
        &extent,
        field.as_ref(),
    );
    drop(field);
    let owned = |t: &TilePoints| t.owned.iter().filter(|&&o| o).count() as u64;
    let points = owned(&before) + owned(&after);
    // Core points whose walk left the tile: walked again over the points along their axes.
    let pending: Vec<usize> = (0..results.len())
        .filter(|&i| results[i].r.reach == Reach::Pending)
        .collect();
    let mut along = 0;
    if !pending.is_empty() {
        let wanted: Vec<KeyedResult> = pending.iter().map(|&i| results[i]).collect();
        let [b, a] = gather_along(
            ctx,
            [&tb, &ta],
            tile,
            [&before, &after],
            &wanted,
            &params,
            &extent,
        )?;
        along = b.len() + a.len();
        drop((before, after));
        let done = distances_along(&b, &a, plan.layout.anchor, &wanted, &params, &extent);
        for (&i, r) in pending.iter().zip(done) {
            results[i] = r;
        }
    }
    let chunks = write_chunks(out, &results, &chunk_options(ctx)?)?;
    (ctx.progress)(points);
    let count = |reach: Reach| results.iter().filter(|k| k.r.reach == reach).count();
    Ok(M3c2Meta {
        chunks,
        core_points: results.len() as u64,
        points,
        halo_points,
        extended: count(Reach::Extended),
        beyond_reach: count(Reach::Beyond),
        walked_beyond_tile: pending.len(),
        points_along: along,
    })
}

/// Where the walks of tile `tile`'s core points may look (global coordinates): the pair's
/// surveys' bounds, and the tile's halo box.
fn tile_extent(plan: &crate::plan::Plan, pair: usize, tile: TileId) -> Result<Extent> {
    let p = &plan.pairs[pair];
    let (b, a) = (
        &plan.surveys[p.before].bounds,
        &plan.surveys[p.after].bounds,
    );
    let grid = plan.layout.grid()?;
    Ok(Extent {
        data_min: std::array::from_fn(|k| b.min[k].min(a.min[k])),
        data_max: std::array::from_fn(|k| b.max[k].max(a.max[k])),
        held: open_box(&grid, tile, plan.layout.halo),
    })
}

/// Tile `id`'s square grown by `grow`, [x0, y0, x1, y1], open at the grid's edges: a tile file
/// holds its halo box, and an edge tile every point beyond the grid (they are clamped onto it).
pub(super) fn open_box(grid: &talus_tiling::TileGrid, id: TileId, grow: f64) -> [f64; 4] {
    let h = grid.halo_box(id, grow);
    let open = |edge: bool, v: f64, inf: f64| if edge { inf } else { v };
    [
        open(id.col == 0, h.min[0], f64::NEG_INFINITY),
        open(id.row == 0, h.min[1], f64::NEG_INFINITY),
        open(id.col + 1 == grid.cols(), h.max[0], f64::INFINITY),
        open(id.row + 1 == grid.rows(), h.max[1], f64::INFINITY),
    ]
}

/// Every point of both epochs (owned by its tile: each once) within the cylinder's radius of
/// the axes of `wanted`'s core points, out to the data's bounds: this tile's from `own`, the
/// others' read a frame at a time from the tilings `tilings`.
fn gather_along(
    ctx: &Ctx,
    tilings: [&Tiles; 2],
    tile: TileId,
    own: [&TilePoints; 2],
    wanted: &[KeyedResult],
    params: &crate::m3c2::M3c2Params,
    extent: &Extent,
) -> Result<[Vec<Point3>; 2]> {
    let r = params.cyl_radius;
    // Each axis as the segment the walk can cover, in global coordinates.
    let axes: Vec<(Point3, Point3, f64, f64)> = wanted
        .iter()
        .map(|k| {
            let (lo, hi) = extent.axis_limits(&k.xyz, &k.r.normal, r);
            (k.xyz, k.r.normal, lo, hi)
        })
        .collect();
    let tubes = Tubes::new(&axes, r);
    // Wider than the walk's exact test by far more than any rounding: a superset is harmless,
    // the walk tests every point again.
    let slack = 1e-6 * (1.0 + r);
    let near = |p: &Point3| tubes.any_holds(p, slack);
    // The frames read are those reaching the axes' bounds grown by the same slack, so that
    // which points `near` sees never depends on where a tile file's frames end.
    let xy = {
        let b = tubes.xy_bounds();
        [b[0] - slack, b[1] - slack, b[2] + slack, b[3] + slack]
    };
    let mut out = [Vec::new(), Vec::new()];
    let grid = ctx.plan.layout.grid()?;
    for id in grid.tiles() {
        // The points the tile owns lie in its square (beyond it at the grid's edges).
        let sq = open_box(&grid, id, 0.0);
        if sq[2] < xy[0] || sq[0] > xy[2] || sq[3] < xy[1] || sq[1] > xy[3] {
            continue;
        }
        for (e, &tiling) in tilings.iter().enumerate() {
            if id == tile {
                let t = own[e];
                out[e].extend(
                    (0..t.len())
                        .filter(|&i| t.owned[i])
                        .map(|i| t.point(i))
                        .filter(|p| near(p)),
                );
                continue;
            }
            // The frames that reach the walks' plan bounds only, a frame held at a time.
            super::for_each_frame_near(ctx, tiling, id, &[xy], |t| {
                out[e].extend(
                    (0..t.len())
                        .filter(|&i| t.owned[i])
                        .map(|i| t.point(i))
                        .filter(|p| near(p)),
                );
            })?;
        }
    }
    Ok(out)
}

/// How result chunks are encoded: the core points' coordinates as the integers of the first
/// survey's coordinate transform, where the core points come from (its thinned tiles, or a
/// campaign's thinned first survey). Exact or not at all: an axis whose values do not all come
/// back bit for bit stays f64 (user core points, an aligned frame), so the results read back
/// are the same either way. 6 bytes less a core point than f64 coordinates (of ≈ 61; issue 46,
/// the peak disk of a run holds every tile's results).
pub(crate) fn chunk_options(ctx: &Ctx) -> Result<talus_tiling::WriteOptions> {
    Ok(super::tiling::write_options(ctx.quantum(0)?))
}

/// Write `results` as chunk files of [`CHUNK_ROWS`] rows; returns how many. Chunks are encoded in
/// parallel, a group at a time (the encoded bytes of a group are held until written), and
/// written plainly: the unit's commit makes them durable.
fn write_chunks(
    out: &mut UnitWriter,
    results: &[KeyedResult],
    opts: &talus_tiling::WriteOptions,
) -> Result<usize> {
    const GROUP: usize = 16;
    let parts: Vec<&[KeyedResult]> = results.chunks(CHUNK_ROWS).collect();
    for (g, group) in parts.chunks(GROUP).enumerate() {
        for (i, bytes) in encode_chunks(group, opts)?.into_iter().enumerate() {
            super::write_bytes(out, &chunk_file(g * GROUP + i), &bytes)?;
        }
    }
    Ok(parts.len())
}

/// Result chunks encoded as chunk files' bytes, in parallel.
pub(crate) fn encode_chunks<C: AsRef<[KeyedResult]> + Sync>(
    chunks: &[C],
    opts: &talus_tiling::WriteOptions,
) -> Result<Vec<Vec<u8>>> {
    use rayon::prelude::*;
    chunks
        .par_iter()
        .map(|part| {
            talus_tiling::encode_tile(&to_columns(part.as_ref()), opts)
                .map_err(|p| Error::Internal(format!("a result chunk: {p}")))
        })
        .collect()
}

fn f64col(name: &str, v: Vec<f64>) -> Column {
    Column {
        name: name.into(),
        data: ColumnData::F64(v),
    }
}

/// A measured quantity stored as f32: a distance, a spread or a normal's component (see
/// [`to_columns`]).
fn f32col(name: &str, v: Vec<f32>) -> Column {
    Column {
        name: name.into(),
        data: ColumnData::F32(v),
    }
}

fn u32col(name: &str, v: Vec<u32>) -> Column {
    Column {
        name: name.into(),
        data: ColumnData::U32(v),
    }
}

/// A chunk's columns. The measured quantities (distance, the two spreads, the normal) are
/// stored as f32: 7 significant digits, 0.06 µm at a 1 m distance, far below what any survey
/// resolves (m3c2.laz has always stored distances so), where f64 noise in the low bytes
/// compresses to nothing and made the results 57 bytes a core point, most of a run's peak disk
/// (issue 46). The uncertainty stays f64: the LoD adds the registration error to it later, and
/// m3c2.laz's float32 LoD is that sum rounded once, as the in-memory route (Python) rounds it.
/// Every reader of the results sees the stored values, so a run's outputs are the same however
/// its units were scheduled.
fn to_columns(rs: &[KeyedResult]) -> TileColumns {
    let col = |f: &dyn Fn(&KeyedResult) -> f64| rs.iter().map(f).collect::<Vec<f64>>();
    let narrow = |f: &dyn Fn(&KeyedResult) -> f64| rs.iter().map(|r| f(r) as f32).collect();
    TileColumns {
        x: col(&|r| r.xyz[0]),
        y: col(&|r| r.xyz[1]),
        z: col(&|r| r.xyz[2]),
        extra: vec![
            u32col("key_hi", rs.iter().map(|r| (r.key >> 32) as u32).collect()),
            u32col("key_lo", rs.iter().map(|r| r.key as u32).collect()),
            f32col("distance", narrow(&|r| r.r.distance)),
            f64col("uncertainty", col(&|r| r.r.uncertainty)),
            Column {
                name: "significant".into(),
                data: ColumnData::U8(rs.iter().map(|r| r.r.significant as u8).collect()),
            },
            f32col("std_dev1", narrow(&|r| r.r.std_dev1)),
            f32col("std_dev2", narrow(&|r| r.r.std_dev2)),
            u32col("count1", rs.iter().map(|r| r.r.count1).collect()),
            u32col("count2", rs.iter().map(|r| r.r.count2).collect()),
            f32col("normal_x", narrow(&|r| r.r.normal[0])),
            f32col("normal_y", narrow(&|r| r.r.normal[1])),
            f32col("normal_z", narrow(&|r| r.r.normal[2])),
            Column {
                name: "reach".into(),
                data: ColumnData::U8(rs.iter().map(|r| r.r.reach as u8).collect()),
            },
            Column {
                name: "sign_known".into(),
                data: ColumnData::U8(rs.iter().map(|r| r.r.sign_known as u8).collect()),
            },
        ],
    }
}

/// Read one result chunk back.
pub(crate) fn read_chunk(path: &std::path::Path) -> Result<Vec<KeyedResult>> {
    let c = talus_tiling::read_tile(path).map_err(|e| super::damaged(path, e))?;
    let missing = |name: &str| Error::Damaged {
        path: path.to_path_buf(),
        problem: format!("no column {name}"),
    };
    let f = |name: &str| -> Result<&Vec<f32>> {
        match c.column(name) {
            Some(ColumnData::F32(v)) => Ok(v),
            _ => Err(missing(name)),
        }
    };
    let u = |name: &str| -> Result<&Vec<u32>> {
        match c.column(name) {
            Some(ColumnData::U32(v)) => Ok(v),
            _ => Err(missing(name)),
        }
    };
    let bytes = |name: &str| -> Result<&Vec<u8>> {
        match c.column(name) {
            Some(ColumnData::U8(v)) => Ok(v),
            _ => Err(missing(name)),
        }
    };
    let (sig, reach, known) = (bytes("significant")?, bytes("reach")?, bytes("sign_known")?);
    let (hi, lo) = (u("key_hi")?, u("key_lo")?);
    let unc = match c.column("uncertainty") {
        Some(ColumnData::F64(v)) => v,
        _ => return Err(missing("uncertainty")),
    };
    let (d, s1, s2) = (f("distance")?, f("std_dev1")?, f("std_dev2")?);
    let (n1, n2) = (u("count1")?, u("count2")?);
    let (nx, ny, nz) = (f("normal_x")?, f("normal_y")?, f("normal_z")?);
    (0..c.len())
        .map(|i| {
            Ok(KeyedResult {
                key: (hi[i] as u64) << 32 | lo[i] as u64,
                xyz: [c.x[i], c.y[i], c.z[i]],
                r: CoreResult {
                    distance: d[i].into(),
                    uncertainty: unc[i],
                    significant: sig[i] == 1,
                    std_dev1: s1[i].into(),
                    std_dev2: s2[i].into(),
                    count1: n1[i],
                    count2: n2[i],
                    normal: [nx[i].into(), ny[i].into(), nz[i].into()],
                    reach: Reach::from_code(reach[i]).ok_or_else(|| Error::Damaged {
                        path: path.to_path_buf(),
                        problem: format!("reach code {} at row {i}", reach[i]),
                    })?,
                    sign_known: known[i] == 1,
                },
            })
        })
        .collect::<Result<_>>()
}

/// The chunk files of a pair's M3C2 units, per tile in grid order.
pub(crate) fn pair_chunks(ctx: &Ctx, pair: usize) -> Result<Vec<Vec<PathBuf>>> {
    match ctx
        .plan
        .find(&Spec::pair(super::merged::MergedStage::KIND, pair))
    {
        Some(u) => {
            let runs = ctx.meta::<super::merged::MergedStage>(u)?.runs;
            runs.iter()
                .enumerate()
                .map(|(r, &n)| {
                    (0..n)
                        .map(|k| ctx.input(u, &super::merged::run_file(r, k)))
                        .collect()
                })
                .collect()
        }
        None => tile_chunks(ctx, pair),
    }
}

/// The chunk files of each of pair `pair`'s M3C2 units, in grid order.
pub(crate) fn tile_chunks(ctx: &Ctx, pair: usize) -> Result<Vec<Vec<PathBuf>>> {
    let grid = ctx.plan.layout.grid()?;
    grid.tiles()
        .map(|t| {
            let u = ctx.unit(&Spec::tile(M3c2Stage::KIND, pair, t))?;
            let n = ctx.meta::<M3c2Stage>(u)?.chunks;
            (0..n).map(|k| ctx.input(u, &chunk_file(k))).collect()
        })
        .collect()
}

/// How many core points a pair's M3C2 units hold, from their records.
pub(crate) fn pair_count(ctx: &Ctx, pair: usize) -> Result<u64> {
    let grid = ctx.plan.layout.grid()?;
    let mut n = 0;
    for t in grid.tiles() {
        let u = ctx.unit(&Spec::tile(M3c2Stage::KIND, pair, t))?;
        n += ctx.meta::<M3c2Stage>(u)?.core_points;
    }
    Ok(n)
}

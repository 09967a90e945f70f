//! An M3C2 unit: normals and M3C2 for the core points one tile owns, for one pair (pass 2 of
//! SPEC.md §3), from the pair's two tilings (and the user's core points, [`cores`]). Results are
//! written as chunk files sorted by core-point key; [`Merged`] streams a pair's results in global
//! key order (a k-way merge over the tiles), so everything downstream is the same whatever the
//! tiling.

use std::cmp::Reverse;
use std::collections::BinaryHeap;
use std::path::PathBuf;

use talus_tiling::{Column, ColumnData, TileColumns, TileId};

use super::{meta_u64, read_tile, Ctx, TilePoints};
use crate::error::{Error, Result};
use crate::io::Point3;
use crate::m3c2::tile::{compute, distances_along, EpochPoints, KeyedResult};
use crate::m3c2::{CoreResult, Extent, Reach};
use crate::plan::Spec;
use crate::spatial::Tubes;
use crate::store::UnitWriter;

/// Rows per result chunk file: a merge holds one chunk per tile.
pub const CHUNK_ROWS: usize = 8192;

/// The file of chunk `k`.
pub fn chunk_file(k: usize) -> String {
    format!("r_{k:05}.tile")
}

/// Resident bytes per point (both epochs, halo included) while a tile is computed: its
/// coordinates and owned flags as read (25), the column index (≈ 40), the per-core-point results
/// (a core point per ≈ 7 points, ≈ 120 each) and the tile file's bytes while decoding. Measured
/// 89–101 bytes per point (unit peak less the process's base, over the tile's points with its
/// halo) on the 5.2M-point cliff's tiles at 300 MiB and 1 GiB. The tile layout sizes tiles by it.
pub const BYTES_PER_POINT: u64 = 104;

/// Resident bytes of an M3C2 unit over `points` points.
pub fn need(points: u64) -> u64 {
    points * BYTES_PER_POINT + (4 << 20)
}

/// Compute tile `tile` of unit `unit`'s pair into `out`.
pub fn run(
    ctx: &Ctx,
    unit: usize,
    tile: TileId,
    out: &mut UnitWriter,
) -> Result<serde_json::Value> {
    let plan = ctx.plan;
    let deps = &plan.units[unit].deps;
    let count = |t: usize| -> Result<u64> {
        let path = ctx.input(t, &super::tiling::tile_file(tile))?;
        Ok(talus_tiling::read_tile_header(&path)
            .map_err(|e| super::damaged(&path, e))?
            .point_count)
    };
    // The pair's densest tile first: a budget that cannot hold it is refused by whichever M3C2
    // unit runs first, not after the tiles before it.
    let points =
        crate::plan::fit::pair_tile_points(plan, &ctx.meta(deps[0])?, &ctx.meta(deps[1])?)?;
    let halo_points = match points {
        Some(p) => {
            crate::plan::fit::check_tiled(plan, &p)?;
            p[plan.layout.grid()?.index(tile)]
        }
        None => count(deps[0])? + count(deps[1])?,
    };
    let _held = ctx.reserve(
        need(halo_points),
        &format!("tile {} ({halo_points} points with its halo)", tile.name()),
    )?;
    let (before, after) = std::thread::scope(|s| {
        // Both epochs at once: decompressing a tile is one thread's work.
        let a = s.spawn(|| read_tile(ctx, deps[1], tile));
        let b = read_tile(ctx, deps[0], tile);
        let a = a
            .join()
            .unwrap_or_else(|_| Err(Error::Internal("a tile reader panicked".into())));
        (b, a)
    });
    let (before, after) = (before?, after?);
    let user_cores = match deps.get(2) {
        Some(&c) => Some(cores::read(ctx, c, tile)?),
        None => None,
    };
    fn epoch(t: &TilePoints) -> EpochPoints<'_> {
        EpochPoints {
            x: &t.x,
            y: &t.y,
            z: &t.z,
            owned: &t.owned,
        }
    }
    let pair = match plan.units[unit].spec {
        Spec::M3c2 { pair, .. } => pair,
        _ => return Err(Error::Internal("an M3C2 unit without a pair".into())),
    };
    let extent = tile_extent(plan, pair, tile)?;
    let params = plan.params.m3c2();
    let mut results = compute(
        &epoch(&before),
        &epoch(&after),
        plan.layout.anchor,
        plan.layout.core_spacing,
        user_cores.as_deref(),
        &params,
        &extent,
    );
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
            [deps[0], deps[1]],
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
    let chunks = write_chunks(out, &results)?;
    (ctx.progress)(points);
    let count = |reach: Reach| results.iter().filter(|k| k.r.reach == reach).count();
    Ok(serde_json::json!({
        "chunks": chunks,
        "core_points": results.len(),
        "points": points,
        "halo_points": halo_points,
        "extended": count(Reach::Extended),
        "beyond_reach": count(Reach::Beyond),
        "walked_beyond_tile": pending.len(),
        "points_along": along,
    }))
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
fn open_box(grid: &talus_tiling::TileGrid, id: TileId, grow: f64) -> [f64; 4] {
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
    tilings: [usize; 2],
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
    let xy = tubes.xy_bounds();
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
            let path = ctx.input(tiling, &super::tiling::tile_file(id))?;
            talus_tiling::read_tile_frames(&path, |f| {
                let owned = match f.column(talus_tiling::OWNED_COLUMN) {
                    Some(talus_tiling::ColumnData::U8(v)) => v.clone(),
                    _ => vec![1; f.len()],
                };
                out[e].extend(
                    (0..f.len())
                        .filter(|&i| owned[i] == 1)
                        .map(|i| [f.x[i], f.y[i], f.z[i]])
                        .filter(|p| near(p)),
                );
                Ok(())
            })
            .map_err(|e| super::damaged(&path, e))?;
        }
    }
    Ok(out)
}

/// Write `results` as chunk files of [`CHUNK_ROWS`] rows; returns how many. Chunks are encoded in
/// parallel, a group at a time (the encoded bytes of a group are held until written), and
/// written plainly: the unit's commit makes them durable.
fn write_chunks(out: &mut UnitWriter, results: &[KeyedResult]) -> Result<usize> {
    use rayon::prelude::*;
    const GROUP: usize = 16;
    let parts: Vec<&[KeyedResult]> = results.chunks(CHUNK_ROWS).collect();
    for (g, group) in parts.chunks(GROUP).enumerate() {
        let encoded: Vec<std::result::Result<Vec<u8>, String>> = group
            .par_iter()
            .map(|part| talus_tiling::encode_tile(&to_columns(part), &Default::default()))
            .collect();
        for (i, bytes) in encoded.into_iter().enumerate() {
            let file = chunk_file(g * GROUP + i);
            let bytes = bytes.map_err(|p| Error::Internal(format!("{file}: {p}")))?;
            super::write_bytes(out, &file, &bytes)?;
        }
    }
    Ok(parts.len())
}

fn f64col(name: &str, v: Vec<f64>) -> Column {
    Column {
        name: name.into(),
        data: ColumnData::F64(v),
    }
}

fn u32col(name: &str, v: Vec<u32>) -> Column {
    Column {
        name: name.into(),
        data: ColumnData::U32(v),
    }
}

fn to_columns(rs: &[KeyedResult]) -> TileColumns {
    let col = |f: &dyn Fn(&KeyedResult) -> f64| rs.iter().map(f).collect::<Vec<f64>>();
    TileColumns {
        x: col(&|r| r.xyz[0]),
        y: col(&|r| r.xyz[1]),
        z: col(&|r| r.xyz[2]),
        extra: vec![
            u32col("key_hi", rs.iter().map(|r| (r.key >> 32) as u32).collect()),
            u32col("key_lo", rs.iter().map(|r| r.key as u32).collect()),
            f64col("distance", col(&|r| r.r.distance)),
            f64col("uncertainty", col(&|r| r.r.uncertainty)),
            Column {
                name: "significant".into(),
                data: ColumnData::U8(rs.iter().map(|r| r.r.significant as u8).collect()),
            },
            f64col("std_dev1", col(&|r| r.r.std_dev1)),
            f64col("std_dev2", col(&|r| r.r.std_dev2)),
            u32col("count1", rs.iter().map(|r| r.r.count1).collect()),
            u32col("count2", rs.iter().map(|r| r.r.count2).collect()),
            f64col("normal_x", col(&|r| r.r.normal[0])),
            f64col("normal_y", col(&|r| r.r.normal[1])),
            f64col("normal_z", col(&|r| r.r.normal[2])),
            Column {
                name: "reach".into(),
                data: ColumnData::U8(rs.iter().map(|r| r.r.reach as u8).collect()),
            },
        ],
    }
}

/// Read one result chunk back.
pub fn read_chunk(path: &std::path::Path) -> Result<Vec<KeyedResult>> {
    let c = talus_tiling::read_tile(path).map_err(|e| super::damaged(path, e))?;
    let missing = |name: &str| Error::Damaged {
        path: path.to_path_buf(),
        problem: format!("no column {name}"),
    };
    let f = |name: &str| -> Result<&Vec<f64>> {
        match c.column(name) {
            Some(ColumnData::F64(v)) => Ok(v),
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
    let (sig, reach) = (bytes("significant")?, bytes("reach")?);
    let (hi, lo) = (u("key_hi")?, u("key_lo")?);
    let (d, unc, s1, s2) = (
        f("distance")?,
        f("uncertainty")?,
        f("std_dev1")?,
        f("std_dev2")?,
    );
    let (n1, n2) = (u("count1")?, u("count2")?);
    let (nx, ny, nz) = (f("normal_x")?, f("normal_y")?, f("normal_z")?);
    (0..c.len())
        .map(|i| {
            Ok(KeyedResult {
                key: (hi[i] as u64) << 32 | lo[i] as u64,
                xyz: [c.x[i], c.y[i], c.z[i]],
                r: CoreResult {
                    distance: d[i],
                    uncertainty: unc[i],
                    significant: sig[i] == 1,
                    std_dev1: s1[i],
                    std_dev2: s2[i],
                    count1: n1[i],
                    count2: n2[i],
                    normal: [nx[i], ny[i], nz[i]],
                    reach: Reach::from_code(reach[i]).ok_or_else(|| Error::Damaged {
                        path: path.to_path_buf(),
                        problem: format!("reach code {} at row {i}", reach[i]),
                    })?,
                },
            })
        })
        .collect::<Result<_>>()
}

/// The chunk files of a pair's M3C2 units, per tile in grid order.
pub fn pair_chunks(ctx: &Ctx, pair: usize) -> Result<Vec<Vec<PathBuf>>> {
    let grid = ctx.plan.layout.grid()?;
    grid.tiles()
        .map(|t| {
            let u = ctx.unit(&Spec::M3c2 {
                pair,
                tile: [t.col, t.row],
            })?;
            let n = meta_u64(&ctx.meta(u)?, "chunks")? as usize;
            (0..n).map(|k| ctx.input(u, &chunk_file(k))).collect()
        })
        .collect()
}

/// How many core points a pair's M3C2 units hold, from their records.
pub fn pair_count(ctx: &Ctx, pair: usize) -> Result<u64> {
    let grid = ctx.plan.layout.grid()?;
    let mut n = 0;
    for t in grid.tiles() {
        let u = ctx.unit(&Spec::M3c2 {
            pair,
            tile: [t.col, t.row],
        })?;
        n += meta_u64(&ctx.meta(u)?, "core_points")?;
    }
    Ok(n)
}

/// Chunks decoded ahead, over all tiles of a merge: a merge of few tiles decodes several of a
/// tile's chunks at once, in parallel (a one-tile pair's results were read on one core while the
/// other waited); a merge of many holds one chunk per tile, as a merge must.
const LOOKAHEAD: usize = 8;

/// Chunks a merge of `tiles` tiles decodes ahead per tile.
fn ahead(tiles: usize) -> usize {
    (LOOKAHEAD / tiles.max(1)).max(1)
}

/// Resident bytes of a [`Merged`] over `tiles` tiles: the other tiles' chunks (one each, a few
/// when the tiles are few) while one tile reads its next ones: its last chunk, the new chunks and
/// their files' decoded columns (about as large again). A stage that merges reserves it: a layout
/// of many small tiles (a low budget, a dense site) costs the merge a chunk for each.
pub fn merge_need(tiles: usize) -> u64 {
    let chunk = (CHUNK_ROWS * std::mem::size_of::<KeyedResult>()) as u64;
    let a = ahead(tiles) as u64;
    ((tiles.max(1) as u64 - 1) * a + 1 + 2 * a) * chunk
}

/// A pair's M3C2 results in global key order: a k-way merge holding one chunk per tile (a few
/// when the tiles are few, see `LOOKAHEAD`).
pub struct Merged {
    tiles: Vec<Vec<PathBuf>>,
    /// Per tile: the loaded chunk, position in it, next chunk number, chunks decoded ahead.
    cursors: Vec<Cursor>,
    heap: BinaryHeap<Reverse<(u64, usize)>>,
    ahead: usize,
}

#[derive(Default)]
struct Cursor {
    chunk: Vec<KeyedResult>,
    pos: usize,
    next: usize,
    decoded: std::collections::VecDeque<Vec<KeyedResult>>,
}

impl Merged {
    pub fn new(ctx: &Ctx, pair: usize) -> Result<Self> {
        let tiles = pair_chunks(ctx, pair)?;
        let mut m = Merged {
            cursors: (0..tiles.len()).map(|_| Cursor::default()).collect(),
            ahead: ahead(tiles.len()),
            tiles,
            heap: BinaryHeap::new(),
        };
        for t in 0..m.tiles.len() {
            m.advance_chunk(t)?;
        }
        Ok(m)
    }

    fn advance_chunk(&mut self, t: usize) -> Result<()> {
        let files = &self.tiles[t];
        let c = &mut self.cursors[t];
        while c.pos >= c.chunk.len() && (c.next < files.len() || !c.decoded.is_empty()) {
            if c.decoded.is_empty() {
                use rayon::prelude::*;
                let end = (c.next + self.ahead).min(files.len());
                let read: Vec<Result<Vec<KeyedResult>>> = files[c.next..end]
                    .par_iter()
                    .map(|f| read_chunk(f))
                    .collect();
                for r in read {
                    c.decoded.push_back(r?);
                }
                c.next = end;
            }
            c.chunk = c.decoded.pop_front().unwrap_or_default();
            c.pos = 0;
        }
        if c.pos < c.chunk.len() {
            self.heap.push(Reverse((c.chunk[c.pos].key, t)));
        }
        Ok(())
    }

    /// The next result in key order.
    pub fn next_result(&mut self) -> Result<Option<KeyedResult>> {
        let Some(Reverse((_, t))) = self.heap.pop() else {
            return Ok(None);
        };
        let c = &mut self.cursors[t];
        let r = c.chunk[c.pos];
        c.pos += 1;
        if c.pos < c.chunk.len() {
            self.heap.push(Reverse((c.chunk[c.pos].key, t)));
        } else {
            self.advance_chunk(t)?;
        }
        Ok(Some(r))
    }
}

/// The user's core points (`--core-points`), cut into the layout's tiles once for every M3C2
/// unit: each tile's file holds the points it owns, keyed by their order in the input (so
/// m3c2.laz gives them back in that order).
pub mod cores {
    use super::*;

    /// The file of tile `id`'s core points.
    pub fn file(id: TileId) -> String {
        format!("c_{}.tile", id.name())
    }

    /// Resident bytes per user core point while it is cut: the key and point (32), the columns
    /// written (32).
    pub const CORE_POINT_BYTES: u64 = 64;

    /// Cut the plan's core-point file into `out`.
    pub fn run(ctx: &Ctx, out: &mut UnitWriter) -> Result<serde_json::Value> {
        let plan = ctx.plan;
        let grid = plan.layout.grid()?;
        let input = plan
            .core_points
            .as_ref()
            .ok_or_else(|| Error::Internal("a core-point unit without core points".into()))?;
        // When the header's count fits the unit's share of the pool, one pass. Otherwise a first
        // pass counts each tile's points; then tiles are taken in batches whose points fit the
        // share, one pass over the file per batch: never the whole file at once (a core-point
        // file can be as large as a survey).
        let pass = |f: &mut dyn FnMut(u64, usize, Point3) -> Result<()>| -> Result<u64> {
            let mut reader = crate::io::open(&input.path)?;
            let mut buf = Vec::new();
            let mut n = 0u64;
            while reader.fill(&mut buf, 1 << 16)? > 0 {
                for p in &buf {
                    f(n, grid.index(grid.owner(p[0], p[1])), *p)?;
                    n += 1;
                }
                crate::interrupt::check()?;
            }
            Ok(n)
        };
        let share = (ctx.pool.limit() / 4).max(CORE_POINT_BYTES);
        let total = crate::io::open(&input.path)?.info().point_count;
        if total * CORE_POINT_BYTES <= share {
            // All of them fit: one pass.
            let _held = ctx.reserve(
                total * CORE_POINT_BYTES + (4 << 20),
                &format!("{total} core points of {}", input.path.display()),
            )?;
            let mut by_tile: Vec<Vec<(u64, Point3)>> = vec![Vec::new(); grid.len()];
            let n = pass(&mut |k, t, p| {
                by_tile[t].push((k, p));
                Ok(())
            })?;
            for id in grid.tiles() {
                write(out, id, &by_tile[grid.index(id)])?;
            }
            return Ok(serde_json::json!({ "points": n }));
        }
        let mut counts = vec![0u64; grid.len()];
        let n = pass(&mut |_, t, _| {
            counts[t] += 1;
            Ok(())
        })?;
        let tiles: Vec<TileId> = grid.tiles().collect();
        let mut start = 0;
        while start < tiles.len() {
            let mut end = start + 1;
            let mut points = counts[grid.index(tiles[start])];
            while end < tiles.len()
                && (points + counts[grid.index(tiles[end])]) * CORE_POINT_BYTES <= share
            {
                points += counts[grid.index(tiles[end])];
                end += 1;
            }
            let _held = ctx.reserve(
                points * CORE_POINT_BYTES + (4 << 20),
                &format!("{points} core points of {}", input.path.display()),
            )?;
            let mut by_tile: Vec<Vec<(u64, Point3)>> = vec![Vec::new(); end - start];
            let batch: Vec<usize> = tiles[start..end].iter().map(|&t| grid.index(t)).collect();
            pass(&mut |k, t, p| {
                if let Some(b) = batch.iter().position(|&x| x == t) {
                    by_tile[b].push((k, p));
                }
                Ok(())
            })?;
            for (b, &id) in tiles[start..end].iter().enumerate() {
                write(out, id, &by_tile[b])?;
            }
            start = end;
        }
        Ok(serde_json::json!({ "points": n }))
    }

    /// The core points of a campaign: the tiling `deps[0]` of unit `unit` thinned on the
    /// core-point grid, tile by tile, keyed by their cells (the keys a pair's M3C2 unit gives
    /// its own thinning: pair 0 of a campaign is a `compare` of its two surveys).
    pub fn thinned(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<serde_json::Value> {
        let plan = ctx.plan;
        let tiling = plan.units[unit].deps[0];
        let grid = plan.layout.grid()?;
        let mut n = 0u64;
        for id in grid.tiles() {
            let path = ctx.input(tiling, &super::super::tiling::tile_file(id))?;
            let count = talus_tiling::read_tile_header(&path)
                .map_err(|e| super::super::damaged(&path, e))?
                .point_count;
            // The tile as read (25 bytes a point), its file's bytes, the thinning's cells.
            let _held = ctx.reserve(
                count * 64 + (4 << 20),
                &format!("thinning tile {} ({count} points)", id.name()),
            )?;
            let t = read_tile(ctx, tiling, id)?;
            let pts: Vec<(u64, Point3)> = crate::m3c2::core_points::thin(
                t.len(),
                |i| t.point(i),
                &plan.layout.anchor,
                plan.layout.core_spacing,
                |i| t.owned[i],
            )
            .into_iter()
            .map(|(k, i)| (k, t.point(i)))
            .collect();
            n += pts.len() as u64;
            write(out, id, &pts)?;
            (ctx.progress)(t.owned.iter().filter(|&&o| o).count() as u64);
        }
        Ok(serde_json::json!({ "points": n }))
    }

    /// Write tile `id`'s core points.
    fn write(out: &mut UnitWriter, id: TileId, pts: &[(u64, Point3)]) -> Result<()> {
        let col = |k: usize| pts.iter().map(|(_, p)| p[k]).collect::<Vec<f64>>();
        let cols = TileColumns {
            x: col(0),
            y: col(1),
            z: col(2),
            extra: vec![
                u32col(
                    "key_hi",
                    pts.iter().map(|(k, _)| (k >> 32) as u32).collect(),
                ),
                u32col("key_lo", pts.iter().map(|(k, _)| *k as u32).collect()),
            ],
        };
        super::super::write_columns(out, &file(id), &cols)
    }

    /// Tile `id`'s core points from the core-point unit `unit`.
    pub fn read(ctx: &Ctx, unit: usize, id: TileId) -> Result<Vec<(u64, Point3)>> {
        let c = super::super::read_columns(ctx, unit, &file(id))?;
        let (Some(ColumnData::U32(hi)), Some(ColumnData::U32(lo))) =
            (c.column("key_hi"), c.column("key_lo"))
        else {
            return Err(Error::Damaged {
                path: ctx.input(unit, &file(id))?,
                problem: "no key columns".into(),
            });
        };
        Ok((0..c.len())
            .map(|i| {
                (
                    (hi[i] as u64) << 32 | lo[i] as u64,
                    [c.x[i], c.y[i], c.z[i]],
                )
            })
            .collect())
    }
}

//! The core points of a run, cut into the layout's tiles, when they are not each M3C2 unit's own
//! thinning of the pair's before survey: the user's core-point file ([`UserCoresStage`]), or a
//! campaign's first survey thinned once for every pair ([`ThinnedStage`], so that every pair is
//! measured at the same places and the time series follows them).

use talus_tiling::{Column, ColumnData, TileColumns, TileId};

use super::stage::{Line, Planner, Scope, Stage, Total};
use super::{read_tile, Ctx};
use crate::error::{Error, Result};
use crate::io::Point3;
use crate::plan::Spec;
use crate::store::UnitWriter;

/// What a core-point unit records.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub(crate) struct CoresMeta {
    /// Core points written.
    pub(crate) points: u64,
}

/// The progress line both count on: cutting core points is part of pass 1.
const LINE: Line = Line {
    name: "pass 1: tiling",
    counts: "points",
    total: Total::SurveyPoints,
};

/// The user's core points (`--core-points`), cut into the layout's tiles once for every M3C2
/// unit: each tile's file holds the points it owns, keyed by their order in the input (so
/// m3c2.laz gives them back in that order).
pub(crate) struct UserCoresStage;

impl Stage for UserCoresStage {
    const KIND: &'static str = "cores";
    const SCOPE: Scope = Scope::Run;
    const VERSION: u32 = 1;
    const LINE: Line = LINE;
    type Meta = CoresMeta;

    fn plan(p: &mut Planner) -> Result<()> {
        if let Some(c) = p.plan.core_points.clone() {
            let layout = p.plan.layout.key();
            p.add(
                Spec::run(Self::KIND),
                "cores",
                &[&c.key, &layout],
                Vec::new(),
            );
        }
        Ok(())
    }

    fn run(ctx: &Ctx, _unit: usize, out: &mut UnitWriter) -> Result<CoresMeta> {
        cut(ctx, out)
    }
}

/// A campaign's core points: its first survey thinned on the core-point grid.
pub(crate) struct ThinnedStage;

impl Stage for ThinnedStage {
    const KIND: &'static str = "thinned";
    const SCOPE: Scope = Scope::Survey;
    const VERSION: u32 = 1;
    const LINE: Line = LINE;
    type Meta = CoresMeta;

    fn plan(p: &mut Planner) -> Result<()> {
        if p.cores != super::stage::CoreSource::Campaign {
            return Ok(());
        }
        // The first survey's tiles (its cleared tiling with `--vegetation remove`).
        let t = p.survey_tiles(0)?;
        let c = p.plan.params.core_spacing.value.to_string();
        let label = format!("thinned-{}", p.plan.surveys[0].label);
        p.add(Spec::survey(Self::KIND, 0), &label, &[&c], t);
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<CoresMeta> {
        thin(ctx, ctx.survey(unit)?, out)
    }
}

fn u32col(name: &str, v: Vec<u32>) -> Column {
    Column {
        name: name.into(),
        data: ColumnData::U32(v),
    }
}

/// The file of tile `id`'s core points.
pub(crate) fn file(id: TileId) -> String {
    format!("c_{}.tile", id.name())
}

/// Resident bytes per user core point while it is cut: the key and point (32), the columns
/// written (32).
pub(crate) const CORE_POINT_BYTES: u64 = 64;

/// Cut the plan's core-point file into `out`.
fn cut(ctx: &Ctx, out: &mut UnitWriter) -> Result<CoresMeta> {
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
            total * CORE_POINT_BYTES + crate::memory::HEADROOM,
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
        return Ok(CoresMeta { points: n });
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
            points * CORE_POINT_BYTES + crate::memory::HEADROOM,
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
    Ok(CoresMeta { points: n })
}

/// The core points of a campaign: survey `survey` thinned on the core-point grid, tile by tile,
/// keyed by their cells (the keys a pair's M3C2 unit gives its own thinning: pair 0 of a
/// campaign is a `compare` of its two surveys).
fn thin(ctx: &Ctx, survey: usize, out: &mut UnitWriter) -> Result<CoresMeta> {
    let plan = ctx.plan;
    let (tiling, meta) = ctx.tiles(survey)?;
    let grid = plan.layout.grid()?;
    let mut n = 0u64;
    for id in grid.tiles() {
        let count = meta.tile_points[grid.index(id)];
        // The tile as read (25 bytes a point), its file's bytes, the thinning's cells.
        let _held = ctx.reserve(
            count * 64 + crate::memory::HEADROOM,
            &format!("thinning tile {} ({count} points)", id.name()),
        )?;
        let t = read_tile(ctx, &tiling, id)?;
        let pts = t
            .epoch()
            .core_points(&plan.layout.anchor, plan.layout.core_spacing);
        n += pts.len() as u64;
        write(out, id, &pts)?;
        (ctx.progress)(t.owned.iter().filter(|&&o| o).count() as u64);
    }
    Ok(CoresMeta { points: n })
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
    super::write_columns(out, &file(id), &cols)
}

/// Tile `id`'s core points from the core-point unit `unit`.
pub(crate) fn read(ctx: &Ctx, unit: usize, id: TileId) -> Result<Vec<(u64, Point3)>> {
    let c = super::read_columns(ctx, unit, &file(id))?;
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

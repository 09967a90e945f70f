//! `--vegetation remove` (SPEC.md §4 "Vegetation"): a survey without its vegetation-like points,
//! tiled anew, read by every later stage in place of its tiling (`Ctx::tiling`).
//!
//! Each of the survey's tiles is read whole (square and halo); each point the tile owns is judged
//! by `events::vegetation::looks_like_vegetation` over the tile's points — exact, since the
//! halo (≥ the cylinder's half-length) reaches beyond the largest ball (8 point spacings) — and
//! the points kept are cut into the run's layout again. A point is judged from the same
//! neighbours in the same frame (the layout's anchor) whatever the tiling, so the cleared survey
//! is the same set of points whatever the tile size. Where the vegetation stood, holes remain;
//! the events' `coverage` reports them.

use serde::{Deserialize, Serialize};

use super::stage::{Line, Planner, Scope, Stage, TilesOf, Total};
use super::tiling::{Splitting, TilingMeta};
use super::{read_tile, Ctx};
use crate::error::Result;
use crate::params::Vegetation;
use crate::plan::Spec;
use crate::store::UnitWriter;

/// Resident bytes per point of a tile while its points are judged: the tile's columns and owned
/// flags (25), the index's copy and cells (≈ 40), the verdicts.
pub(crate) const BYTES_PER_POINT: u64 = 80;

/// A survey cleared of its vegetation-like points.
pub struct ClearedStage;

/// What a cleared unit records: its tiling, and the points it removed.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct ClearedMeta {
    pub(crate) removed: u64,
    pub(crate) tiling: TilingMeta,
}

impl Stage for ClearedStage {
    const KIND: &'static str = "cleared";
    const SCOPE: Scope = Scope::Survey;
    const VERSION: u32 = 1;
    const INTERMEDIATE: bool = true;
    const LINE: Line = Line {
        name: "vegetation removed",
        counts: "points",
        total: Total::SurveyPoints,
    };
    type Meta = ClearedMeta;
    const TILES: Option<TilesOf<ClearedMeta>> = Some(|m| Some(m.tiling.clone()));

    /// One per survey with `--vegetation remove`, over the units holding its tiles.
    fn plan(p: &mut Planner) -> Result<()> {
        if p.plan.params.vegetation.value != Vegetation::Remove {
            return Ok(());
        }
        let spacing = format!("{}", p.plan.params.point_spacing.value);
        for s in 0..p.plan.surveys.len() {
            let deps = p.survey_tiles(s)?;
            let label = p.plan.surveys[s].label.clone();
            p.add(
                Spec::survey(Self::KIND, s),
                &label,
                &["vegetation remove 1", &spacing],
                deps,
            );
        }
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<ClearedMeta> {
        use rayon::prelude::*;
        let plan = ctx.plan;
        let s = ctx.survey(unit)?;
        let (source, meta) = ctx.tiles_before(s, Some(Self::KIND))?;
        let grid = plan.layout.grid()?;
        let spacing = plan.params.point_spacing.value;
        let cell = crate::events::vegetation::SCALES[0] * spacing;
        // The largest tile, judged while the splitter holds its frames: one reservation for both.
        let largest = meta.tile_points.iter().copied().max().unwrap_or(0);
        let mut splitting = Splitting::with(
            ctx,
            s,
            out,
            largest * BYTES_PER_POINT,
            &format!(" without its vegetation (tiles of up to {largest} points judged)"),
        )?;
        splitting.quantum(ctx.quantum(s)?);
        let mut removed = 0u64;
        for id in grid.tiles() {
            if meta.tile_points[grid.index(id)] == 0 {
                continue;
            }
            let t = read_tile(ctx, &source, id)?;
            let index = crate::spatial::Columns::from_fn(
                t.owned.len(),
                |i| t.point(i),
                plan.layout.anchor,
                cell,
            );
            let owned: Vec<usize> = (0..t.owned.len()).filter(|&i| t.owned[i]).collect();
            let kept: Vec<crate::geom::Point3> = owned
                .par_iter()
                .filter(|&&i| {
                    let q = index.to_local(&t.point(i));
                    !crate::events::vegetation::looks_like_vegetation(&index, &q, spacing)
                })
                .map(|&i| t.point(i))
                .collect();
            removed += (owned.len() - kept.len()) as u64;
            splitting.push(&kept)?;
            (ctx.progress)(owned.len() as u64);
            crate::interrupt::check()?;
        }
        let tiling = splitting.finish(out, meta.classes)?;
        Ok(ClearedMeta { removed, tiling })
    }
}

//! A segment unit: a range of ranks of a pair's core points in canonical key order, written as a
//! LAZ file of whole chunks and a piece of the viewer's terrain sample, so that several tasks
//! write a large pair's m3c2.laz and the points unit joins them (issue 47: the one points task
//! was 18.7 s of the 120M-point pair's critical path on a cluster).
//!
//! The pair's `total` core points are cut into as many segments as its before survey's tiling
//! has parts (`units::tiling::parts`, `--tiling-part`), the cuts rounded down to whole LAZ
//! chunks of the file's chunk size (`laz_chunk_size(total)`): every segment but the last is
//! whole chunks, which the join concatenates into the very file one writer writes
//! (`io::laz_join`). A segment finds the key at its first rank in the tiles' sorted results
//! (`m3c2::seek`: a binary search reading key columns only) and merges from there: no segment
//! reads the results before its own (but the chunk each run holds its first key in). The
//! events' kept core points it reads from their first frame (`KeptByKey`: a frame decoded to
//! be passed), at most the pair's kept points a segment, a small share of its results.

use serde::{Deserialize, Serialize};

use super::laz::{self, Written};
use super::points;
use super::view::TerrainSample;
use crate::error::Result;
use crate::io::las_out::laz_chunk_size;
use crate::store::UnitWriter;
use crate::units::events::{KeptByKey, KeptFrames};
use crate::units::m3c2::seek::{ranks_of, RankRange};
use crate::units::stage::{Planner, Scope, Stage};
use crate::units::Ctx;

/// A range of a pair's m3c2.laz.
pub(crate) struct SegmentsStage;

/// What a segment unit records.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct SegmentMeta {
    /// What its part of m3c2.laz holds.
    pub(crate) written: Written,
    /// The canonical ranks of the pair's core points it holds: `from..to`.
    pub(crate) from: u64,
    pub(crate) to: u64,
}

impl crate::units::m3c2::seek::InRange for SegmentMeta {
    fn span(&self) -> (u64, u64) {
        (self.from, self.to)
    }
}

/// How many segments pair `pair`'s m3c2.laz is written in: as many as its before survey's
/// tiling has parts; 0 — the points unit writes it whole — for a survey tiled whole, and for a
/// lean campaign's pair, which has no m3c2.laz (`Plan::lean_pairs`).
pub(crate) fn count(plan: &crate::plan::Plan, pair: usize) -> usize {
    match plan.lean_pairs {
        true => 0,
        false => crate::units::m3c2::seek::ranges(plan, pair),
    }
}

impl Stage for SegmentsStage {
    const KIND: &'static str = "segments";
    const SCOPE: Scope = Scope::Pair;
    const VERSION: u32 = 1;
    /// Joined into the points unit's m3c2.laz, never published themselves.
    const INTERMEDIATE: bool = true;
    const LINE: crate::units::stage::Line = <points::PointsStage as Stage>::LINE;
    type Meta = SegmentMeta;

    fn plan(p: &mut Planner) -> Result<()> {
        for pair in 0..p.plan.pairs.len() {
            let n = count(p.plan, pair);
            if n == 0 {
                continue;
            }
            crate::memory::refuse_unless_fits(
                points::need(crate::units::merged::merge_inputs(p.plan)),
                p.plan.params.memory_bytes.value,
                &format!(
                    "writing a segment of pair {}'s m3c2.laz",
                    p.plan.pairs[pair].label
                ),
            )?;
            let deps = points::pass_deps(p, pair)?;
            let version = format!("{}|{}", env!("CARGO_PKG_VERSION"), p.plan.m3c2_only);
            for unit in p.add_pair_ranges(Self::KIND, pair, n, &version, &deps) {
                // As the points unit: after the pair's volumes, which read the tiles.
                let volumes = p.of_pair(crate::units::volumes::VolumesStage::KIND, pair);
                p.order_after(unit, volumes);
            }
        }
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<SegmentMeta> {
        let plan = ctx.plan;
        let pair = ctx.pair(unit)?;
        let n = count(plan, pair);
        let ground = crate::units::stable::read(ctx, pair)?;
        let params = ground.params(plan);
        let _held = ctx.reserve(
            points::need(crate::units::merged::merge_inputs(plan)),
            "writing a segment of m3c2.laz (and the merge of the pair's tiles)",
        )?;
        let (total, from, to) = ranks_of(ctx, unit, n, |t| u64::from(laz_chunk_size(Some(t))))?;
        let kept = match plan.m3c2_only {
            true => None,
            false => Some(KeptFrames::open(ctx, pair)?),
        };
        let mut kept = KeptByKey::new(kept);
        let mut terrain = TerrainSample::piece(total, plan.layout.anchor, from, to);
        let mut range = RankRange::open(ctx, pair, from, to)?;
        let written = laz::write_m3c2_laz(
            out,
            &mut || range.next_result(),
            total,
            params.reg_error.value,
            Some(points::cloud(plan, pair)?),
            &mut |key| {
                Ok(kept
                    .get(key)?
                    .map_or((f64::NAN, 0), |k| (k.smoothed, k.event)))
            },
            &mut |r| terrain.push(r),
        )?;
        (ctx.progress)(written.core_points);
        terrain.write_piece(out)?;
        Ok(SegmentMeta { written, from, to })
    }
}

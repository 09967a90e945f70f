//! A points unit: a pair's m3c2.laz and the viewer's terrain sample (terrain.bin), in one pass
//! over the pair's results in key order. The outputs unit publishes both from here. A lean
//! campaign's pair (`Plan::lean_pairs`) has no m3c2.laz, and its terrain.bin its distances
//! alone but in the first pair (`shared_positions`).
//!
//! A unit of its own because it needs the events (each core point's smoothed distance and event
//! id) but not their volumes: it runs beside the volumes units instead of after them. Writing
//! m3c2.laz is LAZ encoding for the most part (≈ 30 of its ≈ 43 CPU-s on the 120M-point pair),
//! the volumes are triangulations and solids; neither alone kept both cores busy.

use serde::{Deserialize, Serialize};

use super::laz::{self, Written};
use super::segments::SegmentsStage;
use super::view::{Terrain, TerrainSample};
use crate::error::{Error, Result};
use crate::io::las_out::CoordinateGrid;
use crate::io::{self, Bounds};
use crate::plan::Spec;
use crate::store::UnitWriter;
use crate::units::cores::ThinnedStage;
use crate::units::events::{EventsStage, KeptByKey, KeptFrames};
use crate::units::stable::StableStage;
use crate::units::stage::{Line, Planner, Scope, Stage, Total};
use crate::units::Ctx;

/// Resident bytes of a points unit beside its merge: the LAZ writer's batches and the LAZ
/// compressor's chunks, the viewer's terrain sample (at most 2M points, 16 B each), the kept core
/// points' frames (measured with the outputs it was part of: 110–125 MiB on the 5.2M-point cliff
/// with 15 tiles, of which the merge's about 18).
pub(crate) const FIXED: u64 = 112 << 20;

/// Resident bytes of a points unit whose merge holds `inputs` inputs
/// (`merged::merge_inputs`).
pub(crate) fn need(inputs: usize) -> u64 {
    FIXED + crate::units::m3c2::merge_need(inputs)
}

/// A pair's m3c2.laz and terrain sample.
pub(crate) struct PointsStage;

/// What a points unit records.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct PointsMeta {
    /// What m3c2.laz holds.
    pub(crate) written: Written,
    /// The terrain sample in terrain.bin.
    pub(crate) terrain: Terrain,
    /// Core points in the pair's events' kept set (the significance filter's survivors).
    pub(crate) kept: u64,
}

/// The files of a points unit: m3c2.laz (not in a lean campaign: `Plan::lean_pairs`) and
/// terrain.bin.
pub(crate) fn files(plan: &crate::plan::Plan) -> &'static [&'static str] {
    match plan.lean_pairs {
        false => &["m3c2.laz", "terrain.bin"],
        true => &["terrain.bin"],
    }
}

/// Where pair `pair`'s terrain positions are when not in its own terrain.bin (view.json's
/// `positions`, relative to the pair's folder): in a lean campaign every pair has the
/// campaign's core points in the same order about the same origin, so the first pair's
/// terrain.bin holds the positions and the others' hold their distances alone (4 bytes a point
/// instead of 16).
pub(crate) fn shared_positions(plan: &crate::plan::Plan, pair: usize) -> Option<String> {
    (plan.lean_pairs && pair > 0).then(|| format!("../{}/terrain.bin", plan.pairs[0].label))
}

impl Stage for PointsStage {
    const KIND: &'static str = "points";
    const SCOPE: Scope = Scope::Pair;
    /// 3: a lean campaign's pair writes no m3c2.laz, and its terrain.bin the distances alone but
    /// in the first pair.
    const VERSION: u32 = 3;
    const LINE: Line = Line {
        name: "m3c2.laz",
        counts: "core points",
        total: Total::Unknown,
    };
    type Meta = PointsMeta;

    /// One per pair, over the pair's stable ground, results and events. Its need grows with the
    /// tile count (the merge holds a chunk of every tile's results, or of every run), so it is
    /// checked here.
    fn plan(p: &mut Planner) -> Result<()> {
        let tiles = p.plan.layout.len();
        for pair in 0..p.plan.pairs.len() {
            // A lean campaign's pair: what it writes and where its terrain positions are.
            let lean = match (p.plan.lean_pairs, shared_positions(p.plan, pair)) {
                (false, _) => String::new(),
                (true, None) => "|lean".to_string(),
                (true, Some(at)) => format!("|lean|{at}"),
            };
            let version = format!("{}|{}{lean}", env!("CARGO_PKG_VERSION"), p.plan.m3c2_only);
            let whose = match p.plan.pairs.len() {
                1 => "the pair's".to_string(),
                _ => format!("pair {}'s", p.plan.pairs[pair].label),
            };
            crate::memory::refuse_unless_fits(
                need(crate::units::merged::merge_inputs(p.plan)),
                p.plan.params.memory_bytes.value,
                &format!(
                    "writing {whose} m3c2.laz, merging the results of its {tiles} tiles{}",
                    if crate::units::merged::in_rounds(p.plan) {
                        " (in rounds)"
                    } else {
                        ""
                    }
                ),
            )?;
            // Written in segments: joined from them (which read the results themselves).
            let segments = p.of_pair(SegmentsStage::KIND, pair);
            // (The events for their kept count.)
            let mut deps = match segments.is_empty() {
                true => pass_deps(p, pair)?,
                false => p
                    .find(&Spec::pair(EventsStage::KIND, pair))
                    .into_iter()
                    .collect(),
            };
            deps.extend(segments);
            let unit = p.add_pair(Self::KIND, pair, &version, deps);
            // After the pair's volumes: they read the tiles, m3c2.laz is made from the M3C2
            // results; one after the other, the tiles go before m3c2.laz comes (issue 46).
            let volumes = p.of_pair(crate::units::volumes::VolumesStage::KIND, pair);
            p.order_after(unit, volumes);
        }
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<PointsMeta> {
        run(ctx, ctx.pair(unit)?, out)
    }
}

/// What a pass over pair `pair`'s results that writes m3c2.laz reads: its stable ground (the
/// registration error), its results and its events (each core point's event).
pub(crate) fn pass_deps(p: &Planner, pair: usize) -> Result<Vec<usize>> {
    let mut deps = vec![p.the(&Spec::pair(StableStage::KIND, pair))?];
    deps.extend(p.pair_results(pair));
    deps.extend(p.find(&Spec::pair(EventsStage::KIND, pair)));
    Ok(deps)
}

/// Pair `pair`'s m3c2.laz's CRS (its before survey's) and coordinate grid.
pub(crate) fn cloud(plan: &crate::plan::Plan, pair: usize) -> Result<laz::Cloud> {
    let p = &plan.pairs[pair];
    let bs = &plan.surveys[p.before];
    // The user's core-point file, when there is one, opened once for its scale and bounds.
    let user_cores = plan
        .core_points
        .as_ref()
        .and_then(|c| io::open(&c.path).ok())
        .map(|r| r.info().clone());
    // Core points are C1 points or the user's: the finest coordinate quantum of the file they
    // come from keeps them exact.
    let scales: Vec<[f64; 3]> = [bs.scale, user_cores.as_ref().and_then(|i| i.scale)]
        .into_iter()
        .flatten()
        .collect();
    let crs = io::open(&bs.files[0].path)?.info().crs.clone();
    // The pair's own inputs (not the campaign's union: a survey added later must not change a
    // finished pair's file).
    let mut extent = Bounds::union(&[bs.bounds, plan.surveys[p.after].bounds]);
    if let Some(i) = &user_cores {
        extent.grow(&i.bounds.min);
        extent.grow(&i.bounds.max);
    }
    // A campaign's core points come from its first survey.
    for u in plan.of_kind(ThinnedStage::KIND) {
        if let Some(survey) = plan.units[u].spec.survey {
            extent.grow(&plan.surveys[survey].bounds.min);
            extent.grow(&plan.surveys[survey].bounds.max);
        }
    }
    Ok(laz::Cloud {
        crs,
        grid: CoordinateGrid::for_extent(extent.min, extent.max, &scales),
    })
}

/// Resident bytes of a points unit that joins segments: the whole terrain sample (positions,
/// distances) with its pieces' normals as they are read, and the join's copies.
const JOIN_NEED: u64 = 112 << 20;

/// Pair `pair`'s m3c2.laz and terrain sample joined from its segments (`super::segments`): the
/// bytes one pass writes.
fn join(ctx: &Ctx, pair: usize, out: &mut UnitWriter) -> Result<PointsMeta> {
    let plan = ctx.plan;
    let _held = ctx.reserve(JOIN_NEED, "joining m3c2.laz and the terrain sample")?;
    let mut written = Written::none();
    let (mut files, mut pieces) = (Vec::new(), Vec::new());
    let segments = crate::units::m3c2::seek::ranges_of::<SegmentsStage>(ctx, pair)?;
    for (u, m) in segments {
        if m.written.core_points != m.to - m.from {
            return Err(Error::Internal(format!(
                "segment {} holds core points {}..{} but wrote {}",
                plan.units[u].name, m.from, m.to, m.written.core_points
            )));
        }
        written.add(&m.written);
        files.push(ctx.input(u, "m3c2.laz")?);
        pieces.push(ctx.input(u, super::view::PIECE)?);
    }
    crate::io::laz_join::join_laz(&files, &out.path("m3c2.laz")?)?;
    out.add_file("m3c2.laz")?;
    let terrain =
        TerrainSample::joined(written.core_points, plan.layout.anchor, &pieces)?.write(out)?;
    let kept = match plan.m3c2_only {
        true => 0,
        false => KeptFrames::open(ctx, pair)?.count(),
    };
    Ok(PointsMeta {
        written,
        terrain,
        kept,
    })
}

/// Write pair `pair`'s m3c2.laz and terrain sample into `out`.
fn run(ctx: &Ctx, pair: usize, out: &mut UnitWriter) -> Result<PointsMeta> {
    let plan = ctx.plan;
    if plan.of_pair(SegmentsStage::KIND, pair).next().is_some() {
        return join(ctx, pair, out);
    }
    let ground = crate::units::stable::read(ctx, pair)?;
    let params = ground.params(plan);
    let _held = ctx.reserve(
        need(crate::units::merged::merge_inputs(plan)),
        "writing m3c2.laz (and the merge of the pair's tiles)",
    )?;
    let kept = match plan.m3c2_only {
        true => None,
        false => Some(KeptFrames::open(ctx, pair)?),
    };
    let kept_count = kept.as_ref().map_or(0, |k| k.count());
    // The kept core points beside the results, both in key order.
    let mut kept = KeptByKey::new(kept);
    let total = crate::units::m3c2::pair_count(ctx, pair)?;
    // A lean campaign's pair after the first: its terrain.bin holds the distances alone, and
    // its series unit those very bytes when the sample is every core point.
    let mut terrain = TerrainSample::new(total, plan.layout.anchor, shared_positions(plan, pair));
    // Where m3c2.laz goes: a lean campaign's pairs have none (nor need its input's header).
    let cloud = match plan.lean_pairs {
        true => None,
        false => Some(cloud(plan, pair)?),
    };
    let mut merged = crate::units::m3c2::Merged::new(ctx, pair)?;
    let written = laz::write_m3c2_laz(
        out,
        &mut || merged.next_result(),
        total,
        params.reg_error.value,
        cloud,
        &mut |k| {
            Ok(kept
                .get(k)?
                .map_or((f64::NAN, 0), |k| (k.smoothed, k.event)))
        },
        &mut |k| terrain.push(k),
    )?;
    (ctx.progress)(written.core_points);
    let terrain = terrain.write(out)?;
    Ok(PointsMeta {
        written,
        terrain,
        kept: kept_count,
    })
}

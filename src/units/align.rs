//! The alignment of a later survey onto the first (SPEC.md §1 "Registration: removed, not only
//! measured"), fitted on a sample of the two surveys' tiles: M3C2 at about [`SAMPLE_CORES`] core
//! points of up to [`SAMPLE_TILES`] tiles spread over the grid (all of them when there are
//! fewer), their stable
//! ground found as the stable-ground unit finds it (`events::stable::select`), and a rigid
//! point-to-plane fit over it (`events::align::fit`), applied only when it is significant and
//! well constrained. The sample costs a few tiles' M3C2, not a second pass over all of them;
//! the survey is then tiled again with the transform ([`super::aligned`]) only when it applies.

use serde::{Deserialize, Serialize};

use super::stage::{Line, Planner, Scope, Stage, Total};
use super::tiling::TilingStage;
use super::{read_tile, Ctx, TilePoints};
use crate::error::Result;
use crate::events::align::{fit, Alignment};
use crate::events::stable::{measure, select, Sample};
use crate::m3c2::tile::{compute, EpochPoints};
use crate::m3c2::{Extent, Reach};
use crate::plan::Spec;
use crate::store::UnitWriter;

/// Tiles the fit samples, at most (spread over the grid in its order).
pub const SAMPLE_TILES: usize = 16;
/// Core points the fit computes, about: every k-th core point of the sampled tiles. Enough for a
/// six-parameter fit whose uncertainty is far below the noise (σ/√n), few enough that the
/// sample costs a fraction of one tile's M3C2.
pub const SAMPLE_CORES: usize = 40_000;

/// The file of an align unit: its [`Alignment`].
pub const FILE: &str = "align.json";

/// A later survey aligned onto the first on their stable ground.
pub struct AlignStage;

/// What an align unit records.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct AlignMeta {
    /// The transform is applied (the survey is tiled again with it).
    pub applied: bool,
    /// Core points computed for the fit, and those on stable ground.
    pub sampled: usize,
    pub stable_points: usize,
}

impl Stage for AlignStage {
    const KIND: &'static str = "align";
    const SCOPE: Scope = Scope::Survey;
    const LINE: Line = Line {
        name: "alignment",
        counts: "core points sampled",
        total: Total::Unknown,
    };
    type Meta = AlignMeta;

    /// With `--align auto`: one per survey compared that is not the first, onto the first (a
    /// campaign's surveys all onto its first, so that every pair is in one frame).
    fn plan(p: &mut Planner) -> Result<()> {
        if !p.plan.params.align_enabled() {
            return Ok(());
        }
        let key = format!(
            "{:?}|{}|{SAMPLE_TILES}",
            p.plan.params.m3c2(),
            p.plan.params.core_spacing.value
        );
        let first = p.the(&Spec::survey(TilingStage::KIND, 0))?;
        for s in later_surveys(p.plan) {
            let t = p.the(&Spec::survey(TilingStage::KIND, s))?;
            let label = p.plan.surveys[s].label.clone();
            p.add(Spec::survey(Self::KIND, s), &label, &[&key], vec![first, t]);
        }
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<AlignMeta> {
        let s = ctx.survey(unit)?;
        let (samples, sampled) = sample(ctx, s)?;
        let alignment = align(&samples, ctx.plan.params.core_spacing.value);
        (ctx.progress)(sampled as u64);
        super::write_json(out, FILE, &alignment)?;
        Ok(AlignMeta {
            applied: alignment.applied,
            sampled,
            stable_points: alignment.stable_points,
        })
    }
}

/// The surveys of the plan's pairs other than the first, in order, each once.
pub fn later_surveys(plan: &crate::plan::Plan) -> Vec<usize> {
    let mut s: Vec<usize> = plan
        .pairs
        .iter()
        .flat_map(|p| [p.before, p.after])
        .filter(|&s| s != 0)
        .collect();
    s.sort_unstable();
    s.dedup();
    s
}

/// The fit over `samples`: their stable ground, its noise, the rigid transform.
pub fn align(samples: &[Sample], spacing: f64) -> Alignment {
    let Some(sel) = select(samples) else {
        return Alignment::none(format!(
            "not applied: no stable ground among the {} core points sampled",
            samples.len()
        ));
    };
    let sigma_d = measure(samples, spacing).map_or(f64::NAN, |m| m.sigma_d);
    fit(samples, &sel.keep, &sel.finite, sigma_d)
}

/// The tiles sampled: every k-th of the grid's, k = ⌈tiles / SAMPLE_TILES⌉.
fn sample_tiles(grid: &talus_tiling::TileGrid) -> Vec<talus_tiling::TileId> {
    let all: Vec<_> = grid.tiles().collect();
    let k = all.len().div_ceil(SAMPLE_TILES).max(1);
    all.into_iter().step_by(k).collect()
}

/// M3C2 between survey 0 and survey `s` at the core points of the sampled tiles (raw tilings):
/// the samples with a distance, and how many core points were computed.
fn sample(ctx: &Ctx, s: usize) -> Result<(Vec<Sample>, usize)> {
    let plan = ctx.plan;
    let (t0, ts) = (
        ctx.unit(&Spec::survey(TilingStage::KIND, 0))?,
        ctx.unit(&Spec::survey(TilingStage::KIND, s))?,
    );
    let counts = [
        ctx.meta::<TilingStage>(t0)?.tile_points,
        ctx.meta::<TilingStage>(ts)?.tile_points,
    ];
    let grid = plan.layout.grid()?;
    let params = plan.params.m3c2();
    let (b, a) = (&plan.surveys[0].bounds, &plan.surveys[s].bounds);
    let mut samples = Vec::new();
    let mut computed = 0;
    let tiles = sample_tiles(&grid);
    let per_tile = (SAMPLE_CORES / tiles.len().max(1)).max(1000);
    for tile in tiles {
        let n = counts[0][grid.index(tile)] + counts[1][grid.index(tile)];
        if n == 0 {
            continue;
        }
        let _held = ctx.reserve(
            super::m3c2::need(n),
            &format!("aligning: tile {} ({n} points with its halo)", tile.name()),
        )?;
        let before = read_tile(ctx, t0, tile)?;
        let after = read_tile(ctx, ts, tile)?;
        fn epoch(t: &TilePoints) -> EpochPoints<'_> {
            EpochPoints {
                x: &t.x,
                y: &t.y,
                z: &t.z,
                owned: &t.owned,
            }
        }
        let extent = Extent {
            data_min: std::array::from_fn(|k| b.min[k].min(a.min[k])),
            data_max: std::array::from_fn(|k| b.max[k].max(a.max[k])),
            held: super::m3c2::open_box(&grid, tile, plan.layout.halo),
        };
        // Every k-th of the tile's core points (C1 thinned on the run's grid, keyed as the M3C2
        // units key them).
        let cores: Vec<(u64, crate::geom::Point3)> = crate::m3c2::core_points::thin(
            before.len(),
            |i| before.point(i),
            &plan.layout.anchor,
            plan.layout.core_spacing,
            |i| before.owned[i],
        )
        .into_iter()
        .map(|(k, i)| (k, before.point(i)))
        .collect();
        let stride = cores.len().div_ceil(per_tile).max(1);
        let picked: Vec<(u64, crate::geom::Point3)> = cores.into_iter().step_by(stride).collect();
        let results = compute(
            &epoch(&before),
            &epoch(&after),
            plan.layout.anchor,
            plan.layout.core_spacing,
            Some(&picked),
            &params,
            &extent,
        );
        computed += results.len();
        samples.extend(
            results
                .iter()
                .filter(|k| k.r.reach != Reach::Pending && k.r.measured().is_finite())
                .map(|k| Sample {
                    xyz: k.xyz,
                    normal: k.r.normal,
                    distance: k.r.measured(),
                    std_dev: [k.r.std_dev1, k.r.std_dev2],
                    lod: k.r.uncertainty,
                }),
        );
        crate::interrupt::check()?;
    }
    Ok((samples, computed))
}

/// The alignment of survey `s` (its align unit must be done), if it has one.
pub fn read(ctx: &Ctx, s: usize) -> Result<Option<Alignment>> {
    match ctx.plan.find(&Spec::survey(AlignStage::KIND, s)) {
        Some(u) => Ok(Some(super::read_json(ctx, u, FILE)?)),
        None => Ok(None),
    }
}

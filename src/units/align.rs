//! The alignment of a later survey onto the first (SPEC.md §1 "Registration: removed, not only
//! measured"), fitted on a sample: M3C2 at the core points (about [`SAMPLE_CORES`]) in a lattice
//! of [`WINDOWS`] × [`WINDOWS`] windows over the first survey's footprint — the same whatever
//! the tile layout — their stable ground found as the stable-ground unit finds it (`events::stable::select`), and a rigid
//! point-to-plane fit over it (`events::align::fit`), applied only when it is significant and
//! well constrained. The sample costs a few tiles' M3C2, not a second pass over all of them;
//! the survey is then tiled again with the transform ([`super::aligned`]) only when it applies.

use serde::{Deserialize, Serialize};

use super::stage::{Line, Planner, Scope, Stage, Total};
use super::tiling::TilingStage;
use super::{read_tile_near, Ctx, TilePoints};
use crate::error::Result;
use crate::events::align::{fit, Alignment};
use crate::events::chain::Fits;
use crate::events::stable::{measure, select, Sample};
use crate::m3c2::tile::{compute, EpochPoints};
use crate::m3c2::{Extent, Reach};
use crate::plan::Spec;
use crate::spatial::areas::Areas;
use crate::store::UnitWriter;

/// Windows across and along the first survey's footprint the fit samples (see [`windows`]):
/// 64 patches of about 25 × 25 core points, spread so that the turn about every axis is seen.
pub const WINDOWS: usize = 8;
/// Core points the fit computes, about: every k-th core point of the sampled tiles. Enough for a
/// six-parameter fit whose uncertainty is far below the noise (σ/√n), few enough that the
/// sample costs a fraction of one tile's M3C2.
pub const SAMPLE_CORES: usize = 40_000;

/// The file of an align unit: its [`Fits`].
pub const FILE: &str = "align.json";

/// A later survey aligned onto the first on their stable ground.
pub struct AlignStage;

/// What an align unit records.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct AlignMeta {
    /// The fit onto the first survey applies.
    pub applied: bool,
    /// Core points computed for the fits, and those on the stable ground of the fit onto the
    /// first.
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
    /// campaign's surveys all onto its first, so that every pair is in one frame) and, when its
    /// predecessor is aligned too, onto its predecessor (the chain of [`crate::events::chain`]).
    fn plan(p: &mut Planner) -> Result<()> {
        if !p.plan.params.align_enabled() {
            return Ok(());
        }
        let key = format!(
            "{:?}|{}|{WINDOWS}|chained|{}",
            p.plan.params.m3c2(),
            p.plan.params.core_spacing.value,
            super::stable::areas_key(p.plan)
        );
        let first = p.the(&Spec::survey(TilingStage::KIND, 0))?;
        let later = later_surveys(p.plan);
        for &s in &later {
            let mut deps = vec![first, p.the(&Spec::survey(TilingStage::KIND, s))?];
            if let Some(prev) = predecessor(&later, s) {
                deps.push(p.the(&Spec::survey(TilingStage::KIND, prev))?);
            }
            let label = p.plan.surveys[s].label.clone();
            p.add(Spec::survey(Self::KIND, s), &label, &[&key], deps);
        }
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<AlignMeta> {
        let s = ctx.survey(unit)?;
        let spacing = ctx.plan.params.core_spacing.value;
        let (samples, mut sampled) = sample(ctx, 0, s)?;
        let onto_first = align(&samples, spacing);
        let onto_previous = match predecessor(&later_surveys(ctx.plan), s) {
            Some(prev) => {
                let (samples, n) = sample(ctx, prev, s)?;
                sampled += n;
                Some(align(&samples, spacing))
            }
            None => None,
        };
        (ctx.progress)(sampled as u64);
        let meta = AlignMeta {
            applied: onto_first.applied,
            sampled,
            stable_points: onto_first.stable_points,
        };
        let fits = Fits {
            onto_first,
            onto_previous,
        };
        super::write_json(out, FILE, &fits)?;
        Ok(meta)
    }
}

/// The survey before `s` when it is aligned too (so that `s` may reach the first through it):
/// none for the second survey, whose predecessor is the first.
fn predecessor(later: &[usize], s: usize) -> Option<usize> {
    let prev = s.checked_sub(1)?;
    (prev >= 1 && later.contains(&prev)).then_some(prev)
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

/// The windows the fit samples, [x0, y0, x1, y1]: a [`WINDOWS`] × [`WINDOWS`] lattice over the
/// first survey's footprint, each a square centred in its cell, sized to hold about
/// [`SAMPLE_CORES`] core points in all (never more than its cell). They depend on the first
/// survey and the core spacing only, not on the tiles, so the sample — and the fit — is the same
/// whatever the tile layout.
///
/// With the user's stable areas, the fit is on their ground alone: the windows are the polygons'
/// boxes, and only the core points inside the polygons are sampled ([`sample`]).
fn windows(plan: &crate::plan::Plan) -> Vec<[f64; 4]> {
    if let Some(a) = &plan.stable_areas {
        return a.areas.boxes();
    }
    let b = &plan.surveys[0].bounds;
    let c = plan.params.core_spacing.value;
    let n = WINDOWS as f64;
    let (cw, ch) = ((b.max[0] - b.min[0]) / n, (b.max[1] - b.min[1]) / n);
    let side = c * (SAMPLE_CORES as f64).sqrt() / n;
    let (hw, hh) = (0.5 * side.min(cw), 0.5 * side.min(ch));
    let mut out = Vec::with_capacity(WINDOWS * WINDOWS);
    for j in 0..WINDOWS {
        for i in 0..WINDOWS {
            let cx = b.min[0] + (i as f64 + 0.5) * cw;
            let cy = b.min[1] + (j as f64 + 0.5) * ch;
            out.push([cx - hw, cy - hh, cx + hw, cy + hh]);
        }
    }
    out
}

/// M3C2 between survey `onto` and survey `s` (their own tilings) at the core points in the
/// sample's [`windows`]: the samples measured within the cylinder (a walked distance may be
/// finished in another tile, so it is left out), in core-point key order; and how many were
/// computed.
fn sample(ctx: &Ctx, onto: usize, s: usize) -> Result<(Vec<Sample>, usize)> {
    let plan = ctx.plan;
    let (t0, ts) = (
        ctx.unit(&Spec::survey(TilingStage::KIND, onto))?,
        ctx.unit(&Spec::survey(TilingStage::KIND, s))?,
    );
    let (m0, ms) = (ctx.meta::<TilingStage>(t0)?, ctx.meta::<TilingStage>(ts)?);
    // The densest tile of the two surveys first, as the M3C2 units check it: a budget that
    // cannot hold it is refused with the same words, whichever unit meets it first.
    let pair_points = super::m3c2::fit::pair_tile_points(plan, &m0, &ms)?;
    super::m3c2::fit::check_tiled(plan, &pair_points)?;
    let counts = [m0.tile_points, ms.tile_points];
    let grid = plan.layout.grid()?;
    // The fit is the same whichever way each normal points (a distance and its normal turn
    // together: d = n·(t + ω × c) either way), so the sample needs no orientation field.
    let params = crate::m3c2::M3c2Params {
        orientation: crate::m3c2::Orientation::Up,
        ..plan.params.m3c2()
    };
    let (b, a) = (&plan.surveys[onto].bounds, &plan.surveys[s].bounds);
    let wins = windows(plan);
    let areas = plan.stable_areas.as_ref().map(|a| &a.areas);
    // With the user's areas: about SAMPLE_CORES of their core points however large the areas
    // (the first survey's footprint holds about its area / spacing² of them).
    let thin = areas.map_or(1, |a| {
        let c = plan.layout.core_spacing;
        let footprint = (b.max[0] - b.min[0]) * (b.max[1] - b.min[1]) / (c * c);
        a.one_in(
            [b.min[0], b.min[1], b.max[0], b.max[1]],
            footprint,
            SAMPLE_CORES as u64,
        )
    });
    let inside = |p: &crate::geom::Point3| match areas {
        Some(a) => a.contains(p[0], p[1]),
        None => wins
            .iter()
            .any(|w| p[0] >= w[0] && p[0] < w[2] && p[1] >= w[1] && p[1] < w[3]),
    };
    // Every point a window's core point uses for its normal (and its orientation's look-ups of
    // the top surface, up to 4 normal radii away in cells of half a radius) and its cylinder lies
    // within `reach` of the window: only those points are indexed, and each Window result is the
    // one the whole tile gives, at a fraction of the indexing.
    let reach = (params.cyl_radius.powi(2) + params.cyl_halflen.powi(2))
        .sqrt()
        .max(5.0 * params.normal_radius)
        + plan.layout.core_spacing;
    let mut keyed: Vec<(u64, Sample)> = Vec::new();
    let mut computed = 0;
    for tile in grid.tiles() {
        let sq = grid.square(tile);
        // The windows meeting the tile, grown by `reach`.
        let near: Vec<[f64; 4]> = wins
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
            &format!("aligning: tile {} ({n} points with its halo)", tile.name()),
        )?;
        // Only the frames that reach the windows or their neighbourhoods: every point `within`
        // keeps and every point of a core-point cell `inside` a window (a cell is far smaller
        // than `reach`) is in them, so the sample is the one the whole tile gives.
        let reached: Vec<[f64; 4]> = near.iter().chain(&wins).copied().collect();
        let before = read_tile_near(ctx, t0, tile, &reached)?;
        let after = read_tile_near(ctx, ts, tile, &reached)?;
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
        .filter(|(k, p)| inside(p) && Areas::takes(*k, thin))
        .collect();
        if cores.is_empty() {
            continue;
        }
        let (before, after) = (within(&before, &near), within(&after, &near));
        let results = compute(
            &epoch(&before),
            &epoch(&after),
            plan.layout.anchor,
            plan.layout.core_spacing,
            Some(&cores),
            &params,
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

/// The fits of survey `s` (its align unit must be done), if it has them.
pub fn read(ctx: &Ctx, s: usize) -> Result<Option<Fits>> {
    match ctx.plan.find(&Spec::survey(AlignStage::KIND, s)) {
        Some(u) => Ok(Some(super::read_json(ctx, u, FILE)?)),
        None => Ok(None),
    }
}

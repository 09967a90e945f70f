//! The alignment of a later survey onto the first (SPEC.md §1 "Registration: removed, not only
//! measured"), fitted on a sample: M3C2 at the core points (about [`SAMPLE_CORES`]) in a lattice
//! of [`WINDOWS`] × [`WINDOWS`] windows over the first survey's footprint — the same whatever
//! the tile layout — their stable ground found as the stable-ground unit finds it (`events::stable::select`), and a rigid
//! point-to-plane fit over it (`events::align::fit`), applied only when it is significant and
//! well constrained. The sample costs a few tiles' M3C2, not a second pass over all of them;
//! the survey is then tiled again with the transform ([`super::aligned`]) only when it applies.

use serde::{Deserialize, Serialize};

use super::sample::{Picks, Region};
use super::stage::{Line, Planner, Scope, Stage, Total};
use super::Ctx;
use crate::error::Result;
use crate::events::align::{find, Alignment, Ground, Limits};
use crate::events::chain::Fits;
use crate::events::stable::Sample;
use crate::plan::Spec;
use crate::spatial::areas::Areas;
use crate::store::UnitWriter;

/// Windows across and along the first survey's footprint the fit samples (see `windows`):
/// 64 patches of about 25 × 25 core points, spread so that the turn about every axis is seen.
pub(crate) const WINDOWS: usize = 8;
/// Core points the fit computes, about: every k-th core point of the sampled tiles. Enough for a
/// six-parameter fit whose uncertainty is far below the noise (σ/√n), few enough that the
/// sample costs a fraction of one tile's M3C2.
pub(crate) const SAMPLE_CORES: usize = 40_000;

/// The file of an align unit: its [`Fits`].
pub(crate) const FILE: &str = "align.json";

/// A later survey aligned onto the first on their stable ground.
pub(crate) struct AlignStage;

/// What an align unit records.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct AlignMeta {
    /// The fit onto the first survey applies.
    pub(crate) applied: bool,
    /// Core points computed for the fits, and those on the stable ground of the fit onto the
    /// first.
    pub(crate) sampled: usize,
    pub(crate) stable_points: usize,
}

impl Stage for AlignStage {
    const KIND: &'static str = "align";
    const SCOPE: Scope = Scope::Survey;
    const VERSION: u32 = 1;
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
            "{:?}|{}|{WINDOWS}|chained|{}|align {} {:?}|holdout {}",
            p.plan.params.m3c2(),
            p.plan.params.core_spacing.value,
            super::stable::areas_key(p.plan),
            p.plan.params.align.value,
            p.plan.params.align_limits(),
            crate::events::align::holdout::BLOCKS
        );
        let first = p.tiling_units(0)?;
        let later = later_surveys(p.plan);
        for &s in &later {
            let mut deps = first.clone();
            deps.extend(p.tiling_units(s)?);
            if let Some(prev) = predecessor(&later, s) {
                deps.extend(p.tiling_units(prev)?);
            }
            let label = p.plan.surveys[s].label.clone();
            p.add(Spec::survey(Self::KIND, s), &label, &[&key], deps);
        }
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<AlignMeta> {
        let s = ctx.survey(unit)?;
        let (onto_first, mut sampled) = fit_onto(ctx, 0, s)?;
        gross(ctx, 0, s, &onto_first)?;
        // Through the predecessor unless the direct fit is known to be too small to matter: the
        // route is then the identity (`events::chain`), and a survey that needs no alignment
        // (most of a permanent scanner's) costs one sample, not two.
        let nothing = onto_first.determined && !onto_first.applied;
        let onto_previous = match predecessor(&later_surveys(ctx.plan), s) {
            Some(prev) if !nothing => {
                let (a, n) = fit_onto(ctx, prev, s)?;
                sampled += n;
                gross(ctx, prev, s, &a)?;
                Some(a)
            }
            _ => None,
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

/// The fit of survey `s` onto survey `onto`, and how many points it computed. With the user's
/// stable areas, on every point inside them; where their ground leaves directions free (flat
/// areas see no horizontal shift, no turn about the vertical), those are fitted on the rest of
/// the surveys' stable ground ([`crate::events::align::complete`]).
fn fit_onto(ctx: &Ctx, onto: usize, s: usize) -> Result<(Alignment, usize)> {
    let plan = ctx.plan;
    let limits = limits_onto(plan.params.align_limits(), onto);
    let windows = Region::Windows(windows(plan));
    let Some(areas) = &plan.stable_areas else {
        let (samples, n) = sample_of(ctx, onto, s, &windows, Picks::Cores(1))?;
        return Ok((find(&samples, &limits, Ground::Automatic), n));
    };
    let (inside, mut n) = sample_of(
        ctx,
        onto,
        s,
        &Region::Areas(&areas.areas),
        Picks::Points(points_one_in(plan, onto, &areas.areas)),
    )?;
    let user = find(&inside, &limits, Ground::User);
    if user.constrained >= 6 || !user.determined {
        return Ok((user, n));
    }
    let (rest, m) = sample_of(ctx, onto, s, &windows, Picks::Cores(1))?;
    n += m;
    Ok((
        crate::events::align::complete(&user, &inside, &rest, &limits),
        n,
    ))
}

/// One point in how many of survey `onto`'s inside `areas` the sample takes: about
/// [`SAMPLE_CORES`] however large the areas (the survey holds about its points × the share of
/// its footprint the areas' boxes cover).
fn points_one_in(plan: &crate::plan::Plan, onto: usize, areas: &Areas) -> u64 {
    let sv = &plan.surveys[onto];
    let b = &sv.bounds;
    areas.one_in(
        [b.min[0], b.min[1], b.max[0], b.max[1]],
        sv.points as f64,
        SAMPLE_CORES as u64,
    )
}

/// How far a survey may be off survey `onto` when each is within `limits` of the first: onto
/// the first itself, one misregistration; onto a predecessor (itself aligned), two
/// ([`Limits::between`]).
fn limits_onto(limits: Limits, onto: usize) -> Limits {
    if onto == 0 {
        limits
    } else {
        limits.between()
    }
}

/// A gross misregistration of survey `s` onto survey `onto` stops the run (exit 2), naming the
/// survey, how far off it is and what to do: a comparison of surveys metres apart measures
/// their offset, not the terrain's change.
fn gross(ctx: &Ctx, onto: usize, s: usize, a: &Alignment) -> Result<()> {
    if !a.gross {
        return Ok(());
    }
    let (later, earlier) = (&ctx.plan.surveys[s], &ctx.plan.surveys[onto]);
    let t = a.translation;
    let limits = limits_onto(Limits::PLAUSIBLE, onto);
    Err(crate::error::Error::input(
        &later.arg,
        format!(
            "it lies up to {:.2} m from {} (shift {:+.3}, {:+.3}, {:+.3} m, turn {:.3}°: a rigid \
             fit on {} core points of their common ground, residual {:.3} m, confirmed on \
             held-out ground), more than a registration error leaves ({} m, {}°): check both \
             surveys' CRS and georeferencing; --align on removes the offset, --align off \
             compares the surveys as delivered",
            a.largest_shift_m,
            earlier.arg.display(),
            t[0],
            t[1],
            t[2],
            a.rotation_deg(),
            a.stable_points,
            a.residual_m,
            limits.shift_m,
            limits.turn_deg
        ),
    ))
}

/// The survey before `s` when it is aligned too (so that `s` may reach the first through it):
/// none for the second survey, whose predecessor is the first.
fn predecessor(later: &[usize], s: usize) -> Option<usize> {
    let prev = s.checked_sub(1)?;
    (prev >= 1 && later.contains(&prev)).then_some(prev)
}

/// The surveys of the plan's pairs other than the first, in order, each once.
pub(crate) fn later_surveys(plan: &crate::plan::Plan) -> Vec<usize> {
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

/// The windows the fit samples, [x0, y0, x1, y1]: a [`WINDOWS`] × [`WINDOWS`] lattice over the
/// first survey's footprint, each a square centred in its cell, sized to hold about
/// [`SAMPLE_CORES`] core points in all (never more than its cell). They depend on the first
/// survey and the core spacing only, not on the tiles, so the sample — and the fit — is the same
/// whatever the tile layout.
///
fn windows(plan: &crate::plan::Plan) -> Vec<[f64; 4]> {
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

/// M3C2 between survey `onto` and survey `s` (their own tilings) in `region` at `picks`: the
/// samples (`super::sample`) and how many points were computed. Normals are oriented up: the
/// fit is the same whichever way each normal points (a distance and its normal turn together:
/// d = n·(t + ω × c) either way), so the sample needs no orientation field.
fn sample_of(
    ctx: &Ctx,
    onto: usize,
    s: usize,
    region: &Region,
    picks: Picks,
) -> Result<(Vec<Sample>, usize)> {
    let tilings = [ctx.own_tiling(onto)?, ctx.own_tiling(s)?];
    let params = crate::m3c2::M3c2Params {
        orientation: crate::m3c2::Orientation::Up,
        ..ctx.plan.params.m3c2()
    };
    super::sample::sample(ctx, [&tilings[0], &tilings[1]], region, picks, &params)
}

/// The fits of survey `s` (its align unit must be done), if it has them.
pub(crate) fn read(ctx: &Ctx, s: usize) -> Result<Option<Fits>> {
    match ctx.plan.find(&Spec::survey(AlignStage::KIND, s)) {
        Some(u) => Ok(Some(super::read_json(ctx, u, FILE)?)),
        None => Ok(None),
    }
}

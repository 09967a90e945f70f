//! A stable-ground unit: the pair's noise and registration error measured on the M3C2 results
//! (`events::stable`), and the parameters that follow from them (reg_error, threshold), for
//! everything downstream: LoD95 and significance in m3c2.laz, the events' filter, the volumes'
//! uncertainty.

use serde::{Deserialize, Serialize};

use super::m3c2::{pair_count, Merged};
use super::stage::{Line, Planner, Scope, Stage, Total};
use super::Ctx;
use crate::error::{Error, Result};
use crate::events::stable::{measure, Sample, Stable};
use crate::params::Params;
use crate::plan::Spec;
use crate::spatial::areas::Areas;
use crate::store::UnitWriter;

/// Core points sampled (evenly, in key order) for the measurement: enough for the fit (the robust
/// standard deviation of 500,000 residuals has a relative standard error near 0.2 %) and the
/// variogram (which draws 300,000 pairs and 20,000 anchors from them), and a fixed size whatever
/// the survey, so that the smallest budget does not grow with it (was 1,000,000: 244 MiB, the
/// floor of the 120M-point pair).
pub const SAMPLES: u64 = 500_000;

/// Resident bytes per sampled core point while the stable ground is measured: the sample (80)
/// and the measurement's index lists, residuals and variogram pairs. Measured on the 40M-point
/// pair (481,675 samples): the unit's peak 112–117 MiB in a process of its own, of which the
/// merge of the pair's runs holds up to 34 MiB and the process's base about 12: ≈ 155 bytes a
/// sample (was counted as 256 from an older measurement, 185 MiB for 757 k).
pub const BYTES_PER_SAMPLE: u64 = 176;

/// The file of a stable unit.
pub const FILE: &str = "stable.json";

/// What a stable unit writes: the measurement only. The parameters that follow from it are the
/// current plan's with it (`params`): a unit reused from a run with other parameters (its key
/// does not depend on the threshold, say) must not bring that run's values along.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StableGround {
    /// None: too few stable core points to measure.
    pub stable: Option<Stable>,
}

impl StableGround {
    /// The plan's parameters with reg_error and threshold resolved from the measurement.
    pub fn params(&self, plan: &crate::plan::Plan) -> Params {
        plan.params.clone().with_stable(self.stable.as_ref())
    }
}

/// The pair's stable ground: noise and registration error.
pub struct StableStage;

/// What a stable-ground unit records.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct StableMeta {
    /// Core points sampled for the measurement.
    pub sampled: usize,
}

impl Stage for StableStage {
    const KIND: &'static str = "stable";
    const SCOPE: Scope = Scope::Pair;
    const LINE: Line = Line {
        name: "stable ground",
        counts: "core points sampled",
        total: Total::Unknown,
    };
    type Meta = StableMeta;

    /// One per pair, over the pair's M3C2 units (and the user's stable areas, by content).
    fn plan(p: &mut Planner) -> Result<()> {
        let samples = SAMPLES.to_string();
        let areas = areas_key(p.plan);
        for pair in 0..p.plan.pairs.len() {
            let m3c2 = p.pair_results(pair);
            let label = p.plan.pairs[pair].label.clone();
            p.add(
                Spec::pair(Self::KIND, pair),
                &label,
                &[&samples, &areas],
                m3c2,
            );
        }
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<StableMeta> {
        run(ctx, ctx.pair(unit)?, out)
    }
}

/// Resident bytes of a stable unit sampling `most` core points beside a merge of `inputs`
/// inputs (`merged::merge_inputs`). Fixed: at most SAMPLES and FAN_IN runs, which the smallest
/// budget holds (`memory::MIN_BUDGET`'s test), so no budget talus accepts refuses it.
pub fn need(most: u64, inputs: usize) -> u64 {
    most * BYTES_PER_SAMPLE + (8 << 20) + super::m3c2::merge_need(inputs)
}

/// The key part of the user's stable areas: their file's content key, or `auto`.
pub fn areas_key(plan: &crate::plan::Plan) -> String {
    plan.stable_areas
        .as_ref()
        .map_or_else(|| "auto".into(), |a| format!("areas {}", a.file.key))
}

/// Measure pair `pair`'s stable ground into `out`: on every `step`-th core point, or — with the
/// user's stable areas — on the core points inside them, every one unless they could hold more
/// than SAMPLES (the areas may be narrow: transects a few metres wide would lose most of their
/// points to the pair's step).
fn run(ctx: &Ctx, pair: usize, out: &mut UnitWriter) -> Result<StableMeta> {
    let total = pair_count(ctx, pair)?;
    let areas = ctx.plan.stable_areas.as_ref().map(|a| &a.areas);
    // Every step-th core point; with the user's areas, their core points — one in `step`
    // ([`Areas::one_in`]) when they could hold more than SAMPLES, else every one.
    let step = match areas {
        Some(a) => {
            let e = &ctx.plan.layout.extent;
            a.one_in(
                [e.min[0], e.min[1], e.max[0], e.max[1]],
                total as f64,
                SAMPLES,
            )
        }
        None => total.div_ceil(SAMPLES).max(1),
    };
    // At most SAMPLES are kept (areas denser than the rest could offer more: the rest is left
    // out, and the reservation holds).
    let most = total.div_ceil(step).min(SAMPLES);
    let _held = ctx.reserve(
        need(most, super::merged::merge_inputs(ctx.plan)),
        "the stable-ground sample and the merge of the pair's tiles",
    )?;
    let mut samples = Vec::with_capacity(most as usize);
    let mut merged = Merged::new(ctx, pair)?;
    let mut n = 0u64;
    let need = ctx.plan.params.min_points.value.max(1);
    let mut reached = Reached::default();
    let (mut inside, mut in_areas) = (0u64, 0u64);
    while let Some(k) = merged.next_result()? {
        reached.add(&k.r, need);
        let finite = k.r.measured().is_finite();
        let take = match areas {
            Some(a) => {
                let within = a.contains(k.xyz[0], k.xyz[1]);
                inside += u64::from(within);
                in_areas += u64::from(within && finite);
                within && Areas::takes(k.key, step)
            }
            None => n.is_multiple_of(step),
        };
        if take && finite && (samples.len() as u64) < most {
            samples.push(Sample {
                xyz: k.xyz,
                normal: k.r.normal,
                distance: k.r.measured(),
                std_dev: [k.r.std_dev1, k.r.std_dev2],
                lod: k.r.uncertainty,
            });
        }
        n += 1;
    }
    if reached.distances == 0 {
        return Err(Error::Epochs(reached.why_none(ctx.plan, pair, n)));
    }
    (ctx.progress)(samples.len() as u64);
    if let Some(a) = &ctx.plan.stable_areas {
        if in_areas == 0 {
            return Err(Error::input(
                &a.file.path,
                format!(
                    "its polygons hold {inside} of the {n} core points of {}, none with a \
                     distance: no stable ground to measure (are they where both surveys have \
                     points?)",
                    ctx.plan.pair_name(pair)
                ),
            ));
        }
    }
    let mut stable = measure(&samples, ctx.plan.params.core_spacing.value);
    if let (Some(s), Some(a)) = (stable.as_mut(), &ctx.plan.stable_areas) {
        s.source = "areas".into();
        s.file = Some(a.file.path.clone());
        s.method = format!(
            "{}; the candidates: the {in_areas} core points with a distance inside the stable \
             areas",
            s.method
        );
    }
    let ground = StableGround { stable };
    super::write_json(out, FILE, &ground)?;
    Ok(StableMeta {
        sampled: samples.len(),
    })
}

/// How far a pair's core points got: how many have a normal, enough points of each epoch in their
/// cylinder, a distance.
#[derive(Debug, Default)]
struct Reached {
    normals: u64,
    before: u64,
    after: u64,
    distances: u64,
    /// Core points whose other epoch lies beyond the user's half-length (found by the walk).
    beyond: u64,
}

impl Reached {
    fn add(&mut self, r: &crate::m3c2::CoreResult, need: u32) {
        self.normals += u64::from(r.normal[0].is_finite());
        self.before += u64::from(r.count1 >= need);
        self.after += u64::from(r.count2 >= need);
        self.distances += u64::from(r.measured().is_finite());
        self.beyond += u64::from(r.reach == crate::m3c2::Reach::Beyond);
    }

    /// Why none of the pair's `n` core points got a distance (a run that yields nothing is
    /// refused rather than published as a result of empty columns).
    fn why_none(&self, plan: &crate::plan::Plan, pair: usize, n: u64) -> String {
        let p = &plan.params;
        let what = plan.pair_name(pair);
        let fmt = |v: f64| format!("{v:.4}");
        let given = |r: &crate::params::Resolved<f64>, flag: &str| {
            if r.is_user() {
                format!("{} ({flag})", r.value)
            } else {
                format!("{} ({})", fmt(r.value), r.source)
            }
        };
        let cylinder = format!(
            "M3C2's cylinder (radius {}, half-length {}, at least {} point(s) of each epoch)",
            given(&p.cyl_radius, "--cyl-radius"),
            given(&p.cyl_halflen, "--cyl-halflen"),
            p.min_points.value.max(1)
        );
        let why = if n == 0 {
            "no core point lies where the epochs were tiled".to_string()
        } else if self.normals == 0 {
            format!(
                "no core point has the {} neighbours a normal needs within the normal radius {} (the point spacing is {})",
                crate::m3c2::normals::MIN_NORMAL_POINTS,
                given(&p.normal_radius, "--normal-radius"),
                fmt(p.point_spacing.value),
            )
        } else if self.beyond > 0 {
            format!(
                "at {} core point(s) the other epoch lies along the normal beyond the cylinder's \
                 half-length {}: the epochs do not overlap within it (leave --cyl-halflen out and \
                 talus follows the normal to the other epoch)",
                self.beyond,
                given(&p.cyl_halflen, "--cyl-halflen")
            )
        } else if self.before == 0 {
            format!("no core point has enough points of the before epoch in {cylinder}")
        } else if self.after == 0 {
            format!("no core point has enough points of the after epoch in {cylinder}: the epochs do not overlap along the normals")
        } else {
            format!("no core point has enough points of both epochs in {cylinder}")
        };
        format!("{what}: no distance at any of the {n} core points: {why}")
    }
}

/// The stable ground of pair `pair` (its unit must be done).
pub fn read(ctx: &Ctx, pair: usize) -> Result<StableGround> {
    let u = ctx.unit(&Spec::pair(StableStage::KIND, pair))?;
    super::read_json(ctx, u, FILE)
}

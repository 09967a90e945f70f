//! A stable-ground unit: the pair's noise and registration error measured on the M3C2 results
//! (`events::stable`), and the parameters that follow from them (reg_error, threshold), for
//! everything downstream: LoD95 and significance in m3c2.laz, the events' filter, the volumes'
//! uncertainty.

use serde::{Deserialize, Serialize};

use super::m3c2::{pair_count, Merged};
use super::stage::{Line, Planner, Scope, Stage, Total};
use super::Ctx;
use crate::error::{Error, Result};
use crate::events::stable::{measure, AreasUse, Sample, Stable};
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
pub(crate) const BYTES_PER_SAMPLE: u64 = 176;

/// The file of a stable unit.
pub(crate) const FILE: &str = "stable.json";

/// What a stable unit writes: the measurement only. The parameters that follow from it are the
/// current plan's with it (`params`): a unit reused from a run with other parameters (its key
/// does not depend on the threshold, say) must not bring that run's values along.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct StableGround {
    /// None: too few stable core points to measure.
    pub(crate) stable: Option<Stable>,
    /// With the user's stable areas: what they held, and whether the measurement is theirs.
    pub(crate) areas: Option<AreasUse>,
}

impl StableGround {
    /// The plan's parameters with reg_error and threshold resolved from the measurement.
    pub(crate) fn params(&self, plan: &crate::plan::Plan) -> Params {
        plan.params.clone().with_stable(self.stable.as_ref())
    }
}

/// The pair's stable ground: noise and registration error.
pub(crate) struct StableStage;

/// What a stable-ground unit records.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct StableMeta {
    /// Core points sampled for the measurement.
    pub(crate) sampled: usize,
}

impl Stage for StableStage {
    const KIND: &'static str = "stable";
    const SCOPE: Scope = Scope::Pair;
    const VERSION: u32 = 1;
    const LINE: Line = Line {
        name: "stable ground",
        counts: "core points sampled",
        total: Total::Unknown,
    };
    type Meta = StableMeta;

    /// One per pair, over the pair's M3C2 units — or its `sampled` ranges, which made the pass
    /// over them — (and, with the user's stable areas, by content, the units holding its
    /// surveys' tiles: their points inside the areas are sampled).
    fn plan(p: &mut Planner) -> Result<()> {
        let samples = format!("{SAMPLES}|areas at every point 1");
        let areas = areas_key(p.plan);
        for pair in 0..p.plan.pairs.len() {
            // The pass over the results made in ranges (`super::sampled`), or here.
            let ranges = p.of_pair(super::sampled::SampledStage::KIND, pair);
            let mut m3c2 = match ranges.is_empty() {
                true => p.pair_results(pair),
                false => ranges,
            };
            if p.plan.stable_areas.is_some() {
                let (b, a) = (p.plan.pairs[pair].before, p.plan.pairs[pair].after);
                m3c2.extend(p.survey_tiles(b)?);
                m3c2.extend(p.survey_tiles(a)?);
            }
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
pub(crate) fn need(most: u64, inputs: usize) -> u64 {
    sample_need(most) + super::m3c2::merge_need(inputs)
}

/// Resident bytes of a stable unit's sample of `most` core points alone (read from its ranges).
fn sample_need(most: u64) -> u64 {
    most * BYTES_PER_SAMPLE + crate::memory::IO_HEADROOM
}

/// The key part of the user's stable areas: their file's content key, or `auto`.
pub(crate) fn areas_key(plan: &crate::plan::Plan) -> String {
    plan.stable_areas
        .as_ref()
        .map_or_else(|| "auto".into(), |a| format!("areas {}", a.file.key))
}

/// Measure pair `pair`'s stable ground into `out`: on every `step`-th core point of its M3C2
/// results (the automatic stable ground, found in the distances), or — with the user's stable
/// areas — on every point of the before survey inside them (`super::sample`; one in `n` when
/// they could hold more than [`SAMPLES`]). Areas that give too little ground to measure are not
/// dropped in silence: the automatic measurement is used, and `stable.areas` says why.
fn run(ctx: &Ctx, pair: usize, out: &mut UnitWriter) -> Result<StableMeta> {
    let plan = ctx.plan;
    let spacing = plan.params.core_spacing.value;
    // The user's areas first, while the unit holds nothing else (the sample reserves by tile).
    let inside = match &plan.stable_areas {
        Some(a) => Some(areas_sample(ctx, pair, &a.areas)?),
        None => None,
    };
    let total = pair_count(ctx, pair)?;
    let step = super::sampled::step(total);
    // At most SAMPLES: the multiples of `step` below `total` are no more.
    let most = total.div_ceil(step);
    let ranges: Vec<usize> = plan
        .of_pair(super::sampled::SampledStage::KIND, pair)
        .collect();
    // The merge of the pair's tiles where this unit makes the pass; the ranges' samples are
    // read one file after the other (a buffer each, within the headroom).
    let _held = match ranges.is_empty() {
        true => ctx.reserve(
            need(most, super::merged::merge_inputs(plan)),
            "the stable-ground sample and the merge of the pair's tiles",
        )?,
        false => ctx.reserve(sample_need(most), "the stable-ground sample")?,
    };
    let mut samples = Vec::with_capacity(most as usize);
    let mut n = 0u64;
    let mut reached = Reached::default();
    if ranges.is_empty() {
        let mut merged = Merged::new(ctx, pair)?;
        let need = plan.params.min_points.value.max(1);
        while let Some(k) = merged.next_result()? {
            reached.add(&k.r, need);
            if n.is_multiple_of(step) && k.r.measured().is_finite() {
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
    }
    // The pass made in ranges: their samples one after the other, their counts added up.
    let ranged = super::m3c2::seek::ranges_of::<super::sampled::SampledStage>(ctx, pair)?;
    for (u, m) in ranged {
        super::sampled::read(ctx, u, &m, &mut samples)?;
        reached.merge(&m.reached);
        n = m.to;
    }
    if reached.distances == 0 {
        return Err(Error::Epochs(reached.why_none(plan, pair, n)));
    }
    // Counted by the ranges where they sampled.
    if plan
        .of_pair(super::sampled::SampledStage::KIND, pair)
        .next()
        .is_none()
    {
        (ctx.progress)(samples.len() as u64);
    }
    let automatic = measure(&samples, spacing);
    let (stable, areas) = match (&plan.stable_areas, inside) {
        (Some(a), Some((inside, computed))) => {
            let with_distance = inside.len();
            if with_distance == 0 {
                return Err(Error::input(
                    &a.file.path,
                    format!(
                        "its polygons hold {computed} points of the before survey of {}, none \
                         with a distance: no stable ground to measure (are they where both \
                         surveys have points?)",
                        plan.pair_name(pair)
                    ),
                ));
            }
            let mut use_ = AreasUse {
                file: a.file.path.clone(),
                points_inside: computed,
                with_distance,
                used: true,
                note: None,
            };
            match measure(&inside, spacing) {
                Some(mut m) => {
                    m.source = "user".into();
                    m.file = Some(a.file.path.clone());
                    m.method = format!(
                        "{}; the candidates: the {with_distance} points of the before survey \
                         inside the stable areas with a distance",
                        m.method
                    );
                    (Some(m), Some(use_))
                }
                None => {
                    use_.used = false;
                    use_.note = Some(format!(
                        "the stable areas gave {with_distance} points with a distance, fewer \
                         than the {} stable points a measurement needs: {}",
                        crate::events::stable::MIN_STABLE,
                        if automatic.is_some() {
                            "the automatic stable ground is used instead"
                        } else {
                            "nor is there automatic stable ground: the threshold falls back to \
                             the point spacing"
                        }
                    ));
                    (automatic, Some(use_))
                }
            }
        }
        _ => (automatic, None),
    };
    let ground = StableGround { stable, areas };
    super::write_json(out, FILE, &ground)?;
    Ok(StableMeta {
        sampled: samples.len(),
    })
}

/// M3C2 of pair `pair`'s surveys (as every later stage reads them: aligned, cleared) at every
/// point of the before survey inside `areas` (one in `n` past [`SAMPLES`]): the samples with a
/// distance, and how many points were computed.
fn areas_sample(ctx: &Ctx, pair: usize, areas: &Areas) -> Result<(Vec<Sample>, usize)> {
    let plan = ctx.plan;
    let p = &plan.pairs[pair];
    let sv = &plan.surveys[p.before];
    let b = &sv.bounds;
    let one_in = areas.one_in(
        [b.min[0], b.min[1], b.max[0], b.max[1]],
        sv.points as f64,
        SAMPLES,
    );
    let params = crate::m3c2::M3c2Params {
        orientation: crate::m3c2::Orientation::Up,
        ..plan.params.m3c2()
    };
    super::sample::sample(
        ctx,
        [&ctx.tiling(p.before)?, &ctx.tiling(p.after)?],
        &super::sample::Region::Areas(areas),
        super::sample::Picks::Points(one_in),
        &params,
    )
}

/// How far a pair's core points got: how many have a normal, enough points of each epoch in their
/// cylinder, a distance.
#[derive(Debug, Default, Clone, Serialize, Deserialize)]
pub(crate) struct Reached {
    normals: u64,
    before: u64,
    after: u64,
    distances: u64,
    /// Core points whose other epoch lies beyond the user's half-length (found by the walk).
    beyond: u64,
}

impl Reached {
    /// The counts of `self` and `other` together (the pass made in ranges).
    fn merge(&mut self, other: &Reached) {
        self.normals += other.normals;
        self.before += other.before;
        self.after += other.after;
        self.distances += other.distances;
        self.beyond += other.beyond;
    }

    pub(crate) fn add(&mut self, r: &crate::m3c2::CoreResult, need: u32) {
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
pub(crate) fn read(ctx: &Ctx, pair: usize) -> Result<StableGround> {
    let u = ctx.unit(&Spec::pair(StableStage::KIND, pair))?;
    super::read_json(ctx, u, FILE)
}

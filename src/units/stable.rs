//! A stable-ground unit: the pair's noise and registration error measured on the M3C2 results
//! (`events::stable`), and the parameters that follow from them (reg_error, threshold), for
//! everything downstream: LoD95 and significance in m3c2.laz, the events' filter, the volumes'
//! uncertainty.

use serde::{Deserialize, Serialize};

use super::m3c2::{pair_count, Merged};
use super::Ctx;
use crate::error::Result;
use crate::events::stable::{measure, Sample, Stable};
use crate::params::Params;
use crate::store::UnitWriter;

/// Core points sampled (evenly, in key order) for the measurement: enough for the fit and the
/// variogram, few enough to hold (≈ 80 bytes each).
pub const SAMPLES: u64 = 1_000_000;

/// Resident bytes per sampled core point while the stable ground is measured: the sample (80)
/// and the measurement's index lists, residuals and variogram pairs (measured: 185 MiB for
/// 757 k samples, i.e. about 240).
pub const BYTES_PER_SAMPLE: u64 = 256;

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

/// Measure pair `pair`'s stable ground into `out`.
pub fn run(ctx: &Ctx, pair: usize, out: &mut UnitWriter) -> Result<serde_json::Value> {
    let total = pair_count(ctx, pair)?;
    let step = total.div_ceil(SAMPLES).max(1);
    let _held = ctx.reserve(
        total.div_ceil(step) * BYTES_PER_SAMPLE + (8 << 20),
        "the stable-ground sample",
    )?;
    let mut samples = Vec::with_capacity(total.min(SAMPLES) as usize);
    let mut merged = Merged::new(ctx, pair)?;
    let mut n = 0u64;
    while let Some(k) = merged.next_result()? {
        if n.is_multiple_of(step) && k.r.distance.is_finite() {
            samples.push(Sample {
                xyz: k.xyz,
                normal: k.r.normal,
                distance: k.r.distance,
                std_dev: [k.r.std_dev1, k.r.std_dev2],
                lod: k.r.uncertainty,
            });
        }
        n += 1;
    }
    (ctx.progress)(samples.len() as u64);
    let stable = measure(&samples, ctx.plan.params.core_spacing.value);
    let ground = StableGround { stable };
    super::write_json(out, FILE, &ground)?;
    Ok(serde_json::json!({ "sampled": samples.len() }))
}

/// The stable ground of pair `pair` (its unit must be done).
pub fn read(ctx: &Ctx, pair: usize) -> Result<StableGround> {
    let u = ctx.unit(&crate::plan::Spec::Stable { pair })?;
    super::read_json(ctx, u, FILE)
}

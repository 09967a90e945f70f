//! A sampled unit: the stable ground's sample of a range of a pair's core points, so that several
//! tasks make the pass over every result that the stable-ground unit made alone (3.6 s of the
//! 120M-point pair's critical path on a cluster, almost all of it that pass).
//!
//! The stable unit samples every `step`-th core point of the pair's results in canonical key
//! order (`super::stable::SAMPLES` at most) and counts how far the core points got
//! (`super::stable::Reached`). Both follow from a core point's rank alone, so a range of ranks
//! samples its own: as many ranges as the pair's before survey has tiling parts
//! (`super::tiling::parts`), each starting at the key of its first rank (`m3c2::seek`). The
//! stable unit reads the ranges' samples one after the other — the very sample one pass takes —
//! and adds up their counts.

use serde::{Deserialize, Serialize};

use super::m3c2::seek::{ranges, ranks_of, RankRange};
use super::stable::{Reached, StableStage, SAMPLES};
use super::stage::{Planner, Scope, Stage};
use super::Ctx;
use crate::error::{Error, Result};
use crate::events::stable::Sample;
use crate::store::UnitWriter;

/// The file of a sampled unit: its samples, [`WIDTH`] little-endian f64 each.
pub(crate) const FILE: &str = "samples.bin";

/// Values of a sample: position (3), normal (3), distance, spreads (2), LoD.
const WIDTH: usize = 10;

/// A range of the stable ground's pass.
pub(crate) struct SampledStage;

/// What a sampled unit records.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct SampledMeta {
    /// The canonical ranks of the pair's core points it read: `from..to`.
    pub(crate) from: u64,
    pub(crate) to: u64,
    /// Samples in its file.
    pub(crate) samples: u64,
    /// How far its core points got.
    pub(crate) reached: Reached,
}

impl crate::units::m3c2::seek::InRange for SampledMeta {
    fn span(&self) -> (u64, u64) {
        (self.from, self.to)
    }
}

/// Every `step`-th core point is sampled, of `total`.
pub(crate) fn step(total: u64) -> u64 {
    total.div_ceil(SAMPLES).max(1)
}

impl Stage for SampledStage {
    const KIND: &'static str = "sampled";
    const SCOPE: Scope = Scope::Pair;
    const VERSION: u32 = 1;
    /// Read by the stable unit alone.
    const INTERMEDIATE: bool = true;
    const LINE: crate::units::stage::Line = <StableStage as Stage>::LINE;
    type Meta = SampledMeta;

    fn plan(p: &mut Planner) -> Result<()> {
        for pair in 0..p.plan.pairs.len() {
            let n = ranges(p.plan, pair);
            let deps = p.pair_results(pair);
            p.add_pair_ranges(Self::KIND, pair, n, &SAMPLES.to_string(), &deps);
        }
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<SampledMeta> {
        let plan = ctx.plan;
        let pair = ctx.pair(unit)?;
        let (total, from, to) = ranks_of(ctx, unit, ranges(plan, pair), |_| 1)?;
        let step = step(total);
        let _held = ctx.reserve(
            super::merged::pair_merge_need(plan) + (to - from).div_ceil(step) * 8 * WIDTH as u64,
            "a range of the stable ground's sample (and the merge of the pair's tiles)",
        )?;
        let need = plan.params.min_points.value.max(1);
        let mut reached = Reached::default();
        let mut rows: Vec<f64> = Vec::with_capacity((to - from).div_ceil(step) as usize * WIDTH);
        let mut range = RankRange::open(ctx, pair, from, to)?;
        let mut rank = from;
        while let Some(k) = range.next_result()? {
            reached.add(&k.r, need);
            // As the one pass samples (`stable::run`).
            if rank.is_multiple_of(step) && k.r.measured().is_finite() {
                let r = &k.r;
                rows.extend(k.xyz);
                rows.extend(r.normal);
                rows.extend([r.measured(), r.std_dev1, r.std_dev2, r.uncertainty]);
            }
            rank += 1;
        }
        if rank != to {
            return Err(Error::Internal(format!(
                "ranks {from}..{to} of the pair's results: {} read",
                rank - from
            )));
        }
        (ctx.progress)((rows.len() / WIDTH) as u64);
        super::write_streamed(out, FILE, |w| {
            for run in rows.chunks(1 << 13) {
                let bytes: Vec<u8> = run.iter().flat_map(|v| v.to_le_bytes()).collect();
                w.write_all(&bytes)?;
            }
            Ok(())
        })?;
        Ok(SampledMeta {
            from,
            to,
            samples: (rows.len() / WIDTH) as u64,
            reached,
        })
    }
}

/// The samples of sampled unit `u` (a dependency of the caller; `m`, its record), appended to
/// `into`.
pub(crate) fn read(ctx: &Ctx, u: usize, m: &SampledMeta, into: &mut Vec<Sample>) -> Result<()> {
    let mut rows = super::scratch::RowsReader::input(ctx.input(u, FILE)?, WIDTH)?;
    for _ in 0..m.samples {
        let v = rows.next_row()?;
        into.push(Sample {
            xyz: [v[0], v[1], v[2]],
            normal: [v[3], v[4], v[5]],
            distance: v[6],
            std_dev: [v[7], v[8]],
            lod: v[9],
        });
    }
    Ok(())
}

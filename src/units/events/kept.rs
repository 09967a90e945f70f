//! The events' significance filter over a pair's results in ranges of ranks, a unit (and a Slurm
//! task) each: the pass over every result of the pair that the events unit made alone (on the
//! 120M-point pair, 31M results merged for 840k kept), so that it reads the kept rows only.
//!
//! Whether a core point is kept follows from its own result and the stable ground's threshold
//! and registration error, so a range of ranks filters its own: as many ranges as the pair's
//! before survey has tiling parts (`m3c2::seek::ranges`), each from the key of its first rank
//! (`m3c2::seek::RankRange`), writing its kept core points as the events unit's scratch rows
//! ([`row`]). The events unit reads the ranges' rows one after the other ([`KeptRows`]): the rows
//! one pass keeps, in the same order.

use serde::{Deserialize, Serialize};

use super::{EventsStage, SPILL_WIDTH};
use crate::error::{Error, Result};
use crate::events;
use crate::m3c2::tile::KeyedResult;
use crate::plan::Spec;
use crate::store::UnitWriter;
use crate::units::m3c2::seek::{ranges_of, ranks_of, RankRange};
use crate::units::m3c2::Merged;
use crate::units::scratch::RowsReader;
use crate::units::stable::StableStage;
use crate::units::stage::{Planner, Scope, Stage};
use crate::units::Ctx;

/// The file of a kept unit: its kept core points' rows, [`SPILL_WIDTH`] little-endian f64 each.
pub(crate) const FILE: &str = "kept_rows.bin";

/// A range of the events' filter.
pub(crate) struct KeptStage;

/// What a kept unit records.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct KeptMeta {
    /// The canonical ranks of the pair's core points it read: `from..to`.
    pub(crate) from: u64,
    pub(crate) to: u64,
    /// Rows in its file: its core points kept.
    pub(crate) kept: u64,
}

impl crate::units::m3c2::seek::InRange for KeptMeta {
    fn span(&self) -> (u64, u64) {
        (self.from, self.to)
    }
}

/// The scratch row of result `k` (registration error `reg`, threshold `tau`) when it is kept:
/// key (its bits), position (3), distance, LoD, normal (3), spreads (2), flags (1: beyond reach,
/// 2: sign unknown). A core point beyond the user's reach takes part with the distance the walk
/// found: the change is there, and the event it belongs to says it is incomplete.
pub(crate) fn row(k: &KeyedResult, tau: f64, reg: f64) -> Option<[f64; SPILL_WIDTH]> {
    let r = k.r.with_registration(reg);
    if !events::filter::is_kept(r.distance, r.uncertainty, tau) {
        return None;
    }
    let beyond = r.reach == crate::m3c2::Reach::Beyond;
    let [nx, ny, nz] = r.normal;
    let [x, y, z] = k.xyz;
    Some([
        f64::from_bits(k.key),
        x,
        y,
        z,
        r.distance,
        r.uncertainty,
        nx,
        ny,
        nz,
        r.std_dev1,
        r.std_dev2,
        f64::from(u8::from(beyond) | u8::from(!r.sign_known) << 1),
    ])
}

/// The stable ground's threshold and registration error for pair `pair`.
fn tau_reg(ctx: &Ctx, pair: usize) -> Result<(f64, f64)> {
    let params = crate::units::stable::read(ctx, pair)?.params(ctx.plan);
    Ok((params.threshold.value, params.reg_error.value))
}

impl Stage for KeptStage {
    const KIND: &'static str = "kept";
    const SCOPE: Scope = Scope::Pair;
    const VERSION: u32 = 1;
    /// Read by the events unit alone.
    const INTERMEDIATE: bool = true;
    const LINE: crate::units::stage::Line = <EventsStage as Stage>::LINE;
    type Meta = KeptMeta;

    fn plan(p: &mut Planner) -> Result<()> {
        if p.plan.m3c2_only {
            return Ok(());
        }
        let key = super::filter_key(p.plan);
        for pair in 0..p.plan.pairs.len() {
            let n = crate::units::m3c2::seek::ranges(p.plan, pair);
            if n == 0 {
                continue;
            }
            let mut deps = vec![p.the(&Spec::pair(StableStage::KIND, pair))?];
            deps.extend(p.pair_results(pair));
            p.add_pair_ranges(Self::KIND, pair, n, &key, &deps);
        }
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<KeptMeta> {
        let plan = ctx.plan;
        let pair = ctx.pair(unit)?;
        let (tau, reg) = tau_reg(ctx, pair)?;
        let (_, from, to) = ranks_of(
            ctx,
            unit,
            crate::units::m3c2::seek::ranges(plan, pair),
            |_| 1,
        )?;
        let _held = ctx.reserve(
            crate::units::merged::pair_merge_need(plan),
            "a range of the events' filter (and the merge of the pair's tiles)",
        )?;
        let mut range = RankRange::open(ctx, pair, from, to)?;
        let mut kept = 0u64;
        // A result that does not read (a damaged chunk) is that error, not one of this file: the
        // executor computes the damaged unit again.
        let mut failed = None;
        let written = super::super::write_streamed(out, FILE, |w| {
            let mut bytes = Vec::with_capacity(1 << 16);
            let mut to_io = |e: Error| {
                let io = std::io::Error::other(e.to_string());
                failed = Some(e);
                io
            };
            while let Some(k) = range.next_result().map_err(&mut to_io)? {
                if let Some(r) = row(&k, tau, reg) {
                    kept += 1;
                    bytes.extend(r.iter().flat_map(|v| v.to_le_bytes()));
                    if bytes.len() >= 1 << 16 {
                        w.write_all(&bytes)?;
                        bytes.clear();
                    }
                }
            }
            w.write_all(&bytes)
        });
        if let Some(e) = failed {
            return Err(e);
        }
        written?;
        Ok(KeptMeta { from, to, kept })
    }
}

/// A pair's kept core points' rows in key order: read from its kept units' files one after the
/// other, or (none planned) filtered from a merge of its results.
pub(crate) struct KeptRows {
    source: Source,
}

enum Source {
    Merge {
        merged: Box<Merged>,
        tau: f64,
        reg: f64,
    },
    Ranges {
        files: std::vec::IntoIter<(std::path::PathBuf, u64)>,
        current: Option<(RowsReader, u64)>,
    },
}

impl KeptRows {
    /// Pair `pair`'s, with the threshold `tau` and registration error `reg` its stable ground
    /// gives (the merge's filter; the ranges filtered with the same).
    pub(crate) fn open(ctx: &Ctx, pair: usize, tau: f64, reg: f64) -> Result<KeptRows> {
        let plan = ctx.plan;
        let ranges: Vec<usize> = plan.of_pair(KeptStage::KIND, pair).collect();
        if ranges.is_empty() {
            return Ok(KeptRows {
                source: Source::Merge {
                    merged: Box::new(Merged::new(ctx, pair)?),
                    tau,
                    reg,
                },
            });
        }
        let mut files = Vec::with_capacity(ranges.len());
        for (u, m) in ranges_of::<KeptStage>(ctx, pair)? {
            let path = ctx.input(u, FILE)?;
            let len = std::fs::metadata(&path)
                .map(|m| m.len())
                .unwrap_or(u64::MAX);
            if len != m.kept * 8 * SPILL_WIDTH as u64 {
                return Err(Error::Damaged {
                    path,
                    problem: format!("{len} bytes for the {} kept rows its record says", m.kept),
                });
            }
            files.push((path, m.kept));
        }
        Ok(KeptRows {
            source: Source::Ranges {
                files: files.into_iter(),
                current: None,
            },
        })
    }

    /// The next kept core point's row.
    pub(crate) fn next_row(&mut self) -> Result<Option<[f64; SPILL_WIDTH]>> {
        match &mut self.source {
            Source::Merge { merged, tau, reg } => {
                while let Some(k) = merged.next_result()? {
                    if let Some(r) = row(&k, *tau, *reg) {
                        return Ok(Some(r));
                    }
                }
                Ok(None)
            }
            Source::Ranges { files, current } => loop {
                if let Some((rows, left)) = current.as_mut() {
                    if *left > 0 {
                        *left -= 1;
                        return Ok(Some(rows.next_row()?.try_into().expect("a row's width")));
                    }
                }
                match files.next() {
                    Some((path, kept)) => {
                        *current = Some((RowsReader::input(path, SPILL_WIDTH)?, kept));
                    }
                    None => return Ok(None),
                }
            },
        }
    }
}

//! A pair's M3C2 results merged in rounds of bounded fan-in, when the layout has more tiles than
//! one merge may hold ([`FAN_IN`]) and a direct merge would take a share of the budget that
//! matters ([`in_rounds`]).
//!
//! The stages after M3C2 read a pair's results in global key order through a k-way merge that
//! holds a chunk per input (`m3c2::Merged`). Over the tiles directly, that is a chunk per tile: a
//! small budget makes many tiles, and the merge then needs more than the budget (issue 24: 576
//! tiles, 582 MiB). So where the tiles are more than [`FAN_IN`], this unit merges them once, in
//! groups of at most [`FAN_IN`], into sorted runs — round after round, its intermediate runs
//! deleted as the next round consumes them, until [`FAN_IN`] or fewer remain — and the stable,
//! events, outputs and campaign units merge those runs instead. Every merge then holds at most
//! [`FAN_IN`] chunks, whatever the tile count (a classic external merge sort's balanced merge;
//! Knuth, TAOCP vol. 3, §5.4). A core point's key is unique, so the order is the one a direct
//! merge gives and every output is the same bytes.

use std::path::PathBuf;

use serde::{Deserialize, Serialize};

use super::m3c2::{merge_need, M3c2Stage, Merged, CHUNK_ROWS};
use super::stage::{Line, Planner, Scope, Stage, Total};
use super::Ctx;
use crate::error::{Error, Result};
use crate::m3c2::tile::KeyedResult;
use crate::plan::Spec;
use crate::store::UnitWriter;

/// The most inputs one merge holds a chunk of, where the merge goes in rounds.
pub(crate) const FAN_IN: usize = 32;

/// Whether `plan`'s pairs are merged in rounds: its tiles are more than [`FAN_IN`] and their
/// direct merge would hold more than an eighth of the budget. Below that, the direct merge costs
/// less than a pass over every result (the 120M-point pair's 64 tiles at the default budget:
/// 66 MiB of 2 GiB, against the pass's 12 s).
pub(crate) fn in_rounds(plan: &crate::plan::Plan) -> bool {
    let tiles = plan.layout.len();
    tiles > FAN_IN && merge_need(tiles) > plan.params.memory_bytes.value / 8
}

/// How many inputs a merge of one of `plan`'s pairs' results holds: its tiles, or at most
/// [`FAN_IN`] runs.
pub(crate) fn merge_inputs(plan: &crate::plan::Plan) -> usize {
    if in_rounds(plan) {
        FAN_IN
    } else {
        plan.layout.len()
    }
}

/// Resident bytes of a merge of one of `plan`'s pairs' results (its tiles, or its runs).
pub(crate) fn pair_merge_need(plan: &crate::plan::Plan) -> u64 {
    merge_need(merge_inputs(plan))
}

/// Chunks encoded at once while a run is written (their bytes held until written).
const GROUP: usize = 8;

/// The file of chunk `k` of final run `r`.
pub(crate) fn run_file(r: usize, k: usize) -> String {
    format!("m_{r:03}_{k:05}.tile")
}

/// Resident bytes of a merged unit: its merge of [`FAN_IN`] inputs and the chunks it encodes.
pub(crate) fn need() -> u64 {
    merge_need(FAN_IN) + (GROUP * CHUNK_ROWS * std::mem::size_of::<KeyedResult>()) as u64 * 2
}

/// A pair's results as sorted runs.
pub(crate) struct MergedStage;

/// What a merged unit records: the chunks of each final run, and the rounds it took.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct MergedMeta {
    pub(crate) runs: Vec<usize>,
    pub(crate) rounds: usize,
}

impl Stage for MergedStage {
    const KIND: &'static str = "merged";
    const SCOPE: Scope = Scope::Pair;
    const VERSION: u32 = 4;
    const INTERMEDIATE: bool = true;
    const LINE: Line = Line {
        name: "merging tiles",
        counts: "core points",
        total: Total::Unknown,
    };
    type Meta = MergedMeta;

    /// One per pair when its results are merged in rounds ([`in_rounds`]), over the pair's M3C2
    /// units.
    fn plan(p: &mut Planner) -> Result<()> {
        if !in_rounds(p.plan) {
            return Ok(());
        }
        crate::memory::refuse_unless_fits(
            need(),
            p.plan.params.memory_bytes.value,
            &format!("merging the results of {FAN_IN} tiles at a time"),
        )?;
        let fan_in = FAN_IN.to_string();
        for pair in 0..p.plan.pairs.len() {
            let deps = p.of_pair(M3c2Stage::KIND, pair);
            let label = p.plan.pairs[pair].label.clone();
            p.add(Spec::pair(Self::KIND, pair), &label, &[&fan_in], deps);
        }
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<MergedMeta> {
        let pair = ctx.pair(unit)?;
        let _held = ctx.reserve(need(), "merging the pair's results in rounds")?;
        // The tiles' chunks first (the M3C2 units' own files), then each round's runs.
        let mut runs: Vec<Vec<PathBuf>> = super::m3c2::tile_chunks(ctx, pair)?;
        let opts = super::m3c2::chunk_options(ctx)?;
        let mut rounds = 0;
        loop {
            let groups: Vec<Vec<Vec<PathBuf>>> = runs.chunks(FAN_IN).map(<[_]>::to_vec).collect();
            // The last round leaves at most FAN_IN runs, recorded as the unit's files; the
            // others' runs are temporary files in the unit's directory.
            let last = groups.len() <= FAN_IN;
            let mut next = Vec::with_capacity(groups.len());
            for (g, group) in groups.into_iter().enumerate() {
                let (files, n) = write_run(Merged::of_runs(group)?, &opts, |k, bytes| {
                    if last {
                        let name = run_file(g, k);
                        super::write_bytes(out, &name, &bytes)?;
                        out.path(&name)
                    } else {
                        let path = out.path(&format!("round{rounds}_{g:04}_{k:05}.tmp"))?;
                        std::fs::write(&path, &bytes).map_err(|e| Error::output(&path, e))?;
                        Ok(path)
                    }
                })?;
                if last {
                    (ctx.progress)(n);
                }
                next.push(files);
            }
            if rounds > 0 {
                // The previous round's temporary runs are consumed.
                for f in runs.iter().flatten() {
                    std::fs::remove_file(f).map_err(|e| Error::output(f, e))?;
                }
            }
            runs = next;
            rounds += 1;
            if last {
                return Ok(MergedMeta {
                    runs: runs.iter().map(Vec::len).collect(),
                    rounds,
                });
            }
        }
    }
}

/// Write `merged` as a sorted run of chunk files (encoded with `opts`), [`GROUP`] chunks encoded
/// at a time:
/// `write(k, bytes)` stores chunk `k` and says where. Returns the files and the results written.
fn write_run(
    mut merged: Merged,
    opts: &talus_tiling::WriteOptions,
    mut write: impl FnMut(usize, Vec<u8>) -> Result<PathBuf>,
) -> Result<(Vec<PathBuf>, u64)> {
    let (mut files, mut n) = (Vec::new(), 0u64);
    let mut batch: Vec<Vec<KeyedResult>> = Vec::with_capacity(GROUP);
    let mut chunk = Vec::with_capacity(CHUNK_ROWS);
    loop {
        let next = merged.next_result()?;
        let done = next.is_none();
        if let Some(r) = next {
            chunk.push(r);
            n += 1;
        }
        if chunk.len() == CHUNK_ROWS || (done && !chunk.is_empty()) {
            batch.push(std::mem::replace(
                &mut chunk,
                Vec::with_capacity(CHUNK_ROWS),
            ));
        }
        if batch.len() == GROUP || (done && !batch.is_empty()) {
            for bytes in super::m3c2::encode_chunks(&batch, opts)? {
                files.push(write(files.len(), bytes)?);
            }
            batch.clear();
            crate::interrupt::check()?;
        }
        if done {
            return Ok((files, n));
        }
    }
}

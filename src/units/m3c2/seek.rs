//! A rank of a pair's results in global key order, found without merging what comes before it:
//! the key that has exactly `rank` keys below it over all runs (a pair's tiles or merged runs,
//! each sorted and cut in chunk files of [`CHUNK_ROWS`] rows but the last), and where each run
//! holds it. This lets several tasks each write a range of ranks of m3c2.laz (`units::outputs::
//! segments`) starting where their range starts.
//!
//! The selection is a binary search on the key's value (keys are unique u64), each step counting
//! the keys below a value in every run: a binary search over the run's chunks by their first
//! keys, then within the chunk holding the value. Only the key columns of the chunks probed are
//! decoded (`talus_tiling::read_u32_columns`), their first keys remembered, and the one chunk
//! per run last searched within: a few dozen small reads per run, whatever the pair's size.

use std::collections::HashMap;
use std::path::PathBuf;

use super::CHUNK_ROWS;
use crate::error::{Error, Result};

/// A pair's runs of chunk files, searched by key.
pub(crate) struct RunIndex {
    runs: Vec<Vec<PathBuf>>,
    /// The first key of each chunk decoded so far.
    firsts: HashMap<(usize, usize), u64>,
    /// Per run, the last chunk whose keys were searched, with its keys.
    held: Vec<Option<(usize, Vec<u64>)>>,
}

impl RunIndex {
    pub(crate) fn new(runs: Vec<Vec<PathBuf>>) -> RunIndex {
        let held = vec![None; runs.len()];
        RunIndex {
            runs,
            firsts: HashMap::new(),
            held,
        }
    }

    /// The keys of chunk `c` of run `r`, checked to be a whole chunk unless it is the last.
    fn decode(&self, r: usize, c: usize) -> Result<Vec<u64>> {
        let path = &self.runs[r][c];
        let cols = talus_tiling::read_u32_columns(path, &["key_hi", "key_lo"])
            .map_err(|e| crate::units::damaged(path, e))?;
        let keys: Vec<u64> = cols[0]
            .iter()
            .zip(&cols[1])
            .map(|(&hi, &lo)| u64::from(hi) << 32 | u64::from(lo))
            .collect();
        let last = c + 1 == self.runs[r].len();
        if keys.is_empty() || (!last && keys.len() != CHUNK_ROWS) {
            return Err(Error::Damaged {
                path: path.clone(),
                problem: format!(
                    "{} results in a chunk that is not its run's last (expected {CHUNK_ROWS})",
                    keys.len()
                ),
            });
        }
        Ok(keys)
    }

    /// The first key of chunk `c` of run `r`.
    fn first(&mut self, r: usize, c: usize) -> Result<u64> {
        if let Some(&k) = self.firsts.get(&(r, c)) {
            return Ok(k);
        }
        let keys = self.decode(r, c)?;
        let k = keys[0];
        self.firsts.insert((r, c), k);
        self.held[r] = Some((c, keys));
        Ok(k)
    }

    /// The keys of chunk `c` of run `r` (held while the search stays in it).
    fn keys(&mut self, r: usize, c: usize) -> Result<&[u64]> {
        if self.held[r].as_ref().is_none_or(|(h, _)| *h != c) {
            let keys = self.decode(r, c)?;
            self.firsts.insert((r, c), keys[0]);
            self.held[r] = Some((c, keys));
        }
        Ok(self.held[r].as_ref().map_or(&[][..], |(_, k)| &k[..]))
    }

    /// In run `r`: how many keys lie below `v`, and the chunk the keys from `v` on start in
    /// (every chunk before it lies wholly below `v`).
    fn below_in(&mut self, r: usize, v: u64) -> Result<(u64, usize)> {
        // Chunks whose first key is below v: a prefix of the run.
        let (mut lo, mut hi) = (0usize, self.runs[r].len());
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            if self.first(r, mid)? < v {
                lo = mid + 1;
            } else {
                hi = mid;
            }
        }
        if lo == 0 {
            return Ok((0, 0));
        }
        let c = lo - 1;
        let within = self.keys(r, c)?.partition_point(|&k| k < v);
        Ok(((c * CHUNK_ROWS + within) as u64, c))
    }

    /// How many keys of all runs lie below `v`.
    fn below(&mut self, v: u64) -> Result<u64> {
        let mut n = 0;
        for r in 0..self.runs.len() {
            n += self.below_in(r, v)?.0;
        }
        Ok(n)
    }

    /// The key with exactly `rank` keys below it (None: `rank` is not below the results'
    /// count).
    pub(crate) fn key_at(&mut self, rank: u64) -> Result<Option<u64>> {
        if rank >= self.count_all()? {
            return Ok(None);
        }
        // The smallest v with more than `rank` keys at or below it (those below v + 1; mid is
        // below hi, so mid + 1 does not overflow).
        let (mut lo, mut hi) = (0u64, u64::MAX);
        while lo < hi {
            let mid = lo + (hi - lo) / 2;
            if self.below(mid + 1)? > rank {
                hi = mid;
            } else {
                lo = mid + 1;
            }
        }
        Ok(Some(lo))
    }

    /// Every run's results.
    fn count_all(&mut self) -> Result<u64> {
        let mut n = 0;
        for r in 0..self.runs.len() {
            let c = self.runs[r].len();
            if c > 0 {
                n += ((c - 1) * CHUNK_ROWS + self.keys(r, c - 1)?.len()) as u64;
            }
        }
        Ok(n)
    }

    /// Each run's chunk files from the one holding its first key not below `key` on: a merge
    /// of them, its keys below `key` passed over, goes on from `key`.
    pub(crate) fn runs_from(mut self, key: u64) -> Result<Vec<Vec<PathBuf>>> {
        let mut out = Vec::with_capacity(self.runs.len());
        for r in 0..self.runs.len() {
            let (_, c) = self.below_in(r, key)?;
            out.push(self.runs[r][c..].to_vec());
        }
        Ok(out)
    }
}

/// A pair's results of canonical ranks `from..to`, in key order: a merge started at the key of
/// rank `from` (its keys below it passed over) and stopped after `to - from` results.
pub(crate) struct RankRange {
    merge: Option<(super::Merged, u64)>,
    left: u64,
    to: u64,
}

impl RankRange {
    /// Ranks `from..to` of pair `pair`'s results.
    pub(crate) fn open(ctx: &super::Ctx, pair: usize, from: u64, to: u64) -> Result<RankRange> {
        let mut merge = None;
        if from < to {
            let mut index = RunIndex::new(super::pair_chunks(ctx, pair)?);
            let key = index
                .key_at(from)?
                .ok_or_else(|| Error::Internal(format!("no core point of rank {from}")))?;
            merge = Some((super::Merged::of_runs(index.runs_from(key)?)?, key));
        }
        Ok(RankRange {
            merge,
            left: to.saturating_sub(from),
            to,
        })
    }

    /// The next result of the range.
    pub(crate) fn next_result(&mut self) -> Result<Option<crate::m3c2::tile::KeyedResult>> {
        let Some((m, start)) = self.merge.as_mut() else {
            return Ok(None);
        };
        while self.left > 0 {
            match m.next_result()? {
                Some(r) if r.key < *start => continue,
                Some(r) => {
                    self.left -= 1;
                    return Ok(Some(r));
                }
                None => {
                    return Err(Error::Internal(format!(
                        "the pair's results ended {} core points before rank {}",
                        self.left, self.to
                    )))
                }
            }
        }
        Ok(None)
    }
}

/// The ranks `from..to` of part `k` of `n` of `total` results cut on multiples of `unit` (whole
/// LAZ chunks for m3c2.laz's segments; 1 for any cut): the cuts at k·total/n rounded down to
/// them, so a part may be empty where the units are few.
pub(crate) fn ranks(total: u64, unit: u64, k: usize, n: usize) -> (u64, u64) {
    let cut = |k: usize| -> u64 {
        if k >= n {
            return total;
        }
        let at = (u128::from(total) * k as u128 / n as u128) as u64;
        at / unit.max(1) * unit.max(1)
    };
    (cut(k), cut(k + 1))
}

/// How many ranges a pair's passes over its results are made in (the stable ground's sample,
/// the events' filter, m3c2.laz's segments): as many as its before survey's tiling has parts
/// (`units::tiling::parts`); 0 — one unit makes the pass — for a survey tiled whole.
pub(crate) fn ranges(plan: &crate::plan::Plan, pair: usize) -> usize {
    match crate::units::tiling::parts(plan, plan.pairs[pair].before).len() {
        n if n > 1 => n,
        _ => 0,
    }
}

/// The ranks of range unit `unit`, the `k`-th of `n` of its pair's results cut on multiples of
/// `unit_of(total)` ([`ranks`]): the pair's core points, and `from..to`.
pub(crate) fn ranks_of(
    ctx: &super::Ctx,
    unit: usize,
    n: usize,
    unit_of: impl Fn(u64) -> u64,
) -> Result<(u64, u64, u64)> {
    let total = super::pair_count(ctx, ctx.pair(unit)?)?;
    let (from, to) = ranks(total, unit_of(total), ctx.part(unit)?, n);
    Ok((total, from, to))
}

/// The record of a unit made over a range of its pair's ranks (sampled, kept, segments).
pub(crate) trait InRange {
    /// Its ranks, `from..to`.
    fn span(&self) -> (u64, u64);
}

/// The metas of pair `pair`'s units of stage `S`, made in ranges, in order, checked to cover the
/// pair's core points once.
pub(crate) fn ranges_of<S: crate::units::stage::Stage>(
    ctx: &super::Ctx,
    pair: usize,
) -> Result<Vec<(usize, S::Meta)>>
where
    S::Meta: InRange,
{
    let mut out = Vec::new();
    let mut at = 0;
    for u in ctx.plan.of_pair(S::KIND, pair) {
        let m = ctx.meta::<S>(u)?;
        let (from, to) = m.span();
        if from != at || to < from {
            return Err(Error::Internal(format!(
                "{} holds core points {from}..{to}, after {at}",
                ctx.plan.units[u].name
            )));
        }
        at = to;
        out.push((u, m));
    }
    let total = super::pair_count(ctx, pair)?;
    if !out.is_empty() && at != total {
        return Err(Error::Internal(format!(
            "pair {}'s {} units hold {at} of its {total} core points",
            ctx.plan.pairs[pair].label,
            S::KIND
        )));
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::m3c2::tile::KeyedResult;

    /// Runs of chunk files holding `keys` (each run sorted).
    fn runs(dir: &std::path::Path, keys: &[Vec<u64>]) -> Vec<Vec<PathBuf>> {
        let opts = talus_tiling::WriteOptions::default();
        keys.iter()
            .enumerate()
            .map(|(r, ks)| {
                let results: Vec<KeyedResult> = ks
                    .iter()
                    .map(|&key| KeyedResult {
                        key,
                        xyz: [key as f64, 0.0, 0.0],
                        r: crate::m3c2::CoreResult::default(),
                    })
                    .collect();
                results
                    .chunks(CHUNK_ROWS)
                    .enumerate()
                    .map(|(c, part)| {
                        let bytes = super::super::encode_chunks(&[part], &opts).unwrap();
                        let p = dir.join(format!("r{r}_{c}.tile"));
                        std::fs::write(&p, &bytes[0]).unwrap();
                        p
                    })
                    .collect()
            })
            .collect()
    }

    /// The parts cover every rank once, each but the last whole units.
    #[test]
    fn parts_cut_on_whole_units() {
        for (total, unit, n) in [(1_000_003u64, 50_000u64, 7usize), (10, 10, 3), (0, 1, 2)] {
            let mut at = 0;
            for k in 0..n {
                let (from, to) = ranks(total, unit, k, n);
                assert_eq!(from, at);
                assert!(to >= from);
                if k + 1 < n {
                    assert_eq!(to % unit, 0);
                }
                at = to;
            }
            assert_eq!(at, total);
        }
    }

    /// The key at every tested rank is the merged order's, and the runs from it start the merge
    /// there.
    #[test]
    fn the_key_at_a_rank_is_the_merge_order_s() {
        let dir = tempfile::tempdir().unwrap();
        let mut rng = crate::rng::SplitMix64::new(7);
        // Three runs of unique keys, interleaved, one empty, one of one chunk; u64::MAX a key.
        let mut all: Vec<u64> = (0..40_000).map(|_| rng.next_u64() >> 4).collect();
        all.sort_unstable();
        all.dedup();
        all.push(u64::MAX);
        let mut keys = vec![Vec::new(); 4];
        for (i, &k) in all.iter().enumerate() {
            let r = match i % 7 {
                0..=3 => 0,
                4 | 5 => 1,
                _ if i < 5000 => 3,
                _ => 1,
            };
            keys[r].push(k);
        }
        let files = runs(dir.path(), &keys);
        let mut ix = RunIndex::new(files.clone());
        for rank in [0, 1, 8191, 8192, 20_000, all.len() as u64 - 1] {
            assert_eq!(
                ix.key_at(rank).unwrap(),
                Some(all[rank as usize]),
                "rank {rank}"
            );
        }
        assert_eq!(ix.key_at(all.len() as u64).unwrap(), None);
        let key = all[25_000];
        let mut m =
            super::super::Merged::of_runs(RunIndex::new(files).runs_from(key).unwrap()).unwrap();
        let mut next = || loop {
            match m.next_result().unwrap() {
                Some(k) if k.key < key => continue,
                other => return other.map(|k| k.key),
            }
        };
        for want in &all[25_000..25_100] {
            assert_eq!(next(), Some(*want));
        }
    }
}

//! A pair's M3C2 results in global key order: a k-way merge of sorted runs of chunk files (the
//! tiles' results, or the runs of `units::merged`), holding one chunk per run.
//!
//! The chunks are decoded ahead, on a thread of the merge's own, while the caller consumes the
//! merged results: the stable ground, the events and the outputs read every result of the pair
//! in this order, and with the decoding on the caller's thread those passes kept one core of two
//! busy (about 10 s of the 120M-point pair's run). Which chunk the caller needs next is known
//! before it needs it: a run's chunk is used up when the merge hands out its last key, and keys
//! are unique, so the runs run out in the order of their current chunks' last keys. The reader
//! decodes in that order — the run whose chunk ends first gets its next chunk first — and hands
//! the chunks over in a bounded queue, so the caller receives exactly the chunk it needs next and
//! at most [`ahead`] chunks wait decoded (one for a merge of many runs: the reader decodes a
//! chunk while the caller merges, then waits for the caller to take it).

use std::cmp::Reverse;
use std::collections::{BinaryHeap, VecDeque};
use std::path::PathBuf;

use super::{read_chunk, CHUNK_ROWS};
use crate::error::{Error, Result};
use crate::m3c2::tile::KeyedResult;

/// Chunks decoded ahead, over all runs of a merge: a merge of few runs keeps several of them
/// decoded (a one-tile pair's chunks follow each other), a merge of many one.
const LOOKAHEAD: usize = 8;

/// Chunks decoded ahead of the merge for `runs` runs: the one the reader holds until the merge
/// takes it, and more waiting in the queue when the runs are few.
fn ahead(runs: usize) -> usize {
    (LOOKAHEAD / runs.max(1)).max(1)
}

/// Resident bytes of a [`Merged`] over `runs` inputs (tiles, or the runs of `super::merged`:
/// [`super::super::merged::merge_inputs`]): a chunk per run, the chunks decoded ahead, and the
/// one being decoded with its file's columns (about as large again) — for many runs as much as
/// when the merge decoded its chunks itself (a chunk per run, and one being decoded with its
/// columns). A stage that merges reserves it: a layout of many small tiles (a low budget, a
/// dense site) costs the merge a chunk for each.
pub(crate) fn merge_need(runs: usize) -> u64 {
    let chunk = (CHUNK_ROWS * std::mem::size_of::<KeyedResult>()) as u64;
    (runs.max(1) as u64 + ahead(runs) as u64 + 1) * chunk
}

/// A decoded chunk of run `run`, as the reader hands it over.
type Decoded = Result<(usize, Vec<KeyedResult>)>;

/// The k-way merge.
pub struct Merged {
    cursors: Vec<Cursor>,
    heap: BinaryHeap<Reverse<(u64, usize)>>,
    /// The reader's chunks, in the order the merge needs them (None: no run has a second chunk).
    chunks: Option<crossbeam_channel::Receiver<Decoded>>,
    reader: Option<std::thread::JoinHandle<()>>,
}

/// One run: its current chunk, the position in it, and how many of its chunks are still to come.
struct Cursor {
    chunk: Vec<KeyedResult>,
    pos: usize,
    left: usize,
}

/// When a run needs its next chunk: once the merge hands out `key`, its current chunk's last.
/// Ordered as the merge reaches these moments.
type Due = Reverse<(u64, usize)>;

impl Merged {
    pub fn new(ctx: &super::Ctx, pair: usize) -> Result<Self> {
        Self::of_runs(super::pair_chunks(ctx, pair)?)
    }

    /// The merge of `runs`: each a sorted run of chunk files.
    pub(crate) fn of_runs(runs: Vec<Vec<PathBuf>>) -> Result<Self> {
        use rayon::prelude::*;
        // The first non-empty chunk of every run, in parallel, and how many files it took; the
        // rest from the reader.
        let first: Vec<(Vec<KeyedResult>, usize)> = runs
            .par_iter()
            .map(|files| {
                for (k, f) in files.iter().enumerate() {
                    let chunk = read_chunk(f)?;
                    if !chunk.is_empty() {
                        return Ok((chunk, k + 1));
                    }
                }
                Ok((Vec::new(), files.len()))
            })
            .collect::<Vec<_>>()
            .into_iter()
            .collect::<Result<_>>()?;
        let mut todo = BinaryHeap::new();
        let mut rest: Vec<VecDeque<PathBuf>> = Vec::with_capacity(runs.len());
        let mut m = Merged {
            cursors: Vec::with_capacity(runs.len()),
            heap: BinaryHeap::new(),
            chunks: None,
            reader: None,
        };
        for (r, (files, (chunk, used))) in runs.into_iter().zip(first).enumerate() {
            let files: VecDeque<PathBuf> = files.into_iter().skip(used).collect();
            if let (Some(head), Some(last)) = (chunk.first(), chunk.last()) {
                m.heap.push(Reverse((head.key, r)));
                if !files.is_empty() {
                    todo.push(Reverse((last.key, r)));
                }
            }
            m.cursors.push(Cursor {
                chunk,
                pos: 0,
                left: files.len(),
            });
            rest.push(files);
        }
        if !todo.is_empty() {
            // The reader holds one decoded chunk until the merge takes it (a queue of none for
            // many runs: a rendezvous), so it is at most `ahead` chunks ahead.
            let (send, chunks) = crossbeam_channel::bounded(ahead(rest.len()) - 1);
            let reader = std::thread::Builder::new()
                .name("talus-merge".into())
                .spawn(move || read_ahead(rest, todo, send))
                .map_err(|e| Error::Internal(format!("the merge's reader thread: {e}")))?;
            m.chunks = Some(chunks);
            m.reader = Some(reader);
        }
        Ok(m)
    }

    /// Run `r`'s current chunk is used up: take its next non-empty one from the reader (which
    /// decoded it for this moment) and put its first key on the heap; nothing when the run is
    /// done.
    fn next_chunk(&mut self, r: usize) -> Result<()> {
        let c = &mut self.cursors[r];
        c.chunk = Vec::new();
        c.pos = 0;
        while c.left > 0 {
            let got = self
                .chunks
                .as_ref()
                .and_then(|ch| ch.recv().ok())
                .ok_or_else(|| Error::Internal("the merge's reader stopped early".into()))?;
            let (from, chunk) = got?;
            if from != r {
                return Err(Error::Internal(format!(
                    "the merge's reader decoded a chunk of run {from} where run {r} needed one"
                )));
            }
            c.left -= 1;
            if let Some(first) = chunk.first() {
                self.heap.push(Reverse((first.key, r)));
                c.chunk = chunk;
                break;
            }
        }
        Ok(())
    }

    /// The next result in key order.
    pub fn next_result(&mut self) -> Result<Option<KeyedResult>> {
        let Some(Reverse((_, r))) = self.heap.pop() else {
            return Ok(None);
        };
        let c = &mut self.cursors[r];
        let out = c.chunk[c.pos];
        c.pos += 1;
        if c.pos < c.chunk.len() {
            self.heap.push(Reverse((c.chunk[c.pos].key, r)));
        } else {
            self.next_chunk(r)?;
        }
        Ok(Some(out))
    }
}

impl Drop for Merged {
    /// A merge dropped before its end (an error downstream, an interrupt): the reader finds its
    /// queue closed at its next hand-over and stops.
    fn drop(&mut self) {
        self.chunks = None;
        if let Some(t) = self.reader.take() {
            let _ = t.join();
        }
    }
}

/// The reader: decode the runs' remaining chunks (`rest`) in the order the merge will need them
/// (`todo`: when each run with chunks left needs its next) and hand them over in that order. The
/// first error is handed over and ends it.
fn read_ahead(
    mut rest: Vec<VecDeque<PathBuf>>,
    mut todo: BinaryHeap<Due>,
    send: crossbeam_channel::Sender<Decoded>,
) {
    while let Some(Reverse((key, r))) = todo.pop() {
        let Some(file) = rest[r].pop_front() else {
            continue;
        };
        let chunk = match read_chunk(&file) {
            Ok(c) => c,
            Err(e) => {
                let _ = send.send(Err(e));
                return;
            }
        };
        if !rest[r].is_empty() {
            // An empty chunk is passed over at the moment it is received: the run needs its
            // next one at that same moment (`key` was the least due; keys are unique).
            let due = chunk.last().map_or(key, |last| last.key);
            todo.push(Reverse((due, r)));
        }
        if send.send(Ok((r, chunk))).is_err() {
            return;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::m3c2::CoreResult;

    fn result(key: u64) -> KeyedResult {
        KeyedResult {
            key,
            xyz: [key as f64, 0.0, 0.0],
            r: CoreResult {
                distance: key as f64 * 0.5,
                ..CoreResult::default()
            },
        }
    }

    /// Runs of chunk files from keys: each run's keys split at `cuts` (empty chunks where two
    /// cuts meet).
    fn write_runs(dir: &std::path::Path, runs: &[(Vec<u64>, Vec<usize>)]) -> Vec<Vec<PathBuf>> {
        runs.iter()
            .enumerate()
            .map(|(r, (keys, cuts))| {
                let mut bounds = vec![0];
                bounds.extend(cuts);
                bounds.push(keys.len());
                bounds
                    .windows(2)
                    .enumerate()
                    .map(|(k, w)| {
                        let part: Vec<KeyedResult> =
                            keys[w[0]..w[1]].iter().map(|&k| result(k)).collect();
                        let bytes = super::super::encode_chunks(&[part], &Default::default())
                            .unwrap()
                            .remove(0);
                        let path = dir.join(format!("run{r}_{k}.tile"));
                        std::fs::write(&path, bytes).unwrap();
                        path
                    })
                    .collect()
            })
            .collect()
    }

    fn drain(mut m: Merged) -> Result<Vec<u64>> {
        let mut out = Vec::new();
        while let Some(k) = m.next_result()? {
            assert_eq!(
                k.r.distance,
                k.key as f64 * 0.5,
                "a result's fields travel with it"
            );
            out.push(k.key);
        }
        Ok(out)
    }

    #[test]
    fn runs_merge_in_key_order_whatever_their_chunks() {
        let dir = tempfile::tempdir().unwrap();
        let mut rng = crate::rng::SplitMix64::new(24);
        // Keys dealt to runs at random (runs interleave finely), chunks cut at random, with
        // empty chunks, an empty run, a run of one empty chunk and runs of one chunk.
        for (case, n_runs) in [1usize, 2, 3, 7, 40].into_iter().enumerate() {
            let mut runs: Vec<(Vec<u64>, Vec<usize>)> = vec![(Vec::new(), Vec::new()); n_runs];
            let total = 3000 + 500 * case;
            for key in 0..total as u64 {
                let r = (rng.next_u64() % n_runs as u64) as usize;
                runs[r].0.push(key * 3 + 1);
            }
            for (keys, cuts) in runs.iter_mut() {
                let pieces = (rng.next_u64() % 12) as usize;
                let mut c: Vec<usize> = (0..pieces)
                    .map(|_| (rng.next_u64() % (keys.len() as u64 + 1)) as usize)
                    .collect();
                c.sort_unstable();
                *cuts = c;
            }
            if n_runs > 3 {
                runs[1] = (Vec::new(), Vec::new());
                runs[2].1 = vec![0, 0, 0];
            }
            let files = write_runs(dir.path(), &runs);
            let mut want: Vec<u64> = runs.iter().flat_map(|(k, _)| k.clone()).collect();
            want.sort_unstable();
            let got = drain(Merged::of_runs(files.clone()).unwrap()).unwrap();
            assert_eq!(got, want, "{n_runs} runs");
            // Dropped half-way: the reader stops (the test would hang otherwise).
            let mut m = Merged::of_runs(files).unwrap();
            for _ in 0..want.len() / 2 {
                m.next_result().unwrap();
            }
            drop(m);
        }
        // No runs at all, and runs without files.
        assert!(drain(Merged::of_runs(Vec::new()).unwrap())
            .unwrap()
            .is_empty());
        assert!(drain(Merged::of_runs(vec![Vec::new(); 3]).unwrap())
            .unwrap()
            .is_empty());
    }

    #[test]
    fn a_damaged_chunk_is_reported_when_the_merge_reaches_it() {
        let dir = tempfile::tempdir().unwrap();
        let keys: Vec<u64> = (0..4000).collect();
        let even: Vec<u64> = keys.iter().copied().filter(|k| k % 2 == 0).collect();
        let odd: Vec<u64> = keys.iter().copied().filter(|k| k % 2 == 1).collect();
        let files = write_runs(
            dir.path(),
            &[(even, vec![500, 1000, 1500]), (odd, vec![700, 1400])],
        );
        // Run 1's second chunk (its keys 1401..2799) damaged.
        let bad = &files[1][1];
        let mut bytes = std::fs::read(bad).unwrap();
        let at = bytes.len() / 2;
        bytes[at] ^= 0x55;
        std::fs::write(bad, bytes).unwrap();
        let mut m = Merged::of_runs(files.clone()).unwrap();
        let mut seen = Vec::new();
        let err = loop {
            match m.next_result() {
                Ok(Some(k)) => seen.push(k.key),
                Ok(None) => panic!("the damage went unnoticed"),
                Err(e) => break e,
            }
        };
        // Every result came out in order up to the one whose hand-out needed the damaged chunk
        // (1399, the last of run 1's first chunk), as when the decoding was the caller's.
        assert_eq!(seen, (0..1399).collect::<Vec<u64>>());
        match err {
            Error::Damaged { path, .. } => assert_eq!(&path, bad),
            e => panic!("{e}"),
        }
    }
}

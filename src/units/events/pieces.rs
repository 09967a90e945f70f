//! An events unit's kept core points a piece of space at a time (`events::pieces`), when they
//! are more than the pool holds at once: the pieces handed their points from the unit's scratch
//! rows (one pass for every [`GROUP`] pieces, each piece's into a file of its own), each
//! piece's smoothed distances and labels written in place to a results file, the labels joined,
//! and the events described a batch at a time. What is held is bounded by the cap a piece
//! loads, the columns' counts, and a few bytes a label (which grow with the events, as the
//! drafts do).

use std::fs::File;
use std::io::{BufReader, Read};
use std::os::unix::fs::FileExt;
use std::path::PathBuf;

use super::super::scratch::{Rows, RowsWriter};
use super::super::Ctx;
use super::{from_row, Counts, Found, Members, BYTES_PER_KEPT, FIXED};
use crate::error::{Error, Result};
use crate::events::pieces::{self, Columns, Labelled, Settings, Stitch};
use crate::events::Kind;
use crate::io::Point3;
use crate::store::UnitWriter;

/// Every kept point's smoothed distance and label, by kept index (12 bytes each, in place).
const RESULTS: &str = "kept_results.tmp";
/// The labels a piece gave the core points it holds but does not own: (kept index, label).
const SHARED: &str = "kept_shared.tmp";
/// Bytes a result takes in [`RESULTS`].
const RESULT: u64 = 12;

/// Pieces handed their points by one pass over the scratch rows (a writer's buffer each, within
/// [`FIXED`]).
const GROUP: usize = 8;

/// Bytes a column's count takes held (a B-tree entry with its share of the nodes).
const BYTES_PER_COLUMN: u64 = 64;

/// Every kept point's smoothed distance and event, in kept order.
pub(super) enum Results {
    /// Held (the whole pair's events found at once).
    Held { smoothed: Vec<f64>, event: Vec<u32> },
    /// In a file of the unit, with each label's event.
    File { path: PathBuf, event: Vec<u32> },
}

impl Results {
    /// A reader from the first kept point.
    pub(super) fn reader(&self) -> Result<ResultsReader<'_>> {
        Ok(match self {
            Results::Held { smoothed, event } => ResultsReader::Held {
                smoothed,
                event,
                at: 0,
            },
            Results::File { path, event } => ResultsReader::File {
                file: BufReader::with_capacity(
                    super::super::scratch::BUFFER,
                    File::open(path).map_err(|e| Error::output(path, e))?,
                ),
                path,
                event,
            },
        })
    }

    /// Remove its file.
    pub(super) fn remove(self) -> Result<()> {
        match self {
            Results::Held { .. } => Ok(()),
            Results::File { path, .. } => {
                std::fs::remove_file(&path).map_err(|e| Error::output(&path, e))
            }
        }
    }
}

/// [`Results`] read in kept order.
pub(super) enum ResultsReader<'a> {
    Held {
        smoothed: &'a [f64],
        event: &'a [u32],
        at: usize,
    },
    File {
        file: BufReader<File>,
        path: &'a PathBuf,
        event: &'a [u32],
    },
}

impl ResultsReader<'_> {
    /// The next kept point's smoothed distance and event (0: none).
    pub(super) fn next(&mut self) -> Result<(f64, u32)> {
        match self {
            ResultsReader::Held {
                smoothed,
                event,
                at,
            } => {
                *at += 1;
                Ok((smoothed[*at - 1], event[*at - 1]))
            }
            ResultsReader::File { file, path, event } => {
                let mut b = [0u8; RESULT as usize];
                file.read_exact(&mut b)
                    .map_err(|e| Error::output(path.as_path(), e))?;
                let (v, l) = decode(&b);
                Ok((v, l.checked_sub(1).map_or(0, |l| event[l as usize])))
            }
        }
    }
}

/// A result's bytes: the smoothed distance, then the label.
fn encode(smoothed: f64, label: u32) -> [u8; RESULT as usize] {
    let mut b = [0u8; RESULT as usize];
    b[..8].copy_from_slice(&smoothed.to_le_bytes());
    b[8..].copy_from_slice(&label.to_le_bytes());
    b
}

fn decode(b: &[u8; RESULT as usize]) -> (f64, u32) {
    let v = f64::from_le_bytes(b[..8].try_into().expect("8 bytes"));
    let l = u32::from_le_bytes(b[8..].try_into().expect("4 bytes"));
    (v, l)
}

/// The events of the `n` kept points of `spill`, counted by column in `counts`, a piece of
/// space at a time: each piece's points read from the scratch rows, smoothed and clustered
/// (`events::pieces::label_piece`), the pieces' labels joined and the clusters numbered by their
/// smallest key (the order of the whole pair's).
pub(super) fn found<'a>(
    ctx: &'a Ctx,
    out: &mut UnitWriter,
    spill: &Rows,
    columns: Columns,
    counts: &Counts,
    s: &Settings,
) -> Result<Found<'a>> {
    let n = spill.len();
    let limit = super::room(ctx);
    let overhead = FIXED + counts.len() as u64 * BYTES_PER_COLUMN;
    let cap = limit.saturating_sub(overhead) / BYTES_PER_KEPT;
    let plan = match pieces::plan(counts, cap) {
        Ok(p) => p,
        // Refused, with the budget that holds the fullest column with its halo.
        Err(floor) => {
            crate::memory::refuse_unless_fits(
                floor * BYTES_PER_KEPT + overhead,
                ctx.plan.params.memory_bytes.value,
                &format!("the events of {n} kept core points, a piece of space at a time"),
            )?;
            return Err(Error::Internal(format!(
                "a piece of {floor} kept core points over a cap of {cap}"
            )));
        }
    };
    // What the fullest piece loads, not the whole pool: other units may run beside it.
    let fullest = plan
        .iter()
        .map(|p| pieces::load(counts, p))
        .max()
        .unwrap_or(0);
    let held = ctx.reserve(
        fullest * BYTES_PER_KEPT + overhead,
        &format!("the events of {n} kept core points, in pieces"),
    )?;
    crate::progress::trace(|| format!("events: {n} kept core points in {} pieces", plan.len()));
    let path = out.path(RESULTS)?;
    let results = std::fs::OpenOptions::new()
        .read(true)
        .write(true)
        .create(true)
        .truncate(true)
        .open(&path)
        .map_err(|e| Error::output(&path, e))?;
    let mut shared = RowsWriter::create(out, SHARED, 2)?;
    let mut stitch = Stitch::default();
    for group in plan.chunks(GROUP) {
        // One pass over the scratch rows hands each piece of the group its points (kept order)
        // in a file of its own: a pass for each piece made the time grow as the pieces times
        // the kept points, i.e. with the square of the change at a given budget.
        let mut loads = (0..group.len())
            .map(|k| RowsWriter::create(out, &format!("kept_piece{k}.tmp"), 5))
            .collect::<Result<Vec<_>>>()?;
        let mut rows = spill.reader()?;
        for i in 0..n {
            let r = rows.next_row()?;
            let c = columns.of(&[r[1], r[2], r[3]]);
            for (load, piece) in loads.iter_mut().zip(group) {
                if piece.loads(c) {
                    // The index as f64: exact below 2^53 kept points.
                    load.push(&[i as f64, r[1], r[2], r[3], r[4]])?;
                }
            }
        }
        drop(rows);
        for (load, piece) in loads.into_iter().zip(group) {
            let load = load.finish()?;
            let (mut ids, mut pts, mut d) = (Vec::new(), Vec::new(), Vec::new());
            let mut rows = load.reader()?;
            for _ in 0..load.len() {
                let r = rows.next_row()?;
                ids.push(r[0] as u64);
                pts.push([r[1], r[2], r[3]]);
                d.push(r[4]);
            }
            drop(rows);
            load.remove()?;
            let Labelled {
                owned,
                shared: theirs,
                kinds,
            } = pieces::label_piece(&pts, &d, piece, &columns, s)?;
            let offset = stitch.add(&kinds);
            let named = |l: u32| if l > 0 { l + offset } else { 0 };
            for (at, v, l) in owned {
                let i = ids[at as usize];
                results
                    .write_all_at(&encode(v, named(l)), i * RESULT)
                    .map_err(|e| Error::output(&path, e))?;
            }
            for (at, l) in theirs {
                shared.push(&[ids[at as usize] as f64, f64::from(named(l))])?;
            }
        }
    }
    // The labels a piece gave the core points of its halo, joined to their owners'.
    let shared = shared.finish()?;
    let mut rows = shared.reader()?;
    for _ in 0..shared.len() {
        let r = rows.next_row()?;
        let (i, l) = (r[0] as u64, r[1] as u32);
        let mut b = [0u8; RESULT as usize];
        results
            .read_exact_at(&mut b, i * RESULT)
            .map_err(|e| Error::output(&path, e))?;
        match decode(&b).1 {
            0 => {
                return Err(Error::Internal(format!(
                    "kept core point {i}: core in a piece's halo, in no cluster of its own piece"
                )))
            }
            owner => stitch.join(l, owner),
        }
    }
    drop(rows);
    shared.remove()?;
    // The clusters numbered by their smallest member (kept order is key order), each label
    // given its cluster's number.
    let labels = stitch.len();
    let mut number: rustc_hash::FxHashMap<u32, u32> = Default::default();
    let (mut kinds, mut members) = (Vec::<Kind>::new(), Vec::<u64>::new());
    let mut file = BufReader::with_capacity(super::super::scratch::BUFFER, &results);
    let mut event = vec![0u32; labels];
    for _ in 0..n {
        let mut b = [0u8; RESULT as usize];
        file.read_exact(&mut b)
            .map_err(|e| Error::output(&path, e))?;
        let l = decode(&b).1;
        if l == 0 {
            continue;
        }
        let (root, kind) = stitch.cluster(l);
        let e = *number.entry(root).or_insert_with(|| {
            kinds.push(kind);
            members.push(0);
            kinds.len() as u32
        });
        event[l as usize - 1] = e;
        members[e as usize - 1] += 1;
    }
    Ok(Found {
        pieces: plan.len(),
        results: Results::File { path, event },
        kinds,
        members: Members::Counted { members, held },
    })
}

/// Bytes a member of an event being described takes: its position and distance.
const BYTES_PER_MEMBER: u64 = 32;

/// Describes event `c` (0..) from its members' positions and distances.
pub(super) type Describe<'a> = dyn FnMut(usize, &[Point3], &[f64]) + 'a;

/// Describe the events whose members `counts` counts, a batch of events at a time (each batch
/// reserving what it holds; the caller holds no reservation), their members read from the
/// scratch rows in kept order: `describe(event index, positions,
/// distances)` in event order.
pub(super) fn describe(
    ctx: &Ctx,
    spill: &Rows,
    results: &Results,
    counts: &[u64],
    describe: &mut Describe<'_>,
) -> Result<()> {
    let room = super::room(ctx).saturating_sub(FIXED) / BYTES_PER_MEMBER;
    let mut first = 0;
    while first < counts.len() {
        let mut end = first;
        let mut batch = 0;
        while end < counts.len() && batch + counts[end] <= room.max(counts[first]) {
            batch += counts[end];
            end += 1;
        }
        if counts[first] > room {
            // One event larger than the pool: refused with the budget that holds it.
            crate::memory::refuse_unless_fits(
                counts[first] * BYTES_PER_MEMBER + FIXED,
                ctx.plan.params.memory_bytes.value,
                &format!("describing an event of {} kept core points", counts[first]),
            )?;
        }
        let _held = ctx.reserve(
            batch * BYTES_PER_MEMBER + FIXED,
            &format!(
                "describing {} events of {batch} kept core points",
                end - first
            ),
        )?;
        let mut p: Vec<Vec<Point3>> = vec![Vec::new(); end - first];
        let mut dist: Vec<Vec<f64>> = vec![Vec::new(); end - first];
        let (mut rows, mut result) = (spill.reader()?, results.reader()?);
        for _ in 0..spill.len() {
            let k = from_row(rows.next_row()?);
            let e = result.next()?.1 as usize;
            if e > first && e <= end {
                p[e - 1 - first].push(k.xyz);
                dist[e - 1 - first].push(k.d);
            }
        }
        for (c, (p, d)) in p.iter().zip(&dist).enumerate() {
            describe(first + c, p, d);
        }
        first = end;
    }
    Ok(())
}

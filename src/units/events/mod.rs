//! An events unit: a pair's significance filter → smoothing → signed DBSCAN merged across tiles →
//! description (SPEC.md §1), over the pair's M3C2 results in key order, with the parameters its
//! stable-ground unit resolved.
//!
//! The kept core points (significant and |d| ≥ τ) are few next to the epochs, so their keys,
//! positions and distances are held (this need grows with the change: 80 bytes a kept point in
//! all, [`BYTES_PER_KEPT`]); the rest of each waits in a temporary file of the unit. Smoothing and
//! DBSCAN see them a block of space at a time with what lies within reach (`events::blocks`),
//! so their kd-trees and lists never span the pair.
//! Writes `events.json` (each event described, with the boxes its volume may be extruded along)
//! and `kept.tile` (every kept core point: key, smoothed distance, event id or 0, normal and
//! per-epoch spread, for m3c2.laz and for the volumes' claims and uncertainty), and the drafts
//! filed by the tiles their volumes' search boxes reach (`near.json`, `near_drafts.jsonl`), so
//! that a volumes unit reads its neighbourhood's events, not all of them.

use rustc_hash::FxHashMap as HashMap;

use serde::{Deserialize, Serialize};
use talus_tiling::{Column, ColumnData, TileColumns};

use super::stable::StableStage;
use super::stage::{Line, Planner, Scope, Stage, Total};
use super::Ctx;
use crate::error::{Error, Result};
use crate::events::{self, Event, Kind, Obb};
use crate::io::Point3;
use crate::m3c2::orientation::STEEP_NZ;
use crate::plan::Spec;
use crate::store::UnitWriter;

pub(crate) mod kept;
mod pieces;

pub(crate) const EVENTS: &str = "events.json";
pub(crate) const KEPT: &str = "kept.tile";
/// The drafts by tile (see `write_near`): the index, and the lines it points into.
pub(crate) const NEAR: &str = "near.json";
pub(crate) const NEAR_DRAFTS: &str = "near_drafts.jsonl";

/// An event as the events unit leaves it: described, with its candidate boxes.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct Draft {
    pub(crate) event: Event,
    /// The boxes the volume may be extruded along: the mean normal's, and straight up's where the
    /// normal is not steep (see `volume::axis`).
    pub(crate) candidates: Vec<Obb>,
    /// Its core points whose other epoch lies beyond the user's half-length (not measured: the
    /// event is incomplete).
    pub(crate) beyond_reach: usize,
    /// Its core points whose normal's sign the data does not decide (`CoreResult::sign_known`):
    /// where they are most of it, its sign may be the reverse.
    pub(crate) sign_unknown: usize,
}

/// A kept core point.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Kept {
    pub(crate) key: u64,
    pub(crate) xyz: Point3,
    pub(crate) d: f64,
    pub(crate) lod: f64,
    pub(crate) normal: Point3,
    pub(crate) std_dev: [f64; 2],
    pub(crate) smoothed: f64,
    /// 0 = in no event.
    pub(crate) event: u32,
    /// The other epoch lies beyond the user's half-length: `d` is the walk's finding, not a
    /// measurement (`m3c2::Reach::Beyond`).
    pub(crate) beyond: bool,
    /// The data does not decide which side of the surface is out here (`CoreResult::sign_known`).
    pub(crate) sign_unknown: bool,
}

/// The candidate boxes of an event with core points `cluster` (see [`Draft::candidates`]).
pub(crate) fn candidate_boxes(e: &Event, cluster: &[Point3]) -> Vec<Obb> {
    let mut boxes = vec![e.obb];
    let n = e.mean_normal;
    if n[2] >= STEEP_NZ && n[2] < 1.0 - 1e-9 {
        boxes.extend(events::describe::box_along(cluster, [0.0, 0.0, 1.0]));
    }
    boxes
}

/// Resident bytes per kept core point in the events unit: its key, position and distance (40;
/// the rest waits on disk), the smoothed distance (8), the blocks' order (4), the clustering's
/// core flags, sets and labels (9), the event ids and the clusters' member lists (8); the
/// kd-trees are a block's surroundings only (`events::blocks`). Measured on the 120M-point pair
/// (839,640 kept; VmHWM reset at each step, the process's base ≈ 9.5 MB): 42.7 MB resident once
/// streamed, peaks 54.8 MB smoothing, 64.4 MB clustering, 83.2 MB writing `kept.tile` (its
/// frame of 65,536 rows held twice, as rows and as columns, beside its compressed bytes):
/// ≈ 65 bytes each beyond the base at the clustering's peak, ≈ 78 at the writing's beyond the
/// base and the fixed 8 MiB. Before the blocks (one kd-tree and one clustering over every kept
/// point) the unit took ≈ 117 bytes each.
pub(crate) const BYTES_PER_KEPT: u64 = 80;

/// The pair's events: filter, smoothing, signed clustering, description.
pub(crate) struct EventsStage;

/// What an events unit records.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub(crate) struct EventsMeta {
    /// Events described.
    pub(crate) events: usize,
    /// Core points kept by the filter.
    pub(crate) kept: usize,
    /// Pieces of space they were smoothed and clustered in, when more than the budget holds at
    /// once (0: all at once).
    #[serde(default)]
    pub(crate) pieces: usize,
}

impl Stage for EventsStage {
    const KIND: &'static str = "events";
    const SCOPE: Scope = Scope::Pair;
    const VERSION: u32 = 1;
    const LINE: Line = Line {
        name: "events",
        counts: "events",
        total: Total::Unknown,
    };
    type Meta = EventsMeta;

    /// One per pair (none with `--m3c2-only`), over its stable ground and M3C2 units (or its
    /// `kept` ranges, which made the filter's pass over them); its key
    /// has the parameters the user gave (a measured one comes from the stable unit's key).
    fn plan(p: &mut Planner) -> Result<()> {
        if p.plan.m3c2_only {
            return Ok(());
        }
        let key = key(p.plan);
        for pair in 0..p.plan.pairs.len() {
            let mut deps = vec![p.the(&Spec::pair(StableStage::KIND, pair))?];
            // The filter's pass made in ranges (`kept`), or here.
            let ranges = p.of_pair(kept::KeptStage::KIND, pair);
            match ranges.is_empty() {
                true => deps.extend(p.pair_results(pair)),
                false => deps.extend(ranges),
            }
            let label = p.plan.pairs[pair].label.clone();
            p.add(Spec::pair(Self::KIND, pair), &label, &[&key], deps);
        }
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<EventsMeta> {
        run(ctx, ctx.pair(unit)?, out)
    }
}

/// A parameter's key part: its value where the user gave it, else `measured` (the stable
/// unit, a dependency, measures it).
fn user(r: &crate::params::Resolved<f64>) -> String {
    if r.is_user() {
        r.value.to_string()
    } else {
        "measured".into()
    }
}

/// The key part of the ranges of a pair's filter (`kept`): what a kept row follows from beside
/// the stable unit's measurement — the registration error and threshold the user gave, and the
/// spacing a threshold falls back to without stable ground (`Params::with_stable`). Not the
/// smoothing's or clustering's parameters: changing those does not filter again.
fn filter_key(plan: &crate::plan::Plan) -> String {
    let params = &plan.params;
    format!(
        "{}|{}|spacing {}",
        user(&params.reg_error),
        user(&params.threshold),
        params.point_spacing.value
    )
}

/// The key part of a pair's events: the parameters the user gave (a measured one comes from the
/// stable unit's key).
fn key(plan: &crate::plan::Plan) -> String {
    let params = &plan.params;
    // The three after `near` size the volumes' search boxes, by which the drafts are filed by
    // tile (`write_near`); `blocks 1`: smoothing takes the k nearest within its reach
    // (`events::blocks`).
    format!(
        "{}|{}|{}|{}|{}|{}|near {}|{}|{}|blocks 1",
        user(&params.reg_error),
        user(&params.threshold),
        params.smooth_k.value,
        params.smooth_sigma.value,
        params.eps.value,
        params.cluster_min_points.value,
        params.cyl_radius.value,
        params.cyl_halflen.value,
        params.point_spacing.value
    )
}

/// The scratch rows of an events unit: every kept core point in key order — key (its bits),
/// position (3), distance, LoD, normal (3), spreads (2), flags (1: beyond reach, 2: sign unknown).
/// Read back for the
/// events' descriptions and `kept.tile` together, and, when the kept points are more than the
/// budget holds, a piece of space at a time ([`pieces`]).
const SPILL: &str = "kept_rows.tmp";
const SPILL_WIDTH: usize = 12;

/// A kept core point from its scratch row (its smoothed distance and event not yet known).
fn from_row(r: &[f64]) -> Kept {
    Kept {
        key: r[0].to_bits(),
        xyz: [r[1], r[2], r[3]],
        d: r[4],
        lod: r[5],
        normal: [r[6], r[7], r[8]],
        std_dev: [r[9], r[10]],
        smoothed: f64::NAN,
        event: 0,
        beyond: r[11] as u8 & 1 != 0,
        sign_unknown: r[11] as u8 & 2 != 0,
    }
}

/// The bytes an events unit holds beside its kept points: a frame of `kept.tile` as rows and
/// columns with its compressed bytes, and the scratch files' buffers.
const FIXED: u64 = 8 << 20;

/// Run pair `pair`'s events into `out`.
fn run(ctx: &Ctx, pair: usize, out: &mut UnitWriter) -> Result<EventsMeta> {
    let params = super::stable::read(ctx, pair)?.params(ctx.plan);
    let (tau, reg) = (params.threshold.value, params.reg_error.value);
    let settings = events::pieces::Settings {
        k: params.smooth_k.value as usize,
        sigma: params.smooth_sigma.value,
        reach: events::blocks::SMOOTH_REACH_SIGMAS * params.smooth_sigma.value,
        eps: params.eps.value,
        min_pts: params.cluster_min_points.value as usize,
    };
    // Every kept core point to the scratch rows; their keys, positions and distances held too
    // while the pool could hold what the events of all of them need, else counted by column.
    let limit = room(ctx);
    let mut held = Some((Vec::new(), Vec::<Point3>::new(), Vec::new()));
    let mut columns: Option<(events::pieces::Columns, Counts)> = None;
    let mut spill = super::scratch::RowsWriter::create(out, SPILL, SPILL_WIDTH)?;
    // The merge of the pair's tiles (with `kept` ranges there is none, but the same room covers
    // the kept points' keys, positions and distances held while they stream in, until their
    // count is known and reserved below).
    let merging = ctx.reserve(
        super::merged::pair_merge_need(ctx.plan),
        "the merge of the pair's tiles",
    )?;
    let mut rows = kept::KeptRows::open(ctx, pair, tau, reg)?;
    let mut n = 0u64;
    while let Some(row) = rows.next_row()? {
        n += 1;
        spill.push(&row)?;
        let k = from_row(&row);
        if let Some((keys, pts, d)) = held.as_mut() {
            keys.push(k.key);
            pts.push(k.xyz);
            d.push(k.d);
            if n * BYTES_PER_KEPT + FIXED > limit {
                // More than the pool holds at once: a piece of space at a time.
                let c = events::pieces::Columns::new(pts[0], settings.reach.max(settings.eps));
                let mut counts = Counts::new();
                for p in pts.iter() {
                    *counts.entry(c.of(p)).or_insert(0) += 1;
                }
                columns = Some((c, counts));
                held = None;
            }
        } else if let Some((c, counts)) = columns.as_mut() {
            *counts.entry(c.of(&k.xyz)).or_insert(0) += 1;
        }
    }
    drop(rows);
    let spill = spill.finish()?;
    // Given back before the next reservation: a unit waits only while it holds none.
    drop(merging);
    let found = match (held, columns) {
        (Some((keys, pts, d)), _) => whole(ctx, &keys, pts, d, &settings)?,
        (None, Some((c, counts))) => pieces::found(ctx, out, &spill, c, &counts, &settings)?,
        (None, None) => unreachable!("kept points neither held nor counted"),
    };
    let n = n as usize;
    // One pass over the scratch rows, in kept order: every kept core point to `kept.tile`, a
    // frame at a time; the clustered points' LoDs and normals added up for their clusters (each
    // in its members' order, never held), and how many of each cluster's points lie beyond reach.
    let clusters = found.kinds.len();
    let mut sums = vec![events::describe::Sums::default(); clusters];
    let mut beyond = vec![0usize; clusters];
    let mut unknown = vec![0usize; clusters];
    let mut rows = Vec::with_capacity(KEPT_FRAME.min(n));
    let mut file = KeptWriter::new(out)?;
    let mut scratch = spill.reader()?;
    let mut result = found.results.reader()?;
    for _ in 0..n {
        let mut k = from_row(scratch.next_row()?);
        (k.smoothed, k.event) = result.next()?;
        if let Some(c) = k.event.checked_sub(1) {
            let c = c as usize;
            sums[c].add(k.lod, &k.normal);
            beyond[c] += usize::from(k.beyond);
            unknown[c] += usize::from(k.sign_unknown);
        }
        rows.push(k);
        if rows.len() == KEPT_FRAME {
            file.append(&rows)?;
            rows.clear();
        }
    }
    // The last frame, or the one empty frame when nothing is kept.
    if !rows.is_empty() || n == 0 {
        file.append(&rows)?;
    }
    drop((rows, scratch, result));
    file.finish(out)?;
    let mut drafts = Vec::new();
    let mut describe = |c: usize, p: &[Point3], dist: &[f64]| {
        let id = c as u32 + 1;
        let kind = found.kinds[c];
        if let Some(e) =
            events::describe::describe_with(id, kind, p, dist, &sums[c], params.core_spacing.value)
        {
            let candidates = candidate_boxes(&e, p);
            drafts.push(Draft {
                event: e,
                candidates,
                beyond_reach: beyond[c],
                sign_unknown: unknown[c],
            });
        }
    };
    match found.members {
        Members::Held {
            pts, d, members, ..
        } => {
            for (c, m) in members.iter().enumerate() {
                let p: Vec<Point3> = m.iter().map(|&i| pts[i as usize]).collect();
                let dist: Vec<f64> = m.iter().map(|&i| d[i as usize]).collect();
                describe(c, &p, &dist);
            }
        }
        Members::Counted { members, held } => {
            // Given back: each batch of events reserves what it holds.
            drop(held);
            pieces::describe(ctx, &spill, &found.results, &members, &mut describe)?
        }
    }
    found.results.remove()?;
    spill.remove()?;
    (ctx.progress)(drafts.len() as u64);
    write_near(out, &drafts, &params, &ctx.plan.layout.grid()?)?;
    super::write_json(out, EVENTS, &drafts)?;
    Ok(EventsMeta {
        events: drafts.len(),
        kept: n,
        pieces: found.pieces,
    })
}

/// The bytes an events unit may hold its kept points in: the pool's, or, where
/// `TALUS_EVENTS_HELD` says a number of kept points (for tests that take small scenes through
/// the pieces), what that many need.
fn room(ctx: &Ctx) -> u64 {
    let limit = ctx.pool.limit();
    match std::env::var("TALUS_EVENTS_HELD").map(|v| v.parse::<u64>()) {
        Ok(Ok(n)) => limit.min(n * BYTES_PER_KEPT + FIXED),
        _ => limit,
    }
}

/// Kept core points by column ([`events::pieces::Columns`]).
type Counts = std::collections::BTreeMap<[i64; 2], u64>;

/// The events of a pair's kept points: every kept point's smoothed distance and event, and the
/// events' kinds and members, in the order of their smallest key.
struct Found<'a> {
    /// Pieces of space the kept points were taken in (0: held at once).
    pieces: usize,
    results: pieces::Results,
    kinds: Vec<Kind>,
    members: Members<'a>,
}

/// The members of each event.
enum Members<'a> {
    /// Held with every kept point's position and distance (a lifetime for the reservation).
    Held {
        pts: Vec<Point3>,
        d: Vec<f64>,
        members: Vec<Vec<u32>>,
        _held: crate::memory::Reservation<'a>,
    },
    /// Only counted: read again from the scratch rows, a batch of events at a time (the
    /// pieces' reservation held through the writing of `kept.tile`).
    Counted {
        members: Vec<u64>,
        held: crate::memory::Reservation<'a>,
    },
}

/// The events of a pair's kept points held at once (what the pool holds; 80 bytes each).
fn whole<'a>(
    ctx: &'a Ctx,
    keys: &[u64],
    pts: Vec<Point3>,
    d: Vec<f64>,
    s: &events::pieces::Settings,
) -> Result<Found<'a>> {
    let n = keys.len();
    // The kept points are known only once streamed (40 bytes each, held unreserved meanwhile:
    // half of what the unit then needs, under the merge's reservation given back just before).
    let held = ctx.reserve(
        n as u64 * BYTES_PER_KEPT + FIXED,
        &format!("the events of {n} kept core points"),
    )?;
    // Cubes of space holding every neighbourhood that smoothing and clustering look at, a
    // block with the 26 around it held at a time (`events::blocks`).
    let blocks = events::blocks::Blocks::new(&pts, s.reach.max(s.eps));
    let smoothed = events::blocks::smooth(&pts, &d, s.k, s.sigma, s.reach, &blocks)?;
    // Signed clusters, each sign on its own; members in ascending order of kept index.
    let mut clusters: Vec<(u64, Kind, Vec<u32>)> = Vec::new();
    for kind in [Kind::Gain, Kind::Loss] {
        let labels = events::blocks::cluster(
            &pts,
            &|i| kind.matches(smoothed[i]),
            s.eps,
            s.min_pts,
            &blocks,
        )?;
        let mut members: Vec<Vec<u32>> = Vec::new();
        for (i, &l) in labels.iter().enumerate() {
            if l > 0 {
                // Labels come numbered by their first member: a new one is the next.
                if l as usize > members.len() {
                    members.push(Vec::new());
                }
                members[l as usize - 1].push(i as u32);
            }
        }
        clusters.extend(members.into_iter().map(|m| (keys[m[0] as usize], kind, m)));
    }
    drop(blocks);
    // Event ids in a canonical order: by the smallest key of each cluster.
    clusters.sort_by_key(|c| c.0);
    let mut event = vec![0u32; n];
    for (c, (_, _, members)) in clusters.iter().enumerate() {
        for &i in members {
            event[i as usize] = c as u32 + 1;
        }
    }
    let results = pieces::Results::Held { smoothed, event };
    let (kinds, members) = clusters.into_iter().map(|(_, k, m)| (k, m)).unzip();
    Ok(Found {
        pieces: 0,
        results,
        kinds,
        members: Members::Held {
            pts,
            d,
            members,
            _held: held,
        },
    })
}

/// Where a tile's line of [`NEAR_DRAFTS`] lies.
#[derive(Debug, Clone, Serialize, Deserialize)]
struct NearLine {
    col: u32,
    row: u32,
    offset: u64,
    len: u64,
}

/// File the drafts by tile, for the volumes units: for every tile that one of a draft's search
/// boxes reaches ([`reached_tiles`]), one line of [`NEAR_DRAFTS`] (a JSON array of those
/// drafts, in id order), found through [`NEAR`]. Two events whose search boxes overlap reach a
/// common tile, so a volumes unit that reads the lines of the tiles its own events' boxes reach
/// finds every event that can claim a location of theirs, and never parses the pair's whole
/// `events.json` (each of the 120M-point pair's 961 units at 164 MiB parsed 1,028 drafts and
/// computed all their boxes: a cost per unit growing with the events).
fn write_near(
    out: &mut UnitWriter,
    drafts: &[Draft],
    params: &crate::params::Params,
    grid: &talus_tiling::TileGrid,
) -> Result<()> {
    let mut by_tile: std::collections::BTreeMap<talus_tiling::TileId, Vec<usize>> =
        std::collections::BTreeMap::new();
    for (i, d) in drafts.iter().enumerate() {
        for t in reached_tiles(d, params, grid) {
            by_tile.entry(t).or_default().push(i);
        }
    }
    let mut index = Vec::with_capacity(by_tile.len());
    super::write_streamed(out, NEAR_DRAFTS, |w| {
        let mut offset = 0;
        for (t, list) in &by_tile {
            let here: Vec<&Draft> = list.iter().map(|&i| &drafts[i]).collect();
            let line = serde_json::to_vec(&here).map_err(std::io::Error::other)?;
            w.write_all(&line)?;
            w.write_all(b"\n")?;
            let len = line.len() as u64;
            index.push(NearLine {
                col: t.col,
                row: t.row,
                offset,
                len,
            });
            offset += len + 1;
        }
        Ok(())
    })?;
    super::write_json(out, NEAR, &index)
}

/// A pair's drafts by tile (`write_near`): the index held (a line per tile reached), a tile's
/// drafts read from their line when asked.
pub(crate) struct NearDrafts {
    path: std::path::PathBuf,
    lines: HashMap<(u32, u32), (u64, u64)>,
}

impl NearDrafts {
    /// Pair `pair`'s (its events unit must be done).
    pub(crate) fn open(ctx: &Ctx, pair: usize) -> Result<NearDrafts> {
        let u = ctx.unit(&Spec::pair(EventsStage::KIND, pair))?;
        let index: Vec<NearLine> = super::read_json(ctx, u, NEAR)?;
        Ok(NearDrafts {
            path: ctx.input(u, NEAR_DRAFTS)?,
            lines: index
                .into_iter()
                .map(|l| ((l.col, l.row), (l.offset, l.len)))
                .collect(),
        })
    }

    /// The drafts whose search boxes reach tile `t`, in id order (none when no box does).
    pub(crate) fn drafts(&self, t: talus_tiling::TileId) -> Result<Vec<Draft>> {
        use std::io::{Read, Seek, SeekFrom};
        let Some(&(offset, len)) = self.lines.get(&(t.col, t.row)) else {
            return Ok(Vec::new());
        };
        let damaged = |problem: String| Error::Damaged {
            path: self.path.clone(),
            problem,
        };
        let mut line = vec![0; len as usize];
        let mut f = std::fs::File::open(&self.path).map_err(|e| damaged(e.to_string()))?;
        f.seek(SeekFrom::Start(offset))
            .and_then(|_| f.read_exact(&mut line))
            .map_err(|e| damaged(format!("line of tile {t}: {e}")))?;
        serde_json::from_slice(&line).map_err(|e| damaged(format!("line of tile {t}: {e}")))
    }
}

fn to_columns(kept: &[Kept]) -> TileColumns {
    let f = |name: &str, g: &dyn Fn(&Kept) -> f64| Column {
        name: name.into(),
        data: ColumnData::F64(kept.iter().map(g).collect()),
    };
    let u = |name: &str, g: &dyn Fn(&Kept) -> u32| Column {
        name: name.into(),
        data: ColumnData::U32(kept.iter().map(g).collect()),
    };
    TileColumns {
        x: kept.iter().map(|k| k.xyz[0]).collect(),
        y: kept.iter().map(|k| k.xyz[1]).collect(),
        z: kept.iter().map(|k| k.xyz[2]).collect(),
        extra: vec![
            u("key_hi", &|k| (k.key >> 32) as u32),
            u("key_lo", &|k| k.key as u32),
            f("distance", &|k| k.d),
            f("lod", &|k| k.lod),
            f("normal_x", &|k| k.normal[0]),
            f("normal_y", &|k| k.normal[1]),
            f("normal_z", &|k| k.normal[2]),
            f("std_dev1", &|k| k.std_dev[0]),
            f("std_dev2", &|k| k.std_dev[1]),
            f("smoothed", &|k| k.smoothed),
            u("event", &|k| k.event),
            u("beyond", &|k| k.beyond as u32),
            u("sign_unknown", &|k| k.sign_unknown as u32),
        ],
    }
}

/// The events of pair `pair` (its events unit must be done).
pub(crate) fn read_drafts(ctx: &Ctx, pair: usize) -> Result<Vec<Draft>> {
    let u = ctx.unit(&Spec::pair(EventsStage::KIND, pair))?;
    super::read_json(ctx, u, EVENTS)
}

/// Rows of a `kept.tile` frame: its readers (the volumes units, the outputs) hold a frame at a
/// time, never the pair's kept core points, which grow with the change.
pub(crate) const KEPT_FRAME: usize = 1 << 16;

/// `kept.tile` being written: the kept core points in key order, [`KEPT_FRAME`] rows to a frame
/// (one empty frame when nothing is kept).
struct KeptWriter {
    file: talus_tiling::framed::Framed,
    opts: talus_tiling::WriteOptions,
}

impl KeptWriter {
    fn new(out: &mut UnitWriter) -> Result<KeptWriter> {
        Ok(KeptWriter {
            file: talus_tiling::framed::Framed::new(&out.path(KEPT)?),
            opts: talus_tiling::WriteOptions::default(),
        })
    }

    fn append(&mut self, rows: &[Kept]) -> Result<()> {
        Ok(self.file.append(&to_columns(rows), &self.opts)?)
    }

    fn finish(self, out: &mut UnitWriter) -> Result<()> {
        let d = self.file.finish()?;
        out.add(KEPT, d.crc32, d.size);
        Ok(())
    }
}

/// The kept core points of a pair, a frame at a time in key order.
pub(crate) struct KeptFrames {
    path: std::path::PathBuf,
    frames: talus_tiling::TileFrames,
}

impl KeptFrames {
    /// Pair `pair`'s kept core points (its events unit must be done).
    pub(crate) fn open(ctx: &Ctx, pair: usize) -> Result<KeptFrames> {
        let u = ctx.unit(&Spec::pair(EventsStage::KIND, pair))?;
        let path = ctx.input(u, KEPT)?;
        let frames = talus_tiling::TileFrames::open(&path).map_err(|e| super::damaged(&path, e))?;
        Ok(KeptFrames { path, frames })
    }

    /// Kept core points in the file.
    pub(crate) fn count(&self) -> u64 {
        self.frames.point_count()
    }

    /// The next frame's kept core points; None after the last.
    pub(crate) fn next_frame(&mut self) -> Result<Option<Vec<Kept>>> {
        self.next_frame_where(&|_| true)
    }

    /// The next frame whose bounds `want` accepts (the others are passed over undecoded: the
    /// points are in key order, tile by tile, so a frame covers a strip of a few tiles).
    pub(crate) fn next_frame_where(
        &mut self,
        want: &dyn Fn(&crate::geom::Bounds) -> bool,
    ) -> Result<Option<Vec<Kept>>> {
        match self.frames.next_frame_where(want) {
            Ok(Some(c)) => from_columns(&c, &self.path).map(Some),
            Ok(None) => Ok(None),
            Err(e) => Err(super::damaged(&self.path, e)),
        }
    }
}

/// Pair `pair`'s kept core points looked up by key, the keys asked in ascending order (as the
/// merge of its results gives them): a frame held at a time.
pub(crate) struct KeptByKey {
    frames: Option<KeptFrames>,
    rows: Vec<Kept>,
    at: usize,
}

impl KeptByKey {
    /// Over `frames`; None: no kept core points (an M3C2-only run).
    pub(crate) fn new(frames: Option<KeptFrames>) -> KeptByKey {
        KeptByKey {
            frames,
            rows: Vec::new(),
            at: 0,
        }
    }

    /// The kept core point of `key`, if it is one; `key` not below the last one asked.
    pub(crate) fn get(&mut self, key: u64) -> Result<Option<&Kept>> {
        loop {
            while self.at < self.rows.len() && self.rows[self.at].key < key {
                self.at += 1;
            }
            if self.at < self.rows.len() {
                let k = &self.rows[self.at];
                return Ok((k.key == key).then_some(k));
            }
            match self
                .frames
                .as_mut()
                .map(KeptFrames::next_frame)
                .transpose()?
            {
                Some(Some(rows)) => (self.rows, self.at) = (rows, 0),
                _ => {
                    self.frames = None;
                    return Ok(None);
                }
            }
        }
    }
}

/// The kept core points of one frame of `kept.tile` at `path`.
fn from_columns(c: &TileColumns, path: &std::path::Path) -> Result<Vec<Kept>> {
    let bad = |name: &str| Error::Damaged {
        path: path.to_path_buf(),
        problem: format!("no column {name}"),
    };
    let f = |name: &str| match c.column(name) {
        Some(ColumnData::F64(v)) => Ok(v),
        _ => Err(bad(name)),
    };
    let g = |name: &str| match c.column(name) {
        Some(ColumnData::U32(v)) => Ok(v),
        _ => Err(bad(name)),
    };
    let (hi, lo, ev, beyond) = (g("key_hi")?, g("key_lo")?, g("event")?, g("beyond")?);
    let unknown = g("sign_unknown")?;
    let (d, lod, sm) = (f("distance")?, f("lod")?, f("smoothed")?);
    let (nx, ny, nz) = (f("normal_x")?, f("normal_y")?, f("normal_z")?);
    let (s1, s2) = (f("std_dev1")?, f("std_dev2")?);
    let kept = (0..c.len())
        .map(|i| Kept {
            key: (hi[i] as u64) << 32 | lo[i] as u64,
            xyz: [c.x[i], c.y[i], c.z[i]],
            d: d[i],
            lod: lod[i],
            normal: [nx[i], ny[i], nz[i]],
            std_dev: [s1[i], s2[i]],
            smoothed: sm[i],
            event: ev[i],
            beyond: beyond[i] == 1,
            sign_unknown: unknown[i] == 1,
        })
        .collect();
    Ok(kept)
}

/// The tiles that the plan bounds of `d`'s search boxes ([`crate::volume::Search`]) reach, in
/// order: each box's corners through the grid's `owner` (so clamped onto the grid), every tile
/// between. Two events whose boxes overlap reach a common tile (the owner of a point of the
/// overlap: `owner` is monotone along each axis), and an event reaches the tile owning its
/// centroid. The events unit files drafts by them, the volumes unit reads the tiles.
pub(crate) fn reached_tiles(
    d: &Draft,
    params: &crate::params::Params,
    grid: &talus_tiling::TileGrid,
) -> Vec<talus_tiling::TileId> {
    let mut out = Vec::new();
    for b in search_xy(d, params) {
        let (lo, hi) = (grid.owner(b[0], b[1]), grid.owner(b[2], b[3]));
        for col in lo.col..=hi.col {
            out.extend((lo.row..=hi.row).map(|row| talus_tiling::TileId { col, row }));
        }
    }
    out.sort_unstable();
    out.dedup();
    out
}

/// The reach of the run's search boxes ([`crate::volume::Search`]).
pub(crate) fn search(params: &crate::params::Params) -> crate::volume::Search {
    crate::volume::Search::new(
        params.cyl_radius.value,
        params.point_spacing.value,
        params.cyl_halflen.value,
    )
}

/// The XY bounds of each of `d`'s search boxes, one a candidate box.
pub(crate) fn search_xy(d: &Draft, params: &crate::params::Params) -> Vec<[f64; 4]> {
    let s = search(params);
    let depth = s.depth(d.event.max_abs_distance);
    d.candidates
        .iter()
        .map(|o| s.search_box(o, depth).1)
        .collect()
}

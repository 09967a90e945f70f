//! An events unit: a pair's significance filter → smoothing → signed DBSCAN merged across tiles →
//! description (SPEC.md §1), over the pair's M3C2 results in key order, with the parameters its
//! stable-ground unit resolved.
//!
//! The kept core points (significant and |d| ≥ τ) are few next to the epochs, so they are held.
//! Writes `events.json` (each event described, with the boxes its volume may be extruded along)
//! and `kept.tile` (every kept core point: key, smoothed distance, event id or 0, normal and
//! per-epoch spread, for m3c2.laz and for the volumes' claims and uncertainty).

use rustc_hash::FxHashMap as HashMap;

use serde::{Deserialize, Serialize};
use talus_tiling::{Column, ColumnData, TileColumns};

use super::m3c2::Merged;
use super::stable::StableStage;
use super::stage::{Line, Planner, Scope, Stage, Total};
use super::Ctx;
use crate::error::{Error, Result};
use crate::events::{self, Event, Kind, Obb};
use crate::io::Point3;
use crate::m3c2::orientation::STEEP_NZ;
use crate::plan::Spec;
use crate::store::UnitWriter;

pub const EVENTS: &str = "events.json";
pub const KEPT: &str = "kept.tile";

/// An event as the events unit leaves it: described, with its candidate boxes.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub struct Draft {
    pub event: Event,
    /// The boxes the volume may be extruded along: the mean normal's, and straight up's where the
    /// normal is not steep (see `volume::axis`).
    pub candidates: Vec<Obb>,
    /// Its core points whose other epoch lies beyond the user's half-length (not measured: the
    /// event is incomplete).
    pub beyond_reach: usize,
}

/// A kept core point.
#[derive(Debug, Clone, Copy)]
pub struct Kept {
    pub key: u64,
    pub xyz: Point3,
    pub d: f64,
    pub lod: f64,
    pub normal: Point3,
    pub std_dev: [f64; 2],
    pub smoothed: f64,
    /// 0 = in no event.
    pub event: u32,
    /// The other epoch lies beyond the user's half-length: `d` is the walk's finding, not a
    /// measurement (`m3c2::Reach::Beyond`).
    pub beyond: bool,
}

/// The candidate boxes of an event with core points `cluster` (see [`Draft::candidates`]).
pub fn candidate_boxes(e: &Event, cluster: &[Point3]) -> Vec<Obb> {
    let mut boxes = vec![e.obb];
    let n = e.mean_normal;
    if n[2] >= STEEP_NZ && n[2] < 1.0 - 1e-9 {
        boxes.extend(events::describe::box_along(cluster, [0.0, 0.0, 1.0]));
    }
    boxes
}

/// Resident bytes per kept core point in the events unit: the kept record (104), the positions
/// and distances for smoothing (32) with its kd-tree (≈ 40), the clustering's copies, tile lists
/// and links (≈ 50). `kept.tile` is written a frame at a time, so no column copy of them all.
/// Measured on the 120M-point pair (839,640 kept): the unit's peak 184 MiB in a process of its
/// own, ≈ 200 bytes each beyond the process's base.
pub const BYTES_PER_KEPT: u64 = 224;

/// The pair's events: filter, smoothing, signed clustering, description.
pub struct EventsStage;

/// What an events unit records.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct EventsMeta {
    /// Events described.
    pub events: usize,
    /// Core points kept by the filter.
    pub kept: usize,
}

impl Stage for EventsStage {
    const KIND: &'static str = "events";
    const SCOPE: Scope = Scope::Pair;
    const LINE: Line = Line {
        name: "events",
        counts: "events",
        total: Total::Unknown,
    };
    type Meta = EventsMeta;

    /// One per pair (none with `--m3c2-only`), over its stable ground and M3C2 units; its key
    /// has the parameters the user gave (a measured one comes from the stable unit's key).
    fn plan(p: &mut Planner) -> Result<()> {
        if p.plan.m3c2_only {
            return Ok(());
        }
        let params = &p.plan.params;
        let user = |r: &crate::params::Resolved<f64>| {
            if r.is_user() {
                r.value.to_string()
            } else {
                "measured".into()
            }
        };
        let key = format!(
            "{}|{}|{}|{}|{}|{}",
            user(&params.reg_error),
            user(&params.threshold),
            params.smooth_k.value,
            params.smooth_sigma.value,
            params.eps.value,
            params.cluster_min_points.value
        );
        for pair in 0..p.plan.pairs.len() {
            let mut deps = vec![p.the(&Spec::pair(StableStage::KIND, pair))?];
            deps.extend(p.pair_results(pair));
            let label = p.plan.pairs[pair].label.clone();
            p.add(Spec::pair(Self::KIND, pair), &label, &[&key], deps);
        }
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<EventsMeta> {
        run(ctx, ctx.pair(unit)?, out)
    }
}

/// Run pair `pair`'s events into `out`.
fn run(ctx: &Ctx, pair: usize, out: &mut UnitWriter) -> Result<EventsMeta> {
    let params = super::stable::read(ctx, pair)?.params(ctx.plan);
    let (tau, reg) = (params.threshold.value, params.reg_error.value);
    let mut kept = Vec::new();
    let merging = ctx.reserve(
        super::merged::pair_merge_need(ctx.plan),
        "the merge of the pair's tiles",
    )?;
    let mut merged = Merged::new(ctx, pair)?;
    while let Some(k) = merged.next_result()? {
        let r = k.r.with_registration(reg);
        // A core point beyond the user's reach takes part with the distance the walk found: the
        // change is there, and the event it belongs to says it is incomplete.
        if events::filter::is_kept(r.distance, r.uncertainty, tau) {
            kept.push(Kept {
                key: k.key,
                xyz: k.xyz,
                d: r.distance,
                lod: r.uncertainty,
                normal: r.normal,
                std_dev: [r.std_dev1, r.std_dev2],
                smoothed: f64::NAN,
                event: 0,
                beyond: r.reach == crate::m3c2::Reach::Beyond,
            });
        }
    }
    drop(merged);
    // Given back before the next reservation: a unit waits only while it holds none.
    drop(merging);
    // The kept points are known only once streamed (≈ 104 bytes each, held unreserved meanwhile:
    // a small share of what smoothing and clustering then add).
    let _held = ctx.reserve(
        kept.len() as u64 * BYTES_PER_KEPT + (8 << 20),
        &format!("the events of {} kept core points", kept.len()),
    )?;
    let pts: Vec<Point3> = kept.iter().map(|k| k.xyz).collect();
    let smoothed = {
        let d: Vec<f64> = kept.iter().map(|k| k.d).collect();
        events::smooth::smooth(
            &pts,
            &d,
            params.smooth_k.value as usize,
            params.smooth_sigma.value,
        )?
    };
    for (k, s) in kept.iter_mut().zip(&smoothed) {
        k.smoothed = *s;
    }
    // Signed clusters, each sign on its own, tile by tile over the run's grid.
    let grid = ctx.plan.layout.grid()?;
    let mut clusters: Vec<(u64, Kind, Vec<usize>)> = Vec::new();
    for kind in [Kind::Gain, Kind::Loss] {
        let idx: Vec<usize> = (0..kept.len())
            .filter(|&i| kind.matches(smoothed[i]))
            .collect();
        let p: Vec<Point3> = idx.iter().map(|&i| pts[i]).collect();
        let keys: Vec<u64> = idx.iter().map(|&i| kept[i].key).collect();
        let labels = events::tiled::cluster(
            &p,
            &keys,
            &grid,
            params.eps.value,
            params.cluster_min_points.value as usize,
        )?;
        let mut by_label: HashMap<u32, Vec<usize>> = HashMap::default();
        for (j, &l) in labels.iter().enumerate() {
            if l > 0 {
                by_label.entry(l).or_default().push(idx[j]);
            }
        }
        for (_, members) in by_label {
            let min_key = members.iter().map(|&i| kept[i].key).min().unwrap_or(0);
            clusters.push((min_key, kind, members));
        }
    }
    // Event ids in a canonical order: by the smallest key of each cluster.
    clusters.sort_by_key(|c| c.0);
    let mut drafts = Vec::new();
    for (n, (_, kind, members)) in clusters.iter().enumerate() {
        let id = n as u32 + 1;
        let get = |f: &dyn Fn(&Kept) -> Point3| -> Vec<Point3> {
            members.iter().map(|&i| f(&kept[i])).collect()
        };
        let (p, normals) = (get(&|k| k.xyz), get(&|k| k.normal));
        let dist: Vec<f64> = members.iter().map(|&i| kept[i].d).collect();
        let lod: Vec<f64> = members.iter().map(|&i| kept[i].lod).collect();
        for &i in members {
            kept[i].event = id;
        }
        if let Some(e) = events::describe(
            id,
            *kind,
            &p,
            &dist,
            &lod,
            &normals,
            params.core_spacing.value,
        ) {
            let candidates = candidate_boxes(&e, &p);
            drafts.push(Draft {
                event: e,
                candidates,
                beyond_reach: members.iter().filter(|&&i| kept[i].beyond).count(),
            });
        }
    }
    (ctx.progress)(drafts.len() as u64);
    super::write_json(out, EVENTS, &drafts)?;
    write_kept(out, &kept)?;
    Ok(EventsMeta {
        events: drafts.len(),
        kept: kept.len(),
    })
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
        ],
    }
}

/// The events of pair `pair` (its events unit must be done).
pub fn read_drafts(ctx: &Ctx, pair: usize) -> Result<Vec<Draft>> {
    let u = ctx.unit(&Spec::pair(EventsStage::KIND, pair))?;
    super::read_json(ctx, u, EVENTS)
}

/// Rows of a `kept.tile` frame: its readers (the volumes units, the outputs) hold a frame at a
/// time, never the pair's kept core points, which grow with the change.
pub const KEPT_FRAME: usize = 1 << 16;

/// Write `kept` (in key order) as `kept.tile`, [`KEPT_FRAME`] rows to a frame (one empty frame
/// when nothing is kept).
fn write_kept(out: &mut UnitWriter, kept: &[Kept]) -> Result<()> {
    let path = out.path(KEPT)?;
    let mut file = talus_tiling::framed::Framed::new(&path);
    let opts = talus_tiling::WriteOptions::default();
    let empty: &[Kept] = &[];
    for rows in kept
        .chunks(KEPT_FRAME)
        .chain(kept.is_empty().then_some(empty))
    {
        file.append(&to_columns(rows), &opts)?;
    }
    let d = file.finish()?;
    out.add(KEPT, d.crc32, d.size);
    Ok(())
}

/// The kept core points of a pair, a frame at a time in key order.
pub struct KeptFrames {
    path: std::path::PathBuf,
    frames: talus_tiling::TileFrames,
}

impl KeptFrames {
    /// Pair `pair`'s kept core points (its events unit must be done).
    pub fn open(ctx: &Ctx, pair: usize) -> Result<KeptFrames> {
        let u = ctx.unit(&Spec::pair(EventsStage::KIND, pair))?;
        let path = ctx.input(u, KEPT)?;
        let frames = talus_tiling::TileFrames::open(&path).map_err(|e| super::damaged(&path, e))?;
        Ok(KeptFrames { path, frames })
    }

    /// Kept core points in the file.
    pub fn count(&self) -> u64 {
        self.frames.point_count()
    }

    /// The next frame's kept core points; None after the last.
    pub fn next_frame(&mut self) -> Result<Option<Vec<Kept>>> {
        match self.frames.next_frame() {
            Ok(Some(c)) => from_columns(&c, &self.path).map(Some),
            Ok(None) => Ok(None),
            Err(e) => Err(super::damaged(&self.path, e)),
        }
    }
}

/// Pair `pair`'s kept core points looked up by key, the keys asked in ascending order (as the
/// merge of its results gives them): a frame held at a time.
pub struct KeptByKey {
    frames: Option<KeptFrames>,
    rows: Vec<Kept>,
    at: usize,
}

impl KeptByKey {
    /// Over `frames`; None: no kept core points (an M3C2-only run).
    pub fn new(frames: Option<KeptFrames>) -> KeptByKey {
        KeptByKey {
            frames,
            rows: Vec::new(),
            at: 0,
        }
    }

    /// The kept core point of `key`, if it is one; `key` not below the last one asked.
    pub fn get(&mut self, key: u64) -> Result<Option<&Kept>> {
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
        })
        .collect();
    Ok(kept)
}

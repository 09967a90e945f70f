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

/// Resident bytes per kept core point in the events unit: the kept record (104), its copies for
/// smoothing and clustering (40), the kd-tree and neighbour lists of smoothing (k = 10: ≈ 160),
/// the clustering's labels and union-find (≈ 24), the columns written (≈ 70).
pub const BYTES_PER_KEPT: u64 = 400;

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
    let d: Vec<f64> = kept.iter().map(|k| k.d).collect();
    let smoothed = events::smooth::smooth(
        &pts,
        &d,
        params.smooth_k.value as usize,
        params.smooth_sigma.value,
    )?;
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
    super::write_columns(out, KEPT, &to_columns(&kept))?;
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

/// The events and kept core points of pair `pair` (its events unit must be done).
pub fn read(ctx: &Ctx, pair: usize) -> Result<(Vec<Draft>, Vec<Kept>)> {
    Ok((read_drafts(ctx, pair)?, read_kept(ctx, pair)?))
}

/// The events of pair `pair` (its events unit must be done).
pub fn read_drafts(ctx: &Ctx, pair: usize) -> Result<Vec<Draft>> {
    let u = ctx.unit(&Spec::pair(EventsStage::KIND, pair))?;
    super::read_json(ctx, u, EVENTS)
}

/// The kept core points of pair `pair` (its events unit must be done).
pub fn read_kept(ctx: &Ctx, pair: usize) -> Result<Vec<Kept>> {
    let u = ctx.unit(&Spec::pair(EventsStage::KIND, pair))?;
    let c = super::read_columns(ctx, u, KEPT)?;
    let kept_path = ctx.input(u, KEPT)?;
    let bad = |name: &str| Error::Damaged {
        path: kept_path.clone(),
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

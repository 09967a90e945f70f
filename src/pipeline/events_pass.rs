//! Events: significance filter → smoothing → signed DBSCAN merged across tiles → description →
//! volume per event, in parallel (SPEC.md §1, §3).
//!
//! The kept core points (significant and |d| ≥ τ) are few next to the epochs, so they are
//! gathered in memory. DBSCAN still runs tile by tile, with halos of `eps`, and is merged by a
//! global union-find over core-point keys ([`crate::events::dbscan`]): the clusters are exactly
//! those of one whole-cloud run, whatever the tile size. Volumes read only the points inside each
//! event's grown box, one tile at a time.

use std::collections::HashMap;
use std::path::Path;

use rayon::prelude::*;
use serde::Serialize;

use crate::error::Result;
use crate::events::{self, dbscan, Event, Kind, Obb};
use crate::io::Point3;
use crate::m3c2::orientation::STEEP_NZ;
use crate::params::Params;
use crate::pipeline::m3c2_pass::M3c2Results;
use crate::pipeline::outputs::MergedResults;
use crate::pipeline::tiles::{self, Layout, Tiled};
use crate::spatial::BoxIndex;
use crate::volume::{self, EventVolume, Mesh};

/// A kept core point.
struct Kept {
    key: u64,
    xyz: Point3,
    d: f64,
    lod: f64,
    normal: Point3,
    std_dev: [f64; 2],
}

/// Core points sampled for the stable ground's measurement: enough for the fit and the
/// variogram, few enough to hold (≈ 80 bytes each).
pub const STABLE_SAMPLES: u64 = 1_000_000;

/// Measure the noise and registration error on the stable ground from (an evenly spread sample
/// of) the M3C2 results, and resolve the parameters that depend on them.
pub fn measure_stable(
    results: &M3c2Results,
    params: Params,
) -> Result<(Option<events::stable::Stable>, Params)> {
    let total = results.count()?;
    let step = total.div_ceil(STABLE_SAMPLES).max(1);
    let mut samples = Vec::with_capacity(total.min(STABLE_SAMPLES) as usize);
    let mut merged = MergedResults::new(results)?;
    let mut n = 0u64;
    while let Some(k) = merged.next_result()? {
        if n.is_multiple_of(step) && k.r.distance.is_finite() {
            samples.push(events::stable::Sample {
                xyz: k.xyz,
                normal: k.r.normal,
                distance: k.r.distance,
                std_dev: [k.r.std_dev1, k.r.std_dev2],
                lod: k.r.uncertainty,
            });
        }
        n += 1;
    }
    let stable = events::stable::measure(&samples, params.core_spacing.value);
    let params = params.with_stable(stable.as_ref());
    Ok((stable, params))
}

/// One event with its volume.
#[derive(Debug, Clone, Serialize)]
pub struct EventRecord {
    #[serde(flatten)]
    pub event: Event,
    /// V(C2) − V(C1); None when the footprint had no surface in one epoch.
    pub volume_m3: Option<f64>,
    pub volume_uncertainty_m3: Option<f64>,
    /// The uncertainty's parts (one standard deviation each).
    pub uncertainty: Option<volume::uncertainty::VolumeUncertainty>,
    /// |V| exceeds its 95 % half-width.
    pub significant: bool,
    pub gain_m3: Option<f64>,
    pub loss_m3: Option<f64>,
    pub footprint_area_m2: Option<f64>,
    /// Area of the region the volume was integrated over.
    pub region_area_m2: Option<f64>,
    /// Share of the footprint both epochs cover.
    pub coverage: Option<f64>,
    /// Why there is no volume, when there is none.
    pub volume_note: Option<String>,
    #[serde(skip)]
    pub solids: Option<(Mesh, Mesh)>,
    /// The region's outline: polygons of rings of global points (see `EventVolume::outline`).
    #[serde(skip)]
    pub region: Vec<Vec<Vec<Point3>>>,
}

impl EventRecord {
    /// The record of event `e` from its volume (or why it has none).
    fn new(
        e: Event,
        v: Result<EventVolume>,
        model: impl FnOnce(&EventVolume) -> volume::uncertainty::ErrorModel,
    ) -> EventRecord {
        match v {
            Ok(v) => {
                let u = volume::uncertainty::propagate(&v.region, &model(&v));
                EventRecord {
                    volume_m3: Some(v.volume_m3),
                    volume_uncertainty_m3: Some(u.half_width_95_m3),
                    uncertainty: Some(u),
                    significant: v.volume_m3.abs() > u.half_width_95_m3,
                    gain_m3: Some(v.gain_m3),
                    loss_m3: Some(v.loss_m3),
                    footprint_area_m2: Some(v.footprint_area_m2),
                    region_area_m2: Some(v.region_area_m2),
                    coverage: Some(v.coverage),
                    volume_note: None,
                    region: v.outline(),
                    solids: Some((v.before_solid, v.after_solid)),
                    event: e,
                }
            }
            Err(err) => EventRecord {
                volume_m3: None,
                volume_uncertainty_m3: None,
                uncertainty: None,
                significant: false,
                gain_m3: None,
                loss_m3: None,
                footprint_area_m2: None,
                region_area_m2: None,
                coverage: None,
                volume_note: Some(err.to_string()),
                region: Vec::new(),
                solids: None,
                event: e,
            },
        }
    }
}

/// What the events stage produced.
#[derive(Default)]
pub struct EventsOut {
    pub events: Vec<EventRecord>,
    /// Kept core points: key → (smoothed distance, event id or 0).
    pub per_point: HashMap<u64, (f64, u32)>,
    pub kept_points: usize,
}

/// Run the events stage over the merged M3C2 results, with the parameters `measure_stable`
/// resolved.
pub fn run(
    results: &M3c2Results,
    layout: &Layout,
    tiled: &Tiled,
    params: &Params,
    stable: Option<&events::stable::Stable>,
    meshes: (Option<&Path>, Option<&Path>),
) -> Result<EventsOut> {
    let tau = params.threshold.value;
    let reg = params.reg_error.value;
    let mut kept = Vec::new();
    let mut merged = MergedResults::new(results)?;
    while let Some(k) = merged.next_result()? {
        let r = k.r.with_registration(reg);
        if events::filter::is_kept(r.distance, r.uncertainty, tau) {
            kept.push(Kept {
                key: k.key,
                xyz: k.xyz,
                d: r.distance,
                lod: r.uncertainty,
                normal: r.normal,
                std_dev: [r.std_dev1, r.std_dev2],
            });
        }
    }
    let pts: Vec<Point3> = kept.iter().map(|k| k.xyz).collect();
    let d: Vec<f64> = kept.iter().map(|k| k.d).collect();
    let smoothed = events::smooth::smooth(
        &pts,
        &d,
        params.smooth_k.value as usize,
        params.smooth_sigma.value,
    )?;
    // Signed clusters, each sign on its own.
    let mut clusters: Vec<(u64, Kind, Vec<usize>)> = Vec::new();
    for kind in [Kind::Gain, Kind::Loss] {
        let idx: Vec<usize> = (0..kept.len())
            .filter(|&i| kind.matches(smoothed[i]))
            .collect();
        let p: Vec<Point3> = idx.iter().map(|&i| pts[i]).collect();
        let keys: Vec<u64> = idx.iter().map(|&i| kept[i].key).collect();
        let labels = cluster_tiled(
            &p,
            &keys,
            layout,
            params.eps.value,
            params.cluster_min_points.value as usize,
        )?;
        let mut by_label: HashMap<u32, Vec<usize>> = HashMap::new();
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
    let mut per_point: HashMap<u64, (f64, u32)> = kept
        .iter()
        .zip(&smoothed)
        .map(|(k, &s)| (k.key, (s, 0)))
        .collect();
    let mut described = Vec::new();
    for (n, (_, kind, members)) in clusters.iter().enumerate() {
        let id = n as u32 + 1;
        let get =
            |f: &dyn Fn(&Kept) -> Point3| members.iter().map(|&i| f(&kept[i])).collect::<Vec<_>>();
        let p = get(&|k| k.xyz);
        let normals = get(&|k| k.normal);
        let dist: Vec<f64> = members.iter().map(|&i| kept[i].d).collect();
        let lod: Vec<f64> = members.iter().map(|&i| kept[i].lod).collect();
        for &i in members {
            per_point.insert(kept[i].key, (smoothed[i], id));
        }
        if let Some(e) = events::describe(id, *kind, &p, &dist, &lod, &normals, layout.core_spacing)
        {
            described.push(e);
        }
    }
    // The clustered core points with their event: the volume of one event must not count its
    // neighbour's change where their grown footprints overlap.
    let labelled: Vec<Labelled> = clusters
        .iter()
        .enumerate()
        .flat_map(|(n, (_, _, members))| members.iter().map(move |&i| (n as u32 + 1, i)))
        .map(|(id, i)| Labelled {
            xyz: kept[i].xyz,
            id,
            normal: kept[i].normal,
            std_dev: kept[i].std_dev,
        })
        .collect();
    let events = volumes(described, &labelled, layout, tiled, params, stable, meshes)?;
    Ok(EventsOut {
        events,
        per_point,
        kept_points: kept.len(),
    })
}

/// DBSCAN tile by tile (halo = eps), merged by a global union-find over `keys`.
fn cluster_tiled(
    pts: &[Point3],
    keys: &[u64],
    layout: &Layout,
    eps: f64,
    min_pts: usize,
) -> Result<Vec<u32>> {
    let grid = &layout.grid;
    let mut members: Vec<Vec<usize>> = vec![Vec::new(); grid.len()];
    let mut owner = Vec::with_capacity(pts.len());
    for (i, p) in pts.iter().enumerate() {
        owner.push(grid.index(grid.owner(p[0], p[1])));
        for t in grid.tiles_touching(p[0], p[1], eps) {
            members[grid.index(t)].push(i);
        }
    }
    let tile_points = |t: usize| -> (Vec<Point3>, Vec<bool>) {
        (
            members[t].iter().map(|&i| pts[i]).collect(),
            members[t].iter().map(|&i| owner[i] == t).collect(),
        )
    };
    // Phase 1: each tile decides the core status of the points it owns.
    let flags: Vec<Vec<bool>> = (0..grid.len())
        .into_par_iter()
        .map(|t| {
            let (p, owned) = tile_points(t);
            dbscan::core_flags(&p, &owned, eps, min_pts)
        })
        .collect::<Result<_>>()?;
    let mut core = vec![false; pts.len()];
    for (t, f) in flags.iter().enumerate() {
        for (j, &i) in members[t].iter().enumerate() {
            if owner[i] == t {
                core[i] = f[j];
            }
        }
    }
    // Phase 2: links through core points, halo ones included, then one global merge.
    let links: Vec<dbscan::TileLinks> = (0..grid.len())
        .into_par_iter()
        .map(|t| {
            let (p, owned) = tile_points(t);
            let ids: Vec<u64> = members[t].iter().map(|&i| keys[i]).collect();
            let c: Vec<bool> = members[t].iter().map(|&i| core[i]).collect();
            dbscan::tile_links(&p, &ids, &owned, &c, eps)
        })
        .collect::<Result<_>>()?;
    let labels = dbscan::merge(links);
    Ok(keys.iter().map(|&k| labels.get(k)).collect())
}

/// The box (in the event's frame) whose points the volume needs, and its XY bounds.
fn search_box(obb: &Obb, margin: f64, params: &Params) -> ([f64; 3], [f64; 4]) {
    let s = params.point_spacing;
    let h = [
        obb.half_extents[0] + margin + 3.0 * s,
        obb.half_extents[1] + margin + 3.0 * s,
        obb.half_extents[2] + params.cyl_halflen.value,
    ];
    let mut xy = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for c in 0..8 {
        let l = [
            if c & 1 == 0 { -h[0] } else { h[0] },
            if c & 2 == 0 { -h[1] } else { h[1] },
            if c & 4 == 0 { -h[2] } else { h[2] },
        ];
        let g = obb.to_global(&l);
        xy[0] = xy[0].min(g[0]);
        xy[1] = xy[1].min(g[1]);
        xy[2] = xy[2].max(g[0]);
        xy[3] = xy[3].max(g[1]);
    }
    (h, xy)
}

/// Volume margin of SPEC.md §1: cyl_radius + 2 × point spacing.
pub fn margin(params: &Params) -> f64 {
    params.cyl_radius.value + 2.0 * params.point_spacing
}

/// A clustered core point: where, which event, its normal and per-epoch spread.
struct Labelled {
    xyz: Point3,
    id: u32,
    normal: Point3,
    std_dev: [f64; 2],
}

/// The error model of one event's volume (see `volume::uncertainty`): per epoch the area a point
/// carries in the region and the mean per-point variance, the cluster's own over its core points'
/// share of the region and the stable ground's over the rest; the stable ground's variogram; and
/// the registration error along the event's core normals (the user's value if given).
fn error_model(
    v: &EventVolume,
    members: &[&Labelled],
    core_area: f64,
    params: &Params,
    stable: Option<&events::stable::Stable>,
) -> volume::uncertainty::ErrorModel {
    let area = v.region_area_m2;
    let cluster_area = (members.len() as f64 * core_area).min(area);
    let point_area = std::array::from_fn(|k| match v.region_points[k] {
        0 => params.point_spacing * params.point_spacing,
        n => area / n as f64,
    });
    let variance = std::array::from_fn(|k| {
        let own: Vec<f64> = members
            .iter()
            .map(|m| m.std_dev[k].powi(2))
            .filter(|x| x.is_finite())
            .collect();
        let own = own.iter().sum::<f64>() / own.len().max(1) as f64;
        let rest = stable.map_or(own, |s| s.point_variance[k]);
        (cluster_area * own + (area - cluster_area) * rest) / area.max(f64::MIN_POSITIVE)
    });
    let systematic = match stable {
        Some(s) if params.reg_error.source != "user" => (members
            .iter()
            .map(|m| s.along(&m.normal).powi(2))
            .sum::<f64>()
            / members.len().max(1) as f64)
            .sqrt(),
        _ => params.reg_error.value,
    };
    volume::uncertainty::ErrorModel {
        point_area,
        variance,
        variogram: stable.map(|s| s.variogram),
        systematic,
    }
}

/// The boxes an event's volume may be extruded along: its mean normal's, and straight up's
/// where the normal is not steep (see `volume::axis`).
fn candidate_boxes(e: &Event, cluster: &[Point3]) -> Vec<Obb> {
    let mut boxes = vec![e.obb];
    let n = e.mean_normal;
    if n[2] >= STEEP_NZ && n[2] < 1.0 - 1e-9 {
        boxes.extend(events::describe::box_along(cluster, [0.0, 0.0, 1.0]));
    }
    boxes
}

/// A search box: its half extents in the box frame, its xy bounds, the box.
type SearchBox = ([f64; 3], [f64; 4], Obb);

/// Each event's points of both epochs inside any of its search boxes, from the tiles the boxes
/// touch (owned points only: no duplicates from halos).
#[allow(clippy::type_complexity)]
fn gather(
    boxes: &[Vec<SearchBox>],
    layout: &Layout,
    tiled: &Tiled,
) -> Result<(Vec<Vec<Point3>>, Vec<Vec<Point3>>)> {
    let mut before: Vec<Vec<Point3>> = vec![Vec::new(); boxes.len()];
    let mut after: Vec<Vec<Point3>> = vec![Vec::new(); boxes.len()];
    let flat: Vec<(usize, &SearchBox)> = boxes
        .iter()
        .enumerate()
        .flat_map(|(e, b)| b.iter().map(move |x| (e, x)))
        .collect();
    let index = BoxIndex::new(&flat.iter().map(|(_, b)| b.1).collect::<Vec<_>>());
    for id in layout.grid.tiles() {
        let sq = layout.grid.square(id);
        if !index.any_overlaps(&[sq.min[0], sq.min[1], sq.max[0], sq.max[1]]) {
            continue;
        }
        for (dir, out) in [(&tiled.before, &mut before), (&tiled.after, &mut after)] {
            let t = tiles::read_tile(dir, id)?;
            for (i, &own) in t.owned.iter().enumerate() {
                if !own {
                    continue;
                }
                let p = t.point(i);
                let mut last = usize::MAX;
                for k in index.containing(p[0], p[1]) {
                    let (e, (h, _, obb)) = flat[k];
                    if e == last {
                        continue;
                    }
                    let l = obb.to_local(&p);
                    if l[0].abs() <= h[0] && l[1].abs() <= h[1] && l[2].abs() <= h[2] {
                        out[e].push(p);
                        last = e;
                    }
                }
            }
        }
    }
    Ok((before, after))
}

fn volumes(
    described: Vec<Event>,
    labelled: &[Labelled],
    layout: &Layout,
    tiled: &Tiled,
    params: &Params,
    stable: Option<&events::stable::Stable>,
    meshes: (Option<&Path>, Option<&Path>),
) -> Result<Vec<EventRecord>> {
    let margin = margin(params);
    let spacing = params.point_spacing;
    let user = match meshes {
        (Some(b), Some(a)) => Some((volume::read_ply_mesh(b)?, volume::read_ply_mesh(a)?)),
        (Some(p), None) | (None, Some(p)) => {
            return Err(crate::Error::input(
                p,
                "--before-mesh and --after-mesh go together: give both surfaces",
            ))
        }
        (None, None) => None,
    };
    let mut cores: HashMap<u32, Vec<Point3>> = HashMap::new();
    let mut members: HashMap<u32, Vec<&Labelled>> = HashMap::new();
    for l in labelled {
        cores.entry(l.id).or_default().push(l.xyz);
        members.entry(l.id).or_default().push(l);
    }
    let core_area = params.core_spacing.value.powi(2);
    let no_cores = Vec::new();
    let cluster = |e: &Event| cores.get(&e.id).unwrap_or(&no_cores);
    // Points for every candidate box (user meshes: none, and the mean normal's box).
    let candidates: Vec<Vec<Obb>> = described
        .iter()
        .map(|e| match user {
            Some(_) => vec![e.obb],
            None => candidate_boxes(e, cluster(e)),
        })
        .collect();
    let boxes: Vec<Vec<SearchBox>> = candidates
        .iter()
        .map(|c| {
            c.iter()
                .map(|o| {
                    let (h, xy) = search_box(o, margin, params);
                    (h, xy, *o)
                })
                .collect()
        })
        .collect();
    let (before, after) = match user {
        Some(_) => (
            vec![Vec::new(); described.len()],
            vec![Vec::new(); described.len()],
        ),
        None => gather(&boxes, layout, tiled)?,
    };
    // The extrusion axis: the candidate in which both epochs have the fewest points on walls or
    // fold-overs (volume::axis); the mean normal on a tie.
    let described: Vec<Event> = described
        .into_par_iter()
        .zip(&boxes)
        .enumerate()
        .map(|(i, (mut e, cands))| {
            let walls = |(h, _, o): &SearchBox| {
                let frame = volume::Frame::of_obb(o);
                let r = volume::Footprint::of_obb(o, margin);
                volume::axis::wall_points(&frame, &r, h[2], &before[i], spacing)
                    + volume::axis::wall_points(&frame, &r, h[2], &after[i], spacing)
            };
            if cands.len() > 1 {
                let counts: Vec<usize> = cands.iter().map(walls).collect();
                let best = (0..cands.len())
                    .min_by_key(|&k| (counts[k], k))
                    .unwrap_or(0);
                e.obb = cands[best].2;
            }
            e
        })
        .collect();
    // Each event claims its search box; a location in several boxes belongs to the event with
    // the nearest clustered core point (volume::ownership).
    let claims: Vec<volume::Claim> = described
        .iter()
        .map(|e| {
            let (h, _) = search_box(&e.obb, margin, params);
            volume::Claim::new(
                e.id,
                volume::Frame::of_obb(&e.obb),
                volume::Footprint::of_obb(&e.obb, margin),
                h[2],
                cluster(e),
            )
        })
        .collect();
    let ownership = volume::Ownership::new(claims);
    // Gathered tile by tile, the points come in an order that depends on the tiling;
    // `volume::epoch_tin` sorts what it triangulates, so the volumes do not.
    let records = described
        .into_par_iter()
        .enumerate()
        .map(|(i, e)| {
            let id = e.id;
            let owned = |x: &Point3| ownership.owner(x) == Some(id);
            let v: Result<EventVolume> = match &user {
                Some((mb, ma)) => {
                    let frame = volume::Frame::of_obb(&e.obb);
                    let r = volume::Footprint::of_obb(&e.obb, margin);
                    let sb = volume::UserMesh::new(mb, &frame, &r);
                    let sa = volume::UserMesh::new(ma, &frame, &r);
                    volume::event_volume_from_surfaces(&e.obb, margin, &sb, &sa, spacing, &owned)
                }
                None => {
                    volume::event_volume(&e.obb, margin, &before[i], &after[i], spacing, &owned)
                }
            };
            let m = members.get(&id).map(|v| v.as_slice()).unwrap_or(&[]);
            EventRecord::new(e, v, |v| error_model(v, m, core_area, params, stable))
        })
        .collect();
    Ok(records)
}

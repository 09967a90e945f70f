//! A volumes unit: the volume, region, uncertainty and solids of the pair's events whose centroid
//! one tile owns (SPEC.md §1 "Volume", "Volume accounting"), reading only the points inside each
//! event's search boxes, from the tiles those boxes touch.
//!
//! Every event's claim comes from the events unit, so each volumes unit decides ownership the
//! same way without waiting for the others: an event claims all its candidate boxes (along the
//! mean normal and, on gentle ground, straight up), a location in several claims belongs to the
//! event with the nearest clustered core point (`volume::ownership`). Writes `volumes.json` and
//! each event's two solids as PLY.

use rustc_hash::FxHashMap as HashMap;

use serde::{Deserialize, Serialize};
use talus_tiling::TileId;

use super::events::{reached_tiles, search, search_xy, Draft, EventsStage, Kept};
use super::stable::StableStage;
use super::stage::{Line, Planner, Scope, Stage, Total};
use super::{Ctx, Tiles};
use crate::error::Result;
use crate::events::stable::Stable;
use crate::events::{Event, Obb};
use crate::io::Point3;
use crate::params::Params;
use crate::plan::Spec;
use crate::spatial::BoxIndex;
use crate::store::UnitWriter;
use crate::volume::{self, uncertainty, EventVolume};

pub(crate) const FILE: &str = "volumes.json";

/// Resident bytes per cell of one piece of an event's volume (`volume::PIECE_CELLS` at most)
/// while it is computed: the two tops clipped to the cells, their labels' tables while they are
/// built, the solids grown from them with the sort of their edges, the piece's grids and the
/// heights asked on them (`volume::Lattice`: at most 4 sub-cells a cell for each surface,
/// 64 bytes). The cost follows the cells (about one per point spacing squared of the
/// footprint), not the points. Measured on the cliff's three large events with `--threads 1`
/// (VmHWM reset before each, [`BYTES_PER_POINT`] a point taken off), each then in one piece:
/// 617, 926 and 807 bytes a cell (95 k, 22.5 k and 51 k cells), when every TIN triangle was cut
/// into a piece per cell it crosses; since only the triangles the region's edge passes through
/// are cut (`volume::solid::clipped_top`) the tops hold about a quarter of the faces, so this
/// is now an upper bound. Before large blocks were mapped on their own
/// (`memory::MMAP_THRESHOLD`) the same events measured 1,360, 1,025 and 1,460.
pub(crate) const BYTES_PER_CELL: u64 = 1024;

/// How a large event is cut into pieces (`volume::pieces`).
const CUTTING: volume::Cutting = volume::Cutting::Fewest(volume::PIECE_CELLS);

/// Resident bytes per cell of the whole event beside its pieces: whether both epochs cover it
/// and whether it is in the region (2), the surfaces' difference at its centre (16), the open
/// rim's sort of the region's changes (8), the uncertainty's list of region cells (16, after the
/// rest is given back).
pub(crate) const BYTES_PER_GRID_CELL: u64 = 32;

/// Resident bytes per point (both epochs) a piece triangulates or tests for walls, beside its
/// cells' cost: the points in the event's frame, a triangulation's share (spade is lean: ≈ 40),
/// its mesh copied out for clipping (48).
pub(crate) const BYTES_PER_POINT: u64 = 100;

/// Resident bytes per point gathered around a unit's events (both epochs, global coordinates),
/// held while all of them are measured: reserved with each event's need.
pub(crate) const GATHERED_BYTES: u64 = 24;

/// What one event's volume holds at most, over its candidate boxes: [`BYTES_PER_CELL`] for the
/// cells of its largest piece, [`BYTES_PER_GRID_CELL`] for all its cells, [`BYTES_PER_POINT`] for
/// the most points one of its pieces takes from `points` (before, after).
fn event_need(boxes: &[SearchBox], points: [&[Point3]; 2], margin: f64, spacing: f64) -> u64 {
    boxes
        .iter()
        .map(|(_, _, o)| {
            let cells = volume::grid(o, margin, spacing);
            let piece = cells.len().min(volume::PIECE_CELLS) as u64;
            let taken = volume::pieces(o, margin, points, spacing, CUTTING).1;
            piece * BYTES_PER_CELL
                + cells.len() as u64 * BYTES_PER_GRID_CELL
                + taken as u64 * BYTES_PER_POINT
        })
        .max()
        .unwrap_or(0)
        + crate::memory::HEADROOM
}

/// The mesh files of event `id`: (before, after).
pub(crate) fn mesh_files(id: u32) -> [String; 2] {
    ["before", "after"].map(|w| format!("event_{id:04}_{w}.ply"))
}

/// One event's volume as a volumes unit records it.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct Measured {
    pub(crate) id: u32,
    /// The box of the axis the volume was extruded along.
    pub(crate) obb: Obb,
    pub(crate) volume_m3: Option<f64>,
    pub(crate) uncertainty: Option<uncertainty::VolumeUncertainty>,
    pub(crate) gain_m3: Option<f64>,
    pub(crate) loss_m3: Option<f64>,
    pub(crate) footprint_area_m2: Option<f64>,
    pub(crate) region_area_m2: Option<f64>,
    pub(crate) coverage: Option<f64>,
    /// The region's outline: polygons of rings of global points (see `EventVolume::outline`).
    pub(crate) region: Vec<Vec<Vec<Point3>>>,
    /// Whether the two solids were written.
    pub(crate) meshes: bool,
    /// The volume covers the whole change: no core point beyond the M3C2 cylinder's reach, and
    /// no change running on past the region into ground that was not measured.
    pub(crate) complete: bool,
    /// Why there is no volume, or why it is incomplete.
    pub(crate) note: Option<String>,
    /// The share of the event's core points that look like vegetation in either epoch
    /// (`events::vegetation`); None when the volume came from the user's surfaces (no points).
    pub(crate) vegetation_fraction: Option<f64>,
    /// The data decides the event's sign: most of its core points' normals are oriented by a
    /// decided field ([`sign_known`]).
    pub(crate) sign_known: bool,
}

/// Whether the data decides event `d`'s sign: at most half its core points have a normal whose
/// sign it does not decide (a face near vertical scanned alone: `m3c2::field`).
pub(crate) fn sign_known(d: &Draft) -> bool {
    2 * d.sign_unknown <= d.event.n_points
}

/// Edges of open rim (see `volume::OpenRim`) that must have changed before an event is called
/// incomplete, and the share of the open rim: a single noisy cell at a hole is not a change
/// running on.
const OPEN_RIM_CELLS: f64 = 3.0;
const OPEN_RIM_SHARE: f64 = 0.05;

/// Why event `d`'s volume `v` does not cover its whole change, if it does not: core points
/// whose other epoch lies beyond the user's half-length, or change still well above the noise
/// (`noise`: |Δw| a cell of unchanged ground exceeds in 1 of 40) and above a quarter of the
/// event's own change where the region meets ground not measured.
fn incomplete(d: &Draft, v: &EventVolume, noise: f64, params: &Params) -> Option<String> {
    let mut why = Vec::new();
    if !sign_known(d) {
        why.push(format!(
            "the data cannot tell which side of the surface is out for {} of its {} core points \
             (a face near vertical scanned alone: nothing in front of it or above it to say \
             which way it faces): gain and loss may be the reverse; give --orientation \
             toward:X,Y,Z (the scanner's position) to decide",
            d.sign_unknown, d.event.n_points
        ));
    }
    if d.beyond_reach > 0 {
        why.push(format!(
            "{} of its {} core points have the other survey beyond the M3C2 cylinder's \
             half-length ({} m, set by the user): their distances were not measured",
            d.beyond_reach, d.event.n_points, params.cyl_halflen.value
        ));
    }
    let level = noise.max(0.25 * v.open_rim.p90_change);
    let (changed, open) = v.open_rim.changed_length(level);
    let cell = (v.region.cells.cell_area()).sqrt();
    if changed >= (OPEN_RIM_CELLS * cell).max(OPEN_RIM_SHARE * open) && changed > 0.0 {
        why.push(format!(
            "its change runs on past {changed:.2} m of its region's edge into ground a survey does \
             not cover or beyond its footprint (changed by more than {level:.3} m there): the \
             volume counts the measured part only"
        ));
    }
    (!why.is_empty()).then(|| why.join("; "))
}

/// The ids of the events with a candidate whose search box overlaps, in xy, one of `mine`'s:
/// every event whose claim can contain a location of `mine`'s regions.
fn near_events(drafts: &[Draft], mine: &[&Draft], params: &Params) -> rustc_hash::FxHashSet<u32> {
    let xy = |d: &Draft| search_xy(d, params);
    let ours: Vec<[f64; 4]> = mine.iter().flat_map(|d| xy(d)).collect();
    let index = BoxIndex::new(&ours);
    drafts
        .iter()
        .filter(|d| xy(d).iter().any(|b| index.any_overlaps(b)))
        .map(|d| d.event.id)
        .collect()
}

/// The core points of the `near` events, read a frame at a time, decoding only the frames that
/// reach one of their boxes (an event's box encloses its core points, `events::describe`). Every
/// event's count is checked against its record; should one fall short, the file is read whole.
fn near_members(
    ctx: &Ctx,
    pair: usize,
    drafts: &[Draft],
    near: &rustc_hash::FxHashSet<u32>,
) -> Result<HashMap<u32, Vec<Kept>>> {
    let (mut expected, mut boxes) = (HashMap::default(), Vec::new());
    for d in drafts.iter().filter(|d| near.contains(&d.event.id)) {
        expected.insert(d.event.id, d.event.n_points);
        boxes.push(plan_box(&d.event.obb));
    }
    let reached = |b: &crate::geom::Bounds| super::reaches(b, &boxes);
    let read = |want: &dyn Fn(&crate::geom::Bounds) -> bool| {
        let mut members: HashMap<u32, Vec<Kept>> = HashMap::default();
        let mut kept = super::events::KeptFrames::open(ctx, pair)?;
        while let Some(rows) = kept.next_frame_where(want)? {
            for k in rows {
                if k.event > 0 && near.contains(&k.event) {
                    members.entry(k.event).or_default().push(k);
                }
            }
        }
        Ok::<_, crate::Error>(members)
    };
    let members = read(&reached)?;
    if expected
        .iter()
        .all(|(id, &n)| members.get(id).map_or(0, |m| m.len()) == n)
    {
        return Ok(members);
    }
    crate::progress::trace(|| format!("pair {pair}: kept core points read whole"));
    read(&|_| true)
}

/// The box in plan ([x0, y0, x1, y1]) of an oriented box, padded by a millionth of its size and
/// a micrometre against rounding.
fn plan_box(o: &Obb) -> [f64; 4] {
    let pad = 1e-6 * (1.0 + o.half_extents.iter().fold(0.0f64, |m, &h| m.max(2.0 * h)));
    let h = o.half_extents.map(|h| h + pad);
    volume::Frame::of_obb(o).bounds_xy(h.map(|x| -x), h)
}

/// The claims of every event (one per candidate box) over their clustered core points.
pub(crate) fn ownership(
    drafts: &[&Draft],
    members: &HashMap<u32, Vec<Kept>>,
    params: &Params,
) -> volume::Ownership {
    let s = search(params);
    let claims = drafts
        .iter()
        .flat_map(|d| {
            let cores: Vec<Point3> = members
                .get(&d.event.id)
                .map(|m| m.iter().map(|k| k.xyz).collect())
                .unwrap_or_default();
            d.candidates
                .iter()
                .map(|o| {
                    let (h, _) = s.search_box(o, s.depth(d.event.max_abs_distance));
                    volume::Claim::new(
                        d.event.id,
                        volume::Frame::of_obb(o),
                        volume::Footprint::of_obb(o, s.margin),
                        h[2],
                        &cores,
                    )
                })
                .collect::<Vec<_>>()
        })
        .collect();
    volume::Ownership::new(claims)
}

/// The error model of one event's volume (see `volume::uncertainty`): per epoch the area a point
/// carries in the region and the mean per-point variance, the cluster's own over its core points'
/// share of the region and the stable ground's over the rest; the stable ground's variogram; and
/// the registration error along the event's core normals (the user's value if given).
fn error_model(
    v: &EventVolume,
    members: &[Kept],
    params: &Params,
    stable: Option<&Stable>,
) -> uncertainty::ErrorModel {
    let area = v.region_area_m2;
    let core_area = params.core_spacing.value.powi(2);
    let cluster_area = (members.len() as f64 * core_area).min(area);
    let point_area = std::array::from_fn(|k| match v.region_points[k] {
        0 => params.point_spacing.value * params.point_spacing.value,
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
        Some(s) if !params.reg_error.is_user() => (members
            .iter()
            .map(|m| s.along(&m.normal).powi(2))
            .sum::<f64>()
            / members.len().max(1) as f64)
            .sqrt(),
        _ => params.reg_error.value,
    };
    uncertainty::ErrorModel {
        point_area,
        variance,
        variogram: stable.map(|s| s.variogram),
        systematic,
        sampling: v.step_variance_m6.max(0.0).sqrt(),
    }
}

/// The share of event `e`'s core points `members` that look like vegetation in either epoch
/// (`events::vegetation`), from the points gathered around it: the before survey at the core
/// point, the after survey where its distance puts the after surface (the core point moved
/// along its normal; the core point itself without a distance). The balls (up to 8 point
/// spacings) lie inside the search boxes, which reach the volume margin and three spacings
/// beyond the event's box.
fn vegetation_fraction(
    e: &Event,
    members: &[Kept],
    before: &[Point3],
    after: &[Point3],
    params: &Params,
) -> f64 {
    use crate::events::vegetation;
    let s = params.point_spacing.value;
    let cell = vegetation::SCALES[0] * s;
    let (b, a) = rayon::join(
        || crate::spatial::Columns::new(before, e.centroid, cell),
        || crate::spatial::Columns::new(after, e.centroid, cell),
    );
    let cores: Vec<(Point3, Point3)> = members
        .iter()
        .map(|k| {
            let moved = if k.d.is_finite() && k.normal.iter().all(|c| c.is_finite()) {
                [0, 1, 2].map(|j| k.xyz[j] + k.d * k.normal[j])
            } else {
                k.xyz
            };
            (b.to_local(&k.xyz), a.to_local(&moved))
        })
        .collect();
    vegetation::fraction(&b, &a, &cores, s)
}

/// A search box: its half extents in the box frame, its xy bounds, the box.
type SearchBox = ([f64; 3], [f64; 4], Obb);

/// Each event's points of both epochs inside any of its search boxes, from the tiles the boxes
/// touch (owned points only: no duplicates from halos).
fn gather(
    ctx: &Ctx,
    tilings: [&Tiles; 2],
    boxes: &[Vec<SearchBox>],
) -> Result<[Vec<Vec<Point3>>; 2]> {
    let mut out = [vec![Vec::new(); boxes.len()], vec![Vec::new(); boxes.len()]];
    let flat: Vec<(usize, &SearchBox)> = boxes
        .iter()
        .enumerate()
        .flat_map(|(e, b)| b.iter().map(move |x| (e, x)))
        .collect();
    if flat.is_empty() {
        return Ok(out);
    }
    let boxes_xy: Vec<[f64; 4]> = flat.iter().map(|(_, b)| b.1).collect();
    let index = BoxIndex::new(&boxes_xy);
    let grid = ctx.plan.layout.grid()?;
    for id in grid.tiles() {
        let sq = grid.square(id);
        if !index.any_overlaps(&[sq.min[0], sq.min[1], sq.max[0], sq.max[1]]) {
            continue;
        }
        for (epoch, &tiling) in tilings.iter().enumerate() {
            // Only the tile's frames that reach a box (a frame holds a strip of the tile), a
            // frame held at a time.
            super::for_each_frame_near(ctx, tiling, id, &boxes_xy, |t| {
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
                            out[epoch][e].push(p);
                            last = e;
                        }
                    }
                }
            })?;
        }
    }
    Ok(out)
}

/// The volumes of the pair's events whose centroid a tile owns.
pub(crate) struct VolumesStage;

/// What a volumes unit records.
#[derive(Debug, Clone, Serialize, Deserialize)]
pub(crate) struct VolumesMeta {
    /// Events measured.
    pub(crate) events: usize,
    /// Points gathered for them, both surveys.
    pub(crate) points: usize,
    /// The most points one event gathered.
    pub(crate) largest_event_points: usize,
}

impl Stage for VolumesStage {
    const KIND: &'static str = "volumes";
    const SCOPE: Scope = Scope::Tile;
    const VERSION: u32 = 1;
    const LINE: Line = Line {
        name: "volumes",
        counts: "events",
        total: Total::Unknown,
    };
    type Meta = VolumesMeta;

    /// One per pair and tile (none with `--m3c2-only`), over the pair's events, stable ground
    /// and both tilings (the points around the events), or the user's surfaces.
    fn plan(p: &mut Planner) -> Result<()> {
        if p.plan.m3c2_only {
            return Ok(());
        }
        let grid = p.plan.layout.grid()?;
        let meshes = p
            .plan
            .meshes
            .as_ref()
            .map_or("points".to_string(), |[m1, m2]| {
                format!("{}|{}", m1.key, m2.key)
            });
        let params = &p.plan.params;
        // `vegetation 1`: the events' vegetation fractions (`events::vegetation`) are part of
        // what a unit records.
        let key = format!(
            "{}|{}|{}|vegetation 1",
            params.cyl_radius.value, params.cyl_halflen.value, params.point_spacing.value
        );
        for pair in 0..p.plan.pairs.len() {
            let (b, a) = (p.plan.pairs[pair].before, p.plan.pairs[pair].after);
            let mut deps = vec![
                p.the(&Spec::pair(EventsStage::KIND, pair))?,
                p.the(&Spec::pair(StableStage::KIND, pair))?,
            ];
            deps.extend(p.survey_tiles(b)?);
            deps.extend(p.survey_tiles(a)?);
            let label = p.plan.pairs[pair].label.clone();
            for t in grid.tiles() {
                p.add(
                    Spec::tile(Self::KIND, pair, t),
                    &format!("{label}-{}", t.name()),
                    &[&key, &meshes],
                    deps.clone(),
                );
            }
        }
        Ok(())
    }

    fn run(ctx: &Ctx, unit: usize, out: &mut UnitWriter) -> Result<VolumesMeta> {
        run(ctx, ctx.pair(unit)?, ctx.tile(unit)?, out)
    }
}

/// Measure the events of pair `pair` whose centroid tile `tile` owns, into `out`: find them and
/// the events near them, decide who owns each location, gather both surveys' points in their
/// search boxes, and measure one event at a time ([`TileEvents::measure`]).
fn run(ctx: &Ctx, pair: usize, tile: TileId, out: &mut UnitWriter) -> Result<VolumesMeta> {
    let plan = ctx.plan;
    let p = &plan.pairs[pair];
    let tilings = [ctx.tiling(p.before)?, ctx.tiling(p.after)?];
    let ground = super::stable::read(ctx, pair)?;
    let params = &ground.params(plan);
    let stable = ground.stable.as_ref();
    let grid = plan.layout.grid()?;
    // The events whose boxes reach this tile include those whose centroid it owns (a centroid
    // lies in its event's box); the pair's whole events.json is never read.
    let near_drafts = super::events::NearDrafts::open(ctx, pair)?;
    let here = near_drafts.drafts(tile)?;
    let mine: Vec<&Draft> = here
        .iter()
        .filter(|d| grid.owner(d.event.centroid[0], d.event.centroid[1]) == tile)
        .collect();
    let mut measured: Vec<Measured> = Vec::new();
    let (mut gathered, mut largest) = (0usize, 0usize);
    if !mine.is_empty() {
        let drafts = drafts_near(&near_drafts, &here, &mine, tile, params, &grid)?;
        // Only the events whose claims can reach this tile's events decide ownership here: an
        // event owns a location only inside its claim, which lies inside its search boxes, so
        // the others are never asked (building every event's claim in every unit cost as much
        // as the tile's own volumes on the 120M-point pair).
        let near = near_events(&drafts, &mine, params);
        let members = near_members(ctx, pair, &drafts, &near)?;
        let relevant: Vec<&Draft> = drafts
            .iter()
            .filter(|d| near.contains(&d.event.id))
            .collect();
        let ownership = ownership(&relevant, &members, params);
        let user = user_surfaces(plan)?;
        let margin = search(params).margin;
        let spacing = params.point_spacing.value;
        let boxes = search_boxes(&mine, params, user.is_some());
        let [mut before, mut after] = match user {
            Some(_) => [vec![Vec::new(); mine.len()], vec![Vec::new(); mine.len()]],
            None => gather(ctx, [&tilings[0], &tilings[1]], &boxes)?,
        };
        for (b, a) in before.iter_mut().zip(&mut after) {
            // What was gathered is held while every event of the tile is measured: as much as
            // its points (the pushes left up to twice that).
            b.shrink_to_fit();
            a.shrink_to_fit();
            gathered += b.len() + a.len();
            largest = largest.max(b.len() + a.len());
        }
        let held = gathered as u64 * GATHERED_BYTES;
        let events = TileEvents {
            ownership: &ownership,
            members: &members,
            user: user.as_ref(),
            params,
            stable,
            margin,
            spacing,
        };
        // Gathered tile by tile, the points come in an order that depends on the tiling;
        // `volume::local_in` sorts what it triangulates, so the volumes do not.
        // One event at a time, each with its reservation (the triangulations, grids and solids of
        // a large event are most of the unit's memory); each event's own work is parallel.
        for (i, d) in mine.iter().enumerate() {
            let n = (before[i].len() + after[i].len()) as u64;
            let _held = ctx.reserve(
                event_need(&boxes[i], [&before[i], &after[i]], margin, spacing) + held,
                &format!(
                    "the volume of event {} ({n} points; {gathered} gathered for the tile's {} \
                     events)",
                    d.event.id,
                    mine.len()
                ),
            )?;
            measured.push(events.measure(out, d, &boxes[i], [&before[i], &after[i]])?);
        }
    }
    (ctx.progress)(measured.len() as u64);
    super::write_json(out, FILE, &measured)?;
    Ok(VolumesMeta {
        events: measured.len(),
        points: gathered,
        largest_event_points: largest,
    })
}

/// The drafts of every event near `mine` (the events of `here`, tile `tile`'s line, whose
/// centroid it owns): those of the tiles their boxes reach, in id order, each once. Every event
/// whose boxes overlap one of mine's reaches a tile that one of mine reaches.
fn drafts_near(
    near_drafts: &super::events::NearDrafts,
    here: &[Draft],
    mine: &[&Draft],
    tile: TileId,
    params: &Params,
    grid: &talus_tiling::TileGrid,
) -> Result<Vec<Draft>> {
    let mut tiles: Vec<TileId> = mine
        .iter()
        .flat_map(|d| reached_tiles(d, params, grid))
        .collect();
    tiles.sort_unstable();
    tiles.dedup();
    // This tile's line is already read.
    let mut drafts: Vec<Draft> = here.to_vec();
    for t in tiles.into_iter().filter(|&t| t != tile) {
        drafts.extend(near_drafts.drafts(t)?);
    }
    drafts.sort_by_key(|d| d.event.id);
    drafts.dedup_by_key(|d| d.event.id);
    Ok(drafts)
}

/// The user's surfaces (before, after), read, when the plan has them.
fn user_surfaces(plan: &crate::plan::Plan) -> Result<Option<(volume::Mesh, volume::Mesh)>> {
    match &plan.meshes {
        Some([b, a]) => Ok(Some((
            crate::io::mesh_ply::read_ply_mesh(&b.path)?,
            crate::io::mesh_ply::read_ply_mesh(&a.path)?,
        ))),
        None => Ok(None),
    }
}

/// The search boxes of each of `mine`'s events: one per candidate box, or only the first
/// (the mean normal's) with the user's surfaces (`surfaces`).
fn search_boxes(mine: &[&Draft], params: &Params, surfaces: bool) -> Vec<Vec<SearchBox>> {
    let s = search(params);
    mine.iter()
        .map(|d| {
            let c: &[Obb] = if surfaces {
                &d.candidates[..1]
            } else {
                &d.candidates
            };
            c.iter()
                .map(|o| {
                    let (h, xy) = s.search_box(o, s.depth(d.event.max_abs_distance));
                    (h, xy, *o)
                })
                .collect()
        })
        .collect()
}

/// What every event of a volumes unit is measured with: who owns each location, the events'
/// clustered core points, the user's surfaces if given, the pair's parameters and stable ground.
struct TileEvents<'a> {
    ownership: &'a volume::Ownership,
    members: &'a HashMap<u32, Vec<Kept>>,
    user: Option<&'a (volume::Mesh, volume::Mesh)>,
    params: &'a Params,
    stable: Option<&'a Stable>,
    margin: f64,
    spacing: f64,
}

impl TileEvents<'_> {
    /// The volume of event `d` from `points` (before, after) in its search boxes `boxes`, its
    /// solids written to `out` when it has one.
    fn measure(
        &self,
        out: &mut UnitWriter,
        d: &Draft,
        boxes: &[SearchBox],
        points: [&[Point3]; 2],
    ) -> Result<Measured> {
        let (margin, spacing, params) = (self.margin, self.spacing, self.params);
        let mut e: Event = d.event.clone();
        let (obb, window) = extrusion_box(boxes, points, margin, spacing);
        if let Some(obb) = obb {
            e.obb = obb;
        }
        let id = e.id;
        let owned = |x: &Point3| self.ownership.owner(x) == Some(id);
        let cells = volume::grid(&e.obb, margin, spacing);
        let pieced = cells.len() > volume::PIECE_CELLS;
        let mut solids = super::solids::EventSolids::new(out, id, pieced)?;
        let mut send = |pair: [volume::Mesh; 2]| solids.push(pair);
        let v = match self.user {
            Some((mb, ma)) => {
                let frame = volume::Frame::of_obb(&e.obb);
                let r = volume::Footprint::of_obb(&e.obb, margin);
                let sb = volume::UserMesh::new(mb, &frame, &r);
                let sa = volume::UserMesh::new(ma, &frame, &r);
                volume::event_volume_from_surfaces(
                    &e.obb, margin, &sb, &sa, spacing, &owned, &mut send,
                )
            }
            None => volume::event_volume_in(
                &e.obb, margin, window, points, spacing, &owned, CUTTING, &mut send,
            ),
        };
        let m = self.members.get(&id).map(|v| v.as_slice()).unwrap_or(&[]);
        let vegetation_fraction = match self.user {
            Some(_) => None,
            None => Some(vegetation_fraction(&e, m, points[0], points[1], params)),
        };
        let measured = match v {
            Ok(v) => {
                let model = error_model(&v, m, params, self.stable);
                let u = uncertainty::propagate(&v.region, &model);
                // A cell's difference on unchanged ground: both epochs' point noise and the
                // registration error.
                let noise =
                    2.24 * ((model.variance[0] + model.variance[1]).sqrt() + model.systematic);
                let note = incomplete(d, &v, noise, params);
                Measured {
                    id,
                    obb: e.obb,
                    volume_m3: Some(v.volume_m3),
                    uncertainty: Some(u),
                    gain_m3: Some(v.gain_m3),
                    loss_m3: Some(v.loss_m3),
                    footprint_area_m2: Some(v.footprint_area_m2),
                    region_area_m2: Some(v.region_area_m2),
                    coverage: Some(v.coverage),
                    region: v.outline(),
                    meshes: true,
                    complete: note.is_none(),
                    note,
                    vegetation_fraction,
                    sign_known: sign_known(d),
                }
            }
            Err(err) => Measured {
                id,
                obb: e.obb,
                volume_m3: None,
                uncertainty: None,
                gain_m3: None,
                loss_m3: None,
                footprint_area_m2: None,
                region_area_m2: None,
                coverage: None,
                region: Vec::new(),
                meshes: false,
                complete: false,
                note: Some(err.to_string()),
                vegetation_fraction,
                sign_known: sign_known(d),
            },
        };
        // Written plainly, the digest computed on the way: the unit's commit makes them
        // durable (a sync and a read-back per file cost 2 × 1028 of each at 120M).
        if measured.meshes {
            solids.finish(out)?;
        } else {
            solids.discard()?;
        }
        Ok(measured)
    }
}

/// The extrusion axis of an event with several candidate boxes `boxes`: the one in which both
/// epochs (`points`) have the fewest points on walls or fold-overs (`volume::axis`), the mean
/// normal's on a tie; its box (None with one candidate: the event's own) and search depth.
fn extrusion_box(
    boxes: &[SearchBox],
    points: [&[Point3]; 2],
    margin: f64,
    spacing: f64,
) -> (Option<Obb>, f64) {
    let window = boxes.first().map_or(f64::INFINITY, |b| b.0[2]);
    if boxes.len() <= 1 {
        return (None, window);
    }
    let walls = |(h, _, o): &SearchBox| {
        let frame = volume::Frame::of_obb(o);
        let r = volume::Footprint::of_obb(o, margin);
        volume::axis::wall_points(&frame, &r, h[2], points[0], spacing)
            + volume::axis::wall_points(&frame, &r, h[2], points[1], spacing)
    };
    let counts: Vec<usize> = boxes.iter().map(walls).collect();
    let best = (0..boxes.len())
        .min_by_key(|&k| (counts[k], k))
        .unwrap_or(0);
    (Some(boxes[best].2), boxes[best].0[2])
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Two events whose search boxes overlap (as `near_events` judges) reach a common tile, and
    /// every event reaches the tile owning its centroid: a volumes unit that reads the drafts of
    /// the tiles its own events reach (`events::write_near`) finds every event near them. Boxes
    /// turned and tilted at random, deep ones among them, inside the grid and beyond its edges.
    #[test]
    fn events_whose_boxes_overlap_reach_a_common_tile() {
        let params = Params::resolve(&crate::params::UserParams::default(), 0.15).unwrap();
        let grid = talus_tiling::TileGrid::new([100.0, 200.0], 12.5, 8, 6).unwrap();
        let mut rng = crate::rng::SplitMix64::new(11);
        let drafts: Vec<Draft> = (1..=400)
            .map(|id| {
                let c = [
                    rng.range(90.0, 210.0),
                    rng.range(190.0, 285.0),
                    rng.range(-5.0, 5.0),
                ];
                let (a, b) = (rng.range(0.0, 6.3), rng.range(0.0, 1.2));
                let (ca, sa, cb, sb) = (a.cos(), a.sin(), b.cos(), b.sin());
                let w = [sa * sb, -ca * sb, cb];
                let obb = Obb {
                    center: c,
                    axes: [[ca, sa, 0.0], [-sa * cb, ca * cb, sb], w],
                    half_extents: [
                        rng.range(0.0, 4.0),
                        rng.range(0.0, 2.0),
                        rng.range(0.0, 1.0),
                    ],
                };
                let event = Event {
                    id,
                    kind: crate::events::Kind::Gain,
                    n_points: 10,
                    centroid: c,
                    area_m2: 1.0,
                    mean_distance: 0.5,
                    max_abs_distance: rng.range(0.0, 8.0),
                    mean_lod95: 0.01,
                    obb,
                    mean_normal: w,
                };
                Draft {
                    event,
                    candidates: vec![obb],
                    beyond_reach: 0,
                    sign_unknown: 0,
                }
            })
            .collect();
        let reached: Vec<Vec<TileId>> = drafts
            .iter()
            .map(|d| reached_tiles(d, &params, &grid))
            .collect();
        let (mut pairs, mut spread) = (0, 0);
        for (i, d) in drafts.iter().enumerate() {
            let c = d.event.centroid;
            assert!(
                reached[i].contains(&grid.owner(c[0], c[1])),
                "event {}",
                i + 1
            );
            spread += usize::from(reached[i].len() > 1);
            let near = near_events(&drafts, &[d], &params);
            for (j, e) in drafts.iter().enumerate() {
                if j != i && near.contains(&e.event.id) {
                    pairs += 1;
                    assert!(
                        reached[i].iter().any(|t| reached[j].contains(t)),
                        "events {} and {}",
                        i + 1,
                        j + 1
                    );
                }
            }
        }
        // Not vacuous: many near pairs, many events over more than one tile.
        assert!(
            pairs > 1000 && spread > 100,
            "{pairs} near pairs, {spread} spread"
        );
    }

    /// Every point of a turned, tilted box lies in its plan box: a unit that skips the kept
    /// frames outside it loses none of an event's core points.
    #[test]
    fn the_plan_box_holds_every_point_of_the_oriented_box() {
        let (a, b) = (0.5f64, 0.3f64);
        let (ca, sa, cb, sb) = (a.cos(), a.sin(), b.cos(), b.sin());
        // Turned by a about z, then tilted by b about the first axis.
        let u = [ca, sa, 0.0];
        let v = [-sa * cb, ca * cb, sb];
        let w = [sa * sb, -ca * sb, cb];
        let o = Obb {
            center: [500_123.25, 4_999_876.5, 101.0],
            axes: [u, v, w],
            half_extents: [7.0, 2.5, 0.75],
        };
        let bx = plan_box(&o);
        let mut rng = crate::rng::SplitMix64::new(7);
        for _ in 0..10_000 {
            let l: [f64; 3] =
                std::array::from_fn(|k| rng.range(-o.half_extents[k], o.half_extents[k]));
            let g = o.to_global(&l);
            assert!(bx[0] <= g[0] && g[0] <= bx[2] && bx[1] <= g[1] && g[1] <= bx[3]);
        }
        // Each side of it touches a corner (within its padding): no larger than it must be.
        let corners: Vec<Point3> = (0..8)
            .map(|c| {
                o.to_global(&std::array::from_fn(|k| {
                    if c >> k & 1 == 1 {
                        o.half_extents[k]
                    } else {
                        -o.half_extents[k]
                    }
                }))
            })
            .collect();
        for (side, axis) in [(0, 0), (1, 1), (2, 0), (3, 1)] {
            let gap = corners
                .iter()
                .map(|c| (c[axis] - bx[side]).abs())
                .fold(f64::INFINITY, f64::min);
            assert!(gap < 1e-3, "side {side}: {gap}");
        }
    }
}

//! Event volumes (SPEC.md §1 "Volume" and "Volume accounting"; Gorup & Bohak §3.5, with the
//! fixes of SPEC.md §4): the volume between the before (C1) and after (C2) surfaces over the
//! event's region.
//!
//! Method, per event:
//! 1. Frame: the event's OBB axes (u, v, w), w = outward normal ([`frame`]).
//! 2. Footprint: the OBB's first two extents grown by `margin` on every side, so the rim of
//!    the change lies inside; the same rectangle R for both epochs.
//! 3. Surfaces: each epoch's points near the event, in (u, v, w), triangulated in (u, v)
//!    (2.5-D Delaunay TIN, [`surface`]); no height outside the data's hull.
//! 4. Region ([`region`]): the cells of R that both epochs cover (no hole, nothing beyond the
//!    data) and that no other event owns ([`ownership`]).
//! 5. Solids: each TIN clipped exactly to the region's cells, closed by walls down to one common
//!    base plane below both surfaces and a bottom: two watertight solids ([`solid`]).
//! 6. Volume of each solid by the divergence theorem; V = V(after) − V(before), positive for
//!    gain (the after surface lies further out along w). The base cancels in the difference.
//! 7. Gross gain and loss: ∫ max(Δw, 0) and ∫ min(Δw, 0) over the region, Δw = w_after −
//!    w_before, by the midpoint rule on sub-cells of about spacing/2. (Net V is exact for the
//!    TINs; gain + loss equals it up to the sampling of the steps.)
//!
//! Callers pass each epoch's points around the event: at least R grown by a few spacings in
//! (u, v) (extra points are ignored beyond 3 spacings), and along w far enough to hold both
//! surfaces (at least the M3C2 cylinder half-length, since a distance can reach it), and say
//! which locations the event owns. Everything here is a pure function of its inputs (Send +
//! Sync), for rayon.

pub mod axis;
pub mod boundary;
pub mod frame;
pub mod ownership;
pub mod region;
pub mod solid;
pub mod surface;
pub mod uncertainty;
pub mod user_mesh;

pub use frame::{Footprint, Frame};
pub use ownership::{Claim, Ownership};
pub use region::{Cells, OpenRim, Polygon, Region};
pub use solid::check_watertight;
pub use solid::Mesh;
pub use surface::{Surface, Tin};
pub use user_mesh::UserMesh;

use rayon::prelude::*;

use crate::error::{Error, Result};
use crate::events::Obb;

/// Which locations (global coordinates, on the before surface) an event may count.
pub type Owned<'a> = &'a (dyn Fn(&[f64; 3]) -> bool + Sync);

/// The volume of one event and its two solids.
#[derive(Debug, Clone, PartialEq)]
pub struct EventVolume {
    /// V(after) − V(before) over the region, m³ for metric input (loss < 0).
    pub volume_m3: f64,
    /// ∫ max(Δw, 0) over the region (≥ 0).
    pub gain_m3: f64,
    /// ∫ min(Δw, 0) over the region (≤ 0).
    pub loss_m3: f64,
    /// Area of the footprint rectangle.
    pub footprint_area_m2: f64,
    /// Area of the region the volume is integrated over.
    pub region_area_m2: f64,
    /// Share of the footprint both epochs cover (0..1).
    pub coverage: f64,
    /// The footprint in the event frame.
    pub footprint: Footprint,
    /// The region's cells.
    pub region: Region,
    /// The frame (origin, axes) the footprint is expressed in.
    pub frame: Frame,
    /// The common base plane, w = base_w in the frame.
    pub base_w: f64,
    /// Volumes of the two solids above the base.
    pub before_solid_m3: f64,
    pub after_solid_m3: f64,
    /// The two watertight solids, global coordinates, outward-facing.
    pub before_solid: Mesh,
    pub after_solid: Mesh,
    /// Points of each epoch used (inside the footprint grown by 3 spacings).
    pub n_before: usize,
    pub n_after: usize,
    /// Points of each epoch inside the region (0 for user meshes).
    pub region_points: [usize; 2],
    /// Where the region borders ground it could not measure, and how much changed there.
    pub open_rim: region::OpenRim,
    /// The variance of the volume from where the points sample its steps (m⁶,
    /// [`Region::step_variance`]).
    pub step_variance_m6: f64,
}

impl EventVolume {
    /// The region's outline in global coordinates: polygons (outer ring, holes) in the
    /// footprint plane (w = 0 of the frame), each ring closed (first vertex repeated).
    pub fn outline(&self) -> Vec<Vec<Vec<[f64; 3]>>> {
        let ring = |r: &[[f64; 2]]| -> Vec<[f64; 3]> {
            let mut g: Vec<[f64; 3]> = r
                .iter()
                .map(|p| self.frame.to_global(&[p[0], p[1], 0.0]))
                .collect();
            if let Some(&first) = g.first() {
                g.push(first);
            }
            g
        };
        self.region
            .outline()
            .iter()
            .map(|p| {
                std::iter::once(ring(&p.outer))
                    .chain(p.holes.iter().map(|h| ring(h)))
                    .collect()
            })
            .collect()
    }
}

fn check_params(obb: &Obb, margin: f64, spacing: f64) -> Result<()> {
    let finite = |v: &[f64]| v.iter().all(|x| x.is_finite());
    if !(finite(&obb.center) && finite(&obb.half_extents) && obb.axes.iter().all(|a| finite(a))) {
        return Err(Error::Internal(format!(
            "volume: non-finite event box {obb:?}"
        )));
    }
    if !(spacing.is_finite() && spacing > 0.0) {
        return Err(Error::Usage(format!(
            "volume: point spacing must be > 0, got {spacing}"
        )));
    }
    if !(margin.is_finite() && margin >= 0.0) {
        return Err(Error::Usage(format!(
            "volume: margin must be ≥ 0, got {margin}"
        )));
    }
    Ok(())
}

/// One epoch's (global) points in the event frame, over `r`: points beyond `r` grown by 3
/// spacings are dropped. The points may come in any order (a tiled run gathers them tile by
/// tile): they are sorted, because the triangulation of ties (points sharing u, v) depends on
/// the insertion order.
pub fn epoch_local(
    frame: &Frame,
    r: &Footprint,
    points: &[[f64; 3]],
    spacing: f64,
) -> Vec<[f64; 3]> {
    let keep = r.grown(3.0 * spacing);
    let mut local: Vec<[f64; 3]> = points
        .iter()
        .map(|p| frame.to_local(p))
        .filter(|l| l.iter().all(|x| x.is_finite()) && keep.contains(l[0], l[1]))
        .collect();
    local.sort_unstable_by(|a, b| {
        a[0].total_cmp(&b[0])
            .then(a[1].total_cmp(&b[1]))
            .then(a[2].total_cmp(&b[2]))
    });
    local
}

/// Both epochs' local points ([`epoch_local`]) without the unchanged walls
/// ([`axis::unchanged_walls`], the points gathered within |w| ≤ `window`), and their TINs.
pub fn epoch_tins(
    frame: &Frame,
    r: &Footprint,
    points: [&[[f64; 3]]; 2],
    spacing: f64,
    window: f64,
) -> Result<[(Tin, Vec<[f64; 3]>); 2]> {
    // Only the window's points: the gather may bring more (other candidate boxes), cut by
    // other faces.
    let local = points.map(|p| {
        let mut l = epoch_local(frame, r, p, spacing);
        l.retain(|q| q[2].abs() <= window);
        l
    });
    let gathered = r.grown(3.0 * spacing);
    let drop = axis::unchanged_walls([&local[0], &local[1]], spacing, &gathered, window);
    let mut out = Vec::with_capacity(2);
    for ((l, d), epoch) in local.into_iter().zip(&drop).zip(["before", "after"]) {
        let kept: Vec<[f64; 3]> = l
            .into_iter()
            .zip(d)
            .filter(|(_, &d)| !d)
            .map(|(p, _)| p)
            .collect();
        let tin = Tin::new(&kept)
            .map_err(|e| Error::Epochs(format!("{epoch} epoch around the event: {e}")))?;
        out.push((tin, kept));
    }
    let after = out.pop().expect("two epochs");
    let before = out.pop().expect("two epochs");
    Ok([before, after])
}

/// The region of footprint `r`: cells of about one `spacing` whose four corners both surfaces
/// cover (`surface_covers` at a node, per epoch), that pass `cell_covered` (e.g. a point of each
/// epoch near the centre), and whose location (the centre on the before surface, global) is
/// `owned`.
fn region_of(
    frame: &Frame,
    r: &Footprint,
    spacing: f64,
    before: &dyn Surface,
    after: &dyn Surface,
    cell_covered: &(dyn Fn([f64; 2]) -> bool + Sync),
    owned: Owned,
) -> Region {
    let cells = Cells::new(r, spacing);
    let (nu, nv) = (cells.nu, cells.nv);
    // Nodes covered by both surfaces, row by row in parallel.
    let nodes: Vec<bool> = (0..=nv)
        .into_par_iter()
        .flat_map_iter(|j| {
            (0..=nu).map(move |i| {
                let (u, v) = (cells.u(i), cells.v(j));
                before.height_at(u, v).is_some() && after.height_at(u, v).is_some()
            })
        })
        .collect();
    let node = |i: usize, j: usize| nodes[j * (nu + 1) + i];
    let flags: Vec<(bool, bool)> = (0..nv)
        .into_par_iter()
        .flat_map_iter(|j| {
            (0..nu).map(move |i| {
                let c = cells.centre(i, j);
                let covered = node(i, j)
                    && node(i + 1, j)
                    && node(i, j + 1)
                    && node(i + 1, j + 1)
                    && cell_covered(c);
                let own = covered
                    && before
                        .height_at(c[0], c[1])
                        .is_some_and(|w| owned(&frame.to_global(&[c[0], c[1], w])));
                (covered, own)
            })
        })
        .collect();
    let covered = flags.iter().map(|f| f.0).collect();
    let own: Vec<bool> = flags.iter().map(|f| f.1).collect();
    Region::new(cells, covered, &own)
}

/// Volume change of one event from the two epochs' points around it (global coordinates;
/// extra points are tolerated), `spacing` = point spacing of the clouds, over the part of the
/// footprint both epochs cover and the event owns.
pub fn event_volume(
    obb: &Obb,
    margin: f64,
    before: &[[f64; 3]],
    after: &[[f64; 3]],
    spacing: f64,
    owned: Owned,
) -> Result<EventVolume> {
    event_volume_in(obb, margin, f64::INFINITY, before, after, spacing, owned)
}

/// [`event_volume`] of points gathered within |w| ≤ `window` of the box's centre along its third
/// axis (the search box): the unchanged walls ([`axis::unchanged_walls`]) know where the window
/// cut them.
pub fn event_volume_in(
    obb: &Obb,
    margin: f64,
    window: f64,
    before: &[[f64; 3]],
    after: &[[f64; 3]],
    spacing: f64,
    owned: Owned,
) -> Result<EventVolume> {
    check_params(obb, margin, spacing)?;
    let frame = Frame::of_obb(obb);
    let r = Footprint::of_obb(obb, margin);
    let [(tin1, local1), (tin2, local2)] =
        epoch_tins(&frame, &r, [before, after], spacing, window)?;
    let radius = region::COVER_RADIUS * spacing;
    let uv =
        |l: &Vec<[f64; 3]>| region::PointCoverage::new(l.iter().map(|p| [p[0], p[1]]), &r, radius);
    let (cov1, cov2) = (uv(&local1), uv(&local2));
    let near_points =
        |c: [f64; 2]| cov1.covers(c[0], c[1], radius) && cov2.covers(c[0], c[1], radius);
    let region = region_of(&frame, &r, spacing, &tin1, &tin2, &near_points, owned);
    let inside = |l: &Vec<[f64; 3]>| {
        l.iter()
            .filter(|p| {
                region
                    .cells
                    .cell_of(p[0], p[1])
                    .is_some_and(|(i, j)| region.contains(i, j))
            })
            .count()
    };
    let counts = [inside(&local1), inside(&local2)];
    let (n1, n2) = (local1.len(), local2.len());
    // Counted, the event's own points are no longer needed (the triangulations hold theirs).
    drop((local1, local2));
    // What needs both triangulations first; then each top is clipped from its own, which is
    // given back as soon as it is: a large event's peak was both triangulations beside both
    // tops (≈ 2.2 KB per region cell on the cliff's debris fan).
    let change = change_of(&region, &tin1, &tin2, spacing);
    drop((cov1, cov2));
    let top = |tin: Tin| {
        let (v, f) = tin.mesh();
        drop(tin);
        solid::clipped_top(&v, &f, &region)
    };
    let top1 = top(tin1);
    let top2 = top(tin2);
    covered(&region, &top1, &top2)?;
    let mut v = finish(&frame, region, top1, top2, change, spacing, n1, n2);
    v.region_points = counts;
    Ok(v)
}

/// Volume change of one event between two arbitrary surfaces (e.g. the user's meshes,
/// [`UserMesh`]): the region is where both surfaces have a height and the event owns the
/// location; the tops are sampled on squares of half a cell (see [`solid::grid_top`]).
pub fn event_volume_from_surfaces(
    obb: &Obb,
    margin: f64,
    before: &dyn Surface,
    after: &dyn Surface,
    spacing: f64,
    owned: Owned,
) -> Result<EventVolume> {
    check_params(obb, margin, spacing)?;
    let frame = Frame::of_obb(obb);
    let r = Footprint::of_obb(obb, margin);
    let both = |c: [f64; 2]| {
        before.height_at(c[0], c[1]).is_some() && after.height_at(c[0], c[1]).is_some()
    };
    let region = region_of(&frame, &r, spacing, before, after, &both, owned);
    let none = || Error::Epochs("event footprint not covered by a surface".into());
    let top1 = solid::grid_top(before, &region, 2).ok_or_else(none)?;
    let top2 = solid::grid_top(after, &region, 2).ok_or_else(none)?;
    covered(&region, &top1, &top2)?;
    let change = change_of(&region, before, after, spacing);
    Ok(finish(&frame, region, top1, top2, change, spacing, 0, 0))
}

/// Refuse a region no part of which both epochs cover.
fn covered(region: &Region, top1: &Mesh, top2: &Mesh) -> Result<()> {
    if region.is_empty() || top1.faces.is_empty() || top2.faces.is_empty() {
        return Err(Error::Epochs(format!(
            "no part of the footprint is covered by both epochs and free of other events (coverage {:.0} %)",
            100.0 * region.coverage()
        )));
    }
    Ok(())
}

/// What the two surfaces say of the change over the region beyond the solids: where the
/// change reaches the region's rim, the variance of its steps, the gross gain and loss.
struct Change {
    open_rim: region::OpenRim,
    step_variance_m6: f64,
    gain: f64,
    loss: f64,
}

fn change_of(region: &Region, s1: &dyn Surface, s2: &dyn Surface, spacing: f64) -> Change {
    let change = |u: f64, v: f64| Some(s2.height_at(u, v)? - s1.height_at(u, v)?);
    let dw = region.cell_changes(&change);
    // Gross terms (reported, not part of V) by the midpoint rule on sub-cells of about
    // spacing/2 (a step is misplaced by at most half a sub-cell).
    let (gain, loss) = gross(s1, s2, region, spacing / 2.0);
    Change {
        open_rim: region.open_rim(&dw),
        step_variance_m6: region.step_variance(&dw, spacing),
        gain,
        loss,
    }
}

/// The event's volume from the tops clipped to the region (each closed into a solid over one
/// base plane) and the surfaces' `change`.
#[allow(clippy::too_many_arguments)]
fn finish(
    frame: &Frame,
    region: Region,
    top1: Mesh,
    top2: Mesh,
    change: Change,
    spacing: f64,
    n1: usize,
    n2: usize,
) -> EventVolume {
    let r = region.cells.r;
    // One base plane below both surfaces, one spacing lower still so no wall is flat.
    let base = solid::min_height(&top1).min(solid::min_height(&top2)) - spacing;
    let solid1 = solid::close(top1, base, &r);
    let solid2 = solid::close(top2, base, &r);
    let (v1, v2) = (solid::signed_volume(&solid1), solid::signed_volume(&solid2));
    let Change {
        open_rim,
        step_variance_m6,
        gain,
        loss,
    } = change;
    let to_global = |mut m: Mesh| {
        for v in &mut m.vertices {
            *v = frame.to_global(v);
        }
        m
    };
    EventVolume {
        volume_m3: v2 - v1,
        gain_m3: gain,
        loss_m3: loss,
        footprint_area_m2: r.area(),
        region_area_m2: region.area(),
        coverage: region.coverage(),
        footprint: r,
        region,
        frame: *frame,
        base_w: base,
        before_solid_m3: v1,
        after_solid_m3: v2,
        before_solid: to_global(solid1),
        after_solid: to_global(solid2),
        n_before: n1,
        n_after: n2,
        region_points: [0; 2],
        open_rim,
        step_variance_m6,
    }
}

/// Midpoint-rule gross gain and loss over the region's cells, each cut into sub-cells of at
/// most `sub` a side.
fn gross(s1: &dyn Surface, s2: &dyn Surface, region: &Region, sub: f64) -> (f64, f64) {
    let c = &region.cells;
    let du = (c.r.u1 - c.r.u0) / c.nu as f64;
    let dv = (c.r.v1 - c.r.v0) / c.nv as f64;
    let k = ((du.max(dv) / sub).ceil() as usize).clamp(1, 8);
    let w = c.cell_area() / (k * k) as f64;
    // Rows in parallel, then summed in row order: rayon's `reduce` would add the floats in an
    // order that depends on the thread count and on work stealing.
    let rows: Vec<(f64, f64)> = (0..c.nv)
        .into_par_iter()
        .map(|j| {
            let (mut g, mut l) = (0.0, 0.0);
            for i in 0..c.nu {
                if !region.contains(i, j) {
                    continue;
                }
                for b in 0..k {
                    let v = c.v(j) + dv * (b as f64 + 0.5) / k as f64;
                    for a in 0..k {
                        let u = c.u(i) + du * (a as f64 + 0.5) / k as f64;
                        if let (Some(h1), Some(h2)) = (s1.height_at(u, v), s2.height_at(u, v)) {
                            let d = h2 - h1;
                            if d > 0.0 {
                                g += d;
                            } else {
                                l += d;
                            }
                        }
                    }
                }
            }
            (g, l)
        })
        .collect();
    let (g, l) = rows.iter().fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    (g * w, l * w)
}

//! Event volumes (SPEC.md §1 "Volume"; Gorup & Bohak §3.5, with the fixes of SPEC.md §4):
//! the volume between the before (C1) and after (C2) surfaces over the event's footprint.
//!
//! Method, per event:
//! 1. Frame: the event's OBB axes (u, v, w), w = outward normal ([`frame`]).
//! 2. Footprint: the OBB's first two extents grown by `margin` on every side, so the rim of
//!    the change lies inside; the same rectangle R for both epochs.
//! 3. Surfaces: each epoch's points near the event, in (u, v, w), triangulated in (u, v)
//!    (2.5-D Delaunay TIN, [`surface`]); outside the data's hull, the nearest vertex's height.
//! 4. Solids: each TIN clipped exactly to R, closed by walls down to one common base plane
//!    below both surfaces and a bottom: two watertight solids ([`solid`]).
//! 5. Volume of each solid by the divergence theorem; V = V(after) − V(before), positive for
//!    gain (the after surface lies further out along w). The base cancels in the difference.
//! 6. Gross gain and loss: ∫ max(Δw, 0) and ∫ min(Δw, 0) over R, Δw = w_after − w_before,
//!    by the midpoint rule on cells of spacing/2 (at most 1 M cells). (Net V is exact for the
//!    TINs; gain + loss equals it up to the sampling of the steps.)
//!
//! Uncertainty ([`EventVolume::uncertainty_m3`]): the conservative bound footprint area ×
//! mean LoD95 of the event, i.e. every square metre compared could be off by the level of
//! detection, all errors of the same sign (the registration error part of LoD95 is indeed
//! fully correlated over an event).
//!
//! Callers pass each epoch's points around the event: at least R grown by a few spacings in
//! (u, v) (extra points are ignored beyond 3 spacings), and along w far enough to hold both
//! surfaces (at least the M3C2 cylinder half-length, since a distance can reach it).
//! Everything here is a pure function of its inputs (Send + Sync), for rayon.

pub mod frame;
pub mod mesh_ply;
pub mod solid;
pub mod surface;
pub mod user_mesh;

pub use frame::{Footprint, Frame};
pub use mesh_ply::{check_watertight, read_ply_mesh, write_ply};
pub use solid::Mesh;
pub use surface::{Surface, Tin};
pub use user_mesh::UserMesh;

use crate::error::{Error, Result};
use crate::events::Obb;

/// The volume of one event and its two solids.
#[derive(Debug, Clone, PartialEq)]
pub struct EventVolume {
    /// V(after) − V(before), m³ for metric input (loss < 0).
    pub volume_m3: f64,
    /// ∫ max(Δw, 0) over the footprint (≥ 0).
    pub gain_m3: f64,
    /// ∫ min(Δw, 0) over the footprint (≤ 0).
    pub loss_m3: f64,
    /// Area of the footprint rectangle.
    pub footprint_area_m2: f64,
    /// The footprint in the event frame.
    pub footprint: Footprint,
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
}

impl EventVolume {
    /// Conservative volume uncertainty: footprint area × the event's mean LoD95.
    pub fn uncertainty_m3(&self, mean_lod95: f64) -> f64 {
        self.footprint_area_m2 * mean_lod95
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

/// The TIN of one epoch's (global) points in the event frame, covering `r`: points beyond
/// `r` grown by 3 spacings are dropped. Returns the TIN and the number of points used. The
/// points may come in any order (a tiled run gathers them tile by tile): they are sorted first,
/// because the triangulation of ties (points sharing u, v) depends on the insertion order.
pub fn epoch_tin(
    frame: &Frame,
    r: &Footprint,
    points: &[[f64; 3]],
    spacing: f64,
    epoch: &str,
) -> Result<(Tin, usize)> {
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
    let n = local.len();
    let mut tin = Tin::new(&local)
        .map_err(|e| Error::Epochs(format!("{epoch} epoch around the event: {e}")))?;
    tin.cover(&r.grown(2.0 * spacing), spacing);
    Ok((tin, n))
}

/// Volume change of one event from the two epochs' points around it (global coordinates;
/// extra points are tolerated), `spacing` = point spacing of the clouds.
pub fn event_volume(
    obb: &Obb,
    margin: f64,
    before: &[[f64; 3]],
    after: &[[f64; 3]],
    spacing: f64,
) -> Result<EventVolume> {
    check_params(obb, margin, spacing)?;
    let frame = Frame::of_obb(obb);
    let r = Footprint::of_obb(obb, margin);
    let (tin1, n1) = epoch_tin(&frame, &r, before, spacing, "before")?;
    let (tin2, n2) = epoch_tin(&frame, &r, after, spacing, "after")?;
    let top = |tin: &Tin| {
        let (v, f) = tin.mesh();
        solid::clipped_top(&v, &f, &r)
    };
    let (top1, top2) = (top(&tin1), top(&tin2));
    if top1.faces.is_empty() || top2.faces.is_empty() {
        return Err(Error::Epochs(
            "event footprint not covered by a surface".into(),
        ));
    }
    finish(&frame, &r, top1, top2, &tin1, &tin2, spacing, n1, n2)
}

/// Volume change of one event between two arbitrary surfaces (e.g. the user's meshes,
/// [`UserMesh`], or a [`Tin`] from [`epoch_tin`]) sampled on a grid of cells ≤ spacing/2 over
/// the footprint, node heights averaged over their cells (see [`solid::grid_top`]).
pub fn event_volume_from_surfaces(
    obb: &Obb,
    margin: f64,
    before: &dyn Surface,
    after: &dyn Surface,
    spacing: f64,
) -> Result<EventVolume> {
    check_params(obb, margin, spacing)?;
    let frame = Frame::of_obb(obb);
    let r = Footprint::of_obb(obb, margin);
    // The grid samples SUB² = 16 heights per node: cap at 1 M nodes.
    let cell = (0.5 * spacing).max((r.area() / 1.0e6).sqrt());
    let none = || Error::Epochs("event footprint not covered by a surface".into());
    let top1 = solid::grid_top(before, &r, cell).ok_or_else(none)?;
    let top2 = solid::grid_top(after, &r, cell).ok_or_else(none)?;
    finish(&frame, &r, top1, top2, before, after, spacing, 0, 0)
}

#[allow(clippy::too_many_arguments)]
fn finish(
    frame: &Frame,
    r: &Footprint,
    top1: Mesh,
    top2: Mesh,
    s1: &dyn Surface,
    s2: &dyn Surface,
    spacing: f64,
    n1: usize,
    n2: usize,
) -> Result<EventVolume> {
    // One base plane below both surfaces, one spacing lower still so no wall is flat.
    let base = solid::min_height(&top1).min(solid::min_height(&top2)) - spacing;
    let solid1 = solid::close(&top1, base, r);
    let solid2 = solid::close(&top2, base, r);
    let (v1, v2) = (solid::signed_volume(&solid1), solid::signed_volume(&solid2));
    // Gross terms (reported, not part of V) by the midpoint rule on cells of spacing/2 (a step
    // is misplaced by at most half a cell), at most 1 M cells: finer cells cost more than the
    // whole M3C2 pass on events of tens of m².
    let (gain, loss) = gross(s1, s2, r, (spacing / 2.0).max((r.area() / 1.0e6).sqrt()));
    let to_global = |m: Mesh| Mesh {
        vertices: m.vertices.iter().map(|l| frame.to_global(l)).collect(),
        faces: m.faces,
    };
    Ok(EventVolume {
        volume_m3: v2 - v1,
        gain_m3: gain,
        loss_m3: loss,
        footprint_area_m2: r.area(),
        footprint: *r,
        frame: *frame,
        base_w: base,
        before_solid_m3: v1,
        after_solid_m3: v2,
        before_solid: to_global(solid1),
        after_solid: to_global(solid2),
        n_before: n1,
        n_after: n2,
    })
}

/// Midpoint-rule gross gain and loss over `r`.
fn gross(s1: &dyn Surface, s2: &dyn Surface, r: &Footprint, cell: f64) -> (f64, f64) {
    use rayon::prelude::*;
    let nu = (((r.u1 - r.u0) / cell).ceil() as usize).max(1);
    let nv = (((r.v1 - r.v0) / cell).ceil() as usize).max(1);
    let (du, dv) = ((r.u1 - r.u0) / nu as f64, (r.v1 - r.v0) / nv as f64);
    // Rows in parallel, then summed in row order: rayon's `reduce` would add the floats in an
    // order that depends on the thread count and on work stealing.
    let rows: Vec<(f64, f64)> = (0..nv)
        .into_par_iter()
        .map(|j| {
            let v = r.v0 + (j as f64 + 0.5) * dv;
            let (mut g, mut l) = (0.0, 0.0);
            for i in 0..nu {
                let u = r.u0 + (i as f64 + 0.5) * du;
                if let (Some(a), Some(b)) = (s1.height_at(u, v), s2.height_at(u, v)) {
                    let d = b - a;
                    if d > 0.0 {
                        g += d;
                    } else {
                        l += d;
                    }
                }
            }
            (g, l)
        })
        .collect();
    let (g, l) = rows.iter().fold((0.0, 0.0), |a, b| (a.0 + b.0, a.1 + b.1));
    (g * du * dv, l * du * dv)
}

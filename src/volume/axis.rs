//! The axis an event's volume is extruded along.
//!
//! A volume between two surfaces over a region is defined along an axis in which both surfaces
//! are height fields there; where the change vanishes at the region's rim, any such axis gives the
//! same volume. Two candidates: the cluster's mean M3C2 normal (the direction its distances were
//! measured along: the only one on a cliff face or under an overhang) and straight up (every
//! gentle surface is a height field along z, a DSM by construction). Neither is always right:
//! - the mean normal of a cluster on the flank of a dune or a boulder is tilted by 50° and more;
//!   in that frame the footprint's far side (the other flank, seen from behind) folds over;
//! - a debris fan against a cliff foot has the vertical face inside its footprint; along z the
//!   face is a wall of points stacked in one column, and the triangulation ramps from the beach
//!   to random heights on it.
//!
//! Both failures show in the points as the same thing: two points almost on top of each other in
//! the frame's (u, v) but far apart along w, i.e. a part of the surface seen edge-on or from
//! behind. [`wall_points`] counts such points in a candidate frame; the volume takes the
//! candidate with fewer of them (the mean normal on a tie).

use super::frame::{Footprint, Frame};
use crate::spatial::Index;

/// A pair of points whose w differs by more than this many times their (u, v) distance, plus one
/// point spacing (so that noise on a flat surface never counts), lies on a part steeper than
/// 75° in the frame (tan 75° ≈ 3.73).
pub(crate) const WALL_SLOPE: f64 = 3.73;

/// How many of `points` (global) within `r` grown by one spacing and within `depth` of the
/// frame's (u, v) plane lie on a wall (see [`wall_flags`]).
pub(crate) fn wall_points(
    frame: &Frame,
    r: &Footprint,
    depth: f64,
    points: &[[f64; 3]],
    spacing: f64,
) -> usize {
    let g = r.grown(spacing);
    let local: Vec<[f64; 3]> = points
        .iter()
        .map(|p| frame.to_local(p))
        .filter(|l| g.contains(l[0], l[1]) && l[2].abs() <= depth)
        .collect();
    wall_flags(&local, spacing).iter().filter(|&&w| w).count()
}

/// Per local point (u, v, w): does another point lie within one `spacing` in (u, v) with a w
/// difference beyond [`WALL_SLOPE`] × their distance + `spacing`?
pub(crate) fn wall_flags(local: &[[f64; 3]], spacing: f64) -> Vec<bool> {
    if local.is_empty() || spacing.is_nan() || spacing <= 0.0 {
        return vec![false; local.len()];
    }
    let rho = spacing;
    let (mut u0, mut v0, mut u1, mut v1) = (
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    );
    for l in local {
        u0 = u0.min(l[0]);
        v0 = v0.min(l[1]);
        u1 = u1.max(l[0]);
        v1 = v1.max(l[1]);
    }
    let nx = (((u1 - u0) / rho).ceil() as usize).clamp(1, 1 << 15);
    let ny = (((v1 - v0) / rho).ceil() as usize).clamp(1, 1 << 15);
    let bucket = |l: &[f64; 3]| {
        let bx = (((l[0] - u0) / rho) as usize).min(nx - 1);
        let by = (((l[1] - v0) / rho) as usize).min(ny - 1);
        (bx, by)
    };
    // Counting sort of the point indices into buckets.
    let mut start = vec![0u32; nx * ny + 1];
    for l in local {
        let (bx, by) = bucket(l);
        start[by * nx + bx + 1] += 1;
    }
    for b in 0..nx * ny {
        start[b + 1] += start[b];
    }
    let mut fill = start.clone();
    let mut sorted = vec![0u32; local.len()];
    for (i, l) in local.iter().enumerate() {
        let (bx, by) = bucket(l);
        let b = by * nx + bx;
        sorted[fill[b] as usize] = i as u32;
        fill[b] += 1;
    }
    local
        .iter()
        .map(|p| {
            let (bx, by) = bucket(p);
            for y in by.saturating_sub(1)..=(by + 1).min(ny - 1) {
                for x in bx.saturating_sub(1)..=(bx + 1).min(nx - 1) {
                    let b = y * nx + x;
                    for &j in &sorted[start[b] as usize..start[b + 1] as usize] {
                        let q = &local[j as usize];
                        let (du, dv) = (q[0] - p[0], q[1] - p[1]);
                        let d2 = du * du + dv * dv;
                        if d2 <= rho * rho && (q[2] - p[2]).abs() > WALL_SLOPE * d2.sqrt() + spacing
                        {
                            return true;
                        }
                    }
                }
            }
            false
        })
        .collect()
}

/// How close (in spacings, 3-D) a point of the other survey must lie for a wall point to count
/// as unchanged: the two surveys sample the same unchanged surface at about one spacing apart,
/// so their nearest points are within a spacing or two; a change smaller than this is below
/// what the surveys resolve there anyway.
pub(crate) const UNCHANGED_WALL_SPACINGS: f64 = 2.0;

/// Per local point of each epoch: is it on a wall both epochs hold unchanged? A point is on a
/// wall in the frame ([`wall_flags`] within its own epoch); such a point is *matched* when the
/// nearest point of the other epoch lies within [`UNCHANGED_WALL_SPACINGS`] spacings (it did not
/// move); and a wall point is left out when every wall point of either epoch within one spacing
/// of it in (u, v) — its column — is matched.
///
/// Such points carry no volume (the surface there did not move), but a height field cannot hold
/// them: the triangulation ramps between points stacked along w at heights that depend on where
/// each survey happened to sample the wall, so an unchanged face at the rim of a beach deposit
/// (or a plateau edge above a face scar) adds a random volume of up to its height × a cell per
/// cell. A wall that changed anywhere in its column keeps all its points in both epochs: a fresh
/// scar's sides (the other epoch is a height field there), a block grown taller (its old lower
/// wall is matched, its new upper part is not: dropping only the lower part would triangulate
/// the two epochs' edges differently), a deposit against a face (the face's buried foot).
///
/// The points are those of a box: `gathered` in (u, v) and |w| ≤ `window` (the search box;
/// `f64::INFINITY` when unknown). Near its faces a point's counterpart may lie just outside, so a
/// wall point within reach of a face counts as matched (the box reaches past the event's
/// footprint and deepest change: nothing there moved).
pub(crate) fn unchanged_walls(
    local: [&[[f64; 3]]; 2],
    spacing: f64,
    gathered: &Footprint,
    window: f64,
) -> [Vec<bool>; 2] {
    let walls = local.map(|l| wall_flags(l, spacing));
    let mut out = [vec![false; local[0].len()], vec![false; local[1].len()]];
    if !walls.iter().all(|w| w.contains(&true)) {
        return out;
    }
    let reach = UNCHANGED_WALL_SPACINGS * spacing;
    // Near the gathered box's faces a point's counterpart may lie just outside it.
    let at_edge = |p: &[f64; 3]| {
        p[0] - gathered.u0 <= reach
            || gathered.u1 - p[0] <= reach
            || p[1] - gathered.v0 <= reach
            || gathered.v1 - p[1] <= reach
            || p[2].abs() >= window - reach
    };
    // Every wall point of both epochs: (u, v, matched, epoch, index).
    let mut wall: Vec<([f64; 2], bool, usize, usize)> = Vec::new();
    for e in 0..2 {
        let other = Index::new(local[1 - e], [0.0; 3]);
        for (i, p) in local[e].iter().enumerate() {
            if walls[e][i] {
                let matched = at_edge(p)
                    || other
                        .nearest_one(p)
                        .is_some_and(|(_, d2)| d2 <= reach * reach);
                wall.push(([p[0], p[1]], matched, e, i));
            }
        }
    }
    // Columns: the wall points within one spacing in (u, v), through a bucket grid.
    let (mut u0, mut v0) = (f64::INFINITY, f64::INFINITY);
    for (q, ..) in &wall {
        u0 = u0.min(q[0]);
        v0 = v0.min(q[1]);
    }
    let cell = |q: &[f64; 2]| {
        (
            ((q[0] - u0) / spacing).floor() as i64,
            ((q[1] - v0) / spacing).floor() as i64,
        )
    };
    let mut buckets: std::collections::HashMap<(i64, i64), Vec<usize>> =
        std::collections::HashMap::new();
    for (k, (q, ..)) in wall.iter().enumerate() {
        buckets.entry(cell(q)).or_default().push(k);
    }
    for (q, matched, e, i) in &wall {
        if !matched {
            continue;
        }
        let (cu, cv) = cell(q);
        let mut whole = true;
        'scan: for du in -1..=1 {
            for dv in -1..=1 {
                for &k in buckets.get(&(cu + du, cv + dv)).map_or(&[][..], |v| v) {
                    let (r, ok, ..) = &wall[k];
                    let (du, dv) = (r[0] - q[0], r[1] - q[1]);
                    if !ok && du * du + dv * dv <= spacing * spacing {
                        whole = false;
                        break 'scan;
                    }
                }
            }
        }
        out[*e][*i] = whole;
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn frame(axes: [[f64; 3]; 3]) -> Frame {
        Frame {
            origin: [0.0; 3],
            axes,
        }
    }

    const UP: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]];
    /// w = −y: looking at a face in the plane y = 0 from y < 0.
    const FACE: [[f64; 3]; 3] = [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]];

    #[test]
    fn a_vertical_face_is_a_wall_along_z_and_a_height_field_across() {
        let mut pts = Vec::new();
        for i in 0..40 {
            for k in 0..30 {
                // Face y = 0 (tiny jitter), x ∈ [0, 4], z ∈ [0, 3].
                let jitter = 0.003 * (((i * 7 + k * 13) % 11) as f64 / 11.0 - 0.5);
                pts.push([i as f64 * 0.1, jitter, k as f64 * 0.1]);
            }
        }
        let r = Footprint {
            u0: 0.0,
            u1: 4.0,
            v0: -1.0,
            v1: 4.0,
        };
        let along_z = wall_points(&frame(UP), &r, 10.0, &pts, 0.1);
        let across = wall_points(&frame(FACE), &r, 10.0, &pts, 0.1);
        assert_eq!(across, 0);
        assert!(along_z > pts.len() / 2, "{along_z} of {}", pts.len());
    }

    /// A beach (z = 0) in front of a face (the plane y = 0, z up to 3 m), seen along z: both
    /// epochs hold the face, so its points are unchanged walls in both; a box pit dug in the
    /// after epoch's beach has sides only that epoch holds, which stay.
    #[test]
    fn a_face_both_epochs_hold_is_dropped_and_a_new_pits_sides_are_kept() {
        let s = 0.1;
        let beach = |shift: f64, pit: bool| {
            let mut pts = Vec::new();
            for i in 0..40 {
                for j in 0..20 {
                    let (x, y) = (i as f64 * s + shift, -2.0 + j as f64 * s + shift);
                    let inside = pit && (1.0..2.0).contains(&x) && (-1.5..-0.8).contains(&y);
                    pts.push([x, y, if inside { -0.5 } else { 0.0 }]);
                }
                for k in 1..30 {
                    pts.push([i as f64 * s + shift, 0.0, k as f64 * s + shift]);
                }
            }
            if pit {
                // The pit's sides: x = 1 and x = 2 over its y span, 0.5 m deep.
                for x in [1.0, 2.0] {
                    for j in 0..7 {
                        for k in 1..5 {
                            pts.push([x, -1.5 + j as f64 * s, -0.1 * k as f64]);
                        }
                    }
                }
            }
            pts
        };
        let before = beach(0.0, false);
        let after = beach(0.03, true);
        let all = Footprint {
            u0: f64::NEG_INFINITY,
            u1: f64::INFINITY,
            v0: f64::NEG_INFINITY,
            v1: f64::INFINITY,
        };
        let [d1, d2] = unchanged_walls([&before, &after], s, &all, f64::INFINITY);
        let face = |p: &[f64; 3]| p[1] == 0.0 && p[2] > 0.5;
        for (pts, drop) in [(&before, &d1), (&after, &d2)] {
            let (n, gone) = pts
                .iter()
                .zip(drop)
                .filter(|(p, _)| face(p))
                .fold((0, 0), |(n, g), (_, &d)| (n + 1, g + d as usize));
            assert_eq!(
                gone, n,
                "every face point above the foot is an unchanged wall"
            );
        }
        let sides = after
            .iter()
            .zip(&d2)
            .filter(|(p, _)| p[1] < -0.5 && p[2] < -0.05 && p[2] > -0.45)
            .collect::<Vec<_>>();
        assert!(!sides.is_empty());
        assert!(sides.iter().all(|(_, &d)| !d), "the pit's sides are kept");
    }

    #[test]
    fn a_noisy_slope_of_60_degrees_is_a_height_field() {
        let mut pts = Vec::new();
        let slope = 60f64.to_radians().tan();
        for i in 0..30 {
            for j in 0..30 {
                let (x, y) = (i as f64 * 0.1, j as f64 * 0.1);
                let noise = 0.01 * ((((i * 31 + j * 17) % 13) as f64) / 13.0 - 0.5);
                pts.push([x, y, slope * x + noise]);
            }
        }
        let r = Footprint {
            u0: 0.0,
            u1: 3.0,
            v0: 0.0,
            v1: 3.0,
        };
        assert_eq!(wall_points(&frame(UP), &r, 100.0, &pts, 0.1), 0);
    }
}

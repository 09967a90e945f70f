//! Which event a location belongs to, so that no location is counted by two events (SPEC.md §1
//! "Volume accounting": regions without overlap).
//!
//! Each event claims the box its volume looks into: its grown footprint R in its own frame, and
//! along the frame's third axis as deep as the surfaces can lie (the box's depth plus the M3C2
//! cylinder's half-length, since a distance can reach it). A location inside several boxes
//! belongs to the event with the nearest clustered core point (3-D distance, so it works for a
//! cliff face and the beach below it alike; ties to the smaller id): the boxes are split along the
//! bisectors between the events' core points, a Voronoi partition restricted to the boxes. The rule
//! is a function of the location alone, whatever event asks, so each event's region excludes
//! exactly what the others include.

use super::frame::{Footprint, Frame};
use crate::geom::Point3;
use crate::spatial::{BoxIndex, Index};

/// One event's claim.
pub(crate) struct Claim {
    pub(crate) id: u32,
    pub(crate) frame: Frame,
    /// The grown footprint, in `frame`.
    pub(crate) footprint: Footprint,
    /// Half-depth of the box along the frame's w axis.
    pub(crate) depth: f64,
    cores: Index,
}

impl Claim {
    /// The claim of event `id` with its clustered core points (global coordinates).
    pub(crate) fn new(
        id: u32,
        frame: Frame,
        footprint: Footprint,
        depth: f64,
        cores: &[Point3],
    ) -> Self {
        Claim {
            id,
            frame,
            footprint,
            depth,
            cores: Index::new(cores, frame.origin),
        }
    }

    /// Is the global location `x` inside the claimed box?
    pub(crate) fn contains(&self, x: &Point3) -> bool {
        let l = self.frame.to_local(x);
        self.footprint.contains(l[0], l[1]) && l[2].abs() <= self.depth
    }

    /// The squared distance from `x` to the nearest of the event's core points.
    fn distance2(&self, x: &Point3) -> f64 {
        self.cores
            .nearest_one(&self.cores.to_local(x))
            .map_or(f64::INFINITY, |(_, d2)| d2)
    }

    /// The box's bounds in x and y: [x0, y0, x1, y1].
    pub(crate) fn bounds_xy(&self) -> [f64; 4] {
        let (r, h) = (&self.footprint, self.depth);
        self.frame.bounds_xy([r.u0, r.v0, -h], [r.u1, r.v1, h])
    }
}

/// The claims of all events, with a coarse xy grid to find the boxes a location may be in.
pub(crate) struct Ownership {
    claims: Vec<Claim>,
    boxes: BoxIndex,
}

impl Ownership {
    pub(crate) fn new(claims: Vec<Claim>) -> Self {
        let boxes: Vec<[f64; 4]> = claims.iter().map(Claim::bounds_xy).collect();
        Ownership {
            boxes: BoxIndex::new(&boxes),
            claims,
        }
    }

    /// The id of the event that owns `x`: of the events whose box contains it, the one with the
    /// nearest core point (ties: the smaller id). None when no box contains it.
    pub(crate) fn owner(&self, x: &Point3) -> Option<u32> {
        self.boxes
            .containing(x[0], x[1])
            .filter(|&k| self.claims[k].contains(x))
            .map(|k| (self.claims[k].distance2(x), self.claims[k].id))
            .min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)))
            .map(|(_, id)| id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat_claim(id: u32, cx: f64, half: f64, cores: &[Point3]) -> Claim {
        let frame = Frame {
            origin: [cx, 0.0, 0.0],
            axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
        };
        let r = Footprint {
            u0: -half,
            u1: half,
            v0: -half,
            v1: half,
        };
        Claim::new(id, frame, r, 1.0, cores)
    }

    #[test]
    fn overlapping_boxes_split_at_the_bisector() {
        // Events 1 (cores at x ≤ 1) and 2 (cores at x ≥ 3); boxes overlap on 0 ≤ x ≤ 4.
        let a = flat_claim(1, 0.0, 4.0, &[[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]]);
        let b = flat_claim(2, 4.0, 4.0, &[[3.0, 0.0, 0.0], [4.0, 0.0, 0.0]]);
        let own = Ownership::new(vec![a, b]);
        assert_eq!(own.owner(&[1.9, 0.5, 0.0]), Some(1));
        assert_eq!(own.owner(&[2.1, 0.5, 0.0]), Some(2));
        // Outside 2's box, nearer to 2's cores than to 1's does not matter: 1 owns it.
        assert_eq!(own.owner(&[-3.9, 3.9, 0.0]), Some(1));
        assert_eq!(own.owner(&[7.9, 0.0, 0.0]), Some(2));
        // Outside every box, and above the boxes' depth.
        assert_eq!(own.owner(&[9.0, 0.0, 0.0]), None);
        assert_eq!(own.owner(&[1.0, 0.0, 1.5]), None);
        // A tie goes to the smaller id.
        assert_eq!(own.owner(&[2.0, 0.0, 0.0]), Some(1));
    }
}

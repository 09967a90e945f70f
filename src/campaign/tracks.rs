//! Tracks: events of different pairs at the same place (SPEC.md §5) — a scar that grows again, a
//! fan that keeps building. Two events are at the same place when they are of one kind and their
//! regions overlap: the centroid or a vertex of one region's outline lies inside the other's
//! region, judged in that event's own frame (its footprint plane, within its depth: so a scar on
//! a cliff face and a deposit below it are never taken for one place). Tracks are the connected
//! groups of such links, numbered from 1 in the order of their first event (by pair, then id).

use crate::events::Obb;
use crate::geom::Point3;
use crate::volume::boundary;

/// An event as tracking sees it.
#[derive(Debug, Clone)]
pub(crate) struct Placed {
    pub pair: usize,
    pub id: u32,
    pub gain: bool,
    pub centroid: Point3,
    pub obb: Obb,
    /// The region's outline: polygons → rings (outer first, then holes) of global points in the
    /// footprint plane.
    pub region: Vec<Vec<Vec<Point3>>>,
    /// How far from the footprint plane a point may lie and still be in the region.
    pub depth: f64,
}

impl Placed {
    /// The region's polygons in the event's frame (u, v).
    fn rings_uv(&self) -> Vec<Vec<Vec<[f64; 2]>>> {
        self.region
            .iter()
            .map(|poly| {
                poly.iter()
                    .map(|ring| {
                        ring.iter()
                            .map(|p| {
                                let l = self.obb.to_local(p);
                                [l[0], l[1]]
                            })
                            .collect()
                    })
                    .collect()
            })
            .collect()
    }

    /// Is the global point `p` in the region?
    fn contains(&self, rings: &[Vec<Vec<[f64; 2]>>], p: &Point3) -> bool {
        let l = self.obb.to_local(p);
        if l[2].abs() > self.depth {
            return false;
        }
        rings.iter().any(|poly| {
            poly.first()
                .is_some_and(|outer| boundary::contains(outer, [l[0], l[1]]))
                && !poly[1..]
                    .iter()
                    .any(|h| boundary::contains(h, [l[0], l[1]]))
        })
    }
}

/// Do `a` and `b` lie at the same place? (`ra`, `rb`: their rings in their own frames.)
fn overlap(a: &Placed, ra: &[Vec<Vec<[f64; 2]>>], b: &Placed, rb: &[Vec<Vec<[f64; 2]>>]) -> bool {
    let vertices =
        |e: &Placed| -> Vec<Point3> { e.region.iter().flatten().flatten().copied().collect() };
    a.contains(ra, &b.centroid)
        || b.contains(rb, &a.centroid)
        || vertices(b).iter().any(|p| a.contains(ra, p))
        || vertices(a).iter().any(|p| b.contains(rb, p))
}

/// The track id of each event (same order as `events`), from 1.
pub(crate) fn tracks(events: &[Placed]) -> Vec<u32> {
    let n = events.len();
    let rings: Vec<_> = events.iter().map(Placed::rings_uv).collect();
    // Bounding spheres for a cheap first test.
    let sphere = |e: &Placed| -> (Point3, f64) {
        let r = e
            .region
            .iter()
            .flatten()
            .flatten()
            .map(|p| {
                ((p[0] - e.centroid[0]).powi(2)
                    + (p[1] - e.centroid[1]).powi(2)
                    + (p[2] - e.centroid[2]).powi(2))
                .sqrt()
            })
            .fold(0.0, f64::max);
        (e.centroid, r + e.depth)
    };
    let spheres: Vec<_> = events.iter().map(sphere).collect();
    let mut parent: Vec<usize> = (0..n).collect();
    fn find(p: &mut [usize], i: usize) -> usize {
        let mut r = i;
        while p[r] != r {
            r = p[r];
        }
        let mut i = i;
        while p[i] != r {
            let next = p[i];
            p[i] = r;
            i = next;
        }
        r
    }
    for i in 0..n {
        for j in i + 1..n {
            let (a, b) = (&events[i], &events[j]);
            if a.pair == b.pair || a.gain != b.gain {
                continue;
            }
            let (ca, ra) = spheres[i];
            let (cb, rb) = spheres[j];
            let d = ((ca[0] - cb[0]).powi(2) + (ca[1] - cb[1]).powi(2) + (ca[2] - cb[2]).powi(2))
                .sqrt();
            if d > ra + rb {
                continue;
            }
            if overlap(a, &rings[i], b, &rings[j]) {
                let (x, y) = (find(&mut parent, i), find(&mut parent, j));
                if x != y {
                    parent[x.max(y)] = x.min(y);
                }
            }
        }
    }
    // Number the groups in the order of their first event by (pair, id).
    let mut order: Vec<usize> = (0..n).collect();
    order.sort_by_key(|&i| (events[i].pair, events[i].id));
    let mut number = vec![0u32; n];
    let mut next = 0;
    let mut out = vec![0u32; n];
    for &i in &order {
        let root = find(&mut parent, i);
        if number[root] == 0 {
            next += 1;
            number[root] = next;
        }
        out[i] = number[root];
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;

    fn flat(pair: usize, id: u32, gain: bool, c: [f64; 2], half: f64) -> Placed {
        let obb = Obb {
            center: [c[0], c[1], 0.0],
            axes: [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]],
            half_extents: [half, half, 0.1],
        };
        let ring = vec![
            [c[0] - half, c[1] - half, 0.0],
            [c[0] + half, c[1] - half, 0.0],
            [c[0] + half, c[1] + half, 0.0],
            [c[0] - half, c[1] + half, 0.0],
            [c[0] - half, c[1] - half, 0.0],
        ];
        Placed {
            pair,
            id,
            gain,
            centroid: [c[0], c[1], 0.0],
            obb,
            region: vec![vec![ring]],
            depth: 1.0,
        }
    }

    #[test]
    fn overlapping_events_of_one_kind_share_a_track() {
        let events = vec![
            flat(0, 1, false, [0.0, 0.0], 2.0),
            flat(0, 2, true, [10.0, 0.0], 2.0),
            flat(1, 1, false, [20.0, 0.0], 2.0),
            // The scar at (0, 0) again, larger: pair 2.
            flat(2, 1, false, [1.0, 0.5], 3.0),
            // A gain where the scar was: another kind, another track.
            flat(2, 2, true, [0.0, 0.0], 1.0),
        ];
        let t = tracks(&events);
        assert_eq!(t, vec![1, 2, 3, 1, 4]);
    }

    #[test]
    fn a_face_scar_and_a_deposit_below_it_are_not_one_place() {
        let scar = Placed {
            pair: 0,
            id: 1,
            gain: true,
            centroid: [0.0, 0.0, 5.0],
            obb: Obb {
                center: [0.0, 0.0, 5.0],
                // Frame of a face in the plane y = 0: u = x, v = z, w = −y.
                axes: [[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]],
                half_extents: [2.0, 2.0, 0.1],
            },
            region: vec![vec![vec![
                [-2.0, 0.0, 3.0],
                [2.0, 0.0, 3.0],
                [2.0, 0.0, 7.0],
                [-2.0, 0.0, 7.0],
                [-2.0, 0.0, 3.0],
            ]]],
            depth: 1.0,
        };
        let deposit = flat(1, 1, true, [0.0, -3.0], 2.0);
        assert_eq!(tracks(&[scar, deposit]), vec![1, 2]);
    }
}

//! The orientation field: which side of a survey's surface is out, decided once for the whole
//! surface, so that every core point's normal — in whichever tile it is computed — points out of
//! the material (SPEC.md §1 "Orientation", "Orientation on real surveys").
//!
//! A normal from PCA has no sign. The field is a coarse sample of the surface (one point per
//! cell of a few core spacings, with M3C2's normal; points whose neighbourhood is no surface at
//! that scale — an edge, a crest — are left out, [`FLAT`]), oriented in two steps:
//!
//! 1. **Consistently along the surface**: a maximum-confidence spanning tree over the sample's
//!    nearest-neighbour graph carries one orientation from point to point (Hoppe et al. 1992,
//!    "Surface reconstruction from unorganized points", §3.3), with the flip criterion of König
//!    & Gumhold 2009 ("Consistent propagation of normal orientations in point clouds", VMV): two
//!    points with normals nᵢ, nⱼ and chord direction e agree when nⱼ · (nᵢ − 2(nᵢ·e)e) > 0 —
//!    the reflection of nᵢ across the chord's bisector is nⱼ for any circle through both points,
//!    so the test holds across a cliff's convex edge and a foot's concave one, where the plain
//!    dot product nᵢ·nⱼ is near zero; where the normals are within 60° of parallel, the dot
//!    product speaks ([`agreement`]). The magnitude is the edge's confidence. (A sheet of rock
//!    thinner than a few sample spacings — a rib, a fin — has its two sides linked across it;
//!    their normals' dot product makes them agree, one side inward: the sample cannot resolve
//!    it, nor can the normals of its core points.)
//! 2. **One sign per connected surface, from gravity**: terrain is the upper boundary of its
//!    material, and by the divergence theorem the outward normals of such a surface satisfy
//!    ∫ n_z dA = the area of its footprint ≥ 0 — overhangs and ledges add and subtract, the sum
//!    is what the surface covers in plan. So each connected part is turned so that its
//!    area-weighted mean n_z is positive. A 70° face scanned alone has a mean n_z of cos 70° ≈
//!    0.34; a beach, a plateau or an airborne survey near 1. Where the mean is within
//!    [`MIN_MEAN_NZ`] of zero — a vertical face scanned alone, or a part too small to say — the
//!    data cannot decide: the part's points are marked undecided, and events on them say so
//!    (a face overhanging on average, seen alone, would be turned wrong by this rule: that is the
//!    case `--orientation toward:` the scanner's position is for).
//!
//! Each sample point stands for the surface in its cubic cell; a plane with unit normal n crosses
//! cells of side f at a rate of |n|₁ / f² per unit area (|n|₁ = |n_x| + |n_y| + |n_z|), so a
//! point's area weight is 1 / |n|₁.
//!
//! A core point's fine normal then takes the sign of the field point near it that agrees or
//! disagrees with it most clearly (the same criterion), and its undecided mark when the field
//! there is undecided or no field point speaks clearly. The result depends on the core point,
//! its normal and the field only: not on the tile that computes it.

use std::cmp::Ordering;
use std::collections::BinaryHeap;

use crate::geom::{dot, Point3};
use crate::spatial::Index;

/// A connected part whose area-weighted mean n_z (oriented) is below this is undecided: a face
/// within about 6° of vertical on average.
pub(crate) const MIN_MEAN_NZ: f64 = 0.1;
/// Fewest sample points of a part whose sign is decided (fewer: a scrap too small to say).
pub(crate) const MIN_PART: usize = 10;
/// A sample point whose neighbourhood's smallest eigenvalue is more than this share of the three
/// (0 on a plane; about 0.1 where two planes meet at a right angle, 1/3 for scatter) is no
/// surface at the field's scale — an edge, a crest, a cleft — and is left out: its normal tilts
/// where the surface does not (a dune crest's came out 68° from vertical on St Leonards).
pub(crate) const FLAT: f64 = 0.1;
/// Neighbours per sample point in the propagation graph.
const GRAPH_K: usize = 10;
/// Sample points further apart than this many field spacings are not neighbours: a gap that wide
/// separates two surfaces (or a hole), and the orientation is not carried across it.
const LINK: f64 = 3.0;
/// Field points a core point looks at, within [`REACH`] field spacings.
const LOOK_K: usize = 4;
pub(crate) const REACH: f64 = 2.0;
/// A core point's normal whose clearest agreement with the field is weaker than this (an angle
/// near 90° to every field normal near it) takes that sign but is marked undecided.
pub(crate) const WEAK: f64 = 0.25;

fn flip(n: &mut Point3) {
    *n = [-n[0], -n[1], -n[2]];
}

/// The agreement of normal `nj` at `pj` with normal `ni` at `pi`: positive when they are
/// consistently oriented, near ±1 when the geometry is clear, near 0 when it is not. Where the
/// two normals are within 60° of parallel (a smooth surface, a rounded edge, a scarp sharper
/// than the sample's normals), the plain nᵢ·nⱼ; where they are nearly perpendicular (a sharp
/// convex or concave edge: a cliff's top, its foot, a cavity's ceiling), the König–Gumhold
/// reflection, which alone can tell there. The reflection assumes the two points lie on a
/// circle their normals are radii of; between normals fitted over a ball wider than the feature
/// between the points it rotates nᵢ by far more than the surface turns (two points a few metres
/// apart up a dune's scarp, their normals both tilted 30°: St Leonards' dunes came out upside
/// down by it), so it speaks only where the dot product cannot. Points less than `thin` apart
/// along `ni` are taken to lie on one surface and compared by nᵢ·nⱼ alone.
pub(crate) fn agreement(pi: &Point3, ni: &Point3, pj: &Point3, nj: &Point3, thin: f64) -> f64 {
    let plain = dot(ni, nj);
    let d = [pj[0] - pi[0], pj[1] - pi[1], pj[2] - pi[2]];
    let len = dot(&d, &d).sqrt();
    if plain.abs() >= PARALLEL || len == 0.0 || dot(&d, ni).abs() < thin {
        return plain;
    }
    let e = [d[0] / len, d[1] / len, d[2] / len];
    let k = 2.0 * dot(ni, &e);
    let reflected = [ni[0] - k * e[0], ni[1] - k * e[1], ni[2] - k * e[2]];
    dot(nj, &reflected)
}

/// Normals whose |nᵢ·nⱼ| is at least this (within 60° of parallel, or of anti-parallel) are
/// compared by their dot product ([`agreement`]).
const PARALLEL: f64 = 0.5;

/// Sample points closer than this many field spacings along a normal lie on one surface (see
/// [`agreement`]).
const THIN: f64 = 0.5;

/// A connected part of the sampled surface and its sign.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct Part {
    /// Sample points in it.
    pub(crate) points: usize,
    /// Area-weighted mean n_z of its outward normals, as oriented.
    pub(crate) mean_nz: f64,
    /// Whether the data decides its sign ([`MIN_MEAN_NZ`], [`MIN_PART`]).
    pub(crate) decided: bool,
}

/// An oriented sample: the normals (turned in place), each point's part, and the parts.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Oriented {
    pub(crate) normals: Vec<Point3>,
    pub(crate) part: Vec<u32>,
    pub(crate) parts: Vec<Part>,
}

/// A candidate edge of the spanning tree: reach `to` from the oriented `from`.
#[derive(PartialEq)]
struct Edge {
    confidence: f64,
    from: u32,
    to: u32,
}
impl Eq for Edge {}
impl Ord for Edge {
    fn cmp(&self, o: &Self) -> Ordering {
        // Max-heap on confidence; ties to the smaller indices (determinism).
        self.confidence
            .total_cmp(&o.confidence)
            .then(o.to.cmp(&self.to))
            .then(o.from.cmp(&self.from))
    }
}
impl PartialOrd for Edge {
    fn partial_cmp(&self, o: &Self) -> Option<Ordering> {
        Some(self.cmp(o))
    }
}

/// The neighbours of every sample point (symmetric: j lists i when i lists j), nearest first.
fn graph(points: &[Point3], spacing: f64) -> Vec<Vec<u32>> {
    let origin = points.first().copied().unwrap_or([0.0; 3]);
    let index = Index::new(points, origin);
    let link2 = (LINK * spacing).powi(2);
    let mut adj: Vec<Vec<u32>> = points
        .iter()
        .enumerate()
        .map(|(i, p)| {
            index
                .nearest(&index.to_local(p), GRAPH_K + 1)
                .into_iter()
                .filter(|&(j, d2)| j != i && d2 <= link2)
                .map(|(j, _)| j as u32)
                .collect()
        })
        .collect();
    for i in 0..adj.len() {
        for k in 0..adj[i].len() {
            let j = adj[i][k] as usize;
            if !adj[j].contains(&(i as u32)) {
                adj[j].push(i as u32);
            }
        }
    }
    adj
}

/// Orient the sample `points` with unit `normals` (field spacing `spacing`): consistently along
/// each connected part, then each part so that its mean n_z is positive (see the module doc).
/// Points are visited in the order given (give them in a canonical order: the result is then
/// deterministic).
pub(crate) fn orient(points: &[Point3], normals: &[Point3], spacing: f64) -> Oriented {
    let n = points.len();
    let mut normals = normals.to_vec();
    let adj = graph(points, spacing);
    let mut part = vec![u32::MAX; n];
    let mut parts = Vec::new();
    let mut heap = BinaryHeap::new();
    let push = |heap: &mut BinaryHeap<Edge>, from: usize, normals: &[Point3], part: &[u32]| {
        for &j in &adj[from] {
            if part[j as usize] == u32::MAX {
                let s = agreement(
                    &points[from],
                    &normals[from],
                    &points[j as usize],
                    &normals[j as usize],
                    THIN * spacing,
                );
                heap.push(Edge {
                    confidence: s.abs(),
                    from: from as u32,
                    to: j,
                });
            }
        }
    };
    for (id, members) in components(&adj).into_iter().enumerate() {
        let id = id as u32;
        let seed = members[0];
        part[seed] = id;
        push(&mut heap, seed, &normals, &part);
        while let Some(e) = heap.pop() {
            let (from, to) = (e.from as usize, e.to as usize);
            if part[to] != u32::MAX {
                continue;
            }
            let s = agreement(
                &points[from],
                &normals[from],
                &points[to],
                &normals[to],
                THIN * spacing,
            );
            if s < 0.0 {
                flip(&mut normals[to]);
            }
            part[to] = id;
            push(&mut heap, to, &normals, &part);
        }
        // One sign for the part: outward normals of terrain have a positive mean n_z.
        let (mut sw, mut swz) = (0.0, 0.0);
        for &i in &members {
            let m = &normals[i];
            let w = 1.0 / (m[0].abs() + m[1].abs() + m[2].abs());
            sw += w;
            swz += w * m[2];
        }
        let mut mean_nz = if sw > 0.0 { swz / sw } else { 0.0 };
        if mean_nz < 0.0 {
            for &i in &members {
                flip(&mut normals[i]);
            }
            mean_nz = -mean_nz;
        }
        parts.push(Part {
            points: members.len(),
            mean_nz,
            decided: members.len() >= MIN_PART && mean_nz >= MIN_MEAN_NZ,
        });
    }
    Oriented {
        normals,
        part,
        parts,
    }
}

/// The connected parts of the graph `adj`, each in ascending order, by their first point.
fn components(adj: &[Vec<u32>]) -> Vec<Vec<usize>> {
    let mut seen = vec![false; adj.len()];
    let mut out = Vec::new();
    for start in 0..adj.len() {
        if seen[start] {
            continue;
        }
        seen[start] = true;
        let (mut members, mut stack) = (vec![start], vec![start]);
        while let Some(i) = stack.pop() {
            for &j in &adj[i] {
                let j = j as usize;
                if !seen[j] {
                    seen[j] = true;
                    members.push(j);
                    stack.push(j);
                }
            }
        }
        members.sort_unstable();
        out.push(members);
    }
    out
}

/// The oriented field near a set of core points, indexed in their local frame.
pub struct Field {
    index: Index,
    normals: Vec<Point3>,
    decided: Vec<bool>,
    reach: f64,
    thin: f64,
}

impl Field {
    /// The field points `points` (local frame of the core points), their oriented `normals` and
    /// whether each one's sign is decided; `spacing` is the field's cell.
    pub(crate) fn new(
        points: Vec<Point3>,
        normals: Vec<Point3>,
        decided: Vec<bool>,
        spacing: f64,
    ) -> Self {
        Field {
            index: Index::from_local(points, [0.0; 3]),
            normals,
            decided,
            reach: REACH * spacing,
            thin: THIN * spacing,
        }
    }

    /// Turn normal `n` at core point `p` (local frame) to agree with the field; whether its
    /// sign is decided (the field there is, and agrees or disagrees with it clearly). With no
    /// field point within reach, `n` is turned up and undecided.
    pub(crate) fn orient(&self, p: &Point3, n: &mut Point3) -> bool {
        let reach2 = self.reach * self.reach;
        let mut best: Option<(f64, usize)> = None;
        for (q, d2) in self.index.nearest(p, LOOK_K) {
            if d2 > reach2 {
                break;
            }
            let s = agreement(&self.index.points()[q], &self.normals[q], p, n, self.thin);
            if best.is_none_or(|(b, _)| s.abs() > b.abs()) {
                best = Some((s, q));
            }
        }
        match best {
            Some((s, q)) => {
                if s < 0.0 {
                    flip(n);
                }
                self.decided[q] && s.abs() >= WEAK
            }
            None => {
                if n[2] < 0.0 {
                    flip(n);
                }
                false
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn unit(v: Point3) -> Point3 {
        let l = dot(&v, &v).sqrt();
        [v[0] / l, v[1] / l, v[2] / l]
    }

    /// A cliff: a beach (z = 0, y < 0), a vertical face (y = 0, z ∈ [0, 10], rock at y > 0)
    /// and a plateau (z = 10, y > 0), sampled every `h`, with the true outward normals.
    fn cliff(h: f64) -> (Vec<Point3>, Vec<Point3>) {
        let (mut p, mut n) = (Vec::new(), Vec::new());
        let steps = |a: f64, b: f64| ((b - a) / h).round() as usize;
        for i in 0..steps(0.0, 20.0) {
            let x = i as f64 * h;
            for k in 1..steps(0.0, 10.0) {
                let t = k as f64 * h;
                p.push([x, -t, 0.0]);
                n.push([0.0, 0.0, 1.0]);
                p.push([x, t, 10.0]);
                n.push([0.0, 0.0, 1.0]);
                p.push([x, 0.0, t]);
                n.push([0.0, -1.0, 0.0]);
            }
        }
        (p, n)
    }

    /// Normals with signs scrambled deterministically.
    fn scrambled(n: &[Point3]) -> Vec<Point3> {
        n.iter()
            .enumerate()
            .map(|(i, v)| {
                if (i * 7 + i / 3) % 3 == 0 {
                    [-v[0], -v[1], -v[2]]
                } else {
                    *v
                }
            })
            .collect()
    }

    fn all_agree(got: &[Point3], want: &[Point3]) {
        for (i, (g, w)) in got.iter().zip(want).enumerate() {
            assert!(dot(g, w) > 0.99, "point {i}: {g:?} against {w:?}");
        }
    }

    #[test]
    fn a_cliff_with_beach_and_plateau_is_oriented_out_of_the_rock() {
        let (p, n) = cliff(0.5);
        let o = orient(&p, &scrambled(&n), 0.5);
        all_agree(&o.normals, &n);
        assert_eq!(o.parts.len(), 1);
        assert!(o.parts[0].decided);
    }

    /// A face dipping at `dip` degrees alone (no beach, no plateau), facing −y, with rough
    /// normals (tilted by up to ±25°).
    fn face(dip: f64, h: f64) -> (Vec<Point3>, Vec<Point3>) {
        let d = dip.to_radians();
        let (nn, w) = ([0.0, -d.sin(), d.cos()], [0.0, d.cos(), d.sin()]);
        let (mut p, mut n) = (Vec::new(), Vec::new());
        for i in 0..80 {
            for j in 0..60 {
                let (a, b) = (i as f64 * h, j as f64 * h);
                let q: Point3 = std::array::from_fn(|k| a * [1.0, 0.0, 0.0][k] + b * w[k]);
                let (ta, tb) = (0.4 * (a * 1.3).sin(), 0.3 * (b * 0.9 + a).cos());
                let r = unit(std::array::from_fn(|k| {
                    nn[k] + ta * [1.0, 0.0, 0.0][k] + tb * w[k]
                }));
                p.push(q);
                n.push(r);
            }
        }
        (p, n)
    }

    #[test]
    fn a_face_scanned_alone_is_oriented_by_its_lean() {
        let (p, n) = face(70.0, 0.5);
        let o = orient(&p, &scrambled(&n), 0.5);
        all_agree(&o.normals, &n);
        assert!(o.parts[0].decided && (o.parts[0].mean_nz - 0.34).abs() < 0.05);
    }

    #[test]
    fn a_vertical_face_alone_is_consistent_but_undecided() {
        let (p, n) = face(90.0, 0.5);
        let o = orient(&p, &scrambled(&n), 0.5);
        // One consistent sign (either), and said to be undecided.
        let s = dot(&o.normals[0], &n[0]).signum();
        for (g, w) in o.normals.iter().zip(&n) {
            assert!(s * dot(g, w) > 0.99);
        }
        assert_eq!(o.parts.len(), 1);
        assert!(!o.parts[0].decided, "{:?}", o.parts[0]);
    }

    #[test]
    fn a_rib_keeps_both_sides_outward() {
        // A rib of rock 2 m thick standing on flat ground: its sides face away from each
        // other, the orientation carried over its top's edges.
        let (mut p, mut n) = (Vec::new(), Vec::new());
        for i in 0..40 {
            let x = i as f64 * 0.5;
            for k in 1..12 {
                let z = k as f64 * 0.5;
                p.push([x, -1.0, z]);
                n.push([0.0, -1.0, 0.0]);
                p.push([x, 1.0, z]);
                n.push([0.0, 1.0, 0.0]);
            }
            for k in 1..10 {
                let y = 1.0 + k as f64 * 0.5;
                p.push([x, y, 0.0]);
                n.push([0.0, 0.0, 1.0]);
                p.push([x, -y, 0.0]);
                n.push([0.0, 0.0, 1.0]);
            }
            for k in 0..5 {
                p.push([x, -1.0 + k as f64 * 0.5, 6.0]);
                n.push([0.0, 0.0, 1.0]);
            }
        }
        let o = orient(&p, &scrambled(&n), 0.5);
        all_agree(&o.normals, &n);
    }

    #[test]
    fn a_scarp_sharper_than_the_normals_is_not_a_sheet() {
        // Two sample points up a steep scarp (3 m up over 1 m), both normals smoothed over the
        // scarp to 30° from vertical: one surface, oriented alike.
        let n = unit([0.0, -0.5, 0.866]);
        let s = agreement(&[0.0, 0.0, 2.6], &n, &[0.0, 1.0, 5.45], &n, 0.5 * 4.5);
        assert!(s > 0.9, "{s}");
    }

    #[test]
    fn a_surface_sampled_in_two_stacked_cells_is_one_surface() {
        // A beach whose height straddles a cell boundary: the sample holds two points at most
        // places, a centimetre apart along the normal. They are one surface, not a sheet's two
        // sides (the dense cliff's beach came out a third upside down when they were).
        let (mut p, mut n) = (Vec::new(), Vec::new());
        let tilt = |k: usize| {
            unit([
                0.06 * ((k * 37 % 11) as f64 / 5.0 - 1.0),
                0.06 * ((k * 53 % 7) as f64 / 3.0 - 1.0),
                1.0,
            ])
        };
        for i in 0..60 {
            for j in 0..40 {
                let (x, y) = (i as f64 * 0.07, j as f64 * 0.07);
                p.push([x, y, 0.0]);
                n.push(tilt(i * 40 + j));
                if (i + 2 * j) % 3 != 0 {
                    p.push([x, y, 0.01]);
                    n.push(tilt(i * 40 + j + 5));
                }
            }
        }
        let o = orient(&p, &scrambled(&n), 0.07);
        all_agree(&o.normals, &n);
    }

    #[test]
    fn a_cavity_ceiling_faces_down() {
        // A vertical face (y = 0, rock at y > 0) between a beach and a plateau, with a cavity:
        // a half-cylinder of radius 2 along x about (y, z) = (0, 5). Its ceiling faces down,
        // its back wall out (−y), its floor up: every normal out of the rock, into the cavity.
        let (mut p, mut n) = (Vec::new(), Vec::new());
        for i in 0..40 {
            let x = i as f64 * 0.5;
            for k in 1..16 {
                let t = k as f64 * std::f64::consts::PI / 16.0;
                p.push([x, 2.0 * t.sin(), 5.0 + 2.0 * t.cos()]);
                n.push([0.0, -t.sin(), -t.cos()]);
            }
            for k in 0..=20 {
                let z = k as f64 * 0.5;
                if (z - 5.0).abs() >= 2.0 {
                    p.push([x, 0.0, z]);
                    n.push([0.0, -1.0, 0.0]);
                }
            }
            for k in 1..10 {
                p.push([x, k as f64 * 0.5, 10.0]);
                n.push([0.0, 0.0, 1.0]);
                p.push([x, -(k as f64) * 0.5, 0.0]);
                n.push([0.0, 0.0, 1.0]);
            }
        }
        let o = orient(&p, &scrambled(&n), 0.5);
        all_agree(&o.normals, &n);
    }

    #[test]
    fn core_points_take_the_field_sign_and_its_doubt() {
        let (p, n) = face(70.0, 1.0);
        let o = orient(&p, &n, 1.0);
        let decided = vec![true; p.len()];
        let field = Field::new(p.clone(), o.normals.clone(), decided, 1.0);
        // Fine normals at points between the field points, some flipped.
        for (i, q) in p.iter().enumerate().step_by(17) {
            let c = [q[0] + 0.3, q[1] + 0.1, q[2] + 0.2];
            let mut m = if i % 2 == 0 {
                n[i]
            } else {
                [-n[i][0], -n[i][1], -n[i][2]]
            };
            assert!(field.orient(&c, &mut m));
            assert!(dot(&m, &n[i]) > 0.99);
        }
        // Far from the field: turned up, undecided.
        let mut m = [0.0, 0.3, -0.95];
        assert!(!field.orient(&[500.0, 0.0, 0.0], &mut m));
        assert!(m[2] > 0.0);
        // An undecided field passes its doubt on.
        let (p, n) = face(90.0, 1.0);
        let o = orient(&p, &n, 1.0);
        let undecided: Vec<bool> = o
            .part
            .iter()
            .map(|&k| o.parts[k as usize].decided)
            .collect();
        let field = Field::new(p.clone(), o.normals.clone(), undecided, 1.0);
        let mut m = n[100];
        assert!(!field.orient(&p[100], &mut m));
    }
}

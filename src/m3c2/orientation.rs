//! Consistent orientation of core-point normals.
//!
//! The sign of every M3C2 distance follows the normal, so orientation must be consistent over
//! the surface. `up` flips normals to n·z ≥ 0, which is ambiguous on vertical faces (n·z ≈ 0:
//! noise flips signs point to point and smoothing then cancels a real rockfall).
//!
//! `auto` works in three steps:
//! 1. non-steep normals point up, unless the core point lies under C1's top surface (the highest
//!    point per cell, a small DSM) by more than two normal radii: there the surface may face down
//!    (the ceiling of a cavity, an overhang: a scar in a cliff face that a later survey holds, seen
//!    from the first survey's core points), so "up" is unreliable and the normal is left to step 3;
//! 2. a steep normal points to the side where the terrain is lower: the top surface of C1 (the
//!    highest point per cell, a small DSM) is looked up at horizontal offsets ±a along the
//!    normal's horizontal part. In front of a cliff lies the beach, behind it the plateau or the
//!    rock, so this is "up" generalised to steep faces, and it holds at convex and concave edges
//!    alike (where a plain normal propagation is ambiguous: there n₁·n₂ ≈ 0);
//! 3. steep normals the DSM cannot decide (no data on one side) take the orientation carried
//!    along the surface from decided neighbours, by a maximum-confidence propagation over the
//!    k-nearest-neighbour graph of the core points (Hoppe et al. 1992, "Surface reconstruction
//!    from unorganized points", §3.3: a minimum spanning tree over edge costs 1 − |nᵢ·nⱼ|, grown
//!    here from every decided point at once).

use std::cmp::Ordering;
use std::collections::BinaryHeap;
use std::str::FromStr;

use crate::geom::Point3;
use crate::spatial::{Columns, Index};

/// How normals are oriented (`--orientation`).
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Orientation {
    /// Up where not steep, propagated along the surface on steep parts.
    Auto,
    /// n·z ≥ 0.
    Up,
    /// n·v ≥ 0 for a fixed vector v.
    Vector(Point3),
    /// Toward a point (e.g. the scanner position), global coordinates.
    Toward(Point3),
}

impl std::fmt::Display for Orientation {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Orientation::Auto => write!(f, "auto"),
            Orientation::Up => write!(f, "up"),
            Orientation::Vector(v) => write!(f, "{},{},{}", v[0], v[1], v[2]),
            Orientation::Toward(p) => write!(f, "toward:{},{},{}", p[0], p[1], p[2]),
        }
    }
}

fn parse_triplet(s: &str) -> Option<Point3> {
    let v: Vec<f64> = s
        .split(',')
        .map(|t| t.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .ok()?;
    (v.len() == 3 && v.iter().all(|x| x.is_finite())).then(|| [v[0], v[1], v[2]])
}

impl FromStr for Orientation {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, Self::Err> {
        let bad = || format!("--orientation: expected auto, up, X,Y,Z or toward:X,Y,Z, got '{s}'");
        match s.trim() {
            "auto" => Ok(Orientation::Auto),
            "up" => Ok(Orientation::Up),
            t if t.starts_with("toward:") => parse_triplet(&t[7..])
                .map(Orientation::Toward)
                .ok_or_else(bad),
            t => {
                let v = parse_triplet(t).ok_or_else(bad)?;
                if v.iter().all(|x| *x == 0.0) {
                    return Err(format!("--orientation: the vector {t} has zero length"));
                }
                Ok(Orientation::Vector(v))
            }
        }
    }
}

/// A normal is steep (its "up" sign unreliable) when |n·z| is below this: about 60° from vertical.
pub const STEEP_NZ: f64 = 0.5;
/// A non-steep normal is not simply turned up when C1's top surface lies more than this many
/// normal radii above its core point (the top of a cell of half a normal radius on a slope just
/// below 60° rises at most 1.23 radii above the cell's lowest point).
const UNDER: f64 = 2.0;
/// Neighbours per core point in the propagation graph.
const GRAPH_K: usize = 8;

fn dot(a: &Point3, b: &Point3) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

fn flip(n: &mut Point3) {
    n[0] = -n[0];
    n[1] = -n[1];
    n[2] = -n[2];
}

/// Orient `normals` (unit, or NaN where undefined) at `cores` in place. `cores` are in the local
/// frame of `before` (the indexed C1 points, used by `auto` for its terrain test); `scale` is the
/// normal radius, the length scale of the terrain test.
pub fn orient(
    cores: &[Point3],
    normals: &mut [Point3],
    before: &Columns,
    scale: f64,
    how: Orientation,
) {
    let origin = before.origin();
    match how {
        Orientation::Up => orient_along(normals, &[0.0, 0.0, 1.0]),
        Orientation::Vector(v) => orient_along(normals, &v),
        Orientation::Toward(target) => {
            let t = [
                target[0] - origin[0],
                target[1] - origin[1],
                target[2] - origin[2],
            ];
            for (p, n) in cores.iter().zip(normals.iter_mut()) {
                let to = [t[0] - p[0], t[1] - p[1], t[2] - p[2]];
                if dot(n, &to) < 0.0 {
                    flip(n);
                }
            }
        }
        Orientation::Auto => orient_auto(cores, normals, before, scale),
    }
}

fn orient_along(normals: &mut [Point3], v: &Point3) {
    for n in normals.iter_mut() {
        if dot(n, v) < 0.0 {
            flip(n);
        }
    }
}

/// A candidate edge of the propagation: reach `to` from the oriented `from` with confidence |dot|.
#[derive(PartialEq)]
struct Edge {
    confidence: f64,
    from: usize,
    to: usize,
}
impl Eq for Edge {}
impl Ord for Edge {
    fn cmp(&self, o: &Self) -> Ordering {
        // Max-heap on confidence; ties broken by the smaller indices (determinism).
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

/// Highest C1 point per square cell: the top surface seen from above.
struct TopSurface {
    cell: f64,
    /// The highest height per cell over the points' cells `first..first + dims` (−inf where no
    /// point falls): a dense grid, built in one pass without hashing; a hash map where the
    /// points are too sparse for one.
    top: Top,
}

enum Top {
    Dense {
        first: [i64; 2],
        dims: [usize; 2],
        z: Vec<f64>,
    },
    Sparse(rustc_hash::FxHashMap<(i64, i64), f64>),
}

/// ⌊v⌋ as an integer (for the finite values of local coordinates over a cell), without the
/// library call `floor` is on baseline x86-64.
fn floor_i64(v: f64) -> i64 {
    let t = v as i64;
    if (t as f64) > v {
        t - 1
    } else {
        t
    }
}

impl TopSurface {
    fn new(points: &[Point3], cell: f64) -> Self {
        let key = |p: &Point3| [floor_i64(p[0] / cell), floor_i64(p[1] / cell)];
        let (mut lo, mut hi) = ([i64::MAX; 2], [i64::MIN; 2]);
        for p in points {
            let k = key(p);
            for a in 0..2 {
                lo[a] = lo[a].min(k[a]);
                hi[a] = hi[a].max(k[a]);
            }
        }
        let dims = [0, 1].map(|a| (hi[a].saturating_sub(lo[a]).max(-1) + 1) as usize);
        let cells = dims[0].saturating_mul(dims[1]);
        // At most a cell per point (8 bytes each: less than the hash map's entries once a
        // quarter of the cells hold a point).
        let top = if !points.is_empty() && cells <= points.len().max(1024) {
            let mut z = vec![f64::NEG_INFINITY; cells];
            for p in points {
                let k = key(p);
                let i = (k[1] - lo[1]) as usize * dims[0] + (k[0] - lo[0]) as usize;
                if p[2] > z[i] {
                    z[i] = p[2];
                }
            }
            Top::Dense { first: lo, dims, z }
        } else {
            let mut top = rustc_hash::FxHashMap::default();
            for p in points {
                let k = key(p);
                let z = top.entry((k[0], k[1])).or_insert(f64::NEG_INFINITY);
                if p[2] > *z {
                    *z = p[2];
                }
            }
            Top::Sparse(top)
        };
        TopSurface { cell, top }
    }
    /// How far C1's top surface lies above `p` in `p`'s cell (0 when the cell has no point or
    /// none above).
    fn above(&self, p: &Point3) -> f64 {
        self.at(p[0], p[1]).map_or(0.0, |z| (z - p[2]).max(0.0))
    }
    fn at(&self, x: f64, y: f64) -> Option<f64> {
        let key = [floor_i64(x / self.cell), floor_i64(y / self.cell)];
        match &self.top {
            Top::Dense { first, dims, z } => {
                let (i, j) = (key[0].checked_sub(first[0])?, key[1].checked_sub(first[1])?);
                if i < 0 || j < 0 || i as usize >= dims[0] || j as usize >= dims[1] {
                    return None;
                }
                let v = z[j as usize * dims[0] + i as usize];
                (v > f64::NEG_INFINITY).then_some(v)
            }
            Top::Sparse(top) => top.get(&(key[0], key[1])).copied(),
        }
    }
    /// +1 when the terrain is lower on the +h side of `p`, −1 when on the −h side, 0 when the
    /// data cannot tell (a side without points, or no height difference).
    fn lower_side(&self, p: &Point3, h: [f64; 2]) -> i8 {
        for k in 1..=4 {
            let a = k as f64 * 2.0 * self.cell;
            let front = self.at(p[0] + a * h[0], p[1] + a * h[1]);
            let back = self.at(p[0] - a * h[0], p[1] - a * h[1]);
            if let (Some(f), Some(b)) = (front, back) {
                if (f - b).abs() > self.cell {
                    return if f < b { 1 } else { -1 };
                }
            }
        }
        0
    }
}

fn orient_auto(cores: &[Point3], normals: &mut [Point3], before: &Columns, scale: f64) {
    let n = cores.len();
    if n == 0 {
        return;
    }
    let mut done = vec![false; n];
    let mut steep = vec![false; n];
    let valid = |nv: &Point3| nv[0].is_finite();
    let dsm = TopSurface::new(before.points(), scale / 2.0);
    let mut undecided = false;
    for i in 0..n {
        if !valid(&normals[i]) {
            done[i] = true;
        } else if normals[i][2].abs() < STEEP_NZ {
            steep[i] = true;
            undecided = true;
        } else if dsm.above(&cores[i]) > UNDER * scale {
            // Under C1's top: maybe an overhang, whose normal points down (step 3 decides).
            undecided = true;
        } else {
            if normals[i][2] < 0.0 {
                flip(&mut normals[i]);
            }
            done[i] = true;
        }
    }
    if !undecided {
        return;
    }
    for i in 0..n {
        if done[i] || !steep[i] {
            continue;
        }
        let nv = normals[i];
        let hl = (nv[0] * nv[0] + nv[1] * nv[1]).sqrt();
        let side = dsm.lower_side(&cores[i], [nv[0] / hl, nv[1] / hl]);
        if side != 0 {
            if side < 0 {
                flip(&mut normals[i]);
            }
            done[i] = true;
        }
    }
    let index = Index::from_local(cores.to_vec(), [0.0; 3]);
    let neighbours = |i: usize| index.nearest(&cores[i], GRAPH_K + 1);
    let mut heap = BinaryHeap::new();
    // Seeds: oriented points that touch an undecided one.
    for i in 0..n {
        if !done[i] || !valid(&normals[i]) {
            continue;
        }
        for (j, _) in neighbours(i) {
            if !done[j] {
                heap.push(Edge {
                    confidence: dot(&normals[i], &normals[j]).abs(),
                    from: i,
                    to: j,
                });
            }
        }
    }
    loop {
        while let Some(e) = heap.pop() {
            if done[e.to] {
                continue;
            }
            let from_n = normals[e.from];
            if dot(&from_n, &normals[e.to]) < 0.0 {
                flip(&mut normals[e.to]);
            }
            done[e.to] = true;
            let to = e.to;
            for (j, _) in neighbours(to) {
                if !done[j] {
                    heap.push(Edge {
                        confidence: dot(&normals[to], &normals[j]).abs(),
                        from: to,
                        to: j,
                    });
                }
            }
        }
        // A steep part not connected to any gentle one: orient its first point away from the
        // centroid of all core points (outward for a cliff seen with its top and foot), then
        // propagate from it.
        let Some(seed) = (0..n).find(|&i| !done[i]) else {
            break;
        };
        let c = centroid(cores);
        let out = [
            cores[seed][0] - c[0],
            cores[seed][1] - c[1],
            cores[seed][2] - c[2],
        ];
        if dot(&normals[seed], &out) < 0.0 {
            flip(&mut normals[seed]);
        }
        done[seed] = true;
        for (j, _) in neighbours(seed) {
            if !done[j] {
                heap.push(Edge {
                    confidence: dot(&normals[seed], &normals[j]).abs(),
                    from: seed,
                    to: j,
                });
            }
        }
    }
}

fn centroid(pts: &[Point3]) -> Point3 {
    let mut c = [0.0; 3];
    for p in pts {
        c[0] += p[0];
        c[1] += p[1];
        c[2] += p[2];
    }
    let k = 1.0 / pts.len().max(1) as f64;
    [c[0] * k, c[1] * k, c[2] * k]
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn parses_all_forms() {
        assert_eq!("auto".parse::<Orientation>().unwrap(), Orientation::Auto);
        assert_eq!("up".parse::<Orientation>().unwrap(), Orientation::Up);
        assert_eq!(
            "0,1,0".parse::<Orientation>().unwrap(),
            Orientation::Vector([0.0, 1.0, 0.0])
        );
        assert_eq!(
            "toward:1,2,3".parse::<Orientation>().unwrap(),
            Orientation::Toward([1.0, 2.0, 3.0])
        );
        assert!("sideways".parse::<Orientation>().is_err());
        assert!("0,0,0".parse::<Orientation>().is_err());
    }

    /// C1 of the test cliff every 0.25 along x ∈ [0, 20): a plateau (z = 10, y < 0), a beach
    /// (z = 0, y > 0) and the face between them (y = 0, z ∈ [0, 10)) where `face(z)`.
    fn cliff_c1(face: impl Fn(f64) -> bool) -> Vec<Point3> {
        let mut c1 = Vec::new();
        for i in 0..80 {
            let x = i as f64 * 0.25;
            for k in 0..40 {
                let t = k as f64 * 0.25;
                c1.push([x, -t - 0.25, 10.0]);
                c1.push([x, t + 0.25, 0.0]);
                if face(t) {
                    c1.push([x, 0.0, t]);
                }
            }
        }
        c1
    }

    /// A plateau (z = 10, y < 0) above a vertical face (y = 0) above a beach (z = 0, y > 0):
    /// with `auto`, every face normal must point out of the rock (+y), whatever sign PCA gave.
    #[test]
    fn auto_carries_up_over_a_cliff() {
        let mut cores = Vec::new();
        let mut normals = Vec::new();
        for i in 0..20 {
            let x = i as f64;
            for k in 1..10 {
                cores.push([x, -(k as f64), 10.0]);
                normals.push([0.0, 0.0, if (i + k) % 2 == 0 { 1.0 } else { -1.0 }]);
                cores.push([x, k as f64, 0.0]);
                normals.push([0.0, 0.0, if (i * k) % 3 == 0 { -1.0 } else { 1.0 }]);
            }
            for k in 0..=10 {
                cores.push([x, 0.0, k as f64]);
                // Noise-like alternating signs on the face.
                normals.push([0.0, if (i + k) % 2 == 0 { 1.0 } else { -1.0 }, 0.0]);
            }
        }
        // The C1 points: the same three surfaces, densely.
        let before = Columns::new(&cliff_c1(|_| true), [0.0; 3], 0.5);
        orient(&cores, &mut normals, &before, 1.0, Orientation::Auto);
        for (p, n) in cores.iter().zip(&normals) {
            if p[1] == 0.0 && p[2] > 0.0 && p[2] < 10.0 {
                assert_eq!(n[1], 1.0, "face normal at {p:?} points into the rock");
            } else if p[1] != 0.0 {
                assert_eq!(n[2], 1.0, "flat normal at {p:?} not up");
            }
        }
    }

    /// A face (y = 0, rock at y < 0, a plateau at z = 10 behind it, a beach at z = 0 in front)
    /// with a cavity: a half-cylinder of radius 2 along x about (y, z) = (0, 5). Its ceiling faces
    /// down, its back wall out (+y), its floor up; with `auto` every cavity normal must point out
    /// of the rock, into the cavity, whatever sign PCA gave. ("Up" on the ceiling points into the
    /// rock: the sign of every distance there would be wrong.)
    #[test]
    fn auto_points_a_cavity_ceiling_down() {
        let (axis, radius) = ([0.0, 5.0], 2.0);
        let cavity = |t: f64| [axis[0] - radius * t.sin(), axis[1] + radius * t.cos()];
        let outward = |t: f64| [t.sin(), -t.cos()];
        let mut cores = Vec::new();
        let mut normals = Vec::new();
        let mut truth = Vec::new();
        for i in 0..40 {
            let x = i as f64 * 0.5;
            for k in 1..16 {
                let t = k as f64 * std::f64::consts::PI / 16.0;
                let [y, z] = cavity(t);
                let [ny, nz] = outward(t);
                let s = if (i + k) % 2 == 0 { 1.0 } else { -1.0 };
                cores.push([x, y, z]);
                normals.push([0.0, s * ny, s * nz]);
                truth.push(Some([0.0, ny, nz]));
            }
            for k in 0..=20 {
                let z = k as f64 * 0.5;
                if (z - axis[1]).abs() < radius {
                    continue;
                }
                cores.push([x, 0.0, z]);
                normals.push([0.0, if (i + k) % 2 == 0 { 1.0 } else { -1.0 }, 0.0]);
                truth.push(Some([0.0, 1.0, 0.0]));
            }
            for k in 1..10 {
                cores.push([x, -(k as f64), 10.0]);
                normals.push([0.0, 0.0, 1.0]);
                truth.push(None);
                cores.push([x, k as f64, 0.0]);
                normals.push([0.0, 0.0, -1.0]);
                truth.push(None);
            }
        }
        let mut c1 = cliff_c1(|z| (z - axis[1]).abs() >= radius);
        for i in 0..80 {
            for k in 1..32 {
                let [y, z] = cavity(k as f64 * std::f64::consts::PI / 32.0);
                c1.push([i as f64 * 0.25, y, z]);
            }
        }
        let before = Columns::new(&c1, [0.0; 3], 0.5);
        orient(&cores, &mut normals, &before, 1.0, Orientation::Auto);
        for ((p, n), t) in cores.iter().zip(&normals).zip(&truth) {
            let want = t.unwrap_or([0.0, 0.0, 1.0]);
            assert!(
                dot(n, &want) > 0.99,
                "normal {n:?} at {p:?} does not point out of the rock ({want:?})"
            );
        }
    }
}

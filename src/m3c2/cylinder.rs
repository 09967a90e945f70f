//! Cylinder statistics of M3C2 (Lague, Brodu & Leroux 2013, "Accurate 3D comparison of complex
//! topography with terrestrial laser scanner", §3.2).
//!
//! The cylinder has radius `r`, axis = the normal through the core point, and extends from −h to
//! +h along it (both ends included). The points inside are projected on the axis; we report their
//! count, mean position and population standard deviation.
//!
//! A cylinder is not a kd-tree query shape. The usual way (CloudCompare, py4dgeo) queries the
//! circumscribed sphere of radius √(r² + h²) and filters; on a surface that sphere cuts a disc of
//! radius ≈ √(r² + h²), far more points than the cylinder's disc of radius r when h ≫ r. The
//! column grid (`Columns::cylinder_candidates`) visits only the columns the cylinder crosses,
//! and in each only the heights it can reach.
//!
//! **One surface per cylinder.** The cylinder is meant to meet one surface per epoch near the
//! core point (Lague et al. choose its length so that it does). Where it reaches a second one —
//! the beach in front of a cliff foot, a deposit lying on it, the far side of a fin — that
//! surface's points are not a displacement of the first, and their share of the mean turns the
//! face into a false "gain" that counts the deposit a second time. Along the axis, points of
//! different surfaces are separated by empty space, while one surface's projections, however
//! inclined or rough, follow each other closely (their gaps are of the order of the point
//! spacing). So the projections are split at gaps wider than the cylinder's diameter
//! ([`Projections::surface`]); C1 keeps the group holding the core point (the one nearest to
//! t = 0) and C2 the group nearest to C1's. Where every point of a cylinder lies within one gap
//! of the others — any single surface — this is the plain M3C2 mean, computed without a sort.

use std::ops::Range;

use super::moments::Moments1;
use crate::geom::Point3;
use crate::spatial::{in_cylinder, Columns};

/// Projections of one epoch's points inside one cylinder.
#[derive(Debug, Default, Clone, Copy, PartialEq)]
pub struct CylinderStats {
    pub count: u32,
    /// Mean position along the axis (relative to the core point).
    pub(crate) mean: f64,
    /// Population standard deviation of the positions along the axis.
    pub(crate) std_dev: f64,
}

/// Statistics of the points of `index` inside the cylinder at `q` (local frame of `index`) with
/// unit axis `n`, radius `r`, half-length `h`. The sums are exact (see `moments`), so the result
/// does not depend on the order the points are visited in.
pub fn cylinder_stats(index: &Columns, q: &Point3, n: &Point3, r: f64, h: f64) -> CylinderStats {
    let mut m = Moments1::new(h);
    index.visit_cylinder(q, n, r, h, |t, inside| m.add(t, inside));
    stats(&m)
}

/// The same statistics by the circumscribed-sphere method (one query of radius √(r² + h²), then
/// the cylinder test), kept as the reference the cylinder query is tested and benchmarked against.
pub fn cylinder_stats_sphere(
    index: &Columns,
    q: &Point3,
    n: &Point3,
    r: f64,
    h: f64,
) -> CylinderStats {
    let mut m = Moments1::new(h);
    index.for_each_within(q, (r * r + h * h).sqrt() * (1.0 + 1e-9), |v| {
        let along = v[0] * n[0] + v[1] * n[1] + v[2] * n[2];
        let radial2 = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) - along * along;
        m.add(along, along.abs() <= h && radial2 <= r * r);
    });
    stats(&m)
}

/// The projections on the axis of one epoch's points inside a cylinder, kept for choosing the
/// surface (reused between cylinders: no allocation per core point).
#[derive(Debug, Default, Clone)]
pub struct Projections {
    /// `t[..len]` are the projections; beyond, scratch.
    t: Vec<f64>,
    len: usize,
    h: f64,
}

impl Projections {
    /// Collect the projections of `index`'s points inside the cylinder at `q` (local frame)
    /// with unit axis `n`, radius `r`, half-length `h`.
    pub fn collect(&mut self, index: &Columns, q: &Point3, n: &Point3, r: f64, h: f64) {
        self.h = h;
        let (t, len) = (&mut self.t, &mut self.len);
        // Without a branch on the verdict (about half of the candidates are outside, in no
        // pattern a predictor could learn; measured 17 % faster distances): every candidate is
        // written, and kept by advancing the length only when it is inside.
        *len = 0;
        let cylinder = Cylinder { q, n, r2: r * r, h };
        index.cylinder_candidates(q, n, r, h, |points| {
            if *len + points.len() > t.len() {
                t.resize(2 * (*len + points.len()) + 256, 0.0);
            }
            // Room for the whole run: no check in the loop.
            *len += keep_inside(points, &mut t[*len..*len + points.len()], &cylinder);
        });
    }

    /// The lowest and highest projection ((+∞, −∞) when there is none).
    pub(crate) fn range(&self) -> (f64, f64) {
        range(&self.t[..self.len])
    }

    /// Statistics of the group of projections, split at gaps wider than `gap`, nearest to the
    /// interval `near` (see the module's "one surface per cylinder"), and that group's span.
    /// Sums are exact, so the result does not depend on the order the points were visited in.
    pub fn surface(&mut self, gap: f64, near: (f64, f64)) -> (CylinderStats, (f64, f64)) {
        let t = &mut self.t[..self.len];
        let (lo, hi) = range(t);
        let mut m = Moments1::new(self.h);
        if hi - lo <= gap {
            // One surface (and no points: (+∞, −∞) is its span).
            m.add_all(t);
            return (stats(&m), (lo, hi));
        }
        t.sort_unstable_by(|a, b| a.total_cmp(b));
        let group = &t[nearest_group(t, gap, near)];
        m.add_all(group);
        // Sorted: the group's ends are its span (none, when `near` is itself empty).
        let span = match (group.first(), group.last()) {
            (Some(&a), Some(&b)) => (a, b),
            _ => (f64::INFINITY, f64::NEG_INFINITY),
        };
        (stats(&m), span)
    }
}

/// The lowest and highest of `t` ((+∞, −∞) when empty), in a loop the compiler vectorises
/// (`f64::min`'s NaN rule would keep it scalar; the projections hold no NaN).
fn range(t: &[f64]) -> (f64, f64) {
    t.iter()
        .fold((f64::INFINITY, f64::NEG_INFINITY), |(a, b), &x| {
            (if x < a { x } else { a }, if x > b { x } else { b })
        })
}

/// A cylinder as the exact test takes it ([`in_cylinder`]).
struct Cylinder<'a> {
    q: &'a Point3,
    n: &'a Point3,
    r2: f64,
    h: f64,
}

/// Write into `room` the projections of the `points` inside `c`, in order; how many. Compiled
/// for AVX2 too, chosen when the program runs (four lanes for the test's arithmetic).
#[inline]
fn keep_inside(points: &[Point3], room: &mut [f64], c: &Cylinder) -> usize {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2, checked just above.
            return unsafe { keep_inside_avx2(points, room, c) };
        }
    }
    keep_inside_of(points, room, c)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn keep_inside_avx2(points: &[Point3], room: &mut [f64], c: &Cylinder) -> usize {
    keep_inside_of(points, room, c)
}

#[inline(always)]
fn keep_inside_of(points: &[Point3], room: &mut [f64], c: &Cylinder) -> usize {
    let mut kept = 0;
    for (p, _) in points.iter().zip(0..room.len()) {
        let (along, inside) = in_cylinder(p, c.q, c.n, c.r2, c.h);
        room[kept] = along;
        kept += usize::from(inside);
    }
    kept
}

/// Split the sorted values at gaps wider than `gap`; the index range of the group nearest to
/// the interval `near` (the gap between the two intervals; ties to the earlier group).
pub(crate) fn nearest_group(sorted: &[f64], gap: f64, near: (f64, f64)) -> Range<usize> {
    let mut best = (f64::INFINITY, 0..0);
    let mut start = 0;
    for k in 0..sorted.len() {
        let last = k + 1 == sorted.len() || sorted[k + 1] - sorted[k] > gap;
        if last {
            let (a, b) = (sorted[start], sorted[k]);
            let d = (a - near.1).max(near.0 - b).max(0.0);
            if d < best.0 {
                best = (d, start..k + 1);
            }
            start = k + 1;
        }
    }
    best.1
}

fn stats(m: &Moments1) -> CylinderStats {
    let (mean, var) = m.mean_var();
    CylinderStats {
        count: m.count() as u32,
        mean,
        std_dev: var.sqrt(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pseudo-random points in a box, deterministic.
    fn cloud(n: usize, seed: u64) -> Vec<Point3> {
        let mut rng = crate::rng::Rng::new(seed, 0);
        (0..n)
            .map(|_| {
                let u = [rng.uniform(), rng.uniform(), rng.uniform()];
                [u[0] * 4.0 - 2.0, u[1] * 4.0 - 2.0, u[2] * 8.0 - 4.0]
            })
            .collect()
    }

    #[test]
    fn cylinder_query_equals_the_sphere_query() {
        let pts = cloud(20_000, 7);
        let idx = Columns::new(&pts, [0.0; 3], 0.2);
        for (k, n) in [[0.0, 0.0, 1.0], [0.6, 0.0, 0.8], [0.48, 0.6, 0.64]]
            .iter()
            .enumerate()
        {
            let q = [0.1 * k as f64, -0.2, 0.3];
            for (r, h) in [(0.3, 3.0), (0.5, 0.2), (0.25, 1.1)] {
                let x = cylinder_stats(&idx, &q, n, r, h);
                let y = cylinder_stats_sphere(&idx, &q, n, r, h);
                assert_eq!(x.count, y.count, "r {r} h {h} n {n:?}");
                assert!(x.count > 10);
                assert!((x.mean - y.mean).abs() < 1e-12);
                assert!((x.std_dev - y.std_dev).abs() < 1e-12);
            }
        }
    }

    #[test]
    fn groups_split_at_gaps_and_the_nearest_is_chosen() {
        let t = [-0.02, 0.0, 0.01, 0.03, 2.4, 2.5, 2.7];
        assert_eq!(nearest_group(&t, 0.6, (0.0, 0.0)), 0..4);
        assert_eq!(nearest_group(&t, 0.6, (2.0, 2.2)), 4..7);
        assert_eq!(nearest_group(&t, 3.0, (0.0, 0.0)), 0..7);
        assert_eq!(nearest_group(&[1.0], 0.6, (0.0, 0.0)), 0..1);
    }

    #[test]
    fn a_second_surface_along_the_axis_is_left_out() {
        // A face (the plane y = 0, points every 5 cm) and, 2 m in front of it, a patch of another
        // surface inside the same horizontal cylinder (axis −y).
        let mut pts = Vec::new();
        for i in -20..=20 {
            for k in -20..=20 {
                pts.push([i as f64 * 0.05, 0.0, k as f64 * 0.05]);
            }
        }
        let face_only = Columns::new(&pts, [0.0; 3], 0.2);
        for i in -5..=5 {
            for j in 0..10 {
                pts.push([i as f64 * 0.05, -2.0 - j as f64 * 0.05, -0.2]);
            }
        }
        let idx = Columns::new(&pts, [0.0; 3], 0.2);
        let (q, n, r, h) = ([0.0, 0.0, 0.0], [0.0, -1.0, 0.0], 0.3, 3.0);
        let mut p = Projections::default();
        p.collect(&idx, &q, &n, r, h);
        let (s, span) = p.surface(2.0 * r, (0.0, 0.0));
        let plain = cylinder_stats(&face_only, &q, &n, r, h);
        assert_eq!(s, plain);
        assert_eq!(span, (0.0, 0.0));
        // Without the split the mean moves out to the second surface.
        assert!(cylinder_stats(&idx, &q, &n, r, h).mean > 0.3);
        // Nearer to the second surface's span, that one is chosen.
        p.collect(&idx, &q, &n, r, h);
        assert!(p.surface(2.0 * r, (1.9, 2.0)).0.mean > 2.0);
    }

    #[test]
    fn brute_force_count_and_moments() {
        let pts = cloud(5_000, 11);
        let idx = Columns::new(&pts, [0.0; 3], 0.2);
        let n = [0.0, 0.6, 0.8];
        let q = [0.2, 0.1, -0.4];
        let (r, h) = (0.7, 1.5);
        let mut t: Vec<f64> = Vec::new();
        for p in &pts {
            let v = [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
            let a = v[0] * n[0] + v[1] * n[1] + v[2] * n[2];
            let rad = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2] - a * a).sqrt();
            if a.abs() <= h && rad <= r {
                t.push(a);
            }
        }
        let m = t.iter().sum::<f64>() / t.len() as f64;
        let sd = (t.iter().map(|x| (x - m).powi(2)).sum::<f64>() / t.len() as f64).sqrt();
        let s = cylinder_stats(&idx, &q, &n, r, h);
        assert_eq!(s.count as usize, t.len());
        // The sums are exact on values quantised to 2^-30 (≈ 1 nm): agreement to 1e-9.
        assert!((s.mean - m).abs() < 1e-9 && (s.std_dev - sd).abs() < 1e-9);
    }
}

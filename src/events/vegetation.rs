//! Vegetation from geometry (SPEC.md §4 "geometry for the rest"): whether the points around a
//! location scatter through a volume, as leaves and twigs do, or lie on a surface, as rock and
//! sediment do — however rough.
//!
//! Multi-scale dimensionality (Brodu & Lague 2012, "3D terrestrial lidar data classification of
//! complex natural scenes using a multi-scale dimensionality criterion", ISPRS J. 68): the
//! covariance of the points in balls of several sizes around a location tells whether the
//! neighbourhood is linear, planar or volumetric at each size. Brodu & Lague train a classifier
//! on those features; talus has no training data and uses the features' own meaning instead: with
//! σ₁ ≥ σ₂ ≥ σ₃ the square roots of the covariance's eigenvalues, Demantké et al. 2011
//! ("Dimensionality based scale selection in 3D lidar point clouds", ISPRS Archives XXXVIII-5/W12)
//! define a₁ = (σ₁ − σ₂)/σ₁, a₂ = (σ₂ − σ₃)/σ₁, a₃ = σ₃/σ₁ (they sum to 1), and a neighbourhood is
//! of the dimension whose share is largest.
//!
//! A location looks like vegetation when it is **not planar at two scales**, 4 and 8 point
//! spacings. A surface sampled at spacing s is planar over a few spacings whatever its shape at
//! larger scales: a boulder, a rubble block or a scar's facet is resolved by the scan, so a ball
//! of 4 s on it holds a patch of surface. Leaves and twigs are smaller than the spacing and
//! scattered through the crown: the scan samples them as a cloud, volumetric (or, for stems and
//! grass blades, linear) at every scale the points resolve. Where a rock surface is not planar
//! at 4 s — an edge, a crease between boulders, a corner of a scar — it is at 8 s, or the place
//! is one of few (measured, `tests` below and `tests/vegetation.rs`: boulder beaches, rubble,
//! scree and blocky scars give 0–6 % of their points, shrubs, crowns and grass at terrestrial
//! spacing 77–95 %). An event is vegetation when most of its core points look like it
//! ([`MOST`]); each core point is judged in either epoch, where that epoch's surface is.
//!
//! The moments are exact integer sums (`m3c2::moments`), so the verdict does not depend on the
//! order in which points arrive.

use nalgebra::SymmetricEigen;

use crate::geom::Point3;
use crate::m3c2::moments::Moments3;
use crate::spatial::Columns;

/// The two ball radii, in point spacings (see the module's doc).
pub(crate) const SCALES: [f64; 2] = [4.0, 8.0];

/// Fewer points than this in a ball say nothing of its shape (a plane needs a handful; noise on
/// a few points looks volumetric).
pub(crate) const MIN_POINTS: usize = 10;

/// An event is vegetation when more than this share of its core points look like it.
pub(crate) const MOST: f64 = 0.5;

/// The dimension a neighbourhood shows at one scale.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub(crate) enum Dimension {
    Linear,
    Planar,
    Volumetric,
}

/// Demantké's shares (a₁, a₂, a₃) of a covariance given as its upper triangle (xx xy xz yy yz
/// zz); None when it is not a finite, non-zero covariance.
pub(crate) fn shares(c: &[f64; 6]) -> Option<[f64; 3]> {
    if c.iter().any(|v| !v.is_finite()) {
        return None;
    }
    let mut l: Vec<f64> = SymmetricEigen::new(crate::m3c2::normals::symmetric(c))
        .eigenvalues
        .iter()
        .map(|v| v.max(0.0).sqrt())
        .collect();
    l.sort_by(|a, b| b.total_cmp(a));
    if l[0] <= 0.0 {
        return None;
    }
    Some([(l[0] - l[1]) / l[0], (l[1] - l[2]) / l[0], l[2] / l[0]])
}

/// The dimension of the points of `index` within `radius` of `q` (the index's local frame);
/// None when fewer than [`MIN_POINTS`] lie there.
pub(crate) fn dimension_at(index: &Columns, q: &Point3, radius: f64) -> Option<Dimension> {
    let mut m = Moments3::new(radius);
    let r2 = radius * radius;
    index.sphere_candidates(q, radius, |points| m.add_within(points, q, r2));
    if m.count() < MIN_POINTS {
        return None;
    }
    let a = shares(&m.covariance())?;
    // Ties go to the surface: a place is vegetation only when the points say so.
    Some(if a[1] >= a[0] && a[1] >= a[2] {
        Dimension::Planar
    } else if a[0] > a[2] {
        Dimension::Linear
    } else {
        Dimension::Volumetric
    })
}

/// Whether the points of `index` around `q` (local frame) look like vegetation: not planar at
/// every scale of [`SCALES`] × `spacing`. The largest ball must hold [`MIN_POINTS`]; a smaller
/// one that holds fewer counts as scattered, not as a surface (a surface sampled at the spacing
/// puts about 50 points in a ball of 4 spacings; sparse leaves put a handful).
pub(crate) fn looks_like_vegetation(index: &Columns, q: &Point3, spacing: f64) -> bool {
    let last = SCALES.len() - 1;
    SCALES
        .iter()
        .enumerate()
        .all(|(i, k)| match dimension_at(index, q, k * spacing) {
            Some(d) => d != Dimension::Planar,
            None => i < last,
        })
}

/// The share of `cores` that look like vegetation in either epoch: each is `(where the before
/// surface is, where the after surface is)` in the indexes' local frame (the core point, and the
/// core point moved along its normal by its distance). 0 for no core point.
pub(crate) fn fraction(
    before: &Columns,
    after: &Columns,
    cores: &[(Point3, Point3)],
    spacing: f64,
) -> f64 {
    if cores.is_empty() {
        return 0.0;
    }
    use rayon::prelude::*;
    let n = cores
        .par_iter()
        .filter(|(b, a)| {
            looks_like_vegetation(before, b, spacing) || looks_like_vegetation(after, a, spacing)
        })
        .count();
    n as f64 / cores.len() as f64
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::SplitMix64;

    /// A surface z = f(x, y) over [0, 8]², one point per s² at random, with noise `sd` (a
    /// uniform noise of that standard deviation).
    fn surface(r: &mut SplitMix64, s: f64, sd: f64, f: impl Fn(f64, f64) -> f64) -> Vec<Point3> {
        let n = (64.0 / (s * s)) as usize;
        (0..n)
            .map(|_| {
                let (x, y) = (8.0 * r.uniform(), 8.0 * r.uniform());
                [x, y, f(x, y) + sd * 3f64.sqrt() * (2.0 * r.uniform() - 1.0)]
            })
            .collect()
    }

    /// The share of the points of `pts` selected by `at` that look like vegetation.
    fn share(pts: &[Point3], s: f64, at: impl Fn(&Point3) -> bool) -> f64 {
        let index = Columns::new(pts, [0.0; 3], 4.0 * s);
        let q: Vec<Point3> = pts
            .iter()
            .filter(|p| at(p))
            .step_by(7)
            .map(|p| index.to_local(p))
            .collect();
        q.iter()
            .filter(|p| looks_like_vegetation(&index, p, s))
            .count() as f64
            / q.len() as f64
    }

    fn central(p: &Point3) -> bool {
        (p[0] - 4.0).abs() < 3.0 && (p[1] - 4.0).abs() < 3.0
    }

    /// The top of balls (cx, cy, cz, r) over the plane z = 0.
    fn tops(balls: &[[f64; 4]], x: f64, y: f64) -> f64 {
        balls.iter().fold(0.0, |z, b| {
            let d2 = (x - b[0]).powi(2) + (y - b[1]).powi(2);
            if d2 < b[3] * b[3] {
                z.max(b[2] + (b[3] * b[3] - d2).sqrt())
            } else {
                z
            }
        })
    }

    #[test]
    fn rough_rock_is_a_surface() {
        for (s, sd) in [(0.02, 0.005), (0.1, 0.02)] {
            let mut r = SplitMix64::new(3);
            let boulders: Vec<[f64; 4]> = (0..120)
                .map(|_| {
                    [
                        8.0 * r.uniform(),
                        8.0 * r.uniform(),
                        0.0,
                        0.2 + 0.4 * r.uniform(),
                    ]
                })
                .collect();
            let beach = surface(&mut r, s, sd, |x, y| tops(&boulders, x, y));
            let steps = surface(&mut r, s, sd, |x, y| {
                (x / 0.5).floor() * 0.4 + (y / 0.7).floor() * 0.25
            });
            let plane = surface(&mut r, s, sd, |x, _| 0.7 * x);
            for (name, pts) in [
                ("boulders", &beach),
                ("blocky scar", &steps),
                ("slope", &plane),
            ] {
                let v = share(pts, s, central);
                assert!(v < 0.08, "{name} at spacing {s}: {v}");
            }
        }
    }

    #[test]
    fn a_crown_of_leaves_is_vegetation() {
        for s in [0.02, 0.1] {
            let mut r = SplitMix64::new(5);
            let mut pts = surface(&mut r, s, 0.005, |_, _| 0.0);
            // Leaves of a 2 m crown centred 4.5 m up: mostly its outer half metre.
            let n = (4.0 * std::f64::consts::PI * 4.0 / (s * s)) as usize;
            for _ in 0..n {
                let (u, v) = (2.0 * r.uniform() - 1.0, std::f64::consts::TAU * r.uniform());
                let w = (1.0 - u * u).sqrt();
                let depth = -0.4 * (1.0 - r.uniform()).ln();
                let rad = (2.0 - depth).max(0.0);
                pts.push([
                    4.0 + rad * w * v.cos(),
                    4.0 + rad * w * v.sin(),
                    4.5 + rad * u,
                ]);
            }
            let v = share(&pts, s, |p| p[2] > 2.0);
            assert!(v > 0.8, "crown at spacing {s}: {v}");
        }
    }

    #[test]
    fn shares_of_a_plane_a_line_and_a_ball() {
        let plane = shares(&[1.0, 0.0, 0.0, 1.0, 0.0, 0.0]).unwrap();
        assert!((plane[1] - 1.0).abs() < 1e-12);
        let line = shares(&[1.0, 0.0, 0.0, 0.0, 0.0, 0.0]).unwrap();
        assert!((line[0] - 1.0).abs() < 1e-12);
        let ball = shares(&[1.0, 0.0, 0.0, 1.0, 0.0, 1.0]).unwrap();
        assert!((ball[2] - 1.0).abs() < 1e-12);
        assert!(shares(&[0.0; 6]).is_none());
        assert!(shares(&[f64::NAN; 6]).is_none());
    }

    #[test]
    fn too_few_points_are_not_vegetation() {
        let pts = vec![[0.0, 0.0, 0.0], [0.1, 0.0, 0.3], [0.0, 0.1, -0.2]];
        let index = Columns::new(&pts, [0.0; 3], 0.4);
        assert_eq!(dimension_at(&index, &[0.0; 3], 1.0), None);
        assert!(!looks_like_vegetation(&index, &[0.0; 3], 0.1));
        assert_eq!(fraction(&index, &index, &[], 0.1), 0.0);
    }
}

//! Surface normals at core points by principal component analysis of the neighbourhood.
//!
//! The normal is the eigenvector of the smallest eigenvalue of the covariance of the C1 points
//! within `normal_radius` of the core point (Hoppe et al. 1992, "Surface reconstruction from
//! unorganized points"; the M3C2 normal step of Lague et al. 2013). The covariance is centred on
//! the neighbourhood mean, as CloudCompare, PDAL and py4dgeo do. The sign is left to
//! [`super::orientation`].

use nalgebra::{Matrix3, SymmetricEigen, Vector3};

use super::moments::Moments3;
use crate::geom::Point3;
use crate::spatial::Columns;

/// Fewer neighbours than this leave the normal undefined (a plane needs three points).
pub const MIN_NORMAL_POINTS: usize = 3;

/// Unoriented unit normal at `q` (local frame of `index`) from the points within `radius`, plus
/// the planarity measure λ₀/(λ₀+λ₁+λ₂) (0 = a perfect plane). None when fewer than
/// [`MIN_NORMAL_POINTS`] neighbours exist or the neighbourhood is degenerate.
pub fn normal_at(index: &Columns, q: &Point3, radius: f64) -> Option<(Point3, f64)> {
    // One pass: exact integer moments (see `moments`), so the result does not depend on the
    // order in which the index visits the neighbourhood, and no second query is needed.
    let mut m = Moments3::new(radius);
    let r2 = radius * radius;
    index.sphere_candidates(q, radius, |points| m.add_within(points, q, r2));
    if m.count() < MIN_NORMAL_POINTS {
        return None;
    }
    smallest_eigenvector(&m.covariance())
}

/// The symmetric 3×3 matrix whose upper triangle is `c` (xx xy xz yy yz zz), as
/// [`super::moments::Moments3::covariance`] gives it.
pub fn symmetric(c: &[f64; 6]) -> Matrix3<f64> {
    Matrix3::new(c[0], c[1], c[2], c[1], c[3], c[4], c[2], c[4], c[5])
}

/// The unit eigenvector of the smallest eigenvalue of a symmetric 3×3 matrix given as its upper
/// triangle (xx xy xz yy yz zz), and the ratio λ_min / trace.
pub fn smallest_eigenvector(c: &[f64; 6]) -> Option<(Point3, f64)> {
    let m = symmetric(c);
    let trace = c[0] + c[3] + c[5];
    if trace.is_nan() || trace <= 0.0 || !trace.is_finite() {
        return None;
    }
    let eig = SymmetricEigen::new(m);
    let (imin, lmin) = eig
        .eigenvalues
        .iter()
        .enumerate()
        .min_by(|a, b| a.1.total_cmp(b.1))?;
    let v: Vector3<f64> = eig.eigenvectors.column(imin).into_owned();
    let norm = v.norm();
    if norm.is_nan() || norm <= 0.0 {
        return None;
    }
    let v = v / norm;
    Some(([v.x, v.y, v.z], (lmin.max(0.0)) / trace))
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn plane_normal_is_exact() {
        // Points on the plane z = 0.3 x - 0.2 y: normal ∝ (-0.3, 0.2, 1).
        let mut pts = Vec::new();
        for i in 0..21 {
            for j in 0..21 {
                let x = i as f64 * 0.1 - 1.0;
                let y = j as f64 * 0.1 - 1.0;
                pts.push([x, y, 0.3 * x - 0.2 * y]);
            }
        }
        let idx = Columns::new(&pts, [0.0; 3], 0.25);
        let (n, planarity) = normal_at(&idx, &[0.0, 0.0, 0.0], 0.5).unwrap();
        let e = [-0.3, 0.2, 1.0];
        let en = (0.09f64 + 0.04 + 1.0).sqrt();
        let dot = (n[0] * e[0] + n[1] * e[1] + n[2] * e[2]) / en;
        assert!((dot.abs() - 1.0).abs() < 1e-12, "dot {dot}");
        assert!(planarity < 1e-12);
    }

    #[test]
    fn too_few_points_give_none() {
        let pts = vec![[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
        let idx = Columns::new(&pts, [0.0; 3], 0.25);
        assert!(normal_at(&idx, &[0.0, 0.0, 0.0], 5.0).is_none());
    }
}

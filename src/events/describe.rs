//! Event description (SPEC.md §1 "Event description"; Gorup & Bohak §3.4): statistics of a
//! cluster and its PCA oriented bounding box.
//!
//! OBB: the third axis is the cluster's mean M3C2 normal, the direction its distances were
//! measured along and "out of the terrain" (so below the surface = inside the material). The
//! paper takes PCA's smallest-variance axis instead; for a small or elongated cluster (a dozen
//! core points along a dune foot) the two smaller eigenvalues are about equal and that axis
//! turns at random, up to 65° from the surface normal on the St Leonards beach. The volume stage
//! may extrude along z instead (`box_along`, `crate::volume::axis`). The first two axes are
//! the principal components (Jolliffe 2002) of the points projected on the plane across the
//! third, turned to the cluster's minimum-area rectangle; the first is given a deterministic
//! sign and the second closes a right-handed orthonormal frame. Without usable normals the PCA
//! axes are used. Half extents are half the range of the projections on each axis, the centre
//! the middle of those ranges.

use nalgebra::{Matrix3, SymmetricEigen, Vector3};
use serde::{Deserialize, Serialize};

/// The sign of a change.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Serialize, Deserialize)]
#[serde(rename_all = "lowercase")]
pub enum Kind {
    /// Material gained (smoothed distance > 0).
    Gain,
    /// Material lost (smoothed distance < 0).
    Loss,
}

impl Kind {
    /// Does a smoothed distance belong to this kind? (0 and NaN belong to neither.)
    pub fn matches(self, smoothed: f64) -> bool {
        match self {
            Kind::Gain => smoothed > 0.0,
            Kind::Loss => smoothed < 0.0,
        }
    }
    /// "gain" / "loss", as in the outputs.
    pub(crate) fn as_str(self) -> &'static str {
        match self {
            Kind::Gain => "gain",
            Kind::Loss => "loss",
        }
    }
}

/// Oriented bounding box: `axes` are rows (unit, orthogonal, right-handed), the third one
/// the outward surface normal.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Obb {
    pub center: [f64; 3],
    pub axes: [[f64; 3]; 3],
    pub half_extents: [f64; 3],
}

impl Obb {
    /// Coordinates of a global point in the box frame (u, v, w), relative to the centre.
    pub fn to_local(&self, p: &[f64; 3]) -> [f64; 3] {
        let d = [
            p[0] - self.center[0],
            p[1] - self.center[1],
            p[2] - self.center[2],
        ];
        self.axes.map(|a| a[0] * d[0] + a[1] * d[1] + a[2] * d[2])
    }
    /// The global point of box-frame coordinates (u, v, w).
    #[cfg(test)]
    #[allow(clippy::wrong_self_convention)] // &self: no copy per point mapped
    pub(crate) fn to_global(&self, l: &[f64; 3]) -> [f64; 3] {
        let a = &self.axes;
        std::array::from_fn(|k| self.center[k] + l[0] * a[0][k] + l[1] * a[1][k] + l[2] * a[2][k])
    }
}

/// One change event.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Event {
    pub(crate) id: u32,
    pub(crate) kind: Kind,
    pub n_points: usize,
    pub centroid: [f64; 3],
    /// n_points × core_spacing².
    pub area_m2: f64,
    /// Mean M3C2 distance (signed).
    pub(crate) mean_distance: f64,
    pub max_abs_distance: f64,
    pub mean_lod95: f64,
    pub obb: Obb,
    /// Mean of the cluster's normals, normalised (the outward direction).
    pub(crate) mean_normal: [f64; 3],
}

/// What a description needs of a cluster's LoD95s and normals: their sums over the finite ones,
/// taken in the members' order ([`Sums::add`]), so a caller can add them up as the members go
/// by instead of holding them.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Sums {
    lod: f64,
    lods: usize,
    normal: Vector3<f64>,
}

impl Default for Sums {
    fn default() -> Self {
        Sums {
            lod: 0.0,
            lods: 0,
            normal: Vector3::zeros(),
        }
    }
}

impl Sums {
    /// The next member's LoD95 and normal.
    pub(crate) fn add(&mut self, lod95: f64, normal: &[f64; 3]) {
        if lod95.is_finite() {
            self.lod += lod95;
            self.lods += 1;
        }
        if normal.iter().all(|x| x.is_finite()) {
            self.normal += Vector3::new(normal[0], normal[1], normal[2]);
        }
    }
}

/// Describe a cluster from its core points and their distances, LoD95s and normals (all
/// slices of the same length). `None` for an empty cluster.
pub fn describe(
    id: u32,
    kind: Kind,
    points: &[[f64; 3]],
    distances: &[f64],
    lod95: &[f64],
    normals: &[[f64; 3]],
    core_spacing: f64,
) -> Option<Event> {
    let mut sums = Sums::default();
    for (&l, nm) in lod95.iter().zip(normals) {
        sums.add(l, nm);
    }
    describe_with(id, kind, points, distances, &sums, core_spacing)
}

/// [`describe`] with the members' LoD95s and normals given as their [`Sums`].
pub(crate) fn describe_with(
    id: u32,
    kind: Kind,
    points: &[[f64; 3]],
    distances: &[f64],
    sums: &Sums,
    core_spacing: f64,
) -> Option<Event> {
    let n = points.len();
    if n == 0 {
        return None;
    }
    let nf = n as f64;
    let (centroid, cov) = centroid_cov(points);

    let mn = sums.normal;
    // Without usable normals, "out of the terrain" defaults to up and PCA gives the normal.
    let (mean_normal, axes) = if mn.norm() > 1e-12 {
        let n = mn.normalize();
        (n, normal_axes(&cov, &n))
    } else {
        (Vector3::z(), pca_axes(&cov, &Vector3::z()))
    };
    let obb = fit_box(axes, points, &centroid);

    let finite = |v: &[f64]| -> (f64, usize) {
        v.iter()
            .filter(|x| x.is_finite())
            .fold((0.0, 0), |(s, m), &x| (s + x, m + 1))
    };
    let (sd, nd) = finite(distances);
    let (sl, nl) = (sums.lod, sums.lods);
    Some(Event {
        id,
        kind,
        n_points: n,
        centroid,
        area_m2: nf * core_spacing * core_spacing,
        mean_distance: if nd > 0 { sd / nd as f64 } else { f64::NAN },
        max_abs_distance: distances
            .iter()
            .filter(|x| x.is_finite())
            .fold(0.0, |m, x| m.max(x.abs())),
        mean_lod95: if nl > 0 { sl / nl as f64 } else { f64::NAN },
        obb,
        mean_normal: [mean_normal.x, mean_normal.y, mean_normal.z],
    })
}

/// The box of a cluster with `axis` (unit) as its third axis: the same construction as
/// [`describe`]'s, for another extrusion direction.
pub(crate) fn box_along(points: &[[f64; 3]], axis: [f64; 3]) -> Option<Obb> {
    if points.is_empty() {
        return None;
    }
    let (centroid, cov) = centroid_cov(points);
    let a = Vector3::new(axis[0], axis[1], axis[2]).normalize();
    Some(fit_box(normal_axes(&cov, &a), points, &centroid))
}

/// Centroid and covariance of a non-empty point set. The centroid in two steps (local offsets
/// from the first point) to keep precision with survey coordinates.
fn centroid_cov(points: &[[f64; 3]]) -> ([f64; 3], Matrix3<f64>) {
    let nf = points.len() as f64;
    let o = points[0];
    let mut c = [0.0; 3];
    for p in points {
        for k in 0..3 {
            c[k] += p[k] - o[k];
        }
    }
    let centroid = std::array::from_fn(|k| o[k] + c[k] / nf);
    let mut cov = Matrix3::<f64>::zeros();
    for p in points {
        let d = Vector3::new(p[0] - centroid[0], p[1] - centroid[1], p[2] - centroid[2]);
        cov += d * d.transpose();
    }
    (centroid, cov / nf)
}

/// The box of `points` with the third of `axes` kept and the first two turned to the
/// minimum-area rectangle.
fn fit_box(axes: [Vector3<f64>; 3], points: &[[f64; 3]], centroid: &[f64; 3]) -> Obb {
    // The in-plane axes: PCA's are arbitrary for a square or round cluster (two equal
    // eigenvalues), and a box turned 45° grows its footprint's corners into the neighbours.
    // Keep the third axis and turn the first two to the cluster's minimum-area rectangle.
    let axes = tighten_in_plane(axes, points, centroid);
    // Extents of the projections.
    let mut lo = [f64::INFINITY; 3];
    let mut hi = [f64::NEG_INFINITY; 3];
    for p in points {
        let d = Vector3::new(p[0] - centroid[0], p[1] - centroid[1], p[2] - centroid[2]);
        for k in 0..3 {
            let t = axes[k].dot(&d);
            lo[k] = lo[k].min(t);
            hi[k] = hi[k].max(t);
        }
    }
    let mid: [f64; 3] = std::array::from_fn(|k| 0.5 * (lo[k] + hi[k]));
    let center = std::array::from_fn(|k| {
        centroid[k] + mid[0] * axes[0][k] + mid[1] * axes[1][k] + mid[2] * axes[2][k]
    });
    Obb {
        center,
        axes: axes.map(|a| [a.x, a.y, a.z]),
        half_extents: std::array::from_fn(|k| 0.5 * (hi[k] - lo[k])),
    }
}

/// Turn the first two axes about the third to the minimum-area enclosing rectangle of the points
/// projected on their plane (Freeman & Shapira 1975: one side of that rectangle lies on an edge
/// of the convex hull; rotating calipers, Toussaint 1983).
fn tighten_in_plane(
    axes: [Vector3<f64>; 3],
    points: &[[f64; 3]],
    centroid: &[f64; 3],
) -> [Vector3<f64>; 3] {
    let pts: Vec<[f64; 2]> = points
        .iter()
        .map(|p| {
            let d = Vector3::new(p[0] - centroid[0], p[1] - centroid[1], p[2] - centroid[2]);
            [axes[0].dot(&d), axes[1].dot(&d)]
        })
        .collect();
    let hull = convex_hull(pts);
    if hull.len() < 3 {
        return axes;
    }
    // (area, cos, sin, extent along the side, extent across it) of the smallest rectangle. The
    // hull's extremes are the points' extremes, so the hull alone measures every rectangle.
    let mut best = (f64::INFINITY, 1.0, 0.0, 0.0, 0.0);
    for i in 0..hull.len() {
        let (a, b) = (hull[i], hull[(i + 1) % hull.len()]);
        let (dx, dy) = (b[0] - a[0], b[1] - a[1]);
        let len = (dx * dx + dy * dy).sqrt();
        if len <= 0.0 {
            continue;
        }
        let (c, s) = (dx / len, dy / len);
        let (du, dv) = extent(&hull, c, s);
        // Prefer the PCA orientation unless the rectangle is really smaller (stable for
        // elongated clusters, where PCA already gives the long side).
        if du * dv < best.0 * (1.0 - 1e-9) {
            best = (du * dv, c, s, du, dv);
        }
    }
    let (pu, pv) = extent(&hull, 1.0, 0.0);
    if best.0.is_nan() || best.0 >= pu * pv * 0.999 {
        return axes;
    }
    let (_, c, s, du, dv) = best;
    let e3 = axes[2];
    let e1 = axes[0] * c + axes[1] * s;
    // Of the rectangle's two side directions take the longer as the first axis.
    close_frame(if dv > du { e3.cross(&e1) } else { e1 }, e3)
}

/// Extents (along, across) of `pts` in the direction (c, s) and its perpendicular.
fn extent(pts: &[[f64; 2]], c: f64, s: f64) -> (f64, f64) {
    let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
    for p in pts {
        let u = c * p[0] + s * p[1];
        let v = -s * p[0] + c * p[1];
        lo = [lo[0].min(u), lo[1].min(v)];
        hi = [hi[0].max(u), hi[1].max(v)];
    }
    (hi[0] - lo[0], hi[1] - lo[1])
}

/// A right-handed frame from a first axis and the third: the first axis made deterministic in
/// sign (its largest component positive), re-orthogonalised to the third, the second closing
/// the frame.
fn close_frame(e1: Vector3<f64>, e3: Vector3<f64>) -> [Vector3<f64>; 3] {
    let imax = (0..3)
        .max_by(|&a, &b| e1[a].abs().total_cmp(&e1[b].abs()))
        .unwrap_or(0);
    let e1 = if e1[imax] < 0.0 { -e1 } else { e1 };
    let e1 = (e1 - e3 * e3.dot(&e1)).normalize();
    [e1, e3.cross(&e1), e3]
}

/// Convex hull (Andrew's monotone chain), counter-clockwise, without collinear points.
fn convex_hull(mut p: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    p.sort_by(|a, b| a[0].total_cmp(&b[0]).then(a[1].total_cmp(&b[1])));
    p.dedup();
    if p.len() < 3 {
        return p;
    }
    let cross = |o: [f64; 2], a: [f64; 2], b: [f64; 2]| {
        (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])
    };
    let mut h: Vec<[f64; 2]> = Vec::with_capacity(2 * p.len());
    for &q in &p {
        while h.len() >= 2 && cross(h[h.len() - 2], h[h.len() - 1], q) <= 0.0 {
            h.pop();
        }
        h.push(q);
    }
    let lower = h.len() + 1;
    for &q in p.iter().rev().skip(1) {
        while h.len() >= lower && cross(h[h.len() - 2], h[h.len() - 1], q) <= 0.0 {
            h.pop();
        }
        h.push(q);
    }
    // The upper chain ends where the lower one started.
    h.pop();
    h
}

/// Right-handed axes with `normal` as the third and the principal direction of the covariance
/// across it as the first.
fn normal_axes(cov: &Matrix3<f64>, normal: &Vector3<f64>) -> [Vector3<f64>; 3] {
    let p = Matrix3::identity() - normal * normal.transpose();
    let eig = SymmetricEigen::new(p * cov * p);
    let first = (0..3)
        .max_by(|&a, &b| eig.eigenvalues[a].total_cmp(&eig.eigenvalues[b]))
        .unwrap_or(0);
    let e1 = eig.eigenvectors.column(first).into_owned();
    // A cluster of one point (or all on the normal's line) has no direction across it.
    let e1 = if (e1 - normal * normal.dot(&e1)).norm() > 1e-9 {
        e1
    } else if normal.x.abs() < 0.9 {
        Vector3::x()
    } else {
        Vector3::y()
    };
    close_frame(e1, *normal)
}

/// Right-handed PCA axes: decreasing variance, third axis agreeing with `outward`.
fn pca_axes(cov: &Matrix3<f64>, outward: &Vector3<f64>) -> [Vector3<f64>; 3] {
    let eig = SymmetricEigen::new(*cov);
    let mut order = [0usize, 1, 2];
    order.sort_by(|&a, &b| eig.eigenvalues[b].total_cmp(&eig.eigenvalues[a]));
    let col = |i: usize| -> Vector3<f64> { eig.eigenvectors.column(order[i]).into_owned() };
    let e3 = col(2);
    let e3 = if e3.dot(outward) < 0.0 { -e3 } else { e3 };
    // The solver's vectors are orthogonal to rounding: close_frame re-orthonormalises.
    close_frame(col(0), e3)
}

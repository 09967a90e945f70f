//! Surfaces as height fields w(u, v) in the event frame.
//!
//! [`Tin`]: the 2.5-D Delaunay triangulation (Delaunay 1934; spade's incremental/bulk
//! algorithm with robust predicates, Shewchuk 1997) of an epoch's points projected on the
//! (u, v) plane, heights w linearly interpolated inside each triangle. Robust predicates
//! keep the near-degenerate triangles that vertical walls produce (their points project onto
//! a line) valid, and the interpolation never divides by a triangle's area on the exact
//! volume path (see [`super::solid`]).
//!
//! Outside the data's convex hull a TIN has no height: nothing is extrapolated (SPEC.md §1
//! "Coverage"; the region of an event keeps only what both epochs cover).

use spade::{
    DelaunayTriangulation, FloatTriangulation, HasPosition, HierarchyHintGenerator, Point2,
    Triangulation,
};

use crate::error::{Error, Result};

/// A surface that gives a height along the frame's w axis at (u, v).
pub trait Surface: Sync {
    /// The height at (u, v), or `None` where the surface has none.
    fn height_at(&self, u: f64, v: f64) -> Option<f64>;
}

/// A TIN vertex: position in (u, v), height w.
#[derive(Debug, Clone, Copy)]
struct Vertex {
    p: Point2<f64>,
    w: f64,
}

impl HasPosition for Vertex {
    type Scalar = f64;
    fn position(&self) -> Point2<f64> {
        self.p
    }
}

/// spade rejects |x| < 1.8e-43 other than 0 (subnormal trouble in its predicates).
fn snap(x: f64) -> f64 {
    if x.abs() < 1e-30 {
        0.0
    } else {
        x
    }
}

/// 2.5-D triangulated surface of local points (u, v, w).
pub struct Tin {
    tri: Tri,
}

/// The triangulation, with a hierarchy of coarser ones to find the triangle of a point in
/// logarithmic time from anywhere: the region's heights are asked for by several threads at
/// once, and with the default hint (the last vertex found, shared by all threads) each query
/// walked from wherever another thread had been (a quarter of the volumes' time).
type Tri = DelaunayTriangulation<Vertex, (), (), (), HierarchyHintGenerator<f64>>;

impl std::fmt::Debug for Tin {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "Tin({} vertices)", self.tri.num_vertices())
    }
}

impl Tin {
    /// Triangulate local points (non-finite ones skipped). Points at an identical (u, v)
    /// keep one height (spade merges duplicates). Fails when the points do not span a
    /// triangle (fewer than 3, or all collinear in (u, v)).
    pub fn new(local: &[[f64; 3]]) -> Result<Self> {
        let verts: Vec<Vertex> = local
            .iter()
            .filter(|p| p.iter().all(|x| x.is_finite()))
            .map(|p| Vertex {
                p: Point2::new(snap(p[0]), snap(p[1])),
                w: p[2],
            })
            .collect();
        let tri = Tri::bulk_load(verts)
            .map_err(|e| Error::Epochs(format!("cannot triangulate surface: {e:?}")))?;
        if tri.num_inner_faces() == 0 {
            return Err(Error::Epochs(format!(
                "surface has {} points not spanning a triangle",
                tri.num_vertices()
            )));
        }
        Ok(Tin { tri })
    }

    /// Is (u, v) inside the triangulated area (the convex hull of the points)?
    pub fn contains(&self, u: f64, v: f64) -> bool {
        self.height_at(u, v).is_some()
    }

    /// Vertices (u, v, w) by spade's fixed index, and the triangles (counter-clockwise in
    /// (u, v), i.e. facing +w).
    pub fn mesh(&self) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
        let verts = self
            .tri
            .vertices()
            .map(|v| {
                let d = v.data();
                [d.p.x, d.p.y, d.w]
            })
            .collect();
        let faces = self
            .tri
            .inner_faces()
            .map(|f| f.vertices().map(|v| v.fix().index() as u32))
            .collect();
        (verts, faces)
    }

    /// Number of vertices.
    pub fn len(&self) -> usize {
        self.tri.num_vertices()
    }

    /// True when empty (never, for a constructed TIN).
    pub fn is_empty(&self) -> bool {
        self.tri.num_vertices() == 0
    }
}

impl Surface for Tin {
    /// Linear (barycentric) interpolation inside the hull, None outside.
    fn height_at(&self, u: f64, v: f64) -> Option<f64> {
        let p = Point2::new(snap(u), snap(v));
        self.tri.barycentric().interpolate(|h| h.data().w, p)
    }
}

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

use std::cell::Cell;
use std::sync::atomic::{AtomicU64, Ordering};

use spade::handles::FixedVertexHandle;
use spade::{
    DelaunayTriangulation, FloatTriangulation, HasPosition, HintGenerator, Point2, Triangulation,
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
    tri: DelaunayTriangulation<Vertex, (), (), (), ThreadHint>,
}

thread_local! {
    /// Each thread's last vertex found, with the TIN it belongs to: the search for the next
    /// point's triangle starts there. The heights of a region are asked for row by row by
    /// several threads at once: with spade's own hint (the last vertex found by any thread)
    /// each search walked from where another thread had been, across the surface (half of the
    /// volumes' time at 120M).
    /// A slot per TIN id modulo [`SLOTS`]: the two epochs' TINs of an event are asked in turn.
    static HINT: [Cell<(u64, Option<FixedVertexHandle>)>; SLOTS] =
        const { [const { Cell::new((0, None)) }; SLOTS] };
}

/// Hint slots per thread.
const SLOTS: usize = 4;

/// Ids of the TINs made.
static TINS: AtomicU64 = AtomicU64::new(1);

/// spade's hint generator with a hint per thread ([`HINT`]) instead of one shared by all.
struct ThreadHint {
    /// Tells this TIN's hints from another's in a thread's [`HINT`].
    id: u64,
}

impl Default for ThreadHint {
    fn default() -> Self {
        ThreadHint {
            id: TINS.fetch_add(1, Ordering::Relaxed),
        }
    }
}

impl ThreadHint {
    fn slot(&self) -> usize {
        (self.id % SLOTS as u64) as usize
    }
    fn set(&self, vertex: Option<FixedVertexHandle>) {
        HINT.with(|h| h[self.slot()].set((self.id, vertex)));
    }
}

impl HintGenerator<f64> for ThreadHint {
    fn get_hint(&self, _: Point2<f64>) -> FixedVertexHandle {
        match HINT.with(|h| h[self.slot()].get()) {
            (id, Some(v)) if id == self.id => v,
            _ => FixedVertexHandle::from_index(0),
        }
    }
    fn notify_vertex_lookup(&self, vertex: FixedVertexHandle) {
        self.set(Some(vertex));
    }
    fn notify_vertex_inserted(&mut self, vertex: FixedVertexHandle, _: Point2<f64>) {
        self.set(Some(vertex));
    }
    fn notify_vertex_removed(
        &mut self,
        _: Option<Point2<f64>>,
        _: FixedVertexHandle,
        _: Point2<f64>,
    ) {
        // The handles may have moved: start the next search anywhere.
        self.set(None);
    }
    fn initialize_from_triangulation<TR, V>(_: &TR) -> Self
    where
        TR: Triangulation,
        V: HasPosition<Scalar = f64>,
    {
        Self::default()
    }
}

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
        let tri = DelaunayTriangulation::bulk_load(verts)
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
    /// Linear (barycentric) interpolation inside the hull, None outside (the search for the
    /// point's triangle starting from this thread's last vertex found, [`ThreadHint`]).
    fn height_at(&self, u: f64, v: f64) -> Option<f64> {
        let p = Point2::new(snap(u), snap(v));
        self.tri.barycentric().interpolate(|h| h.data().w, p)
    }
}

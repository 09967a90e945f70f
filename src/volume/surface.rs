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

use super::region::Cells;
use crate::error::{Error, Result};
use crate::geom::Bounds;

/// A surface that gives a height along the frame's w axis at (u, v).
pub trait Surface: Sync {
    /// The height at (u, v), or `None` where the surface has none.
    fn height_at(&self, u: f64, v: f64) -> Option<f64>;

    /// The heights at every point of `lattice`, row by row, NaN where the surface has none:
    /// [`Surface::height_at`] at each point (rows in parallel) unless a surface knows a faster
    /// way ([`Tin`]'s scan of its triangles).
    fn heights_on(&self, lattice: &Lattice) -> Vec<f64> {
        use rayon::prelude::*;
        (0..lattice.nv)
            .into_par_iter()
            .flat_map_iter(|j| {
                (0..lattice.nu).map(move |i| {
                    let (u, v) = lattice.point(i, j);
                    self.height_at(u, v).unwrap_or(f64::NAN)
                })
            })
            .collect()
    }
}

/// The points (u0 + i·du, v0 + j·dv), i < nu, j < nv, row by row: the places a region's heights
/// are asked for (cell corners, cell centres, sub-cell midpoints).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Lattice {
    pub(crate) u0: f64,
    pub(crate) du: f64,
    pub(crate) nu: usize,
    pub(crate) v0: f64,
    pub(crate) dv: f64,
    pub(crate) nv: usize,
}

impl Lattice {
    /// Point (i, j).
    pub(crate) fn point(&self, i: usize, j: usize) -> (f64, f64) {
        (self.u0 + i as f64 * self.du, self.v0 + j as f64 * self.dv)
    }

    /// Number of points.
    pub(crate) fn len(&self) -> usize {
        self.nu * self.nv
    }

    /// The corners of the cells of `c`: (nu + 1) × (nv + 1).
    pub(crate) fn nodes(c: &Cells) -> Lattice {
        let (du, dv) = c.pitch();
        Lattice {
            u0: c.r.u0,
            du,
            nu: c.nu + 1,
            v0: c.r.v0,
            dv,
            nv: c.nv + 1,
        }
    }

    /// The centres of the cells of `c`, row by row as the cells.
    pub(crate) fn centres(c: &Cells) -> Lattice {
        Lattice::within(c, 1, 0..c.nv)
    }

    /// The centres of the `k × k` sub-cells of each cell of `c` in rows `rows`: k·nu points a
    /// row, k rows a row of cells.
    pub(crate) fn within(c: &Cells, k: usize, rows: std::ops::Range<usize>) -> Lattice {
        let (du, dv) = c.pitch();
        let (du, dv) = (du / k as f64, dv / k as f64);
        Lattice {
            u0: c.r.u0 + 0.5 * du,
            du,
            nu: c.nu * k,
            v0: c.r.v0 + (rows.start * k) as f64 * dv + 0.5 * dv,
            dv,
            nv: rows.len() * k,
        }
    }

    /// The indices (inclusive, clamped) of the points along one axis within [lo, hi] and a
    /// billionth of a step either side (the caller's test decides those): rounding here must not
    /// lose a point on the edge. None when there are none.
    fn span(lo: f64, hi: f64, o: f64, d: f64, n: usize) -> Option<(usize, usize)> {
        const HAIR: f64 = 1e-9;
        let a = ((lo - o) / d - HAIR).ceil();
        let b = ((hi - o) / d + HAIR).floor();
        if n == 0 || a.is_nan() || b.is_nan() || a > b || b < 0.0 || a > (n - 1) as f64 {
            return None;
        }
        Some((a.max(0.0) as usize, b.min((n - 1) as f64) as usize))
    }
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
    pub(crate) fn new(local: &[[f64; 3]]) -> Result<Self> {
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

    /// Vertices (u, v, w) by spade's fixed index, and the triangles (counter-clockwise in
    /// (u, v), i.e. facing +w).
    pub(crate) fn mesh(&self) -> (Vec<[f64; 3]>, Vec<[u32; 3]>) {
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
}

impl Surface for Tin {
    /// Linear (barycentric) interpolation inside the hull, None outside (the search for the
    /// point's triangle starting from this thread's last vertex found, `ThreadHint`).
    fn height_at(&self, u: f64, v: f64) -> Option<f64> {
        let p = Point2::new(snap(u), snap(v));
        self.tri.barycentric().interpolate(|h| h.data().w, p)
    }

    /// Each triangle in turn writes the linear interpolation at the lattice points it covers
    /// (a scan conversion: no search for each point's triangle, which was a third of the
    /// volumes' time). The inside test is by edge functions computed from each edge's
    /// lower-numbered vertex, so the two triangles of an edge test a point against it with
    /// exactly opposite signs: a point is inside one, or on the edge and inside both (the first
    /// triangle scanned gives it its height); none falls between them. Inside the hull every
    /// point gets a height, outside none, as [`Surface::height_at`] says.
    fn heights_on(&self, lattice: &Lattice) -> Vec<f64> {
        let mut out = vec![f64::NAN; lattice.len()];
        // Edge function of the directed edge a → b at p, antisymmetric in (a, b) bit for bit.
        let edge = |a: (usize, [f64; 3]), b: (usize, [f64; 3]), p: (f64, f64)| -> f64 {
            let (lo, hi, sign) = if a.0 < b.0 {
                (a.1, b.1, 1.0)
            } else {
                (b.1, a.1, -1.0)
            };
            sign * ((hi[0] - lo[0]) * (p.1 - lo[1]) - (hi[1] - lo[1]) * (p.0 - lo[0]))
        };
        for f in self.tri.inner_faces() {
            let t = f.vertices().map(|v| {
                let d = v.data();
                (v.fix().index(), [d.p.x, d.p.y, d.w])
            });
            let b = Bounds::of(t.iter().map(|x| &x.1));
            let l = lattice;
            let (Some((i0, i1)), Some((j0, j1))) = (
                Lattice::span(b.min[0], b.max[0], l.u0, l.du, l.nu),
                Lattice::span(b.min[1], b.max[1], l.v0, l.dv, l.nv),
            ) else {
                continue;
            };
            for j in j0..=j1 {
                for i in i0..=i1 {
                    let k = j * l.nu + i;
                    if !out[k].is_nan() {
                        continue;
                    }
                    let (u, v) = l.point(i, j);
                    let p = (snap(u), snap(v));
                    // Counter-clockwise: each is twice the area of the sub-triangle opposite
                    // its vertex, all ≥ 0 inside.
                    let e = [
                        edge(t[1], t[2], p),
                        edge(t[2], t[0], p),
                        edge(t[0], t[1], p),
                    ];
                    if e.iter().any(|&x| x < 0.0 || x.is_nan()) {
                        continue;
                    }
                    let area = e[0] + e[1] + e[2];
                    out[k] = if area > 0.0 {
                        (e[0] * t[0].1[2] + e[1] * t[1].1[2] + e[2] * t[2].1[2]) / area
                    } else {
                        (t[0].1[2] + t[1].1[2] + t[2].1[2]) / 3.0
                    };
                }
            }
        }
        out
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The scan of a TIN's triangles against a search for each point's triangle, on a rough TIN
    /// and a lattice reaching past its hull, through vertices and along edges: the same points
    /// have a height, and the same height.
    #[test]
    fn heights_on_a_lattice_are_the_heights_at_its_points() {
        let mut rng = crate::rng::SplitMix64::new(42);
        let mut pts: Vec<[f64; 3]> = (0..3000)
            .map(|_| {
                [
                    rng.range(-3.0, 3.0),
                    rng.range(-2.0, 2.0),
                    rng.range(0.0, 1.5),
                ]
            })
            .collect();
        // Points on the lattice's own lines: lattice points on TIN vertices and edges.
        pts.extend((0..40).map(|k| [-1.0 + 0.05 * k as f64, 0.25, rng.range(0.0, 1.5)]));
        let tin = Tin::new(&pts).unwrap();
        let lattice = Lattice {
            u0: -3.5,
            du: 0.05,
            nu: 141,
            v0: -2.5,
            dv: 0.0625,
            nv: 81,
        };
        let got = tin.heights_on(&lattice);
        let (mut inside, mut outside) = (0, 0);
        for j in 0..lattice.nv {
            for i in 0..lattice.nu {
                let (u, v) = lattice.point(i, j);
                let h = got[j * lattice.nu + i];
                match tin.height_at(u, v) {
                    Some(w) => {
                        inside += 1;
                        assert!((h - w).abs() < 1e-9, "({u}, {v}): {h} vs {w}");
                    }
                    None => {
                        outside += 1;
                        assert!(h.is_nan(), "({u}, {v}): {h} outside the hull");
                    }
                }
            }
        }
        assert!(
            inside > 5000 && outside > 1000,
            "{inside} inside, {outside} outside"
        );
    }
}

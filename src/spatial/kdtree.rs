//! The kd-tree index: kiddo 6 over coordinates relative to a local origin.

use std::num::NonZeroUsize;

use kiddo::{ImmutableKdTree, SquaredEuclidean};

use crate::geom::Point3;

/// An indexed point set. Points are stored relative to `origin`; query points must be given in
/// the same local frame (see [`Index::to_local`]).
pub struct Index {
    origin: Point3,
    points: Vec<Point3>,
    tree: ImmutableKdTree<f64, 3>,
}

impl Index {
    /// Index `points` (global coordinates) in a frame centred on `origin`.
    pub fn new(points: &[Point3], origin: Point3) -> Self {
        let local: Vec<Point3> = points
            .iter()
            .map(|p| [p[0] - origin[0], p[1] - origin[1], p[2] - origin[2]])
            .collect();
        Self::from_local(local, origin)
    }

    /// Index points already expressed relative to `origin`.
    pub(crate) fn from_local(points: Vec<Point3>, origin: Point3) -> Self {
        // kiddo refuses an empty slice; an index over nothing answers every query with nothing.
        let tree = if points.is_empty() {
            ImmutableKdTree::new_from_slice(&[[f64::MAX; 3]]).expect("one point always builds")
        } else {
            // Parallel construction on the current rayon pool above kiddo's size threshold; it
            // builds the same tree as the sequential algorithm.
            ImmutableKdTree::new_from_slice_parallel(&points).expect("finite points always build")
        };
        Index {
            origin,
            points,
            tree,
        }
    }

    /// The indexed points, local coordinates.
    pub(crate) fn points(&self) -> &[Point3] {
        &self.points
    }

    /// A global point in this index's local frame.
    pub fn to_local(&self, p: &Point3) -> Point3 {
        [
            p[0] - self.origin[0],
            p[1] - self.origin[1],
            p[2] - self.origin[2],
        ]
    }

    /// Call `f(index, squared distance)` for every point within `radius` of `q` (local frame),
    /// boundary included, in no particular order.
    #[inline]
    pub fn for_each_within(&self, q: &Point3, radius: f64, mut f: impl FnMut(usize, f64)) {
        if self.points.is_empty() {
            return;
        }
        self.tree
            .query(q)
            .within::<SquaredEuclidean<f64>>(radius * radius)
            .unsorted()
            .visit(|it| f(it.item as usize, it.distance));
    }

    /// The nearest point to `q` (local frame) as (index, squared distance); None when nothing is
    /// indexed. No allocation (a per-point lookup of the volume gather).
    pub(crate) fn nearest_one(&self, q: &Point3) -> Option<(usize, f64)> {
        if self.points.is_empty() {
            return None;
        }
        let it = self
            .tree
            .query(q)
            .nearest_one::<SquaredEuclidean<f64>>()
            .execute();
        Some((it.item as usize, it.distance))
    }

    /// The `k` nearest points to `q` (local frame) as (index, squared distance), nearest first;
    /// ties keep kiddo's order, then we sort by (distance, index) for determinism.
    pub fn nearest(&self, q: &Point3, k: usize) -> Vec<(usize, f64)> {
        let Some(k) = NonZeroUsize::new(k.min(self.points.len())) else {
            return Vec::new();
        };
        let mut out: Vec<(usize, f64)> = self
            .tree
            .query(q)
            .nearest_n::<SquaredEuclidean<f64>>(k)
            .execute()
            .into_iter()
            .map(|it| (it.item as usize, it.distance))
            .collect();
        out.sort_by(|a, b| a.1.total_cmp(&b.1).then(a.0.cmp(&b.0)));
        out
    }
}

//! Change events: from per-core-point M3C2 distances to described clusters (SPEC.md §1
//! "Significance filter" to "Event description", §3 "Clusters").
//!
//! The stages, one module each, all pure functions on in-memory slices (the caller streams
//! tiles and writes outputs):
//! [`filter`] (keep significant points) → [`smooth`] (normalised Gaussian smoothing of the
//! distances over the k nearest kept neighbours) → [`dbscan`] (signed DBSCAN, tile-mergeable
//! through the global `union_find`) → [`describe`](fn@describe) (centroid, statistics, PCA box).
//! [`blocks`] runs smoothing and DBSCAN over a pair's kept points a cube of space at a time;
//! [`pieces`], a piece of space at a time when they are more than the budget holds.

pub(crate) mod align;
pub mod blocks;
pub(crate) mod chain;
pub mod dbscan;
pub mod describe;
pub mod filter;
pub mod pieces;
pub mod smooth;
pub(crate) mod stable;
pub(crate) mod union_find;
pub(crate) mod vegetation;

pub use describe::{describe, Event, Kind, Obb};

use crate::error::{Error, Result};
use kiddo::ImmutableKdTree;

/// A kd-tree over 3-D points; items are indices into the slice it was built from.
pub(crate) type Tree3 = ImmutableKdTree<f64, 3>;

/// Coordinates relative to `origin`: survey coordinates (UTM, 10⁶ m) would lose precision in
/// squared distances, local ones keep it.
pub(crate) fn relative(points: &[[f64; 3]], origin: [f64; 3]) -> Vec<[f64; 3]> {
    points.iter().map(|p| local(p, &origin)).collect()
}

/// One point relative to `origin` (the arithmetic of [`relative`]).
pub(crate) fn local(p: &[f64; 3], origin: &[f64; 3]) -> [f64; 3] {
    [p[0] - origin[0], p[1] - origin[1], p[2] - origin[2]]
}

/// The first point (a local origin for [`relative`]), or zero for an empty slice.
pub(crate) fn origin_of(points: &[[f64; 3]]) -> [f64; 3] {
    points.first().copied().unwrap_or([0.0; 3])
}

/// Build a kd-tree over local coordinates. Fails only beyond u32::MAX points per tile.
pub(crate) fn build_tree(local: &[[f64; 3]]) -> Result<Tree3> {
    Tree3::new_from_slice(local)
        .map_err(|e| Error::Internal(format!("kd-tree construction failed: {e:?}")))
}

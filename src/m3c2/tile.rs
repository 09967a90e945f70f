//! M3C2 for the core points one tile owns, from the points of both epochs the tile holds (its
//! square and halo): index both, thin C1 to the tile's core points (or take the user's), normals,
//! distances. A pure function of its inputs.
//!
//! Every tile uses the same local frame (the core-point anchor), not one of its own: the local
//! coordinates, and so every rounding in the sums and the top-surface cells of `auto`
//! orientation, are then the same whatever the tiling, and a tiled run gives the bytes of a
//! whole-cloud run.

use super::{core_points, CoreResult, Extent, M3c2Params};
use crate::geom::Point3;
use crate::spatial::Columns;

/// One epoch's points in a tile (as the tile file holds them: a column per coordinate), with
/// whether the tile owns each.
pub struct EpochPoints<'a> {
    pub x: &'a [f64],
    pub y: &'a [f64],
    pub z: &'a [f64],
    pub owned: &'a [bool],
}

impl EpochPoints<'_> {
    pub(crate) fn len(&self) -> usize {
        self.owned.len()
    }
    /// Point `i`.
    #[inline]
    pub(crate) fn point(&self, i: usize) -> Point3 {
        [self.x[i], self.y[i], self.z[i]]
    }

    /// The core points the tile owns ([`core_points::thin`] on the grid anchored at `anchor`
    /// with cells of `core_spacing`), with their cell keys.
    pub(crate) fn core_points(&self, anchor: &Point3, core_spacing: f64) -> Vec<(u64, Point3)> {
        core_points::thin(
            self.len(),
            |i| self.point(i),
            anchor,
            core_spacing,
            |i| self.owned[i],
        )
        .into_iter()
        .map(|(k, i)| (k, self.point(i)))
        .collect()
    }
}

/// One core point's result with its global sort key.
#[derive(Debug, Clone, Copy)]
pub struct KeyedResult {
    pub(crate) key: u64,
    pub(crate) xyz: Point3,
    pub r: CoreResult,
}

/// Normals and M3C2 at the core points the tile owns — C1 thinned on the grid anchored at
/// `anchor` with cells of `core_spacing` (keyed by cell), or the user's `cores` (keyed by input
/// order) — sorted by key. `extent` (global coordinates) holds the data's bounds and the tile's
/// halo box: a core point whose walk (`super::reach`) needs points beyond that box comes back
/// [`Reach::Pending`](super::Reach::Pending), for `distances_along`. `field` is the before
/// survey's orientation field near the tile (`auto` orientation).
#[allow(clippy::too_many_arguments)]
pub fn compute(
    before: &EpochPoints,
    after: &EpochPoints,
    anchor: Point3,
    core_spacing: f64,
    cores: Option<&[(u64, Point3)]>,
    params: &M3c2Params,
    extent: &Extent,
    field: Option<&super::field::Field>,
) -> Vec<KeyedResult> {
    let cell = super::column_width(params);
    let index = |t: &EpochPoints| Columns::from_fn(t.len(), |i| t.point(i), anchor, cell);
    let (b, a) = rayon::join(|| index(before), || index(after));
    let keyed: Vec<(u64, Point3)> = match cores {
        Some(c) => c.to_vec(),
        None => before.core_points(&anchor, core_spacing),
    };
    if keyed.is_empty() {
        return Vec::new();
    }
    let local: Vec<Point3> = keyed.iter().map(|(_, p)| b.to_local(p)).collect();
    let n = super::normals(&b, &local, params, field);
    let results = super::distances(
        &b,
        &a,
        &local,
        &n.normal,
        &n.surface,
        params,
        &extent.local(&anchor),
    );
    keyed_by(&keyed, results, &n.known)
}

/// The results at the core points `keyed` (key, global position), with whether each normal's
/// sign is known, sorted by key.
pub(super) fn keyed_by(
    keyed: &[(u64, Point3)],
    results: Vec<CoreResult>,
    known: &[bool],
) -> Vec<KeyedResult> {
    let mut out: Vec<KeyedResult> = keyed
        .iter()
        .zip(results)
        .zip(known)
        .map(|((&(key, xyz), r), &sign_known)| KeyedResult {
            key,
            xyz,
            r: CoreResult { sign_known, ..r },
        })
        .collect();
    out.sort_by_key(|k| k.key);
    out
}

/// M3C2 again at core points whose walk left their tile ([`super::Reach::Pending`]): `before`
/// and `after` hold every point of each epoch within the cylinder's radius of those core points'
/// axes, out to the data's bounds (`extent`, global coordinates), and the normals (and whether
/// their signs are known) are the ones the tile computed. The result is the one a run over the whole surveys gives.
pub(crate) fn distances_along(
    before: &[Point3],
    after: &[Point3],
    anchor: Point3,
    pending: &[KeyedResult],
    params: &M3c2Params,
    extent: &Extent,
) -> Vec<KeyedResult> {
    let cell = super::column_width(params);
    let (b, a) = rayon::join(
        || Columns::new(before, anchor, cell),
        || Columns::new(after, anchor, cell),
    );
    let local: Vec<Point3> = pending.iter().map(|k| b.to_local(&k.xyz)).collect();
    let normals: Vec<Point3> = pending.iter().map(|k| k.r.normal).collect();
    let whole = Extent::whole(extent.data_min, extent.data_max).local(&anchor);
    // Only a surface's core point walks: every pending one is.
    let results = super::distances(
        &b,
        &a,
        &local,
        &normals,
        &vec![true; normals.len()],
        params,
        &whole,
    );
    pending
        .iter()
        .zip(results)
        .map(|(k, r)| KeyedResult {
            r: CoreResult {
                sign_known: k.r.sign_known,
                ..r
            },
            ..*k
        })
        .collect()
}

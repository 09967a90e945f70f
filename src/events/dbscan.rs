//! DBSCAN (Ester, Kriegel, Sander & Xu 1996, "A density-based algorithm for discovering
//! clusters in large spatial databases with noise"), split so that tiles can be clustered
//! independently and merged into exactly the whole-cloud result (SPEC.md §3 "Clusters").
//!
//! Definitions (as in the paper, with the point itself counted in its neighbourhood):
//! N(p) = { q : |pq| ≤ eps }; p is *core* when |N(p)| ≥ min_pts; two core points within eps
//! of each other are in the same cluster (the transitive closure gives the clusters); a
//! non-core point with at least one core point within eps is a *border* point; the others
//! are noise (label 0).
//!
//! The original algorithm gives a border point to whichever cluster reaches it first, which
//! depends on the visiting order. Here a border point joins the cluster of its core
//! neighbour with the smallest global id, so the result is unique.
//!
//! Tiled protocol (every tile = owned points + a halo at least `eps` wide, each point with a
//! global id):
//! 1. `core_flags` per tile decides the core status of the tile's owned points (exact,
//!    because the whole eps-ball of an owned point lies inside the tile);
//! 2. `tile_links` per tile, given the core flag of every point in the tile (halo points'
//!    flags come from their owning tiles), unites the owned core points with the core points
//!    within eps and emits a spanning forest of those unions (an edge from each linked point to
//!    its set's root) and the border assignments of the owned non-core points;
//! 3. `merge` unions all edges over global ids (union-find, order independent) and numbers
//!    the clusters 1.. by the smallest global id of each cluster.
//!
//! Every edge of the whole-cloud eps-graph between two core points is emitted by the tile
//! owning either end, and every border decision is taken where all of the point's
//! neighbours are visible, so tiled = whole cloud exactly. [`dbscan`] is the one-tile case.

use kiddo::SquaredEuclidean;
use rayon::prelude::*;

use super::describe::Kind;
use super::union_find::UnionFind;
use super::{build_tree, origin_of, relative};
use crate::error::Result;

/// Phase 1: the core flag of each owned point (`false` for halo points, which their own
/// tile decides). A neighbourhood counts the point itself and every point within `eps`
/// (inclusive), owned or halo.
pub(crate) fn core_flags(
    points: &[[f64; 3]],
    owned: &[bool],
    eps: f64,
    min_pts: usize,
) -> Result<Vec<bool>> {
    let local = relative(points, origin_of(points));
    let tree = build_tree(&local)?;
    let r2 = eps * eps;
    Ok(local
        .par_iter()
        .zip(owned.par_iter())
        .map(|(p, &own)| {
            if !own {
                return false;
            }
            let mut n = 0usize;
            tree.query(p)
                .within::<SquaredEuclidean<f64>>(r2)
                .unsorted()
                .visit(|_| n += 1);
            n >= min_pts
        })
        .collect())
}

/// What one tile contributes to the global merge; all in global ids.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub(crate) struct TileLinks {
    /// The tile's owned core points.
    pub(crate) cores: Vec<u64>,
    /// A spanning forest of the tile's unions of owned core points with core points within eps
    /// (owned or halo): (a linked core point, its set's root).
    pub(crate) edges: Vec<(u64, u64)>,
    /// (owned border point, its core neighbour with the smallest global id).
    pub(crate) borders: Vec<(u64, u64)>,
}

/// Phase 2: union edges and border assignments of one tile. `core` holds the core flag of
/// every point of the tile (owned ones from [`core_flags`] of this tile, halo ones from their
/// owning tiles); `ids` are the global ids.
///
/// The tile's core–core links within eps are united here, over the tile's own points, and only
/// a spanning forest of them is emitted: one edge from each linked core point to its set's root.
/// The global merge sees the same connectivity (so the same clusters) from at most one edge per
/// core point, where every link would be about ten per point at the derived eps (2.5 core
/// spacings) — most of the events unit's memory on a large pair. The links are found a batch of
/// points at a time, so they are never all held either.
pub(crate) fn tile_links(
    points: &[[f64; 3]],
    ids: &[u64],
    owned: &[bool],
    core: &[bool],
    eps: f64,
) -> Result<TileLinks> {
    /// Points whose links are found (in parallel) before they are united.
    const BATCH: usize = 1 << 14;
    let local = relative(points, origin_of(points));
    let tree = build_tree(&local)?;
    let r2 = eps * eps;
    let mut sets = UnionFind::new(local.len());
    let mut links = TileLinks::default();
    // Per point: the core points it is linked to (tile indices), and its border assignment.
    type PointLinks = (Vec<u32>, Option<(u64, u64)>);
    for start in (0..local.len()).step_by(BATCH) {
        let end = (start + BATCH).min(local.len());
        let per_point: Vec<PointLinks> = (start..end)
            .into_par_iter()
            .map(|i| {
                if !owned[i] {
                    return (Vec::new(), None);
                }
                let mut edges = Vec::new();
                let mut best: Option<u64> = None;
                tree.query(&local[i])
                    .within::<SquaredEuclidean<f64>>(r2)
                    .unsorted()
                    .visit(|it| {
                        let j = it.item as usize;
                        if j == i || !core[j] {
                            return;
                        }
                        if core[i] {
                            edges.push(j as u32);
                        } else {
                            best = Some(best.map_or(ids[j], |b| b.min(ids[j])));
                        }
                    });
                (edges, best.map(|c| (ids[i], c)))
            })
            .collect();
        for (k, (edges, border)) in per_point.into_iter().enumerate() {
            let i = start + k;
            if owned[i] && core[i] {
                links.cores.push(ids[i]);
            }
            for j in edges {
                sets.union(i, j as usize);
            }
            links.borders.extend(border);
        }
    }
    // The spanning forest: each linked point to its set's root (the root is the set's smallest
    // tile index, whatever order the unions came in).
    for i in 0..local.len() {
        let r = sets.find(i);
        if r != i {
            links.edges.push((ids[i], ids[r]));
        }
    }
    Ok(links)
}

/// Cluster labels of the clustered points (cores and borders), by global id; every other
/// id is noise (0).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub(crate) struct Labels {
    /// Sorted global ids of the clustered points.
    ids: Vec<u64>,
    /// Label of `ids[i]`, 1-based.
    labels: Vec<u32>,
}

impl Labels {
    /// The label of a global id: 1.. for clusters, 0 for noise.
    pub(crate) fn get(&self, id: u64) -> u32 {
        match self.ids.binary_search(&id) {
            Ok(i) => self.labels[i],
            Err(_) => 0,
        }
    }
}

/// Phase 3: merge the contributions of all tiles (any order) into cluster labels, numbered
/// 1.. in the order of the smallest global id of each cluster (core or border).
pub(crate) fn merge(tiles: impl IntoIterator<Item = TileLinks>) -> Labels {
    let mut cores = Vec::new();
    let mut edges = Vec::new();
    let mut borders = Vec::new();
    for t in tiles {
        cores.extend(t.cores);
        edges.extend(t.edges);
        borders.extend(t.borders);
    }
    cores.sort_unstable();
    cores.dedup();
    let index = |id: u64| cores.binary_search(&id).ok();
    // Dense indices follow the id order, so each set's root is its smallest core id.
    let mut uf = UnionFind::new(cores.len());
    for (a, b) in edges {
        if let (Some(a), Some(b)) = (index(a), index(b)) {
            uf.union(a, b);
        }
    }
    // Root (dense core index) of each clustered point.
    let mut members: Vec<(u64, usize)> = (0..cores.len()).map(|i| (cores[i], uf.find(i))).collect();
    borders.sort_unstable();
    borders.dedup_by_key(|b| b.0);
    for (p, c) in borders {
        if let Some(c) = index(c) {
            members.push((p, uf.find(c)));
        }
    }
    members.sort_unstable();
    members.dedup_by_key(|m| m.0);
    // Smallest member id of each root, then rank roots by it.
    let mut first: Vec<u64> = vec![u64::MAX; cores.len()];
    for &(id, root) in &members {
        first[root] = first[root].min(id);
    }
    let mut roots: Vec<usize> = (0..cores.len()).filter(|&r| first[r] != u64::MAX).collect();
    roots.sort_unstable_by_key(|&r| first[r]);
    let mut label_of_root = vec![0u32; cores.len()];
    for (k, &r) in roots.iter().enumerate() {
        label_of_root[r] = k as u32 + 1;
    }
    Labels {
        ids: members.iter().map(|m| m.0).collect(),
        labels: members.iter().map(|m| label_of_root[m.1]).collect(),
    }
}

/// Whole-cloud DBSCAN: one tile owning every point, ids = indices (the same code path as a
/// tiled run). Returns one label per point, 0 = noise.
pub fn dbscan(points: &[[f64; 3]], eps: f64, min_pts: usize) -> Result<Vec<u32>> {
    let owned = vec![true; points.len()];
    let ids: Vec<u64> = (0..points.len() as u64).collect();
    let core = core_flags(points, &owned, eps, min_pts)?;
    let labels = merge([tile_links(points, &ids, &owned, &core, eps)?]);
    Ok(ids.iter().map(|&id| labels.get(id)).collect())
}

/// Signed clustering (SPEC.md §1): DBSCAN separately on the gain points (smoothed d > 0) and
/// on the loss points (smoothed d < 0) of a whole cloud. Returns per point `None` (noise, or
/// smoothed d = 0 / NaN) or the kind and the cluster label within that kind (1..).
pub fn signed_dbscan(
    points: &[[f64; 3]],
    smoothed: &[f64],
    eps: f64,
    min_pts: usize,
) -> Result<Vec<Option<(Kind, u32)>>> {
    let mut out = vec![None; points.len()];
    for kind in [Kind::Gain, Kind::Loss] {
        let idx: Vec<usize> = (0..points.len())
            .filter(|&i| kind.matches(smoothed[i]))
            .collect();
        let sub: Vec<[f64; 3]> = idx.iter().map(|&i| points[i]).collect();
        for (&i, l) in idx.iter().zip(dbscan(&sub, eps, min_pts)?) {
            if l > 0 {
                out[i] = Some((kind, l));
            }
        }
    }
    Ok(out)
}

//! DBSCAN tile by tile, merged into the clusters of one whole-cloud run (SPEC.md §3 "Clusters").
//!
//! Each tile sees the points it owns plus a halo of `eps` around its square. Phase 1: each tile
//! decides the core status of the points it owns (their whole `eps`-neighbourhood is in its
//! halo). Phase 2: each tile links every point within `eps` of a core point to it, halo points
//! included, and a global union-find over the points' keys merges the tiles' links
//! ([`super::dbscan::merge`]): a cluster spanning tiles is joined through core points, and a
//! border point joins exactly one cluster, chosen by key. The labels are those of one DBSCAN over
//! all points, whatever the tile size (tests/events_volume.rs checks it against the whole-cloud
//! run and a brute force).

use rayon::prelude::*;
use talus_tiling::TileGrid;

use super::dbscan;
use crate::error::Result;
use crate::geom::Point3;

/// DBSCAN labels (0 = noise, clusters numbered by the merge) of `pts`, whose global keys are
/// `keys`, computed tile by tile over `grid`.
pub fn cluster(
    pts: &[Point3],
    keys: &[u64],
    grid: &TileGrid,
    eps: f64,
    min_pts: usize,
) -> Result<Vec<u32>> {
    // u32 indices: these lists are most of the clustering's memory beside the points.
    let mut members: Vec<Vec<u32>> = vec![Vec::new(); grid.len()];
    let mut owner: Vec<u32> = Vec::with_capacity(pts.len());
    for (i, p) in pts.iter().enumerate() {
        owner.push(grid.index(grid.owner(p[0], p[1])) as u32);
        for t in grid.tiles_touching(p[0], p[1], eps) {
            members[grid.index(t)].push(i as u32);
        }
    }
    let tile_points = |t: usize| -> (Vec<Point3>, Vec<bool>) {
        (
            members[t].iter().map(|&i| pts[i as usize]).collect(),
            members[t]
                .iter()
                .map(|&i| owner[i as usize] as usize == t)
                .collect(),
        )
    };
    // Phase 1: each tile decides the core status of the points it owns.
    let flags: Vec<Vec<bool>> = (0..grid.len())
        .into_par_iter()
        .map(|t| {
            let (p, owned) = tile_points(t);
            dbscan::core_flags(&p, &owned, eps, min_pts)
        })
        .collect::<Result<_>>()?;
    let mut core = vec![false; pts.len()];
    for (t, f) in flags.iter().enumerate() {
        for (j, &i) in members[t].iter().enumerate() {
            if owner[i as usize] as usize == t {
                core[i as usize] = f[j];
            }
        }
    }
    // Phase 2: links through core points, halo ones included, then one global merge.
    let links: Vec<dbscan::TileLinks> = (0..grid.len())
        .into_par_iter()
        .map(|t| {
            let (p, owned) = tile_points(t);
            let ids: Vec<u64> = members[t].iter().map(|&i| keys[i as usize]).collect();
            let c: Vec<bool> = members[t].iter().map(|&i| core[i as usize]).collect();
            dbscan::tile_links(&p, &ids, &owned, &c, eps)
        })
        .collect::<Result<_>>()?;
    let labels = dbscan::merge(links);
    Ok(keys.iter().map(|&k| labels.get(k)).collect())
}

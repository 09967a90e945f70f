//! A pair's kept core points cut into cubes of space ("blocks"), each processed with the 26
//! around it: smoothing ([`smooth`](fn@smooth): the k nearest within a reach) and signed DBSCAN
//! ([`cluster`]: Ester et al. 1996, in the tiled form of [`super::dbscan`], a block owning its
//! points and seeing the blocks around as its halo). A block's neighbourhood is held at a time,
//! never a kd-tree or clustering lists over every kept point of the pair (those were most of the
//! events unit's memory, and grew with the change); what a neighbourhood holds is bounded by its
//! volume in core-point cells, not by the survey.
//!
//! The blocks are fixed in space — a side from the parameters, an origin at the first point —
//! and never follow the run's tiles, so the results are the same whatever the memory budget.

use std::num::NonZero;

use rayon::prelude::*;

use super::{build_tree, dbscan, local, origin_of, smooth, union_find::UnionFind};
use crate::error::Result;
use crate::geom::Point3;

/// Blocks processed in parallel before their results are put in place: a bound on what the
/// threads hold at once.
const BATCH: usize = 64;

/// The smoothing's reach, in smoothing σ: a neighbour beyond it would weigh less than
/// e^(−12.5) ≈ 4 × 10⁻⁶ of the point itself (which is always among its nearest), so the k nearest
/// are taken among those within it.
pub(crate) const SMOOTH_REACH_SIGMAS: f64 = 5.0;

/// How many reaches a block's side is: its neighbourhood (the block grown by the reach) then
/// holds (1 + 2/4)² ≈ 2.3 times its own points on a surface, where blocks one reach wide would
/// hold 9 times.
const SIDE_IN_REACHES: f64 = 4.0;

/// The side of the blocks that reach `reach`.
pub(crate) fn side_for(reach: f64) -> f64 {
    if reach > 0.0 && reach.is_finite() {
        SIDE_IN_REACHES * reach
    } else {
        f64::INFINITY
    }
}

/// The block holding `p`, of side `side` anchored at `origin`.
pub(crate) fn block_of(p: &Point3, origin: &Point3, side: f64) -> [i64; 3] {
    std::array::from_fn(|k| ((p[k] - origin[k]) / side).floor() as i64)
}

/// Which blocks (by their place in the grid of blocks) a pass looks at.
pub(crate) type Chosen<'a> = dyn Fn([i64; 3]) -> bool + Sync + 'a;

/// Points cut into cubic blocks, each seen with every point within a reach of it.
pub struct Blocks {
    reach: f64,
    side: f64,
    origin: Point3,
    /// Point indices by (block, index).
    order: Vec<u32>,
    /// Every non-empty block with where its points start in `order`, ascending.
    starts: Vec<([i64; 3], u32)>,
}

impl Blocks {
    /// `points` in blocks seen with every point within `reach` of them, anchored at the first
    /// point. Fewer than 2³² points.
    pub fn new(points: &[Point3], reach: f64) -> Blocks {
        Self::anchored(points, reach, origin_of(points))
    }

    /// [`Blocks::new`] anchored at `origin`: a part of a larger set of points (a piece of a
    /// pair's, `super::pieces`) cut along the very planes the whole set's blocks are, so that
    /// each of its blocks that holds all its surroundings sees what the whole set's does.
    pub(crate) fn anchored(points: &[Point3], reach: f64, origin: Point3) -> Blocks {
        assert!(points.len() <= u32::MAX as usize, "{} points", points.len());
        let side = side_for(reach);
        let block = |i: u32| block_of(&points[i as usize], &origin, side);
        let mut order: Vec<u32> = (0..points.len() as u32).collect();
        order.par_sort_unstable_by(|&a, &b| block(a).cmp(&block(b)).then(a.cmp(&b)));
        let mut starts: Vec<([i64; 3], u32)> = Vec::new();
        for (k, &i) in order.iter().enumerate() {
            let c = block(i);
            if starts.last().is_none_or(|s| s.0 != c) {
                starts.push((c, k as u32));
            }
        }
        Blocks {
            reach,
            side,
            origin,
            order,
            starts,
        }
    }

    /// Non-empty blocks.
    pub(crate) fn len(&self) -> usize {
        self.starts.len()
    }

    /// Block `b`'s place in the grid of blocks.
    pub(crate) fn coord(&self, b: usize) -> [i64; 3] {
        self.starts[b].0
    }

    /// The points of block `b`, ascending.
    pub(crate) fn owned(&self, b: usize) -> &[u32] {
        let start = self.starts[b].1 as usize;
        let end = self
            .starts
            .get(b + 1)
            .map_or(self.order.len(), |s| s.1 as usize);
        &self.order[start..end]
    }

    /// The points of `points` (those the blocks were made of) in block `b` grown by the reach
    /// (and a millionth of it against rounding), ascending: every point within the reach of a
    /// point of `b`. They lie in `b` and the 26 blocks around it (the side is over the reach).
    pub(crate) fn around(&self, b: usize, points: &[Point3]) -> Vec<u32> {
        let c = self.starts[b].0;
        let h = self.reach * (1.0 + 1e-6);
        let lo: [f64; 3] = std::array::from_fn(|k| c[k] as f64 * self.side - h);
        let hi: [f64; 3] = std::array::from_fn(|k| (c[k] + 1) as f64 * self.side + h);
        let inside = |i: u32| {
            !self.side.is_finite()
                || (0..3).all(|k| {
                    let x = points[i as usize][k] - self.origin[k];
                    lo[k] <= x && x <= hi[k]
                })
        };
        let mut out = Vec::new();
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let n = [c[0] + dx, c[1] + dy, c[2] + dz];
                    if let Ok(j) = self.starts.binary_search_by(|s| s.0.cmp(&n)) {
                        out.extend(self.owned(j).iter().copied().filter(|&i| inside(i)));
                    }
                }
            }
        }
        out.sort_unstable();
        out
    }

    /// `f` of every block, a batch of blocks at a time in parallel, each result handed to `put`
    /// in block order.
    fn each<T: Send>(
        &self,
        f: impl Fn(usize) -> Result<T> + Sync,
        put: impl FnMut(T),
    ) -> Result<()> {
        self.each_chosen(&|_| true, f, put)
    }

    /// [`Self::each`] over the blocks whose place `chosen` accepts.
    fn each_chosen<T: Send>(
        &self,
        chosen: &Chosen<'_>,
        f: impl Fn(usize) -> Result<T> + Sync,
        mut put: impl FnMut(T),
    ) -> Result<()> {
        let blocks: Vec<usize> = (0..self.len()).filter(|&b| chosen(self.coord(b))).collect();
        for batch in blocks.chunks(BATCH) {
            let done: Vec<T> = batch.par_iter().map(|&b| f(b)).collect::<Result<_>>()?;
            done.into_iter().for_each(&mut put);
        }
        Ok(())
    }
}

/// Smoothed distances ([`super::smooth`]'s normalised Gaussian mean over the k nearest, chosen
/// by (distance, index)), the k nearest taken among the points within `reach` (a point with
/// fewer within it takes those). Where the k nearest lie within `reach`, the value has the bits
/// of the whole-cloud [`super::smooth::smooth`]. `reach` at most the blocks' reach.
pub fn smooth(
    points: &[Point3],
    d: &[f64],
    k: usize,
    sigma: f64,
    reach: f64,
    blocks: &Blocks,
) -> Result<Vec<f64>> {
    let Some(k) = NonZero::new(k.min(points.len())) else {
        return Ok(d.to_vec());
    };
    if sigma.is_nan() || sigma <= 0.0 || points.len() != d.len() {
        return Ok(d.to_vec());
    }
    assert!(
        reach <= blocks.reach,
        "reach {reach} beyond the blocks' {}",
        blocks.reach
    );
    let inv_two_sigma2 = 1.0 / (2.0 * sigma * sigma);
    let reach2 = reach * reach;
    // The first point: the local frame of a whole-cloud smoothing, so distances have its bits.
    let o = blocks.origin;
    let mut out = vec![f64::NAN; points.len()];
    blocks.each(
        |b| {
            let around = blocks.around(b, points);
            let near: Vec<Point3> = around
                .iter()
                .map(|&i| local(&points[i as usize], &o))
                .collect();
            let tree = build_tree(&near)?;
            let kk = NonZero::new(k.get().min(near.len())).unwrap_or(NonZero::<usize>::MIN);
            let values: Vec<(u32, f64)> = blocks
                .owned(b)
                .iter()
                .map(|&i| {
                    let p = local(&points[i as usize], &o);
                    let at = |item: u32| around[item as usize];
                    (
                        i,
                        smooth::mean_at(&tree, &p, kk, reach2, &at, d, inv_two_sigma2),
                    )
                })
                .collect();
            Ok(values)
        },
        |values| {
            for (i, v) in values {
                out[i as usize] = v;
            }
        },
    )?;
    Ok(out)
}

/// DBSCAN labels (0 = noise; clusters numbered 1.. in the order of their smallest index) of the
/// points `member` accepts, the others noise: the labels of one whole-cloud
/// [`dbscan::dbscan`] over those points, found block by block (`eps` at most the blocks' reach,
/// so a block's surroundings hold every eps-neighbourhood of its points).
pub fn cluster(
    points: &[Point3],
    member: &(dyn Fn(usize) -> bool + Sync),
    eps: f64,
    min_pts: usize,
    blocks: &Blocks,
) -> Result<Vec<u32>> {
    let mut found = cluster_chosen(points, member, eps, min_pts, blocks, &|_| true, &|_| true)?;
    // Each clustered point's set (its own for a core point, its core neighbour's for a border
    // one), then the sets numbered by their smallest member.
    let mut label = vec![0u32; points.len()];
    for (i, l) in label.iter_mut().enumerate() {
        if found.core[i] && member(i) {
            *l = found.sets.find(i) as u32 + 1;
        }
    }
    for &(p, c) in &found.borders {
        label[p as usize] = found.sets.find(c as usize) as u32 + 1;
    }
    drop(found);
    let mut number: rustc_hash::FxHashMap<u32, u32> = Default::default();
    for l in label.iter_mut().filter(|l| **l > 0) {
        let next = number.len() as u32 + 1;
        *l = *number.entry(*l).or_insert(next);
    }
    Ok(label)
}

/// What DBSCAN found over some blocks ([`cluster_chosen`]).
pub(crate) struct Found {
    /// The core flag of every point of the deciding blocks (false elsewhere).
    pub(crate) core: Vec<bool>,
    /// The sets of the core points linked by the linking blocks.
    pub(crate) sets: UnionFind,
    /// (border point of a linking block, its core neighbour with the smallest index).
    pub(crate) borders: Vec<(u32, u32)>,
}

/// DBSCAN's two phases over chosen blocks: the core flags of the points of the blocks `decide`
/// accepts, then the links and border points of those `link` accepts (whose surroundings must
/// lie in deciding blocks). Over every block, the sets are those of one whole-cloud
/// [`dbscan::dbscan`]; over part of the blocks of a piece of space whose points are all there
/// (`super::pieces`), what the whole cloud's clustering finds in that part.
pub(crate) fn cluster_chosen(
    points: &[Point3],
    member: &(dyn Fn(usize) -> bool + Sync),
    eps: f64,
    min_pts: usize,
    blocks: &Blocks,
    decide: &Chosen<'_>,
    link: &Chosen<'_>,
) -> Result<Found> {
    assert!(
        eps <= blocks.reach,
        "eps {eps} beyond the blocks' {}",
        blocks.reach
    );
    // A block's members with the around ones: (indices, points, owned flags).
    let members = |b: usize| {
        let ids: Vec<u32> = blocks
            .around(b, points)
            .into_iter()
            .filter(|&i| member(i as usize))
            .collect();
        let mine = blocks.owned(b);
        let owned: Vec<bool> = ids.iter().map(|i| mine.binary_search(i).is_ok()).collect();
        let p: Vec<Point3> = ids.iter().map(|&i| points[i as usize]).collect();
        (ids, p, owned)
    };
    // Phase 1: each block decides the core status of its own members.
    let mut core = vec![false; points.len()];
    blocks.each_chosen(
        decide,
        |b| {
            let (ids, p, owned) = members(b);
            let flags = dbscan::core_flags(&p, &owned, eps, min_pts)?;
            Ok(ids
                .into_iter()
                .zip(owned)
                .zip(flags)
                .filter(|((_, own), _)| *own)
                .map(|((i, _), c)| (i, c))
                .collect::<Vec<_>>())
        },
        |flags| {
            for (i, c) in flags {
                core[i as usize] = c;
            }
        },
    )?;
    // Phase 2: each block's links through core points, united over the dense indices; a border
    // point to the core neighbour with the smallest index.
    let mut sets = UnionFind::new(points.len());
    let mut borders: Vec<(u32, u32)> = Vec::new();
    blocks.each_chosen(
        link,
        |b| {
            let (ids, p, owned) = members(b);
            let c: Vec<bool> = ids.iter().map(|&i| core[i as usize]).collect();
            let global: Vec<u64> = ids.iter().map(|&i| u64::from(i)).collect();
            dbscan::tile_links(&p, &global, &owned, &c, eps)
        },
        |links| {
            for (a, b) in links.edges {
                sets.union(a as usize, b as usize);
            }
            borders.extend(links.borders.iter().map(|&(p, c)| (p as u32, c as u32)));
        },
    )?;
    Ok(Found {
        core,
        sets,
        borders,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A block's surroundings hold every point within the reach of its points, and not many
    /// more.
    #[test]
    fn around_holds_every_point_within_the_reach() {
        let mut rng = crate::rng::SplitMix64::new(3);
        let pts: Vec<Point3> = (0..3000)
            .map(|_| {
                [
                    rng.range(0.0, 20.0),
                    rng.range(0.0, 20.0),
                    rng.range(0.0, 4.0),
                ]
            })
            .collect();
        let reach = 1.7;
        let blocks = Blocks::new(&pts, reach);
        let (mut seen, mut held) = (0, 0);
        for b in 0..blocks.len() {
            let around = blocks.around(b, &pts);
            held += around.len();
            for &i in blocks.owned(b) {
                seen += 1;
                for (j, q) in pts.iter().enumerate() {
                    let p = pts[i as usize];
                    let d2: f64 = (0..3).map(|k| (p[k] - q[k]).powi(2)).sum();
                    if d2 <= reach * reach {
                        assert!(around.binary_search(&(j as u32)).is_ok(), "{i} {j}");
                    }
                }
            }
        }
        assert_eq!(seen, pts.len());
        // Blocks of 6.8 over 20 × 20 × 4 grown by 1.7: about 3 × 3 blocks' worth each.
        assert!(held < 6 * pts.len(), "{held} held for {seen}");
    }
}

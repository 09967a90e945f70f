//! A pair's kept core points smoothed and clustered a piece of space at a time, for a change
//! too large for the budget to hold every kept point at once (issue 24: the events unit's need
//! grew with the change, 80 bytes a kept point).
//!
//! The pieces are rectangles of columns — the x and y of [`super::blocks`]' cubes, so a piece
//! is a union of whole blocks — each loaded with `HALO_COLUMNS` columns around it. Within a
//! piece, the blocks of its own columns and of the ring around them hold all their surroundings,
//! so their smoothing, core flags and links are what the whole pair's blocks find, to the bit;
//! the piece keeps the smoothed distances and clusters of the points it owns. A cluster that
//! crosses pieces is joined through its core points in the ring around a piece: a piece labels
//! those as it links them to its own, their owner labels them too, and the two labels are the
//! same cluster (`Stitch`). Every link of the pair's clustering starts at a core point some
//! piece owns and ends within eps of it, inside that piece's ring; so the joined sets are the
//! whole pair's (DBSCAN's merge of partitions with halos: Götz, Bodenstein & Riedel 2015,
//! HPDBSCAN; the same merge as `super::dbscan`'s tiles).
//!
//! What a piece holds is bounded by the points of its columns and their ring: [`plan`] cuts the
//! columns so that no piece loads more than a cap, and says what cap the densest column needs.

use std::collections::BTreeMap;

use super::blocks::{self, Blocks};
use super::union_find::UnionFind;
use super::Kind;
use crate::error::Result;
use crate::geom::Point3;

/// Columns loaded on each side of a piece's own: its own blocks and the ring of blocks around
/// them then hold every point within their reach (blocks are wider than it), and the points
/// those surroundings hold have every point within the smoothing's reach loaded too.
pub(crate) const HALO_COLUMNS: i64 = 2;

/// The columns of a pair's kept points: the (x, y) of the blocks they lie in.
#[derive(Debug, Clone, Copy)]
pub struct Columns {
    origin: Point3,
    side: f64,
    reach: f64,
}

impl Columns {
    /// The columns of blocks reaching `reach` (the larger of the smoothing's reach and eps),
    /// anchored at `origin` (the pair's first kept point, as its blocks are).
    pub fn new(origin: Point3, reach: f64) -> Columns {
        Columns {
            origin,
            side: blocks::side_for(reach),
            reach,
        }
    }

    /// The column of `p`.
    pub fn of(&self, p: &Point3) -> [i64; 2] {
        let b = blocks::block_of(p, &self.origin, self.side);
        [b[0], b[1]]
    }
}

/// A piece: the columns it owns, x and y ranges inclusive.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Piece {
    pub(crate) x: [i64; 2],
    pub y: [i64; 2],
}

impl Piece {
    /// Whether the piece owns column `c`.
    pub(crate) fn owns(&self, c: [i64; 2]) -> bool {
        (self.x[0]..=self.x[1]).contains(&c[0]) && (self.y[0]..=self.y[1]).contains(&c[1])
    }

    /// Whether the piece loads the points of column `c` (its own, and the halo around).
    pub(crate) fn loads(&self, c: [i64; 2]) -> bool {
        self.grown(HALO_COLUMNS).owns(c)
    }

    /// The piece grown by `g` columns on every side.
    fn grown(&self, g: i64) -> Piece {
        Piece {
            x: [self.x[0].saturating_sub(g), self.x[1].saturating_add(g)],
            y: [self.y[0].saturating_sub(g), self.y[1].saturating_add(g)],
        }
    }
}

/// Points in the columns a piece owning `p` loads.
pub(crate) fn load(counts: &BTreeMap<[i64; 2], u64>, p: &Piece) -> u64 {
    let g = p.grown(HALO_COLUMNS);
    counts
        .range([g.x[0], i64::MIN]..=[g.x[1], i64::MAX])
        .filter(|(c, _)| g.owns(**c))
        .map(|(_, n)| n)
        .sum()
}

/// Cut the columns with `counts` points (the non-empty ones) into pieces loading at most `cap`
/// points each: slabs of whole x columns, a column too full for one slab cut along y. Err: the
/// smallest cap that works (what the fullest column loads with its halo).
pub fn plan(counts: &BTreeMap<[i64; 2], u64>, cap: u64) -> std::result::Result<Vec<Piece>, u64> {
    let one = |c: [i64; 2]| Piece {
        x: [c[0]; 2],
        y: [c[1]; 2],
    };
    let floor = counts
        .keys()
        .map(|&c| load(counts, &one(c)))
        .max()
        .unwrap_or(0);
    if floor > cap {
        return Err(floor);
    }
    let (Some(ylo), Some(yhi)) = (
        counts.keys().map(|c| c[1]).min(),
        counts.keys().map(|c| c[1]).max(),
    ) else {
        return Ok(Vec::new());
    };
    let mut xs: Vec<i64> = counts.keys().map(|c| c[0]).collect();
    xs.dedup();
    let slab = |a: i64, b: i64| Piece {
        x: [a, b],
        y: [ylo, yhi],
    };
    let mut pieces = Vec::new();
    let mut i = 0;
    while i < xs.len() {
        let a = xs[i];
        if load(counts, &slab(a, a)) > cap {
            // One column of x too full: its columns cut along y.
            let ys: Vec<i64> = counts
                .range([a, i64::MIN]..=[a, i64::MAX])
                .map(|(c, _)| c[1])
                .collect();
            let mut j = 0;
            while j < ys.len() {
                let mut end = j;
                let piece = |b: usize| Piece {
                    x: [a, a],
                    y: [ys[j], ys[b]],
                };
                while end + 1 < ys.len() && load(counts, &piece(end + 1)) <= cap {
                    end += 1;
                }
                pieces.push(piece(end));
                j = end + 1;
            }
            i += 1;
            continue;
        }
        let mut end = i;
        while end + 1 < xs.len() && load(counts, &slab(a, xs[end + 1])) <= cap {
            end += 1;
        }
        pieces.push(slab(a, xs[end]));
        i = end + 1;
    }
    Ok(pieces)
}

/// The smoothing and clustering parameters of a pair's events.
#[derive(Debug, Clone, Copy)]
pub struct Settings {
    /// Smoothing: the k nearest, the Gaussian's σ, and the reach they are taken within.
    pub k: usize,
    pub sigma: f64,
    pub reach: f64,
    /// DBSCAN's eps and fewest points.
    pub eps: f64,
    pub min_pts: usize,
}

/// What a piece found.
#[derive(Debug, Default)]
pub(crate) struct Labelled {
    /// Each owned point's (position among the piece's points, smoothed distance, label: 0 in no
    /// cluster, else 1.. of this piece's).
    pub(crate) owned: Vec<(u32, f64, u32)>,
    /// (position, label) of the core points the piece holds but does not own: their owner
    /// labels them too, and the two labels are one cluster.
    pub(crate) shared: Vec<(u32, u32)>,
    /// The kind of each label (label `l` at `l - 1`).
    pub(crate) kinds: Vec<Kind>,
}

/// Smooth and cluster the points of one piece: `points` (with their distances `d`) are every
/// kept point of the columns `piece` loads, in the pair's kept order.
pub(crate) fn label_piece(
    points: &[Point3],
    d: &[f64],
    piece: &Piece,
    columns: &Columns,
    s: &Settings,
) -> Result<Labelled> {
    let blocks = Blocks::anchored(points, columns.reach, columns.origin);
    let smoothed = blocks::smooth(points, d, s.k, s.sigma, s.reach, &blocks)?;
    let ring = piece.grown(1);
    let column = |c: [i64; 3]| [c[0], c[1]];
    let owned: Vec<bool> = points.iter().map(|p| piece.owns(columns.of(p))).collect();
    let mut out = Labelled::default();
    let mut label = vec![0u32; points.len()];
    for kind in [Kind::Gain, Kind::Loss] {
        let member = |i: usize| kind.matches(smoothed[i]);
        let mut found = blocks::cluster_chosen(
            points,
            &member,
            s.eps,
            s.min_pts,
            &blocks,
            &|c| ring.owns(column(c)),
            &|c| piece.owns(column(c)),
        )?;
        // This kind's sets, numbered as they are first met.
        let mut number: rustc_hash::FxHashMap<usize, u32> = Default::default();
        let mut name = |root: usize, out: &mut Labelled| {
            *number.entry(root).or_insert_with(|| {
                out.kinds.push(kind);
                out.kinds.len() as u32
            })
        };
        for i in 0..points.len() {
            if found.core[i] && member(i) {
                let l = name(found.sets.find(i), &mut out);
                if owned[i] {
                    label[i] = l;
                } else {
                    out.shared.push((i as u32, l));
                }
            }
        }
        for &(p, c) in &found.borders {
            label[p as usize] = name(found.sets.find(c as usize), &mut out);
        }
    }
    out.owned = (0..points.len())
        .filter(|&i| owned[i])
        .map(|i| (i as u32, smoothed[i], label[i]))
        .collect();
    Ok(out)
}

/// The pieces' labels joined into the pair's clusters.
#[derive(Debug, Default)]
pub(crate) struct Stitch {
    kinds: Vec<Kind>,
    sets: UnionFind,
}

impl Stitch {
    /// Take a piece's labels: the number to add to them to make them the pair's.
    pub(crate) fn add(&mut self, kinds: &[Kind]) -> u32 {
        let offset = self.kinds.len() as u32;
        self.kinds.extend_from_slice(kinds);
        self.sets.grow(self.kinds.len());
        offset
    }

    /// Labels taken.
    pub(crate) fn len(&self) -> usize {
        self.kinds.len()
    }

    /// Two of the pair's labels (1..) name one cluster.
    pub(crate) fn join(&mut self, a: u32, b: u32) {
        self.sets.union(a as usize - 1, b as usize - 1);
    }

    /// The cluster of label `l` (1..): the smallest label joined to it, and its kind.
    pub(crate) fn cluster(&mut self, l: u32) -> (u32, Kind) {
        let root = self.sets.find(l as usize - 1);
        (root as u32 + 1, self.kinds[root])
    }
}

/// Smoothed distances and each point's cluster (0 in none, else numbered 1.. in the order of
/// their smallest member) of `points`, in pieces loading at most `cap` points, every piece held
/// here: the computation the events unit makes with the pieces read from disk, for tests.
pub fn in_pieces(
    points: &[Point3],
    d: &[f64],
    s: &Settings,
    cap: u64,
) -> std::result::Result<(Vec<f64>, Vec<u32>), u64> {
    let columns = Columns::new(
        super::origin_of(points),
        (blocks::SMOOTH_REACH_SIGMAS * s.sigma).max(s.eps),
    );
    let mut counts = BTreeMap::new();
    for p in points {
        *counts.entry(columns.of(p)).or_insert(0u64) += 1;
    }
    let pieces = plan(&counts, cap)?;
    let (mut smoothed, mut label) = (vec![f64::NAN; points.len()], vec![0u32; points.len()]);
    let (mut stitch, mut shared) = (Stitch::default(), Vec::new());
    for piece in &pieces {
        let ids: Vec<usize> = (0..points.len())
            .filter(|&i| piece.loads(columns.of(&points[i])))
            .collect();
        assert!(ids.len() as u64 <= cap, "{} loaded over {cap}", ids.len());
        let p: Vec<Point3> = ids.iter().map(|&i| points[i]).collect();
        let dd: Vec<f64> = ids.iter().map(|&i| d[i]).collect();
        let found = label_piece(&p, &dd, piece, &columns, s).expect("labelled");
        let offset = stitch.add(&found.kinds);
        for (at, v, l) in found.owned {
            let i = ids[at as usize];
            smoothed[i] = v;
            label[i] = if l > 0 { l + offset } else { 0 };
        }
        shared.extend(
            found
                .shared
                .iter()
                .map(|&(at, l)| (ids[at as usize], l + offset)),
        );
    }
    for (i, l) in shared {
        stitch.join(l, label[i]);
    }
    let mut number: rustc_hash::FxHashMap<u32, u32> = Default::default();
    for l in label.iter_mut().filter(|l| **l > 0) {
        let next = number.len() as u32 + 1;
        *l = *number.entry(stitch.cluster(*l).0).or_insert(next);
    }
    Ok((smoothed, label))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pieces own every column once and load at most the cap; the floor is the fullest
    /// column's load.
    #[test]
    fn plan_owns_every_column_once_within_the_cap() {
        let mut counts = BTreeMap::new();
        for x in 0..12 {
            for y in 0..9 {
                counts.insert([x, y], 1 + ((x * 7 + y * 3) % 5) as u64);
            }
        }
        // A column of x far fuller than the rest: cut along y.
        for y in 0..9 {
            counts.insert([5, y], 40);
        }
        let floor = plan(&counts, 0).unwrap_err();
        let pieces = plan(&counts, floor).unwrap();
        for c in counts.keys() {
            assert_eq!(pieces.iter().filter(|p| p.owns(*c)).count(), 1, "{c:?}");
        }
        for p in &pieces {
            assert!(load(&counts, p) <= floor, "{p:?}");
        }
        assert!(pieces.iter().any(|p| p.x == [5, 5] && p.y != [0, 8]));
        assert_eq!(plan(&counts, u64::MAX).unwrap().len(), 1);
    }
}

//! Pairs of points closer than a fixed distance: a cell list (Allen & Tildesley, "Computer
//! Simulation of Liquids", §5.3.2) of square xy cells as wide as that distance, so that a point's
//! partners lie in the 3 × 3 cells around its own, and a row of three cells is one run of the
//! sorted points.
//!
//! The variogram of the stable ground asks for every partner of 20,000 anchors within eight core
//! spacings (millions of pairs); a kd-tree's radius query spent ≈ 16 ns a pair there, a scan of
//! the three runs ≈ 2 ns a candidate, about three candidates a pair.

use super::grid::XyGrid;
use crate::geom::Point3;

/// Points bucketed by xy cell, with their positions in the caller's slice.
pub(crate) struct Pairs {
    reach2: f64,
    cell: f64,
    corner: [f64; 2],
    dims: [usize; 2],
    /// Cell `j · dims[0] + i` holds the sorted points `starts[k]..starts[k + 1]`.
    starts: Vec<u32>,
    /// Coordinates relative to the first point (as [`super::Index`] keeps them), by cell.
    points: Vec<Point3>,
    /// The caller's position of each sorted point.
    index: Vec<u32>,
    /// Every point's place in `points`.
    place: Vec<u32>,
}

impl Pairs {
    /// Bucket `points` for the pairs within `reach` of each other (3-D distance, boundary
    /// included).
    pub(crate) fn new(points: &[Point3], reach: f64) -> Self {
        assert!(points.len() < u32::MAX as usize, "{} points", points.len());
        let origin = points.first().copied().unwrap_or([0.0; 3]);
        let local: Vec<Point3> = points
            .iter()
            .map(|p| [p[0] - origin[0], p[1] - origin[1], p[2] - origin[2]])
            .collect();
        // Cells no narrower than the reach (partners then lie in the neighbouring cells), and
        // not many more cells than points.
        let XyGrid { corner, cell, dims } =
            XyGrid::fit(local.iter().copied(), reach, 2 * local.len() + 16);
        let mut pairs = Pairs {
            reach2: reach * reach,
            cell,
            corner,
            dims,
            starts: vec![0; dims[0] * dims[1] + 1],
            points: Vec::with_capacity(local.len()),
            index: vec![0; local.len()],
            place: vec![0; local.len()],
        };
        // A counting sort by cell, stable: within a cell, points keep the caller's order.
        let cell_of: Vec<usize> = local.iter().map(|p| pairs.cell_of(p)).collect();
        for &c in &cell_of {
            pairs.starts[c + 1] += 1;
        }
        for k in 1..pairs.starts.len() {
            pairs.starts[k] += pairs.starts[k - 1];
        }
        let mut next: Vec<u32> = pairs.starts[..dims[0] * dims[1]].to_vec();
        for (i, &c) in cell_of.iter().enumerate() {
            pairs.index[next[c] as usize] = i as u32;
            pairs.place[i] = next[c];
            next[c] += 1;
        }
        pairs.points = pairs.index.iter().map(|&i| local[i as usize]).collect();
        pairs
    }

    fn cell_of(&self, p: &Point3) -> usize {
        let axis = |a: usize| {
            let c = ((p[a] - self.corner[a]) / self.cell).floor();
            (c.max(0.0) as usize).min(self.dims[a] - 1)
        };
        axis(1) * self.dims[0] + axis(0)
    }

    /// `f(b, squared distance)` for every point `b > a` within the reach of point `a` (positions
    /// in the slice given to [`Pairs::new`]), in a fixed order. `found` is scratch space (kept
    /// between calls: no allocation per point).
    pub(crate) fn after(
        &self,
        a: usize,
        found: &mut Vec<(u32, f64)>,
        mut f: impl FnMut(usize, f64),
    ) {
        let q = self.points[self.place[a] as usize];
        let c = self.cell_of(&q);
        let (ci, cj) = (c % self.dims[0], c / self.dims[0]);
        let (i0, i1) = (ci.saturating_sub(1), (ci + 1).min(self.dims[0] - 1));
        let a = a as u32;
        for j in cj.saturating_sub(1)..=(cj + 1).min(self.dims[1] - 1) {
            let (s, e) = (
                self.starts[j * self.dims[0] + i0] as usize,
                self.starts[j * self.dims[0] + i1 + 1] as usize,
            );
            // Room for every candidate of the run (what lies past the partners is stale).
            if found.len() < e - s {
                found.resize(e - s, (0, 0.0));
            }
            // Every candidate written, kept by advancing only when it is a partner: no branch
            // on a verdict that follows no pattern.
            let mut kept = 0;
            for (k, p) in (s..e).zip(&self.points[s..e]) {
                let (dx, dy, dz) = (p[0] - q[0], p[1] - q[1], p[2] - q[2]);
                let h2 = dx * dx + dy * dy + dz * dz;
                let b = self.index[k];
                found[kept] = (b, h2);
                kept += usize::from((b > a) & (h2 <= self.reach2));
            }
            for &(b, h2) in &found[..kept] {
                f(b as usize, h2);
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_pairs_are_those_of_a_brute_force_search() {
        let mut rng = crate::rng::Rng::new(3, 0);
        // Clustered and spread points, a duplicate, points on the reach exactly.
        let mut pts: Vec<Point3> = (0..3000)
            .map(|k| {
                let s = if k % 7 == 0 { 40.0 } else { 6.0 };
                [rng.uniform() * s, rng.uniform() * s, rng.uniform() * 0.5]
            })
            .collect();
        pts.push(pts[10]);
        pts.push([pts[20][0] + 0.75, pts[20][1], pts[20][2]]);
        for reach in [0.75, 2.0, 100.0] {
            let pairs = Pairs::new(&pts, reach);
            let local = |p: &Point3| [p[0] - pts[0][0], p[1] - pts[0][1], p[2] - pts[0][2]];
            let mut found = Vec::new();
            for a in (0..pts.len()).step_by(7) {
                let mut got = Vec::new();
                pairs.after(a, &mut found, |b, h2| got.push((b, h2)));
                got.sort_by_key(|x| x.0);
                let p = local(&pts[a]);
                let want: Vec<(usize, f64)> = (a + 1..pts.len())
                    .map(|b| {
                        let o = local(&pts[b]);
                        let d = [o[0] - p[0], o[1] - p[1], o[2] - p[2]];
                        (b, d[0] * d[0] + d[1] * d[1] + d[2] * d[2])
                    })
                    .filter(|&(_, h2)| h2 <= reach * reach)
                    .collect();
                assert_eq!(got, want, "anchor {a}, reach {reach}");
            }
        }
        assert!(Pairs::new(&[], 1.0).points.is_empty());
    }

    #[test]
    fn sparse_points_over_a_wide_extent_keep_the_grid_small() {
        let pts = vec![[0.0, 0.0, 0.0], [1e6, 1e6, 0.0], [1e6 + 0.5, 1e6, 0.0]];
        let pairs = Pairs::new(&pts, 1.0);
        assert!(pairs.starts.len() <= 2 * pts.len() + 17);
        let mut got = Vec::new();
        pairs.after(1, &mut Vec::new(), |b, h2| got.push((b, h2)));
        assert_eq!(got, vec![(2, 0.25)]);
    }
}

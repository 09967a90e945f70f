//! Where a survey is dense: its points counted in a grid of XY cells over its bounds, and the
//! most points any square of a given side can hold. The tile layout sizes tiles from the densest
//! square rather than the bounds' mean density (`plan::layout`): a terrestrial scan is many times
//! denser near the scanner than at its edge, and a footprint that fills a fraction of its bounds
//! (a rotated strip, a cliff line) has a mean far below its density, so a tile sized from the
//! mean would not fit the budget where the points are.

use crate::geom::{Bounds, Point3};

/// Cells along the bounds' longer side: a square's count is bounded within about 1/CELLS of the
/// bounds' extent per side, with 1 MiB of counts.
pub(crate) const CELLS: usize = 512;

/// Points per XY cell.
#[derive(Debug, Clone, serde::Serialize, serde::Deserialize)]
pub struct DensityGrid {
    origin: [f64; 2],
    cell: f64,
    cols: usize,
    rows: usize,
    counts: Vec<u32>,
    total: u64,
}

impl DensityGrid {
    /// An empty grid over `bounds`.
    pub(crate) fn new(bounds: &Bounds) -> DensityGrid {
        let w = (bounds.max[0] - bounds.min[0]).max(0.0);
        let h = (bounds.max[1] - bounds.min[1]).max(0.0);
        let cell = (w.max(h) / CELLS as f64).max(1e-9);
        let cols = ((w / cell) as usize + 1).min(CELLS);
        let rows = ((h / cell) as usize + 1).min(CELLS);
        DensityGrid {
            origin: [bounds.min[0], bounds.min[1]],
            cell,
            cols,
            rows,
            counts: vec![0; cols * rows],
            total: 0,
        }
    }

    /// Count `points` (points outside the bounds count in the nearest cell).
    pub(crate) fn add(&mut self, points: &[Point3]) {
        let inv = 1.0 / self.cell;
        let (cmax, rmax) = (self.cols - 1, self.rows - 1);
        for p in points {
            // `as usize` saturates: NaN and negatives go to 0.
            let c = (((p[0] - self.origin[0]) * inv) as usize).min(cmax);
            let r = (((p[1] - self.origin[1]) * inv) as usize).min(rmax);
            self.counts[r * self.cols + c] += 1;
        }
        self.total += points.len() as u64;
    }

    /// Points counted.
    pub(crate) fn total(&self) -> u64 {
        self.total
    }

    /// The most points an axis-aligned square of side `side` can hold, wherever it is placed:
    /// the largest count over windows of ⌈side / cell⌉ + 1 cells (such a square meets at most
    /// that many cells a side), so never less than the truth.
    pub(crate) fn densest(&self, side: f64) -> u64 {
        let k = ((side / self.cell).ceil().max(0.0) as usize).saturating_add(1);
        let (kc, kr) = (k.min(self.cols), k.min(self.rows));
        // Prefix sums: s[(r, c)] = points in cells [0, r) × [0, c).
        let w = self.cols + 1;
        let mut s = vec![0u64; w * (self.rows + 1)];
        for r in 0..self.rows {
            let mut row = 0u64;
            for c in 0..self.cols {
                row += self.counts[r * self.cols + c] as u64;
                s[(r + 1) * w + c + 1] = s[r * w + c + 1] + row;
            }
        }
        let mut best = 0;
        for r in 0..=self.rows - kr {
            for c in 0..=self.cols - kc {
                let n = s[(r + kr) * w + c + kc] + s[r * w + c]
                    - s[r * w + c + kc]
                    - s[(r + kr) * w + c];
                best = best.max(n);
            }
        }
        best
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn bounds(w: f64, h: f64) -> Bounds {
        let mut b = Bounds::empty();
        b.grow(&[0.0, 0.0, 0.0]);
        b.grow(&[w, h, 1.0]);
        b
    }

    /// The densest square, by brute force over the points themselves: a square with a point on
    /// its left and bottom edges holds as many as any other placement.
    fn brute(points: &[Point3], side: f64) -> u64 {
        let mut best = 0;
        for a in points {
            for b in points {
                let (x0, y0) = (a[0], b[1]);
                let n = points
                    .iter()
                    .filter(|p| p[0] >= x0 && p[0] <= x0 + side && p[1] >= y0 && p[1] <= y0 + side)
                    .count() as u64;
                best = best.max(n);
            }
        }
        best
    }

    #[test]
    fn the_densest_square_is_never_undercounted_and_close() {
        // A sparse strip with a dense patch: the mean over the bounds is far below the patch.
        let mut points = Vec::new();
        let mut rng = crate::rng::Rng::new(7, 0);
        let mut rnd = || rng.uniform();
        for _ in 0..100 {
            points.push([1000.0 * rnd(), 200.0 * rnd(), 0.0]);
        }
        for _ in 0..100 {
            points.push([600.0 + 20.0 * rnd(), 50.0 + 20.0 * rnd(), 0.0]);
        }
        let mut fp = DensityGrid::new(&bounds(1000.0, 200.0));
        fp.add(&points);
        assert_eq!(fp.total(), 200);
        for side in [5.0, 20.0, 60.0, 300.0] {
            let truth = brute(&points, side);
            let got = fp.densest(side);
            assert!(got >= truth, "side {side}: {got} < {truth}");
            // Cells of 1000/512 ≈ 2 units: one more cell a side than the square needs.
            let loose = brute(&points, side + 2.0 * fp.cell);
            assert!(got <= loose, "side {side}: {got} > {loose}");
        }
        assert_eq!(fp.densest(5000.0), 200);
    }

    #[test]
    fn points_outside_or_on_the_edge_are_counted() {
        let mut fp = DensityGrid::new(&bounds(10.0, 0.0));
        fp.add(&[[10.0, 0.0, 0.0], [-1.0, 3.0, 0.0], [f64::NAN, 0.0, 0.0]]);
        assert_eq!(fp.total(), 3);
        assert_eq!(fp.densest(100.0), 3);
    }
}

//! The square xy cells a grid index lays over its points ([`super::Columns`], [`super::Pairs`]):
//! no narrower than asked, widened until the cells are not many more than a budget (sparse points
//! over a wide extent would otherwise cost a cell each of millions).

use crate::geom::Point3;

/// Cells of `cell` width from `corner`, `dims[0]` × `dims[1]` of them.
#[derive(Debug, Clone, Copy)]
pub(crate) struct XyGrid {
    pub corner: [f64; 2],
    pub cell: f64,
    pub dims: [usize; 2],
}

impl XyGrid {
    /// The grid over `points` (NaN coordinates ignored; none: one cell at the origin) with cells
    /// at least `cell` wide and at most about `most` of them.
    pub(crate) fn fit(points: impl Iterator<Item = Point3>, cell: f64, most: usize) -> Self {
        let (mut lo, mut hi) = ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]);
        let mut any = false;
        for p in points {
            any = true;
            for a in 0..2 {
                // Comparisons a NaN fails (it is ignored) rather than `f64::min`, whose NaN rule
                // costs a branch per value.
                lo[a] = if p[a] < lo[a] { p[a] } else { lo[a] };
                hi[a] = if p[a] > hi[a] { p[a] } else { hi[a] };
            }
        }
        if !any {
            lo = [0.0; 2];
            hi = [0.0; 2];
        }
        let span = [hi[0] - lo[0], hi[1] - lo[1]];
        let budget = most.max(1) as f64;
        // No narrower than a billionth of the extent (nor subnormal): the growth below must be
        // able to move it.
        let mut cell = cell.max(1e-9 * span[0].max(span[1])).max(f64::MIN_POSITIVE);
        let cells = |c: f64| (span[0] / c + 1.0) * (span[1] / c + 1.0);
        if cells(cell) > budget {
            // Solve (w/c + 1)(h/c + 1) ≈ budget for c, then nudge up until it fits.
            cell = ((span[0] * span[1]) / budget).sqrt().max(cell);
            while cells(cell) > budget {
                cell *= 1.25;
            }
        }
        XyGrid {
            corner: lo,
            cell,
            dims: [
                (span[0] / cell).floor() as usize + 1,
                (span[1] / cell).floor() as usize + 1,
            ],
        }
    }
}

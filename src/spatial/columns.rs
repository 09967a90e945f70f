//! A column grid: the points of one epoch bucketed into square vertical columns of the xy plane,
//! each column's points stored contiguously and sorted by height (a cell list, Allen & Tildesley,
//! "Computer Simulation of Liquids", §5.3.2, with one axis kept sorted instead of binned).
//!
//! M3C2 asks two questions at every core point: which points lie within a sphere (the normal),
//! and which lie within a cylinder along that normal (the distance). A kd-tree answers the
//! second only through a sphere around the cylinder, and spends most of its time descending the
//! tree. Here a query walks the few columns its shape can reach; in each it bounds the heights
//! the shape can have over that column, finds the first candidate by binary search and scans
//! contiguous memory until the bound. On terrain a column holds one stretch of surface, so the
//! scan is short; on a cliff the height bound skips the rest of the face. The final test is exact,
//! so the grid only decides which points are tested, never which are accepted.

use super::grid::XyGrid;
use crate::geom::Point3;

/// At most this many columns per point: a sparse cloud over a wide extent gets wider columns
/// rather than a mostly empty table.
const MAX_COLUMNS_PER_POINT: usize = 2;

/// Bands of `1 << shift` consecutive columns, at most this many bands: the write positions of
/// the band scatter then stay in the cache (1024 cache lines, 64 KiB).
const MAX_BANDS: usize = 1024;

/// The shift that cuts `columns` columns into at most [`MAX_BANDS`] bands.
fn band_shift(columns: usize) -> u32 {
    let mut shift = 0;
    while columns.div_ceil(1 << shift) > MAX_BANDS {
        shift += 1;
    }
    shift
}

/// The exact cylinder test every cylinder query makes: the projection t of `p − q` on the unit
/// axis `n`, and whether |t| ≤ `h` and |p − q|² − t² ≤ `r2` (no branch: the verdicts follow no
/// pattern a predictor could learn).
#[inline(always)]
pub fn in_cylinder(p: &Point3, q: &Point3, n: &Point3, r2: f64, h: f64) -> (f64, bool) {
    let v = [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
    let t = v[0] * n[0] + v[1] * n[1] + v[2] * n[2];
    let radial2 = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]) - t * t;
    (t, (t.abs() <= h) & (radial2 <= r2))
}

/// Points in a local frame, bucketed into columns of width `cell`.
pub struct Columns {
    origin: Point3,
    cell: f64,
    /// 1 / cell: a point's column is found by a multiplication (a division took a third of
    /// building the index). Bucketing and queries use the same map, which is monotone.
    inverse: f64,
    /// Local xy of the lower corner of column (0, 0).
    corner: [f64; 2],
    /// Columns along x and y.
    dims: [usize; 2],
    /// Column `j · dims[0] + i` holds the points `starts[k]..starts[k + 1]`.
    starts: Vec<usize>,
    /// Local coordinates, by column, ascending height within each column.
    points: Vec<Point3>,
}

impl Columns {
    /// Bucket `points` (global coordinates) in the frame centred on `origin`, in columns about
    /// `cell` wide (wider when the extent is large for the number of points). Memory: the index
    /// (24 bytes a point) and nothing else.
    pub fn new(points: &[Point3], origin: Point3, cell: f64) -> Self {
        Self::from_fn(points.len(), |i| points[i], origin, cell)
    }

    /// [`Columns::new`] over the `n` points `point(0..n)`, whatever their storage (a tile keeps
    /// its coordinates as columns).
    pub(crate) fn from_fn(
        n: usize,
        point: impl Fn(usize) -> Point3,
        origin: Point3,
        cell: f64,
    ) -> Self {
        assert!(cell > 0.0 && cell.is_finite(), "column width {cell}");
        let local = |i: usize| {
            let p = point(i);
            [p[0] - origin[0], p[1] - origin[1], p[2] - origin[2]]
        };
        let XyGrid { corner, cell, dims } =
            XyGrid::fit((0..n).map(local), cell, MAX_COLUMNS_PER_POINT * n);
        let mut index = Columns {
            origin,
            cell,
            inverse: 1.0 / cell,
            corner,
            dims,
            starts: vec![0; dims[0] * dims[1] + 1],
            points: Vec::new(),
        };
        // A counting sort by column whose scatter stays in cache: a tile's points come in file
        // order, which on a scanner's or a random sample's file is all over the tile, and one
        // scatter straight into the columns missed the cache at nearly every point (it was a
        // third of building the index). Points go first, with their columns, into bands of
        // consecutive columns (few enough that every band's write position stays cached); then
        // each band, now small, is placed into its columns through a copy that stays in cache.
        let columns = dims[0] * dims[1];
        assert!(columns < u32::MAX as usize, "{columns} columns");
        let column: Vec<u32> = (0..n)
            .map(local)
            .map(|p| {
                let c = index.column_of(p[0], p[1]);
                index.starts[c + 1] += 1;
                c as u32
            })
            .collect();
        for k in 1..index.starts.len() {
            index.starts[k] += index.starts[k - 1];
        }
        let shift = band_shift(columns);
        let bands = columns.div_ceil(1 << shift);
        let mut next: Vec<usize> = (0..bands).map(|b| index.starts[b << shift]).collect();
        let mut sorted = vec![[0.0; 3]; n];
        let mut banded = vec![0u32; n];
        for (p, &c) in (0..n).map(local).zip(&column) {
            let b = c as usize >> shift;
            sorted[next[b]] = p;
            banded[next[b]] = c;
            next[b] += 1;
        }
        drop(column);
        // Each band into its columns: copied out (it is small), then placed back by column.
        let (mut points, mut cols, mut at) = (Vec::new(), Vec::new(), Vec::new());
        for b in 0..bands {
            let (c0, c1) = (b << shift, ((b + 1) << shift).min(columns));
            let (s0, s1) = (index.starts[c0], index.starts[c1]);
            points.clear();
            points.extend_from_slice(&sorted[s0..s1]);
            cols.clear();
            cols.extend_from_slice(&banded[s0..s1]);
            at.clear();
            at.extend_from_slice(&index.starts[c0..c1]);
            for (&p, &c) in points.iter().zip(&cols) {
                let k = c as usize - c0;
                sorted[at[k]] = p;
                at[k] += 1;
            }
        }
        drop(banded);
        // Each column by height. Points of equal height may come in any order: no query's
        // result depends on the order it visits points in (exact sums, see `m3c2::moments`).
        for w in index.starts.windows(2) {
            sorted[w[0]..w[1]].sort_unstable_by(|a, b| a[2].total_cmp(&b[2]));
        }
        index.points = sorted;
        index
    }

    /// True when nothing is indexed.
    pub(crate) fn is_empty(&self) -> bool {
        self.points.is_empty()
    }

    /// The local origin.
    pub(crate) fn origin(&self) -> Point3 {
        self.origin
    }

    /// A global point in this index's local frame.
    pub(crate) fn to_local(&self, p: &Point3) -> Point3 {
        [
            p[0] - self.origin[0],
            p[1] - self.origin[1],
            p[2] - self.origin[2],
        ]
    }

    /// The column index along one axis of a local coordinate, clamped to the grid. Monotone in
    /// `v`, so a range of coordinates maps onto a range of columns whatever the rounding.
    #[inline]
    fn axis_cell(&self, v: f64, a: usize) -> usize {
        // Truncation is the floor for the positive values that reach it (`floor` itself is a
        // library call on baseline x86-64); NaN goes to column 0.
        let f = (v - self.corner[a]) * self.inverse;
        if f > 0.0 {
            (f as usize).min(self.dims[a] - 1)
        } else {
            0
        }
    }

    #[inline]
    fn column_of(&self, x: f64, y: f64) -> usize {
        self.axis_cell(y, 1) * self.dims[0] + self.axis_cell(x, 0)
    }

    /// The columns' extent along one axis, widened by `pad` so that every point bucketed into
    /// it lies inside whatever the rounding of the bucketing.
    #[inline]
    fn axis_bounds(&self, i: usize, a: usize, pad: f64) -> (f64, f64) {
        let lo = self.corner[a] + i as f64 * self.cell;
        (lo - pad, lo + self.cell + pad)
    }

    /// The range of the points of column `k` whose height is in `[zlo, zhi]`.
    #[inline]
    fn heights(&self, k: usize, zlo: f64, zhi: f64) -> (usize, usize) {
        let (s, e) = (self.starts[k], self.starts[k + 1]);
        if s == e {
            return (s, s);
        }
        let col = &self.points[s..e];
        // On terrain a column usually lies wholly inside the bounds: no search then.
        let a = if col[0][2] >= zlo {
            s
        } else {
            s + col.partition_point(|p| p[2] < zlo)
        };
        let b = if col[col.len() - 1][2] <= zhi {
            e
        } else {
            s + col.partition_point(|p| p[2] <= zhi)
        };
        (a, b.max(a))
    }

    /// A rounding margin for bounds computed around `q`: far below any length that matters and
    /// far above the rounding of the arithmetic.
    fn pad(&self, q: &Point3, extent: f64) -> f64 {
        1e-9 * (1.0 + extent + self.cell + q[0].abs().max(q[1].abs()).max(q[2].abs()))
    }

    /// Call `f(v)` with `v = p − q` for every point `p` with |p − q|² ≤ `radius`² (`q` in the
    /// local frame), in no particular order.
    #[inline]
    pub fn for_each_within(&self, q: &Point3, radius: f64, mut f: impl FnMut(Point3)) {
        self.visit_sphere(q, radius, |v, inside| {
            if inside {
                f(v)
            }
        })
    }

    /// Call `f(t)` with the position `t = (p − q)·n` along the axis for every point `p` of the
    /// closed cylinder of unit axis `n` through `q` (local frame), radius `r`, extending from
    /// `−h` to `+h` along the axis: |t| ≤ h and |p − q|² − t² ≤ r².
    /// The plain walk the scans below are tested against.
    #[inline]
    #[cfg(test)]
    pub(crate) fn for_each_in_cylinder(
        &self,
        q: &Point3,
        n: &Point3,
        r: f64,
        h: f64,
        mut f: impl FnMut(f64),
    ) {
        self.visit_cylinder(q, n, r, h, |t, inside| {
            if inside {
                f(t)
            }
        })
    }

    /// [`Columns::for_each_within`] as a scan: `f(v, inside)` for every candidate the columns
    /// give, with the exact test's verdict, so that a caller can accumulate without a branch
    /// (the verdicts follow no pattern a branch predictor could learn).
    #[inline]
    pub(crate) fn visit_sphere(&self, q: &Point3, radius: f64, mut f: impl FnMut(Point3, bool)) {
        let r2 = radius * radius;
        self.sphere_candidates(q, radius, |points| {
            for p in points {
                let v = [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
                f(v, v[0] * v[0] + v[1] * v[1] + v[2] * v[2] <= r2);
            }
        })
    }

    /// The candidates of the sphere of `radius` at `q` (local frame), a column's run at a time:
    /// every point within the sphere is in one of the runs given to `f`, with others that are
    /// not (the caller tests |p − q|² ≤ radius² itself).
    #[inline]
    pub(crate) fn sphere_candidates(&self, q: &Point3, radius: f64, mut f: impl FnMut(&[Point3])) {
        if self.is_empty() || radius.is_nan() || radius < 0.0 {
            return;
        }
        let r2 = radius * radius;
        let pad = self.pad(q, radius);
        let (i0, i1) = (
            self.axis_cell(q[0] - radius - pad, 0),
            self.axis_cell(q[0] + radius + pad, 0),
        );
        let (j0, j1) = (
            self.axis_cell(q[1] - radius - pad, 1),
            self.axis_cell(q[1] + radius + pad, 1),
        );
        for j in j0..=j1 {
            let (ylo, yhi) = self.axis_bounds(j, 1, pad);
            let dy = (ylo - q[1]).max(q[1] - yhi).max(0.0);
            for i in i0..=i1 {
                let (xlo, xhi) = self.axis_bounds(i, 0, pad);
                let dx = (xlo - q[0]).max(q[0] - xhi).max(0.0);
                let d2 = dx * dx + dy * dy;
                if d2 > r2 {
                    continue;
                }
                let dz = (r2 - d2).sqrt() + pad;
                let (a, b) = self.heights(j * self.dims[0] + i, q[2] - dz, q[2] + dz);
                if a < b {
                    f(&self.points[a..b]);
                }
            }
        }
    }

    /// `for_each_in_cylinder` (the tests' reference) as a scan: `f(t, inside)` for every candidate, with the
    /// exact test's verdict (see [`Columns::visit_sphere`]).
    #[inline]
    pub(crate) fn visit_cylinder(
        &self,
        q: &Point3,
        n: &Point3,
        r: f64,
        h: f64,
        mut f: impl FnMut(f64, bool),
    ) {
        let r2 = r * r;
        self.cylinder_candidates(q, n, r, h, |points| {
            for p in points {
                let (t, inside) = in_cylinder(p, q, n, r2, h);
                f(t, inside);
            }
        })
    }

    /// The candidates of the cylinder of `for_each_in_cylinder` (the tests' reference), a column's run at a
    /// time: every point [`in_cylinder`] accepts is in one of the runs given to `f`, with others
    /// it rejects.
    #[inline]
    pub(crate) fn cylinder_candidates(
        &self,
        q: &Point3,
        n: &Point3,
        r: f64,
        h: f64,
        mut f: impl FnMut(&[Point3]),
    ) {
        if self.is_empty() || !(r >= 0.0 && h >= 0.0) || !n.iter().all(|c| c.is_finite()) {
            return;
        }
        let r2 = r * r;
        let pad = self.pad(q, r + h);
        // The exact test computes radial² as |v|² − t², which cancels: a point it accepts may lie
        // up to ≈ 4u(r² + h²) (u = 2⁻⁵³) beyond r² geometrically. Cull with that radius, so a
        // point the test accepts is never left out, however long and thin the cylinder.
        let rc = (r2 + 8.0 * f64::EPSILON * (r2 + h * h)).sqrt();
        // A point p = q + t·n + w with w ⊥ n, |w| ≤ rc: w's component along axis a is at most
        // rc·√(1 − n_a²) in magnitude.
        let reach = |a: usize| rc * (1.0 - n[a] * n[a]).max(0.0).sqrt() + pad;
        let e = [reach(0), reach(1), reach(2)];
        let span = |a: usize| {
            let (u, v) = (q[a] - h * n[a], q[a] + h * n[a]);
            (u.min(v) - e[a], u.max(v) + e[a])
        };
        let ((x0, x1), (y0, y1)) = (span(0), span(1));
        let (i0, i1) = (self.axis_cell(x0, 0), self.axis_cell(x1, 0));
        let (j0, j1) = (self.axis_cell(y0, 1), self.axis_cell(y1, 1));
        // The axis positions t at which a point of the cylinder can have its coordinate a in
        // [lo, hi]: the axis must pass within e[a] of that slab.
        let slab = |a: usize, lo: f64, hi: f64, t: (f64, f64)| -> (f64, f64) {
            let (lo, hi) = (lo - e[a], hi + e[a]);
            if n[a].abs() < 1e-12 {
                if q[a] >= lo && q[a] <= hi {
                    t
                } else {
                    (1.0, -1.0)
                }
            } else {
                let (u, v) = ((lo - q[a]) / n[a], (hi - q[a]) / n[a]);
                (t.0.max(u.min(v)), t.1.min(u.max(v)))
            }
        };
        let along = (-h - pad, h + pad);
        let horizontal = (n[0] * n[0] + n[1] * n[1]).sqrt();
        for j in j0..=j1 {
            let (ylo, yhi) = self.axis_bounds(j, 1, pad);
            let ty = slab(1, ylo, yhi, along);
            if ty.0 > ty.1 {
                continue;
            }
            for i in i0..=i1 {
                let k = j * self.dims[0] + i;
                let (s, e_) = (self.starts[k], self.starts[k + 1]);
                if s == e_ {
                    continue;
                }
                let (xlo, xhi) = self.axis_bounds(i, 0, pad);
                // The axis positions that can reach this column's points: within its x slab
                // and within the heights its points actually have.
                let tx = slab(0, xlo, xhi, ty);
                let (t0, t1) = slab(2, self.points[s][2] - pad, self.points[e_ - 1][2] + pad, tx);
                if t0 > t1 {
                    continue;
                }
                // Over those positions the axis's trace in the plane is a segment of half
                // length `half` around `mid`; a point of the column within rc of the axis is
                // within rc of that trace, so within rc + half of `mid`.
                let tm = 0.5 * (t0 + t1);
                let half = 0.5 * (t1 - t0) * horizontal;
                let mid = [q[0] + tm * n[0], q[1] + tm * n[1]];
                let dx = (xlo - mid[0]).max(mid[0] - xhi).max(0.0);
                let dy = (ylo - mid[1]).max(mid[1] - yhi).max(0.0);
                let reach = rc + half + pad;
                if dx * dx + dy * dy > reach * reach {
                    continue;
                }
                let (u, v) = (q[2] + t0 * n[2], q[2] + t1 * n[2]);
                let (a, b) = self.heights(k, u.min(v) - e[2] - pad, u.max(v) + e[2] + pad);
                if a < b {
                    f(&self.points[a..b]);
                }
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Pseudo-random points, each `f` of three uniform numbers, deterministic.
    fn cloud(n: usize, seed: u64, f: impl Fn([f64; 3]) -> Point3) -> Vec<Point3> {
        let mut rng = crate::rng::Rng::new(seed, 0);
        (0..n)
            .map(|_| f([rng.uniform(), rng.uniform(), rng.uniform()]))
            .collect()
    }

    fn sorted(mut v: Vec<f64>) -> Vec<f64> {
        v.sort_by(f64::total_cmp);
        v
    }

    /// Both queries return exactly the points a brute-force scan accepts, on a volume cloud, a
    /// terrain and a vertical face, for axes in every direction and several column widths
    /// (including queries reaching past the grid's edge).
    #[test]
    fn queries_equal_brute_force() {
        let shapes: Vec<Vec<Point3>> = vec![
            cloud(6000, 1, |u| {
                [u[0] * 4.0 - 2.0, u[1] * 4.0 - 2.0, u[2] * 6.0 - 3.0]
            }),
            cloud(6000, 2, |u| {
                let (x, y) = (u[0] * 6.0 - 3.0, u[1] * 6.0 - 3.0);
                [x, y, 0.4 * (x * 1.3).sin() * y.cos() + 0.01 * u[2]]
            }),
            cloud(6000, 3, |u| {
                [u[0] * 4.0 - 2.0, 0.02 * u[1], u[2] * 6.0 - 3.0]
            }),
        ];
        let axes = [
            [0.0, 0.0, 1.0],
            [0.0, 0.0, -1.0],
            [1.0, 0.0, 0.0],
            [0.0, -1.0, 0.0],
            [0.6, 0.0, 0.8],
            [0.48, -0.6, 0.64],
            [-0.36, 0.48, -0.8],
        ];
        for (s, pts) in shapes.iter().enumerate() {
            for cell in [0.1, 0.37, 1.0, 10.0] {
                let idx = Columns::new(pts, [0.5, -0.25, 0.0], cell);
                assert_eq!(idx.points.len(), pts.len());
                for (k, n) in axes.iter().enumerate() {
                    let q = idx.to_local(&pts[k * 97]);
                    let q = [q[0] + 0.03, q[1] - 0.02, q[2] + 0.01];
                    for (r, h) in [(0.3, 2.5), (0.5, 0.2), (0.25, 1.1), (1.5, 9.0)] {
                        let mut brute = Vec::new();
                        for p in pts {
                            let v = idx.to_local(p);
                            let v = [v[0] - q[0], v[1] - q[1], v[2] - q[2]];
                            let t = v[0] * n[0] + v[1] * n[1] + v[2] * n[2];
                            if t.abs() <= h
                                && v[0] * v[0] + v[1] * v[1] + v[2] * v[2] - t * t <= r * r
                            {
                                brute.push(t);
                            }
                        }
                        let mut got = Vec::new();
                        idx.for_each_in_cylinder(&q, n, r, h, |t| got.push(t));
                        assert_eq!(
                            sorted(got),
                            sorted(brute.clone()),
                            "shape {s} cell {cell} n {n:?} r {r} h {h}"
                        );
                        assert!(s == 2 || r < 1.0 || !brute.is_empty());
                    }
                    for radius in [0.05, 0.3, 1.0, 4.0] {
                        let mut brute = Vec::new();
                        for p in pts {
                            let v = idx.to_local(p);
                            let v = [v[0] - q[0], v[1] - q[1], v[2] - q[2]];
                            if v[0] * v[0] + v[1] * v[1] + v[2] * v[2] <= radius * radius {
                                brute.push(v[0] + 3.0 * v[1] + 7.0 * v[2]);
                            }
                        }
                        let mut got = Vec::new();
                        idx.for_each_within(&q, radius, |v| {
                            got.push(v[0] + 3.0 * v[1] + 7.0 * v[2])
                        });
                        assert_eq!(
                            sorted(got),
                            sorted(brute),
                            "shape {s} cell {cell} radius {radius}"
                        );
                    }
                }
            }
        }
    }

    /// A cylinder far longer than wide, whose axis runs along a column boundary: points the
    /// exact test accepts only through the rounding of |v|² − t² (a few µm off a 1 µm radius at
    /// 1 km) are still visited.
    #[test]
    fn thin_long_cylinder_across_a_column_boundary() {
        let mut pts: Vec<Point3> = (0..100)
            .map(|k| [(k % 10) as f64 * 0.5, (k / 10) as f64 * 0.5, 0.0])
            .collect();
        let (r, h) = (1e-6, 1000.0);
        for k in 0..40 {
            let off = k as f64 * 0.5e-6;
            pts.push([1.0 + 0.5 * off, 0.5, 999.0 + 0.02 * k as f64]);
        }
        let idx = Columns::new(&pts, [0.0; 3], 1.0);
        assert_eq!(idx.cell, 1.0);
        for k in 0..40 {
            let q = [1.0 - 0.25 * k as f64 * 1e-6, 0.5, 0.0];
            let n = [0.0, 0.0, 1.0];
            let brute = pts
                .iter()
                .filter(|p| {
                    let v = [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
                    let t = v[2];
                    t.abs() <= h && v[0] * v[0] + v[1] * v[1] + v[2] * v[2] - t * t <= r * r
                })
                .count();
            let mut got = 0;
            idx.for_each_in_cylinder(&q, &n, r, h, |_| got += 1);
            assert_eq!(got, brute, "query {k}");
        }
    }

    /// A sparse cloud over a wide extent gets wider columns, not a huge table; an empty one
    /// answers every query with nothing.
    #[test]
    fn wide_sparse_and_empty() {
        let pts = vec![[0.0, 0.0, 0.0], [1e5, 1e5, 1.0], [5e4, 2e4, 2.0]];
        let idx = Columns::new(&pts, [0.0; 3], 0.1);
        assert!(idx.dims[0] * idx.dims[1] <= 6, "{:?}", idx.dims);
        let mut n = 0;
        idx.for_each_within(&[5e4, 2e4, 2.0], 1.0, |_| n += 1);
        assert_eq!(n, 1);
        let empty = Columns::new(&[], [0.0; 3], 0.5);
        // A subnormal width (the parameters forbid it; the index must still not hang).
        let line = Columns::new(&[[0.0; 3], [1.0, 0.0, 0.0]], [0.0; 3], 5e-324);
        assert!(line.cell > 0.0 && line.dims[0] * line.dims[1] <= 4);
        idx.for_each_in_cylinder(&[0.0; 3], &[0.0, 0.0, 1.0], 1.0, 1.0, |_| n += 1);
        empty.for_each_in_cylinder(&[0.0; 3], &[0.0, 0.0, 1.0], 1.0, 1.0, |_| n += 1);
        empty.for_each_within(&[0.0; 3], 1.0, |_| n += 1);
        assert_eq!(n, 2);
    }
}

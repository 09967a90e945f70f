//! The region an event's volume is integrated over (SPEC.md §1 "Volume accounting").
//!
//! The footprint rectangle R is cut into a grid of cells (about one point spacing a side, the
//! resolution the data resolves). A cell belongs to the event's region when
//! - both epochs **cover** it: all four corners inside the epoch's triangulated surface, and a
//!   point of that epoch within [`COVER_RADIUS`] point spacings of its centre, measured in the
//!   footprint plane. Nothing is interpolated across a hole wider than about four spacings (water,
//!   occlusion, a flight that covered less), and nothing is extrapolated beyond the data;
//! - the event **owns** it: the location (the cell centre on the before surface) is not another
//!   event's (see [`crate::volume::ownership`]), so no location is counted by two events.
//!
//! The volume is then the exact integral of the two surfaces' difference over the union of the
//! region's cells ([`crate::volume::solid::clipped_top`]); `coverage` is the covered share of R.

use std::ops::Range;

use super::boundary;
use super::frame::Footprint;

/// A cell is covered by an epoch when one of its points lies within this many point spacings of
/// the cell's centre. For points on a grid of spacing s the farthest a location can be from its
/// nearest point is s/√2; for random points of the same density a gap of 2 s occurs with
/// probability e^{−4π} ≈ 3·10⁻⁶. So 2 s never cuts covered ground and finds every hole wider than
/// about 4 s.
pub(crate) const COVER_RADIUS: f64 = 2.0;

/// Most cells per event: beyond this the cells grow (a 1-km footprint at 0.1 m spacing).
pub(crate) const MAX_CELLS: usize = 4_000_000;

/// Which way a grid is cut into bands (`Cells::bands`).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Cut {
    Rows,
    Columns,
}

/// A grid of `nu × nv` cells that tiles the footprint `r` exactly.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Cells {
    pub(crate) r: Footprint,
    pub nu: usize,
    pub nv: usize,
}

impl Cells {
    /// Cells of about `cell` a side (at most [`MAX_CELLS`]) over `r`.
    pub(crate) fn new(r: &Footprint, cell: f64) -> Cells {
        let (w, h) = (r.u1 - r.u0, r.v1 - r.v0);
        let cell = cell.max((w * h / MAX_CELLS as f64).sqrt());
        let n = |len: f64| (((len / cell).round()) as usize).max(1);
        Cells {
            r: *r,
            nu: n(w),
            nv: n(h),
        }
    }

    /// Number of cells.
    pub fn len(&self) -> usize {
        self.nu * self.nv
    }

    /// True when there are no cells (never: a grid has at least one).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The u of grid line `i` (0..=nu); the last line is exactly `r.u1`.
    pub(crate) fn u(&self, i: usize) -> f64 {
        if i >= self.nu {
            self.r.u1
        } else {
            self.r.u0 + (self.r.u1 - self.r.u0) * i as f64 / self.nu as f64
        }
    }

    /// The v of grid line `j` (0..=nv); the last line is exactly `r.v1`.
    pub(crate) fn v(&self, j: usize) -> f64 {
        if j >= self.nv {
            self.r.v1
        } else {
            self.r.v0 + (self.r.v1 - self.r.v0) * j as f64 / self.nv as f64
        }
    }

    /// The cells of columns `cols` and rows `rows` as a grid of their own: the same lines (a
    /// part's first and last lines are the grid's), so parts side by side share their seams
    /// exactly.
    pub(crate) fn part(&self, cols: Range<usize>, rows: Range<usize>) -> Cells {
        if cols == (0..self.nu) && rows == (0..self.nv) {
            return *self;
        }
        Cells {
            r: Footprint {
                u0: self.u(cols.start),
                u1: self.u(cols.end),
                v0: self.v(rows.start),
                v1: self.v(rows.end),
            },
            nu: cols.len(),
            nv: rows.len(),
        }
    }

    /// Bands of whole rows (or whole columns) of at most `most` cells each (one row or column
    /// at least), as even as they allow, in order: (columns, rows) of each. One band, the
    /// whole grid, when it has at most `most` cells.
    pub(crate) fn bands(&self, most: usize, cut: Cut) -> Vec<(Range<usize>, Range<usize>)> {
        let (along, across) = match cut {
            Cut::Rows => (self.nv, self.nu),
            Cut::Columns => (self.nu, self.nv),
        };
        let per = (most / across).max(1);
        let n = along.div_ceil(per);
        (0..n)
            .map(|k| {
                let band = k * along / n..(k + 1) * along / n;
                match cut {
                    Cut::Rows => (0..self.nu, band),
                    Cut::Columns => (band, 0..self.nv),
                }
            })
            .collect()
    }

    /// Index of cell (i, j).
    pub(crate) fn index(&self, i: usize, j: usize) -> usize {
        j * self.nu + i
    }

    /// The cell (i, j) that (u, v) falls in, None outside the footprint.
    pub(crate) fn cell_of(&self, u: f64, v: f64) -> Option<(usize, usize)> {
        if !self.r.contains(u, v) {
            return None;
        }
        let i = ((u - self.r.u0) / (self.r.u1 - self.r.u0) * self.nu as f64) as usize;
        let j = ((v - self.r.v0) / (self.r.v1 - self.r.v0) * self.nv as f64) as usize;
        Some((i.min(self.nu - 1), j.min(self.nv - 1)))
    }

    /// Centre of cell (i, j).
    pub(crate) fn centre(&self, i: usize, j: usize) -> [f64; 2] {
        [
            0.5 * (self.u(i) + self.u(i + 1)),
            0.5 * (self.v(j) + self.v(j + 1)),
        ]
    }

    /// A cell's sides (du, dv).
    pub(crate) fn pitch(&self) -> (f64, f64) {
        (
            (self.r.u1 - self.r.u0) / self.nu as f64,
            (self.r.v1 - self.r.v0) / self.nv as f64,
        )
    }

    /// Area of one cell.
    pub(crate) fn cell_area(&self) -> f64 {
        self.r.area() / self.len() as f64
    }

    /// The cells (i range, j range, half-open) that the box [u0, u1] × [v0, v1] overlaps.
    pub(crate) fn overlapping(
        &self,
        u0: f64,
        u1: f64,
        v0: f64,
        v1: f64,
    ) -> (std::ops::Range<usize>, std::ops::Range<usize>) {
        let span = |lo: f64, hi: f64, a: f64, b: f64, n: usize| {
            let t = |x: f64| (x - a) / (b - a) * n as f64;
            let i0 = t(lo).floor().clamp(0.0, n as f64) as usize;
            let i1 = (t(hi).floor() + 1.0).clamp(0.0, n as f64) as usize;
            i0..i1.max(i0)
        };
        (
            span(u0, u1, self.r.u0, self.r.u1, self.nu),
            span(v0, v1, self.r.v0, self.r.v1, self.nv),
        )
    }
}

/// Which cells of a footprint an event's volume is integrated over.
#[derive(Debug, Clone, PartialEq)]
pub struct Region {
    pub cells: Cells,
    /// Per cell: in the region (covered by both epochs and owned by the event).
    pub inside: Vec<bool>,
    /// Per cell: covered by both epochs (owned or not).
    pub covered: Vec<bool>,
}

/// Where an event's region borders ground it could not measure: the region's cell edges that
/// face a cell neither epoch pair covers (a hole of either epoch) or the footprint's own edge,
/// each with the change |Δw| of the region cell behind it. A change that is still large there
/// runs on beyond what was measured (SPEC.md §1: the event says it is incomplete); ground another
/// event owns is not open (that event measures it).
#[derive(Debug, Clone, PartialEq, Default)]
pub(crate) struct OpenRim {
    /// (|Δw| of the cell, the edge's length) per open edge.
    pub(crate) edges: Vec<(f32, f32)>,
    /// The 90th percentile of |Δw| over the region's cells: how large the event's change is.
    pub(crate) p90_change: f64,
}

impl OpenRim {
    /// The length of open rim whose cell changed by more than `level`, and the open rim's length.
    pub(crate) fn changed_length(&self, level: f64) -> (f64, f64) {
        self.edges.iter().fold((0.0, 0.0), |(c, t), &(dw, len)| {
            let len = len as f64;
            (c + if dw as f64 > level { len } else { 0.0 }, t + len)
        })
    }
}

impl Region {
    /// The open rim of the region (see [`OpenRim`]), `dw` the surfaces' difference per cell
    /// ([`Region::cell_changes`]).
    pub(crate) fn open_rim(&self, dw: &[Option<f64>]) -> OpenRim {
        let c = &self.cells;
        let (du, dv) = (
            (c.r.u1 - c.r.u0) / c.nu as f64,
            (c.r.v1 - c.r.v0) / c.nv as f64,
        );
        let open = |i: isize, j: isize| {
            i < 0
                || j < 0
                || i >= c.nu as isize
                || j >= c.nv as isize
                || !self.covered[c.index(i as usize, j as usize)]
        };
        let mut edges = Vec::new();
        let mut all = Vec::new();
        for j in 0..c.nv {
            for i in 0..c.nu {
                if !self.contains(i, j) {
                    continue;
                }
                let dw = dw[c.index(i, j)].map_or(0.0, f64::abs);
                all.push(dw);
                let (ii, jj) = (i as isize, j as isize);
                for (di, dj, len) in [(-1, 0, dv), (1, 0, dv), (0, -1, du), (0, 1, du)] {
                    if open(ii + di, jj + dj) {
                        edges.push((dw as f32, len as f32));
                    }
                }
            }
        }
        all.sort_unstable_by(f64::total_cmp);
        let p90_change = all
            .get(((all.len() as f64 * 0.9) as usize).min(all.len().saturating_sub(1)))
            .copied()
            .unwrap_or(0.0);
        OpenRim { edges, p90_change }
    }
}

impl Region {
    /// The surfaces' difference at the centre of every covered cell (None elsewhere), row-major,
    /// from their heights `before` and `after` at the centres (`surface::Lattice::centres`, NaN
    /// where a surface has none): evaluated once for the open rim and the step variance.
    pub(crate) fn cell_changes(&self, before: &[f64], after: &[f64]) -> Vec<Option<f64>> {
        (0..self.cells.len())
            .map(|k| {
                let d = after[k] - before[k];
                (self.covered[k] && d.is_finite()).then_some(d)
            })
            .collect()
    }

    /// The variance (m⁶) of the volume from where the points happen to sample a step: a TIN puts
    /// a step of height H anywhere between the last point before it and the first after, so
    /// each length `spacing` of a step carries an error H·s·x with x uniform over ±s/2, a
    /// variance H²s⁴/12, independent from one length to the next. Smooth change gives none (a
    /// TIN is exact for a plane, and its error goes with the curvature times s²), so the step is
    /// read from the second difference of the change between neighbouring cells: across a step
    /// of H between two cell centres, the two cells either side have |D2| = H, hence
    /// Σ (s² D2)² / 24 over the region's cells. `dw` is the surfaces' difference per cell
    /// ([`Region::cell_changes`]).
    ///
    /// A box scar 2.2 m wide and 0.67 m deep sampled every 0.26 m: ±0.14 m³ (95 %) from its
    /// edges alone, where the noise of thousands of points averages to a few litres.
    pub(crate) fn step_variance(&self, dw: &[Option<f64>], spacing: f64) -> f64 {
        let c = &self.cells;
        let at = |i: isize, j: isize| -> Option<f64> {
            if i < 0 || j < 0 || i >= c.nu as isize || j >= c.nv as isize {
                return None;
            }
            dw[c.index(i as usize, j as usize)]
        };
        let s4 = spacing.powi(4);
        let mut sum = 0.0;
        for j in 0..c.nv {
            for i in 0..c.nu {
                if !self.contains(i, j) {
                    continue;
                }
                let (ii, jj) = (i as isize, j as isize);
                let Some(d) = at(ii, jj) else { continue };
                let second = |a: Option<f64>, b: Option<f64>| match (a, b) {
                    (Some(a), Some(b)) => (a - 2.0 * d + b).abs(),
                    _ => 0.0,
                };
                let d2 = second(at(ii - 1, jj), at(ii + 1, jj))
                    .max(second(at(ii, jj - 1), at(ii, jj + 1)));
                sum += s4 * d2 * d2 / 24.0;
            }
        }
        sum
    }
}

/// One polygon of a region's outline in (u, v): an outer ring (counter-clockwise) and its holes
/// (clockwise), first vertex not repeated.
#[derive(Debug, Clone, PartialEq)]
pub(crate) struct Polygon {
    pub(crate) outer: Vec<[f64; 2]>,
    pub(crate) holes: Vec<Vec<[f64; 2]>>,
}

impl Region {
    /// The region from per-cell `covered` (both epochs) and `owned` flags.
    pub(crate) fn new(cells: Cells, covered: Vec<bool>, owned: &[bool]) -> Region {
        let inside = covered.iter().zip(owned).map(|(&c, &o)| c && o).collect();
        Region {
            cells,
            inside,
            covered,
        }
    }

    /// Is cell (i, j) in the region?
    pub(crate) fn contains(&self, i: usize, j: usize) -> bool {
        self.inside[self.cells.index(i, j)]
    }

    /// Area of the region.
    pub(crate) fn area(&self) -> f64 {
        self.inside.iter().filter(|&&x| x).count() as f64 * self.cells.cell_area()
    }

    /// The covered share of the footprint (0..1).
    pub(crate) fn coverage(&self) -> f64 {
        self.covered.iter().filter(|&&x| x).count() as f64 / self.cells.len() as f64
    }

    /// True when no cell is in the region.
    pub(crate) fn is_empty(&self) -> bool {
        !self.inside.iter().any(|&x| x)
    }

    /// The outline of the region: the cell edges between a region cell and a cell outside it (or
    /// the footprint's edge), chained into rings, straight runs merged; holes assigned to the
    /// outer ring around them.
    pub(crate) fn outline(&self) -> Vec<Polygon> {
        let c = &self.cells;
        let node = |i: usize, j: usize| (j * (c.nu + 1) + i) as u32;
        let pos = |n: u32| {
            let (i, j) = (n as usize % (c.nu + 1), n as usize / (c.nu + 1));
            [c.u(i), c.v(j)]
        };
        let is_in = |i: isize, j: isize| {
            i >= 0
                && j >= 0
                && (i as usize) < c.nu
                && (j as usize) < c.nv
                && self.contains(i as usize, j as usize)
        };
        // Counter-clockwise cell edges facing a cell outside the region: the region on the left.
        let mut edges = Vec::new();
        for j in 0..c.nv {
            for i in 0..c.nu {
                if !self.contains(i, j) {
                    continue;
                }
                let (ii, jj) = (i as isize, j as isize);
                if !is_in(ii, jj - 1) {
                    edges.push((node(i, j), node(i + 1, j)));
                }
                if !is_in(ii + 1, jj) {
                    edges.push((node(i + 1, j), node(i + 1, j + 1)));
                }
                if !is_in(ii, jj + 1) {
                    edges.push((node(i + 1, j + 1), node(i, j + 1)));
                }
                if !is_in(ii - 1, jj) {
                    edges.push((node(i, j + 1), node(i, j)));
                }
            }
        }
        let rings: Vec<Vec<[f64; 2]>> = boundary::loops(&edges, pos)
            .into_iter()
            .map(|l| simplify(l.into_iter().map(pos).collect()))
            .collect();
        let (mut outers, mut holes) = (Vec::new(), Vec::new());
        for r in rings {
            if boundary::signed_area2(&r) > 0.0 {
                outers.push(Polygon {
                    outer: r,
                    holes: Vec::new(),
                });
            } else {
                holes.push(r);
            }
        }
        let half = [
            0.5 * (c.r.u1 - c.r.u0) / c.nu as f64,
            0.5 * (c.r.v1 - c.r.v0) / c.nv as f64,
        ];
        for h in holes {
            // The centre of the region cell on the left of the hole's first edge.
            let (a, b) = (h[0], h[1]);
            let d = [b[0] - a[0], b[1] - a[1]];
            let len = d[0].hypot(d[1]);
            let left = [-d[1] / len, d[0] / len];
            let probe = [
                0.5 * (a[0] + b[0]) + left[0] * half[0],
                0.5 * (a[1] + b[1]) + left[1] * half[1],
            ];
            // Innermost outer ring around the probe (rings nest when islands sit in holes).
            let owner = outers
                .iter_mut()
                .filter(|p| boundary::contains(&p.outer, probe))
                .min_by(|x, y| {
                    boundary::signed_area2(&x.outer).total_cmp(&boundary::signed_area2(&y.outer))
                });
            if let Some(p) = owner {
                p.holes.push(h);
            }
        }
        outers
    }
}

/// Drop the vertices of a rectilinear ring where it goes straight on.
fn simplify(ring: Vec<[f64; 2]>) -> Vec<[f64; 2]> {
    let n = ring.len();
    let keep = |k: usize| {
        let (p, q, r) = (ring[(k + n - 1) % n], ring[k], ring[(k + 1) % n]);
        let cross = (q[0] - p[0]) * (r[1] - q[1]) - (q[1] - p[1]) * (r[0] - q[0]);
        cross != 0.0
    };
    (0..n).filter(|&k| keep(k)).map(|k| ring[k]).collect()
}

/// Which (u, v) locations have a point within a radius: points bucketed on a grid of that radius,
/// a query looks at the 3 × 3 buckets around it.
pub(crate) struct PointCoverage {
    origin: [f64; 2],
    size: f64,
    nx: usize,
    ny: usize,
    /// Bucket b's points are `points[start[b]..start[b + 1]]`.
    start: Vec<u32>,
    points: Vec<[f64; 2]>,
}

impl PointCoverage {
    /// Index the (u, v) of `points` that fall in `r` grown by `radius`.
    pub(crate) fn new(points: impl Iterator<Item = [f64; 2]>, r: &Footprint, radius: f64) -> Self {
        let g = r.grown(radius);
        let size = radius.max(1e-9);
        let nx = (((g.u1 - g.u0) / size).ceil() as usize).clamp(1, 1 << 14);
        let ny = (((g.v1 - g.v0) / size).ceil() as usize).clamp(1, 1 << 14);
        let size = size
            .max((g.u1 - g.u0) / nx as f64)
            .max((g.v1 - g.v0) / ny as f64);
        let bucket = |p: &[f64; 2]| {
            let bx = (((p[0] - g.u0) / size) as usize).min(nx - 1);
            let by = (((p[1] - g.v0) / size) as usize).min(ny - 1);
            by * nx + bx
        };
        let pts: Vec<[f64; 2]> = points.filter(|p| g.contains(p[0], p[1])).collect();
        let mut count = vec![0u32; nx * ny + 1];
        for p in &pts {
            count[bucket(p) + 1] += 1;
        }
        for b in 0..nx * ny {
            count[b + 1] += count[b];
        }
        let mut fill = count.clone();
        let mut sorted = vec![[0.0; 2]; pts.len()];
        for p in &pts {
            let b = bucket(p);
            sorted[fill[b] as usize] = *p;
            fill[b] += 1;
        }
        PointCoverage {
            origin: [g.u0, g.v0],
            size,
            nx,
            ny,
            start: count,
            points: sorted,
        }
    }

    /// Is there a point within `radius` (the one given to [`PointCoverage::new`]) of (u, v)?
    pub(crate) fn covers(&self, u: f64, v: f64, radius: f64) -> bool {
        let bx = ((u - self.origin[0]) / self.size).floor() as isize;
        let by = ((v - self.origin[1]) / self.size).floor() as isize;
        let r2 = radius * radius;
        for y in by - 1..=by + 1 {
            for x in bx - 1..=bx + 1 {
                if x < 0 || y < 0 || x as usize >= self.nx || y as usize >= self.ny {
                    continue;
                }
                let b = y as usize * self.nx + x as usize;
                let pts = &self.points[self.start[b] as usize..self.start[b + 1] as usize];
                if pts
                    .iter()
                    .any(|p| (p[0] - u).powi(2) + (p[1] - v).powi(2) <= r2)
                {
                    return true;
                }
            }
        }
        false
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn square() -> Footprint {
        Footprint {
            u0: -2.0,
            u1: 2.0,
            v0: -1.0,
            v1: 1.0,
        }
    }

    #[test]
    fn cells_tile_the_footprint() {
        let c = Cells::new(&square(), 0.3);
        assert_eq!((c.nu, c.nv), (13, 7));
        assert_eq!(c.u(0), -2.0);
        assert_eq!(c.u(c.nu), 2.0);
        assert!((c.cell_area() * c.len() as f64 - 8.0).abs() < 1e-12);
        let (iu, iv) = c.overlapping(-2.5, -1.9, 0.95, 3.0);
        assert_eq!((iu, iv), (0..1, 6..7));
    }

    #[test]
    fn outline_with_a_hole_and_a_pinch() {
        // 4 × 3 cells: a ring of cells around the middle ones, which are out.
        let r = Footprint {
            u0: 0.0,
            u1: 4.0,
            v0: 0.0,
            v1: 3.0,
        };
        let cells = Cells::new(&r, 1.0);
        let mut inside = vec![true; 12];
        inside[cells.index(1, 1)] = false;
        inside[cells.index(2, 1)] = false;
        let region = Region::new(cells, vec![true; 12], &inside);
        let p = region.outline();
        assert_eq!(p.len(), 1);
        assert_eq!(boundary::signed_area2(&p[0].outer), 24.0);
        assert_eq!(p[0].holes.len(), 1);
        assert_eq!(boundary::signed_area2(&p[0].holes[0]), -4.0);
        assert_eq!(region.area(), 10.0);

        // Two cells touching at a corner are two polygons.
        let mut inside = vec![false; 12];
        inside[cells.index(0, 0)] = true;
        inside[cells.index(1, 1)] = true;
        let region = Region::new(cells, vec![true; 12], &inside);
        assert_eq!(region.outline().len(), 2);
    }

    #[test]
    fn point_coverage_finds_holes() {
        let r = square();
        // A grid of points every 0.1 except a hole of radius 0.5 around (1, 0).
        let mut pts = Vec::new();
        for i in -25..=25 {
            for j in -15..=15 {
                let p = [i as f64 * 0.1, j as f64 * 0.1];
                if (p[0] - 1.0).hypot(p[1]) > 0.5 {
                    pts.push(p);
                }
            }
        }
        let cov = PointCoverage::new(pts.into_iter(), &r, 0.2);
        assert!(cov.covers(0.0, 0.0, 0.2));
        assert!(cov.covers(1.0, 0.65, 0.2));
        assert!(!cov.covers(1.0, 0.0, 0.2));
        assert!(!cov.covers(1.2, 0.1, 0.2));
    }
}

//! Which of many long thin cylinders ("tubes": axis segments with a radius) hold a point: the
//! points M3C2's walk needs along the axes of core points whose walk left their tile
//! (`m3c2::reach`), gathered from the tiles those axes cross.
//!
//! Tubes along a cliff's normals run side by side in plan view (horizontal axes over one
//! stretch of beach, at different heights), so an xy index would offer a point every tube above
//! it. Here each axis is sampled every half cell of a 3-D grid and registered in the cells of
//! its samples; a point asks its own cell and the 26 around it. The cell is at least twice the
//! radius: a point within r of the axis is within r + cell/4 < cell of a sample, so the
//! sample's cell is a neighbour of the point's.

use rustc_hash::FxHashMap as HashMap;

use crate::geom::Point3;

/// The most cells registered over all tubes: the cells grow when the tubes are long.
const MAX_ENTRIES: f64 = 4e6;

/// One tube: the points p with t = (p − q)·n in [lo, hi] and |p − q|² − t² ≤ r².
#[derive(Debug, Clone, Copy)]
struct Tube {
    q: Point3,
    n: Point3,
    lo: f64,
    hi: f64,
}

/// Tubes of one radius, indexed by the cells their axes cross.
pub(crate) struct Tubes {
    r: f64,
    cell: f64,
    origin: Point3,
    tubes: Vec<Tube>,
    cells: HashMap<[i64; 3], Vec<u32>>,
    /// Bounds of every tube, grown by the radius: most points of a tile are outside.
    min: Point3,
    max: Point3,
}

impl Tubes {
    /// Tubes of radius `r` along the unit axes `n` through `q`, from t = lo to t = hi:
    /// `(q, n, lo, hi)` each.
    pub(crate) fn new(axes: &[(Point3, Point3, f64, f64)], r: f64) -> Tubes {
        let total: f64 = axes.iter().map(|a| (a.3 - a.2).abs()).sum();
        let cell = (2.0 * r)
            .max(2.0 * total / MAX_ENTRIES)
            .max(f64::MIN_POSITIVE);
        let origin = axes.first().map_or([0.0; 3], |a| a.0);
        let mut index = Tubes {
            r,
            cell,
            origin,
            tubes: Vec::with_capacity(axes.len()),
            cells: HashMap::default(),
            min: [f64::INFINITY; 3],
            max: [f64::NEG_INFINITY; 3],
        };
        for (k, &(q, n, lo, hi)) in axes.iter().enumerate() {
            index.tubes.push(Tube { q, n, lo, hi });
            let steps = ((hi - lo) / (0.5 * cell)).ceil().max(0.0) as usize;
            let mut last = None;
            for s in 0..=steps {
                let t = (lo + s as f64 * 0.5 * cell).min(hi);
                let p: Point3 = std::array::from_fn(|a| q[a] + t * n[a]);
                for (a, x) in p.iter().enumerate() {
                    index.min[a] = index.min[a].min(x - r);
                    index.max[a] = index.max[a].max(x + r);
                }
                let key = index.key(&p);
                if last != Some(key) {
                    let v = index.cells.entry(key).or_default();
                    if v.last() != Some(&(k as u32)) {
                        v.push(k as u32);
                    }
                    last = Some(key);
                }
            }
        }
        index
    }

    fn key(&self, p: &Point3) -> [i64; 3] {
        std::array::from_fn(|a| ((p[a] - self.origin[a]) / self.cell).floor() as i64)
    }

    /// Does any tube hold `p` (its radius widened by `slack`, for the roundings of callers that
    /// test again exactly)?
    pub(crate) fn any_holds(&self, p: &Point3, slack: f64) -> bool {
        if (0..3).any(|a| p[a] < self.min[a] - slack || p[a] > self.max[a] + slack) {
            return false;
        }
        let c = self.key(p);
        let r2 = (self.r + slack) * (self.r + slack);
        for dx in -1..=1 {
            for dy in -1..=1 {
                for dz in -1..=1 {
                    let Some(ids) = self.cells.get(&[c[0] + dx, c[1] + dy, c[2] + dz]) else {
                        continue;
                    };
                    for &k in ids {
                        let t = &self.tubes[k as usize];
                        let v = [p[0] - t.q[0], p[1] - t.q[1], p[2] - t.q[2]];
                        let along = v[0] * t.n[0] + v[1] * t.n[1] + v[2] * t.n[2];
                        let radial2 = v[0] * v[0] + v[1] * v[1] + v[2] * v[2] - along * along;
                        if along >= t.lo - slack && along <= t.hi + slack && radial2 <= r2 {
                            return true;
                        }
                    }
                }
            }
        }
        false
    }

    /// The xy bounds of every tube: [x0, y0, x1, y1].
    pub(crate) fn xy_bounds(&self) -> [f64; 4] {
        [self.min[0], self.min[1], self.max[0], self.max[1]]
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The index answers exactly as testing every tube, for points near and far from long tubes
    /// side by side (horizontal axes at several heights over one strip) and a vertical one.
    #[test]
    fn holds_exactly_what_a_test_of_every_tube_holds() {
        let mut axes = Vec::new();
        for k in 0..20 {
            axes.push((
                [1.0 + 0.1 * k as f64, 0.0, 5.0 + 0.3 * k as f64],
                [0.0, -1.0, 0.0],
                -2.0,
                30.0,
            ));
        }
        axes.push(([3.0, 3.0, 0.0], [0.0, 0.0, 1.0], -1.0, 12.0));
        let r = 0.05;
        let tubes = Tubes::new(&axes, r);
        let mut rng = crate::rng::Rng::new(3, 0);
        let (mut inside, mut n) = (0, 0);
        for _ in 0..200_000 {
            let p = [
                rng.uniform() * 4.0,
                rng.uniform() * 40.0 - 32.0,
                rng.uniform() * 13.0 - 1.0,
            ];
            let brute = axes.iter().any(|&(q, d, lo, hi)| {
                let v = [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
                let t = v[0] * d[0] + v[1] * d[1] + v[2] * d[2];
                t >= lo && t <= hi && v[0] * v[0] + v[1] * v[1] + v[2] * v[2] - t * t <= r * r
            });
            assert_eq!(tubes.any_holds(&p, 0.0), brute, "{p:?}");
            inside += brute as usize;
            n += 1;
        }
        assert!(inside > 20 && inside < n, "{inside} of {n} inside");
    }
}

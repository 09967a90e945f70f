//! Core points: where M3C2 is evaluated.
//!
//! Either a file given by the user, or C1 thinned to one point per cubic cell of size
//! `core_spacing` on a grid anchored at a global origin: the point nearest each occupied cell's
//! centre, ties to the earlier point (SPEC.md §1). Because the grid is global and tiles are
//! aligned to it, a tiled run picks exactly the core points of a whole-cloud run.

use rustc_hash::FxHashMap as HashMap;

use crate::geom::Point3;

/// A cell of the core-point grid.
pub(crate) type Cell = [i64; 3];

/// The cell of `p` on the grid of size `spacing` anchored at `anchor`.
pub(crate) fn cell_of(p: &Point3, anchor: &Point3, spacing: f64) -> Cell {
    [
        floor_i64((p[0] - anchor[0]) / spacing),
        floor_i64((p[1] - anchor[1]) / spacing),
        floor_i64((p[2] - anchor[2]) / spacing),
    ]
}

/// `v.floor() as i64` for every `v` (NaN → 0, saturating at the ends), without `floor`, which
/// is a library call on baseline x86-64 (a tenth of thinning): truncate, then step down where
/// truncation went up.
#[inline]
pub(crate) fn floor_i64(v: f64) -> i64 {
    let t = v as i64;
    if (t as f64) > v {
        t.saturating_sub(1)
    } else {
        t
    }
}

/// Interleave the low 21 bits of three cell indices (Morton / Z order): a global sort key that
/// keeps neighbouring cells close, for cache-friendly queries and a canonical output order.
pub(crate) fn morton(c: &Cell) -> u64 {
    fn spread(v: u64) -> u64 {
        let mut x = v & 0x1f_ffff;
        x = (x | x << 32) & 0x1f00000000ffff;
        x = (x | x << 16) & 0x1f0000ff0000ff;
        x = (x | x << 8) & 0x100f00f00f00f00f;
        x = (x | x << 4) & 0x10c30c30c30c30c3;
        x = (x | x << 2) & 0x1249249249249249;
        x
    }
    // Offset so that negative cells (points below the anchor) still order sensibly.
    let o = |v: i64| (v + (1 << 20)).clamp(0, (1 << 21) - 1) as u64;
    spread(o(c[0])) | spread(o(c[1])) << 1 | spread(o(c[2])) << 2
}

/// Indices of the chosen core points among the `n` points `point(0..n)`, with their Morton keys,
/// sorted by key. Only points for which `owned(i)` is true are candidates (a tile thins the
/// points it owns).
///
/// The points come in file order, which on a scanner's file (or a random sample) is all over
/// the tile, so a single map of the tile's cells (≈ 500k on the 120M-point pair's tiles, 20 MB)
/// missed the cache at nearly every point. The candidates are first counted into bands of
/// rows of cells holding about `BAND_POINTS` candidates (a stable counting sort of their
/// indices, 4 bytes a candidate), then each band is thinned with a map small enough to stay cached, reused from
/// band to band. A cell lies in one band, and its candidates keep their order, so the choice
/// (nearest the centre, ties to the earlier point) is the one map's.
pub(crate) fn thin(
    n: usize,
    point: impl Fn(usize) -> Point3,
    anchor: &Point3,
    spacing: f64,
    owned: impl Fn(usize) -> bool,
) -> Vec<(u64, usize)> {
    let row = |i: usize| cell_of(&point(i), anchor, spacing)[1];
    let (mut lo, mut hi, mut candidates) = (i64::MAX, i64::MIN, 0usize);
    for i in (0..n).filter(|&i| owned(i)) {
        let r = row(i);
        (lo, hi, candidates) = (lo.min(r), hi.max(r), candidates + 1);
    }
    if candidates == 0 {
        return Vec::new();
    }
    // Rows a band: about BAND_POINTS candidates a band where they spread evenly over the rows
    // (the rows of far-apart points may span all of i64: counted in u128).
    let rows = u128::from(hi.abs_diff(lo)) + 1;
    let per_band = (rows * BAND_POINTS as u128 / candidates as u128).clamp(1, rows) as u64;
    let bands = rows.div_ceil(u128::from(per_band)).min(candidates as u128) as usize;
    let band = |i: usize| ((row(i).abs_diff(lo) / per_band) as usize).min(bands - 1);
    let mut starts = vec![0usize; bands + 1];
    for i in (0..n).filter(|&i| owned(i)) {
        starts[band(i) + 1] += 1;
    }
    for b in 1..=bands {
        starts[b] += starts[b - 1];
    }
    let mut next = starts.clone();
    // Indices as u32: a tile's points are far fewer than 2³² (its unit reserves ≥ 24 bytes each).
    assert!(n <= u32::MAX as usize, "{n} points to thin");
    let mut order = vec![0u32; candidates];
    for i in (0..n).filter(|&i| owned(i)) {
        let b = band(i);
        order[next[b]] = i as u32;
        next[b] += 1;
    }
    let mut best: HashMap<Cell, (usize, f64)> = HashMap::default();
    let mut out: Vec<(u64, usize)> = Vec::new();
    for w in starts.windows(2) {
        best.clear();
        for &i in &order[w[0]..w[1]] {
            let i = i as usize;
            let p = &point(i);
            let c = cell_of(p, anchor, spacing);
            let mut d2 = 0.0;
            for k in 0..3 {
                let centre = anchor[k] + (c[k] as f64 + 0.5) * spacing;
                d2 += (p[k] - centre) * (p[k] - centre);
            }
            best.entry(c)
                .and_modify(|b| {
                    if d2 < b.1 {
                        *b = (i, d2);
                    }
                })
                .or_insert((i, d2));
        }
        out.extend(best.iter().map(|(c, b)| (morton(c), b.0)));
    }
    // Morton keys are unique per cell within the 2^21 range; the index breaks any clamp tie.
    out.sort_unstable();
    out
}

/// Candidates a band of [`thin`] holds where they spread evenly: its map (≈ 40 bytes a cell,
/// a cell holding a few candidates) then stays within a core's cache.
const BAND_POINTS: usize = 1 << 16;

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_point_per_cell_nearest_the_centre() {
        let pts = [
            [0.1, 0.1, 0.1],
            [0.5, 0.5, 0.5], // centre of cell (0,0,0)
            [0.9, 0.9, 0.9],
            [1.4, 0.5, 0.5], // cell (1,0,0)
            [1.6, 0.5, 0.5], // same distance to centre (1.5, .5, .5): earlier one wins
        ];
        let t = thin(pts.len(), |i| pts[i], &[0.0; 3], 1.0, |_| true);
        let idx: Vec<usize> = t.iter().map(|x| x.1).collect();
        assert_eq!(idx.len(), 2);
        assert!(idx.contains(&1) && idx.contains(&3));
    }

    /// The one-map thinning [`thin`] replaced, as the reference: every candidate into one map
    /// of cells, in index order.
    fn thin_with_one_map(
        pts: &[Point3],
        anchor: &Point3,
        spacing: f64,
        owned: impl Fn(usize) -> bool,
    ) -> Vec<(u64, usize)> {
        let mut best: HashMap<Cell, (usize, f64)> = HashMap::default();
        for (i, p) in pts.iter().enumerate().filter(|(i, _)| owned(*i)) {
            let c = cell_of(p, anchor, spacing);
            let d2: f64 = (0..3)
                .map(|k| (p[k] - (anchor[k] + (c[k] as f64 + 0.5) * spacing)).powi(2))
                .sum();
            let b = best.entry(c).or_insert((i, d2));
            if d2 < b.1 {
                *b = (i, d2);
            }
        }
        let mut out: Vec<(u64, usize)> = best.iter().map(|(c, b)| (morton(c), b.0)).collect();
        out.sort_unstable();
        out
    }

    #[test]
    fn bands_choose_the_points_one_map_chooses() {
        let mut rng = crate::rng::Rng::new(11, 0);
        // Coordinates on a 1 cm lattice, so that many points tie for their cell's centre.
        let mut q = |scale: f64| (rng.uniform() * scale * 100.0).round() / 100.0;
        // Terrain 300 × 200 m (many bands), a cliff 2 m wide and 150 m high (few rows, many
        // cells a row), and a one-row strip.
        let scenes: Vec<Vec<Point3>> = vec![
            (0..400_000).map(|_| [q(300.0), q(200.0), q(3.0)]).collect(),
            (0..200_000)
                .map(|_| [q(80.0), 10.0 + q(0.5), q(150.0)])
                .collect(),
            (0..50_000).map(|_| [q(500.0), 0.05, q(0.5)]).collect(),
        ];
        let anchor = [-0.013, 0.007, -0.5];
        for (s, pts) in scenes.iter().enumerate() {
            let owned = |i: usize| i % 7 != 3;
            let got = thin(pts.len(), |i| pts[i], &anchor, 0.1, owned);
            let want = thin_with_one_map(pts, &anchor, 0.1, owned);
            assert!(want.len() > 1000, "scene {s}: {} cells", want.len());
            assert_eq!(got, want, "scene {s}");
        }
        assert!(thin(3, |_| [0.0; 3], &anchor, 0.1, |_| false).is_empty());
    }

    #[test]
    fn floor_without_floor() {
        let edges = [
            0.0,
            -0.0,
            0.5,
            -0.5,
            1.0,
            -1.0,
            2.5,
            -2.5,
            1e-300,
            -1e-300,
            4503599627370495.5,
            -4503599627370495.5,
            9.3e18,
            -9.3e18,
            9.223372036854775e18,
            -9.223372036854776e18,
            f64::MAX,
            f64::MIN,
            f64::INFINITY,
            f64::NEG_INFINITY,
            f64::NAN,
            -f64::NAN,
        ];
        let mut rng = crate::rng::Rng::new(3, 0);
        let random = (0..100_000).map(|k| (rng.uniform() - 0.5) * 10f64.powi(k % 40 - 20));
        for v in edges.into_iter().chain(random) {
            assert_eq!(floor_i64(v), v.floor() as i64, "{v:e}");
        }
    }

    #[test]
    fn morton_orders_neighbours() {
        assert!(morton(&[0, 0, 0]) < morton(&[1, 0, 0]));
        assert!(morton(&[1, 0, 0]) < morton(&[0, 1, 0]));
        assert!(morton(&[1, 1, 1]) < morton(&[2, 0, 0]));
        assert_ne!(morton(&[-1, 0, 0]), morton(&[0, 0, 0]));
    }
}

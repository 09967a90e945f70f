//! Core points: where M3C2 is evaluated.
//!
//! Either a file given by the user, or C1 thinned to one point per cubic cell of size
//! `core_spacing` on a grid anchored at a global origin: the point nearest each occupied cell's
//! centre, ties to the earlier point (SPEC.md §1). Because the grid is global and tiles are
//! aligned to it, a tiled run picks exactly the core points of a whole-cloud run.

use rustc_hash::FxHashMap as HashMap;

use crate::geom::Point3;

/// A cell of the core-point grid.
pub type Cell = [i64; 3];

/// The cell of `p` on the grid of size `spacing` anchored at `anchor`.
pub fn cell_of(p: &Point3, anchor: &Point3, spacing: f64) -> Cell {
    [
        ((p[0] - anchor[0]) / spacing).floor() as i64,
        ((p[1] - anchor[1]) / spacing).floor() as i64,
        ((p[2] - anchor[2]) / spacing).floor() as i64,
    ]
}

/// Interleave the low 21 bits of three cell indices (Morton / Z order): a global sort key that
/// keeps neighbouring cells close, for cache-friendly queries and a canonical output order.
pub fn morton(c: &Cell) -> u64 {
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
pub fn thin(
    n: usize,
    point: impl Fn(usize) -> Point3,
    anchor: &Point3,
    spacing: f64,
    owned: impl Fn(usize) -> bool,
) -> Vec<(u64, usize)> {
    let mut best: HashMap<Cell, (usize, f64)> = HashMap::default();
    for i in 0..n {
        if !owned(i) {
            continue;
        }
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
    let mut out: Vec<(u64, usize)> = best.iter().map(|(c, b)| (morton(c), b.0)).collect();
    // Morton keys are unique per cell within the 2^21 range; the index breaks any clamp tie.
    out.sort_unstable();
    out
}

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

    #[test]
    fn morton_orders_neighbours() {
        assert!(morton(&[0, 0, 0]) < morton(&[1, 0, 0]));
        assert!(morton(&[1, 0, 0]) < morton(&[0, 1, 0]));
        assert!(morton(&[1, 1, 1]) < morton(&[2, 0, 0]));
        assert_ne!(morton(&[-1, 0, 0]), morton(&[0, 0, 0]));
    }
}

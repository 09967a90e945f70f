//! Gaussian smoothing of M3C2 distances (SPEC.md §1 "Smoothing"; Gorup & Bohak eq. (1),
//! normalised): at each kept point, the weighted mean Σ wᵢdᵢ / Σ wᵢ over its `k` nearest kept
//! neighbours (itself included), wᵢ = exp(−rᵢ²/2σ²), rᵢ the spatial distance. The paper's
//! unnormalised sum scales with point density; the normalised mean does not, so a constant
//! field stays constant.
//!
//! Deterministic: the k nearest are chosen by (distance, index), so ties at the k-th distance
//! do not depend on the kd-tree's traversal order, and the sum is taken in that order.

use std::num::NonZero;

use kiddo::SquaredEuclidean;
use rayon::prelude::*;

use super::{build_tree, origin_of, relative};
use crate::error::Result;

/// Smoothed distances, one per point of `points` (the kept points of a tile, halo included:
/// the caller keeps the values of the points it owns). `k == 0` or `sigma <= 0` return `d`
/// unchanged (no smoothing).
pub fn smooth(points: &[[f64; 3]], d: &[f64], k: usize, sigma: f64) -> Result<Vec<f64>> {
    let Some(k) = NonZero::new(k.min(points.len())) else {
        return Ok(d.to_vec());
    };
    if sigma.is_nan() || sigma <= 0.0 || points.len() != d.len() {
        return Ok(d.to_vec());
    }
    let local = relative(points, origin_of(points));
    let tree = build_tree(&local)?;
    let inv_two_sigma2 = 1.0 / (2.0 * sigma * sigma);
    Ok(local
        .par_iter()
        .map(|p| mean_at(&tree, p, k, f64::INFINITY, &|i| i, d, inv_two_sigma2))
        .collect())
}

/// The normalised Gaussian mean at `p` (in `tree`'s frame) over its `k` nearest among the
/// points within squared distance `reach2` of it (all of them: infinity), chosen by (distance,
/// index) — so ties at the k-th distance do not depend on the tree's traversal order — and
/// summed in that order. `index` turns a tree item into its point's index in `d`; `k` at most
/// the tree's size.
pub(crate) fn mean_at(
    tree: &super::Tree3,
    p: &[f64; 3],
    k: NonZero<usize>,
    reach2: f64,
    index: &dyn Fn(u32) -> u32,
    d: &[f64],
    inv_two_sigma2: f64,
) -> f64 {
    let nearest = tree
        .query(p)
        .nearest_n::<SquaredEuclidean<f64>>(k)
        .execute();
    let kth = nearest
        .iter()
        .map(|n| n.distance)
        .fold(0.0f64, f64::max)
        .min(reach2);
    // Everything at or within the k-th distance, ordered by (distance, index): the first k are
    // the deterministic k nearest whatever the tree returned on ties.
    let mut within: Vec<(f64, u32)> = Vec::with_capacity(k.get() + 4);
    tree.query(p)
        .within::<SquaredEuclidean<f64>>(kth)
        .unsorted()
        .visit(|it| within.push((it.distance, index(it.item))));
    within.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    let (mut num, mut den) = (0.0, 0.0);
    for &(r2, i) in within.iter().take(k.get()) {
        let w = (-r2 * inv_two_sigma2).exp();
        num += w * d[i as usize];
        den += w;
    }
    // den ≥ 1 (the point itself, r = 0, is always among its nearest).
    if den > 0.0 {
        num / den
    } else {
        f64::NAN
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn k_one_is_identity() {
        let pts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 2.0, 0.0]];
        let d = [1.0, -2.0, 3.0];
        assert_eq!(smooth(&pts, &d, 1, 1.0).unwrap(), d.to_vec());
    }

    #[test]
    fn two_points_weighted_mean() {
        // Two points 1 m apart, σ = 1: each sees the other with weight e^{-1/2}.
        let pts = [[0.0, 0.0, 0.0], [1.0, 0.0, 0.0]];
        let d = [0.0, 1.0];
        let s = smooth(&pts, &d, 2, 1.0).unwrap();
        let w = (-0.5f64).exp();
        assert!((s[0] - w / (1.0 + w)).abs() < 1e-12);
        assert!((s[1] - 1.0 / (1.0 + w)).abs() < 1e-12);
    }
}

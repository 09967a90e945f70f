//! Significance filter (SPEC.md §1; Gorup & Bohak, after Lague et al. 2013): a core point
//! takes part in event detection only when its M3C2 distance is finite, at least the
//! threshold τ in magnitude, and larger than its level of detection (|d| > LoD95).

/// Is one core point kept? NaN distances (too few points in a cylinder) and NaN LoD95s are
/// never kept: every comparison with NaN is false.
pub(crate) fn is_kept(d: f64, lod95: f64, threshold: f64) -> bool {
    d.is_finite() && d.abs() >= threshold && d.abs() > lod95
}

/// Keep-flags for all core points (`d` and `lod95` have the same length).
pub fn kept(d: &[f64], lod95: &[f64], threshold: f64) -> Vec<bool> {
    d.iter()
        .zip(lod95)
        .map(|(&d, &l)| is_kept(d, l, threshold))
        .collect()
}

/// Indices of the kept core points, ascending.
pub fn kept_indices(d: &[f64], lod95: &[f64], threshold: f64) -> Vec<usize> {
    d.iter()
        .zip(lod95)
        .enumerate()
        .filter(|(_, (&d, &l))| is_kept(d, l, threshold))
        .map(|(i, _)| i)
        .collect()
}

//! Whether a fitted transform holds out of sample: fitted on part of the stable ground, does it
//! explain the rest? (SPEC.md §1 "Registration": "confirmed out of sample".)
//!
//! Spatial blocks, not random points (Roberts et al. 2017, "Cross-validation strategies for data
//! with temporal, spatial, hierarchical, or phylogenetic structure", Ecography 40:913): the
//! sample's footprint is cut into [`BLOCKS`] × [`BLOCKS`] blocks; each block's points are held
//! out in turn, the transform fitted on the stable points of the others, and its prediction
//! compared with the held-out distances. A misregistration moves every block alike, so what the
//! other blocks fix it predicts in the held-out one; a "fit" to real change (the relief that
//! changed, a BMX track's jumps) or to ground that moves by different amounts from place to place
//! predicts nothing there.
//!
//! The measure: over the held-out points, how much of the variance the prediction claims to
//! remove it does remove, (Σ d² − Σ (d − a·p)²) / Σ (a·p)² — 1 for a misregistration (the
//! residual is the noise), 0 or below for a fit that explains nothing or makes things worse. It
//! is taken over the held-out points that are small under either hypothesis (the 80 % with the
//! least min(|d|, |d − a·p|)): changed ground is large under both and left out, without
//! favouring either.

use nalgebra::Vector3;

use super::{row, solve};
use crate::events::stable::Sample;

/// Blocks across and along the sample's footprint.
pub(crate) const BLOCKS: usize = 3;
/// Share of the held-out points the measure is taken over (the rest: changed ground).
const KEPT: f64 = 0.8;
/// Fewest held-out points, over all blocks, for the measure to be taken.
pub(crate) const MIN_HELD_OUT: usize = 30;
/// Fewest stable points a block's complement must hold to be fitted.
const MIN_TRAIN: usize = 20;

/// The block of sample `s` in the grid over `bbox` ([x0, y0, x1, y1]).
fn block(s: &Sample, bbox: &[f64; 4]) -> usize {
    let at = |v: f64, lo: f64, hi: f64| {
        let t = ((v - lo) / (hi - lo).max(f64::MIN_POSITIVE) * BLOCKS as f64).floor();
        (t.max(0.0) as usize).min(BLOCKS - 1)
    };
    at(s.xyz[1], bbox[1], bbox[3]) * BLOCKS + at(s.xyz[0], bbox[0], bbox[2])
}

/// The share of the predicted change of the held-out distances that they confirm (see the
/// module doc); NaN when too few points could be held out. `keep` is the stable ground the
/// transform was fitted on, `pool` every candidate (held out by block), `o` and `scale` the
/// fit's origin and rotation scale, `vertical_only` whether only the vertical was fitted.
pub(crate) fn confirmed_share(
    samples: &[Sample],
    keep: &[usize],
    pool: &[usize],
    o: &Vector3<f64>,
    scale: f64,
    vertical_only: bool,
) -> f64 {
    let mut bbox = [
        f64::INFINITY,
        f64::INFINITY,
        f64::NEG_INFINITY,
        f64::NEG_INFINITY,
    ];
    for &i in pool {
        let p = samples[i].xyz;
        bbox = [
            bbox[0].min(p[0]),
            bbox[1].min(p[1]),
            bbox[2].max(p[0]),
            bbox[3].max(p[1]),
        ];
    }
    // Per held-out point: its distance and the transform's prediction there.
    let mut pairs: Vec<(f64, f64)> = Vec::new();
    for b in 0..BLOCKS * BLOCKS {
        let train: Vec<usize> = keep
            .iter()
            .copied()
            .filter(|&i| block(&samples[i], &bbox) != b)
            .collect();
        let held: Vec<usize> = pool
            .iter()
            .copied()
            .filter(|&i| block(&samples[i], &bbox) == b)
            .collect();
        if held.is_empty() || train.len() < MIN_TRAIN || train.len() == keep.len() {
            continue;
        }
        let p = if vertical_only {
            super::solve_vertical(samples, &train)
        } else {
            solve(samples, &train, o, scale).0
        };
        for &i in &held {
            let pred = if vertical_only {
                samples[i].normal[2] * p[5]
            } else {
                row(&samples[i], o, scale).dot(&p)
            };
            pairs.push((samples[i].distance, pred));
        }
    }
    if pairs.len() < MIN_HELD_OUT {
        return f64::NAN;
    }
    let small = |(d, p): &(f64, f64)| d.abs().min((d - p).abs());
    pairs.sort_by(|a, b| small(a).total_cmp(&small(b)));
    pairs.truncate(((pairs.len() as f64) * KEPT).ceil() as usize);
    let (mut before, mut after, mut claimed) = (0.0, 0.0, 0.0);
    for (d, p) in &pairs {
        before += d * d;
        after += (d - p) * (d - p);
        claimed += p * p;
    }
    if claimed <= 0.0 {
        return f64::NAN;
    }
    (before - after) / claimed
}

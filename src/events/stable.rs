//! Noise and registration error measured on the stable ground (SPEC.md §1 "Noise and registration
//! error from the data").
//!
//! On ground that did not change, the M3C2 distance at core point j is the registration error
//! seen along its normal plus noise: d_j = n_j·t + e_j, t the translation between the epochs
//! (Lague et al. 2013 §3.3 treat registration as a uniform error of this kind). The stable ground
//! is not known beforehand. A registration error is small next to the changes a survey is made
//! to find, so the stable ground is the mode of the distances nearest zero: a mean shift
//! (Fukunaga & Hostetler 1975) started at d = 0 with a bandwidth of a few per-point LoD95s
//! climbs to it, whatever share of the area changed (on the St Leonards beach half of it does:
//! a water surface 2 m higher, where a median would land between the two). From the points near
//! that mode, t and the noise scale are fitted robustly (an M-estimator by iterative
//! re-selection: residuals beyond [`KEEP_SIGMAS`] robust standard deviations are left out and
//! the fit repeated).
//! - `reg_error`: the root mean square of n_j·t over the stable points, the systematic part
//!   along the normals (a 3 cm vertical shift on flat ground gives 3 cm; a horizontal shift over
//!   flat ground is invisible to M3C2 and to volumes alike, and gives nothing);
//! - `sigma_d`: the robust standard deviation (1.4826 × MAD) of the residuals e_j: the noise of
//!   one M3C2 distance on stable ground;
//! - the **variogram** of the residuals (Matheron 1963; spherical model c₀ + c₁·Sph(h/a) fitted
//!   by weighted least squares), whose partial sill c₁ and range a are the spatially correlated
//!   error that volume uncertainties propagate (Rolstad et al. 2009; Anderson 2019, ESPL 44:1015).
//!   Pure noise gives c₁ ≈ 0.
//!
//! Everything is deterministic: pairs are drawn with a fixed-seed generator from the points in
//! the order given (the callers give them in core-point key order).

use crate::geom::{dot, Point3};
use rayon::prelude::*;

use crate::spatial::Pairs;

/// Residuals beyond this many robust standard deviations are not stable ground.
pub(crate) const KEEP_SIGMAS: f64 = 2.5;
/// Re-selection rounds of the robust fit.
const ROUNDS: usize = 6;
/// Point pairs drawn at random for the variogram's long lags.
const RANDOM_PAIRS: usize = 300_000;
/// Anchor points whose neighbours give the variogram's short lags.
const ANCHORS: usize = 20_000;
/// Fewest stable points for a measurement.
pub(crate) const MIN_STABLE: usize = 50;

/// One computed core point: position, oriented normal, M3C2 distance, and the standard deviation
/// of each epoch's points along the normal in its cylinder.
#[derive(Debug, Clone, Copy)]
pub(crate) struct Sample {
    pub(crate) xyz: Point3,
    pub(crate) normal: Point3,
    pub(crate) distance: f64,
    pub(crate) std_dev: [f64; 2],
    /// LoD95 without registration error: 1.96 √(σ₁²/n₁ + σ₂²/n₂).
    pub(crate) lod: f64,
}

/// A spherical variogram γ(h) = nugget + sill · Sph(h / range).
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct Variogram {
    pub(crate) nugget: f64,
    /// Partial sill: the variance of the spatially correlated part.
    pub(crate) sill: f64,
    pub(crate) range: f64,
}

impl Variogram {
    /// Covariance of the correlated part at lag h: sill · (1 − Sph(h / range)).
    pub(crate) fn covariance(&self, h: f64) -> f64 {
        if self.sill <= 0.0 || self.range <= 0.0 {
            return 0.0;
        }
        self.sill * (1.0 - spherical(h / self.range))
    }
}

/// Sph(x) = 1.5 x − 0.5 x³ for x < 1, else 1.
fn spherical(x: f64) -> f64 {
    if x >= 1.0 {
        1.0
    } else {
        1.5 * x - 0.5 * x * x * x
    }
}

/// What the stable ground says about the pair.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct Stable {
    /// The fitted translation t between the epochs (input units).
    pub(crate) translation: Point3,
    /// RMS of n·t over the stable points.
    pub(crate) reg_error: f64,
    /// Robust standard deviation of the residual distances.
    pub(crate) sigma_d: f64,
    /// Per epoch: mean variance of the points along the normal in a cylinder, on stable ground
    /// (the per-point spread volumes propagate where a region has no event core point).
    pub(crate) point_variance: [f64; 2],
    pub(crate) variogram: Variogram,
    /// Core points judged stable, of those given.
    pub(crate) stable_points: usize,
    pub(crate) sampled_points: usize,
    pub(crate) method: String,
    /// Where the stable ground came from: `automatic` (found in the distances) or `user` (the
    /// points inside the user's polygons, `file`).
    #[serde(default = "automatic")]
    pub(crate) source: String,
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub(crate) file: Option<std::path::PathBuf>,
}

/// What the user's stable areas held for a pair, and whether they gave the stable ground.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub(crate) struct AreasUse {
    pub(crate) file: std::path::PathBuf,
    /// Points of the before survey inside the polygons that were sampled, and those with a
    /// distance.
    pub(crate) points_inside: usize,
    pub(crate) with_distance: usize,
    /// Whether the measurement is theirs (else: the automatic stable ground, and `note` says why).
    pub(crate) used: bool,
    pub(crate) note: Option<String>,
}

fn automatic() -> String {
    "automatic".into()
}

impl Stable {
    /// The systematic displacement along `normal` (unit): |n·t|.
    pub(crate) fn along(&self, normal: &Point3) -> f64 {
        dot(normal, &self.translation).abs()
    }
}

/// The median of `v` (NaN-free), reordering it.
pub(crate) fn median(v: &mut [f64]) -> f64 {
    if v.is_empty() {
        return f64::NAN;
    }
    let k = v.len() / 2;
    let (_, m, _) = v.select_nth_unstable_by(k, |a, b| a.total_cmp(b));
    *m
}

/// Least squares t for d ≈ n·t over `idx`, with a small ridge so that directions the normals do
/// not see (horizontal ones on flat ground) stay at zero instead of blowing up.
fn fit_translation(samples: &[Sample], idx: &[usize]) -> Point3 {
    let mut a = nalgebra::Matrix3::<f64>::zeros();
    let mut b = nalgebra::Vector3::<f64>::zeros();
    for &i in idx {
        let s = &samples[i];
        let n = nalgebra::Vector3::new(s.normal[0], s.normal[1], s.normal[2]);
        a += n * n.transpose();
        b += n * s.distance;
    }
    let ridge = 1e-3 * idx.len().max(1) as f64;
    a += nalgebra::Matrix3::identity() * ridge;
    match a.lu().solve(&b) {
        Some(t) => [t.x, t.y, t.z],
        None => [0.0; 3],
    }
}

/// σ_d of the stable ground `sel` found in `samples`: the robust standard deviation (1.4826 ×
/// MAD) of its distances less the translation's share, what [`measure`] reports, without the
/// variogram (the alignment needs the noise, not its spatial structure).
pub(crate) fn spread(samples: &[Sample], sel: &Selected) -> f64 {
    let mut r: Vec<f64> = sel
        .keep
        .iter()
        .map(|&i| samples[i].distance - dot(&samples[i].normal, &sel.t))
        .collect();
    let centre = median(&mut r);
    let mut dev: Vec<f64> = r.iter().map(|x| (x - centre).abs()).collect();
    1.4826 * median(&mut dev)
}

/// Measure the stable ground from `samples` (computed core points, finite distances and unit
/// normals). `spacing` is the core spacing (the variogram's shortest lag). None when fewer than
/// [`MIN_STABLE`] points are stable.
pub(crate) fn measure(samples: &[Sample], spacing: f64) -> Option<Stable> {
    let selected = select(samples)?;
    let sigma_d = spread(samples, &selected);
    let Selected { finite, keep, t } = selected;
    let reg_error = (keep
        .iter()
        .map(|&i| dot(&samples[i].normal, &t).powi(2))
        .sum::<f64>()
        / keep.len() as f64)
        .sqrt();
    let variogram = fit_variogram(samples, &keep, &t, spacing);
    let point_variance = std::array::from_fn(|k| {
        let v: Vec<f64> = keep
            .iter()
            .map(|&i| samples[i].std_dev[k].powi(2))
            .filter(|v| v.is_finite())
            .collect();
        v.iter().sum::<f64>() / v.len().max(1) as f64
    });
    Some(Stable {
        translation: t,
        reg_error,
        sigma_d,
        point_variance,
        variogram,
        stable_points: keep.len(),
        sampled_points: samples.len(),
        method: format!(
            "robust fit d = n·t on core points within {KEEP_SIGMAS} robust standard deviations \
             ({} of {} computed core points), spherical variogram of the residuals",
            keep.len(),
            finite.len()
        ),
        source: automatic(),
        file: None,
    })
}

/// The stable ground found among `samples`: the samples with a finite distance, the stable ones
/// (indices into `samples`), and the translation fitted on them.
pub(crate) struct Selected {
    pub(crate) finite: Vec<usize>,
    pub(crate) keep: Vec<usize>,
    pub(crate) t: Point3,
}

/// Find the stable ground (see the module doc): None with fewer than [`MIN_STABLE`] points.
pub(crate) fn select(samples: &[Sample]) -> Option<Selected> {
    let finite: Vec<usize> = (0..samples.len())
        .filter(|&i| {
            let s = &samples[i];
            s.distance.is_finite() && s.normal.iter().all(|x| x.is_finite())
        })
        .collect();
    if finite.len() < MIN_STABLE {
        return None;
    }
    let residual = |t: &Point3, i: usize| samples[i].distance - dot(&samples[i].normal, t);
    // The mode nearest zero, with a bandwidth of a few per-point LoD95s (the spread one distance
    // has on stable ground).
    let mut lods: Vec<f64> = finite
        .iter()
        .map(|&i| samples[i].lod)
        .filter(|l| l.is_finite() && *l > 0.0)
        .collect();
    let d: Vec<f64> = finite.iter().map(|&i| samples[i].distance).collect();
    let mut spread: Vec<f64> = d.iter().map(|x| x.abs()).collect();
    let h = if lods.is_empty() {
        1.4826 * median(&mut spread)
    } else {
        3.0 * median(&mut lods)
    }
    .max(1e-9);
    let mode = mode_near_zero(&d, h);
    let mut keep: Vec<usize> = finite
        .iter()
        .copied()
        .filter(|&i| (samples[i].distance - mode).abs() <= KEEP_SIGMAS * h)
        .collect();
    if keep.len() < MIN_STABLE {
        return None;
    }
    let mut t = fit_translation(samples, &keep);
    let mut sigma = f64::INFINITY;
    for _ in 0..ROUNDS {
        let mut r: Vec<f64> = keep.iter().map(|&i| residual(&t, i)).collect();
        let centre = median(&mut r);
        let mut dev: Vec<f64> = r.iter().map(|x| (x - centre).abs()).collect();
        sigma = 1.4826 * median(&mut dev);
        if sigma.is_nan() || sigma <= 0.0 {
            sigma = dev.iter().cloned().fold(0.0, f64::max).max(1e-12);
        }
        let next: Vec<usize> = finite
            .iter()
            .copied()
            .filter(|&i| (residual(&t, i) - centre).abs() <= KEEP_SIGMAS * sigma)
            .collect();
        if next.len() < MIN_STABLE || next == keep {
            break;
        }
        keep = next;
        t = fit_translation(samples, &keep);
    }
    if keep.len() < MIN_STABLE {
        return None;
    }
    let _ = sigma;
    Some(Selected { finite, keep, t })
}

/// The mode of `d`'s kernel density (Gaussian kernel, bandwidth `h`) that a mean shift started
/// at 0 climbs to. Weights are taken relative to the nearest value, so that a mode many
/// bandwidths away is still found instead of every weight underflowing.
fn mode_near_zero(d: &[f64], h: f64) -> f64 {
    let mut c = 0.0;
    for _ in 0..200 {
        let near = d
            .iter()
            .map(|x| (x - c).powi(2))
            .fold(f64::INFINITY, f64::min);
        let (mut sw, mut swx) = (0.0, 0.0);
        for x in d {
            let w = (-((x - c).powi(2) - near) / (2.0 * h * h)).exp();
            sw += w;
            swx += w * x;
        }
        let next = swx / sw;
        if (next - c).abs() <= 1e-6 * h {
            return next;
        }
        c = next;
    }
    c
}

/// The empirical semivariogram of the residuals of the stable points in log-spaced lag bins,
/// fitted with a spherical model.
fn fit_variogram(samples: &[Sample], keep: &[usize], t: &Point3, spacing: f64) -> Variogram {
    let pts: Vec<Point3> = keep.iter().map(|&i| samples[i].xyz).collect();
    let res: Vec<f64> = keep
        .iter()
        .map(|&i| samples[i].distance - dot(&samples[i].normal, t))
        .collect();
    let n = pts.len();
    let dist2 = |a: usize, b: usize| {
        let (p, q) = (&pts[a], &pts[b]);
        (p[0] - q[0]).powi(2) + (p[1] - q[1]).powi(2) + (p[2] - q[2]).powi(2)
    };
    let dist = |a: usize, b: usize| dist2(a, b).sqrt();
    // Lag bins from one core spacing to the largest distance, 4 per octave.
    let mut rng = crate::rng::SplitMix64::new(0x5EED_7A15);
    let mut max_d: f64 = 0.0;
    for _ in 0..2000 {
        max_d = max_d.max(dist(rng.below(n), rng.below(n)));
    }
    let h0 = spacing.max(1e-9);
    if max_d.is_nan() || max_d <= 2.0 * h0 {
        return Variogram {
            nugget: 0.0,
            sill: 0.0,
            range: 0.0,
        };
    }
    let per_octave = 4.0;
    let bins = ((max_d / h0).log2() * per_octave).ceil() as usize + 1;
    // Lag bins of a quarter octave centred on h0·2^(k/4), the first reaching down to h0/2: bin k
    // holds the squared lags from edges[k] up to edges[k + 1]. Comparing squared lags with the
    // edges spares a logarithm per pair (millions of pairs), and the square root of the pairs
    // no bin holds.
    let edges: Vec<f64> = (0..=bins)
        .map(|k| {
            let lo = if k == 0 {
                0.5 * h0
            } else {
                h0 * ((k as f64 - 0.5) / per_octave).exp2()
            };
            lo * lo
        })
        .collect();
    // The bin of a squared lag: the edges it reaches, counted without a branch (a binary search
    // mispredicts on random lags).
    let bin = |h2: f64| -> Option<usize> {
        let k: usize = edges.iter().map(|&e| usize::from(e <= h2)).sum();
        (k > 0 && k <= bins).then(|| k - 1)
    };
    let step = (n / ANCHORS).max(1);
    let reach = 8.0 * h0;
    let near_pairs = Pairs::new(&pts, reach);
    let anchors: Vec<usize> = (0..n).step_by(step).collect();
    // The pairs are summed in parts of fixed size, in parallel, and the parts added in order:
    // the same sums whatever the number of threads.
    let part = |lags: &mut Lags, a: usize, b: usize, h2: f64| {
        if let Some(k) = bin(h2) {
            lags.add(k, h2.sqrt(), 0.5 * (res[a] - res[b]).powi(2));
        }
    };
    let near: Vec<Lags> = anchors
        .par_chunks(512)
        .map(|chunk| {
            let mut lags = Lags::new(bins);
            let mut found = Vec::new();
            for &a in chunk {
                near_pairs.after(a, &mut found, |b, h2| part(&mut lags, a, b, h2));
            }
            lags
        })
        .collect();
    let pairs: Vec<(usize, usize)> = (0..RANDOM_PAIRS.min(n * (n - 1) / 2))
        .map(|_| (rng.below(n), rng.below(n)))
        .collect();
    let far: Vec<Lags> = pairs
        .par_chunks(16384)
        .map(|chunk| {
            let mut lags = Lags::new(bins);
            for &(a, b) in chunk {
                let h2 = dist2(a, b);
                if a != b && h2 > reach * reach {
                    part(&mut lags, a, b, h2);
                }
            }
            lags
        })
        .collect();
    let mut total = Lags::new(bins);
    for l in near.iter().chain(&far) {
        total.merge(l);
    }
    let Lags { sum, lag, count } = total;
    let obs: Vec<(f64, f64, f64)> = (0..bins)
        .filter(|&k| count[k] >= 30)
        .map(|k| {
            (
                lag[k] / count[k] as f64,
                sum[k] / count[k] as f64,
                count[k] as f64,
            )
        })
        .collect();
    fit_spherical(&obs, h0, max_d)
}

/// Sums per lag bin of a variogram: semivariances, lags, pair counts.
struct Lags {
    sum: Vec<f64>,
    lag: Vec<f64>,
    count: Vec<usize>,
}

impl Lags {
    fn new(bins: usize) -> Self {
        Lags {
            sum: vec![0.0; bins],
            lag: vec![0.0; bins],
            count: vec![0; bins],
        }
    }

    fn add(&mut self, k: usize, h: f64, semivariance: f64) {
        self.sum[k] += semivariance;
        self.lag[k] += h;
        self.count[k] += 1;
    }

    fn merge(&mut self, other: &Lags) {
        for k in 0..self.sum.len() {
            self.sum[k] += other.sum[k];
            self.lag[k] += other.lag[k];
            self.count[k] += other.count[k];
        }
    }
}

/// Weighted least squares fit of nugget + sill·Sph(h/range) to (lag, γ, weight), the range by a
/// search over log-spaced candidates, nugget and sill ≥ 0.
fn fit_spherical(obs: &[(f64, f64, f64)], h0: f64, max_d: f64) -> Variogram {
    let flat = || {
        let w: f64 = obs.iter().map(|o| o.2).sum();
        Variogram {
            nugget: if w > 0.0 {
                obs.iter().map(|o| o.1 * o.2).sum::<f64>() / w
            } else {
                0.0
            },
            sill: 0.0,
            range: 0.0,
        }
    };
    if obs.len() < 3 {
        return flat();
    }
    let mut best = (f64::INFINITY, flat());
    let sse = |v: &Variogram| {
        obs.iter()
            .map(|&(h, g, w)| {
                w * (g - v.nugget - v.sill * spherical(h / v.range.max(1e-12))).powi(2)
            })
            .sum::<f64>()
    };
    best.0 = sse(&best.1);
    let candidates = 40;
    for k in 0..=candidates {
        let range = 2.0 * h0 * (max_d / (2.0 * h0)).powf(k as f64 / candidates as f64);
        // Linear in (nugget, sill): normal equations on x = Sph(h / range).
        let (mut sw, mut sx, mut sxx, mut sy, mut sxy) = (0.0, 0.0, 0.0, 0.0, 0.0);
        for &(h, g, w) in obs {
            let x = spherical(h / range);
            sw += w;
            sx += w * x;
            sxx += w * x * x;
            sy += w * g;
            sxy += w * x * g;
        }
        let det = sw * sxx - sx * sx;
        if det.abs() < 1e-300 {
            continue;
        }
        let mut sill = (sw * sxy - sx * sy) / det;
        let mut nugget = (sy - sill * sx) / sw;
        if sill < 0.0 {
            sill = 0.0;
            nugget = sy / sw;
        }
        if nugget < 0.0 {
            nugget = 0.0;
            sill = if sxx > 0.0 { sxy / sxx } else { 0.0 }.max(0.0);
        }
        let v = Variogram {
            nugget,
            sill,
            range,
        };
        let e = sse(&v);
        if e < best.0 {
            best = (e, v);
        }
    }
    best.1
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// A 100 m × 100 m field of core points every metre, normals up except a band of slopes.
    fn field(shift: Point3, noise: f64, correlated: f64, seed: u64) -> Vec<Sample> {
        let mut rng = Rng::new(seed, 0);
        let mut out = Vec::new();
        for j in 0..100 {
            for i in 0..100 {
                let (x, y) = (i as f64, j as f64);
                let tilt: f64 = if i > 60 { 0.5 } else { 0.0 };
                let n = [tilt, 0.0, 1.0];
                let len = (1.0 + tilt * tilt).sqrt();
                let n = [n[0] / len, n[1] / len, n[2] / len];
                // A smooth correlated error: a wave of 40 m wavelength.
                let c = correlated * (x / 40.0 * std::f64::consts::TAU).sin();
                let d = dot(&n, &shift) + c + noise * rng.normal();
                out.push(Sample {
                    xyz: [x, y, 0.0],
                    normal: n,
                    distance: d,
                    std_dev: [noise; 2],
                    lod: 1.96 * noise,
                });
            }
        }
        out
    }

    #[test]
    fn a_vertical_shift_is_measured_and_changes_are_left_out() {
        let mut s = field([0.0, 0.0, 0.03], 0.003, 0.0, 1);
        // A fifth of the points changed by a metre.
        for (k, p) in s.iter_mut().enumerate() {
            if k % 5 == 0 {
                p.distance += 1.0;
            }
        }
        let m = measure(&s, 1.0).unwrap();
        assert!((m.translation[2] - 0.03).abs() < 0.001, "{m:?}");
        assert!((m.reg_error - 0.03).abs() < 0.002, "{m:?}");
        assert!((m.sigma_d - 0.003).abs() < 0.0006, "{m:?}");
        assert!(m.stable_points < 8200 && m.stable_points > 7500, "{m:?}");
        // Pure noise: no correlated part to speak of.
        assert!(m.variogram.sill < 0.1 * m.variogram.nugget, "{m:?}");
    }

    #[test]
    fn most_of_the_area_changed_and_the_stable_mode_is_still_found() {
        // 60 % of the points moved by +2 m (a water level), the rest shifted 1 cm.
        let mut s = field([0.0, 0.0, 0.01], 0.005, 0.0, 4);
        for (k, p) in s.iter_mut().enumerate() {
            if k % 5 < 3 {
                p.distance += 2.0 + 0.01 * ((k % 7) as f64 - 3.0);
            }
        }
        let m = measure(&s, 1.0).unwrap();
        assert!((m.translation[2] - 0.01).abs() < 0.002, "{m:?}");
        assert!((m.sigma_d - 0.005).abs() < 0.001, "{m:?}");
    }

    #[test]
    fn a_shift_far_beyond_the_noise_is_still_found() {
        let s = field([0.0, 0.0, 0.08], 0.002, 0.0, 5);
        let m = measure(&s, 1.0).unwrap();
        assert!((m.translation[2] - 0.08).abs() < 0.001, "{m:?}");
    }

    #[test]
    fn a_horizontal_shift_shows_where_the_ground_slopes() {
        let s = field([0.02, 0.0, 0.0], 0.002, 0.0, 2);
        let m = measure(&s, 1.0).unwrap();
        assert!((m.translation[0] - 0.02).abs() < 0.002, "{m:?}");
        // Only the sloping band (39 % of the points, n·t = 0.0089) sees it.
        let want: f64 = 0.39f64.sqrt() * 0.02 * 0.5 / 1.25f64.sqrt();
        assert!(
            (m.reg_error - want).abs() < 0.1 * want,
            "{} vs {want}",
            m.reg_error
        );
    }

    #[test]
    fn a_correlated_error_gives_a_sill_and_a_range() {
        let s = field([0.0; 3], 0.002, 0.02, 3);
        let m = measure(&s, 1.0).unwrap();
        // A sine of amplitude 2 cm has variance 2e-4; its correlation fades over ~10-20 m.
        let v = m.variogram;
        assert!(v.sill > 1e-4 && v.sill < 4e-4, "{v:?}");
        assert!(v.range > 8.0 && v.range < 40.0, "{v:?}");
    }
}

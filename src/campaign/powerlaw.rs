//! The magnitude–frequency distribution of event volumes: a continuous power law
//! p(x) ∝ x^−α for x ≥ x_min, fitted as Clauset, Shalizi & Newman (2009), "Power-law
//! distributions in empirical data", SIAM Review 51:661, do it:
//!
//! - for a given x_min, α by maximum likelihood over the n values x ≥ x_min,
//!   α = 1 + n [Σ ln(xᵢ / x_min)]⁻¹ (their eq. 3.1), with standard error (α − 1)/√n (eq. 3.2);
//! - x_min is the candidate (each distinct value) whose fitted law is closest to the tail's
//!   empirical distribution in the Kolmogorov–Smirnov distance
//!   D = sup_x |S(x) − P(x)|, P(x) = 1 − (x / x_min)^(1−α) (their §3.3).
//!
//! Only finite positive values are used (|event volumes|; the caller takes the magnitude): NaN,
//! infinities, zero and negative values are ignored, and [`PowerLawFit::n`] counts the values
//! that were used. Deterministic: the values are sorted with `total_cmp`, and of candidates with
//! the same distance the smallest x_min wins. The search is O(n²) in the number of distinct
//! values (each candidate's sum and distance are one pass over its tail): milliseconds for the
//! thousands of events a campaign finds.

/// The fewest values a tail may have: x_min is chosen among the distinct values that leave at
/// least this many at or above it, and [`fit`] gives `None` for fewer valid values.
///
/// Why 10: α − 1 is estimated as (α − 1) n / G with G ~ Gamma(n, 1) (eq. 3.1 is an
/// inverse-gamma variable), so its relative standard error is 1/√n (eq. 3.2) and its bias
/// 1/(n − 1). With α = 2.5, the central 80 % of estimates span 1.9–4.1 for n = 5 (±45 %, 25 %
/// too steep on average) — wider than the range of exponents reported for rockfall inventories,
/// so no exponent worth printing — and 2.1–3.4 for n = 10 (±32 %, 11 %). Clauset et al. find
/// the estimate reliable only from about 50 tail values; 10 is the smallest tail for which a
/// reported α ± se still says something, and few enough that a pair with a dozen losses gets a
/// fit. The floor seldom decides x_min itself: the expected distance of a fitted sample falls
/// as 1/√n, so the minimisation shuns short tails on its own (on 400 samples of 40 values, pure
/// power law or lognormal, floors of 2 and 5 chose a tail shorter than 10 in 0.25–2 % of them).
pub(crate) const MIN_TAIL: usize = 10;

/// A power law fitted to the tail x ≥ `x_min` of `n` positive values.
#[derive(Debug, Clone, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct PowerLawFit {
    /// The exponent α of the density p(x) ∝ x^−α (the exceedance falls as x^(1−α)).
    pub alpha: f64,
    /// Its standard error, (α − 1)/√n_tail.
    pub alpha_se: f64,
    /// The lower bound of the power-law behaviour (one of the values).
    pub x_min: f64,
    /// Values ≥ x_min: the ones α is estimated from.
    pub n_tail: usize,
    /// Valid (finite, positive) values given.
    pub n: usize,
    /// Kolmogorov–Smirnov distance between the tail's empirical CDF and the fitted CDF.
    pub ks: f64,
}

/// Fit p(x) ∝ x^−α for x ≥ x_min to the positive `values` (|event volumes|): for each candidate
/// x_min (each distinct value leaving at least `MIN_TAIL` values in the tail), α by maximum
/// likelihood and the Kolmogorov–Smirnov distance of the tail to the fitted law; x_min
/// minimises that distance. NaN, infinite, zero and negative values are ignored. `None` when
/// fewer than `MIN_TAIL` values remain or all of them are equal.
pub fn fit(values: &[f64]) -> Option<PowerLawFit> {
    let x = valid_sorted(values);
    let n = x.len();
    if n < MIN_TAIL {
        return None;
    }
    let mut best: Option<PowerLawFit> = None;
    let mut start = 0;
    while n - start >= MIN_TAIL {
        let x_min = x[start];
        let tail = &x[start..];
        if let Some(alpha) = alpha_mle(tail, x_min) {
            let d = ks_distance(tail, x_min, alpha);
            if best.as_ref().is_none_or(|b| d < b.ks) {
                best = Some(PowerLawFit {
                    alpha,
                    alpha_se: (alpha - 1.0) / (tail.len() as f64).sqrt(),
                    x_min,
                    n_tail: tail.len(),
                    n,
                    ks: d,
                });
            }
        }
        // The next distinct value.
        start += tail.partition_point(|w| *w <= x_min);
    }
    best
}

/// The complementary CDF rows for a magnitude–frequency plot or CSV: for each value, sorted
/// descending, (value, number of values ≥ it, that number / n). Tied values share their count
/// (all of them are ≥ each). The same values as [`fit`] uses: NaN, infinite, zero and negative
/// ones are left out, and n counts the rest.
pub(crate) fn exceedance(values: &[f64]) -> Vec<(f64, usize, f64)> {
    let mut x = valid_sorted(values);
    x.reverse();
    let n = x.len();
    let mut rows = Vec::with_capacity(n);
    let mut i = 0;
    while i < n {
        let j = i + x[i..].partition_point(|w| *w >= x[i]);
        for &v in &x[i..j] {
            rows.push((v, j, j as f64 / n as f64));
        }
        i = j;
    }
    rows
}

/// The finite positive values, ascending.
fn valid_sorted(values: &[f64]) -> Vec<f64> {
    let mut x: Vec<f64> = values
        .iter()
        .copied()
        .filter(|v| v.is_finite() && *v > 0.0)
        .collect();
    x.sort_by(f64::total_cmp);
    x
}

/// α = 1 + n / Σ ln(xᵢ / x_min) over `tail` (all ≥ x_min); `None` when every value equals
/// x_min (the sum is zero: no exponent).
fn alpha_mle(tail: &[f64], x_min: f64) -> Option<f64> {
    let sum: f64 = tail.iter().map(|v| (v / x_min).ln()).sum();
    (sum > 0.0).then(|| 1.0 + tail.len() as f64 / sum)
}

/// sup_x |S(x) − P(x)| for the ascending `tail`, S its empirical CDF and P the power law's CDF
/// 1 − (x / x_min)^(1−α). S steps at each distinct value v from (values < v)/n to
/// (values ≤ v)/n and P is continuous and increasing, so the supremum is at a step, on one
/// side of it.
fn ks_distance(tail: &[f64], x_min: f64, alpha: f64) -> f64 {
    let n = tail.len() as f64;
    let mut d: f64 = 0.0;
    let mut i = 0;
    while i < tail.len() {
        let v = tail[i];
        let j = i + tail[i..].partition_point(|w| *w <= v);
        let p = 1.0 - (v / x_min).powf(1.0 - alpha);
        d = d
            .max((p - i as f64 / n).abs())
            .max((j as f64 / n - p).abs());
        i = j;
    }
    d
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rng::Rng;

    /// `n` values of a power law by inverse transform: x = x_min (1 − u)^(−1/(α − 1)).
    fn power_law(rng: &mut Rng, n: usize, alpha: f64, x_min: f64) -> Vec<f64> {
        (0..n)
            .map(|_| x_min * (1.0 - rng.uniform()).powf(-1.0 / (alpha - 1.0)))
            .collect()
    }

    /// The distance of `tail` (any order) to the law, by counting: at every value v,
    /// S(v) = #(≤ v)/n and S(v−) = #(< v)/n against P(v).
    fn brute_ks(tail: &[f64], x_min: f64, alpha: f64) -> f64 {
        let n = tail.len() as f64;
        let mut d: f64 = 0.0;
        for &v in tail {
            let le = tail.iter().filter(|w| **w <= v).count() as f64 / n;
            let lt = tail.iter().filter(|w| **w < v).count() as f64 / n;
            let p = 1.0 - (v / x_min).powf(1.0 - alpha);
            d = d.max((le - p).abs()).max((lt - p).abs());
        }
        d
    }

    /// The whole fit without sorting or partitioning: every value as a candidate x_min.
    fn brute_fit(values: &[f64]) -> (f64, f64, usize, f64) {
        let mut best = (f64::NAN, f64::NAN, 0, f64::INFINITY);
        for &x_min in values {
            let tail: Vec<f64> = values.iter().copied().filter(|v| *v >= x_min).collect();
            if tail.len() < MIN_TAIL {
                continue;
            }
            let logs: f64 = tail.iter().map(|v| v.ln() - x_min.ln()).sum();
            if logs <= 0.0 {
                continue;
            }
            let alpha = 1.0 + tail.len() as f64 / logs;
            let d = brute_ks(&tail, x_min, alpha);
            if d < best.3 - 1e-12 || ((d - best.3).abs() <= 1e-12 && x_min < best.0) {
                best = (alpha, x_min, tail.len(), d);
            }
        }
        best
    }

    #[test]
    fn recovers_a_pure_power_law() {
        let mut rng = Rng::new(2009, 0);
        let x = power_law(&mut rng, 2000, 2.5, 1.0);
        let f = fit(&x).unwrap();
        assert_eq!(f.n, 2000);
        assert!(
            (f.alpha - 2.5).abs() < 3.0 * f.alpha_se,
            "alpha {} ± {}",
            f.alpha,
            f.alpha_se
        );
        assert!((f.alpha_se - (f.alpha - 1.0) / (f.n_tail as f64).sqrt()).abs() < 1e-12);
        // Any x_min at or above the true one fits; the distance picks one that keeps most of
        // the sample.
        assert!(f.x_min >= 1.0 && f.x_min < 1.5, "x_min {}", f.x_min);
        assert!(f.n_tail > 1000, "n_tail {}", f.n_tail);
        // The expected distance of a fitted sample of n is ≈ 0.87/√n.
        assert!(f.ks < 2.0 / (f.n_tail as f64).sqrt(), "ks {}", f.ks);
    }

    #[test]
    fn finds_the_tail_of_a_mixture() {
        // Body: lognormal (median 2, σ_ln 0.7) kept below 10; tail: α = 2.2 from x_min = 10.
        let mut rng = Rng::new(7, 1);
        let mut x = Vec::new();
        while x.len() < 1500 {
            let v = 2.0 * (0.7 * rng.normal()).exp();
            if v < 10.0 {
                x.push(v);
            }
        }
        x.extend(power_law(&mut rng, 500, 2.2, 10.0));
        let f = fit(&x).unwrap();
        assert_eq!(f.n, 2000);
        assert!(f.x_min > 6.0 && f.x_min < 15.0, "x_min {}", f.x_min);
        assert!(
            (f.alpha - 2.2).abs() < 3.0 * f.alpha_se,
            "alpha {} ± {}",
            f.alpha,
            f.alpha_se
        );
        // A fit over everything is far worse: the body is no power law.
        let all = alpha_mle(&valid_sorted(&x), valid_sorted(&x)[0]).unwrap();
        let sorted = valid_sorted(&x);
        assert!(ks_distance(&sorted, sorted[0], all) > 3.0 * f.ks);
    }

    #[test]
    fn distance_agrees_with_counting() {
        let mut rng = Rng::new(11, 0);
        let x = power_law(&mut rng, 500, 1.8, 0.5);
        let f = fit(&x).unwrap();
        let tail: Vec<f64> = x.iter().copied().filter(|v| *v >= f.x_min).collect();
        let logs: f64 = tail.iter().map(|v| v.ln() - f.x_min.ln()).sum();
        let alpha = 1.0 + tail.len() as f64 / logs;
        assert_eq!(tail.len(), f.n_tail);
        assert!((alpha - f.alpha).abs() < 1e-9, "{alpha} vs {}", f.alpha);
        assert!((brute_ks(&tail, f.x_min, alpha) - f.ks).abs() < 1e-12);
        // And at an x_min that is not the chosen one, on the sorted tail.
        let sorted = valid_sorted(&x);
        let other = &sorted[100..];
        let a = alpha_mle(other, other[0]).unwrap();
        assert!((ks_distance(other, other[0], a) - brute_ks(other, other[0], a)).abs() < 1e-12);
    }

    #[test]
    fn the_whole_search_agrees_with_brute_force_with_ties() {
        // Rounded to 0.1: many ties, in the body and in the tail.
        let mut rng = Rng::new(5, 3);
        let x: Vec<f64> = power_law(&mut rng, 80, 2.0, 1.0)
            .into_iter()
            .map(|v| (v * 10.0).round() / 10.0)
            .collect();
        let f = fit(&x).unwrap();
        let (alpha, x_min, n_tail, d) = brute_fit(&x);
        assert_eq!(f.x_min, x_min);
        assert_eq!(f.n_tail, n_tail);
        assert!((f.alpha - alpha).abs() < 1e-9);
        assert!((f.ks - d).abs() < 1e-12);
    }

    #[test]
    fn order_of_the_values_does_not_matter() {
        let mut rng = Rng::new(3, 0);
        let x = power_law(&mut rng, 300, 2.5, 2.0);
        let mut y = x.clone();
        rng.shuffle(&mut y);
        assert_eq!(fit(&x), fit(&y));
        assert_eq!(exceedance(&x), exceedance(&y));
    }

    #[test]
    fn degenerate_inputs() {
        assert_eq!(fit(&[]), None);
        assert_eq!(fit(&[3.0]), None);
        assert_eq!(fit(&[3.0; 50]), None);
        let nine: Vec<f64> = (1..=9).map(f64::from).collect();
        assert_eq!(fit(&nine), None);
        let ten: Vec<f64> = (1..=10).map(f64::from).collect();
        let f = fit(&ten).unwrap();
        assert_eq!((f.n, f.n_tail, f.x_min), (10, 10, 1.0));
        // Invalid values are ignored, not counted.
        let mut dirty = ten.clone();
        dirty.extend([f64::NAN, -4.0, 0.0, f64::INFINITY, f64::NEG_INFINITY, -0.0]);
        assert_eq!(fit(&dirty), Some(f));
        assert_eq!(fit(&[f64::NAN; 20]), None);
        // Nine valid values and junk are still too few.
        let mut few = nine.clone();
        few.extend([f64::NAN, -1.0]);
        assert_eq!(fit(&few), None);
        // Equal values above a distinct body still fit (the equal tail is no candidate).
        let mut top = vec![5.0; 12];
        top.extend([1.0, 2.0]);
        let f = fit(&top).unwrap();
        assert_eq!((f.x_min, f.n_tail), (1.0, 14));
        assert!(f.alpha.is_finite() && f.ks.is_finite());
    }

    #[test]
    fn exceedance_rows() {
        let rows = exceedance(&[2.0, 1.0, f64::NAN, 3.0, 2.0, -5.0]);
        assert_eq!(
            rows,
            vec![
                (3.0, 1, 0.25),
                (2.0, 3, 0.75),
                (2.0, 3, 0.75),
                (1.0, 4, 1.0)
            ]
        );
        assert!(exceedance(&[]).is_empty());
        assert_eq!(exceedance(&[7.0]), vec![(7.0, 1, 1.0)]);
    }
}

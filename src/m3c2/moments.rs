//! Order-independent sums for neighbourhood statistics.
//!
//! The points of a neighbourhood are visited in an order that depends on how the tile's index was
//! built, and the tile depends on the tiling. Floating-point sums in visiting order would make the
//! last bits of every mean and covariance depend on the tiling. Integer sums are exact, so the
//! result is the same in any order, at one pass and no sort.
//!
//! Values are quantised to steps of `extent / 2²⁶` (the query's radius or half-length: 45 nm for
//! a 3 m half-length), rounded to nearest, so a square fits in 52 bits. They are summed in
//! 64-bit registers, which hold 2¹⁰ such squares, and moved into 128-bit totals every 2¹⁰ values:
//! exact for any count, at the cost of 64-bit arithmetic in the loop. The centred moments come
//! from the exact raw sums without the cancellation that makes raw-moment formulas unsafe in
//! floating point.
//!
//! `add(value, keep)` takes every candidate the index tests with the test's verdict and adds the
//! value only when `keep`, without a branch: about half the candidates of a neighbourhood are
//! rejected, in no predictable pattern.

/// Bits of a quantised value's magnitude (relative to the extent).
const BITS: i32 = 26;
/// Candidates between two moves of the 64-bit sums into the 128-bit totals.
const FLUSH: u32 = 1 << 10;
/// Adding 1.5 · 2⁵² to |x| < 2⁵¹ rounds x to the nearest integer (ties to even) and leaves it in
/// the low bits of the mantissa: a rounding without the library call `round` is on baseline
/// x86-64, and without the saturation checks of `as i64`.
const MAGIC: f64 = 6_755_399_441_055_744.0;

/// Scales values of magnitude up to `extent` to integers of magnitude up to 2²⁶.
#[derive(Debug, Clone, Copy)]
struct Quantiser {
    factor: f64,
}

impl Quantiser {
    fn new(extent: f64) -> Self {
        // An extent the quantisation cannot serve (not positive, not finite, or so small that
        // the factor overflows; the parameters forbid these) falls back to 1: the sums stay
        // exact and finite, only coarse.
        let factor = 2f64.powi(BITS) / extent;
        Quantiser {
            factor: if extent > 0.0 && factor.is_finite() {
                factor
            } else {
                2f64.powi(BITS)
            },
        }
    }

    /// The quantised value, or 0 when `!keep` (whatever `v` is: values outside the extent, even
    /// NaN, only ever reach this masked out).
    #[inline(always)]
    fn masked(&self, v: f64, keep: bool) -> i64 {
        // Wrapping: a rejected value far outside the extent may give any bits, masked below.
        let x = ((v * self.factor + MAGIC).to_bits() as i64).wrapping_sub(MAGIC.to_bits() as i64);
        x & -(keep as i64)
    }

    /// A sum of quantised values back in the input's units.
    fn value(&self, sum: i128) -> f64 {
        sum as f64 / self.factor
    }

    /// A sum of products of two quantised values back in squared units.
    fn value2(&self, sum: i128) -> f64 {
        sum as f64 / (self.factor * self.factor)
    }
}

/// Count, mean and population variance of scalar values of magnitude up to the extent.
#[derive(Debug, Clone, Copy)]
pub struct Moments1 {
    q: Quantiser,
    pending: u32,
    n: i64,
    s: i64,
    ss: i64,
    total: [i128; 3],
}

impl Moments1 {
    /// Sums for values within ±`extent`.
    pub fn new(extent: f64) -> Self {
        Moments1 {
            q: Quantiser::new(extent),
            pending: 0,
            n: 0,
            s: 0,
            ss: 0,
            total: [0; 3],
        }
    }

    /// Add `v` when `keep`.
    #[inline(always)]
    pub fn add(&mut self, v: f64, keep: bool) {
        let x = self.q.masked(v, keep);
        self.n += keep as i64;
        self.s += x;
        self.ss += x * x;
        self.pending += 1;
        if self.pending == FLUSH {
            self.flush();
        }
    }

    #[inline(never)]
    fn flush(&mut self) {
        self.total[0] += self.n as i128;
        self.total[1] += self.s as i128;
        self.total[2] += self.ss as i128;
        (self.n, self.s, self.ss, self.pending) = (0, 0, 0, 0);
    }

    fn totals(&self) -> [i128; 3] {
        let mut m = *self;
        m.flush();
        m.total
    }

    pub fn count(&self) -> u64 {
        self.totals()[0] as u64
    }

    /// (mean, population variance); NaN for no values.
    pub fn mean_var(&self) -> (f64, f64) {
        let [n, s, ss] = self.totals();
        if n == 0 {
            return (f64::NAN, f64::NAN);
        }
        let mean = self.q.value(s) / n as f64;
        // n²·var·factor² = n·Σx² − (Σx)², exact in i128.
        let var = self.q.value2(n * ss - s * s) / (n as f64 * n as f64);
        (mean, var.max(0.0))
    }
}

/// Count, mean and covariance of 3-D offsets of magnitude up to the extent.
#[derive(Clone, Copy)]
pub struct Moments3 {
    q: Quantiser,
    pending: u32,
    n: i64,
    s: [i64; 3],
    /// xx xy xz yy yz zz
    ss: [i64; 6],
    total_n: i128,
    total_s: [i128; 3],
    total_ss: [i128; 6],
}

const PAIRS: [(usize, usize); 6] = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];

impl Moments3 {
    /// Sums for offsets within a ball of radius `extent`.
    pub fn new(extent: f64) -> Self {
        Moments3 {
            q: Quantiser::new(extent),
            pending: 0,
            n: 0,
            s: [0; 3],
            ss: [0; 6],
            total_n: 0,
            total_s: [0; 3],
            total_ss: [0; 6],
        }
    }

    /// Add `p` when `keep`.
    #[inline(always)]
    pub fn add(&mut self, p: [f64; 3], keep: bool) {
        let x = [
            self.q.masked(p[0], keep),
            self.q.masked(p[1], keep),
            self.q.masked(p[2], keep),
        ];
        self.n += keep as i64;
        for (s, x) in self.s.iter_mut().zip(x) {
            *s += x;
        }
        for (k, &(a, b)) in PAIRS.iter().enumerate() {
            self.ss[k] += x[a] * x[b];
        }
        self.pending += 1;
        if self.pending == FLUSH {
            self.flush();
        }
    }

    #[inline(never)]
    fn flush(&mut self) {
        self.total_n += self.n as i128;
        for a in 0..3 {
            self.total_s[a] += self.s[a] as i128;
        }
        for k in 0..6 {
            self.total_ss[k] += self.ss[k] as i128;
        }
        (self.n, self.s, self.ss, self.pending) = (0, [0; 3], [0; 6], 0);
    }

    pub fn count(&self) -> usize {
        (self.total_n + self.n as i128) as usize
    }

    /// The population covariance (xx xy xz yy yz zz), exact up to the final conversion.
    pub fn covariance(&self) -> [f64; 6] {
        let mut m = *self;
        m.flush();
        let n = m.total_n;
        if n == 0 {
            return [f64::NAN; 6];
        }
        let s = &m.total_s;
        std::array::from_fn(|k| {
            let (a, b) = PAIRS[k];
            self.q.value2(n * m.total_ss[k] - s[a] * s[b]) / (n as f64 * n as f64)
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_does_not_matter_and_values_are_right() {
        let v = [0.3, -1.25, 2.0, 0.001, -0.7];
        let (mut a, mut b) = (Moments1::new(2.0), Moments1::new(2.0));
        v.iter().for_each(|x| a.add(*x, true));
        v.iter().rev().for_each(|x| b.add(*x, true));
        assert_eq!(a.mean_var(), b.mean_var());
        let m = v.iter().sum::<f64>() / 5.0;
        let var = v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / 5.0;
        let (mm, vv) = a.mean_var();
        assert!((mm - m).abs() < 1e-7 && (vv - var).abs() < 1e-7);
    }

    #[test]
    fn rejected_values_leave_no_trace() {
        let mut a = Moments1::new(1.0);
        let mut b = Moments1::new(1.0);
        for k in 0..5000 {
            let v = (k as f64 * 0.37).sin();
            a.add(v, true);
            b.add(v, true);
            // Anything at all, rejected: far outside the extent, infinite, NaN.
            b.add(
                [1e300, f64::INFINITY, f64::NAN, -7.0, -1.5e8, 1.5e8][k % 6],
                false,
            );
        }
        assert_eq!(a.count(), 5000);
        assert_eq!(a.mean_var(), b.mean_var());
        assert_eq!(a.count(), b.count());
    }

    /// Many values at the extent (the largest squares) across many flushes: the 128-bit totals
    /// keep the sums exact.
    #[test]
    fn large_counts_stay_exact() {
        let mut m = Moments1::new(3.0);
        let n = 3 * FLUSH as usize + 17;
        for k in 0..n {
            m.add(if k % 2 == 0 { 3.0 } else { -3.0 }, true);
        }
        let (mean, var) = m.mean_var();
        assert_eq!(m.count(), n as u64);
        assert!((mean - 3.0 / n as f64).abs() < 1e-12, "{mean}");
        assert!((var - (9.0 - mean * mean)).abs() < 1e-9, "{var}");
    }

    #[test]
    fn covariance_of_a_line() {
        let mut m = Moments3::new(2.0);
        for i in 0..11 {
            let t = i as f64 * 0.1 - 0.5;
            m.add([t, 2.0 * t, -t], true);
            m.add([5.0, f64::NAN, 1.0], false);
        }
        assert_eq!(m.count(), 11);
        let c = m.covariance();
        let var = 0.1; // of t = -0.5..0.5 step 0.1: Σt²/11 = 1.1/11
        for (k, f) in [1.0, 2.0, -1.0, 4.0, -2.0, 1.0].iter().enumerate() {
            assert!((c[k] - f * var).abs() < 1e-7, "{k}: {}", c[k]);
        }
    }
}

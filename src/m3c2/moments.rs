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

use crate::geom::Point3;

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
pub(crate) struct Moments1 {
    q: Quantiser,
    pending: u32,
    n: i64,
    s: i64,
    ss: i64,
    total: [i128; 3],
}

impl Moments1 {
    /// Sums for values within ±`extent`.
    pub(crate) fn new(extent: f64) -> Self {
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
    pub(crate) fn add(&mut self, v: f64, keep: bool) {
        let x = self.q.masked(v, keep);
        self.n += keep as i64;
        self.s += x;
        self.ss += x * x;
        self.pending += 1;
        if self.pending == FLUSH {
            self.flush();
        }
    }

    /// [`Moments1::add`] of every value of `values` (each within the extent), kept: the same
    /// sums, a block at a time in a loop without a branch that the compiler turns into vector
    /// instructions (as [`Moments3::add_within`]).
    pub(crate) fn add_all(&mut self, values: &[f64]) {
        let mut rest = values;
        while !rest.is_empty() {
            let room = (FLUSH - self.pending) as usize;
            let (block, next) = rest.split_at(room.min(rest.len()));
            let (s, ss) = block_sums1(block, self.q.factor);
            self.n += block.len() as i64;
            self.s += s;
            self.ss += ss;
            self.pending += block.len() as u32;
            if self.pending == FLUSH {
                self.flush();
            }
            rest = next;
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

    pub(crate) fn count(&self) -> u64 {
        self.totals()[0] as u64
    }

    /// (mean, population variance); NaN for no values.
    pub(crate) fn mean_var(&self) -> (f64, f64) {
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
pub(crate) struct Moments3 {
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

/// The sum and sum of squares of the quantised `values` (each within the extent, at most
/// [`FLUSH`] of them: the sums fit i64).
fn block_sums1(values: &[f64], factor: f64) -> (i64, i64) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2, checked just above.
            return unsafe { block_sums1_avx2(values, factor) };
        }
    }
    block_sums1_of(values, factor)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn block_sums1_avx2(values: &[f64], factor: f64) -> (i64, i64) {
    block_sums1_of(values, factor)
}

/// [`block_sums1`], inlined into each instruction set's copy.
#[inline(always)]
fn block_sums1_of(values: &[f64], factor: f64) -> (i64, i64) {
    let magic = MAGIC.to_bits() as i64;
    let (mut s, mut ss) = (0i64, 0i64);
    for &v in values {
        // Within the extent a value is at most 2²⁶ in magnitude: its 32-bit truncation is
        // itself, and the square a 32 × 32 → 64-bit multiplication.
        let x = ((v * factor + MAGIC).to_bits() as i64).wrapping_sub(magic) as i32 as i64;
        s += x;
        ss += x * x;
    }
    (s, ss)
}

/// The count, sums and sums of products of the quantised `p − q` of the `points` within
/// √`r2` of `q` (at most [`FLUSH`] points: the sums fit i64).
fn block_sums(points: &[Point3], q: &Point3, r2: f64, factor: f64) -> (i64, [i64; 3], [i64; 6]) {
    #[cfg(target_arch = "x86_64")]
    {
        if std::arch::is_x86_feature_detected!("avx2") {
            // SAFETY: the CPU has AVX2, checked just above.
            return unsafe { block_sums_avx2(points, q, r2, factor) };
        }
    }
    block_sums_of(points, q, r2, factor)
}

#[cfg(target_arch = "x86_64")]
#[target_feature(enable = "avx2")]
fn block_sums_avx2(
    points: &[Point3],
    q: &Point3,
    r2: f64,
    factor: f64,
) -> (i64, [i64; 3], [i64; 6]) {
    block_sums_of(points, q, r2, factor)
}

/// [`block_sums`], inlined into each instruction set's copy.
#[inline(always)]
fn block_sums_of(points: &[Point3], q: &Point3, r2: f64, factor: f64) -> (i64, [i64; 3], [i64; 6]) {
    let (mut n, mut s, mut ss) = (0i64, [0i64; 3], [0i64; 6]);
    let magic = MAGIC.to_bits() as i64;
    for p in points {
        let v = [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
        let keep = v[0] * v[0] + v[1] * v[1] + v[2] * v[2] <= r2;
        let mask = -(keep as i64);
        // A kept value is at most 2²⁶ in magnitude: its 32-bit truncation is itself, and the
        // products are 32 × 32 → 64-bit multiplications (one instruction for four).
        let x = v.map(|c| {
            let r = ((c * factor + MAGIC).to_bits() as i64).wrapping_sub(magic) & mask;
            r as i32 as i64
        });
        n += keep as i64;
        for k in 0..3 {
            s[k] += x[k];
        }
        ss[0] += x[0] * x[0];
        ss[1] += x[0] * x[1];
        ss[2] += x[0] * x[2];
        ss[3] += x[1] * x[1];
        ss[4] += x[1] * x[2];
        ss[5] += x[2] * x[2];
    }
    (n, s, ss)
}

impl Moments3 {
    /// Sums for offsets within a ball of radius `extent`.
    pub(crate) fn new(extent: f64) -> Self {
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
    #[cfg(test)]
    #[inline(always)]
    pub(crate) fn add(&mut self, p: [f64; 3], keep: bool) {
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

    pub(crate) fn count(&self) -> usize {
        (self.total_n + self.n as i128) as usize
    }

    /// [`Moments3::add`] of `p − q` for every `p` of `points`, kept when |p − q|² ≤ `r2`: the
    /// same sums, a block at a time in a loop without a branch, which the compiler turns into
    /// vector instructions (four points at a time where the CPU has AVX2, chosen when the
    /// program runs; two otherwise).
    pub(crate) fn add_within(&mut self, points: &[Point3], q: &Point3, r2: f64) {
        let mut rest = points;
        while !rest.is_empty() {
            let room = (FLUSH - self.pending) as usize;
            let (block, next) = rest.split_at(room.min(rest.len()));
            let (n, s, ss) = block_sums(block, q, r2, self.q.factor);
            self.n += n;
            for (total, part) in self.s.iter_mut().zip(s) {
                *total += part;
            }
            for (total, part) in self.ss.iter_mut().zip(ss) {
                *total += part;
            }
            self.pending += block.len() as u32;
            if self.pending == FLUSH {
                self.flush();
            }
            rest = next;
        }
    }

    /// The population covariance (xx xy xz yy yz zz), exact up to the final conversion.
    pub(crate) fn covariance(&self) -> [f64; 6] {
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

    /// Values added a block at a time (the vector path where the CPU has AVX2, and the plain
    /// one) give the sums of one-at-a-time adds, bit for bit, across flushes.
    #[test]
    fn values_added_at_once_equal_the_adds_one_at_a_time() {
        let mut rng = crate::rng::Rng::new(9, 0);
        let h = 3.0;
        let v: Vec<f64> = (0..3 * FLUSH as usize + 311)
            .map(|_| (rng.uniform() - 0.5) * 2.0 * h)
            .collect();
        let mut one = Moments1::new(h);
        v.iter().for_each(|&x| one.add(x, true));
        let mut all = Moments1::new(h);
        all.add(0.25, false);
        for part in v.chunks(700) {
            all.add_all(part);
        }
        assert_eq!(one.count(), all.count());
        let bits = |m: &Moments1| {
            let (a, b) = m.mean_var();
            (a.to_bits(), b.to_bits())
        };
        assert_eq!(bits(&one), bits(&all));
        let factor = Quantiser::new(h).factor;
        let block = &v[..FLUSH as usize];
        assert_eq!(block_sums1_of(block, factor), block_sums1(block, factor));
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

    /// The block sums of points within a radius (the vector path where the CPU has AVX2, and
    /// the plain one) equal the one-at-a-time adds of every candidate with its verdict, bit
    /// for bit, across flushes and with candidates far outside.
    #[test]
    fn sums_within_a_radius_equal_the_adds_one_at_a_time() {
        let mut rng = crate::rng::Rng::new(5, 0);
        let q = [0.3, -0.2, 0.1];
        let radius = 1.0;
        let points: Vec<Point3> = (0..3 * FLUSH as usize + 77)
            .map(|k| {
                let spread = if k % 13 == 0 { 40.0 } else { 1.5 };
                [0.0; 3].map(|_| (rng.uniform() - 0.5) * 2.0 * spread)
            })
            .collect();
        let mut one = Moments3::new(radius);
        for p in &points {
            let v = [p[0] - q[0], p[1] - q[1], p[2] - q[2]];
            one.add(
                v,
                v[0] * v[0] + v[1] * v[1] + v[2] * v[2] <= radius * radius,
            );
        }
        let mut blocks = Moments3::new(radius);
        for part in points.chunks(300) {
            blocks.add_within(part, &q, radius * radius);
        }
        assert!(one.count() > 300, "{}", one.count());
        assert_eq!(one.count(), blocks.count());
        assert_eq!(
            one.covariance().map(f64::to_bits),
            blocks.covariance().map(f64::to_bits)
        );
        let factor = Quantiser::new(radius).factor;
        let plain = block_sums_of(&points[..FLUSH as usize], &q, radius * radius, factor);
        assert_eq!(
            plain,
            block_sums(&points[..FLUSH as usize], &q, radius * radius, factor)
        );
    }
}

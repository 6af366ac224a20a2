//! The one encoding behind every content hash of calib: measurements, the measured data
//! a worker caches, objective fingerprints, campaign identities and evaluation keys.
//!
//! BLAKE3 over a tag naming what is hashed and its version, then the content written
//! with these rules: integers as little-endian `u64`, numbers as the little-endian bits
//! of their IEEE-754 `f64` (so `0.0` and `-0.0` differ, and every bit counts), text as
//! its byte length then its UTF-8 bytes. Sequences carry their length, either where they
//! are ([`ContentHasher::series`]) or in counts written before them. What a hash covers,
//! and in which order, is documented where it is computed; store keys and the protocol's
//! `measurement_hash` depend on it, so a change there needs a new tag.

/// A BLAKE3 hasher that writes content in the encoding above.
#[derive(Debug, Clone)]
pub struct ContentHasher(blake3::Hasher);

impl ContentHasher {
    /// A hasher for content of the kind `tag` names (written first, as is).
    pub fn new(tag: &[u8]) -> ContentHasher {
        let mut hasher = blake3::Hasher::new();
        hasher.update(tag);
        ContentHasher(hasher)
    }

    /// Bytes as they are: another hash, or a name whose end is known.
    pub fn bytes(&mut self, bytes: &[u8]) -> &mut Self {
        self.0.update(bytes);
        self
    }

    /// A count or an index, as a little-endian `u64`.
    pub fn count(&mut self, count: usize) -> &mut Self {
        self.0.update(&(count as u64).to_le_bytes());
        self
    }

    /// Text, after its byte length.
    pub fn text(&mut self, text: &str) -> &mut Self {
        self.count(text.len()).bytes(text.as_bytes())
    }

    /// Numbers whose count is written elsewhere (before them, or fixed by the format).
    pub fn values(&mut self, values: &[f64]) -> &mut Self {
        let bytes: Vec<u8> = values.iter().flat_map(|v| v.to_le_bytes()).collect();
        self.0.update(&bytes);
        self
    }

    /// Numbers after their count.
    pub fn series(&mut self, values: &[f64]) -> &mut Self {
        self.count(values.len()).values(values)
    }

    /// The 32-byte hash of what was written.
    pub fn finish(&self) -> [u8; 32] {
        *self.0.finalize().as_bytes()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_encoding_is_pinned() {
        let mut expected = blake3::Hasher::new();
        expected.update(b"tag\0");
        expected.update(&3u64.to_le_bytes());
        expected.update(b"abc");
        expected.update(&2u64.to_le_bytes());
        expected.update(&1.5f64.to_bits().to_le_bytes());
        expected.update(&(-0.0f64).to_bits().to_le_bytes());
        expected.update(&7u64.to_le_bytes());
        expected.update(&0.25f64.to_bits().to_le_bytes());
        expected.update(&[9, 9]);
        let hash = ContentHasher::new(b"tag\0")
            .text("abc")
            .series(&[1.5, -0.0])
            .count(7)
            .values(&[0.25])
            .bytes(&[9, 9])
            .finish();
        assert_eq!(hash, *expected.finalize().as_bytes());
    }

    #[test]
    fn lengths_keep_neighbours_apart() {
        let split = |a: &str, b: &str| ContentHasher::new(b"t").text(a).text(b).finish();
        assert_ne!(split("ab", "c"), split("a", "bc"));
        let series = |a: &[f64], b: &[f64]| ContentHasher::new(b"t").series(a).series(b).finish();
        assert_ne!(series(&[1.0, 2.0], &[3.0]), series(&[1.0], &[2.0, 3.0]));
    }
}

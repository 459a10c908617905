//! The host's one random number generator: SplitMix64 (G. Steele, D. Lea, C. Flood, "Fast splittable
//! pseudorandom number generators", OOPSLA 2014).
//!
//! Tiny, seedable from any 64-bit value, and good enough for jitter, stratification and test inputs. Every
//! random number on the host (form-factor rays, the regression jitter, benchmarks, tests) comes from here, so a
//! seed means the same stream everywhere. Streams that must not depend on the order of work (the rays of one
//! pair of patches, whatever thread casts them) are keyed by their coordinates through
//! [`SplitMix64::for_stream`].

/// A SplitMix64 generator: a 64-bit counter advanced by the golden-ratio increment, then finalized.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct SplitMix64(u64);

impl SplitMix64 {
    /// A generator whose state starts at `seed`.
    #[must_use]
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// A generator for one stream, seeded from `seed` and the stream's coordinates `(a, b)` (e.g. a pair of patch
    /// indices): each coordinate is mixed in through one step of the generator, so neighbouring coordinates give
    /// unrelated streams.
    #[must_use]
    pub fn for_stream(seed: u64, a: u64, b: u64) -> Self {
        let mut g = Self(seed);
        let k1 = g.next_u64() ^ a;
        g = Self(k1);
        let k2 = g.next_u64() ^ b;
        Self(k2)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in the half-open interval `[0, 1)`, in steps of `2^-53`.
    pub fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in `(0, 1]`, meant as the open interval: the midpoints of [`SplitMix64::unit`]'s steps, rounded
    /// to f64. Below 1/2 the midpoint is exact, so the value is never 0 nor on a step's boundary; above 1/2 the
    /// rounding may land on the step's upper end, and the last step's midpoint rounds to exactly 1 (probability
    /// 2^-53), the boundary of the last stratum a jittered grid draws it for. The rounding is kept because the
    /// streams, and so the baked tables, depend on it.
    pub fn open_unit(&mut self) -> f64 {
        ((self.next_u64() >> 11) as f64 + 0.5) * (1.0 / (1u64 << 53) as f64)
    }

    /// Fisher-Yates shuffle (the modulo bias of `% (k + 1)`, below 2^-50, is irrelevant here).
    pub fn shuffle<T>(&mut self, items: &mut [T]) {
        for k in (1..items.len()).rev() {
            items.swap(k, (self.next_u64() % (k as u64 + 1)) as usize);
        }
    }
}

#[cfg(test)]
mod tests {
    use super::SplitMix64;

    /// The first outputs for seed 0 are those of the reference implementation (Vigna's `splitmix64.c`), and the
    /// two unit intervals are half a step apart.
    #[test]
    fn matches_the_reference_stream() {
        let mut g = SplitMix64::new(0);
        assert_eq!(g.next_u64(), 0xE220_A839_7B1D_CDAF);
        assert_eq!(g.next_u64(), 0x6E78_9E6A_A1B9_65F4);
        let (mut a, mut b) = (SplitMix64::new(42), SplitMix64::new(42));
        for _ in 0..1000 {
            let (u, o) = (a.unit(), b.open_unit());
            assert!((0.0..1.0).contains(&u) && o > 0.0 && o <= 1.0);
            // Half a step apart, up to the rounding of `k + 1/2` (exact below 1/2).
            assert!(o >= u && o - u <= 1.0 / (1u64 << 53) as f64, "{u} {o}");
            assert!(u >= 0.5 || o - u == 0.5 / (1u64 << 53) as f64, "{u} {o}");
        }
    }

    #[test]
    fn streams_differ_and_shuffle_permutes() {
        let first = |a, b| SplitMix64::for_stream(7, a, b).next_u64();
        assert_ne!(first(0, 1), first(1, 0));
        assert_ne!(first(0, 1), first(0, 2));
        assert_eq!(first(3, 4), first(3, 4));
        let mut items: Vec<u32> = (0..50).collect();
        SplitMix64::new(1).shuffle(&mut items);
        assert_ne!(items, (0..50).collect::<Vec<_>>());
        items.sort_unstable();
        assert_eq!(items, (0..50).collect::<Vec<_>>());
    }
}

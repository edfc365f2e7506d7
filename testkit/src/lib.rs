//! Test helpers shared by the integration tests of `rovib` (`tests/common`) and of
//! `rovib-runtime` (`runtime/tests/common`): a small seeded generator, so that every run sees
//! the same "random" states, and a high-order central difference. Dev-dependency only.

/// A small deterministic generator (SplitMix64), so that tests need no further crate and every
/// run sees the same points.
#[derive(Clone, Debug)]
pub struct Rng(u64);

impl Rng {
    /// A generator with the given seed.
    pub fn new(seed: u64) -> Self {
        Self(seed)
    }

    /// The next 64 random bits.
    pub fn next_u64(&mut self) -> u64 {
        self.0 = self.0.wrapping_add(0x9E37_79B9_7F4A_7C15);
        let mut z = self.0;
        z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
        z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
        z ^ (z >> 31)
    }

    /// Uniform in `[0, 1)`.
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `[lo, hi)`.
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next_f64()
    }
}

/// `f'(x)` by the 5-point central difference with step `h`, improved by one Richardson
/// extrapolation (error O(h⁶)).
pub fn derivative(mut f: impl FnMut(f64) -> f64, x: f64, h: f64) -> f64 {
    let mut d4 = |h: f64| (8.0 * (f(x + h) - f(x - h)) - (f(x + 2.0 * h) - f(x - 2.0 * h))) / (12.0 * h);
    let (coarse, fine) = (d4(h), d4(0.5 * h));
    (16.0 * fine - coarse) / 15.0
}

#[cfg(test)]
mod tests {
    use super::*;

    /// SplitMix64's published first output for seed 0, and uniforms inside their interval.
    #[test]
    fn generator_is_splitmix64() {
        assert_eq!(Rng::new(0).next_u64(), 0xE220_A839_7B1D_CDAF);
        let mut rng = Rng::new(42);
        for _ in 0..1000 {
            let u = rng.uniform(-2.0, 3.0);
            assert!((-2.0..3.0).contains(&u));
        }
    }

    #[test]
    fn derivative_of_sin_is_cos() {
        let d = derivative(f64::sin, 0.3, 1e-2);
        assert!((d - 0.3f64.cos()).abs() < 1e-12, "{d}");
    }
}

pub mod module_graph;

//! Special functions that generated code calls.

/// The error function, erf(x) = 2/√π ∫₀ˣ e^(−t²) dt: `libm`'s port of the fdlibm/musl
/// implementation (rational approximations on |x| < 0.84375, < 1.25, < 1/0.35, < 6, and 1
/// beyond), documented there as accurate to within 1 ulp. `tests` check it against values to 20
/// digits and the Maclaurin series.
#[inline]
pub fn erf(x: f64) -> f64 {
    libm::erf(x)
}

#[cfg(test)]
mod tests {
    use super::erf;

    /// erf at points where its value is known to 20 significant digits (Abramowitz & Stegun
    /// table 7.1 extended; computed with mpmath at 30 digits), to within 2 ulp.
    #[test]
    // The reference values as published, to 20 digits (more than an f64 holds).
    #[allow(clippy::excessive_precision)]
    fn erf_matches_reference_values() {
        let reference = [
            (0.1, 0.112_462_916_018_284_892_2),
            (0.5, 0.520_499_877_813_046_537_7),
            (1.0, 0.842_700_792_949_714_869_3),
            (1.5, 0.966_105_146_475_310_713_9),
            (2.0, 0.995_322_265_018_952_734_2),
            (3.0, 0.999_977_909_503_001_414_6),
            (4.0, 0.999_999_984_582_742_099_7),
        ];
        for (x, want) in reference {
            for (x, want) in [(x, want), (-x, -want)] {
                let got = erf(x);
                assert!((got - want).abs() <= 2.0 * f64::EPSILON * want.abs(), "erf({x}) = {got:e}, want {want:e}");
            }
        }
        assert_eq!(erf(0.0), 0.0);
        assert_eq!(erf(7.0), 1.0);
        assert_eq!(erf(f64::NEG_INFINITY), -1.0);
        assert!(erf(f64::NAN).is_nan());
    }

    /// Near 0, erf is its Maclaurin series 2/√π Σ (−1)ⁿ x^(2n+1) / (n! (2n+1)).
    #[test]
    fn erf_matches_its_series_near_zero() {
        for i in 1..=40 {
            let x = f64::from(i) * 0.01;
            let (mut term, mut sum, mut n) = (x, 0.0, 0.0f64);
            while term.abs() > 1e-30 {
                sum += term / (2.0 * n + 1.0);
                n += 1.0;
                term *= -x * x / n;
            }
            let want = 2.0 / std::f64::consts::PI.sqrt() * sum;
            assert!((erf(x) - want).abs() <= 2.0 * f64::EPSILON * want, "erf({x}): {} vs {want}", erf(x));
        }
    }
}

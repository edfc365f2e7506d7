//! `sin_cos` and `exp` written once over [`Real`], what the SIMD lane types
//! ([`crate::lanes`]) use: every lane of every vector width computes the same bits as the `f64`
//! instance of these functions, in vector instructions. They are the generated code's most
//! frequent transcendental calls (water's right-hand side has one `sin_cos` and two `exp`).
//!
//! Called lane by lane, the platform's libm cost about 14 % of a batched water ensemble's
//! instructions, and a third of the eight-lane ensemble's gain on AVX-512 (docs/src/history/benchmarks.md, "Many
//! trajectories per core"). The functions need only `+ − × ÷`, a sign flip and a
//! power of two built from its exponent bits, with no fused multiply-add, so the bits do not
//! depend on the build's target features either.
//!
//! The one-trajectory `f64` path (`Real for f64`) keeps calling libm: on one number glibc's
//! table-driven `sincos` and `exp` are faster than these polynomials (13 against 20 ns, 9
//! against 26 ns, same section). So a lane's trajectory is the `f64` one to round-off.
//!
//! # Method
//! - `sin_cos`: `k = round(x · 2/π)` (by adding and subtracting 1.5·2⁵², exact below 2⁵¹),
//!   `r = |x| − k·π/2` with π/2 split into three parts (Cody & Waite; the first two have 25 and
//!   24 significant bits, so `k` times them is exact for `k < 2²⁸`, and `|x| ≤ 10⁵` means
//!   `k < 2¹⁶`), then the minimax polynomials of
//!   Cephes (S. L. Moshier, *Methods and Programs for Mathematical Functions*, 1989) on
//!   `[−π/4, π/4]`: `sin r = r + r³·P(r²)`, `cos r = 1 − r²/2 + r⁴·Q(r²)`, and the quadrant
//!   `k mod 4` swaps them and sets their signs; the sine takes the sign of `x`.
//! - `exp`: `k = round(x / ln 2)`, `r = x − k·ln 2` with ln 2 in two parts (fdlibm's), `eʳ` by
//!   its Taylor polynomial of degree 13 (truncation below 4·10⁻¹⁸ relative for
//!   `|r| ≤ ln 2 / 2`), times `2ᵏ` made from its exponent bits.
//!
//! # Accuracy and range
//! Against glibc's libm (correctly rounded in nearly all cases), measured by
//! `tests::accuracy_against_libm` on 2·10⁵ arguments per range: at most [`MAX_ULPS`] units in
//! the last place inside the ranges below (for results below ½ in magnitude, in units of 2⁻⁵³
//! absolute: near a zero of sin or cos the reduction's absolute error is what counts). Outside
//! them, and for NaN and ±∞, the lane falls back to libm, so no argument is computed worse than
//! libm would:
//! - `sin_cos`: `|x| ≤` [`SIN_COS_RANGE`] (the three-part reduction loses accuracy far beyond);
//! - `exp`: `|x| ≤` [`EXP_RANGE`] (beyond it the result overflows, or is subnormal or zero).
//!
//! The fallback is decided per lane by the same test in every instance, so a lane equals this
//! module's `f64` instance bit for bit for every argument.

use crate::lanes::Real;

/// `|x|` up to which `sin_cos` uses the polynomial.
pub const SIN_COS_RANGE: f64 = 1.0e5;
/// `|x|` up to which `exp` uses the polynomial.
pub const EXP_RANGE: f64 = 700.0;
/// The largest error of the polynomials against libm inside their ranges (see the module docs),
/// what `tests::accuracy_against_libm` asserts.
pub const MAX_ULPS: u64 = 2;

/// Rounds to the nearest integer (ties to even) for `|x| < 2⁵¹`, by IEEE addition alone.
#[inline(always)]
fn round<T: Real>(x: T) -> T {
    let magic = T::splat(6_755_399_441_055_744.0); // 1.5 · 2⁵²
    (x + magic) - magic
}

/// Lanes where `|x| ≤ range` fails (outside, or NaN): the lanes libm evaluates.
#[inline(always)]
fn outside<T: Real>(x: T, range: f64) -> u32 {
    x.abs().gt_mask(T::splat(range)) | (T::ALL & !x.not_nan_mask())
}

/// `(sin x, cos x)`, lane-wise (see the module docs).
// The constants keep the published digits (Cephes), so that they can be compared with the source.
#[allow(clippy::excessive_precision)]
#[inline(always)]
pub fn sin_cos<T: Real>(x: T) -> (T, T) {
    // Cephes' three-part π/2 (its DP1..DP3 for π/4, doubled) and polynomials.
    const PI_2_HI: f64 = 7.853_981_554_508_209_228_515_625E-1 * 2.0;
    const PI_2_MID: f64 = 7.946_627_356_147_928_367_14E-9 * 2.0;
    const PI_2_LO: f64 = 3.061_616_997_868_382_943_07E-17 * 2.0;
    const S: [f64; 6] = [
        1.589_623_015_765_465_680_60E-10,
        -2.505_074_776_285_780_728_66E-8,
        2.755_731_362_138_572_452_13E-6,
        -1.984_126_982_958_953_859_96E-4,
        8.333_333_333_322_118_588_78E-3,
        -1.666_666_666_666_663_072_95E-1,
    ];
    const C: [f64; 6] = [
        -1.135_853_652_138_768_173_00E-11,
        2.087_570_084_197_473_167_78E-9,
        -2.755_731_417_929_673_881_12E-7,
        2.480_158_728_885_170_453_48E-5,
        -1.388_888_888_887_305_641_16E-3,
        4.166_666_666_666_659_292_18E-2,
    ];
    let xa = x.abs();
    let k = round(xa * T::splat(core::f64::consts::FRAC_2_PI));
    let r = ((xa - k * T::splat(PI_2_HI)) - k * T::splat(PI_2_MID)) - k * T::splat(PI_2_LO);
    let r2 = r * r;
    let horner = |c: &[f64; 6]| c[1..].iter().fold(T::splat(c[0]), |acc, &ci| acc * r2 + T::splat(ci));
    let sin_r = r + r * r2 * horner(&S);
    let cos_r = (T::splat(1.0) - T::splat(0.5) * r2) + r2 * r2 * horner(&C);
    // The quadrant k mod 4 = 2·high + low: `low` swaps sin and cos, the signs follow.
    let k4 = round(k * T::splat(0.25) - T::splat(0.375)); // ⌊k/4⌋, exact for integral k
    let quadrant = k - T::splat(4.0) * k4;
    let half = round(quadrant * T::splat(0.5) - T::splat(0.25)); // ⌊quadrant/2⌋
    let low = quadrant - T::splat(2.0) * half;
    let one = T::splat(1.0);
    // Exact selections: `low` is 0 or 1 and both results are finite.
    let (s, c) = (low * cos_r + (one - low) * sin_r, low * sin_r + (one - low) * cos_r);
    // sin is negative in quadrants 2, 3; cos in 1, 2.
    let sin_sign = one - T::splat(2.0) * half;
    let cos_sign = one - T::splat(2.0) * (half + low - T::splat(2.0) * half * low);
    let (mut s, mut c) = ((s * sin_sign).flip_sign_where_negative(x), c * cos_sign);
    let out = outside(x, SIN_COS_RANGE);
    if out != 0 {
        for lane in 0..T::LANES {
            if out >> lane & 1 == 1 {
                let (ls, lc) = x.lane(lane).sin_cos();
                s.set_lane(lane, ls);
                c.set_lane(lane, lc);
            }
        }
    }
    (s, c)
}

/// `eˣ`, lane-wise (see the module docs).
// The constants keep the published digits (fdlibm), so that they can be compared with the source.
#[allow(clippy::excessive_precision)]
#[inline(always)]
pub fn exp<T: Real>(x: T) -> T {
    // fdlibm's two-part ln 2 (e_exp.c): the high part has 32 bits, so k · LN2_HI is exact.
    const LN2_HI: f64 = 6.931_471_803_691_238_164_90E-1;
    const LN2_LO: f64 = 1.908_214_929_270_587_700_02E-10;
    let k = round(x * T::splat(core::f64::consts::LOG2_E));
    let r = (x - k * T::splat(LN2_HI)) - k * T::splat(LN2_LO);
    // eʳ − 1 − r = r²·(1/2! + r·(1/3! + … + r/13!)), Horner from the highest term.
    const INVERSE_FACTORIALS: [f64; 12] = [
        1.0 / 6_227_020_800.0,
        1.0 / 479_001_600.0,
        1.0 / 39_916_800.0,
        1.0 / 3_628_800.0,
        1.0 / 362_880.0,
        1.0 / 40_320.0,
        1.0 / 5_040.0,
        1.0 / 720.0,
        1.0 / 120.0,
        1.0 / 24.0,
        1.0 / 6.0,
        1.0 / 2.0,
    ];
    let p = INVERSE_FACTORIALS[1..].iter().fold(T::splat(INVERSE_FACTORIALS[0]), |acc, &c| acc * r + T::splat(c));
    let e = (T::splat(1.0) + (r + r * r * p)) * k.pow2();
    let out = outside(x, EXP_RANGE);
    if out == 0 {
        return e;
    }
    let mut e = e;
    for lane in 0..T::LANES {
        if out >> lane & 1 == 1 {
            e.set_lane(lane, x.lane(lane).exp());
        }
    }
    e
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::lanes::{F64x2, F64x4, F64x8, Real};

    /// Distance in units in the last place between two finite doubles of the same sign.
    fn ulps(a: f64, b: f64) -> u64 {
        if a == b {
            return 0;
        }
        if a.signum() != b.signum() {
            // Across zero: both tiny; count through zero.
            return a.abs().to_bits() + b.abs().to_bits();
        }
        a.to_bits().abs_diff(b.to_bits())
    }

    /// A deterministic uniform sample in `[lo, hi)` (SplitMix64), without a test dependency.
    fn sample(count: usize, lo: f64, hi: f64, seed: u64) -> Vec<f64> {
        let mut s = seed;
        (0..count)
            .map(|_| {
                s = s.wrapping_add(0x9E37_79B9_7F4A_7C15);
                let mut z = s;
                z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
                z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
                z ^= z >> 31;
                lo + (hi - lo) * ((z >> 11) as f64 / (1u64 << 53) as f64)
            })
            .collect()
    }

    /// Inside the ranges the polynomials are within MAX_ULPS of libm; the worst case per range is
    /// printed (`cargo test -p rovib-runtime accuracy -- --nocapture`). Near the zeros of sin and
    /// cos an absolute error of one ulp of the argument's reduction is what any reduction gives,
    /// so there the error is measured against 1 ulp of 1.0 scaled by the result.
    #[test]
    fn accuracy_against_libm() {
        let ranges = [(-0.1, 0.1), (-4.0, 4.0), (-100.0, 100.0), (-1e4, 1e4), (-SIN_COS_RANGE, SIN_COS_RANGE)];
        for (r, &(lo, hi)) in ranges.iter().enumerate() {
            let (mut worst, mut at) = (0, 0.0);
            for x in sample(200_000, lo, hi, 11 + r as u64) {
                let (s, c) = sin_cos(x);
                let (ls, lc) = x.sin_cos();
                for (got, want) in [(s, ls), (c, lc)] {
                    // Relative to the result where it is not tiny, else absolute at ulp(2^-1).
                    let e =
                        if want.abs() >= 0.5 { ulps(got, want) } else { ((got - want).abs() / 2f64.powi(-53)) as u64 };
                    if e > worst {
                        (worst, at) = (e, x);
                    }
                }
            }
            println!("sin_cos on [{lo}, {hi}]: worst {worst} ulp at {at}");
            assert!(worst <= MAX_ULPS, "sin_cos on [{lo}, {hi}]: {worst} ulp at x = {at}");
        }
        for (r, &(lo, hi)) in [(-1.0, 1.0), (-40.0, 40.0), (-EXP_RANGE, EXP_RANGE)].iter().enumerate() {
            let (mut worst, mut at) = (0, 0.0);
            for x in sample(200_000, lo, hi, 31 + r as u64) {
                let e = ulps(exp(x), x.exp());
                if e > worst {
                    (worst, at) = (e, x);
                }
            }
            println!("exp on [{lo}, {hi}]: worst {worst} ulp at {at}");
            assert!(worst <= MAX_ULPS, "exp on [{lo}, {hi}]: {worst} ulp at x = {at}");
        }
    }

    /// Outside the ranges, and for NaN and ±∞, the result is libm's, bit for bit; the special
    /// values of the ranges' edges are right.
    #[test]
    fn outside_the_ranges_libm_decides() {
        let same = |a: f64, b: f64| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
        for x in [1.5e5, -3.0e7, 1e300, f64::MAX, f64::INFINITY, f64::NEG_INFINITY, f64::NAN] {
            let ((s, c), (ls, lc)) = (sin_cos(x), x.sin_cos());
            assert!(same(s, ls) && same(c, lc), "sin_cos({x})");
        }
        for x in [700.5, 709.9, 710.0, -700.5, -745.2, -746.0, f64::INFINITY, f64::NEG_INFINITY, f64::NAN] {
            assert!(same(exp(x), x.exp()), "exp({x})");
        }
        assert_eq!(exp(0.0), 1.0);
        assert_eq!(sin_cos(0.0), (0.0, 1.0));
        assert!(sin_cos(-0.0).0.is_sign_negative(), "sin(−0) = −0");
    }

    /// Every lane of every vector type (through [`Real`], as the generated code calls them) equals
    /// this module's functions at `f64` on that lane, bit for bit, for arguments inside, at the
    /// edge of and outside the ranges.
    #[test]
    fn lanes_equal_f64_bit_for_bit() {
        let mut xs = sample(4096, -50.0, 50.0, 7);
        xs.extend([0.0, -0.0, SIN_COS_RANGE, -SIN_COS_RANGE, 1.0000001e5, EXP_RANGE, -EXP_RANGE, 700.0001]);
        xs.extend([f64::NAN, f64::INFINITY, f64::NEG_INFINITY, 1e-310, -745.5, 709.7, 3e6, -1e9]);
        let check = |v: &dyn Fn(usize) -> (f64, f64, f64), i: usize| {
            let x = xs[i];
            let (s, c, e) = v(i);
            let ((fs, fc), fe) = (sin_cos(x), exp(x));
            let same = |a: f64, b: f64| a.to_bits() == b.to_bits() || (a.is_nan() && b.is_nan());
            assert!(same(s, fs) && same(c, fc) && same(e, fe), "x = {x}: ({s}, {c}, {e}) vs ({fs}, {fc}, {fe})");
        };
        for chunk in 0..xs.len() / 8 {
            let base = chunk * 8;
            let arr8: [f64; 8] = core::array::from_fn(|i| xs[base + i]);
            let v8 = F64x8::from_array(arr8);
            let (s8, c8) = Real::sin_cos(v8);
            let e8 = Real::exp(v8);
            for l in 0..8 {
                check(&|_| (s8.lane(l), c8.lane(l), e8.lane(l)), base + l);
            }
            for half in 0..2 {
                let v4 = F64x4::from_array(core::array::from_fn(|i| arr8[4 * half + i]));
                let (s4, c4) = Real::sin_cos(v4);
                let e4 = Real::exp(v4);
                for l in 0..4 {
                    check(&|_| (s4.lane(l), c4.lane(l), e4.lane(l)), base + 4 * half + l);
                }
            }
            let v2 = F64x2::from_array([arr8[0], arr8[1]]);
            let ((s2, c2), e2) = (Real::sin_cos(v2), Real::exp(v2));
            for l in 0..2 {
                check(&|_| (s2.lane(l), c2.lane(l), e2.lane(l)), base + l);
            }
        }
    }
}

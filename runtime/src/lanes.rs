//! Lane types: one number type for the code that evaluates one trajectory (`f64`) and for the
//! code that evaluates several independent trajectories at once, one per SIMD lane
//! ([`F64x2`], [`F64x4`], [`F64x8`]).
//!
//! The generated molecule code has a lane-generic form (`Kinematics::kinetic_and_gradient_lanes`
//! and `Molecule::potential_gradient_lanes`) written over [`Real`], and the production right-hand
//! side ([`crate::hamiltonian::lanes`]) is written once over [`Real`]: instantiated with `f64` it
//! is the one-trajectory production path, with a vector type it evaluates `LANES` trajectories.
//!
//! # What a lane computes
//!
//! `+ − × ÷`, negation and `sqrt` are IEEE operations lane by lane (no fused multiply-add is
//! ever formed: Rust does not contract), so on them every lane computes exactly what the `f64`
//! instance computes. `sin_cos` and `exp`, the generated code's frequent transcendental calls,
//! are the vector polynomials of [`crate::transcendental`] (within 2 ulp of libm, which the `f64`
//! instance calls); the rarer ones (`acos`, `atan2`, `powf`, ...) call libm lane by lane. So:
//! - lanes of every width ([`F64x2`], [`F64x4`], [`F64x8`]) compute the same bits, on every
//!   build (baseline or `-C target-cpu=native`: nothing here depends on FMA);
//! - a lane's trajectory is the one-trajectory (`f64`) trajectory to round-off.
//!
//! `tests/numerics/lanes.rs` checks both. libm lane by lane would make the lanes equal `f64` bit for
//! bit, but it costs a third of the lanes' gain on AVX-512 (docs/src/history/benchmarks.md, "Many trajectories
//! per core").
//!
//! # Target features
//!
//! The vector types are `wide`'s `f64x2`/`f64x4`/`f64x8`, which use whatever the build's target
//! features allow: for the default target (baseline x86-64, SSE2) an `F64x4` is two 128-bit
//! registers; a build with AVX2 or AVX-512 (`RUSTFLAGS="-C target-cpu=native"`) uses 256- or
//! 512-bit ones. There is no run-time detection (calling code compiled for a feature the build
//! lacks needs `unsafe`, which the workspace forbids outside the `ffi` crate; a dispatch tried
//! through that crate made the command slower at every level, docs/src/history/benchmarks.md,
//! "Run-time dispatch of the SIMD lanes"); the binary checks at start that the CPU has the
//! features it was built for (`rovib::cpu`).

use core::fmt::Debug;
use core::ops::{Add, Div, Mul, Neg, Sub};

use nalgebra::SMatrix;

use crate::kinetic_matrices::KineticMatrices;

/// A real number, or a vector of `LANES` independent real numbers with lane-wise operations.
pub trait Real:
    Copy
    + Debug
    + Send
    + Sync
    + 'static
    + Add<Output = Self>
    + Sub<Output = Self>
    + Mul<Output = Self>
    + Div<Output = Self>
    + Neg<Output = Self>
{
    /// The number of lanes.
    const LANES: usize;
    /// Every lane `x`.
    fn splat(x: f64) -> Self;
    /// Lane `i` (`i < LANES`).
    fn lane(self, i: usize) -> f64;
    /// Sets lane `i` to `x`.
    fn set_lane(&mut self, i: usize, x: f64);
    /// Lane-wise `(sin, cos)`.
    fn sin_cos(self) -> (Self, Self);
    /// Lane-wise sine.
    fn sin(self) -> Self;
    /// Lane-wise cosine.
    fn cos(self) -> Self;
    /// Lane-wise tangent.
    fn tan(self) -> Self;
    /// Lane-wise arcsine.
    fn asin(self) -> Self;
    /// Lane-wise arccosine.
    fn acos(self) -> Self;
    /// Lane-wise arctangent.
    fn atan(self) -> Self;
    /// Lane-wise exponential.
    fn exp(self) -> Self;
    /// Lane-wise natural logarithm.
    fn ln(self) -> Self;
    /// Lane-wise square root.
    fn sqrt(self) -> Self;
    /// Lane-wise hyperbolic sine.
    fn sinh(self) -> Self;
    /// Lane-wise hyperbolic cosine.
    fn cosh(self) -> Self;
    /// Lane-wise hyperbolic tangent.
    fn tanh(self) -> Self;
    /// Lane-wise `self^e`.
    fn powf(self, e: Self) -> Self;
    /// Lane-wise `atan2(self, x)`.
    fn atan2(self, x: Self) -> Self;
    /// Lane-wise absolute value.
    fn abs(self) -> Self;
    /// Lane-wise `f64::max` (NaN loses, as in `f64::max`).
    fn max(self, other: Self) -> Self;
    /// Bit `i` set where lane `i` of `self` is greater than that of `other` (false for NaN).
    fn gt_mask(self, other: Self) -> u32;
    /// Lane-wise error function ([`crate::special::erf`], lane by lane).
    fn erf(self) -> Self;
    /// Lane-wise `if x < y { a } else { b }` (a NaN comparison gives `b`), branch-free.
    fn select_lt(x: Self, y: Self, a: Self, b: Self) -> Self;
    /// Lane-wise `if x <= y { a } else { b }` (a NaN comparison gives `b`), branch-free.
    fn select_le(x: Self, y: Self, a: Self, b: Self) -> Self;
    /// Bit `i` set where lane `i` is not NaN.
    fn not_nan_mask(self) -> u32;
    /// `self` with its sign flipped in the lanes where `x` has its sign bit set (`−0` included).
    fn flip_sign_where_negative(self, x: Self) -> Self;
    /// `2ᵏ` for each lane's `k = self`, which must be an integer in `[−1022, 1023]` (any other
    /// lane gives an unspecified number, never a panic): built from the exponent bits.
    fn pow2(self) -> Self;
    /// All lanes' bits.
    const ALL: u32 = if Self::LANES >= 32 { u32::MAX } else { (1u32 << Self::LANES) - 1 };
}

/// The sign bit of an `f64`.
const SIGN_BIT: u64 = 1 << 63;
/// `2⁵² + 1023`: added to an integer `k`, it leaves `k + 1023` (the biased exponent of `2ᵏ`) in
/// the low bits of the mantissa, from where a shift by 52 moves it into the exponent field.
const POW2_BIAS: f64 = 4_503_599_627_371_519.0;

impl Real for f64 {
    const LANES: usize = 1;
    #[inline(always)]
    fn splat(x: f64) -> Self {
        x
    }
    #[inline(always)]
    fn lane(self, _: usize) -> f64 {
        self
    }
    #[inline(always)]
    fn set_lane(&mut self, _: usize, x: f64) {
        *self = x;
    }
    #[inline(always)]
    fn sin_cos(self) -> (Self, Self) {
        f64::sin_cos(self)
    }
    #[inline(always)]
    fn sin(self) -> Self {
        f64::sin(self)
    }
    #[inline(always)]
    fn cos(self) -> Self {
        f64::cos(self)
    }
    #[inline(always)]
    fn tan(self) -> Self {
        f64::tan(self)
    }
    #[inline(always)]
    fn asin(self) -> Self {
        f64::asin(self)
    }
    #[inline(always)]
    fn acos(self) -> Self {
        f64::acos(self)
    }
    #[inline(always)]
    fn atan(self) -> Self {
        f64::atan(self)
    }
    #[inline(always)]
    fn exp(self) -> Self {
        f64::exp(self)
    }
    #[inline(always)]
    fn ln(self) -> Self {
        f64::ln(self)
    }
    #[inline(always)]
    fn sqrt(self) -> Self {
        f64::sqrt(self)
    }
    #[inline(always)]
    fn sinh(self) -> Self {
        f64::sinh(self)
    }
    #[inline(always)]
    fn cosh(self) -> Self {
        f64::cosh(self)
    }
    #[inline(always)]
    fn tanh(self) -> Self {
        f64::tanh(self)
    }
    #[inline(always)]
    fn powf(self, e: Self) -> Self {
        f64::powf(self, e)
    }
    #[inline(always)]
    fn atan2(self, x: Self) -> Self {
        f64::atan2(self, x)
    }
    #[inline(always)]
    fn abs(self) -> Self {
        f64::abs(self)
    }
    #[inline(always)]
    fn max(self, other: Self) -> Self {
        f64::max(self, other)
    }
    #[inline(always)]
    fn gt_mask(self, other: Self) -> u32 {
        u32::from(self > other)
    }
    #[inline(always)]
    fn erf(self) -> Self {
        crate::special::erf(self)
    }
    #[inline(always)]
    fn select_lt(x: Self, y: Self, a: Self, b: Self) -> Self {
        if x < y { a } else { b }
    }
    #[inline(always)]
    fn select_le(x: Self, y: Self, a: Self, b: Self) -> Self {
        if x <= y { a } else { b }
    }
    #[inline(always)]
    fn not_nan_mask(self) -> u32 {
        u32::from(!self.is_nan())
    }
    #[inline(always)]
    fn flip_sign_where_negative(self, x: Self) -> Self {
        f64::from_bits(self.to_bits() ^ (x.to_bits() & SIGN_BIT))
    }
    #[inline(always)]
    fn pow2(self) -> Self {
        f64::from_bits((self + POW2_BIAS).to_bits() << 52)
    }
}

/// Defines a lane vector type around a `wide` vector: arithmetic by `wide` (IEEE, lane-wise),
/// transcendental functions by the `f64` method on each lane.
macro_rules! lane_type {
    ($name:ident, $wide:ty, $int:ty, $lanes:expr, $doc:literal) => {
        #[doc = $doc]
        #[derive(Copy, Clone, Debug, Default, PartialEq)]
        #[repr(transparent)]
        pub struct $name(pub $wide);

        impl $name {
            /// The lanes as an array.
            #[inline(always)]
            pub fn to_array(self) -> [f64; $lanes] {
                self.0.to_array()
            }

            /// From an array of lanes.
            #[inline(always)]
            pub fn from_array(a: [f64; $lanes]) -> Self {
                Self(<$wide>::new(a))
            }

            #[inline(always)]
            fn map(self, f: impl Fn(f64) -> f64) -> Self {
                Self::from_array(self.to_array().map(f))
            }

            #[inline(always)]
            fn zip(self, other: Self, f: impl Fn(f64, f64) -> f64) -> Self {
                let (a, b) = (self.to_array(), other.to_array());
                Self::from_array(core::array::from_fn(|i| f(a[i], b[i])))
            }
        }

        impl Add for $name {
            type Output = Self;
            #[inline(always)]
            fn add(self, o: Self) -> Self {
                Self(self.0 + o.0)
            }
        }

        impl Sub for $name {
            type Output = Self;
            #[inline(always)]
            fn sub(self, o: Self) -> Self {
                Self(self.0 - o.0)
            }
        }

        impl Mul for $name {
            type Output = Self;
            #[inline(always)]
            fn mul(self, o: Self) -> Self {
                Self(self.0 * o.0)
            }
        }

        impl Div for $name {
            type Output = Self;
            #[inline(always)]
            fn div(self, o: Self) -> Self {
                Self(self.0 / o.0)
            }
        }

        impl Neg for $name {
            type Output = Self;
            /// Flips the sign bit (so `−0 = −(+0)`, as for `f64`).
            #[inline(always)]
            fn neg(self) -> Self {
                Self(-self.0)
            }
        }

        impl Real for $name {
            const LANES: usize = $lanes;
            #[inline(always)]
            fn splat(x: f64) -> Self {
                Self(<$wide>::splat(x))
            }
            #[inline(always)]
            fn lane(self, i: usize) -> f64 {
                self.to_array()[i]
            }
            #[inline(always)]
            fn set_lane(&mut self, i: usize, x: f64) {
                let mut a = self.to_array();
                a[i] = x;
                *self = Self::from_array(a);
            }
            /// [`crate::transcendental::sin_cos`]: the same bits as the `f64` instance per lane.
            #[inline(always)]
            fn sin_cos(self) -> (Self, Self) {
                crate::transcendental::sin_cos(self)
            }
            #[inline(always)]
            fn sin(self) -> Self {
                Real::sin_cos(self).0
            }
            #[inline(always)]
            fn cos(self) -> Self {
                Real::sin_cos(self).1
            }
            #[inline(always)]
            fn tan(self) -> Self {
                self.map(f64::tan)
            }
            #[inline(always)]
            fn asin(self) -> Self {
                self.map(f64::asin)
            }
            #[inline(always)]
            fn acos(self) -> Self {
                self.map(f64::acos)
            }
            #[inline(always)]
            fn atan(self) -> Self {
                self.map(f64::atan)
            }
            /// [`crate::transcendental::exp`]: the same bits as the `f64` instance per lane.
            #[inline(always)]
            fn exp(self) -> Self {
                crate::transcendental::exp(self)
            }
            #[inline(always)]
            fn ln(self) -> Self {
                self.map(f64::ln)
            }
            #[inline(always)]
            fn sqrt(self) -> Self {
                // IEEE square root lane by lane, as f64::sqrt.
                Self(self.0.sqrt())
            }
            #[inline(always)]
            fn sinh(self) -> Self {
                self.map(f64::sinh)
            }
            #[inline(always)]
            fn cosh(self) -> Self {
                self.map(f64::cosh)
            }
            #[inline(always)]
            fn tanh(self) -> Self {
                self.map(f64::tanh)
            }
            #[inline(always)]
            fn powf(self, e: Self) -> Self {
                self.zip(e, f64::powf)
            }
            #[inline(always)]
            fn atan2(self, x: Self) -> Self {
                self.zip(x, f64::atan2)
            }
            #[inline(always)]
            fn abs(self) -> Self {
                Self(self.0.abs())
            }
            #[inline(always)]
            fn max(self, other: Self) -> Self {
                self.zip(other, f64::max)
            }
            #[inline(always)]
            fn gt_mask(self, other: Self) -> u32 {
                self.0.simd_gt(other.0).to_bitmask()
            }
            #[inline(always)]
            fn erf(self) -> Self {
                self.map(crate::special::erf)
            }
            #[inline(always)]
            fn select_lt(x: Self, y: Self, a: Self, b: Self) -> Self {
                Self(x.0.simd_lt(y.0).select(a.0, b.0))
            }
            #[inline(always)]
            fn select_le(x: Self, y: Self, a: Self, b: Self) -> Self {
                Self(x.0.simd_le(y.0).select(a.0, b.0))
            }
            #[inline(always)]
            fn not_nan_mask(self) -> u32 {
                self.0.simd_eq(self.0).to_bitmask()
            }
            #[inline(always)]
            fn flip_sign_where_negative(self, x: Self) -> Self {
                Self(self.0 ^ (x.0 & <$wide>::splat(-0.0)))
            }
            #[inline(always)]
            fn pow2(self) -> Self {
                let biased = self.0 + <$wide>::splat(POW2_BIAS);
                Self(wide::bytemuck::cast(wide::bytemuck::cast::<$wide, $int>(biased) << 52))
            }
        }
    };
}

lane_type!(F64x2, wide::f64x2, wide::i64x2, 2, "Two `f64` lanes (one SSE2 register on baseline x86-64).");
lane_type!(
    F64x4,
    wide::f64x4,
    wide::i64x4,
    4,
    "Four `f64` lanes (two SSE2 registers on baseline x86-64, one AVX register with AVX)."
);
lane_type!(
    F64x8,
    wide::f64x8,
    wide::i64x8,
    8,
    "Eight `f64` lanes (four SSE2 registers on baseline x86-64, two with AVX, one with AVX-512)."
);

/// The kinetic matrices `a` (N × N), `A` (3 × N) and `I` (3 × 3) of `T::LANES` states, as
/// arrays indexed `[row][column]`: what the lane-generic generated code writes.
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct KineticLanes<T, const N: usize> {
    /// The vibrational kinetic matrix `a`.
    pub a: [[T; N]; N],
    /// The Coriolis matrix `A`.
    pub coriolis: [[T; N]; 3],
    /// The inertia tensor `I`.
    pub inertia: [[T; 3]; 3],
}

impl<T: Real, const N: usize> KineticLanes<T, N> {
    /// All zero.
    pub fn zeros() -> Self {
        let z = T::splat(0.0);
        Self { a: [[z; N]; N], coriolis: [[z; N]; 3], inertia: [[z; 3]; 3] }
    }

    /// Lane `lane` as nalgebra matrices.
    pub fn lane(&self, lane: usize) -> KineticMatrices<N> {
        KineticMatrices {
            a: SMatrix::from_fn(|i, j| self.a[i][j].lane(lane)),
            coriolis: SMatrix::from_fn(|i, j| self.coriolis[i][j].lane(lane)),
            inertia: SMatrix::from_fn(|i, j| self.inertia[i][j].lane(lane)),
        }
    }

    /// Sets lane `lane` from nalgebra matrices.
    pub fn set_lane(&mut self, lane: usize, k: &KineticMatrices<N>) {
        for i in 0..N {
            for j in 0..N {
                self.a[i][j].set_lane(lane, k.a[(i, j)]);
            }
        }
        for r in 0..3 {
            for j in 0..N {
                self.coriolis[r][j].set_lane(lane, k.coriolis[(r, j)]);
            }
            for c in 0..3 {
                self.inertia[r][c].set_lane(lane, k.inertia[(r, c)]);
            }
        }
    }
}

/// Whether every lane of every element is finite, as a lane mask: `x · 0` is `±0` for finite `x`
/// and NaN otherwise, so the sum is NaN exactly in the lanes with a non-finite element.
#[inline(always)]
pub fn finite_mask<T: Real>(v: &[T]) -> u32 {
    v.iter().fold(T::splat(0.0), |acc, &x| acc + x * T::splat(0.0)).not_nan_mask()
}

pub mod transcendental;

#[cfg(test)]
mod tests {
    use super::*;

    /// Every operation of a vector lane equals the `f64` operation, bit for bit, including signed
    /// zeros, infinities and NaN; masks follow IEEE comparisons.
    #[test]
    fn lanes_compute_what_f64_computes() {
        let xs = [0.3, -1.7, 0.0, -0.0, 1e300, f64::INFINITY, f64::NAN, 2.5e-310];
        for w in xs.windows(4) {
            let v = F64x4::from_array([w[0], w[1], w[2], w[3]]);
            let u = F64x4::from_array([w[3], w[0], w[1], w[2]]);
            let same = |lane: F64x4, f: &dyn Fn(f64, f64) -> f64| {
                for i in 0..4 {
                    let (got, want) = (lane.lane(i), f(v.lane(i), u.lane(i)));
                    assert!(got.to_bits() == want.to_bits() || (got.is_nan() && want.is_nan()), "{got} vs {want}");
                }
            };
            same(v + u, &|a, b| a + b);
            same(v - u, &|a, b| a - b);
            same(v * u, &|a, b| a * b);
            same(v / u, &|a, b| a / b);
            same(-v, &|a, _| -a);
            same(v.sqrt(), &|a, _| a.sqrt());
            // sin_cos and exp: the polynomials of crate::transcendental (tested there against libm).
            same(v.sin_cos().0, &|a, _| transcendental::sin_cos(a).0);
            same(v.sin_cos().1, &|a, _| transcendental::sin_cos(a).1);
            same(v.exp(), &|a, _| transcendental::exp(a));
            same(v.atan2(u), &|a, b| a.atan2(b));
            same(v.powf(u), &|a, b| a.powf(b));
            same(v.abs(), &|a, _| a.abs());
            same(v.max(u), &|a, b| a.max(b));
            // Piecewise: both branches computed, one chosen per lane (NaN compares false).
            same(v.erf(), &|a, _| crate::special::erf(a));
            same(F64x4::select_lt(v, u, v * u, v - u), &|a, b| f64::select_lt(a, b, a * b, a - b));
            same(F64x4::select_le(v, u, v * u, v - u), &|a, b| f64::select_le(a, b, a * b, a - b));
            same(F64x4::select_le(v, v, u, v), &|a, b| if a <= a { b } else { a });
            let gt = v.gt_mask(u);
            let nn = v.not_nan_mask();
            for i in 0..4 {
                assert_eq!(gt >> i & 1 == 1, v.lane(i) > u.lane(i));
                assert_eq!(nn >> i & 1 == 1, !v.lane(i).is_nan());
            }
        }
        let mut v = F64x2::splat(1.0);
        v.set_lane(1, 3.0);
        assert_eq!(v.to_array(), [1.0, 3.0]);
        assert_eq!(finite_mask(&[F64x2::from_array([1.0, f64::INFINITY]), F64x2::splat(2.0)]), 0b01);
        assert_eq!(finite_mask(&[1.0, 2.0]), 1);
        assert_eq!(finite_mask(&[1.0, f64::NAN]), 0);
        assert_eq!(<F64x4 as Real>::ALL, 0b1111);
    }
}

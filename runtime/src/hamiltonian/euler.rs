//! Euler angles (z-x-z): the rotation matrix, the matrix W of the seed's eq. (2) and its
//! derivatives, eq. (7).
//!
//! # Convention
//!
//! `Ω_e = (φ, θ, ψ)` and the body-to-lab rotation is
//!
//! ```text
//! R(φ, θ, ψ) = Rz(φ) · Rx(θ) · Rz(ψ),   r_lab = R · r_body,
//! Rz(a) = [[cos a, −sin a, 0], [sin a, cos a, 0], [0, 0, 1]],
//! Rx(a) = [[1, 0, 0], [0, cos a, −sin a], [0, sin a, cos a]].
//! ```
//!
//! The body-frame angular velocity (the axial vector of `Rᵀ Ṙ`) is `ω = M Ω̇` with
//!
//! ```text
//! M = [[sin θ sin ψ,  cos ψ, 0],
//!      [sin θ cos ψ, −sin ψ, 0],
//!      [cos θ,        0,     1]],
//! ```
//!
//! and since `p_e = ∂L/∂Ω̇ = Mᵀ ∂L/∂ω = Mᵀ J`, the body-frame angular momentum is
//! `J = M⁻ᵀ p_e = W p_e` with `W = M⁻ᵀ` (eq. 2). `det M = −sin θ`, so W is undefined where
//! `sin θ = 0` (gimbal lock); the converse map `p_e = Mᵀ J` is defined everywhere.

use nalgebra::{Matrix3, Vector3};

use super::HamiltonianError;
use super::finite::all_finite;

/// Below this `|sin θ|` the functions that need W fail with
/// [`HamiltonianError::EulerSingular`].
///
/// `J = W p_e` divides `p_φ − cos θ p_ψ` (a difference of two numbers of the size of `|J|`) by
/// `sin θ`, so its relative rounding error grows like `ε / |sin θ|`; at this bound it is still
/// about 1e-8, below which the results would be dominated by cancellation.
pub const MIN_SIN_THETA: f64 = 1e-8;

/// The body-to-lab rotation matrix `R = Rz(φ) Rx(θ) Rz(ψ)` (defined for all angles).
pub fn rotation_matrix(euler: &Vector3<f64>) -> Matrix3<f64> {
    let rz = |a: f64| {
        let (s, c) = a.sin_cos();
        Matrix3::new(c, -s, 0.0, s, c, 0.0, 0.0, 0.0, 1.0)
    };
    let (st, ct) = euler[1].sin_cos();
    let rx = Matrix3::new(1.0, 0.0, 0.0, 0.0, ct, -st, 0.0, st, ct);
    rz(euler[0]) * rx * rz(euler[2])
}

/// The matrix `M` of `ω = M Ω̇` (body-frame angular velocity from Euler-angle rates); `W = M⁻ᵀ`.
pub fn angular_velocity_matrix(euler: &Vector3<f64>) -> Matrix3<f64> {
    let (st, ct) = euler[1].sin_cos();
    let (sp, cp) = euler[2].sin_cos();
    Matrix3::new(st * sp, cp, 0.0, st * cp, -sp, 0.0, ct, 0.0, 1.0)
}

/// `W` of eq. (2) and its derivatives of eq. (7) at one orientation (`∂W/∂φ = 0`).
#[derive(Copy, Clone, Debug, PartialEq)]
pub struct WMatrices {
    /// `W`, with `J = W p_e`.
    pub w: Matrix3<f64>,
    /// `∂W/∂θ`.
    pub dw_dtheta: Matrix3<f64>,
    /// `∂W/∂ψ`.
    pub dw_dpsi: Matrix3<f64>,
}

impl WMatrices {
    /// Evaluates W, ∂W/∂θ and ∂W/∂ψ; fails if `|sin θ| <` [`MIN_SIN_THETA`] or an angle is not
    /// finite.
    pub fn new(euler: &Vector3<f64>) -> Result<Self, HamiltonianError> {
        let EulerTrig { st, ct, sp, cp, .. } = EulerTrig::new(euler)?;
        let cot = ct / st;
        let s2 = st * st;
        #[rustfmt::skip]
        let w = Matrix3::new(
            sp / st,  cp, -cot * sp,
            cp / st, -sp, -cot * cp,
            0.0,      0.0, 1.0,
        );
        // d(1/sin θ)/dθ = −cos θ / sin²θ and d(−cot θ)/dθ = 1 / sin²θ.
        #[rustfmt::skip]
        let dw_dtheta = Matrix3::new(
            -ct * sp / s2, 0.0, sp / s2,
            -ct * cp / s2, 0.0, cp / s2,
            0.0,           0.0, 0.0,
        );
        #[rustfmt::skip]
        let dw_dpsi = Matrix3::new(
             cp / st, -sp, -cot * cp,
            -sp / st, -cp,  cot * sp,
             0.0,      0.0, 0.0,
        );
        Ok(Self { w, dw_dtheta, dw_dpsi })
    }
}

/// `sin`/`cos` of θ and ψ: everything W, Wᵀ and ∂W need (W does not depend on φ), with
/// `1 / sin θ` computed once (one division instead of three). [`WMatrices::new`] builds the
/// matrices from it; the fast paths apply W, Wᵀ and ∂W to vectors without forming them.
#[derive(Copy, Clone, Debug)]
pub(crate) struct EulerTrig {
    st: f64,
    inv_st: f64,
    ct: f64,
    sp: f64,
    cp: f64,
}

impl EulerTrig {
    /// The one validation of an orientation for W: fails with [`HamiltonianError::NonFinite`]
    /// for non-finite angles, then with [`HamiltonianError::EulerSingular`] if
    /// `|sin θ| <` [`MIN_SIN_THETA`].
    #[inline]
    pub(crate) fn new(euler: &Vector3<f64>) -> Result<Self, HamiltonianError> {
        if !all_finite(euler.as_slice()) {
            return Err(HamiltonianError::NonFinite { quantity: "Euler angles (φ, θ, ψ)" });
        }
        let theta = euler[1];
        let (st, ct) = theta.sin_cos();
        if st.abs() < MIN_SIN_THETA {
            return Err(HamiltonianError::EulerSingular { theta });
        }
        let (sp, cp) = euler[2].sin_cos();
        Ok(Self { st, inv_st: 1.0 / st, ct, sp, cp })
    }

    /// `J = W p_e` (eq. 2).
    #[inline]
    pub(crate) fn j(&self, pe: &Vector3<f64>) -> Vector3<f64> {
        let g = (pe[0] - self.ct * pe[2]) * self.inv_st;
        Vector3::new(self.sp * g + self.cp * pe[1], self.cp * g - self.sp * pe[1], pe[2])
    }

    /// `Ω̇_e = Wᵀ ω` (eq. 6).
    #[inline]
    pub(crate) fn euler_rates(&self, omega: &Vector3<f64>) -> Vector3<f64> {
        let phi_dot = (self.sp * omega[0] + self.cp * omega[1]) * self.inv_st;
        Vector3::new(phi_dot, self.cp * omega[0] - self.sp * omega[1], omega[2] - self.ct * phi_dot)
    }

    /// `ṗ_e = −((∂W/∂Ω_e) p_e) · ω` (eqs. 5, 7) with `ṗ_φ` a literal `+0.0` (H does not depend
    /// on φ; negating a computed zero could give −0.0), given `J = W p_e`.
    #[inline]
    pub(crate) fn euler_momenta_rates(
        &self,
        pe: &Vector3<f64>,
        j: &Vector3<f64>,
        omega: &Vector3<f64>,
    ) -> Vector3<f64> {
        let dh_dtheta =
            (pe[2] - self.ct * pe[0]) * (self.inv_st * self.inv_st) * (self.sp * omega[0] + self.cp * omega[1]);
        let dh_dpsi = j[1] * omega[0] - j[0] * omega[1];
        Vector3::new(0.0, -dh_dtheta, -dh_dpsi)
    }
}

/// `W` of eq. (2) alone; fails like [`WMatrices::new`].
pub fn w_matrix(euler: &Vector3<f64>) -> Result<Matrix3<f64>, HamiltonianError> {
    WMatrices::new(euler).map(|w| w.w)
}

/// The body-frame angular momentum `J = W p_e`; fails like [`WMatrices::new`].
pub fn angular_momentum_from_euler_momenta(
    euler: &Vector3<f64>,
    pe: &Vector3<f64>,
) -> Result<Vector3<f64>, HamiltonianError> {
    Ok(w_matrix(euler)? * pe)
}

/// The Euler momenta `p_e = W⁻¹ J = Mᵀ J` of a body-frame angular momentum `J` (defined for
/// all angles; at `sin θ = 0` it is not invertible, which is why the forward map fails there).
pub fn euler_momenta_from_angular_momentum(euler: &Vector3<f64>, j: &Vector3<f64>) -> Vector3<f64> {
    angular_velocity_matrix(euler).transpose() * j
}

/// The Euler angles `(φ, θ, ψ)` of a rotation matrix `R = Rz(φ) Rx(θ) Rz(ψ)`, with `θ ∈ [0, π]`
/// and `φ, ψ ∈ (−π, π]`; the inverse of [`rotation_matrix`] wherever `sin θ ≠ 0`.
///
/// From `R₃₁ = sin θ sin ψ`, `R₃₂ = sin θ cos ψ`, `R₁₃ = sin φ sin θ`, `R₂₃ = −cos φ sin θ`,
/// `R₃₃ = cos θ`. θ comes from `atan2(sin θ, cos θ)` rather than `acos(R₃₃)`, which loses half
/// the digits near 0 and π. At `sin θ = 0` only `φ ± ψ` is defined; this returns `ψ = 0` there,
/// and the caller decides whether that is acceptable (see `frames::FrameError::EulerSingular`).
pub fn euler_angles(rotation: &Matrix3<f64>) -> Vector3<f64> {
    let r = rotation;
    // sin θ from both the third row and the third column (equal for an exact rotation).
    let sin_theta = 0.5 * (r[(2, 0)].hypot(r[(2, 1)]) + r[(0, 2)].hypot(r[(1, 2)]));
    let theta = sin_theta.atan2(r[(2, 2)]);
    if sin_theta > 0.0 {
        let psi = r[(2, 0)].atan2(r[(2, 1)]);
        let phi = r[(0, 2)].atan2(-r[(1, 2)]);
        Vector3::new(phi, theta, psi)
    } else {
        // R = Rz(φ ± ψ) (with a flip for θ = π): put it all into φ.
        let phi = r[(1, 0)].atan2(r[(0, 0)]);
        Vector3::new(phi, theta, 0.0)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn w_is_the_inverse_transpose_of_m_and_undefined_at_gimbal_lock() {
        let euler = Vector3::new(0.3, 1.1, -2.0);
        let w = w_matrix(&euler).unwrap();
        let m = angular_velocity_matrix(&euler);
        assert!((w * m.transpose() - Matrix3::identity()).abs().max() < 1e-15);
        let j = Vector3::new(1.0, -2.0, 0.5);
        let pe = euler_momenta_from_angular_momentum(&euler, &j);
        assert!((angular_momentum_from_euler_momenta(&euler, &pe).unwrap() - j).norm() < 1e-15);
        assert_eq!(w_matrix(&Vector3::new(0.3, 0.0, -2.0)), Err(HamiltonianError::EulerSingular { theta: 0.0 }));
    }
}

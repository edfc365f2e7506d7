//! The finiteness checks every path of the Hamiltonian makes, in one place: fast and
//! branch-light on the hot path, with the error (which names what was not finite) built on a
//! cold path.

use super::{HamiltonianError, PhaseState};

/// Whether every element is finite: `x · 0` is `±0` for finite `x` and NaN for ±∞ and NaN, so
/// the sum is NaN iff some element is not finite.
///
/// Why not `iter().all(is_finite)`: short-circuiting costs ~16 instructions per element
/// (callgrind: a third of the factorization's instructions went to this check), and the
/// branch-free `fold(true, |ok, x| ok & x.is_finite())` is vectorized into 16-byte loads of
/// values just written by 8-byte stores, which stalls on store-to-load forwarding (perf: half
/// the cycles of the output check). A scalar sum has neither problem, and nothing waits for
/// it but a well-predicted branch.
#[inline(always)]
pub(crate) fn all_finite(v: &[f64]) -> bool {
    !v.iter().fold(0.0, |acc, &x| acc + x * 0.0).is_nan()
}

/// Whether every component of a state is finite; inlined so that the values are checked where
/// they are computed instead of being reloaded from memory.
#[inline(always)]
pub(crate) fn state_is_finite<const N: usize>(s: &PhaseState<N>) -> bool {
    all_finite(s.q.as_slice())
        & all_finite(s.p.as_slice())
        & all_finite(s.euler.as_slice())
        & all_finite(s.pe.as_slice())
}

/// [`PhaseState::check_finite`] with the fast check first; the state's own check (which names the
/// block) only runs when something is not finite.
#[inline(always)]
pub(crate) fn check_state<const N: usize>(s: &PhaseState<N>) -> Result<(), HamiltonianError> {
    if state_is_finite(s) { Ok(()) } else { cold_check_state(s) }
}

#[cold]
#[inline(never)]
fn cold_check_state<const N: usize>(s: &PhaseState<N>) -> Result<(), HamiltonianError> {
    s.check_finite()
}

/// `x`, or [`HamiltonianError::NonFinite`] naming `quantity` if it is NaN or infinite.
pub(crate) fn finite(x: f64, quantity: &'static str) -> Result<f64, HamiltonianError> {
    if x.is_finite() { Ok(x) } else { Err(HamiltonianError::NonFinite { quantity }) }
}

/// A computed right-hand side, or [`HamiltonianError::NonFinite`] if any component is NaN or
/// infinite.
#[inline(always)]
pub(crate) fn check_rhs<const N: usize>(out: &PhaseState<N>) -> Result<(), HamiltonianError> {
    if state_is_finite(out) { Ok(()) } else { Err(non_finite_rhs()) }
}

#[cold]
#[inline(never)]
fn non_finite_rhs() -> HamiltonianError {
    HamiltonianError::NonFinite { quantity: "right-hand side of Hamilton's equations" }
}

#[cfg(test)]
mod tests {
    use nalgebra::{SVector, Vector3};

    use super::*;

    #[test]
    fn all_finite_rejects_nan_and_both_infinities_anywhere() {
        assert!(all_finite(&[]));
        assert!(all_finite(&[0.0, -0.0, 1e308, -1e308, f64::MIN_POSITIVE, 5e-324]));
        for bad in [f64::NAN, f64::INFINITY, f64::NEG_INFINITY] {
            for at in 0..3 {
                let mut v = [1.0, 2.0, 3.0];
                v[at] = bad;
                assert!(!all_finite(&v), "{v:?}");
            }
        }
        assert!(finite(1.5, "x").is_ok());
        assert_eq!(finite(f64::NAN, "x"), Err(HamiltonianError::NonFinite { quantity: "x" }));
    }

    /// The fast state check agrees with the state's own, which names the first bad block; a
    /// non-finite right-hand side is named as such.
    #[test]
    fn state_checks_name_the_first_non_finite_block() {
        let ok = PhaseState::<2> {
            q: SVector::from([1.0, 2.0]),
            p: SVector::zeros(),
            euler: Vector3::new(0.0, 1.0, 0.0),
            pe: Vector3::zeros(),
        };
        assert_eq!(check_state(&ok), Ok(()));
        assert_eq!(check_rhs(&ok), Ok(()));
        let mut bad = ok;
        bad.p[1] = f64::INFINITY;
        bad.pe[0] = f64::NAN;
        assert!(!state_is_finite(&bad));
        assert_eq!(check_state(&bad), Err(HamiltonianError::NonFinite { quantity: "internal momenta p" }));
        assert_eq!(
            check_rhs(&bad),
            Err(HamiltonianError::NonFinite { quantity: "right-hand side of Hamilton's equations" })
        );
    }
}

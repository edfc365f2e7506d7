! The spline x Legendre surface of molecules/arn2.toml (and ffi/surfaces/arn2_spline.c) in
! Fortran, named by tests/surfaces/arn2_fortran.toml and compiled into rovib-ffi with gfortran.
! The functions a definition's Fortran exports, with C binding, for molecule NAME:
!   real(c_double) function NAME_gradient(q, grad): dU/dq into grad, returns U (hartree)
!   real(c_double) function NAME_energy(q): U
! q = (R in bohr, theta in rad).
module arn2_fortran_surface
  use, intrinsic :: iso_c_binding, only: c_double
  implicit none
  private
  real(c_double), parameter :: knots(7) = [5.0d0, 6.0d0, 7.0d0, 8.0d0, 9.0d0, 10.5d0, 12.0d0]
  real(c_double), parameter :: a = 30.0d0, beta = 1.6d0, a2 = 0.4d0
  ! Spline coefficients per interval (a, b, c, d): V(R) = a + t (b + t (c + t d)).
  real(c_double), parameter :: v0(4, 6) = reshape([ &
    -0.00512d0, 0.006144d0, -0.003718698377862021d0, 0.0009800207372584549d0, &
    -0.0017146776406035665d0, 0.0016466654560513229d0, -0.0007786361660866564d0, 0.00016665957045377297d0, &
    -0.000679988780185127d0, 0.000589371835239329d0, -0.0002786574547253375d0, 6.409861842113553d-05, &
    -0.00030517578125d0, 0.00022435278105206055d0, -8.636159946193091d-05, 1.6650485807156708d-05, &
    -0.00015053411385271365d0, 0.00010158103954966883d0, -3.6410142040460786d-05, 6.040931078019843d-06, &
    -5.969723173093021d-05, 3.3126898204920415d-05, -9.225952189371495d-06, 1.1773151748754712d-06], [4, 6])
  real(c_double), parameter :: v2(4, 6) = reshape([ &
    0.001536d0, -0.0018432d0, 0.0011156095133586065d0, -0.0002940062211775367d0, &
    0.00051440329218107d0, -0.0004939996368153968d0, 0.00023359084982599648d0, -4.9997871136131664d-05, &
    0.00020399663405553807d0, -0.0001768115505717988d0, 8.359723641760148d-05, -1.9229585526340763d-05, &
    9.1552734375d-05, -6.730583431561812d-05, 2.5908479838579193d-05, -4.995145742146978d-06, &
    4.51602341558141d-05, -3.0474311864900664d-05, 1.0923042612138258d-05, -1.81227932340596d-06, &
    1.7909169519279064d-05, -9.93806946147612d-06, 2.767785656811438d-06, -3.531945524626377d-07], [4, 6])
  public :: arn2_fortran_gradient, arn2_fortran_energy
contains
  ! V_l(R) and dV_l/dR from the table v, or the -C6/R^6 tail beyond the knots.
  pure subroutine radial(v, c6, r, val, dv)
    real(c_double), intent(in) :: v(4, 6), c6, r
    real(c_double), intent(out) :: val, dv
    real(c_double) :: t, r6
    integer :: i
    if (r >= knots(7)) then
      r6 = r**6
      val = -c6 / r6
      dv = 6.0d0 * c6 / (r6 * r)
      return
    end if
    i = 1
    do while (i < 6)
      if (r < knots(i + 1)) exit
      i = i + 1
    end do
    t = r - knots(i)
    val = v(1, i) + t * (v(2, i) + t * (v(3, i) + t * v(4, i)))
    dv = v(2, i) + t * (2.0d0 * v(3, i) + t * (3.0d0 * v(4, i)))
  end subroutine radial

  real(c_double) function arn2_fortran_gradient(q, grad) bind(C, name="arn2_fortran_gradient")
    real(c_double), intent(in) :: q(2)
    real(c_double), intent(out) :: grad(2)
    real(c_double) :: r, c, s, p2, dp2, val0, dv0, val2, dv2, short_range
    r = q(1)
    c = cos(q(2))
    s = sin(q(2))
    p2 = 1.5d0 * c * c - 0.5d0
    dp2 = 3.0d0 * c
    call radial(v0, 80.0d0, r, val0, dv0)
    call radial(v2, -24.0d0, r, val2, dv2)
    short_range = a * exp(-beta * r)
    grad(1) = -beta * short_range * (1.0d0 + a2 * p2) + dv0 + dv2 * p2
    grad(2) = -(short_range * a2 + val2) * dp2 * s
    arn2_fortran_gradient = short_range * (1.0d0 + a2 * p2) + val0 + val2 * p2
  end function arn2_fortran_gradient

  real(c_double) function arn2_fortran_energy(q) bind(C, name="arn2_fortran_energy")
    real(c_double), intent(in) :: q(2)
    real(c_double) :: grad(2)
    arn2_fortran_energy = arn2_fortran_gradient(q, grad)
  end function arn2_fortran_energy
end module arn2_fortran_surface

/*
 * co2ar_sites.c: molecules/co2ar.toml's surface written over the atoms' Cartesian positions,
 * as a shared library with the rovib_surface_positions_* functions of rovib_surface.h:
 *
 *   U = lj(|Ar - O1|, eps_o, sig_o) + lj(|Ar - O2|, eps_o, sig_o) + lj(|Ar - C|, eps_c, sig_c),
 *   lj(r, eps, sig) = 4 eps ((sig / r)^12 - (sig / r)^6)   (cm-1, returned in hartree),
 *
 * and its dipole mu = (quad (P2(c) + c^2) + exch) r_hat - quad c u, with r = Ar - C, R = |r|,
 * r_hat = r / R, u = (O1 - O2) / |O1 - O2| (the CO2 axis), c = r_hat . u, quad = k_quad / R^4,
 * exch = -d0 exp(-R / rho): the definition's body-frame dipole written so that it turns with
 * the atoms.
 *
 * Atoms in the definition's order C, O1, O2, Ar; x[3 i + k] is component k of atom i, bohr.
 * Build: gcc -O2 -shared -fPIC -I ffi/include -o libco2ar.so co2ar_sites.c -lm
 * (tests/numerics/position_surfaces.rs does). With -DCO2AR_FIELD an external field along z is
 * added (not rotation-invariant: refused at load); with -DCO2AR_GRADIENT_SCALE=x the gradient
 * is scaled by x (a wrong gradient: refused at load).
 */
#include <math.h>

#include "rovib_surface.h"

#ifndef CO2AR_GRADIENT_SCALE
#define CO2AR_GRADIENT_SCALE 1.0
#endif

enum { C = 0, O1 = 1, O2 = 2, AR = 3, ATOMS = 4 };

static const double WAVENUMBERS = 219474.63136320; /* cm-1 per hartree */
static const double EPS_O = 55, SIG_O = 6.047, EPS_C = 40, SIG_C = 6.425;
static const double K_QUAD = -106.04, D0 = 20.0, RHO = 0.8;

int rovib_surface_abi(void) { return ROVIB_SURFACE_ABI; }

int rovib_surface_atoms(void) { return ATOMS; }

/* lj(r) in cm-1 and its derivative d lj / dr into *dv. */
static double lj(double r, double eps, double sig, double *dv) {
    double s12 = pow(sig / r, 12), s6 = pow(sig / r, 6);
    *dv = 4 * eps * (-12 * s12 + 6 * s6) / r;
    return 4 * eps * (s12 - s6);
}

/* The Ar - atom j pair: adds its energy (cm-1) and, if grad, its gradient (cm-1 / bohr). */
static double pair(const double *x, int j, double eps, double sig, double *grad) {
    double d[3], r2 = 0, dv;
    for (int k = 0; k < 3; k++) {
        d[k] = x[3 * AR + k] - x[3 * j + k];
        r2 += d[k] * d[k];
    }
    double r = sqrt(r2);
    double v = lj(r, eps, sig, &dv);
    if (grad)
        for (int k = 0; k < 3; k++) {
            grad[3 * AR + k] += dv * d[k] / r;
            grad[3 * j + k] -= dv * d[k] / r;
        }
    return v;
}

static double surface(const double *x, double *grad) {
    if (grad)
        for (int k = 0; k < 3 * ATOMS; k++) grad[k] = 0;
    double u = pair(x, O1, EPS_O, SIG_O, grad) + pair(x, O2, EPS_O, SIG_O, grad) + pair(x, C, EPS_C, SIG_C, grad);
#ifdef CO2AR_FIELD
    u += 1e-3 * x[3 * AR + 2];
    if (grad) grad[3 * AR + 2] += 1e-3;
#endif
    if (grad)
        for (int k = 0; k < 3 * ATOMS; k++) grad[k] *= CO2AR_GRADIENT_SCALE / WAVENUMBERS;
    return u / WAVENUMBERS;
}

double rovib_surface_positions_energy(const double *x) { return surface(x, 0); }

double rovib_surface_positions_gradient(const double *x, double *grad) { return surface(x, grad); }

/* r_hat, R, u, D (= |O1 - O2|) and c of positions x. */
static void frame(const double *x, double *rh, double *r, double *u, double *d, double *c) {
    double r2 = 0, d2 = 0;
    for (int k = 0; k < 3; k++) {
        rh[k] = x[3 * AR + k] - x[3 * C + k];
        u[k] = x[3 * O1 + k] - x[3 * O2 + k];
        r2 += rh[k] * rh[k];
        d2 += u[k] * u[k];
    }
    *r = sqrt(r2);
    *d = sqrt(d2);
    *c = 0;
    for (int k = 0; k < 3; k++) {
        rh[k] /= *r;
        u[k] /= *d;
        *c += rh[k] * u[k];
    }
}

void rovib_surface_positions_dipole(const double *x, double *mu) {
    double rh[3], u[3], r, d, c;
    frame(x, rh, &r, u, &d, &c);
    double quad = K_QUAD / pow(r, 4), exch = -D0 * exp(-r / RHO);
    double a = quad * ((3 * c * c - 1) / 2 + c * c) + exch, b = quad * c;
    for (int k = 0; k < 3; k++) mu[k] = a * rh[k] - b * u[k];
}

/* d mu_a / d x_{i k} into dmu[3 (3 i + k) + a]. */
void rovib_surface_positions_dipole_jacobian(const double *x, double *dmu) {
    double rh[3], u[3], r, d, c;
    frame(x, rh, &r, u, &d, &c);
    double quad = K_QUAD / pow(r, 4), dquad = -4 * quad / r;
    double exch = -D0 * exp(-r / RHO), dexch = -exch / RHO;
    double a = quad * ((3 * c * c - 1) / 2 + c * c) + exch, b = quad * c;
    double a_r = dquad * ((3 * c * c - 1) / 2 + c * c) + dexch, a_c = quad * 5 * c;
    double b_r = dquad * c, b_c = quad;
    for (int k = 0; k < 3; k++) {
        double dc_dr = (u[k] - c * rh[k]) / r, dc_dd = (rh[k] - c * u[k]) / d;
        for (int m = 0; m < 3; m++) {
            double delta = m == k ? 1.0 : 0.0;
            /* d mu_m / d r_k and d mu_m / d d_k (r = Ar - C, d = O1 - O2). */
            double by_r = a_r * rh[k] * rh[m] + a_c * dc_dr * rh[m] + a * (delta - rh[m] * rh[k]) / r
                          - u[m] * (b_r * rh[k] + b_c * dc_dr);
            double by_d = a_c * dc_dd * rh[m] - b_c * dc_dd * u[m] - b * (delta - u[m] * u[k]) / d;
            dmu[3 * (3 * AR + k) + m] = by_r;
            dmu[3 * (3 * C + k) + m] = -by_r;
            dmu[3 * (3 * O1 + k) + m] = by_d;
            dmu[3 * (3 * O2 + k) + m] = -by_d;
        }
    }
}

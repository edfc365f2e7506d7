/*
 * arn2_spline.c: a rigid Ar-N2-like atom-diatom surface in the style of published van der Waals
 * surfaces: cubic splines in R over intervals times Legendre polynomials P_l(cos theta), an
 * exponential short-range part and a -C6/R^6 tail,
 *
 *   U(R, theta) = A exp(-beta R) (1 + a2 P2(c)) + V0(R) + V2(R) P2(c),   c = cos(theta),
 *
 * V_l a clamped cubic spline through -C6_l / R^6 at the knots 5, 6, 7, 8, 9, 10.5, 12 bohr
 * (C6_0 = 80, C6_2 = -24), extended below 5 bohr by its first piece and above 12 bohr by
 * -C6_l / R^6 itself. T-shaped minimum about -109 cm-1 at R = 6.54 bohr.
 * Coordinates as molecules/arn2.toml: q[0] = R (bohr), q[1] = theta (rad).
 * Also a body-frame induced dipole mu = m(R) (sin theta, 0, cos theta), m(R) = -D7 / R^7.
 *
 * The same surface is molecules/arn2.toml's potential and dipole in the definition language.
 * Compiled as a shared library (gcc -shared -fPIC -Iffi/include) it exports the
 * rovib_surface_* functions of rovib_surface.h; rovib-ffi's build script compiles it into the
 * crate with SURFACE(name) defined to give the functions their own prefix.
 * With -DARN2_THETA_SIGN_BUG the theta gradient has the wrong sign (a test of the gradient check);
 * with -DARN2_NO_GRADIENT the library exports no gradient function (a test of central differences).
 */
#include <math.h>

#ifndef SURFACE
#include "rovib_surface.h"
#define SURFACE(name) rovib_surface_##name
#endif

#define NKNOTS 7
static const double KNOTS[NKNOTS] = {5.0, 6.0, 7.0, 8.0, 9.0, 10.5, 12.0};
static const double C6[2] = {80.0, -24.0};
static const double A = 30.0, BETA = 1.6, A2 = 0.4, D7 = 12.0;

/* Spline coefficients per interval: V(R) = a + t (b + t (c + t d)), t = R - KNOTS[i]. */
static const double V0[6][4] = {
    {-0.00512, 0.006144, -0.003718698377862021, 0.0009800207372584549},
    {-0.0017146776406035665, 0.0016466654560513229, -0.0007786361660866564, 0.00016665957045377297},
    {-0.000679988780185127, 0.000589371835239329, -0.0002786574547253375, 6.409861842113553e-05},
    {-0.00030517578125, 0.00022435278105206055, -8.636159946193091e-05, 1.6650485807156708e-05},
    {-0.00015053411385271365, 0.00010158103954966883, -3.6410142040460786e-05, 6.040931078019843e-06},
    {-5.969723173093021e-05, 3.3126898204920415e-05, -9.225952189371495e-06, 1.1773151748754712e-06},
};
static const double V2[6][4] = {
    {0.001536, -0.0018432, 0.0011156095133586065, -0.0002940062211775367},
    {0.00051440329218107, -0.0004939996368153968, 0.00023359084982599648, -4.9997871136131664e-05},
    {0.00020399663405553807, -0.0001768115505717988, 8.359723641760148e-05, -1.9229585526340763e-05},
    {9.1552734375e-05, -6.730583431561812e-05, 2.5908479838579193e-05, -4.995145742146978e-06},
    {4.51602341558141e-05, -3.0474311864900664e-05, 1.0923042612138258e-05, -1.81227932340596e-06},
    {1.7909169519279064e-05, -9.93806946147612e-06, 2.767785656811438e-06, -3.531945524626377e-07},
};

/* V_l(R) and dV_l/dR from coefficient table `v` (interval by R) or the tail beyond the knots. */
static double radial(const double v[][4], double c6, double r, double *dv) {
    if (r >= KNOTS[NKNOTS - 1]) {
        double r6 = pow(r, 6);
        *dv = 6.0 * c6 / (r6 * r);
        return -c6 / r6;
    }
    int i = 0;
    while (i < NKNOTS - 2 && r >= KNOTS[i + 1]) i++;
    double t = r - KNOTS[i];
    const double *k = v[i];
    *dv = k[1] + t * (2.0 * k[2] + t * (3.0 * k[3]));
    return k[0] + t * (k[1] + t * (k[2] + t * k[3]));
}

/* P_l(x) by Bonnet's recurrence and its derivative by P'_{n+1} = P'_{n-1} + (2n + 1) P_n. */
static double legendre(int l, double x, double *dp) {
    double p_prev = 1.0, p = x, dp_prev = 0.0, d = 1.0;
    if (l == 0) { *dp = 0.0; return 1.0; }
    for (int n = 1; n < l; n++) {
        double p_next = ((2 * n + 1) * x * p - n * p_prev) / (n + 1);
        double d_next = dp_prev + (2 * n + 1) * p;
        p_prev = p; p = p_next;
        dp_prev = d; d = d_next;
    }
    *dp = d;
    return p;
}

int SURFACE(abi)(void) { return 1; }

int SURFACE(coordinates)(void) { return 2; }

#ifdef ARN2_NO_GRADIENT
/* Not exported: rovib takes central differences of the energy. */
#define GRADIENT static double arn2_unexported_gradient
#define GRADIENT_CALL arn2_unexported_gradient
#else
#define GRADIENT double SURFACE(gradient)
#define GRADIENT_CALL SURFACE(gradient)
#endif

GRADIENT(const double *q, double *grad) {
    double r = q[0], theta = q[1];
    double c = cos(theta), s = sin(theta);
    double dp2;
    double p2 = legendre(2, c, &dp2);
    double dv0, dv2;
    double v0 = radial(V0, C6[0], r, &dv0);
    double v2 = radial(V2, C6[1], r, &dv2);
    double short_range = A * exp(-BETA * r);
    grad[0] = -BETA * short_range * (1.0 + A2 * p2) + dv0 + dv2 * p2;
#ifdef ARN2_THETA_SIGN_BUG
    grad[1] = (short_range * A2 + v2) * dp2 * s;
#else
    grad[1] = -(short_range * A2 + v2) * dp2 * s;
#endif
    return short_range * (1.0 + A2 * p2) + v0 + v2 * p2;
}

double SURFACE(energy)(const double *q) {
    double grad[2];
    return GRADIENT_CALL(q, grad);
}

void SURFACE(dipole)(const double *q, double *mu) {
    double m = -D7 / pow(q[0], 7);
    mu[0] = m * sin(q[1]);
    mu[1] = 0.0;
    mu[2] = m * cos(q[1]);
}

void SURFACE(dipole_jacobian)(const double *q, double *dmu) {
    double m = -D7 / pow(q[0], 7), dm = -7.0 * m / q[0];
    double s = sin(q[1]), c = cos(q[1]);
    dmu[0] = dm * s; dmu[1] = 0.0; dmu[2] = dm * c;   /* d/dR */
    dmu[3] = m * c;  dmu[4] = 0.0; dmu[5] = -m * s;   /* d/dtheta */
}

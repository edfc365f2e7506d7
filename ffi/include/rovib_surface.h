/*
 * rovib_surface.h: the C ABI of a potential energy (and optional dipole) surface that rovib
 * loads at run time from a shared library, named in a scene:
 *
 *     [potential]
 *     library = "libsurf.so"   # relative to the scene file
 *
 * Build one with e.g.  gcc -O2 -shared -fPIC -o libsurf.so surf.c -lm
 * (docs/src/howto/outside-surfaces.md has a worked example). rovib itself is not rebuilt.
 *
 * Units: atomic units. q[k] is internal coordinate k of the molecule, in the molecule
 * definition's coordinate order, in bohr (lengths) or radians (angles), whatever unit the
 * definition writes it in. Energies in hartree, dipoles in e*bohr, in the molecule's body frame
 * (the frame of the definition's positions, centre of mass at the origin).
 *
 * Thread safety: rovib calls the functions from several threads at once (ensembles run
 * trajectories in parallel), so they must be reentrant: no writable global state after init.
 *
 * Before the first trajectory rovib checks the gradient against central differences of the
 * energy at the molecule's reference geometry and at random points inside the coordinates'
 * ranges (a fixed seed); a disagreement is an error naming the coordinate and both values.
 */
#ifndef ROVIB_SURFACE_H
#define ROVIB_SURFACE_H

#ifdef __cplusplus
extern "C" {
#endif

/* The version of this ABI; rovib_surface_abi() must return it. */
#define ROVIB_SURFACE_ABI 1

/* ---- Required -------------------------------------------------------------------------- */

/* ROVIB_SURFACE_ABI, for the header the library was compiled against. */
int rovib_surface_abi(void);

/* The number of internal coordinates n the surface expects. rovib refuses (an error, before
 * any other call) a library whose n differs from the molecule's. */
int rovib_surface_coordinates(void);

/* U(q), hartree. q points to n doubles. */
double rovib_surface_energy(const double *q);

/* ---- Optional -------------------------------------------------------------------------- */

/* Writes dU/dq_k into grad[k] (k = 0 .. n-1, hartree per unit of q_k) and returns U(q).
 * Without it rovib takes central differences of rovib_surface_energy (2n + 1 calls per
 * gradient, step 6.06e-6 * max(1, |q_k|), about 4e-11 relative accuracy) and says so. */
double rovib_surface_gradient(const double *q, double *grad);

/* Called once, after loading and the two counts above and before any other call; 0 means
 * ready, anything else is reported as an error (with the number) and the run does not start. */
int rovib_surface_init(void);

/* A dipole surface: both or neither (one without the other is refused).
 * rovib_surface_dipole writes the body-frame mu(q) into mu[0..3] (x, y, z);
 * rovib_surface_dipole_jacobian writes d mu_a / d q_k into dmu[3 * k + a]. */
void rovib_surface_dipole(const double *q, double *mu);
void rovib_surface_dipole_jacobian(const double *q, double *dmu);

#ifdef __cplusplus
}
#endif

#endif /* ROVIB_SURFACE_H */

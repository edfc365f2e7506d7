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
 * Two forms: a surface over the internal coordinates q (rovib_surface_coordinates and
 * rovib_surface_energy, below), or over the atoms' Cartesian positions x (rovib_surface_atoms
 * and rovib_surface_positions_energy, at the end), which rovib composes with the molecule's
 * positions R(q). A library has exactly one of the two energy functions, and no function of
 * the other form (each is refused at load, with the function named).
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

/* ---- A surface over internal coordinates --------------------------------------------------- */

/* The number of internal coordinates n the surface expects. rovib refuses (an error, before
 * any other call) a library whose n differs from the molecule's. */
int rovib_surface_coordinates(void);

/* U(q), hartree. q points to n doubles. */
double rovib_surface_energy(const double *q);

/* Optional: writes dU/dq_k into grad[k] (k = 0 .. n-1, hartree per unit of q_k) and returns U(q).
 * Without it rovib takes central differences of rovib_surface_energy (2n + 1 calls per
 * gradient, step 6.06e-6 * max(1, |q_k|), about 4e-11 relative accuracy) and says so. */
double rovib_surface_gradient(const double *q, double *grad);

/* Optional, a dipole surface: both or neither (one without the other is refused).
 * rovib_surface_dipole writes the body-frame mu(q) into mu[0..3] (x, y, z);
 * rovib_surface_dipole_jacobian writes d mu_a / d q_k into dmu[3 * k + a]. */
void rovib_surface_dipole(const double *q, double *mu);
void rovib_surface_dipole_jacobian(const double *q, double *dmu);

/* ---- A surface over the atoms' Cartesian positions ------------------------------------------ */

/* x points to 3 * NA doubles: atom i's x, y, z at x[3 i], x[3 i + 1], x[3 i + 2], bohr, the atoms
 * in the molecule definition's order, in the body frame (the frame of the definition's
 * positions, centre of mass at the origin). The surface must not depend on where the molecule
 * is or how it is turned: before the first trajectory rovib checks that U and its gradient are
 * unchanged (to 1e-10 relative) when the atoms at the reference geometry are turned by three
 * rotations and moved by a translation, and refuses the library otherwise. */

/* NA, the number of atoms; must equal the molecule's. */
int rovib_surface_atoms(void);

/* U(x), hartree. */
double rovib_surface_positions_energy(const double *x);

/* Optional: writes dU/dx_j into grad[j] (j = 0 .. 3 NA - 1, hartree/bohr) and returns U(x).
 * rovib makes dU/dq = sum_j dU/dx_j dR_j/dq through the molecule's positions Jacobian; without
 * this function, central differences of U(R(q)) in q as above. */
double rovib_surface_positions_gradient(const double *x, double *grad);

/* Optional, a dipole surface (e*bohr), both or neither: mu(x) into mu[0..3], turning with the
 * atoms (it is evaluated in the body frame); d mu_a / d x_j into dmu[3 j + a]. */
void rovib_surface_positions_dipole(const double *x, double *mu);
void rovib_surface_positions_dipole_jacobian(const double *x, double *dmu);

/* ---- Either form ----------------------------------------------------------------------------- */

/* Optional: called once, after loading and the counts above and before any other call; 0 means
 * ready, anything else is reported as an error (with the number) and the run does not start. */
int rovib_surface_init(void);

#ifdef __cplusplus
}
#endif

#endif /* ROVIB_SURFACE_H */

/* nd_linalg: the small dense linear algebra the controllers and fits need, row-major. */
#ifndef ND_LINALG_H
#define ND_LINALG_H

/* Cholesky factor of the symmetric positive definite n x n matrix A in place (its lower
 * triangle becomes L, A = L L'). Return 0, or -1 if a pivot is not positive. */
int nd_chol(double *A, int n);

/* Solve L L' x = b with nd_chol's factor L; x may alias b. */
void nd_chol_solve(const double *L, int n, const double *b, double *x);

/* out = A A' + lambda I for the r x c matrix A (out is r x r). */
void nd_aat(const double *A, int r, int c, double lambda, double *out);

#endif

/* linalg.h — small dense double-precision solves shared by the closed-form fits (train/fit_lmmse.c,
 * train/coding.c): a lower Cholesky factor in place and the two triangular solves.
 * What it is not: a LAPACK (no pivoting, no blocking: n is a window's taps, ~100-250).
 * Row-major n x n matrices. */
#ifndef LM_LINALG_H
#define LM_LINALG_H

/* A = L L^T in place: reads A's lower triangle, writes L there (the upper is left as it was).
 * Returns 0, or -1 when A is not (numerically) positive definite. */
int lm_cholesky(double *A, int n);
/* X (n x m, in place) = A^-1 X given A's Cholesky factor L (lower triangle of an n x n matrix):
 * forward with L, backward with L^T, each column's sums in ascending index order. */
void lm_cholesky_solve(const double *L, int n, double *X, int m);

#endif

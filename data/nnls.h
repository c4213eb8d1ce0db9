/* nnls.h — non-negative least squares: min ||A x - b||_2 subject to x >= 0 (Lawson and Hanson,
 * "Solving Least Squares Problems", 1974, chapter 23: the active-set algorithm NNLS).
 * What it is: a small dense solver in double for the LED-gain calibration (data/calib.h) and
 * anything else with a few dozen unknowns; each least-squares subproblem is solved by Householder
 * QR of the columns in the passive set (no normal equations).
 * What it is not: a large or sparse solver, or a clipped unconstrained solution (which is not
 * the NNLS solution once unknowns are coupled). */
#ifndef LM_NNLS_H
#define LM_NNLS_H
#include "tensor/status.h"

#define LM_NNLS_MAX_N 256

/* A: m x n row-major (A[i * n + j]), b: m; x: n (out). m >= 1, 1 <= n <= LM_NNLS_MAX_N.
 * *resid (optional): ||A x - b||_2 at the solution. At return x satisfies the KKT conditions
 * within rounding: x >= 0, w = A^T (b - A x) <= tol where x_j = 0 and |w_j| <= tol where
 * x_j > 0. LM_ERR_ARG (bad sizes, NULL), LM_ERR_NUMERIC (non-finite A or b, or no convergence
 * in 3n outer iterations), LM_ERR_NOMEM. */
lm_status lm_nnls(const double *A, int m, int n, const double *b, double *x, double *resid,
                  lm_err *err);

#endif

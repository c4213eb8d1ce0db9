/* nnls.c — Lawson-Hanson active-set NNLS (nnls.h).
 * Notation: P the passive set (unknowns free to be > 0), Z the active set (held at 0);
 * w = A^T (b - A x) the negative gradient. The outer loop moves the Z unknown with the largest
 * positive w into P; the inner loop solves the unconstrained least squares on P and, while
 * that solution z has a non-positive entry, steps from x towards z as far as feasibility allows
 * and moves the unknowns that reached 0 back to Z. */
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include "data/nnls.h"

/* Least squares on the columns cols[0..k) of A: z[cols[j]] = solution, the rest untouched.
 * Householder QR of the m x k submatrix (copied column-major into q); a column whose pivot is
 * negligible (dependent on earlier ones) gets 0. work: m * k + m doubles. */
static void ls_subset(const double *A, int m, int n, const double *b, const int *cols, int k,
                      double *z, double *work)
{
    double *q = work, *r = work + (size_t)m * k;
    for (int j = 0; j < k; j++)
        for (int i = 0; i < m; i++) q[(size_t)j * m + i] = A[(size_t)i * n + cols[j]];
    memcpy(r, b, (size_t)m * sizeof *r);
    double scale = 0.0;
    for (size_t i = 0; i < (size_t)m * k; i++) scale = fmax(scale, fabs(q[i]));
    int kk = k < m ? k : m;
    for (int j = 0; j < kk; j++) { /* reflect column j below the diagonal onto e_j */
        double *v = q + (size_t)j * m, norm = 0.0;
        for (int i = j; i < m; i++) norm += v[i] * v[i];
        norm = sqrt(norm);
        if (norm <= 1e3 * DBL_EPSILON * scale * m) continue;
        double alpha = v[j] > 0 ? -norm : norm, vj = v[j] - alpha, vtv = vj * vj;
        for (int i = j + 1; i < m; i++) vtv += v[i] * v[i];
        v[j] = vj;
        for (int c = j + 1; c < k; c++) { /* apply H = I - 2 v v^T / v^T v */
            double *u = q + (size_t)c * m, s = 0.0;
            for (int i = j; i < m; i++) s += v[i] * u[i];
            s = 2.0 * s / vtv;
            for (int i = j; i < m; i++) u[i] -= s * v[i];
        }
        double s = 0.0;
        for (int i = j; i < m; i++) s += v[i] * r[i];
        s = 2.0 * s / vtv;
        for (int i = j; i < m; i++) r[i] -= s * v[i];
        v[j] = alpha; /* R's diagonal; below it is v, no longer needed */
    }
    for (int j = k - 1; j >= 0; j--) { /* back substitution on R (k x k upper) */
        double diag = j < m ? q[(size_t)j * m + j] : 0.0, s = j < m ? r[j] : 0.0;
        if (fabs(diag) <= 1e3 * DBL_EPSILON * scale * m) {
            z[cols[j]] = 0.0;
            continue;
        }
        for (int c = j + 1; c < k; c++) s -= q[(size_t)c * m + j] * z[cols[c]];
        z[cols[j]] = s / diag;
    }
}

/* w = A^T (b - A x); returns ||b - A x||. */
static double gradient(const double *A, int m, int n, const double *b, const double *x,
                       double *w, double *res)
{
    double rr = 0.0;
    for (int i = 0; i < m; i++) {
        double s = b[i];
        for (int j = 0; j < n; j++) s -= A[(size_t)i * n + j] * x[j];
        res[i] = s;
        rr += s * s;
    }
    for (int j = 0; j < n; j++) {
        double s = 0.0;
        for (int i = 0; i < m; i++) s += A[(size_t)i * n + j] * res[i];
        w[j] = s;
    }
    return sqrt(rr);
}

lm_status lm_nnls(const double *A, int m, int n, const double *b, double *x, double *resid,
                  lm_err *err)
{
    if (!A || !b || !x || m < 1 || n < 1 || n > LM_NNLS_MAX_N)
        return lm_err_set(err, LM_ERR_ARG, "nnls: bad arguments (m %d, n %d)", m, n);
    double anorm = 0.0;
    for (size_t i = 0; i < (size_t)m * n; i++) {
        if (!isfinite(A[i])) return lm_err_set(err, LM_ERR_NUMERIC, "nnls: non-finite matrix");
        anorm = fmax(anorm, fabs(A[i]));
    }
    for (int i = 0; i < m; i++)
        if (!isfinite(b[i])) return lm_err_set(err, LM_ERR_NUMERIC, "nnls: non-finite vector");
    double *work = malloc(((size_t)m * n + 3 * (size_t)m + 2 * (size_t)n) * sizeof *work);
    int *passive = calloc((size_t)n, sizeof *passive), *cols = malloc((size_t)n * sizeof *cols);
    if (!work || !passive || !cols) {
        free(work), free(passive), free(cols);
        return lm_err_set(err, LM_ERR_NOMEM, "nnls: out of memory");
    }
    double *qr = work, *res = work + (size_t)m * n + m, *w = res + m, *z = w + n;
    double bnorm = 0.0;
    for (int i = 0; i < m; i++) bnorm = fmax(bnorm, fabs(b[i]));
    double tol = 10.0 * DBL_EPSILON * (anorm * bnorm + 1e-300) * (m > n ? m : n);
    memset(x, 0, (size_t)n * sizeof *x);
    lm_status st = LM_OK;
    double rn = gradient(A, m, n, b, x, w, res);
    for (int outer = 0;; outer++) {
        int jmax = -1;
        for (int j = 0; j < n; j++)
            if (!passive[j] && w[j] > tol && (jmax < 0 || w[j] > w[jmax])) jmax = j;
        if (jmax < 0) break; /* KKT holds */
        if (outer >= 3 * n) {
            st = lm_err_set(err, LM_ERR_NUMERIC, "nnls: no convergence in %d iterations", 3 * n);
            break;
        }
        passive[jmax] = 1;
        for (int inner = 0; inner <= n; inner++) {
            int k = 0;
            for (int j = 0; j < n; j++)
                if (passive[j]) cols[k++] = j;
            memset(z, 0, (size_t)n * sizeof *z);
            ls_subset(A, m, n, b, cols, k, z, qr);
            if (inner == 0 && z[jmax] <= 0.0) { /* the new unknown cannot help: stop (rounding) */
                passive[jmax] = 0;
                w[jmax] = 0.0;
                goto next;
            }
            double step = 1.0;
            int block = -1; /* the unknown that reaches 0 first on the way from x to z */
            for (int c = 0; c < k; c++) {
                int j = cols[c];
                if (z[j] <= 0.0) {
                    double t = x[j] / (x[j] - z[j]);
                    if (block < 0 || t < step) step = t, block = j;
                }
            }
            if (block < 0) {
                memcpy(x, z, (size_t)n * sizeof *x);
                break;
            }
            for (int c = 0; c < k; c++) {
                int j = cols[c];
                x[j] += step * (z[j] - x[j]);
                if (j == block || x[j] <= 0.0) x[j] = 0.0, passive[j] = 0;
            }
        }
        rn = gradient(A, m, n, b, x, w, res);
    next:;
    }
    if (!st) rn = gradient(A, m, n, b, x, w, res);
    if (resid) *resid = rn;
    free(work), free(passive), free(cols);
    return st;
}

/* test_nnls.c — the NNLS solver (data/nnls.h): on random coupled problems (m = 30, n = 8,
 * correlated columns, a true solution with zeros, noise) the solution is non-negative, meets the
 * KKT conditions and has the smallest residual over all 2^n passive sets (brute force: every
 * subset's unconstrained least squares that is feasible); it differs from clipping the
 * unconstrained solution at 0 (which is not the NNLS solution on such problems); a problem with
 * a non-negative unconstrained solution gives that solution; separable problems give the
 * per-unknown clipped ratio; bad input fails with the documented status. */
#include <stdlib.h>
#include "tests/check.h"
#include "data/nnls.h"

#define M 30
#define N 8

static double urand(unsigned *s)
{
    *s = *s * 1103515245u + 12345u;
    return ((*s >> 8) & 0xFFFFFF) / 16777216.0;
}

/* Unconstrained least squares on the subset mask by normal equations (Gauss-Jordan): the
 * brute-force reference, independent of the solver's QR. Returns 0 if singular. */
static int ls_mask(const double *A, const double *b, unsigned mask, double *x)
{
    int idx[N], k = 0;
    for (int j = 0; j < N; j++)
        if (mask >> j & 1) idx[k++] = j;
    double G[N][N + 1];
    for (int r = 0; r < k; r++) {
        for (int c = 0; c < k; c++) {
            double s = 0;
            for (int i = 0; i < M; i++) s += A[i * N + idx[r]] * A[i * N + idx[c]];
            G[r][c] = s;
        }
        double s = 0;
        for (int i = 0; i < M; i++) s += A[i * N + idx[r]] * b[i];
        G[r][k] = s;
    }
    for (int c = 0; c < k; c++) {
        int p = c;
        for (int r = c + 1; r < k; r++)
            if (fabs(G[r][c]) > fabs(G[p][c])) p = r;
        if (fabs(G[p][c]) < 1e-12) return 0;
        for (int t = 0; t <= k; t++) {
            double tmp = G[c][t];
            G[c][t] = G[p][t], G[p][t] = tmp;
        }
        for (int r = 0; r < k; r++) {
            if (r == c) continue;
            double f = G[r][c] / G[c][c];
            for (int t = c; t <= k; t++) G[r][t] -= f * G[c][t];
        }
    }
    for (int j = 0; j < N; j++) x[j] = 0;
    for (int r = 0; r < k; r++) x[idx[r]] = G[r][k] / G[r][r];
    return 1;
}

static double resid(const double *A, const double *b, const double *x)
{
    double rr = 0;
    for (int i = 0; i < M; i++) {
        double s = b[i];
        for (int j = 0; j < N; j++) s -= A[i * N + j] * x[j];
        rr += s * s;
    }
    return sqrt(rr);
}

static void test_random_coupled(void)
{
    unsigned seed = 7;
    int differs = 0;
    for (int trial = 0; trial < 40; trial++) {
        double A[M * N], b[M], x[N], xt[N], best[N], r = -1;
        for (int i = 0; i < M; i++) {
            double common = urand(&seed);
            for (int j = 0; j < N; j++) A[i * N + j] = 0.6 * common + urand(&seed) - 0.3;
        }
        for (int j = 0; j < N; j++) xt[j] = urand(&seed) < 0.4 ? 0.0 : urand(&seed) * 2 - 0.5;
        for (int i = 0; i < M; i++) {
            double s = 0.2 * (urand(&seed) - 0.5);
            for (int j = 0; j < N; j++) s += A[i * N + j] * xt[j];
            b[i] = s;
        }
        lm_err e = {0};
        CHECK(lm_nnls(A, M, N, b, x, &r, &e) == LM_OK);
        CHECK_CLOSE(r, resid(A, b, x), 1e-10, 1e-10);
        double w[N], tol = 1e-9;
        for (int j = 0; j < N; j++) {
            double s = 0;
            for (int i = 0; i < M; i++) {
                double ri = b[i];
                for (int c = 0; c < N; c++) ri -= A[i * N + c] * x[c];
                s += A[i * N + j] * ri;
            }
            w[j] = s;
            CHECK(x[j] >= 0.0);
            if (x[j] > 0) CHECK_MSG(fabs(w[j]) < tol, "trial %d: w[%d] = %g at x = %g", trial, j,
                                    w[j], x[j]);
            else CHECK_MSG(w[j] < tol, "trial %d: w[%d] = %g at 0", trial, j, w[j]);
        }
        double rbest = INFINITY;
        for (unsigned mask = 0; mask < 1u << N; mask++) {
            double z[N];
            if (!ls_mask(A, b, mask, z)) continue;
            int ok = 1;
            for (int j = 0; j < N; j++) ok &= z[j] >= -1e-12;
            double rz = resid(A, b, z);
            if (ok && rz < rbest) rbest = rz, memcpy(best, z, sizeof best);
        }
        CHECK_CLOSE(r, rbest, 1e-9, 1e-9);
        for (int j = 0; j < N; j++) CHECK_CLOSE(x[j], best[j], 1e-7, 1e-6);
        double u[N]; /* clipped unconstrained: a worse residual whenever it clipped something */
        ls_mask(A, b, (1u << N) - 1, u);
        int clipped = 0;
        for (int j = 0; j < N; j++)
            if (u[j] < 0) u[j] = 0, clipped = 1;
        if (clipped && resid(A, b, u) > r * (1 + 1e-6)) differs++;
    }
    CHECK_MSG(differs >= 10, "clipping equalled NNLS in all but %d of 40 problems", differs);
}

static void test_interior_and_separable(void)
{
    double A[M * N], b[M], x[N], xt[N] = {1, 2, 3, 0.5, 0.25, 4, 1.5, 2.5};
    unsigned seed = 3;
    for (int i = 0; i < M * N; i++) A[i] = urand(&seed);
    for (int i = 0; i < M; i++) {
        b[i] = 0;
        for (int j = 0; j < N; j++) b[i] += A[i * N + j] * xt[j];
    }
    lm_err e = {0};
    CHECK(lm_nnls(A, M, N, b, x, NULL, &e) == LM_OK);
    for (int j = 0; j < N; j++) CHECK_CLOSE(x[j], xt[j], 1e-9, 1e-9);
    /* separable (one column per block of rows): x_j = max(0, a_j.b_j / a_j.a_j) */
    double S[24 * 3] = {0}, c[24];
    for (int i = 0; i < 24; i++) {
        int j = i / 8;
        S[i * 3 + j] = 1 + urand(&seed);
        c[i] = (j == 1 ? -1.0 : 1.0) * (0.5 + urand(&seed));
    }
    double y[3];
    CHECK(lm_nnls(S, 24, 3, c, y, NULL, &e) == LM_OK);
    for (int j = 0; j < 3; j++) {
        double ab = 0, aa = 0;
        for (int i = j * 8; i < j * 8 + 8; i++) ab += S[i * 3 + j] * c[i], aa += S[i * 3 + j] * S[i * 3 + j];
        CHECK_CLOSE(y[j], fmax(0.0, ab / aa), 1e-12, 1e-10);
    }
}

static void test_bad_input(void)
{
    double A[4] = {1, 0, 0, NAN}, b[2] = {1, 1}, x[2];
    lm_err e = {0};
    CHECK(lm_nnls(A, 2, 2, b, x, NULL, &e) == LM_ERR_NUMERIC);
    CHECK(lm_nnls(A, 0, 2, b, x, NULL, &e) == LM_ERR_ARG);
    CHECK(lm_nnls(NULL, 2, 2, b, x, NULL, &e) == LM_ERR_ARG);
    A[3] = 1;
    b[1] = INFINITY;
    CHECK(lm_nnls(A, 2, 2, b, x, NULL, &e) == LM_ERR_NUMERIC);
}

int main(void)
{
    RUN(test_random_coupled);
    RUN(test_interior_and_separable);
    RUN(test_bad_input);
    return check_summary();
}

/* test_linalg.c — tensor/linalg.h: Cholesky and its solves on random SPD systems (residual
 * against the original matrix), a matrix that is not positive definite refused. */
#include "tensor/linalg.h"
#include "tensor/rng.h"
#include "tests/check.h"
#include <stdlib.h>

static void test_solve(void)
{
    lm_rng r;
    lm_rng_seed(&r, 3);
    const int sizes[3] = {1, 7, 122}, m = 5;
    for (int t = 0; t < 3; t++) {
        const int n = sizes[t];
        double *G = malloc(sizeof(double) * n * n), *A = malloc(sizeof(double) * n * n);
        double *L = malloc(sizeof(double) * n * n), *B = malloc(sizeof(double) * n * m);
        double *X = malloc(sizeof(double) * n * m);
        for (int i = 0; i < n * n; i++) G[i] = lm_rng_normal(&r);
        for (int i = 0; i < n; i++) /* A = G G^T + n I */
            for (int j = 0; j < n; j++) {
                double s = i == j ? n : 0;
                for (int k = 0; k < n; k++) s += G[i * n + k] * G[j * n + k];
                A[i * n + j] = L[i * n + j] = s;
            }
        for (int i = 0; i < n * m; i++) X[i] = B[i] = lm_rng_normal(&r);
        CHECK(lm_cholesky(L, n) == 0);
        lm_cholesky_solve(L, n, X, m);
        double worst = 0;
        for (int i = 0; i < n; i++)
            for (int c = 0; c < m; c++) {
                double s = -B[i * m + c];
                for (int k = 0; k < n; k++) s += A[i * n + k] * X[k * m + c];
                worst = fmax(worst, fabs(s));
            }
        CHECK_MSG(worst < 1e-9 * n, "n %d: residual %g", n, worst);
        free(G), free(A), free(L), free(B), free(X);
    }
    double bad[4] = {1, 2, 2, 1}; /* eigenvalues 3, -1 */
    CHECK(lm_cholesky(bad, 2) == -1);
    double zero[1] = {0};
    CHECK(lm_cholesky(zero, 1) == -1);
}

int main(void)
{
    RUN(test_solve);
    return check_summary();
}

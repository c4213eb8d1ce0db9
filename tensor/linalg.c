/* linalg.c — see linalg.h. */
#include "tensor/linalg.h"
#include <math.h>

int lm_cholesky(double *A, int n)
{
    for (int j = 0; j < n; j++) {
        double d = A[(long)j * n + j];
        for (int k = 0; k < j; k++) d -= A[(long)j * n + k] * A[(long)j * n + k];
        if (!(d > 0)) return -1;
        d = sqrt(d);
        A[(long)j * n + j] = d;
        for (int i = j + 1; i < n; i++) {
            double v = A[(long)i * n + j];
            for (int k = 0; k < j; k++) v -= A[(long)i * n + k] * A[(long)j * n + k];
            A[(long)i * n + j] = v / d;
        }
    }
    return 0;
}

void lm_cholesky_solve(const double *L, int n, double *X, int m)
{
    for (int i = 0; i < n; i++) /* L z = x */
        for (int c = 0; c < m; c++) {
            double v = X[(long)i * m + c];
            for (int k = 0; k < i; k++) v -= L[(long)i * n + k] * X[(long)k * m + c];
            X[(long)i * m + c] = v / L[(long)i * n + i];
        }
    for (int i = n - 1; i >= 0; i--) /* L^T x = z */
        for (int c = 0; c < m; c++) {
            double v = X[(long)i * m + c];
            for (int k = i + 1; k < n; k++) v -= L[(long)k * n + i] * X[(long)k * m + c];
            X[(long)i * m + c] = v / L[(long)i * n + i];
        }
}

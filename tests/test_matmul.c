/* test_matmul.c — lm_matmul (2-D, batched, broadcast, all transpose combinations) and
 * lm_linear: forward and backward against plain loops written here, finite-difference
 * gradient checks, the thread-split GEMM on sizes large enough to be split, errors. */
#include "tests/check.h"
#include <stdlib.h>

/* element (i, k) of op(a) for a stored rows x cols (row-major), transposed if t */
static double opel(const float *a, int rows_op, int cols_op, int t, int i, int k)
{
    (void)rows_op;
    return t ? a[(long)k * rows_op + i] : a[(long)i * cols_op + k];
}

typedef struct mm_case { int batch, M, N, K, ta, tb, a3, b3; } mm_case;

static lm_tensor *make_operand(lm_ctx *c, lm_rng *r, int batched, int batch, int rows, int cols)
{
    int s[3] = {batch, rows, cols};
    lm_tensor *t = batched ? lm_tensor_uniform(c, 3, s, r, -1, 1)
                           : lm_tensor_uniform(c, 2, s + 1, r, -1, 1);
    lm_tensor_set_requires_grad(t, 1);
    return t;
}

/* Plain loops: y = op(a) op(b); da += dy op(b)^T, db += op(a)^T dy, in stored layout. */
static void mm_reference(const mm_case *q, const float *a, const float *b, const float *dy,
                         double *y, double *da, double *db)
{
    for (int z = 0; z < q->batch; z++) {
        const float *az = a + (q->a3 ? (long)z * q->M * q->K : 0);
        const float *bz = b + (q->b3 ? (long)z * q->K * q->N : 0);
        double *daz = da + (q->a3 ? (long)z * q->M * q->K : 0);
        double *dbz = db + (q->b3 ? (long)z * q->K * q->N : 0);
        for (int i = 0; i < q->M; i++)
            for (int j = 0; j < q->N; j++) {
                double s = 0.0, g = dy[((long)z * q->M + i) * q->N + j];
                for (int k = 0; k < q->K; k++) {
                    s += opel(az, q->M, q->K, q->ta, i, k) * opel(bz, q->K, q->N, q->tb, k, j);
                    /* stored index of op(a)[i,k] and op(b)[k,j] */
                    long ia = q->ta ? (long)k * q->M + i : (long)i * q->K + k;
                    long ib = q->tb ? (long)j * q->K + k : (long)k * q->N + j;
                    daz[ia] += g * opel(bz, q->K, q->N, q->tb, k, j);
                    dbz[ib] += g * opel(az, q->M, q->K, q->ta, i, k);
                }
                y[((long)z * q->M + i) * q->N + j] = s;
            }
    }
}

static void check_vs(const float *got, const double *want, long n, double tol, const char *what,
                     const char *where)
{
    long bad = 0, first = 0;
    for (long i = 0; i < n; i++)
        if (!(fabs(got[i] - want[i]) <= tol * (1.0 + fabs(want[i])))) {
            if (!bad) first = i;
            bad++;
        }
    CHECK_MSG(bad == 0, "%s (%s): %ld of %ld differ, [%ld] %.7g vs %.7g", what, where, bad, n,
              first, bad ? got[first] : 0.0, bad ? want[first] : 0.0);
}

static void run_case(const mm_case *q, int nthreads, double tol)
{
    lm_ctx c;
    lm_ctx_init(&c, nthreads);
    lm_rng r;
    lm_rng_seed(&r, 11);
    lm_tensor *a = make_operand(&c, &r, q->a3, q->batch, q->ta ? q->K : q->M, q->ta ? q->M : q->K);
    lm_tensor *b = make_operand(&c, &r, q->b3, q->batch, q->tb ? q->N : q->K, q->tb ? q->K : q->N);
    lm_tensor *y = lm_matmul(&c, a, b, q->ta, q->tb);
    CHECK_CTX_OK(&c);
    if (!y) {
        lm_ctx_free(&c);
        return;
    }
    CHECK(y->ndim == (q->a3 || q->b3 ? 3 : 2));
    CHECK(y->shape[y->ndim - 2] == q->M && y->shape[y->ndim - 1] == q->N);
    lm_tensor *dy = lm_tensor_uniform(&c, y->ndim, y->shape, &r, -1, 1);
    lm_tensor_fill(lm_grad(&c, a), 0.5f); /* gradients accumulate: start from 0.5 */
    lm_tensor_fill(lm_grad(&c, b), 0.5f);
    CHECK(lm_backward(&c, y, dy) == LM_OK);
    long ny = lm_tensor_numel(y), na = lm_tensor_numel(a), nb = lm_tensor_numel(b);
    double *ry = calloc((size_t)ny, sizeof(double)), *rda = calloc((size_t)na, sizeof(double));
    double *rdb = calloc((size_t)nb, sizeof(double));
    for (long i = 0; i < na; i++) rda[i] = 0.5;
    for (long i = 0; i < nb; i++) rdb[i] = 0.5;
    mm_reference(q, a->data, b->data, dy->data, ry, rda, rdb);
    char where[128];
    snprintf(where, sizeof where, "batch %d M %d N %d K %d ta %d tb %d a3 %d b3 %d", q->batch,
             q->M, q->N, q->K, q->ta, q->tb, q->a3, q->b3);
    check_vs(y->data, ry, ny, tol, "y", where);
    check_vs(a->grad->data, rda, na, tol, "da", where);
    check_vs(b->grad->data, rdb, nb, tol, "db", where);
    free(ry), free(rda), free(rdb);
    lm_ctx_free(&c);
}

static void test_matmul_all_layouts(void)
{
    /* {a3, b3}: 2-D x 2-D, batched, b broadcast, a broadcast */
    const int kinds[4][2] = {{0, 0}, {1, 1}, {1, 0}, {0, 1}};
    for (int k = 0; k < 4; k++)
        for (int ta = 0; ta < 2; ta++)
            for (int tb = 0; tb < 2; tb++) {
                int batch = kinds[k][0] || kinds[k][1] ? 3 : 1;
                mm_case q = {batch, 4, 5, 3, ta, tb, kinds[k][0], kinds[k][1]};
                run_case(&q, 2, 1e-5);
            }
}

static void test_matmul_hand_computed(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *a = lm_tensor_from(&c, 2, (int[]){2, 3}, (float[]){1, 2, 3, 4, 5, 6});
    lm_tensor *b = lm_tensor_from(&c, 2, (int[]){3, 2}, (float[]){7, 8, 9, 10, 11, 12});
    lm_tensor *y = lm_matmul(&c, a, b, 0, 0);
    float e[4] = {58, 64, 139, 154};
    CHECK(y && y->ndim == 2 && y->shape[0] == 2 && y->shape[1] == 2);
    if (y) CHECK_ARRAY_CLOSE(y->data, e, 4, 0, 0);
    lm_tensor *yt = lm_matmul(&c, a, a, 0, 1); /* a a^T */
    float e2[4] = {14, 32, 32, 77};
    if (yt) CHECK_ARRAY_CLOSE(yt->data, e2, 4, 0, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* Large enough for the GEMM to be split over threads (by columns and by rows) and for the
 * batch to be spread; 1 and 3 threads. */
static void test_matmul_split_sizes(void)
{
    mm_case qs[] = {
        {1, 70, 300, 50, 0, 0, 0, 0}, {1, 300, 20, 64, 1, 1, 0, 0}, {4, 40, 90, 45, 0, 1, 1, 1},
        {5, 33, 70, 60, 1, 0, 1, 0},  {6, 48, 64, 40, 0, 0, 1, 0},  {6, 20, 65, 50, 1, 1, 0, 1},
    };
    for (int i = 0; i < (int)(sizeof qs / sizeof qs[0]); i++) {
        run_case(&qs[i], 3, 2e-5);
        run_case(&qs[i], 1, 2e-5);
    }
}

static lm_tensor *fn_matmul(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin;
    const int *t = u;
    return lm_matmul(c, in[0], in[1], t[0], t[1]);
}

static void test_matmul_gradcheck(void)
{
    const int kinds[4][2] = {{0, 0}, {1, 1}, {1, 0}, {0, 1}};
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 3);
    lm_gradcheck_opts go;
    lm_gradcheck_default_opts(&go);
    go.atol = 1e-3;
    go.rtol = 5e-3;
    for (int k = 0; k < 4; k++)
        for (int ta = 0; ta < 2; ta++)
            for (int tb = 0; tb < 2; tb++) {
                int M = 3, N = 4, K = 5, B = 2, t[2] = {ta, tb};
                lm_tensor *in[2] = {
                    make_operand(&c, &r, kinds[k][0], B, ta ? K : M, ta ? M : K),
                    make_operand(&c, &r, kinds[k][1], B, tb ? N : K, tb ? K : N)};
                CHECK_GRAD(&c, fn_matmul, in, 2, t, &go);
                lm_ctx_reset(&c);
            }
    lm_ctx_free(&c);
}

static void test_matmul_errors(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *a = lm_tensor_zeros(&c, 2, (int[]){3, 4});
    lm_tensor *b = lm_tensor_zeros(&c, 2, (int[]){5, 6});
    CHECK(lm_matmul(&c, a, b, 0, 0) == NULL);
    CHECK(strstr(c.msg, "matmul") && strstr(c.msg, "3x4") && strstr(c.msg, "5x6"));
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_matmul(&c, a, b, 1, 1) == NULL); /* 4x3 x 6x5: K 3 vs 6 */
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_matmul(&c, a, lm_tensor_zeros(&c, 2, (int[]){6, 3}), 1, 1) != NULL); /* 4x3 x 3x6 */
    CHECK_CTX_OK(&c);
    lm_tensor *a3 = lm_tensor_zeros(&c, 3, (int[]){2, 3, 4});
    lm_tensor *b3 = lm_tensor_zeros(&c, 3, (int[]){3, 4, 2});
    CHECK(lm_matmul(&c, a3, b3, 0, 0) == NULL); /* batch 2 vs 3 */
    CHECK(strstr(c.msg, "batch") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_matmul(&c, lm_tensor_zeros(&c, 1, (int[]){4}), a, 0, 0) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_matmul(&c, lm_tensor_zeros(&c, 4, (int[]){1, 1, 3, 4}), a, 0, 1) == NULL);
    CHECK(strstr(c.msg, "matmul") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_matmul(&c, NULL, a, 0, 0) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    lm_ctx_free(&c);
}

/* ---- linear --------------------------------------------------------------------------- */
/* y = x W^T + b and its adjoints, by plain loops over R rows. */
static void linear_reference(int R, int in, int out, const float *x, const float *w,
                             const float *b, const float *dy, double *y, double *dx, double *dw,
                             double *db)
{
    for (int r = 0; r < R; r++)
        for (int o = 0; o < out; o++) {
            double s = b ? b[o] : 0.0, g = dy[(long)r * out + o];
            for (int i = 0; i < in; i++) {
                s += (double)x[(long)r * in + i] * w[(long)o * in + i];
                dx[(long)r * in + i] += g * w[(long)o * in + i];
                dw[(long)o * in + i] += g * x[(long)r * in + i];
            }
            if (db) db[o] += g;
            y[(long)r * out + o] = s;
        }
}

static void linear_case(int ndim, const int *xshape, int out, int bias, int nthreads)
{
    lm_ctx c;
    lm_ctx_init(&c, nthreads);
    lm_rng r;
    lm_rng_seed(&r, 21);
    int in = xshape[ndim - 1];
    lm_tensor *x = lm_tensor_uniform(&c, ndim, xshape, &r, -1, 1);
    lm_tensor *w = lm_tensor_uniform(&c, 2, (int[]){out, in}, &r, -1, 1);
    lm_tensor *b = bias ? lm_tensor_uniform(&c, 1, &out, &r, -1, 1) : NULL;
    lm_tensor_set_requires_grad(x, 1);
    lm_tensor_set_requires_grad(w, 1);
    if (b) lm_tensor_set_requires_grad(b, 1);
    lm_tensor *y = lm_linear(&c, x, w, b);
    CHECK_CTX_OK(&c);
    if (!y) {
        lm_ctx_free(&c);
        return;
    }
    CHECK(y->ndim == ndim && y->shape[ndim - 1] == out && (ndim == 1 || y->shape[0] == xshape[0]));
    int R = (int)(lm_tensor_numel(x) / in);
    lm_tensor *dy = lm_tensor_uniform(&c, y->ndim, y->shape, &r, -1, 1);
    lm_tensor_fill(lm_grad(&c, w), 0.25f); /* gradients accumulate */
    CHECK(lm_backward(&c, y, dy) == LM_OK);
    double *ry = calloc((size_t)R * out, sizeof(double));
    double *rdx = calloc((size_t)R * in, sizeof(double));
    double *rdw = calloc((size_t)out * in, sizeof(double));
    double *rdb = calloc((size_t)out, sizeof(double));
    for (long i = 0; i < (long)out * in; i++) rdw[i] = 0.25;
    linear_reference(R, in, out, x->data, w->data, b ? b->data : NULL, dy->data, ry, rdx, rdw,
                     b ? rdb : NULL);
    char where[64];
    snprintf(where, sizeof where, "R %d in %d out %d bias %d", R, in, out, bias);
    check_vs(y->data, ry, (long)R * out, 2e-5, "linear y", where);
    check_vs(x->grad->data, rdx, (long)R * in, 2e-5, "linear dx", where);
    check_vs(w->grad->data, rdw, (long)out * in, 1e-4, "linear dw", where);
    if (b) check_vs(b->grad->data, rdb, out, 1e-4, "linear db", where);
    free(ry), free(rdx), free(rdw), free(rdb);
    lm_ctx_free(&c);
}

static void test_linear_reference(void)
{
    linear_case(3, (int[]){2, 3, 5}, 4, 1, 2);
    linear_case(1, (int[]){7}, 3, 1, 2);
    linear_case(2, (int[]){6, 4}, 5, 0, 1);
    linear_case(2, (int[]){700, 24}, 100, 1, 3); /* split GEMMs, parallel bias sum */
    linear_case(4, (int[]){2, 9, 10, 2}, 128, 1, 2); /* MCAN's per-pixel MLP shape */
}

static lm_tensor *fn_linear(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)u;
    return lm_linear(c, in[0], in[1], nin > 2 ? in[2] : NULL);
}

static void test_linear_gradcheck(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 5);
    lm_gradcheck_opts go;
    lm_gradcheck_default_opts(&go);
    go.atol = 1e-3;
    go.rtol = 5e-3;
    for (int nin = 3; nin >= 2; nin--) { /* with and without bias */
        lm_tensor *in[3] = {lm_tensor_uniform(&c, 3, (int[]){2, 3, 4}, &r, -1, 1),
                            lm_tensor_uniform(&c, 2, (int[]){5, 4}, &r, -1, 1),
                            lm_tensor_uniform(&c, 1, (int[]){5}, &r, -1, 1)};
        for (int i = 0; i < 3; i++) lm_tensor_set_requires_grad(in[i], 1);
        CHECK_GRAD(&c, fn_linear, in, nin, NULL, &go);
        lm_ctx_reset(&c);
    }
    lm_ctx_free(&c);
}

static void test_linear_errors(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_zeros(&c, 2, (int[]){3, 4});
    lm_tensor *w = lm_tensor_zeros(&c, 2, (int[]){5, 4});
    CHECK(lm_linear(&c, x, lm_tensor_zeros(&c, 2, (int[]){5, 3}), NULL) == NULL);
    CHECK(strstr(c.msg, "linear") && strstr(c.msg, "3x4") && strstr(c.msg, "5x3"));
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_linear(&c, x, w, lm_tensor_zeros(&c, 1, (int[]){4})) == NULL);
    CHECK(strstr(c.msg, "bias") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_linear(&c, x, lm_tensor_zeros(&c, 1, (int[]){4}), NULL) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_linear(&c, x, NULL, NULL) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    lm_ctx_free(&c);
}

int main(void)
{
    RUN(test_matmul_hand_computed);
    RUN(test_matmul_all_layouts);
    RUN(test_matmul_split_sizes);
    RUN(test_matmul_gradcheck);
    RUN(test_matmul_errors);
    RUN(test_linear_reference);
    RUN(test_linear_gradcheck);
    RUN(test_linear_errors);
    return check_summary();
}

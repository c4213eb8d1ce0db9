/* test_reduce.c — sum / mean over axis masks with and without keepdim, and global average
 * pooling (reduce.c): hand values, output shapes, an independent reference for every mask of a
 * 4-D tensor, double accumulation, gradient checks, exact backward, errors and determinism. */
#include "tests/check.h"
#include <stdlib.h>

/* Reference: for every input element, add it (in double) to the output element that has its
 * indices on the kept dims. */
static void ref_reduce(const float *x, int nd, const int *shape, unsigned mask, int mean,
                       double *y, long *ny)
{
    long nx = 1, n = 1, count = 1;
    for (int i = 0; i < nd; i++) {
        nx *= shape[i];
        if (mask >> i & 1u) count *= shape[i];
        else n *= shape[i];
    }
    for (long k = 0; k < n; k++) y[k] = 0;
    for (long e = 0; e < nx; e++) {
        long r = e, out = 0, mul = 1;
        for (int i = nd - 1; i >= 0; i--) {
            long idx = r % shape[i];
            r /= shape[i];
            if (!(mask >> i & 1u)) {
                out += idx * mul;
                mul *= shape[i];
            }
        }
        y[out] += x[e];
    }
    if (mean)
        for (long k = 0; k < n; k++) y[k] /= (double)count;
    *ny = n;
}

static void test_reduce_hand_values(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_from(&c, 2, (int[]){2, 3}, (float[]){1, 2, 3, 4, 5, 6});
    lm_tensor *s0 = lm_sum(&c, x, 1u, 0);
    CHECK(s0 && s0->ndim == 1 && s0->shape[0] == 3);
    CHECK_ARRAY_CLOSE(s0->data, ((float[]){5, 7, 9}), 3, 0, 0);
    lm_tensor *s1 = lm_sum(&c, x, 2u, 1);
    CHECK(s1 && s1->ndim == 2 && s1->shape[0] == 2 && s1->shape[1] == 1);
    CHECK_ARRAY_CLOSE(s1->data, ((float[]){6, 15}), 2, 0, 0);
    lm_tensor *all = lm_sum(&c, x, 3u, 0);
    CHECK(all && all->ndim == 1 && all->shape[0] == 1 && all->data[0] == 21);
    lm_tensor *allk = lm_mean(&c, x, 3u, 1);
    CHECK(allk && allk->ndim == 2 && allk->shape[0] == 1 && allk->shape[1] == 1);
    CHECK_CLOSE(allk->data[0], 3.5, 0, 0);
    lm_tensor *m1 = lm_mean(&c, x, 2u, 0);
    CHECK_ARRAY_CLOSE(m1->data, ((float[]){2, 5}), 2, 0, 1e-7);
    /* mask 0 reduces nothing: a copy */
    lm_tensor *id = lm_sum(&c, x, 0u, 0);
    CHECK(id && lm_tensor_same_shape(id, x));
    CHECK_ARRAY_CLOSE(id->data, x->data, 6, 0, 0);
    /* global average pooling */
    lm_tensor *img = lm_tensor_from(&c, 4, (int[]){1, 2, 2, 2}, (float[]){1, 2, 3, 4, 0, 0, 0, 8});
    lm_tensor *g = lm_global_avg_pool(&c, img);
    CHECK(g && g->ndim == 4 && g->shape[0] == 1 && g->shape[1] == 2 && g->shape[2] == 1 &&
          g->shape[3] == 1);
    CHECK_ARRAY_CLOSE(g->data, ((float[]){2.5f, 2}), 2, 0, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* All 16 masks of a 4-D tensor (with a size-1 dim), sum and mean, keepdim 0 and 1. */
static void test_reduce_matches_reference(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 2);
    int shapes[2][4] = {{3, 4, 5, 70}, {2, 1, 6, 3}};
    double ref[4200];
    for (int s = 0; s < 2; s++) {
        lm_tensor *x = lm_tensor_uniform(&c, 4, shapes[s], &r, -1, 1);
        for (unsigned mask = 0; mask < 16; mask++)
            for (int mean = 0; mean < 2; mean++)
                for (int keep = 0; keep < 2; keep++) {
                    lm_tensor *y = mean ? lm_mean(&c, x, mask, keep) : lm_sum(&c, x, mask, keep);
                    long ny;
                    ref_reduce(x->data, 4, shapes[s], mask, mean, ref, &ny);
                    CHECK(y && lm_tensor_numel(y) == ny);
                    if (!y) continue;
                    int nd = 0, ok = 1;
                    for (int i = 0; i < 4; i++) {
                        int red = mask >> i & 1u;
                        if (keep || !red) ok &= y->shape[nd++] == (red ? 1 : shapes[s][i]);
                    }
                    if (nd == 0) ok &= y->shape[nd++] == 1;
                    CHECK_MSG(ok && y->ndim == nd, "shape: mask %u keep %d", mask, keep);
                    int bad = 0;
                    for (long k = 0; k < ny; k++)
                        bad += !(fabs(y->data[k] - ref[k]) <= 1e-6 + 1e-6 * fabs(ref[k]));
                    CHECK_MSG(bad == 0, "shape %d mask %u mean %d: %d off", s, mask, mean, bad);
                }
    }
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* 1e8 followed by 1000 ones: a float accumulator would stay at 1e8 (spacing 8 there). */
static void test_reduce_accumulates_in_double(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    int n = 1001;
    lm_tensor *x = lm_tensor_full(&c, 1, &n, 1.0f);
    x->data[0] = 1e8f;
    lm_tensor *s = lm_sum(&c, x, 1u, 0);
    CHECK(s && s->data[0] == 100001000.0f);
    /* same along a reduced inner run and along rows (kept inner dim) */
    lm_tensor *x2 = lm_tensor_full(&c, 2, (int[]){2, 1001}, 1.0f);
    x2->data[0] = x2->data[1001] = 1e8f;
    lm_tensor *s2 = lm_sum(&c, x2, 2u, 0);
    CHECK(s2 && s2->data[0] == 100001000.0f && s2->data[1] == 100001000.0f);
    lm_tensor *x3 = lm_tensor_full(&c, 2, (int[]){1001, 2}, 1.0f);
    x3->data[0] = x3->data[1] = 1e8f;
    lm_tensor *s3 = lm_sum(&c, x3, 1u, 0);
    CHECK(s3 && s3->data[0] == 100001000.0f && s3->data[1] == 100001000.0f);
    /* large all-reduced (chunked parallel path): 300000 x 0.1f */
    int big = 300000;
    lm_tensor *b = lm_tensor_full(&c, 1, &big, 0.1f);
    lm_tensor *sb = lm_sum(&c, b, 1u, 0);
    CHECK_CLOSE(sb->data[0], 300000.0 * (double)0.1f, 0, 1e-7);
    lm_tensor *img = lm_tensor_full(&c, 4, (int[]){1, 1, 1, 1001}, 1.0f);
    img->data[0] = 1e8f;
    lm_tensor *g = lm_global_avg_pool(&c, img);
    CHECK_CLOSE(g->data[0], 100001000.0 / 1001.0, 0, 1e-7);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

typedef struct red_case { unsigned mask; int keep, mean; } red_case;

static lm_tensor *fn_reduce(lm_ctx *c, lm_tensor *const *in, int nin, void *user)
{
    (void)nin;
    const red_case *rc = user;
    return rc->mean ? lm_mean(c, in[0], rc->mask, rc->keep) : lm_sum(c, in[0], rc->mask, rc->keep);
}

static lm_tensor *fn_gap(lm_ctx *c, lm_tensor *const *in, int nin, void *user)
{
    (void)nin, (void)user;
    return lm_global_avg_pool(c, in[0]);
}

static void test_reduce_gradcheck(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_rng r;
    lm_rng_seed(&r, 13);
    red_case cases[] = {{1u, 0, 0}, {2u, 1, 1}, {8u, 0, 0}, {5u, 1, 0}, {6u, 0, 1},
                        {10u, 0, 0}, {15u, 0, 1}, {15u, 1, 0}, {12u, 1, 1}, {9u, 0, 1}};
    for (size_t k = 0; k < sizeof cases / sizeof cases[0]; k++) {
        lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, 3, 4, 5}, &r, -1, 1);
        lm_tensor_set_requires_grad(x, 1);
        int before = check_failures_;
        CHECK_GRAD(&c, fn_reduce, &x, 1, &cases[k], NULL);
        if (check_failures_ != before) fprintf(stderr, "  mask %u\n", cases[k].mask);
        lm_ctx_reset(&c);
    }
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, 3, 4, 5}, &r, -1, 1);
    lm_tensor_set_requires_grad(x, 1);
    CHECK_GRAD(&c, fn_gap, &x, 1, NULL, NULL);
    lm_ctx_free(&c);
}

/* Backward broadcasts gy back: gx[e] = scale * gy[out(e)], exactly. */
static void test_reduce_grad_exact(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 17);
    int shape[4] = {3, 4, 5, 70};
    unsigned masks[5] = {1u, 6u, 9u, 15u, 8u};
    for (int k = 0; k < 5; k++)
        for (int mean = 0; mean < 2; mean++) {
            lm_tensor *x = lm_tensor_uniform(&c, 4, shape, &r, -1, 1);
            lm_tensor_set_requires_grad(x, 1);
            lm_tensor *y = mean ? lm_mean(&c, x, masks[k], 0) : lm_sum(&c, x, masks[k], 0);
            lm_tensor *w = lm_tensor_uniform(&c, y->ndim, y->shape, &r, -1, 1);
            CHECK(lm_backward(&c, y, w) == LM_OK);
            long count = 1, bad = 0;
            for (int i = 0; i < 4; i++) count *= masks[k] >> i & 1u ? shape[i] : 1;
            float scale = mean ? (float)(1.0 / (double)count) : 1.0f;
            for (long e = 0; e < lm_tensor_numel(x); e++) {
                long rr = e, out = 0, mul = 1;
                for (int i = 3; i >= 0; i--) {
                    long idx = rr % shape[i];
                    rr /= shape[i];
                    if (!(masks[k] >> i & 1u)) out += idx * mul, mul *= shape[i];
                }
                bad += x->grad->data[e] != w->data[out] * scale;
            }
            CHECK_MSG(bad == 0, "mask %u mean %d: %ld off", masks[k], mean, bad);
            lm_ctx_reset(&c);
        }
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, 3, 4, 5}, &r, -1, 1);
    lm_tensor_set_requires_grad(x, 1);
    lm_tensor *w = lm_tensor_uniform(&c, 4, (int[]){2, 3, 1, 1}, &r, -1, 1);
    CHECK(lm_backward(&c, lm_global_avg_pool(&c, x), w) == LM_OK);
    for (long e = 0; e < 120; e++) CHECK(x->grad->data[e] == w->data[e / 20] * (1.0f / 20));
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_reduce_errors(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_zeros(&c, 3, (int[]){2, 3, 4});
    CHECK(lm_sum(&c, x, 8u, 0) == NULL);
    CHECK_MSG(strstr(c.msg, "sum") && strstr(c.msg, "2x3x4"), "message: %s", c.msg);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_mean(&c, x, 0x100u, 1) == NULL);
    CHECK_MSG(strstr(c.msg, "mean") != NULL, "message: %s", c.msg);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_global_avg_pool(&c, x) == NULL);
    CHECK_MSG(strstr(c.msg, "global_avg_pool") && strstr(c.msg, "2x3x4"), "message: %s", c.msg);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_sum(&c, NULL, 1u, 0) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    CHECK(lm_global_avg_pool(&c, NULL) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    /* strided input is copied first */
    lm_tensor *m = lm_tensor_from(&c, 2, (int[]){2, 3}, (float[]){1, 2, 3, 4, 5, 6});
    lm_tensor *s = lm_sum(&c, lm_slice(&c, m, 1, 1, 2), 2u, 0);
    if (s) CHECK_ARRAY_CLOSE(s->data, ((float[]){5, 11}), 2, 0, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* Every parallel path (inner reduced, inner kept, all reduced, gap), forward and backward.
 * Writes the outputs and, per reduction, x's gradient; returns the number of floats. */
#define BIG_FLOATS (6L * 4 * 32 * 48 * 50)
static long run_big(int nthreads, float *out)
{
    lm_ctx c;
    lm_ctx_init(&c, nthreads);
    lm_rng r;
    lm_rng_seed(&r, 23);
    int shape[4] = {4, 32, 48, 50};
    lm_tensor *x = lm_tensor_uniform(&c, 4, shape, &r, -1, 1);
    lm_tensor_set_requires_grad(x, 1);
    lm_tensor *ys[5] = {lm_sum(&c, x, 12u, 0), lm_mean(&c, x, 5u, 1), lm_sum(&c, x, 15u, 0),
                        lm_global_avg_pool(&c, x), lm_mean(&c, x, 1u, 0)};
    long k = 0, nx = lm_tensor_numel(x);
    for (int i = 0; i < 5; i++) {
        lm_tensor *w = lm_tensor_uniform(&c, ys[i]->ndim, ys[i]->shape, &r, -1, 1);
        CHECK(lm_backward(&c, ys[i], w) == LM_OK);
        memcpy(out + k, ys[i]->data, (size_t)lm_tensor_numel(ys[i]) * sizeof(float));
        k += lm_tensor_numel(ys[i]);
        memcpy(out + k, x->grad->data, (size_t)nx * sizeof(float));
        k += nx;
        lm_tape_clear(&c); /* the next backward starts from zero gradients */
    }
    CHECK(k <= BIG_FLOATS);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
    return k;
}

static void test_reduce_determinism(void)
{
    float *a = calloc(BIG_FLOATS, sizeof(float)), *b = calloc(BIG_FLOATS, sizeof(float));
    float *one = calloc(BIG_FLOATS, sizeof(float));
    size_t n = 0;
    for (int nt = 1; nt <= 2; nt++) {
        n = (size_t)run_big(nt, a);
        CHECK((size_t)run_big(nt, b) == n);
        CHECK_MSG(memcmp(a, b, n * sizeof(float)) == 0, "nthreads %d: runs differ", nt);
        if (nt == 1) memcpy(one, a, n * sizeof(float));
    }
    CHECK_MSG(memcmp(one, a, n * sizeof(float)) == 0, "1 and 2 threads differ");
    free(a);
    free(b);
    free(one);
}

int main(void)
{
    RUN(test_reduce_hand_values);
    RUN(test_reduce_matches_reference);
    RUN(test_reduce_accumulates_in_double);
    RUN(test_reduce_gradcheck);
    RUN(test_reduce_grad_exact);
    RUN(test_reduce_errors);
    RUN(test_reduce_determinism);
    return check_summary();
}

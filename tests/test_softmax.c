/* test_softmax.c — softmax along an axis (softmax.c): hand values, an independent reference on
 * every axis of 3-D and 4-D tensors (row path and column-block path), huge logits, gradient
 * checks on axes 0, 1 and -1, the exact backward formula, errors and determinism. */
#include "tests/check.h"
#include <stdlib.h>

/* Reference: softmax over axis of a contiguous tensor, in double, plain loops. */
static void ref_softmax(const float *x, float *y, int nd, const int *shape, int axis)
{
    long outer = 1, inner = 1, len = shape[axis];
    for (int i = 0; i < axis; i++) outer *= shape[i];
    for (int i = axis + 1; i < nd; i++) inner *= shape[i];
    for (long o = 0; o < outer; o++)
        for (long j = 0; j < inner; j++) {
            const float *p = x + o * len * inner + j;
            double m = -INFINITY, s = 0;
            for (long l = 0; l < len; l++) m = p[l * inner] > m ? p[l * inner] : m;
            for (long l = 0; l < len; l++) s += exp(p[l * inner] - m);
            for (long l = 0; l < len; l++)
                y[o * len * inner + j + l * inner] = (float)(exp(p[l * inner] - m) / s);
        }
}

static void test_softmax_hand_values(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_from(&c, 2, (int[]){2, 3}, (float[]){1, 2, 3, 0, 0, 0});
    lm_tensor *y = lm_softmax(&c, x, -1);
    float e[6] = {0.09003057317038046f, 0.24472847105479767f, 0.6652409557748219f,
                  1 / 3.f, 1 / 3.f, 1 / 3.f};
    CHECK_ARRAY_CLOSE(y->data, e, 6, 1e-7, 1e-6);
    /* along axis 0: columns (1,0), (2,0), (3,0): sigmoid(1), sigmoid(2), sigmoid(3) on top */
    lm_tensor *y0 = lm_softmax(&c, x, 0);
    float e0[6] = {0.7310585786300049f, 0.8807970779778823f, 0.9525741268224334f,
                   0.2689414213699951f, 0.11920292202211769f, 0.04742587317756678f};
    CHECK_ARRAY_CLOSE(y0->data, e0, 6, 1e-7, 1e-6);
    /* logits far beyond exp's range: max-subtracted, so finite and exact */
    lm_tensor *big = lm_tensor_from(&c, 1, (int[]){3}, (float[]){1000, 1001, 1002});
    lm_tensor *yb = lm_softmax(&c, big, 0);
    CHECK_ARRAY_CLOSE(yb->data, e, 3, 1e-7, 1e-6);
    lm_tensor *neg = lm_tensor_from(&c, 1, (int[]){2}, (float[]){-1e4f, 0});
    lm_tensor *yn = lm_softmax(&c, neg, 0);
    CHECK(yn->data[0] == 0.0f && yn->data[1] == 1.0f);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* 3-D and 4-D shapes, every axis, incl. inner > 64 (two column blocks, one partial). */
static void test_softmax_matches_reference(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 4);
    int shapes[3][4] = {{3, 4, 5, 0}, {2, 3, 70, 0}, {2, 3, 4, 5}};
    int nds[3] = {3, 3, 4};
    float ref[2000];
    for (int k = 0; k < 3; k++) {
        lm_tensor *x = lm_tensor_uniform(&c, nds[k], shapes[k], &r, -5, 5);
        long n = lm_tensor_numel(x);
        for (int axis = -nds[k]; axis < nds[k]; axis++) {
            lm_tensor *y = lm_softmax(&c, x, axis);
            CHECK(y && lm_tensor_same_shape(x, y));
            if (!y) continue;
            ref_softmax(x->data, ref, nds[k], shapes[k], axis < 0 ? axis + nds[k] : axis);
            int before = check_failures_;
            CHECK_ARRAY_CLOSE(y->data, ref, n, 1e-7, 1e-5);
            if (check_failures_ != before) fprintf(stderr, "  shape %d axis %d\n", k, axis);
        }
    }
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static lm_tensor *fn_softmax(lm_ctx *c, lm_tensor *const *in, int nin, void *user)
{
    (void)nin;
    return lm_softmax(c, in[0], *(int *)user);
}

static void test_softmax_gradcheck(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_rng r;
    lm_rng_seed(&r, 6);
    lm_gradcheck_opts o;
    lm_gradcheck_default_opts(&o);
    o.eps = 1e-3;
    o.atol = 2e-4;
    o.rtol = 1e-2;
    int axes[4] = {0, 1, -1, 2};
    for (int k = 0; k < 4; k++) {
        int shape[3] = {3, 4, k == 3 ? 67 : 5}; /* last: column blocks of the middle axis */
        int axis = k == 3 ? 1 : axes[k];
        lm_tensor *x = lm_tensor_uniform(&c, 3, shape, &r, -2, 2);
        lm_tensor_set_requires_grad(x, 1);
        if (k == 3) o.max_checks = 150;
        int before = check_failures_;
        CHECK_GRAD(&c, fn_softmax, &x, 1, &axis, &o);
        if (check_failures_ != before) fprintf(stderr, "  axis %d\n", axis);
        lm_ctx_reset(&c);
    }
    lm_ctx_free(&c);
}

/* gx = y * (gy - sum(gy * y)) along the axis, checked against the formula in double. */
static void test_softmax_grad_exact(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_rng r;
    lm_rng_seed(&r, 12);
    for (int axis = 0; axis < 2; axis++) {
        lm_tensor *x = lm_tensor_uniform(&c, 2, (int[]){3, 4}, &r, -2, 2);
        lm_tensor *w = lm_tensor_uniform(&c, 2, (int[]){3, 4}, &r, -1, 1);
        lm_tensor_set_requires_grad(x, 1);
        lm_tensor *y = lm_softmax(&c, x, axis);
        CHECK(lm_backward(&c, y, w) == LM_OK);
        for (int i = 0; i < 3; i++)
            for (int j = 0; j < 4; j++) {
                double dot = 0;
                for (int l = 0; l < (axis ? 4 : 3); l++) {
                    int k = axis ? i * 4 + l : l * 4 + j;
                    dot += (double)w->data[k] * y->data[k];
                }
                int k = i * 4 + j;
                CHECK_CLOSE(x->grad->data[k], y->data[k] * (w->data[k] - dot), 1e-7, 1e-5);
            }
        lm_ctx_reset(&c);
    }
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_softmax_errors(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_zeros(&c, 3, (int[]){2, 3, 4});
    CHECK(lm_softmax(&c, x, 3) == NULL);
    CHECK_MSG(strstr(c.msg, "softmax") && strstr(c.msg, "2x3x4"), "message: %s", c.msg);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_softmax(&c, x, -4) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_softmax(&c, NULL, 0) == NULL);
    CHECK(strstr(c.msg, "softmax") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    /* a strided view is copied first */
    lm_tensor *m = lm_tensor_from(&c, 2, (int[]){2, 3}, (float[]){0, 1, 2, 3, 4, 5});
    lm_tensor *y = lm_softmax(&c, lm_slice(&c, m, 1, 1, 2), -1);
    float e = 0.2689414213699951f; /* softmax(a, a + 1)[0] */
    if (y) CHECK_ARRAY_CLOSE(y->data, ((float[]){e, 1 - e, e, 1 - e}), 4, 1e-7, 1e-6);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* Row path (last axis) and block path (middle axis) on parallel sizes: bitwise repeatable. */
static void run_big(int nthreads, float *out, long n)
{
    lm_ctx c;
    lm_ctx_init(&c, nthreads);
    lm_rng r;
    lm_rng_seed(&r, 31);
    int shape[3] = {16, 96, 100};
    lm_tensor *x = lm_tensor_uniform(&c, 3, shape, &r, -8, 8);
    lm_tensor *w = lm_tensor_uniform(&c, 3, shape, &r, -1, 1);
    lm_tensor_set_requires_grad(x, 1);
    lm_tensor *y = lm_add(&c, lm_softmax(&c, x, -1), lm_softmax(&c, x, 1));
    CHECK(lm_backward(&c, y, w) == LM_OK);
    memcpy(out, y->data, (size_t)n * sizeof(float));
    memcpy(out + n, x->grad->data, (size_t)n * sizeof(float));
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_softmax_determinism(void)
{
    long n = 16L * 96 * 100;
    float *a = malloc(2 * (size_t)n * sizeof(float)), *b = malloc(2 * (size_t)n * sizeof(float));
    float *one = malloc(2 * (size_t)n * sizeof(float));
    for (int nt = 1; nt <= 2; nt++) {
        run_big(nt, a, n);
        run_big(nt, b, n);
        CHECK_MSG(memcmp(a, b, 2 * (size_t)n * sizeof(float)) == 0, "nthreads %d differ", nt);
        if (nt == 1) memcpy(one, a, 2 * (size_t)n * sizeof(float));
    }
    CHECK_MSG(memcmp(one, a, 2 * (size_t)n * sizeof(float)) == 0, "1 and 2 threads differ");
    free(a);
    free(b);
    free(one);
}

int main(void)
{
    RUN(test_softmax_hand_values);
    RUN(test_softmax_matches_reference);
    RUN(test_softmax_gradcheck);
    RUN(test_softmax_grad_exact);
    RUN(test_softmax_errors);
    RUN(test_softmax_determinism);
    return check_summary();
}

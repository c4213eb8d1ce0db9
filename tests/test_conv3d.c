/* test_conv3d.c — lm_conv3d: hand-computed values, a plain-loop reference (gather form, double
 * accumulation) over several configs incl. the CSAM case, thread-count agreement and
 * determinism, gradient checks for x, w and bias, a non-contiguous input, and error cases. */
#include "tests/check.h"
#include <stdlib.h>

typedef struct cfg3 {
    int B, Cin, Cout, D, H, W, kd, kh, kw, pd, ph, pw, bias;
} cfg3;

static const cfg3 CONFIGS[] = {
    {2, 1, 1, 5, 6, 7, 3, 3, 3, 1, 1, 1, 1},  /* CSAM: 1 -> 1, 3x3x3, pad 1 */
    {1, 2, 3, 4, 5, 6, 2, 3, 1, 0, 1, 0, 1},  /* multi-channel, anisotropic kernel */
    {1, 1, 2, 3, 4, 5, 2, 2, 2, 2, 2, 2, 0},  /* padding larger than kernel - 1, no bias */
    {2, 3, 1, 2, 3, 9, 1, 1, 5, 0, 0, 2, 1},  /* 1x1x5 along W */
    {1, 2, 2, 3, 3, 3, 3, 3, 3, 0, 0, 0, 1},  /* valid conv to a single voxel */
    {1, 3, 2, 3, 4, 5, 3, 3, 3, 1, 1, 1, 1},  /* 81 taps per output row (> one tap batch) */
};
#define NCONFIGS ((int)(sizeof CONFIGS / sizeof CONFIGS[0]))

static int out_d(const cfg3 *k) { return k->D + 2 * k->pd - k->kd + 1; }
static int out_h(const cfg3 *k) { return k->H + 2 * k->ph - k->kh + 1; }
static int out_w(const cfg3 *k) { return k->W + 2 * k->pw - k->kw + 1; }

/* Independent reference: for each output voxel, gather with explicit bounds checks. */
static void ref_conv3d(const cfg3 *k, const float *x, const float *w, const float *bias, float *y)
{
    int Do = out_d(k), Ho = out_h(k), Wo = out_w(k);
    for (int b = 0; b < k->B; b++)
        for (int co = 0; co < k->Cout; co++)
            for (int z = 0; z < Do; z++)
                for (int r = 0; r < Ho; r++)
                    for (int q = 0; q < Wo; q++) {
                        double s = bias ? bias[co] : 0.0;
                        for (int ci = 0; ci < k->Cin; ci++)
                            for (int a = 0; a < k->kd; a++)
                                for (int e = 0; e < k->kh; e++)
                                    for (int f = 0; f < k->kw; f++) {
                                        int iz = z - k->pd + a, iy = r - k->ph + e;
                                        int ix = q - k->pw + f;
                                        if (iz < 0 || iz >= k->D || iy < 0 || iy >= k->H ||
                                            ix < 0 || ix >= k->W)
                                            continue;
                                        double xv = x[(((long)b * k->Cin + ci) * k->D + iz) *
                                                          k->H * k->W + (long)iy * k->W + ix];
                                        double wv = w[((((long)co * k->Cin + ci) * k->kd + a) *
                                                           k->kh + e) * k->kw + f];
                                        s += xv * wv;
                                    }
                        y[((((long)b * k->Cout + co) * Do + z) * Ho + r) * Wo + q] = (float)s;
                    }
}

/* in[0] = x, in[1] = w, in[2] = bias (if cfg has bias). */
static void make_inputs(lm_ctx *c, const cfg3 *k, lm_rng *r, lm_tensor **in)
{
    in[0] = lm_tensor_uniform(c, 5, (int[]){k->B, k->Cin, k->D, k->H, k->W}, r, -1, 1);
    in[1] = lm_tensor_uniform(c, 5, (int[]){k->Cout, k->Cin, k->kd, k->kh, k->kw}, r, -1, 1);
    in[2] = k->bias ? lm_tensor_uniform(c, 1, &k->Cout, r, -1, 1) : NULL;
}

static lm_tensor *fn_conv3d(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    const cfg3 *k = u;
    return lm_conv3d(c, in[0], in[1], nin > 2 ? in[2] : NULL, k->pd, k->ph, k->pw);
}

static void test_hand_values(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    /* ones (*) ones, pad 1, bias 0.5: each output counts its in-volume 3x3x3 neighbours:
     * corner 8, edge 12, face 18, centre 27 */
    lm_tensor *x = lm_tensor_full(&c, 5, (int[]){1, 1, 3, 3, 3}, 1.0f);
    lm_tensor *w = lm_tensor_full(&c, 5, (int[]){1, 1, 3, 3, 3}, 1.0f);
    lm_tensor *b = lm_tensor_full(&c, 1, (int[]){1}, 0.5f);
    lm_tensor *y = lm_conv3d(&c, x, w, b, 1, 1, 1);
    CHECK_CTX_OK(&c);
    CHECK(y && y->ndim == 5 && y->shape[2] == 3 && y->shape[3] == 3 && y->shape[4] == 3);
    if (y) {
        CHECK(y->data[0] == 8.5f);                /* corner (0,0,0) */
        CHECK(y->data[1] == 12.5f);               /* edge (0,0,1) */
        CHECK(y->data[4] == 18.5f);               /* face (0,1,1) */
        CHECK(y->data[13] == 27.5f);              /* centre (1,1,1) */
        CHECK(y->data[26] == 8.5f);               /* corner (2,2,2) */
    }
    /* 1x1x2 kernel [1, 10], no padding: y[i] = x[i] + 10 x[i+1] */
    lm_tensor *x2 = lm_tensor_from(&c, 5, (int[]){1, 1, 1, 1, 4}, (float[]){1, 2, 3, 4});
    lm_tensor *w2 = lm_tensor_from(&c, 5, (int[]){1, 1, 1, 1, 2}, (float[]){1, 10});
    lm_tensor *y2 = lm_conv3d(&c, x2, w2, NULL, 0, 0, 0);
    CHECK_CTX_OK(&c);
    CHECK(y2 && y2->shape[4] == 3);
    if (y2) CHECK_ARRAY_CLOSE(y2->data, ((float[]){21, 32, 43}), 3, 0, 0);
    lm_ctx_free(&c);
}

static void test_forward_reference(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 11);
    for (int i = 0; i < NCONFIGS; i++) {
        const cfg3 *k = &CONFIGS[i];
        lm_tensor *in[3];
        make_inputs(&c, k, &r, in);
        lm_tensor *y = lm_conv3d(&c, in[0], in[1], in[2], k->pd, k->ph, k->pw);
        CHECK_CTX_OK(&c);
        if (!y) continue;
        CHECK(y->shape[0] == k->B && y->shape[1] == k->Cout && y->shape[2] == out_d(k) &&
              y->shape[3] == out_h(k) && y->shape[4] == out_w(k));
        long n = lm_tensor_numel(y);
        float *ref = malloc((size_t)n * sizeof(float));
        ref_conv3d(k, in[0]->data, in[1]->data, in[2] ? in[2]->data : NULL, ref);
        CHECK_ARRAY_CLOSE(y->data, ref, n, 1e-5, 1e-5);
        free(ref);
        lm_ctx_reset(&c);
    }
    lm_ctx_free(&c);
}

/* The CSAM shape: B x 1 x C x 66 x 64, 3x3x3, pad 1. */
static void test_csam_shape_reference(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 12);
    cfg3 k = {2, 1, 1, 16, 66, 64, 3, 3, 3, 1, 1, 1, 1};
    lm_tensor *in[3];
    make_inputs(&c, &k, &r, in);
    lm_tensor *y = lm_conv3d(&c, in[0], in[1], in[2], 1, 1, 1);
    CHECK_CTX_OK(&c);
    if (y) {
        long n = lm_tensor_numel(y);
        float *ref = malloc((size_t)n * sizeof(float));
        ref_conv3d(&k, in[0]->data, in[1]->data, in[2]->data, ref);
        CHECK_ARRAY_CLOSE(y->data, ref, n, 1e-5, 1e-5);
        free(ref);
    }
    lm_ctx_free(&c);
}

/* Run forward + backward (seed = fixed random) with nthreads; copy y, dx, dw, db out. */
static void run_fwd_bwd(int nthreads, const cfg3 *k, float *out, long *nout)
{
    lm_ctx c;
    lm_ctx_init(&c, nthreads);
    lm_rng r;
    lm_rng_seed(&r, 21);
    lm_tensor *in[3];
    make_inputs(&c, k, &r, in);
    for (int i = 0; i < 3; i++) lm_tensor_set_requires_grad(in[i], 1);
    lm_tensor *y = lm_conv3d(&c, in[0], in[1], in[2], k->pd, k->ph, k->pw);
    lm_tensor *seed = lm_tensor_uniform(&c, y->ndim, y->shape, &r, -1, 1);
    CHECK(lm_backward(&c, y, seed) == LM_OK);
    const lm_tensor *parts[4] = {y, in[0]->grad, in[1]->grad, in[2]->grad};
    long o = 0;
    for (int i = 0; i < 4; i++) {
        long n = lm_tensor_numel(parts[i]);
        memcpy(out + o, parts[i]->data, (size_t)n * sizeof(float));
        o += n;
    }
    *nout = o;
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_threads_agree_and_deterministic(void)
{
    cfg3 k = {2, 1, 1, 9, 13, 21, 3, 3, 3, 1, 1, 1, 1};
    long ny = 2L * 9 * 13 * 21, n = 2 * ny + 27 + 1, n1, n2, n3;
    float *a = malloc((size_t)n * sizeof(float)), *b = malloc((size_t)n * sizeof(float));
    float *d = malloc((size_t)n * sizeof(float));
    run_fwd_bwd(1, &k, a, &n1);
    run_fwd_bwd(2, &k, b, &n2);
    run_fwd_bwd(2, &k, d, &n3);
    CHECK(n1 == n && n2 == n && n3 == n);
    /* y and dx are computed plane by plane: identical for any thread count */
    CHECK(memcmp(a, b, (size_t)(2 * ny) * sizeof(float)) == 0);
    /* dw, db use per-thread partial sums: close across thread counts, identical per count */
    CHECK_ARRAY_CLOSE(b + 2 * ny, a + 2 * ny, 28, 1e-4, 1e-5);
    CHECK(memcmp(b, d, (size_t)n * sizeof(float)) == 0);
    free(a), free(b), free(d);
}

/* Gradient check on fresh inputs (a new step: an old tape would add into the new grads);
 * mask bit j = input j requires grad. */
static void grad_case(lm_ctx *c, const cfg3 *k, lm_rng *r, unsigned mask,
                      const lm_gradcheck_opts *o)
{
    lm_ctx_reset(c);
    lm_tensor *in[3];
    make_inputs(c, k, r, in);
    int nin = k->bias ? 3 : 2;
    for (int j = 0; j < nin; j++) lm_tensor_set_requires_grad(in[j], (mask >> j) & 1);
    CHECK_GRAD(c, fn_conv3d, in, nin, (void *)k, o);
}

/* Backward adds into existing gradients: gradients pre-filled with 1 end at 1 + fresh. */
static void grads_with_prefill(const cfg3 *k, float prefill, float *out, long *nout)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 51);
    lm_tensor *in[3];
    make_inputs(&c, k, &r, in);
    for (int j = 0; j < 3; j++) {
        lm_tensor_set_requires_grad(in[j], 1);
        lm_tensor_fill(lm_grad(&c, in[j]), prefill);
    }
    lm_tensor *y = fn_conv3d(&c, in, 3, (void *)k);
    lm_tensor *seed = y ? lm_tensor_uniform(&c, y->ndim, y->shape, &r, -1, 1) : NULL;
    CHECK(seed && lm_backward(&c, y, seed) == LM_OK);
    long o = 0;
    for (int j = 0; j < 3 && seed; j++) {
        long n = lm_tensor_numel(in[j]);
        for (long i = 0; i < n; i++) out[o++] = in[j]->grad->data[i] - prefill;
    }
    *nout = o;
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_backward_accumulates(void)
{
    const cfg3 *k = &CONFIGS[1];
    float a[4096], b[4096];
    long na = 0, nb = 0;
    grads_with_prefill(k, 0.0f, a, &na);
    grads_with_prefill(k, 1.0f, b, &nb);
    CHECK(na == nb && na > 0 && na < 4096);
    CHECK_ARRAY_CLOSE(b, a, na, 1e-5, 1e-5);
}

static void test_gradients(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 31);
    lm_gradcheck_opts o;
    lm_gradcheck_default_opts(&o);
    o.atol = 1e-3, o.rtol = 1e-3;
    for (int i = 0; i < NCONFIGS; i++) {
        const cfg3 *k = &CONFIGS[i];
        grad_case(&c, k, &r, 7u, &o);            /* all inputs together */
        for (int j = 0; j < (k->bias ? 3 : 2); j++) /* each input alone */
            grad_case(&c, k, &r, 1u << j, &o);
    }
    /* a larger CSAM-like volume (above the threshold for threads), sampled elements */
    cfg3 big = {1, 1, 1, 12, 12, 20, 3, 3, 3, 1, 1, 1, 1};
    o.max_checks = 60;
    grad_case(&c, &big, &r, 7u, &o);
    lm_ctx_free(&c);
}

/* A strided view as input: slice along D, then conv. */
static lm_tensor *fn_sliced(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin, (void)u;
    return lm_conv3d(c, lm_slice(c, in[0], 3, 1, 4), in[1], NULL, 1, 1, 1);
}

static void test_non_contiguous_input(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 41);
    lm_tensor *x = lm_tensor_uniform(&c, 5, (int[]){1, 1, 3, 6, 5}, &r, -1, 1);
    lm_tensor *w = lm_tensor_uniform(&c, 5, (int[]){1, 1, 3, 3, 3}, &r, -1, 1);
    lm_tensor *in[2] = {x, w};
    lm_tensor *y = fn_sliced(&c, in, 2, NULL);
    CHECK_CTX_OK(&c);
    cfg3 k = {1, 1, 1, 3, 4, 5, 3, 3, 3, 1, 1, 1, 0};
    float xs[60], ref[60];
    for (int z = 0; z < 3; z++)
        for (int i = 0; i < 4; i++)
            for (int j = 0; j < 5; j++) xs[(z * 4 + i) * 5 + j] = x->data[(z * 6 + i + 1) * 5 + j];
    ref_conv3d(&k, xs, w->data, NULL, ref);
    if (y) CHECK_ARRAY_CLOSE(y->data, ref, 60, 1e-5, 1e-5);
    lm_tensor_set_requires_grad(x, 1);
    lm_tensor_set_requires_grad(w, 1);
    CHECK_GRAD(&c, fn_sliced, in, 2, NULL, NULL);
    lm_ctx_free(&c);
}

/* y must be NULL with error s and a message naming the op; reports the caller's line. */
#define expect_error(c, y, s) expect_error_((c), (y), (s), __LINE__)
static void expect_error_(lm_ctx *c, lm_tensor *y, lm_status s, int line)
{
    CHECK_MSG(y == NULL, "line %d", line);
    CHECK_MSG(strstr(c->msg, "conv3d") != NULL, "line %d: message: %s", line, c->msg);
    CHECK_MSG(c->status == s, "line %d: status %d, expected %d", line, (int)c->status, (int)s);
    lm_ctx_clear_error(c);
}

static void test_errors(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_zeros(&c, 5, (int[]){1, 2, 4, 4, 4});
    lm_tensor *w = lm_tensor_zeros(&c, 5, (int[]){3, 2, 3, 3, 3});
    lm_tensor *b = lm_tensor_zeros(&c, 1, (int[]){3});
    lm_tensor *x4 = lm_tensor_zeros(&c, 4, (int[]){2, 4, 4, 4});
    lm_tensor *w4 = lm_tensor_zeros(&c, 4, (int[]){3, 2, 3, 3});
    lm_tensor *w_cin = lm_tensor_zeros(&c, 5, (int[]){3, 1, 3, 3, 3});
    lm_tensor *b_bad = lm_tensor_zeros(&c, 1, (int[]){2});
    lm_tensor *b_2d = lm_tensor_zeros(&c, 2, (int[]){3, 1});
    lm_tensor *w_big = lm_tensor_zeros(&c, 5, (int[]){3, 2, 5, 3, 3});
    CHECK(lm_conv3d(&c, x, w, b, 1, 1, 1) != NULL);
    CHECK_CTX_OK(&c);
    expect_error(&c, lm_conv3d(&c, x4, w, b, 1, 1, 1), LM_ERR_SHAPE);
    expect_error(&c, lm_conv3d(&c, x, w4, b, 1, 1, 1), LM_ERR_SHAPE);
    expect_error(&c, lm_conv3d(&c, x, w_cin, b, 1, 1, 1), LM_ERR_SHAPE);
    expect_error(&c, lm_conv3d(&c, x, w, b_bad, 1, 1, 1), LM_ERR_SHAPE);
    expect_error(&c, lm_conv3d(&c, x, w, b_2d, 1, 1, 1), LM_ERR_SHAPE);
    expect_error(&c, lm_conv3d(&c, x, w_big, b, 0, 1, 1), LM_ERR_SHAPE); /* 5 > 4 in depth */
    CHECK(lm_conv3d(&c, x, w_big, b, 1, 1, 1) != NULL);                    /* 5 <= 4 + 2 */
    CHECK_CTX_OK(&c);
    expect_error(&c, lm_conv3d(&c, x, w, b, 1, -1, 1), LM_ERR_ARG);
    expect_error(&c, lm_conv3d(&c, NULL, w, b, 1, 1, 1), LM_ERR_ARG);
    /* sticky: after a failure, NULL in gives NULL out and the first message stays */
    lm_tensor *bad = lm_conv3d(&c, x4, w, NULL, 1, 1, 1);
    CHECK(lm_conv3d(&c, bad, w, NULL, 1, 1, 1) == NULL);
    CHECK(strstr(c.msg, "2x4x4x4") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    lm_ctx_free(&c);
}

int main(void)
{
    RUN(test_hand_values);
    RUN(test_forward_reference);
    RUN(test_csam_shape_reference);
    RUN(test_threads_agree_and_deterministic);
    RUN(test_gradients);
    RUN(test_backward_accumulates);
    RUN(test_non_contiguous_input);
    RUN(test_errors);
    return check_summary();
}

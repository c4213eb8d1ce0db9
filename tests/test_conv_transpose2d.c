/* test_conv_transpose2d.c — lm_conv_transpose2d: hand-computed values, a plain scatter-loop
 * reference over many configs (stride, padding, dilation, output padding, groups, rectangular
 * kernels, batch), the identity with the input gradient of lm_conv2d, thread-count agreement
 * and determinism, gradient checks for x, w and bias, a non-contiguous input, and errors. */
#include "tests/check.h"
#include <stdlib.h>

typedef struct cfgt {
    int B, Cin, Cout, H, W, kh, kw, sh, sw, ph, pw, dh, dw, g, oph, opw, bias;
} cfgt;

static const cfgt CONFIGS[] = {
    /*B Ci Co H  W kh kw sh sw ph pw dh dw g oph opw bias */
    {1, 4, 2, 3, 4, 2, 2, 2, 2, 0, 0, 1, 1, 1, 0, 0, 1}, /* SRNet / MST++ 2x2 stride 2 */
    {2, 3, 2, 4, 3, 3, 3, 1, 1, 1, 1, 1, 1, 1, 0, 0, 1}, /* 3x3 stride 1 pad 1 */
    {1, 2, 3, 3, 3, 3, 3, 2, 2, 1, 1, 1, 1, 1, 1, 1, 1}, /* stride 2, output_padding 1 */
    {2, 4, 6, 3, 4, 3, 3, 1, 1, 1, 1, 1, 1, 2, 0, 0, 1}, /* groups 2 */
    {1, 2, 2, 4, 4, 3, 3, 1, 1, 2, 2, 2, 2, 1, 0, 0, 0}, /* dilation 2, no bias */
    {1, 3, 2, 3, 5, 3, 2, 2, 1, 1, 0, 1, 1, 1, 1, 0, 1}, /* 3x2 kernel, stride (2,1) */
    {1, 2, 2, 3, 3, 3, 3, 1, 1, 0, 0, 2, 2, 1, 1, 1, 1}, /* output_padding < dilation */
    {3, 2, 4, 5, 4, 4, 4, 2, 2, 1, 1, 1, 1, 2, 0, 0, 1}, /* 4x4 s2 p1, groups 2, batch 3 */
    {1, 4, 4, 3, 3, 3, 3, 2, 2, 1, 1, 1, 1, 4, 1, 1, 1}, /* depthwise, stride 2 */
    {1, 1, 1, 2, 2, 1, 1, 3, 3, 0, 0, 1, 1, 1, 2, 2, 0}, /* 1x1 stride 3: gaps of zeros */
};
#define NCONFIGS ((int)(sizeof CONFIGS / sizeof CONFIGS[0]))

static int out_h(const cfgt *k)
{
    return (k->H - 1) * k->sh - 2 * k->ph + k->dh * (k->kh - 1) + k->oph + 1;
}
static int out_w(const cfgt *k)
{
    return (k->W - 1) * k->sw - 2 * k->pw + k->dw * (k->kw - 1) + k->opw + 1;
}

/* Independent reference: every input pixel scatters x * w into the output (double). */
static void ref_convt(const cfgt *k, const float *x, const float *w, const float *bias, float *y)
{
    int Ho = out_h(k), Wo = out_w(k), Cig = k->Cin / k->g, Cog = k->Cout / k->g;
    long n = (long)k->B * k->Cout * Ho * Wo;
    double *acc = calloc((size_t)n, sizeof(double));
    for (int b = 0; b < k->B; b++)
        for (int ci = 0; ci < k->Cin; ci++)
            for (int iy = 0; iy < k->H; iy++)
                for (int ix = 0; ix < k->W; ix++) {
                    double xv = x[(((long)b * k->Cin + ci) * k->H + iy) * k->W + ix];
                    for (int j = 0; j < Cog; j++)
                        for (int u = 0; u < k->kh; u++)
                            for (int v = 0; v < k->kw; v++) {
                                int oy = iy * k->sh - k->ph + u * k->dh;
                                int ox = ix * k->sw - k->pw + v * k->dw;
                                if (oy < 0 || oy >= Ho || ox < 0 || ox >= Wo) continue;
                                int co = ci / Cig * Cog + j;
                                acc[(((long)b * k->Cout + co) * Ho + oy) * Wo + ox] +=
                                    xv * w[(((long)ci * Cog + j) * k->kh + u) * k->kw + v];
                            }
                }
    for (long i = 0; i < n; i++) {
        long co = i / ((long)Ho * Wo) % k->Cout;
        y[i] = (float)(acc[i] + (bias ? bias[co] : 0.0));
    }
    free(acc);
}

static lm_conv2d_opts opts_of(const cfgt *k)
{
    lm_conv2d_opts o = {k->sh, k->sw, k->ph, k->pw, k->dh, k->dw, k->g};
    return o;
}

/* in[0] = x, in[1] = w, in[2] = bias (if cfg has bias). */
static void make_inputs(lm_ctx *c, const cfgt *k, lm_rng *r, lm_tensor **in)
{
    in[0] = lm_tensor_uniform(c, 4, (int[]){k->B, k->Cin, k->H, k->W}, r, -1, 1);
    in[1] = lm_tensor_uniform(c, 4, (int[]){k->Cin, k->Cout / k->g, k->kh, k->kw}, r, -1, 1);
    in[2] = k->bias ? lm_tensor_uniform(c, 1, &k->Cout, r, -1, 1) : NULL;
}

static lm_tensor *fn_convt(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    const cfgt *k = u;
    lm_conv2d_opts o = opts_of(k);
    return lm_conv_transpose2d(c, in[0], in[1], nin > 2 ? in[2] : NULL, &o, k->oph, k->opw);
}

static void test_hand_values(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    /* 2x2 kernel, stride 2: each input pixel stamps x * kernel into its own 2x2 block */
    lm_tensor *x = lm_tensor_from(&c, 4, (int[]){1, 1, 2, 2}, (float[]){1, 2, 3, 4});
    lm_tensor *w = lm_tensor_from(&c, 4, (int[]){1, 1, 2, 2}, (float[]){1, 10, 100, 1000});
    lm_conv2d_opts o = {2, 2, 0, 0, 1, 1, 1};
    lm_tensor *y = lm_conv_transpose2d(&c, x, w, NULL, &o, 0, 0);
    CHECK_CTX_OK(&c);
    float expect[16] = {1, 10, 2, 20, 100, 1000, 200, 2000, 3, 30, 4, 40, 300, 3000, 400, 4000};
    CHECK(y && y->shape[2] == 4 && y->shape[3] == 4);
    if (y) CHECK_ARRAY_CLOSE(y->data, expect, 16, 0, 0);
    /* stride 1, overlapping: [1 2] (*)T [1 10] = [1, 10 + 2, 20]; pad 1 crops to [12]; bias */
    lm_tensor *x2 = lm_tensor_from(&c, 4, (int[]){1, 1, 1, 2}, (float[]){1, 2});
    lm_tensor *w2 = lm_tensor_from(&c, 4, (int[]){1, 1, 1, 2}, (float[]){1, 10});
    lm_tensor *b2 = lm_tensor_from(&c, 1, (int[]){1}, (float[]){0.5f});
    lm_tensor *y2 = lm_conv_transpose2d(&c, x2, w2, NULL, NULL, 0, 0);
    CHECK(y2 && y2->shape[3] == 3);
    if (y2) CHECK_ARRAY_CLOSE(y2->data, ((float[]){1, 12, 20}), 3, 0, 0);
    lm_conv2d_opts o3 = {1, 1, 0, 1, 1, 1, 1};
    lm_tensor *y3 = lm_conv_transpose2d(&c, x2, w2, b2, &o3, 0, 0);
    CHECK(y3 && y3->shape[3] == 1 && y3->data[0] == 12.5f);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_forward_reference(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 5);
    for (int i = 0; i < NCONFIGS; i++) {
        const cfgt *k = &CONFIGS[i];
        lm_tensor *in[3];
        make_inputs(&c, k, &r, in);
        lm_tensor *y = fn_convt(&c, in, k->bias ? 3 : 2, (void *)k);
        CHECK_CTX_OK(&c);
        if (!y) continue;
        CHECK_MSG(y->shape[0] == k->B && y->shape[1] == k->Cout && y->shape[2] == out_h(k) &&
                  y->shape[3] == out_w(k), "config %d", i);
        long n = lm_tensor_numel(y);
        float *ref = malloc((size_t)n * sizeof(float));
        ref_convt(k, in[0]->data, in[1]->data, in[2] ? in[2]->data : NULL, ref);
        CHECK_ARRAY_CLOSE(y->data, ref, n, 1e-5, 1e-5);
        free(ref);
        lm_ctx_reset(&c);
    }
    lm_ctx_free(&c);
}

/* conv_transpose2d(x, w) is the gradient of conv2d(z, w) w.r.t. z, seeded with x. Only where
 * conv2d maps the Ho x Wo output back to H x W (output_padding < stride). */
static void test_adjoint_of_conv2d(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 6);
    int tested = 0;
    for (int i = 0; i < NCONFIGS; i++) {
        const cfgt *k = &CONFIGS[i];
        if (k->oph >= k->sh || k->opw >= k->sw) continue;
        lm_tensor *in[3];
        make_inputs(&c, k, &r, in);
        lm_tensor *y = fn_convt(&c, in, 2, (void *)k); /* no bias */
        lm_tensor *z = lm_tensor_uniform(&c, 4, (int[]){k->B, k->Cout, out_h(k), out_w(k)}, &r,
                                         -1, 1);
        lm_tensor_set_requires_grad(z, 1);
        lm_conv2d_opts o = opts_of(k);
        lm_tensor *zc = lm_conv2d(&c, z, in[1], NULL, &o);
        CHECK_MSG(zc && lm_tensor_same_shape(zc, in[0]), "config %d", i);
        if (zc && y && lm_tensor_same_shape(zc, in[0]) && lm_backward(&c, zc, in[0]) == LM_OK) {
            CHECK_ARRAY_CLOSE(z->grad->data, y->data, lm_tensor_numel(y), 1e-5, 1e-5);
            tested++;
        }
        CHECK_CTX_OK(&c);
        lm_ctx_reset(&c);
    }
    CHECK(tested == NCONFIGS - 1);
    lm_ctx_free(&c);
}

/* Forward + backward with nthreads; copies y, dx, dw, db into out. */
static long run_fwd_bwd(int nthreads, const cfgt *k, float *out)
{
    lm_ctx c;
    lm_ctx_init(&c, nthreads);
    lm_rng r;
    lm_rng_seed(&r, 7);
    lm_tensor *in[3];
    make_inputs(&c, k, &r, in);
    for (int i = 0; i < 3; i++) lm_tensor_set_requires_grad(in[i], 1);
    lm_tensor *y = fn_convt(&c, in, 3, (void *)k);
    lm_tensor *seed = lm_tensor_uniform(&c, 4, y->shape, &r, -1, 1);
    CHECK(lm_backward(&c, y, seed) == LM_OK);
    const lm_tensor *parts[4] = {y, in[0]->grad, in[1]->grad, in[2]->grad};
    long o = 0;
    for (int i = 0; i < 4; i++) {
        memcpy(out + o, parts[i]->data, (size_t)lm_tensor_numel(parts[i]) * sizeof(float));
        o += lm_tensor_numel(parts[i]);
    }
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
    return o;
}

static void test_threads_agree_and_deterministic(void)
{
    /* SRNet-like upsampling, big enough that both threads get columns and rows */
    cfgt k = {2, 16, 8, 17, 21, 2, 2, 2, 2, 0, 0, 1, 1, 1, 0, 0, 1};
    long n = 2L * 8 * 34 * 42 + 2L * 16 * 17 * 21 + 16 * 8 * 4 + 8;
    float *a = malloc((size_t)n * sizeof(float)), *b = malloc((size_t)n * sizeof(float));
    float *d = malloc((size_t)n * sizeof(float));
    CHECK(run_fwd_bwd(1, &k, a) == n);
    CHECK(run_fwd_bwd(2, &k, b) == n);
    CHECK(run_fwd_bwd(2, &k, d) == n);
    CHECK_ARRAY_CLOSE(b, a, n, 1e-5, 1e-5);
    CHECK(memcmp(b, d, (size_t)n * sizeof(float)) == 0);
    free(a), free(b), free(d);
}

/* Gradient check on fresh inputs (a new step: an old tape would add into the new grads);
 * mask bit j = input j requires grad. */
static void grad_case(lm_ctx *c, const cfgt *k, lm_rng *r, unsigned mask,
                      const lm_gradcheck_opts *o)
{
    lm_ctx_reset(c);
    lm_tensor *in[3];
    make_inputs(c, k, r, in);
    int nin = k->bias ? 3 : 2;
    for (int j = 0; j < nin; j++) lm_tensor_set_requires_grad(in[j], (mask >> j) & 1);
    CHECK_GRAD(c, fn_convt, in, nin, (void *)k, o);
}

/* Backward adds into existing gradients: gradients pre-filled with 1 end at 1 + fresh. */
static void grads_with_prefill(const cfgt *k, float prefill, float *out, long *nout)
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
    lm_tensor *y = fn_convt(&c, in, 3, (void *)k);
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
    const cfgt *k = &CONFIGS[7];
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
    lm_rng_seed(&r, 8);
    lm_gradcheck_opts o;
    lm_gradcheck_default_opts(&o);
    o.atol = 1e-3, o.rtol = 1e-3;
    for (int i = 0; i < NCONFIGS; i++) {
        const cfgt *k = &CONFIGS[i];
        grad_case(&c, k, &r, 7u, &o);            /* all inputs together */
        for (int j = 0; j < (k->bias ? 3 : 2); j++) /* each input alone */
            grad_case(&c, k, &r, 1u << j, &o);
    }
    /* large enough for the threaded path; sampled elements */
    cfgt big = {2, 16, 16, 8, 8, 3, 3, 2, 2, 1, 1, 1, 1, 2, 1, 1, 1};
    o.max_checks = 40;
    grad_case(&c, &big, &r, 7u, &o);
    lm_ctx_free(&c);
}

/* Strided view as input: a slice along W. */
static lm_tensor *fn_sliced(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin;
    const cfgt *k = u;
    lm_conv2d_opts o = opts_of(k);
    return lm_conv_transpose2d(c, lm_slice(c, in[0], 3, 1, k->W), in[1], in[2], &o, k->oph,
                               k->opw);
}

static void test_non_contiguous_input(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 9);
    const cfgt *k = &CONFIGS[2];
    lm_tensor *in[3];
    make_inputs(&c, k, &r, in);
    in[0] = lm_tensor_uniform(&c, 4, (int[]){k->B, k->Cin, k->H, k->W + 2}, &r, -1, 1);
    lm_tensor *y = fn_sliced(&c, in, 3, (void *)k);
    CHECK_CTX_OK(&c);
    long nx = (long)k->B * k->Cin * k->H * k->W, ny = (long)k->B * k->Cout * out_h(k) * out_w(k);
    float *xs = malloc((size_t)nx * sizeof(float)), *ref = malloc((size_t)ny * sizeof(float));
    for (long i = 0; i < nx; i++) xs[i] = in[0]->data[i / k->W * (k->W + 2) + 1 + i % k->W];
    ref_convt(k, xs, in[1]->data, in[2]->data, ref);
    if (y) CHECK_ARRAY_CLOSE(y->data, ref, ny, 1e-5, 1e-5);
    for (int j = 0; j < 3; j++) lm_tensor_set_requires_grad(in[j], 1);
    CHECK_GRAD(&c, fn_sliced, in, 3, (void *)k, NULL);
    free(xs), free(ref);
    lm_ctx_free(&c);
}

/* y must be NULL with error s and a message naming the op; reports the caller's line. */
#define expect_error(c, y, s) expect_error_((c), (y), (s), __LINE__)
static void expect_error_(lm_ctx *c, lm_tensor *y, lm_status s, int line)
{
    CHECK_MSG(y == NULL, "line %d", line);
    CHECK_MSG(strstr(c->msg, "conv_transpose2d") != NULL, "line %d: message: %s", line, c->msg);
    CHECK_MSG(c->status == s, "line %d: status %d, expected %d", line, (int)c->status, (int)s);
    lm_ctx_clear_error(c);
}

static void test_errors(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_zeros(&c, 4, (int[]){1, 4, 3, 3});
    lm_tensor *w = lm_tensor_zeros(&c, 4, (int[]){4, 3, 3, 3});
    lm_tensor *b = lm_tensor_zeros(&c, 1, (int[]){3});
    lm_tensor *x3 = lm_tensor_zeros(&c, 3, (int[]){4, 3, 3});
    lm_tensor *w_cin = lm_tensor_zeros(&c, 4, (int[]){3, 3, 3, 3});
    lm_tensor *x_odd = lm_tensor_zeros(&c, 4, (int[]){1, 3, 3, 3});
    lm_tensor *b_bad = lm_tensor_zeros(&c, 1, (int[]){4});
    lm_tensor *w1 = lm_tensor_zeros(&c, 4, (int[]){4, 3, 1, 1});
    lm_conv2d_opts s2 = {2, 2, 1, 1, 1, 1, 1}, g2 = {1, 1, 0, 0, 1, 1, 2};
    lm_conv2d_opts neg_s = {-1, 1, 0, 0, 1, 1, 1}, neg_p = {1, 1, -1, 0, 1, 1, 1};
    lm_conv2d_opts pad1 = {1, 1, 1, 1, 1, 1, 1};
    CHECK(lm_conv_transpose2d(&c, x, w, b, &s2, 1, 1) != NULL);
    CHECK_CTX_OK(&c);
    expect_error(&c, lm_conv_transpose2d(&c, x3, w, b, NULL, 0, 0), LM_ERR_SHAPE);
    expect_error(&c, lm_conv_transpose2d(&c, x, w_cin, NULL, NULL, 0, 0), LM_ERR_SHAPE);
    expect_error(&c, lm_conv_transpose2d(&c, x_odd, w_cin, NULL, &g2, 0, 0), LM_ERR_SHAPE);
    expect_error(&c, lm_conv_transpose2d(&c, x, w, b_bad, NULL, 0, 0), LM_ERR_SHAPE);
    expect_error(&c, lm_conv_transpose2d(&c, x, w, b, &s2, 2, 0), LM_ERR_ARG);
    expect_error(&c, lm_conv_transpose2d(&c, x, w, b, NULL, 0, 1), LM_ERR_ARG);
    expect_error(&c, lm_conv_transpose2d(&c, x, w, b, &s2, -1, 0), LM_ERR_ARG);
    expect_error(&c, lm_conv_transpose2d(&c, x, w, b, &neg_s, 0, 0), LM_ERR_ARG);
    expect_error(&c, lm_conv_transpose2d(&c, x, w, b, &neg_p, 0, 0), LM_ERR_ARG);
    /* 1x1 kernel, pad 1 on 3x3: output (3 - 1) - 2 + 0 + 1 = 1 is fine; on 1x1 it is empty */
    CHECK(lm_conv_transpose2d(&c, x, w1, NULL, &pad1, 0, 0) != NULL);
    lm_tensor *x11 = lm_tensor_zeros(&c, 4, (int[]){1, 4, 1, 1});
    expect_error(&c, lm_conv_transpose2d(&c, x11, w1, NULL, &pad1, 0, 0), LM_ERR_SHAPE);
    expect_error(&c, lm_conv_transpose2d(&c, x, NULL, NULL, NULL, 0, 0), LM_ERR_ARG);
    /* sticky: a failed op's NULL flows through and the first message stays */
    lm_tensor *bad = lm_conv_transpose2d(&c, x3, w, NULL, NULL, 0, 0);
    CHECK(lm_conv_transpose2d(&c, bad, w, NULL, NULL, 0, 0) == NULL);
    CHECK(strstr(c.msg, "4x3x3") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    lm_ctx_free(&c);
}

int main(void)
{
    RUN(test_hand_values);
    RUN(test_forward_reference);
    RUN(test_adjoint_of_conv2d);
    RUN(test_threads_agree_and_deterministic);
    RUN(test_gradients);
    RUN(test_backward_accumulates);
    RUN(test_non_contiguous_input);
    RUN(test_errors);
    return check_summary();
}

/* test_conv2d_depthwise.c — the stride-1 stencil forward of the depthwise conv path
 * (conv2d_depthwise.c) against its reference (the per-tap loops, lm_op_set_path) and against
 * the whole-image im2col reference of conv2d.c (lm_conv2d_set_path): kernel sizes, padding,
 * channel multipliers, widths that are not a multiple of the vector length, bias or not,
 * 1 and 2 threads; strided depthwise convs still take the per-tap loops. */
#include "tensor/ops/gemm_internal.h"
#include "tensor/ops/op_paths.h"
#include "tests/check.h"
#include <stdlib.h>

typedef struct dw_case {
    int B, C, mult, H, W, kh, kw, stride, ph, pw, bias;
    const char *what;
} dw_case;

static const dw_case CASES[] = {
    {2, 32, 1, 40, 32, 3, 3, 1, 1, 1, 1, "3x3 pad 1, the SRNet shape"},
    {1, 5, 1, 5, 4, 3, 3, 1, 1, 1, 1, "width 4 < one vector"},
    {2, 3, 1, 9, 37, 3, 3, 1, 1, 1, 0, "width 37, no bias"},
    {1, 4, 2, 11, 13, 5, 5, 1, 2, 2, 1, "5x5 pad 2, multiplier 2"},
    {1, 3, 3, 7, 19, 3, 2, 1, 1, 0, 1, "3x2 pad (1, 0), multiplier 3"},
    {2, 6, 1, 8, 17, 3, 3, 1, 0, 0, 1, "3x3 unpadded"},
    {1, 4, 1, 6, 9, 1, 1, 1, 0, 0, 1, "1x1"},
    {1, 4, 1, 10, 12, 3, 3, 2, 1, 1, 1, "stride 2 (per-tap loops)"},
};

/* y = depthwise conv of the case on (x, w, b) with the given paths and threads. */
static void run_case(const dw_case *k, int op_path, int conv_path, int threads, const float *xv,
                     const float *wv, const float *bv, float *out, long *n_out)
{
    lm_ctx c;
    lm_ctx_init(&c, threads);
    int Co = k->C * k->mult;
    lm_tensor *x = lm_tensor_from(&c, 4, (int[]){k->B, k->C, k->H, k->W}, xv);
    lm_tensor *w = lm_tensor_from(&c, 4, (int[]){Co, 1, k->kh, k->kw}, wv);
    lm_tensor *b = k->bias ? lm_tensor_from(&c, 1, (int[]){Co}, bv) : NULL;
    lm_conv2d_opts o = {k->stride, k->stride, k->ph, k->pw, 1, 1, k->C};
    int old_op = lm_op_set_path(&c, op_path), old_conv = lm_conv2d_set_path(&c, conv_path);
    lm_tensor *y = lm_conv2d(&c, x, w, b, &o);
    lm_op_set_path(&c, old_op);
    lm_conv2d_set_path(&c, old_conv);
    CHECK_CTX_OK(&c);
    *n_out = y ? lm_tensor_numel(y) : 0;
    if (y) memcpy(out, y->data, sizeof(float) * (size_t)*n_out);
    lm_ctx_free(&c);
}

static void test_stencil_matches_references(void)
{
    lm_rng r;
    lm_rng_seed(&r, 31);
    for (size_t i = 0; i < sizeof CASES / sizeof CASES[0]; i++) {
        const dw_case *k = &CASES[i];
        int Co = k->C * k->mult;
        long nx = (long)k->B * k->C * k->H * k->W, nw = (long)Co * k->kh * k->kw;
        long ny = (long)k->B * Co * (k->H + 2 * k->ph) * (k->W + 2 * k->pw); /* upper bound */
        float *xv = malloc(sizeof(float) * nx), *wv = malloc(sizeof(float) * nw);
        float *bv = malloc(sizeof(float) * Co), *y[4];
        lm_rng_fill_uniform(&r, xv, nx, -1.0f, 1.0f);
        lm_rng_fill_uniform(&r, wv, nw, -1.0f, 1.0f);
        lm_rng_fill_uniform(&r, bv, Co, -1.0f, 1.0f);
        long n[4];
        for (int v = 0; v < 4; v++) y[v] = malloc(sizeof(float) * ny);
        run_case(k, LM_OP_PATH_FAST, LM_CONV_PATH_AUTO, 1, xv, wv, bv, y[0], &n[0]);
        run_case(k, LM_OP_PATH_FAST, LM_CONV_PATH_AUTO, 2, xv, wv, bv, y[1], &n[1]);
        run_case(k, LM_OP_PATH_REFERENCE, LM_CONV_PATH_AUTO, 1, xv, wv, bv, y[2], &n[2]);
        run_case(k, LM_OP_PATH_FAST, LM_CONV_PATH_SIMPLE, 1, xv, wv, bv, y[3], &n[3]);
        CHECK_MSG(n[0] > 0 && n[0] == n[1] && n[0] == n[2] && n[0] == n[3], "%s", k->what);
        if (n[0] > 0 && n[0] == n[1] && n[0] == n[2] && n[0] == n[3]) {
            /* same order of summation as the per-tap loops: identical where multiply-adds
             * are fused (-march=native), within rounding otherwise; any thread count */
            CHECK_ARRAY_CLOSE(y[0], y[2], n[0], 1e-6, 1e-6);
            CHECK_ARRAY_CLOSE(y[1], y[0], n[0], 0, 0);
            CHECK_ARRAY_CLOSE(y[0], y[3], n[0], 1e-5, 1e-5);
        }
        for (int v = 0; v < 4; v++) free(y[v]);
        free(xv), free(wv), free(bv);
    }
}

/* Gradients through the fast forward: the backward paths are unchanged, so only the forward
 * values matter; checked on one small case with finite differences. */
static lm_tensor *fn_dw(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin, (void)u;
    lm_conv2d_opts o = {1, 1, 1, 1, 1, 1, 3};
    return lm_conv2d(c, in[0], in[1], in[2], &o);
}

static void test_stencil_gradcheck(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 32);
    lm_tensor *in[3] = {lm_tensor_uniform(&c, 4, (int[]){2, 3, 5, 11}, &r, -1, 1),
                        lm_tensor_uniform(&c, 4, (int[]){3, 1, 3, 3}, &r, -1, 1),
                        lm_tensor_uniform(&c, 1, (int[]){3}, &r, -1, 1)};
    for (int i = 0; i < 3; i++) lm_tensor_set_requires_grad(in[i], 1);
    lm_gradcheck_opts o;
    lm_gradcheck_default_opts(&o);
    lm_gradcheck_result res;
    CHECK(lm_gradcheck(&c, fn_dw, in, 3, NULL, &o, &res) == LM_OK);
    CHECK_MSG(res.failed == 0, "%ld failed, max rel err %g", res.failed, res.max_rel_err);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

int main(void)
{
    RUN(test_stencil_matches_references);
    RUN(test_stencil_gradcheck);
    return check_summary();
}

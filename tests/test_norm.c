/* test_norm.c — layer_norm_channels and l2_normalize: independent double-precision references,
 * hand values, gradient checks for every differentiable input (l2 on both sides of the eps
 * clamp), exact w/b gradients, thread-count independence, strided inputs and error cases. */
#include "tensor/ops/op_paths.h"
#include "tests/check.h"
#include <stdlib.h>

/* ---- layer_norm_channels ---------------------------------------------------------------- */
static void ref_layer_norm(const lm_tensor *x, const float *w, const float *b, float eps,
                           float *out)
{
    int B = x->shape[0], C = x->shape[1], HW = x->shape[2] * x->shape[3];
    for (int n = 0; n < B; n++)
        for (int p = 0; p < HW; p++) {
            double m = 0, v = 0;
            for (int ch = 0; ch < C; ch++) m += x->data[(n * C + ch) * HW + p];
            m /= C;
            for (int ch = 0; ch < C; ch++) {
                double d = x->data[(n * C + ch) * HW + p] - m;
                v += d * d;
            }
            v /= C;
            for (int ch = 0; ch < C; ch++) {
                double xh = (x->data[(n * C + ch) * HW + p] - m) / sqrt(v + eps);
                out[(n * C + ch) * HW + p] = (float)(xh * (w ? w[ch] : 1) + (b ? b[ch] : 0));
            }
        }
}

static void test_layer_norm_reference(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 71);
    /* 7 x 11 = 77 pixels: more than one 64-pixel block, the last one partial */
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, 5, 7, 11}, &r, -2, 3);
    lm_tensor *w = lm_tensor_uniform(&c, 1, (int[]){5}, &r, 0.5f, 1.5f);
    lm_tensor *b = lm_tensor_uniform(&c, 1, (int[]){5}, &r, -1, 1);
    float e[2 * 5 * 77];
    lm_tensor *y = lm_layer_norm_channels(&c, x, w, b, 1e-5f);
    ref_layer_norm(x, w->data, b->data, 1e-5f, e);
    if (y) CHECK_ARRAY_CLOSE(y->data, e, 770, 1e-5, 1e-5);
    lm_tensor *y0 = lm_layer_norm_channels(&c, x, NULL, NULL, 0.1f);
    ref_layer_norm(x, NULL, NULL, 0.1f, e);
    if (y0) CHECK_ARRAY_CLOSE(y0->data, e, 770, 1e-5, 1e-5);
    lm_tensor *yb = lm_layer_norm_channels(&c, x, NULL, b, 1e-5f); /* bias only */
    ref_layer_norm(x, NULL, b->data, 1e-5f, e);
    if (yb) CHECK_ARRAY_CLOSE(yb->data, e, 770, 1e-5, 1e-5);
    /* hand values: channels {1, 3} at one pixel: mean 2, var 1 -> {-1, 1} / sqrt(1 + eps) */
    lm_tensor *h = lm_tensor_from(&c, 4, (int[]){1, 2, 1, 1}, (float[]){1, 3});
    lm_tensor *hy = lm_layer_norm_channels(&c, h, NULL, NULL, 0.0f);
    if (hy) CHECK_ARRAY_CLOSE(hy->data, ((float[]){-1, 1}), 2, 1e-7, 0);
    /* strided input (a channel slice) */
    lm_tensor *s = lm_slice(&c, x, 1, 1, 3);
    lm_tensor *ys = lm_layer_norm_channels(&c, s, NULL, NULL, 1e-5f);
    ref_layer_norm(lm_contiguous(&c, s), NULL, NULL, 1e-5f, e);
    if (ys) CHECK_ARRAY_CLOSE(ys->data, e, 2 * 3 * 77, 1e-5, 1e-5);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static lm_tensor *fn_ln(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)u;
    lm_tensor *y = lm_layer_norm_channels(c, in[0], nin > 1 ? in[1] : NULL,
                                          nin > 2 ? in[2] : NULL, 1e-5f);
    return check_with_input(c, y, in[0]);
}

/* w and b used by two layer norms in a chain: their gradients must add up. */
static lm_tensor *fn_ln_chain(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin, (void)u;
    lm_tensor *y1 = lm_layer_norm_channels(c, in[0], in[1], in[2], 1e-5f);
    return check_with_input(c, lm_layer_norm_channels(c, y1, in[1], in[2], 1e-5f), y1);
}

static void test_layer_norm_gradients(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 72);
    lm_tensor *in[3];
    in[0] = lm_tensor_uniform(&c, 4, (int[]){2, 4, 3, 5}, &r, -1, 1);
    in[1] = lm_tensor_uniform(&c, 1, (int[]){4}, &r, 0.5f, 1.5f);
    in[2] = lm_tensor_uniform(&c, 1, (int[]){4}, &r, -1, 1);
    for (int i = 0; i < 3; i++) lm_tensor_set_requires_grad(in[i], 1);
    lm_gradcheck_opts o;
    lm_gradcheck_default_opts(&o);
    o.eps = 1e-3;
    CHECK_GRAD(&c, fn_ln, in, 3, NULL, &o);
    CHECK_GRAD(&c, fn_ln, in, 1, NULL, &o); /* no affine */
    CHECK_GRAD(&c, fn_ln_chain, in, 3, NULL, &o);
    lm_tensor_set_requires_grad(in[0], 0);  /* only w and b */
    CHECK_GRAD(&c, fn_ln, in, 3, NULL, &o);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* Exact: with seed g, db = sum g, dw = sum g xhat (reference in double); and the gradients
 * are bitwise the same with 1 and 2 threads. */
static void test_layer_norm_wb_exact_and_threads(void)
{
    const int B = 2, C = 3, H = 9, W = 10, HW = H * W;
    float g1[2 * 3 * 90 + 6];
    for (int nt = 1; nt <= 2; nt++) {
        lm_ctx c;
        lm_ctx_init(&c, nt);
        lm_rng r;
        lm_rng_seed(&r, 73);
        lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){B, C, H, W}, &r, -1, 1);
        lm_tensor *w = lm_tensor_uniform(&c, 1, (int[]){C}, &r, 0.5f, 1.5f);
        lm_tensor *b = lm_tensor_zeros(&c, 1, (int[]){C});
        lm_tensor_set_requires_grad(x, 1);
        lm_tensor_set_requires_grad(w, 1);
        lm_tensor_set_requires_grad(b, 1);
        lm_tensor *y = lm_layer_norm_channels(&c, x, w, b, 1e-5f);
        lm_tensor *g = lm_tensor_uniform(&c, 4, y->shape, &r, -1, 1);
        CHECK(lm_backward(&c, y, g) == LM_OK);
        float xh[2 * 3 * 90];
        ref_layer_norm(x, NULL, NULL, 1e-5f, xh);
        for (int ch = 0; ch < C; ch++) {
            double sw = 0, sb = 0;
            for (int n = 0; n < B; n++)
                for (int p = 0; p < HW; p++) {
                    sw += (double)g->data[(n * C + ch) * HW + p] * xh[(n * C + ch) * HW + p];
                    sb += g->data[(n * C + ch) * HW + p];
                }
            CHECK_CLOSE(w->grad->data[ch], sw, 1e-4, 1e-4);
            CHECK_CLOSE(b->grad->data[ch], sb, 1e-5, 1e-5);
        }
        if (nt == 1) {
            memcpy(g1, x->grad->data, sizeof(float) * B * C * HW);
            memcpy(g1 + B * C * HW, w->grad->data, sizeof(float) * C);
            memcpy(g1 + B * C * HW + C, b->grad->data, sizeof(float) * C);
        } else {
            CHECK(memcmp(g1, x->grad->data, sizeof(float) * B * C * HW) == 0);
            CHECK(memcmp(g1 + B * C * HW, w->grad->data, sizeof(float) * C) == 0);
            CHECK(memcmp(g1 + B * C * HW + C, b->grad->data, sizeof(float) * C) == 0);
        }
        lm_ctx_free(&c);
    }
}

static void test_layer_norm_errors(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_zeros(&c, 4, (int[]){1, 3, 2, 2});
    lm_tensor *w4 = lm_tensor_zeros(&c, 1, (int[]){4});
    lm_tensor *w2d = lm_tensor_zeros(&c, 2, (int[]){1, 3});
    CHECK(lm_layer_norm_channels(&c, x, w4, NULL, 1e-5f) == NULL);
    CHECK(strstr(c.msg, "layer_norm_channels") && strstr(c.msg, "1x3x2x2"));
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_layer_norm_channels(&c, x, NULL, w2d, 1e-5f) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    lm_tensor *x3 = lm_tensor_zeros(&c, 3, (int[]){3, 2, 2});
    CHECK(lm_layer_norm_channels(&c, x3, NULL, NULL, 1e-5f) == NULL);
    CHECK(strstr(c.msg, "layer_norm_channels") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_layer_norm_channels(&c, x, NULL, NULL, -1.0f) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    CHECK(lm_layer_norm_channels(&c, x, NULL, NULL, NAN) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    CHECK(lm_layer_norm_channels(&c, NULL, NULL, NULL, 1e-5f) == NULL);
    CHECK(strstr(c.msg, "layer_norm_channels") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    lm_ctx_free(&c);
}

/* ---- l2_normalize ----------------------------------------------------------------------- */
static void ref_l2(const lm_tensor *x, int axis, float eps, float *out)
{
    long outer = 1, inner = 1, len = x->shape[axis];
    for (int d = 0; d < axis; d++) outer *= x->shape[d];
    for (int d = axis + 1; d < x->ndim; d++) inner *= x->shape[d];
    for (long o = 0; o < outer; o++)
        for (long i = 0; i < inner; i++) {
            double s = 0;
            for (long a = 0; a < len; a++) {
                double v = x->data[(o * len + a) * inner + i];
                s += v * v;
            }
            double d = sqrt(s) > eps ? sqrt(s) : eps;
            for (long a = 0; a < len; a++)
                out[(o * len + a) * inner + i] = (float)(x->data[(o * len + a) * inner + i] / d);
        }
}

static void test_l2_reference(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 74);
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, 3, 5, 30}, &r, -1, 1);
    float *e = malloc(sizeof(float) * 900);
    for (int axis = -4; axis < 4; axis++) {
        lm_tensor *y = lm_l2_normalize(&c, x, axis, 1e-12f);
        ref_l2(x, axis < 0 ? axis + 4 : axis, 1e-12f, e);
        if (y) CHECK_ARRAY_CLOSE(y->data, e, 900, 1e-6, 1e-5);
    }
    /* hand values: (3, 4) -> (0.6, 0.8); below eps = 10: (3, 4) / 10 */
    lm_tensor *h = lm_tensor_from(&c, 2, (int[]){1, 2}, (float[]){3, 4});
    lm_tensor *hy = lm_l2_normalize(&c, h, 1, 1e-12f);
    if (hy) CHECK_ARRAY_CLOSE(hy->data, ((float[]){0.6f, 0.8f}), 2, 1e-7, 0);
    lm_tensor *he = lm_l2_normalize(&c, h, -1, 10.0f);
    if (he) CHECK_ARRAY_CLOSE(he->data, ((float[]){0.3f, 0.4f}), 2, 1e-7, 0);
    /* inner size > one 64-wide block, strided input */
    lm_tensor *big = lm_tensor_uniform(&c, 3, (int[]){2, 4, 150}, &r, -1, 1);
    lm_tensor *s = lm_slice(&c, big, 2, 3, 140);
    lm_tensor *ys = lm_l2_normalize(&c, s, 1, 1e-12f);
    float *es = malloc(sizeof(float) * 2 * 4 * 140);
    ref_l2(lm_contiguous(&c, s), 1, 1e-12f, es);
    if (ys) CHECK_ARRAY_CLOSE(ys->data, es, 2 * 4 * 140, 1e-6, 1e-5);
    free(es);
    free(e);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

typedef struct l2_case { int axis; float eps; } l2_case;
static lm_tensor *fn_l2(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin;
    const l2_case *p = u;
    return check_with_input(c, lm_l2_normalize(c, in[0], p->axis, p->eps), in[0]);
}

/* Vectors along axis 1 of a 3 x 4 x 5 tensor: half with norm ~0.3, half ~3; with eps = 1 both
 * sides of the clamp are exercised, well away from the kink. */
static void test_l2_gradients(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 75);
    lm_tensor *x = lm_tensor_uniform(&c, 3, (int[]){3, 4, 5}, &r, -1, 1);
    int below = 0, above = 0;
    for (int o = 0; o < 3; o++)
        for (int i = 0; i < 5; i++) {
            double s = 0;
            for (int a = 0; a < 4; a++) {
                double v = x->data[(o * 4 + a) * 5 + i];
                s += v * v;
            }
            double target = (o * 5 + i) % 2 ? 3.0 : 0.3;
            for (int a = 0; a < 4; a++) x->data[(o * 4 + a) * 5 + i] *= (float)(target / sqrt(s));
            target < 1 ? below++ : above++;
        }
    CHECK(below > 0 && above > 0);
    lm_tensor_set_requires_grad(x, 1);
    l2_case clamp = {1, 1.0f}, plain = {-1, 1e-12f}, first = {0, 1e-12f};
    lm_gradcheck_opts o;
    lm_gradcheck_default_opts(&o);
    o.eps = 1e-3;
    CHECK_GRAD(&c, fn_l2, &x, 1, &clamp, &o);
    CHECK_GRAD(&c, fn_l2, &x, 1, &plain, &o);
    CHECK_GRAD(&c, fn_l2, &x, 1, &first, &o);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_l2_errors(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_zeros(&c, 3, (int[]){2, 3, 4});
    CHECK(lm_l2_normalize(&c, x, 3, 1e-12f) == NULL);
    CHECK(strstr(c.msg, "l2_normalize") && strstr(c.msg, "2x3x4"));
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    CHECK(lm_l2_normalize(&c, x, -4, 1e-12f) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    CHECK(lm_l2_normalize(&c, x, 0, -1.0f) == NULL);
    CHECK(strstr(c.msg, "l2_normalize") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    CHECK(lm_l2_normalize(&c, NULL, 0, 1e-12f) == NULL);
    CHECK(strstr(c.msg, "l2_normalize") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    /* zero vectors with eps > 0 give zeros, not NaN */
    lm_tensor *y = lm_l2_normalize(&c, x, 1, 1e-12f);
    for (int i = 0; y && i < 24; i++) CHECK(y->data[i] == 0.0f);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* The row path of the forward (last axis, as in the spectral attention) against the blocked
 * reference loop: row lengths around the 4-wide unroll, rows below eps, 1 and 2 threads. */
static void test_l2_rows_match_reference(void)
{
    lm_rng r;
    lm_rng_seed(&r, 76);
    const int lens[] = {1, 3, 4, 5, 80, 1280, 1283};
    for (size_t i = 0; i < sizeof lens / sizeof lens[0]; i++) {
        int shape[3] = {3, 40, lens[i]};
        long n = 3L * 40 * lens[i];
        float *xv = malloc(sizeof(float) * n), *y[3];
        lm_rng_fill_uniform(&r, xv, n, -1.0f, 1.0f);
        for (int k = 0; k < lens[i]; k++) xv[k] *= 1e-3f; /* row 0 below eps = 1e-2 if short */
        for (int v = 0; v < 3; v++) {
            lm_ctx c;
            lm_ctx_init(&c, v == 1 ? 2 : 1);
            int old = lm_op_set_path(&c, v == 2 ? LM_OP_PATH_REFERENCE : LM_OP_PATH_FAST);
            lm_tensor *x = lm_tensor_from(&c, 3, shape, xv);
            lm_tensor *yt = lm_l2_normalize(&c, x, -1, lens[i] < 100 ? 1e-2f : 1e-12f);
            lm_op_set_path(&c, old);
            y[v] = malloc(sizeof(float) * n);
            if (yt) memcpy(y[v], yt->data, sizeof(float) * n);
            CHECK_CTX_OK(&c);
            lm_ctx_free(&c);
        }
        /* the norms are summed in double in another order: equal after rounding but for
         * ties, so within one float ulp */
        CHECK_ARRAY_CLOSE(y[0], y[2], n, 1e-30, 1.2e-7);
        CHECK_ARRAY_CLOSE(y[1], y[0], n, 0, 0);
        for (int v = 0; v < 3; v++) free(y[v]);
        free(xv);
    }
}

int main(void)
{
    RUN(test_layer_norm_reference);
    RUN(test_layer_norm_gradients);
    RUN(test_layer_norm_wb_exact_and_threads);
    RUN(test_layer_norm_errors);
    RUN(test_l2_reference);
    RUN(test_l2_gradients);
    RUN(test_l2_errors);
    RUN(test_l2_rows_match_reference);
    return check_summary();
}

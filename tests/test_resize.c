/* test_resize.c — resize_bilinear against hand-computed PyTorch values and an independent
 * double-precision reference (forward, and backward as a direct scatter), both align_corners
 * settings, up/down/non-integer ratios, gradient checks, thread-count independence, errors. */
#include "tests/check.h"
#include <stdlib.h>

/* PyTorch's source coordinate, in double; returns i0, i1 and the weight of i1. */
static void ref_src(int dst, int in, int out, int ac, int *i0, int *i1, double *l)
{
    double s;
    if (ac) s = out > 1 ? dst * (double)(in - 1) / (out - 1) : 0.0;
    else {
        s = (dst + 0.5) * (double)in / out - 0.5;
        if (s < 0) s = 0;
    }
    int i = (int)floor(s);
    if (i > in - 1) i = in - 1;
    *i0 = i;
    *i1 = i + 1 < in ? i + 1 : in - 1;
    *l = s - i;
}

/* Forward (g == NULL: out = resize(x)) or backward (gx += scatter of g) reference. */
static void ref_resize(const float *x, float *out, const float *g, double *gx, int P, int H,
                       int W, int oh, int ow, int ac)
{
    for (int p = 0; p < P; p++)
        for (int Y = 0; Y < oh; Y++)
            for (int X = 0; X < ow; X++) {
                int y0, y1, x0, x1;
                double ly, lx;
                ref_src(Y, H, oh, ac, &y0, &y1, &ly);
                ref_src(X, W, ow, ac, &x0, &x1, &lx);
                const long b = (long)p * H * W, o = ((long)p * oh + Y) * ow + X;
                double w[4] = {(1 - ly) * (1 - lx), (1 - ly) * lx, ly * (1 - lx), ly * lx};
                long idx[4] = {b + y0 * W + x0, b + y0 * W + x1, b + y1 * W + x0, b + y1 * W + x1};
                if (!g) {
                    double v = 0;
                    for (int k = 0; k < 4; k++) v += w[k] * x[idx[k]];
                    out[o] = (float)v;
                } else
                    for (int k = 0; k < 4; k++) gx[idx[k]] += w[k] * g[o];
            }
}

static void test_hand_values(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_from(&c, 4, (int[]){1, 1, 2, 2}, (float[]){0, 1, 2, 3});
    lm_tensor *y = lm_resize_bilinear(&c, x, 4, 4, 0);
    float e[16] = {0, 0.25f, 0.75f, 1, 0.5f, 0.75f, 1.25f, 1.5f,
                   1.5f, 1.75f, 2.25f, 2.5f, 2, 2.25f, 2.75f, 3};
    if (y) CHECK_ARRAY_CLOSE(y->data, e, 16, 1e-6, 0);
    lm_tensor *z = lm_resize_bilinear(&c, x, 3, 3, 1);
    float ez[9] = {0, 0.5f, 1, 1, 1.5f, 2, 2, 2.5f, 3};
    if (z) CHECK_ARRAY_CLOSE(z->data, ez, 9, 1e-6, 0);
    /* same size without align_corners is the identity */
    lm_tensor *id = lm_resize_bilinear(&c, x, 2, 2, 0);
    if (id) CHECK_ARRAY_CLOSE(id->data, x->data, 4, 0, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_reference_sizes(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 51);
    const int H = 7, W = 9, sizes[6][2] = {{14, 18}, {3, 4}, {11, 5}, {1, 1}, {7, 9}, {22, 16}};
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, 3, H, W}, &r, -1, 1);
    float *e = malloc(6 * 22 * 18 * sizeof *e);
    for (int k = 0; k < 6; k++)
        for (int ac = 0; ac < 2; ac++) {
            int oh = sizes[k][0], ow = sizes[k][1];
            lm_tensor *y = lm_resize_bilinear(&c, x, oh, ow, ac);
            CHECK_CTX_OK(&c);
            if (!y) continue;
            CHECK(y->shape[0] == 2 && y->shape[1] == 3 && y->shape[2] == oh && y->shape[3] == ow);
            ref_resize(x->data, e, NULL, NULL, 6, H, W, oh, ow, ac);
            CHECK_ARRAY_CLOSE(y->data, e, 6L * oh * ow, 1e-5, 1e-5);
        }
    free(e);
    lm_ctx_free(&c);
}

/* Analytic backward equals the direct scatter reference, and is bitwise the same for 1 and 2
 * threads. */
static void test_backward_reference_and_threads(void)
{
    const int H = 6, W = 70, oh = 13, ow = 150, P = 3;
    float *g1 = NULL;
    for (int nt = 1; nt <= 2; nt++)
        for (int ac = 0; ac < 2; ac++) {
            lm_ctx c;
            lm_ctx_init(&c, nt);
            lm_rng r;
            lm_rng_seed(&r, 52 + ac);
            lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){1, P, H, W}, &r, -1, 1);
            lm_tensor_set_requires_grad(x, 1);
            lm_tensor *y = lm_resize_bilinear(&c, x, oh, ow, ac);
            lm_tensor *seed = lm_tensor_uniform(&c, 4, y->shape, &r, -1, 1);
            CHECK(lm_backward(&c, y, seed) == LM_OK);
            double *gx = calloc((size_t)P * H * W, sizeof *gx);
            float *gf = malloc((size_t)P * H * W * sizeof *gf);
            ref_resize(NULL, NULL, seed->data, gx, P, H, W, oh, ow, ac);
            for (int i = 0; i < P * H * W; i++) gf[i] = (float)gx[i];
            /* float coordinates (as PyTorch's) put ~1e-5 of weight on a neighbour at some rows */
            CHECK_ARRAY_CLOSE(x->grad->data, gf, P * H * W, 1e-4, 1e-5);
            if (nt == 1 && ac == 1) {
                g1 = malloc((size_t)P * H * W * sizeof *g1);
                memcpy(g1, x->grad->data, (size_t)P * H * W * sizeof *g1);
            }
            if (nt == 2 && ac == 1) CHECK(memcmp(g1, x->grad->data, (size_t)P * H * W * 4) == 0);
            free(gx);
            free(gf);
            lm_ctx_free(&c);
        }
    free(g1);
}

typedef struct rs_case { int oh, ow, ac; } rs_case;
static lm_tensor *fn_resize(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin;
    const rs_case *p = u;
    return check_with_input(c, lm_resize_bilinear(c, in[0], p->oh, p->ow, p->ac), in[0]);
}

static void test_gradients(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 53);
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, 2, 4, 5}, &r, -1, 1);
    lm_tensor_set_requires_grad(x, 1);
    const rs_case cases[4] = {{7, 11, 0}, {3, 2, 0}, {7, 11, 1}, {3, 3, 1}};
    for (int k = 0; k < 4; k++) CHECK_GRAD(&c, fn_resize, &x, 1, (void *)&cases[k], NULL);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_errors(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_zeros(&c, 4, (int[]){1, 2, 3, 4});
    CHECK(lm_resize_bilinear(&c, x, 0, 4, 0) == NULL);
    CHECK(strstr(c.msg, "resize_bilinear") != NULL && strstr(c.msg, "1x2x3x4") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_resize_bilinear(&c, x, 4, -2, 1) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    lm_tensor *x3 = lm_tensor_zeros(&c, 3, (int[]){2, 3, 4});
    CHECK(lm_resize_bilinear(&c, x3, 4, 4, 0) == NULL);
    CHECK(strstr(c.msg, "resize_bilinear") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_resize_bilinear(&c, NULL, 4, 4, 0) == NULL);
    CHECK(strstr(c.msg, "resize_bilinear") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    lm_ctx_free(&c);
}

int main(void)
{
    RUN(test_hand_values);
    RUN(test_reference_sizes);
    RUN(test_backward_reference_and_threads);
    RUN(test_gradients);
    RUN(test_errors);
    return check_summary();
}

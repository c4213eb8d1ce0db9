/* test_whole.c — whole-frame strip inference (infer/whole.h) against one forward pass over
 * the whole frame (linear, rt-8, rt-16; odd frame sizes, several strip heights, 1 and 2
 * threads); a too-small halo must break the equality (the comparison can fail); the 31-band
 * cube; refusals. The rt presets: exact parameter counts and names, and the residual
 * structure (branch columns of the head zeroed = the linear model). The direct conv2d
 * forward path (tensor/ops/conv2d_direct.c) against a plain loop written here and against
 * the simple reference path, thread-count determinism, and a gradient check through it. */
#include "tests/check.h"
#include "infer/whole.h"
#include "tensor/ops/gemm_internal.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

/* ---- direct conv2d path ------------------------------------------------------------------ */
typedef struct dcfg { int B, Cin, H, W, Cout, k, pad, bias; } dcfg;
static const dcfg DCFGS[] = {
    {1, 12, 7, 13, 16, 3, 1, 1},  {2, 16, 5, 33, 16, 3, 1, 0}, {1, 32, 9, 17, 32, 3, 1, 1},
    {1, 12, 6, 20, 33, 1, 0, 1},  {1, 16, 4, 37, 33, 1, 0, 0}, {1, 3, 8, 11, 5, 3, 0, 1},
    {1, 4, 7, 10, 7, 5, 2, 0},    {2, 8, 3, 8, 8, 3, 1, 1},    {1, 5, 6, 49, 48, 3, 2, 1},
    {1, 12, 5, 16, 24, 3, 1, 1},
};
#define NDCFG ((int)(sizeof DCFGS / sizeof DCFGS[0]))

/* Plain-loop cross-correlation, in double. */
static void conv_ref(const dcfg *k, const float *x, const float *w, const float *b, double *y)
{
    int Ho = k->H + 2 * k->pad - k->k + 1, Wo = k->W + 2 * k->pad - k->k + 1;
    for (int n = 0; n < k->B; n++)
        for (int o = 0; o < k->Cout; o++)
            for (int oy = 0; oy < Ho; oy++)
                for (int ox = 0; ox < Wo; ox++) {
                    double s = b ? b[o] : 0.0;
                    for (int ci = 0; ci < k->Cin; ci++)
                        for (int i = 0; i < k->k; i++)
                            for (int j = 0; j < k->k; j++) {
                                int iy = oy - k->pad + i, ix = ox - k->pad + j;
                                if (iy < 0 || iy >= k->H || ix < 0 || ix >= k->W) continue;
                                s += (double)x[((n * k->Cin + ci) * k->H + iy) * k->W + ix] *
                                     w[((o * k->Cin + ci) * k->k + i) * k->k + j];
                            }
                    y[((n * k->Cout + o) * Ho + oy) * Wo + ox] = s;
                }
}

static lm_tensor *direct_conv(lm_ctx *c, const dcfg *k, lm_rng *r, int threads)
{
    lm_rng_seed(r, 11);
    lm_tensor *x = lm_tensor_uniform(c, 4, (int[]){k->B, k->Cin, k->H, k->W}, r, -1, 1);
    lm_tensor *w = lm_tensor_uniform(c, 4, (int[]){k->Cout, k->Cin, k->k, k->k}, r, -1, 1);
    lm_tensor *b = k->bias ? lm_tensor_uniform(c, 1, &k->Cout, r, -1, 1) : NULL;
    lm_conv2d_opts o = {1, 1, k->pad, k->pad, 1, 1, 1};
    c->nthreads = threads;
    return lm_conv2d(c, x, w, b, &o);
}

static void test_direct_matches_references(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    /* 3x3 convs with 16+ channels take the Winograd path by default: test the direct one */
    int path0 = lm_conv2d_set_path(&c, LM_CONV_PATH_NO_WINOGRAD);
    for (int q = 0; q < NDCFG; q++) {
        const dcfg *k = &DCFGS[q];
        int Ho = k->H + 2 * k->pad - k->k + 1, Wo = k->W + 2 * k->pad - k->k + 1;
        lm_conv_geom g = {k->B, k->Cin, k->H, k->W, k->Cout, Ho, Wo, k->k, k->k, 1, 1,
                          k->pad, k->pad, 1, 1, 1};
        CHECK_MSG(lm_conv2d_direct_applies(&g), "config %d: the direct path does not apply", q);
        lm_tensor *y2 = direct_conv(&c, k, &r, 2), *y1 = direct_conv(&c, k, &r, 1);
        int old = lm_conv2d_set_path(&c, LM_CONV_PATH_SIMPLE);
        lm_tensor *ys = direct_conv(&c, k, &r, 2);
        lm_conv2d_set_path(&c, old);
        CHECK_CTX_OK(&c);
        if (!y1 || !y2 || !ys) continue;
        long n = lm_tensor_numel(y2);
        CHECK_MSG(!memcmp(y1->data, y2->data, sizeof(float) * (size_t)n),
                  "config %d: 1 and 2 threads differ", q);
        CHECK_ARRAY_CLOSE(y2->data, ys->data, n, 1e-5, 1e-5);
        /* the plain loop: x, w, b are the first tensors drawn with seed 11 */
        lm_rng_seed(&r, 11);
        lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){k->B, k->Cin, k->H, k->W}, &r, -1, 1);
        lm_tensor *w = lm_tensor_uniform(&c, 4, (int[]){k->Cout, k->Cin, k->k, k->k}, &r, -1, 1);
        lm_tensor *b = k->bias ? lm_tensor_uniform(&c, 1, &k->Cout, &r, -1, 1) : NULL;
        double *ref = malloc(sizeof(double) * (size_t)n);
        conv_ref(k, x->data, w->data, b ? b->data : NULL, ref);
        long bad = 0;
        for (long i = 0; i < n; i++)
            bad += !(fabs(y2->data[i] - ref[i]) <= 1e-5 * (1 + fabs(ref[i])));
        CHECK_MSG(bad == 0, "config %d: %ld of %ld outputs differ from the plain loop", q, bad, n);
        free(ref);
        lm_ctx_reset(&c);
    }
    lm_conv2d_set_path(&c, path0);
    lm_ctx_free(&c);
}

static lm_tensor *fn_conv3(lm_ctx *c, lm_tensor *const *in, int nin, void *user)
{
    (void)user;
    lm_conv2d_opts o = {1, 1, 1, 1, 1, 1, 1};
    return lm_conv2d(c, in[0], in[1], nin > 2 ? in[2] : NULL, &o);
}

/* The direct forward with the tiled backward: finite differences through both. */
static void test_direct_gradcheck(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 3);
    lm_tensor *in[3] = {lm_tensor_uniform(&c, 4, (int[]){1, 6, 5, 17}, &r, -1, 1),
                        lm_tensor_uniform(&c, 4, (int[]){10, 6, 3, 3}, &r, -1, 1),
                        lm_tensor_uniform(&c, 1, (int[]){10}, &r, -1, 1)};
    for (int i = 0; i < 3; i++) lm_tensor_set_requires_grad(in[i], 1);
    lm_gradcheck_opts go;
    lm_gradcheck_default_opts(&go);
    go.atol = 1e-3, go.rtol = 5e-3, go.max_checks = 60;
    CHECK_GRAD(&c, fn_conv3, in, 3, NULL, &go);
    lm_ctx_free(&c);
}

/* ---- rt presets ---------------------------------------------------------------------------- */
static void test_rt_params(void)
{
    lm_err e = {0};
    const int widths[2] = {8, 16};
    for (int i = 0; i < 2; i++) {
        char name[16];
        snprintf(name, sizeof name, "rt-%d", widths[i]);
        lm_model *m = lm_model_create(name, NULL, 1, &e);
        CHECK_MSG(m != NULL, "%s", e.msg);
        if (!m) continue;
        long C = widths[i];
        long want = (13 * C * 9 + C) + (C * C * 9 + C) + ((12 + C) * 33 + 33);
        CHECK(lm_params_count(&m->params, 0) == want);
        CHECK(!strcmp(m->family, "rt"));
        const char *names[] = {"body.0.weight", "body.0.bias", "body.2.weight", "body.2.bias",
                               "head.weight", "head.bias"};
        lm_param *hw = lm_params_find(&m->params, "head.weight");
        CHECK(hw && hw->t.shape[0] == 33 && hw->t.shape[1] == 12 + C && hw->t.shape[2] == 1);
        for (int k = 0; k < 6; k++) CHECK_MSG(lm_params_find(&m->params, names[k]) != NULL,
                                              "%s: no %s", name, names[k]);
        lm_model_free(m);
    }
}

/* With the head's branch columns zeroed, rt is the linear model whose map is the head's first
 * 12 columns; the branch columns alone change the output. */
static void test_rt_residual(void)
{
    lm_err e = {0};
    lm_model *rt = lm_model_create("rt-8", NULL, 5, &e);
    lm_model *lin = lm_model_create("linear", NULL, 6, &e);
    CHECK_MSG(rt && lin, "%s", e.msg);
    if (!rt || !lin) return;
    lm_tensor *hw = &lm_params_find(&rt->params, "head.weight")->t; /* 33 x 20 x 1 x 1 */
    float *pw = lm_params_find(&lin->params, "proj.weight")->t.data;  /* 33 x 12 x 1 x 1 */
    for (int o = 0; o < 33; o++)
        for (int k = 0; k < 20; k++)
            if (k < 12) pw[o * 12 + k] = hw->data[o * 20 + k];
            else hw->data[o * 20 + k] = 0.0f;
    memcpy(lm_params_find(&lin->params, "proj.bias")->t.data,
           lm_params_find(&rt->params, "head.bias")->t.data, sizeof(float) * 33);
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_ctx_set_grad(&c, 0);
    lm_rng r;
    lm_rng_seed(&r, 9);
    lm_tensor *raw = lm_tensor_uniform(&c, 4, (int[]){2, 1, 12, 16}, &r, 0, 1);
    lm_tensor *a = lm_model_forward(&c, rt, raw), *b = lm_model_forward(&c, lin, raw);
    CHECK_CTX_OK(&c);
    if (a && b) {
        CHECK(a->shape[0] == 2 && a->shape[1] == 33 && a->shape[2] == 12 && a->shape[3] == 16);
        CHECK_ARRAY_CLOSE(a->data, b->data, lm_tensor_numel(a), 1e-6, 1e-6);
        for (int o = 0; o < 33; o++) hw->data[o * 20 + 12 + o % 8] = 0.5f;
        lm_tensor *d = lm_model_forward(&c, rt, raw);
        double diff = 0;
        for (long i = 0; d && i < lm_tensor_numel(d); i++) diff += fabs(d->data[i] - b->data[i]);
        CHECK_MSG(diff > 1.0, "the branch does not reach the output (%g)", diff);
    }
    lm_ctx_free(&c);
    lm_model_free(rt);
    lm_model_free(lin);
}

/* ---- strips against one whole-frame forward ---------------------------------------------- */
/* Max |strips - whole| over all 33 channels; -1 on error. */
static double strip_error(lm_model *m, int H, int W, int strip, int halo, int threads)
{
    lm_ctx c;
    lm_ctx_init(&c, threads);
    lm_rng r;
    lm_rng_seed(&r, (uint64_t)(H * 1000 + W));
    const int C = m->in_channels; /* 2: both buckets, plane after plane */
    float *frame = malloc(sizeof(float) * C * (size_t)H * W);
    float *out = malloc(sizeof(float) * 33 * (size_t)H * W);
    lm_rng_fill_uniform(&r, frame, (long)C * H * W, 0.0f, 1.0f);
    lm_whole_opts o = {strip, halo};
    lm_err e = {0};
    double worst = -1;
    lm_status st = lm_whole_forward(&c, m, frame, H, W, &o, 0, 33, out, &e);
    CHECK_MSG(st == LM_OK, "%s", e.msg);
    lm_ctx_set_grad(&c, 0);
    lm_tensor *raw = lm_tensor_from(&c, 4, (int[]){1, C, H, W}, frame);
    lm_tensor *y = st ? NULL : lm_model_forward(&c, m, raw);
    CHECK_CTX_OK(&c);
    if (y) {
        worst = 0;
        for (long i = 0; i < 33L * H * W; i++) worst = fmax(worst, fabs(out[i] - y->data[i]));
    }
    free(frame);
    free(out);
    lm_ctx_free(&c);
    return worst;
}

static void test_strips_equal_whole(void)
{
    const char *names[] = {"linear", "rt-8", "rt-16", "rt-8-b2", "lmmse-5-b2"};
    const int sizes[][2] = {{33, 44}, {51, 28}, {6, 12}};
    const int strips[] = {3, 9, 16, 96};
    lm_err e = {0};
    for (int n = 0; n < 5; n++) { /* the -b2 models: strips of both bucket planes */
        lm_model *m = lm_model_create(names[n], NULL, 3, &e);
        CHECK_MSG(m != NULL, "%s", e.msg);
        if (!m) continue;
        CHECK(lm_whole_halo(m) == (n ? 6 : 3));
        for (int s = 0; s < 3; s++)
            for (int k = 0; k < 4; k++)
                for (int t = strips[k] == 9 ? 1 : 2; t <= 2; t++) {
                    double d = strip_error(m, sizes[s][0], sizes[s][1], strips[k], -1, t);
                    CHECK_MSG(d >= 0 && d <= 1e-5, "%s %dx%d strips of %d, %d threads: max "
                              "|strips - whole| %g", names[n], sizes[s][0], sizes[s][1],
                              strips[k], t, d);
                }
        lm_model_free(m);
    }
}

/* One tile row less halo than declared: the strip edges show (the equality test can fail). */
static void test_small_halo_breaks(void)
{
    const char *names[] = {"linear", "rt-8", "rt-8-b2"};
    lm_err e = {0};
    for (int n = 0; n < 3; n++) {
        lm_model *m = lm_model_create(names[n], NULL, 3, &e);
        if (!m) continue;
        double d = strip_error(m, 33, 44, 9, lm_whole_halo(m) - 3, 2);
        CHECK_MSG(d > 1e-3, "%s: halo %d still matches (%g)", names[n], lm_whole_halo(m) - 3, d);
        lm_model_free(m);
    }
}

static void test_infer_cube(void)
{
    lm_err e = {0};
    lm_model *m = lm_model_create("rt-8", NULL, 4, &e);
    if (!m) return;
    const int H = 30, W = 36;
    float *frame = malloc(sizeof(float) * H * W), *all = malloc(sizeof(float) * 33 * H * W);
    lm_rng r;
    lm_rng_seed(&r, 1);
    lm_rng_fill_uniform(&r, frame, H * W, 0.0f, 1.0f);
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_cube cube;
    CHECK(lm_whole_forward(&c, m, frame, H, W, NULL, 0, 33, all, &e) == LM_OK);
    CHECK_MSG(lm_whole_infer(&c, m, frame, H, W, &cube, &e) == LM_OK, "%s", e.msg);
    CHECK(cube.bands == 31 && cube.height == H && cube.width == W);
    CHECK_CLOSE(cube.wavelength[0], 400.0, 1e-6, 0);
    CHECK_CLOSE(cube.wavelength[30], 700.0, 1e-4, 0);
    if (cube.data) CHECK(!memcmp(cube.data, all + H * W, sizeof(float) * 31 * H * W));
    lm_cube_free(&cube);
    free(frame);
    free(all);
    lm_ctx_free(&c);
    lm_model_free(m);
}

static void test_errors(void)
{
    lm_err e = {0};
    lm_ctx c;
    lm_ctx_init(&c, 1);
    float frame[36 * 48] = {0}, out[33 * 36 * 48];
    lm_model *mc = lm_model_create("mcan-tiny", NULL, 1, &e);
    lm_model *m = lm_model_create("rt-8", NULL, 1, &e);
    if (!mc || !m) return;
    CHECK(lm_whole_halo(mc) < 0);
    CHECK(lm_whole_forward(&c, mc, frame, 36, 48, NULL, 0, 33, out, &e) == LM_ERR_ARG);
    CHECK(strstr(e.msg, "whole:") && strstr(e.msg, "mcan-tiny"));
    e = (lm_err){0};
    CHECK(lm_whole_forward(&c, m, frame, 35, 48, NULL, 0, 33, out, &e) == LM_ERR_SHAPE);
    CHECK(strstr(e.msg, "whole:") != NULL);
    e = (lm_err){0};
    CHECK(lm_whole_forward(&c, m, frame, 36, 46, NULL, 0, 33, out, &e) == LM_ERR_SHAPE);
    e = (lm_err){0};
    CHECK(lm_whole_forward(&c, m, frame, 36, 48, NULL, 20, 14, out, &e) == LM_ERR_ARG);
    CHECK(strstr(e.msg, "channels") != NULL);
    e = (lm_err){0};
    lm_whole_opts o = {12, 4};
    CHECK(lm_whole_forward(&c, m, frame, 36, 48, &o, 0, 33, out, &e) == LM_ERR_ARG);
    CHECK(strstr(e.msg, "halo") != NULL);
    lm_cube cube;
    e = (lm_err){0};
    CHECK(lm_whole_infer(&c, mc, frame, 36, 48, &cube, &e) == LM_ERR_ARG && cube.data == NULL);
    CHECK(lm_ctx_status(&c) == LM_OK);
    lm_model_free(mc);
    lm_model_free(m);
    lm_ctx_free(&c);
}

int main(void)
{
    RUN(test_direct_matches_references);
    RUN(test_direct_gradcheck);
    RUN(test_rt_params);
    RUN(test_rt_residual);
    RUN(test_strips_equal_whole);
    RUN(test_small_halo_breaks);
    RUN(test_infer_cube);
    RUN(test_errors);
    return check_summary();
}

/* test_mosaic_upsample.c — phase-aware demosaic upsampling: exactness at sample positions,
 * linear ramps reproduced in the interior for every phase, constants stay constant, an
 * independent integer-arithmetic reference (forward and backward), gradient checks (with
 * repeated phases), thread-count independence, a full-frame run and error cases. */
#include "tests/check.h"
#include <stdlib.h>

/* The 3 x 4 tile: 12 phases in raster order. */
static int PY[12] = {0, 0, 0, 0, 1, 1, 1, 1, 2, 2, 2, 2};
static int PX[12] = {0, 1, 2, 3, 0, 1, 2, 3, 0, 1, 2, 3};

/* Reference along one axis with integer arithmetic: the two raw coordinates and the weight of
 * the second for output position Y of a phase-p sub-image with period t over n pixels. */
static void ref_axis(int Y, int n, int t, int p, int *r0, int *r1, double *l)
{
    int ns = n / t, d = Y - p;
    if (d <= 0) { /* at or before the first sample: nearest = first */
        *r0 = *r1 = p;
        *l = 0;
    } else if (d >= t * (ns - 1)) { /* at or after the last sample */
        *r0 = *r1 = p + t * (ns - 1);
        *l = 0;
    } else {
        *r0 = p + t * (d / t);
        *r1 = *r0 + t;
        *l = (double)(d % t) / t;
    }
}

/* out (B x nch x H x W) = reference, or graw += reference scatter of g when g != NULL. */
static void ref_mosaic(const float *raw, float *out, const float *g, double *graw, int B, int H,
                       int W, int ty, int tx, int nch, const int *py, const int *px)
{
    for (int b = 0; b < B; b++)
        for (int k = 0; k < nch; k++)
            for (int Y = 0; Y < H; Y++)
                for (int X = 0; X < W; X++) {
                    int y0, y1, x0, x1;
                    double ly, lx;
                    ref_axis(Y, H, ty, py[k], &y0, &y1, &ly);
                    ref_axis(X, W, tx, px[k], &x0, &x1, &lx);
                    long base = (long)b * H * W, o = (((long)b * nch + k) * H + Y) * W + X;
                    long id[4] = {base + y0 * W + x0, base + y0 * W + x1, base + y1 * W + x0,
                                  base + y1 * W + x1};
                    double w[4] = {(1 - ly) * (1 - lx), (1 - ly) * lx, ly * (1 - lx), ly * lx};
                    if (g)
                        for (int q = 0; q < 4; q++) graw[id[q]] += w[q] * g[o];
                    else {
                        double v = 0;
                        for (int q = 0; q < 4; q++) v += w[q] * raw[id[q]];
                        out[o] = (float)v;
                    }
                }
}

static void test_exact_at_samples_and_reference(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 61);
    const int B = 2, H = 12, W = 16;
    lm_tensor *raw = lm_tensor_uniform(&c, 4, (int[]){B, 1, H, W}, &r, 0, 1);
    lm_tensor *y = lm_mosaic_upsample(&c, raw, 3, 4, 12, PY, PX);
    CHECK_CTX_OK(&c);
    CHECK(y && y->shape[0] == B && y->shape[1] == 12 && y->shape[2] == H && y->shape[3] == W);
    if (!y) return;
    long bad = 0;
    for (int b = 0; b < B; b++)
        for (int k = 0; k < 12; k++)
            for (int Y = PY[k]; Y < H; Y += 3)
                for (int X = PX[k]; X < W; X += 4)
                    bad += *lm_at4(y, b, k, Y, X) != raw->data[(b * H + Y) * W + X];
    CHECK_MSG(bad == 0, "%ld sample positions not reproduced exactly", bad);
    float *e = malloc(sizeof(float) * B * 12 * H * W);
    ref_mosaic(raw->data, e, NULL, NULL, B, H, W, 3, 4, 12, PY, PX);
    CHECK_ARRAY_CLOSE(y->data, e, B * 12 * H * W, 1e-6, 1e-6);
    free(e);
    lm_ctx_free(&c);
}

/* raw = a y + b x + d: every phase reproduces it wherever the pixel lies between its first and
 * last sample row and column; and a constant frame stays constant everywhere. */
static void test_ramp_and_constant(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    const int H = 15, W = 20;
    lm_tensor *raw = lm_tensor_new(&c, 4, (int[]){1, 1, H, W});
    for (int Y = 0; Y < H; Y++)
        for (int X = 0; X < W; X++) raw->data[Y * W + X] = 0.5f * Y - 0.25f * X + 3.0f;
    lm_tensor *y = lm_mosaic_upsample(&c, raw, 3, 4, 12, PY, PX);
    CHECK_CTX_OK(&c);
    long bad = 0, checked = 0;
    for (int k = 0; y && k < 12; k++)
        for (int Y = PY[k]; Y <= PY[k] + 3 * (H / 3 - 1); Y++)
            for (int X = PX[k]; X <= PX[k] + 4 * (W / 4 - 1); X++) {
                float v = *lm_at4(y, 0, k, Y, X), e = 0.5f * Y - 0.25f * X + 3.0f;
                bad += fabsf(v - e) > 1e-5f;
                checked++;
            }
    CHECK_MSG(bad == 0, "%ld of %ld interior ramp values off", bad, checked);
    CHECK(checked == 12L * 13 * 17);
    lm_tensor *k7 = lm_tensor_full(&c, 4, (int[]){2, 1, H, W}, 7.25f);
    lm_tensor *yk = lm_mosaic_upsample(&c, k7, 3, 4, 12, PY, PX);
    for (long i = 0; yk && i < lm_tensor_numel(yk); i++) bad += yk->data[i] != 7.25f;
    CHECK_MSG(bad == 0, "constant frame changed");
    lm_ctx_free(&c);
}

typedef struct mc { int ty, tx, nch; const int *py, *px; } mc;
static lm_tensor *fn_mosaic(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin;
    const mc *m = u;
    return check_with_input(c, lm_mosaic_upsample(c, in[0], m->ty, m->tx, m->nch, m->py, m->px),
                      in[0]);
}

static void test_gradients(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 62);
    lm_tensor *raw = lm_tensor_uniform(&c, 4, (int[]){2, 1, 6, 8}, &r, -1, 1);
    lm_tensor_set_requires_grad(raw, 1);
    mc all = {3, 4, 12, PY, PX};
    CHECK_GRAD(&c, fn_mosaic, &raw, 1, &all, NULL);
    /* repeated and partial phases: several channels scatter into the same samples */
    static const int py[4] = {1, 0, 1, 1}, px[4] = {2, 0, 2, 1};
    mc rep = {2, 3, 4, py, px};
    lm_tensor *raw2 = lm_tensor_uniform(&c, 4, (int[]){1, 1, 8, 9}, &r, -1, 1);
    lm_tensor_set_requires_grad(raw2, 1);
    CHECK_GRAD(&c, fn_mosaic, &raw2, 1, &rep, NULL);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* Backward against the scatter reference on a frame wider than one column band (W/tx > 32),
 * bitwise identical for 1 and 2 threads. */
static void test_backward_reference_and_threads(void)
{
    const int B = 2, H = 9, W = 160;
    float *g1 = NULL;
    for (int nt = 1; nt <= 2; nt++) {
        lm_ctx c;
        lm_ctx_init(&c, nt);
        lm_rng r;
        lm_rng_seed(&r, 63);
        lm_tensor *raw = lm_tensor_uniform(&c, 4, (int[]){B, 1, H, W}, &r, -1, 1);
        lm_tensor_set_requires_grad(raw, 1);
        lm_tensor *y = lm_mosaic_upsample(&c, raw, 3, 4, 12, PY, PX);
        lm_tensor *seed = lm_tensor_uniform(&c, 4, y->shape, &r, -1, 1);
        CHECK(lm_backward(&c, y, seed) == LM_OK);
        double *gd = calloc((size_t)B * H * W, sizeof *gd);
        float *gf = malloc((size_t)B * H * W * sizeof *gf);
        ref_mosaic(NULL, NULL, seed->data, gd, B, H, W, 3, 4, 12, PY, PX);
        for (int i = 0; i < B * H * W; i++) gf[i] = (float)gd[i];
        CHECK_ARRAY_CLOSE(raw->grad->data, gf, B * H * W, 1e-5, 1e-5);
        if (nt == 1) {
            g1 = malloc((size_t)B * H * W * sizeof *g1);
            memcpy(g1, raw->grad->data, (size_t)B * H * W * sizeof *g1);
        } else
            CHECK(memcmp(g1, raw->grad->data, (size_t)B * H * W * sizeof *g1) == 0);
        free(gd);
        free(gf);
        lm_ctx_free(&c);
    }
    free(g1);
}

/* A full 640 x 480 frame, 12 channels: spot values against the reference formula. */
static void test_full_frame(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 64);
    const int H = 480, W = 640;
    lm_tensor *raw = lm_tensor_uniform(&c, 4, (int[]){1, 1, H, W}, &r, 0, 1);
    lm_tensor *y = lm_mosaic_upsample(&c, raw, 3, 4, 12, PY, PX);
    CHECK_CTX_OK(&c);
    for (int i = 0; y && i < 2000; i++) {
        int k = (int)lm_rng_below(&r, 12), Y = (int)lm_rng_below(&r, H);
        int X = (int)lm_rng_below(&r, W), y0, y1, x0, x1;
        double ly, lx;
        ref_axis(Y, H, 3, PY[k], &y0, &y1, &ly);
        ref_axis(X, W, 4, PX[k], &x0, &x1, &lx);
        const float *d = raw->data;
        double e = (1 - ly) * ((1 - lx) * d[y0 * W + x0] + lx * d[y0 * W + x1]) +
                   ly * ((1 - lx) * d[y1 * W + x0] + lx * d[y1 * W + x1]);
        CHECK_CLOSE(*lm_at4(y, 0, k, Y, X), e, 1e-6, 1e-6);
    }
    lm_ctx_free(&c);
}

static void test_errors(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *raw = lm_tensor_zeros(&c, 4, (int[]){1, 1, 6, 8});
    CHECK(lm_mosaic_upsample(&c, raw, 4, 4, 12, PY, PX) == NULL); /* H % ty */
    CHECK(strstr(c.msg, "mosaic_upsample") != NULL && strstr(c.msg, "1x1x6x8") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_mosaic_upsample(&c, raw, 3, 3, 9, PY, PX) == NULL); /* W % tx */
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_mosaic_upsample(&c, raw, 3, 4, 0, PY, PX) == NULL); /* nch < 1 */
    CHECK(strstr(c.msg, "mosaic_upsample") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    CHECK(lm_mosaic_upsample(&c, raw, 3, 4, 12, PY, NULL) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    CHECK(lm_mosaic_upsample(&c, raw, 2, 4, 12, PY, PX) == NULL); /* phase_y 2 >= ty */
    CHECK(strstr(c.msg, "mosaic_upsample") != NULL && strstr(c.msg, "phase") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    CHECK(lm_mosaic_upsample(&c, raw, 3, 2, 2, PY, (int[]){0, -1}) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    lm_tensor *two = lm_tensor_zeros(&c, 4, (int[]){1, 2, 6, 8}); /* not B x 1 x H x W */
    CHECK(lm_mosaic_upsample(&c, two, 3, 4, 12, PY, PX) == NULL);
    CHECK(strstr(c.msg, "mosaic_upsample") != NULL && strstr(c.msg, "1x2x6x8") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    lm_tensor *three = lm_tensor_zeros(&c, 3, (int[]){1, 6, 8});
    CHECK(lm_mosaic_upsample(&c, three, 3, 4, 12, PY, PX) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_mosaic_upsample(&c, raw, 0, 4, 12, PY, PX) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_mosaic_upsample(&c, NULL, 3, 4, 12, PY, PX) == NULL);
    CHECK(strstr(c.msg, "mosaic_upsample") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    lm_ctx_free(&c);
}

int main(void)
{
    RUN(test_exact_at_samples_and_reference);
    RUN(test_ramp_and_constant);
    RUN(test_gradients);
    RUN(test_backward_reference_and_threads);
    RUN(test_full_frame);
    RUN(test_errors);
    return check_summary();
}

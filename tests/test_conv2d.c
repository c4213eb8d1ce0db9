/* test_conv2d.c — conv2d forward against a direct-convolution loop written here, backward
 * (x, w, bias) against direct loops and finite differences, the fast CPU paths (tiled
 * im2col + GEMM, Winograd, pointwise, depthwise) against the simple reference path, determinism for a thread
 * count, gradient accumulation, and shape/option errors. */
#include "tests/check.h"
#include "tensor/ops/gemm_internal.h"
#include "tensor/ops/gemm_bf16.h"
#include "tensor/isa.h"
#include "tensor/ops/wcache.h"
#include <stdlib.h>

typedef struct cfg {
    int B, Cin, H, W, Cout, kh, kw;
    lm_conv2d_opts o;
    int bias;
    const char *what;
} cfg;

/* stride_h, stride_w, pad_h, pad_w, dil_h, dil_w, groups */
static const cfg CFGS[] = {
    {1, 5, 7, 9, 6, 1, 1, {1, 1, 0, 0, 1, 1, 1}, 1, "1x1"},
    {3, 4, 10, 13, 6, 1, 1, {2, 2, 1, 1, 1, 1, 1}, 0, "1x1 stride 2 pad 1"},
    {3, 4, 10, 13, 6, 3, 3, {1, 1, 1, 1, 1, 1, 1}, 1, "3x3 pad 1"},
    {1, 3, 12, 10, 5, 4, 4, {2, 2, 1, 1, 1, 1, 1}, 0, "4x4 stride 2 pad 1"},
    {3, 6, 11, 9, 6, 5, 7, {1, 1, 2, 3, 1, 1, 6}, 1, "5x7 depthwise pad (2,3)"},
    {1, 4, 9, 8, 8, 3, 3, {2, 2, 1, 1, 1, 1, 4}, 1, "depthwise x2 stride 2"},
    {1, 3, 9, 12, 4, 3, 3, {1, 1, 2, 2, 2, 2, 1}, 1, "3x3 dilation 2 pad 2"},
    {3, 4, 8, 11, 6, 3, 3, {1, 1, 1, 1, 1, 1, 2}, 1, "groups 2"},
    {1, 8, 10, 9, 8, 3, 5, {2, 1, 1, 2, 1, 2, 4}, 0, "groups 4, 3x5, stride (2,1), dil (1,2)"},
    {2, 3, 6, 7, 4, 2, 3, {1, 2, 0, 1, 1, 1, 1}, 0, "2x3 pad (0,1) stride (1,2)"},
    {2, 5, 5, 5, 3, 5, 5, {3, 3, 0, 0, 1, 1, 1}, 1, "kernel = image"},
    {3, 32, 23, 37, 12, 3, 3, {1, 1, 1, 1, 1, 1, 1}, 1, "several tiles per image"},
    {1, 24, 19, 21, 16, 3, 3, {2, 2, 1, 1, 1, 1, 2}, 1, "groups 2 stride 2, tiles"},
    {1, 128, 20, 20, 8, 3, 3, {1, 1, 1, 1, 1, 1, 1}, 0, "K = 1152: column chunks"},
    {2, 8, 9, 19, 8, 3, 3, {1, 1, 1, 1, 1, 1, 8}, 1, "3x3 depthwise (stencil backward)"},
    {1, 4, 7, 11, 8, 3, 3, {1, 1, 1, 1, 1, 1, 4}, 0, "3x3 depthwise x2 (stencil dw)"},
};
#define NCFG ((int)(sizeof CFGS / sizeof CFGS[0]))

static int outdim(int n, int k, int s, int p, int d)
{
    return (n + 2 * p - d * (k - 1) - 1) / s + 1;
}

static void opts_of(const cfg *k, int *sh, int *sw, int *ph, int *pw, int *dh, int *dw, int *g)
{
    *sh = k->o.stride_h ? k->o.stride_h : 1, *sw = k->o.stride_w ? k->o.stride_w : 1;
    *ph = k->o.pad_h, *pw = k->o.pad_w;
    *dh = k->o.dil_h ? k->o.dil_h : 1, *dw = k->o.dil_w ? k->o.dil_w : 1;
    *g = k->o.groups ? k->o.groups : 1;
}

/* Direct convolution, and (mode 1) its adjoints: for every output element and tap,
 * y += w x; dx += w dy; dw += x dy; db += dy. Double accumulation. */
static void direct(const cfg *k, const float *x, const float *w, const float *bias, float *y,
                   const float *dy, double *dx, double *dw, double *db)
{
    int sh, sw, ph, pw, dh, dwl, G;
    opts_of(k, &sh, &sw, &ph, &pw, &dh, &dwl, &G);
    int Ho = outdim(k->H, k->kh, sh, ph, dh), Wo = outdim(k->W, k->kw, sw, pw, dwl);
    int cig = k->Cin / G, cog = k->Cout / G;
    for (int b = 0; b < k->B; b++)
        for (int o = 0; o < k->Cout; o++)
            for (int oy = 0; oy < Ho; oy++)
                for (int ox = 0; ox < Wo; ox++) {
                    long yi = (((long)b * k->Cout + o) * Ho + oy) * Wo + ox;
                    double acc = bias ? bias[o] : 0.0;
                    if (db) db[o] += dy[yi];
                    for (int ci = 0; ci < cig; ci++)
                        for (int i = 0; i < k->kh; i++)
                            for (int j = 0; j < k->kw; j++) {
                                int iy = oy * sh - ph + i * dh, ix = ox * sw - pw + j * dwl;
                                if (iy < 0 || iy >= k->H || ix < 0 || ix >= k->W) continue;
                                int cin = (o / cog) * cig + ci;
                                long xi = (((long)b * k->Cin + cin) * k->H + iy) * k->W + ix;
                                long wi = (((long)o * cig + ci) * k->kh + i) * k->kw + j;
                                acc += (double)w[wi] * x[xi];
                                if (dx) dx[xi] += (double)w[wi] * dy[yi];
                                if (dw) dw[wi] += (double)x[xi] * dy[yi];
                            }
                    if (y) y[yi] = (float)acc;
                }
}

typedef struct made { lm_tensor *x, *w, *b; } made;

static made make_inputs(lm_ctx *c, const cfg *k, lm_rng *r, int grad)
{
    int G = k->o.groups ? k->o.groups : 1;
    made m;
    m.x = lm_tensor_uniform(c, 4, (int[]){k->B, k->Cin, k->H, k->W}, r, -1, 1);
    m.w = lm_tensor_uniform(c, 4, (int[]){k->Cout, k->Cin / G, k->kh, k->kw}, r, -1, 1);
    m.b = k->bias ? lm_tensor_uniform(c, 1, &k->Cout, r, -1, 1) : NULL;
    if (grad) {
        lm_tensor_set_requires_grad(m.x, 1);
        lm_tensor_set_requires_grad(m.w, 1);
        if (m.b) lm_tensor_set_requires_grad(m.b, 1);
    }
    return m;
}

/* got ~ want within tol * (sum of |terms| + 1): the float rounding of a long sum grows with
 * the magnitude of its terms, a wrong or missing term does not hide in it. */
static void check_doubles(const float *got, const double *want, const double *mag, long n,
                          double tol, const char *what, const char *name)
{
    long bad = 0, first = -1;
    for (long i = 0; i < n; i++)
        if (!(fabs(got[i] - want[i]) <= tol * (1.0 + mag[i]))) {
            bad++;
            if (first < 0) first = i;
        }
    CHECK_MSG(bad == 0, "%s (%s): %ld of %ld differ, first [%ld] %.7g vs %.7g", what, name, bad,
              n, first, bad ? got[first] : 0.0, bad ? want[first] : 0.0);
}

static float *abs_copy(const float *a, long n)
{
    float *r = calloc((size_t)n, sizeof(float));
    for (long i = 0; i < n; i++) r[i] = fabsf(a[i]);
    return r;
}

/* Reference results of the direct loops: value[0..3] = y, dx, dw, db and mag[0..3] the same
 * computed with |inputs| (the rounding scale of each sum). */
typedef struct reference { double *val[4], *mag[4]; } reference;

static double *to_double(const float *a, long n)
{
    double *r = calloc((size_t)n, sizeof(double));
    for (long i = 0; i < n; i++) r[i] = a[i];
    return r;
}

static reference make_reference(const cfg *k, const made *m, const lm_tensor *seed)
{
    long nx = lm_tensor_numel(m->x), nw = lm_tensor_numel(m->w), ny = lm_tensor_numel(seed);
    long len[4] = {ny, nx, nw, k->Cout};
    reference R;
    for (int i = 1; i < 4; i++) {
        R.val[i] = calloc((size_t)len[i], sizeof(double));
        R.mag[i] = calloc((size_t)len[i], sizeof(double));
    }
    float *y = calloc((size_t)ny, sizeof(float)), *ymag = calloc((size_t)ny, sizeof(float));
    direct(k, m->x->data, m->w->data, m->b ? m->b->data : NULL, y, seed->data, R.val[1],
           R.val[2], R.val[3]);
    float *ax = abs_copy(m->x->data, nx), *aw = abs_copy(m->w->data, nw);
    float *ab = m->b ? abs_copy(m->b->data, k->Cout) : NULL, *as = abs_copy(seed->data, ny);
    direct(k, ax, aw, ab, ymag, as, R.mag[1], R.mag[2], R.mag[3]);
    R.val[0] = to_double(y, ny);
    R.mag[0] = to_double(ymag, ny);
    free(y), free(ymag), free(ax), free(aw), free(ab), free(as);
    return R;
}

static void free_reference(reference *R)
{
    for (int i = 0; i < 4; i++) free(R->val[i]), free(R->mag[i]);
}

/* Forward and all gradients against the direct loops, for each (path, threads) variant,
 * within tol * (1 + magnitude of the sum). */
static void check_config_paths(const cfg *k, const int (*variants)[2], int nvar, double tol)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_rng r;
    lm_rng_seed(&r, 100 + (uint64_t)(k - CFGS));
    made m = make_inputs(&c, k, &r, 1);
    lm_ctx_set_grad(&c, 0); /* only for the output shape */
    lm_tensor *y = lm_conv2d(&c, m.x, m.w, m.b, &k->o);
    lm_ctx_set_grad(&c, 1);
    lm_tensor *seed = y ? lm_tensor_uniform(&c, y->ndim, y->shape, &r, -1, 1) : NULL;
    CHECK_CTX_OK(&c);
    if (!seed) {
        lm_ctx_free(&c);
        return;
    }
    reference R = make_reference(k, &m, seed);
    long n[4] = {lm_tensor_numel(y), lm_tensor_numel(m.x), lm_tensor_numel(m.w), k->Cout};
    static const char *names[4] = {"y", "dx", "dw", "db"};
    for (int v = 0; v < nvar; v++) {
        int old = lm_conv2d_set_path(&c, variants[v][0]);
        c.nthreads = variants[v][1];
        lm_tape_clear(&c); /* earlier variants' nodes stay on the tape but are skipped */
        y = lm_conv2d(&c, m.x, m.w, m.b, &k->o);
        CHECK(y && lm_backward(&c, y, seed) == LM_OK);
        CHECK_CTX_OK(&c);
        const float *got[4] = {y ? y->data : NULL, m.x->grad ? m.x->grad->data : NULL,
                               m.w->grad ? m.w->grad->data : NULL,
                               m.b && m.b->grad ? m.b->grad->data : NULL};
        for (int i = 0; i < (m.b ? 4 : 3); i++)
            if (got[i]) check_doubles(got[i], R.val[i], R.mag[i], n[i], tol, k->what, names[i]);
        lm_conv2d_set_path(&c, old);
    }
    free_reference(&R);
    lm_ctx_free(&c);
}

/* The fast paths but Winograd (tiled, direct, depthwise; Winograd has its own tolerance,
 * below) on 2 and 3 threads and the SIMPLE path, to 1e-6. */
static void check_config(const cfg *k)
{
    static const int variants[3][2] = {{LM_CONV_PATH_NO_WINOGRAD, 2},
                                       {LM_CONV_PATH_NO_WINOGRAD, 3}, {LM_CONV_PATH_SIMPLE, 2}};
    check_config_paths(k, variants, 3, 1e-6);
}

static void test_forward_backward_vs_direct(void)
{
    for (int i = 0; i < NCFG; i++) check_config(&CFGS[i]);
}

/* 3x3 stride-1 convs that take the Winograd F(4x4, 3x3) path: edges that are not multiples
 * of the 4 x 4 tile, padding 0/1/2, several chunks of tiles, uneven channel counts. */
static const cfg WINO[] = {
    {2, 16, 13, 18, 16, 3, 3, {1, 1, 1, 1, 1, 1, 1}, 1, "winograd 16->16 13x18"},
    {1, 24, 9, 7, 20, 3, 3, {1, 1, 0, 0, 1, 1, 1}, 0, "winograd pad 0"},
    {3, 17, 8, 8, 33, 3, 3, {1, 1, 2, 2, 1, 1, 1}, 1, "winograd pad 2, 17->33"},
    {1, 20, 11, 9, 18, 3, 3, {1, 1, 1, 0, 1, 1, 1}, 1, "winograd pad (1,0)"},
    {2, 64, 22, 16, 64, 3, 3, {1, 1, 1, 1, 1, 1, 1}, 1, "winograd 64->64"},
    {4, 16, 40, 44, 16, 3, 3, {1, 1, 1, 1, 1, 1, 1}, 0, "winograd several chunks"},
    {2, 13, 12, 40, 8, 3, 3, {1, 1, 1, 1, 1, 1, 1}, 1, "winograd 13->8 (rt-8's first conv)"},
    /* a tile group spans 4 x 16 output columns with AVX-512 (4 x 8 without): full groups */
    {2, 16, 10, 70, 16, 3, 3, {1, 1, 1, 1, 1, 1, 1}, 1, "winograd 70 wide (full + partial group)"},
    {1, 8, 9, 130, 12, 3, 3, {1, 1, 0, 1, 1, 1, 1}, 1, "winograd 130 wide, pad (0,1)"},
    /* input read straight from x: groups inside the image (plain loads) and at both edges
     * (masked loads), pad 0 and 1 (pad 2 at the edges above; its corner outputs sum few
     * terms of a tile whose other values are large, so they round beyond this tolerance) */
    {1, 8, 9, 200, 8, 3, 3, {1, 1, 1, 1, 1, 1, 1}, 1, "winograd 200 wide (interior groups)"},
    {1, 8, 6, 203, 8, 3, 3, {1, 1, 1, 1, 1, 1, 1}, 0, "winograd 203 wide"},
    {1, 8, 7, 140, 8, 3, 3, {1, 1, 0, 0, 1, 1, 1}, 0, "winograd 140 wide, pad 0"},
};
#define NWINO ((int)(sizeof WINO / sizeof WINO[0]))

static lm_conv_geom geom_of(const cfg *k)
{
    lm_conv_geom g;
    memset(&g, 0, sizeof g);
    g.B = k->B, g.Cin = k->Cin, g.H = k->H, g.W = k->W, g.Cout = k->Cout, g.kh = k->kh;
    g.kw = k->kw;
    opts_of(k, &g.sh, &g.sw, &g.ph, &g.pw, &g.dh, &g.dw, &g.groups);
    g.Ho = outdim(k->H, k->kh, g.sh, g.ph, g.dh), g.Wo = outdim(k->W, k->kw, g.sw, g.pw, g.dw);
    return g;
}

/* A fast path's eligibility: every shape of `on` takes it, none of `off` does. */
static void check_applies(int (*applies)(const lm_conv_geom *), const char *path,
                          const cfg *on, int non, const cfg *off, int noff)
{
    for (int i = 0; i < non + noff; i++) {
        const cfg *k = i < non ? &on[i] : &off[i - non];
        lm_conv_geom g = geom_of(k);
        CHECK_MSG(!applies(&g) == !(i < non), "%s: %son the %s path", k->what,
                  i < non ? "not " : "", path);
    }
}

/* AUTO on 1, 2 and 3 threads (the paths under test). */
static const int AUTO_123[3][2] = {{LM_CONV_PATH_AUTO, 1}, {LM_CONV_PATH_AUTO, 2},
                                   {LM_CONV_PATH_AUTO, 3}};

/* Winograd (AUTO) on 1, 2 and 3 threads against the direct loops in double. F(4x4, 3x3)
 * rounds more than a plain sum (its transforms scale terms by up to 8 and 1/24): 4e-6 of the
 * magnitude; the tiled path it replaces is held to 1e-6 on the same shapes. A wrong
 * transform coefficient gives errors of the order of the values themselves. */
static void test_winograd_vs_direct(void)
{
    static const int tiled[2][2] = {{LM_CONV_PATH_NO_WINOGRAD, 2}, {LM_CONV_PATH_SIMPLE, 1}};
    /* Winograd's transforms round more than a direct sum: 4e-6 of the terms' magnitude with
     * FMA (avx2 and up); the generic level rounds each multiply and add apart, 5x that */
    const double tol = lm_isa_active() >= LM_ISA_AVX2 ? 4e-6 : 2e-5;
    for (int i = 0; i < NWINO; i++) {
        check_config_paths(&WINO[i], AUTO_123, 3, tol);
        check_config_paths(&WINO[i], tiled, 2, 1e-6);
    }
    /* shapes the Winograd path must leave alone */
    static const cfg other[] = {
        {1, 16, 9, 9, 16, 3, 3, {2, 2, 1, 1, 1, 1, 1}, 0, "stride 2"},
        {1, 16, 9, 9, 16, 3, 3, {1, 1, 2, 2, 2, 2, 1}, 0, "dilation 2"},
        {1, 16, 9, 9, 16, 3, 3, {1, 1, 1, 1, 1, 1, 2}, 0, "groups 2"},
        {1, 4, 9, 9, 16, 3, 3, {1, 1, 1, 1, 1, 1, 1}, 0, "4 input channels"},
        {1, 16, 9, 9, 7, 3, 3, {1, 1, 1, 1, 1, 1, 1}, 0, "7 output channels"},
        {1, 16, 9, 9, 16, 3, 3, {1, 1, 3, 3, 1, 1, 1}, 0, "pad 3"},
        {1, 16, 9, 9, 16, 5, 5, {1, 1, 2, 2, 1, 1, 1}, 0, "5x5"},
    };
    check_applies(lm_conv2d_winograd_applies, "Winograd", WINO, NWINO, other,
                  (int)(sizeof other / sizeof other[0]));
}

/* bf16 operands (lm_ctx.precision): the Winograd forward and input gradient against the
 * double reference. Both products' operands are the transformed input and weights rounded to
 * bf16 (2^-8 of themselves each); the transforms' coefficients (up to 5 in B^T, 8 in A^T) let
 * that grow, and an output's error comes from its whole 6 x 6 input patch, not its own terms:
 * so each element within 2^-4 of its terms' magnitude plus the tensor's mean magnitude, and
 * the error's typical size (rms over rms magnitude) near bf16's own, under 2^-7; the weight
 * gradient stays fp32 (4e-6, as above). The products run with the process's bf16 kernel
 * (AMX tiles on a CPU with them; AVX-512-BF16 in the isa run at avx512; the fp32 twin below). */
static void test_winograd_bf16(void)
{
    double worst = 0, e2 = 0, m2 = 0;
    long bad = 0;
    for (int i = 0; i < NWINO; i++) {
        const cfg *k = &WINO[i];
        lm_ctx c;
        lm_ctx_init(&c, 2);
        lm_rng r;
        lm_rng_seed(&r, 300 + (uint64_t)i);
        made m = make_inputs(&c, k, &r, 1);
        lm_ctx_set_grad(&c, 0);
        lm_tensor *y = lm_conv2d(&c, m.x, m.w, m.b, &k->o);
        lm_ctx_set_grad(&c, 1);
        lm_tensor *seed = y ? lm_tensor_uniform(&c, y->ndim, y->shape, &r, -1, 1) : NULL;
        if (!seed) {
            CHECK_CTX_OK(&c);
            lm_ctx_free(&c);
            continue;
        }
        reference R = make_reference(k, &m, seed);
        c.precision = LM_PRECISION_BF16;
        lm_tape_clear(&c);
        y = lm_conv2d(&c, m.x, m.w, m.b, &k->o);
        CHECK(y && lm_backward(&c, y, seed) == LM_OK);
        CHECK_CTX_OK(&c);
        if (y && m.x->grad && m.w->grad) {
            const float *got[2] = {y->data, m.x->grad->data};
            long n[2] = {lm_tensor_numel(y), lm_tensor_numel(m.x)};
            for (int t = 0; t < 2; t++) {
                double mean = 0;
                for (long j = 0; j < n[t]; j++) mean += R.mag[t][j] / (double)n[t];
                for (long j = 0; j < n[t]; j++) {
                    double d = fabs(got[t][j] - R.val[t][j]), mag = R.mag[t][j];
                    if (!(d <= (1.0 / 16) * (mag + mean))) bad++;
                    if (d / (mag + mean) > worst) worst = d / (mag + mean);
                    e2 += d * d, m2 += mag * mag;
                }
            }
            check_doubles(m.w->grad->data, R.val[2], R.mag[2], lm_tensor_numel(m.w), 4e-6,
                          k->what, "dw (fp32)");
        }
        free_reference(&R);
        lm_ctx_free(&c);
    }
    double rms = sqrt(e2 / m2);
    CHECK_MSG(bad == 0 && rms < 1.0 / 128, "%ld over the bound; worst %.3g of the magnitude plus "
              "the mean, rms %.3g", bad, worst, rms);
    /* the operands were rounded (fp32 products would leave ~1e-7): the bf16 kernel ran */
    CHECK_MSG(rms > 1e-5, "rms %.3g: no bf16 rounding seen", rms);
    printf("     (bf16 Winograd through the %s kernel: worst %.3g of the magnitude plus the "
           "mean, rms %.3g)\n", lm_bf16_kernel_name(lm_bf16_kernel_active()), worst, rms);
}

/* Output and input gradient of one Winograd conv in ctx c (grad on), copied to y / dx. */
static void wino_run(lm_ctx *c, const cfg *k, made *m, lm_tensor *seed, float *y, float *dx)
{
    lm_tape_clear(c);
    m->x->grad = NULL, m->w->grad = NULL; /* fresh gradients */
    lm_tensor *t = lm_conv2d(c, m->x, m->w, m->b, &k->o);
    CHECK(t && lm_backward(c, t, seed) == LM_OK);
    CHECK_CTX_OK(c);
    if (t && m->x->grad) {
        memcpy(y, t->data, sizeof(float) * (size_t)lm_tensor_numel(t));
        memcpy(dx, m->x->grad->data, sizeof(float) * (size_t)lm_tensor_numel(m->x));
    }
}

/* The transformed weights kept across calls (tensor/ops/wcache.h): a repeated call gives the
 * same bits as the first; after the weights change in place (same address, as an optimizer
 * step does) the result is that of the new weights, bit for bit what a context without a
 * store computes, in fp32 and in bf16; the store holds one entry per direction and
 * precision, within its bound. */
static void test_weight_cache(void)
{
    const cfg *k = &WINO[0];
    lm_ctx c, fresh;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 77);
    made m = make_inputs(&c, k, &r, 1);
    lm_ctx_set_grad(&c, 0);
    lm_tensor *y0 = lm_conv2d(&c, m.x, m.w, m.b, &k->o);
    lm_ctx_set_grad(&c, 1);
    lm_tensor *seed = y0 ? lm_tensor_uniform(&c, y0->ndim, y0->shape, &r, -1, 1) : NULL;
    CHECK(seed != NULL);
    if (!seed) {
        lm_ctx_free(&c);
        return;
    }
    long ny = lm_tensor_numel(y0), nx = lm_tensor_numel(m.x);
    size_t by = sizeof(float) * (size_t)ny, bx = sizeof(float) * (size_t)nx;
    float *ya = malloc(by), *yb = malloc(by), *yf = malloc(by);
    float *da = malloc(bx), *db = malloc(bx), *df = malloc(bx);
    int entries;
    size_t held;
    for (int prec = 0; prec < 2 && ya && yb && yf && da && db && df; prec++) {
        c.precision = prec ? LM_PRECISION_BF16 : LM_PRECISION_FP32;
        wino_run(&c, k, &m, seed, ya, da);
        wino_run(&c, k, &m, seed, yb, db); /* from the store */
        CHECK_MSG(!memcmp(ya, yb, by) && !memcmp(da, db, bx), "precision %d: a repeated call "
                  "differs", prec);
        lm_wcache_stats(&c, &entries, &held);
        CHECK_MSG(entries == 2 * (prec + 1) && held > 0 && held <= LM_WCACHE_BYTES,
                  "precision %d: %d entries, %zu bytes", prec, entries, held);
        for (long i = 0; i < lm_tensor_numel(m.w); i += 7) m.w->data[i] += 0.25f; /* in place */
        wino_run(&c, k, &m, seed, yb, db);
        CHECK_MSG(memcmp(ya, yb, by) != 0, "precision %d: the old weights' result", prec);
        /* the same tensors in a context with an empty store */
        lm_ctx_init(&fresh, 2);
        fresh.precision = c.precision;
        lm_tape_clear(&fresh);
        m.x->grad = NULL, m.w->grad = NULL;
        lm_tensor *t = lm_conv2d(&fresh, m.x, m.w, m.b, &k->o);
        CHECK(t && lm_backward(&fresh, t, seed) == LM_OK);
        CHECK_CTX_OK(&fresh);
        if (t && m.x->grad) {
            memcpy(yf, t->data, by);
            memcpy(df, m.x->grad->data, bx);
            CHECK_MSG(!memcmp(yf, yb, by) && !memcmp(df, db, bx), "precision %d: changed "
                      "weights: the stored result differs from a fresh context's", prec);
        }
        lm_ctx_free(&fresh);
    }
    free(ya), free(yb), free(yf), free(da), free(db), free(df);
    lm_ctx_free(&c);
}

/* 1x1 convs on the pointwise path (a plain sum, held to 1e-6 like the tiled path): pixel
 * counts with 16-column blocks, one 8-column block and a scalar tail, output channels that
 * are not a multiple of the 6-row panel. */
static void test_pointwise_vs_direct(void)
{
    static const cfg pw[] = {
        {2, 20, 7, 9, 33, 1, 1, {1, 1, 0, 0, 1, 1, 1}, 1, "pointwise 20->33, 63 pixels"},
        {1, 12, 16, 40, 6, 1, 1, {1, 1, 0, 0, 1, 1, 1}, 0, "pointwise 12->6, 640 pixels"},
        {3, 5, 3, 8, 13, 1, 1, {1, 1, 0, 0, 1, 1, 1}, 1, "pointwise 5->13, 24 pixels"},
        {1, 64, 33, 32, 64, 1, 1, {1, 1, 0, 0, 1, 1, 1}, 1, "pointwise 64->64, several blocks"},
    };
    int npw = (int)(sizeof pw / sizeof pw[0]);
    for (int i = 0; i < npw; i++) check_config_paths(&pw[i], AUTO_123, 3, 1e-6);
    static const cfg other[] = {
        {1, 4, 9, 9, 6, 1, 1, {2, 2, 0, 0, 1, 1, 1}, 0, "1x1 stride 2"},
        {1, 4, 9, 9, 6, 1, 1, {1, 1, 1, 1, 1, 1, 1}, 0, "1x1 pad 1"},
        {1, 4, 9, 9, 6, 1, 1, {1, 1, 0, 0, 1, 1, 2}, 0, "1x1 groups 2"},
    };
    check_applies(lm_conv2d_pointwise_applies, "pointwise", pw, npw, other,
                  (int)(sizeof other / sizeof other[0]));
}

/* Hand-computed: 1 x 1 x 3 x 3 image, 2x2 kernel, pad 1, stride 2, bias 0.5. */
static void test_hand_computed(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_from(&c, 4, (int[]){1, 1, 3, 3}, (float[]){1, 2, 3, 4, 5, 6, 7, 8, 9});
    lm_tensor *w = lm_tensor_from(&c, 4, (int[]){1, 1, 2, 2}, (float[]){1, 10, 100, 1000});
    lm_tensor *b = lm_tensor_from(&c, 1, (int[]){1}, (float[]){0.5f});
    lm_conv2d_opts o = {2, 2, 1, 1, 0, 0, 0};
    lm_tensor *y = lm_conv2d(&c, x, w, b, &o);
    /* outputs at (oy, ox) cover input rows 2oy-1.., cols 2ox-1..; 2x2 output */
    float expect[4] = {1000 * 1 + 0.5f, 100 * 2 + 1000 * 3 + 0.5f, 10 * 4 + 1000 * 7 + 0.5f,
                       1 * 5 + 10 * 6 + 100 * 8 + 1000 * 9 + 0.5f};
    CHECK(y && y->shape[2] == 2 && y->shape[3] == 2);
    if (y) CHECK_ARRAY_CLOSE(y->data, expect, 4, 0, 1e-6);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* ---- finite differences ------------------------------------------------------------------ */
static lm_tensor *fn_conv(lm_ctx *c, lm_tensor *const *in, int nin, void *user)
{
    return lm_conv2d(c, in[0], in[1], nin > 2 ? in[2] : NULL, user);
}

static void gradcheck_config(const cfg *k, int path)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 7);
    made m = make_inputs(&c, k, &r, 1);
    lm_tensor *in[3] = {m.x, m.w, m.b};
    lm_gradcheck_opts go;
    lm_gradcheck_default_opts(&go);
    go.atol = 1e-3;
    go.rtol = 5e-3;
    go.max_checks = 60;
    /* conv2d is linear in each input, so central differences are exact for any step: a large
     * one keeps the forward's rounding (Winograd's, without FMA, a few 1e-5) out of the check */
    go.eps = 0.1;
    int old = lm_conv2d_set_path(&c, path);
    CHECK_GRAD(&c, fn_conv, in, m.b ? 3 : 2, (void *)&k->o, &go);
    lm_conv2d_set_path(&c, old);
    lm_ctx_free(&c);
}

static void test_gradcheck(void)
{
    static const cfg small[] = {
        {2, 4, 5, 6, 3, 3, 3, {1, 1, 1, 1, 1, 1, 1}, 1, "3x3"},
        {1, 4, 7, 6, 4, 3, 2, {2, 1, 1, 0, 2, 1, 2}, 1, "strided dilated groups 2"},
        {2, 3, 6, 7, 3, 5, 3, {1, 1, 2, 1, 1, 1, 3}, 1, "depthwise 5x3"},
        {1, 2, 6, 6, 4, 4, 4, {2, 2, 1, 1, 1, 1, 2}, 0, "depthwise x2 4x4 s2"},
        {2, 3, 4, 5, 2, 1, 1, {1, 1, 0, 0, 1, 1, 1}, 1, "1x1"},
        {1, 8, 6, 9, 8, 3, 3, {1, 1, 1, 1, 1, 1, 1}, 1, "3x3 8->8 (Winograd under AUTO)"},
    };
    for (int i = 0; i < (int)(sizeof small / sizeof small[0]); i++) {
        gradcheck_config(&small[i], LM_CONV_PATH_AUTO);
        gradcheck_config(&small[i], LM_CONV_PATH_SIMPLE);
    }
}

/* ---- fast path vs simple path, determinism, accumulation --------------------------------- */
typedef struct run_out { float *y, *dx, *dw, *db; long ny, nx, nw; } run_out;

static run_out run_once(const cfg *k, int path, int nthreads, int pre)
{
    lm_ctx c;
    lm_ctx_init(&c, nthreads);
    lm_rng r;
    lm_rng_seed(&r, 5);
    made m = make_inputs(&c, k, &r, 1);
    run_out o = {0};
    if (pre) { /* gradients already hold 1: backward must add */
        lm_tensor_fill(lm_grad(&c, m.x), 1.0f);
        lm_tensor_fill(lm_grad(&c, m.w), 1.0f);
        if (m.b) lm_tensor_fill(lm_grad(&c, m.b), 1.0f);
    }
    int old = lm_conv2d_set_path(&c, path);
    lm_tensor *y = lm_conv2d(&c, m.x, m.w, m.b, &k->o);
    lm_tensor *seed = y ? lm_tensor_uniform(&c, 4, y->shape, &r, -1, 1) : NULL;
    if (y && seed && lm_backward(&c, y, seed) == LM_OK) {
        o.ny = lm_tensor_numel(y), o.nx = lm_tensor_numel(m.x), o.nw = lm_tensor_numel(m.w);
        o.y = malloc(sizeof(float) * (size_t)o.ny);
        o.dx = malloc(sizeof(float) * (size_t)o.nx);
        o.dw = malloc(sizeof(float) * (size_t)o.nw);
        o.db = calloc((size_t)k->Cout, sizeof(float));
        memcpy(o.y, y->data, sizeof(float) * (size_t)o.ny);
        memcpy(o.dx, m.x->grad->data, sizeof(float) * (size_t)o.nx);
        memcpy(o.dw, m.w->grad->data, sizeof(float) * (size_t)o.nw);
        if (m.b) memcpy(o.db, m.b->grad->data, sizeof(float) * (size_t)k->Cout);
    }
    CHECK_CTX_OK(&c);
    lm_conv2d_set_path(&c, old);
    lm_ctx_free(&c);
    return o;
}

static void free_run(run_out *o) { free(o->y), free(o->dx), free(o->dw), free(o->db); }

static void test_fast_matches_simple(void)
{
    cfg big[] = {
        {3, 48, 20, 22, 40, 3, 3, {1, 1, 1, 1, 1, 1, 1}, 1, "3x3 48->40"},
        {2, 32, 17, 16, 32, 1, 1, {1, 1, 0, 0, 1, 1, 1}, 1, "1x1 32->32"},
        {2, 16, 18, 20, 16, 7, 7, {1, 1, 3, 3, 1, 1, 16}, 0, "depthwise 7x7"},
        {1, 24, 21, 19, 24, 4, 4, {2, 2, 1, 1, 1, 1, 3}, 1, "groups 3 4x4 s2"},
        {2, 200, 15, 17, 24, 3, 3, {1, 1, 1, 1, 1, 1, 1}, 1, "3x3 200->24, chunks"},
    };
    for (int i = 0; i < (int)(sizeof big / sizeof big[0]); i++) { /* (Winograd: above) */
        run_out f = run_once(&big[i], LM_CONV_PATH_NO_WINOGRAD, 2, 0);
        run_out s = run_once(&big[i], LM_CONV_PATH_SIMPLE, 2, 0);
        /* the output is a sum of Cin/groups x kh x kw terms of |x w| ~ 0.25, summed in another
         * order by each path (the blocked SGEMM's order depends on the CPU): its rounding grows
         * with the sum's length, so the absolute tolerance scales with it beyond the 432 terms
         * of the first case (for 200 -> 24: 8e-5; one wrong term would be ~0.25) */
        const int G = big[i].o.groups ? big[i].o.groups : 1;
        const double terms = (double)(big[i].Cin / G) * big[i].kh * big[i].kw;
        const double ytol = 2e-5 * (terms > 432 ? terms / 432 : 1.0);
        if (f.y && s.y) {
            CHECK_ARRAY_CLOSE(f.y, s.y, f.ny, ytol, 1e-5);
            CHECK_ARRAY_CLOSE(f.dx, s.dx, f.nx, 2e-5, 1e-5);
            CHECK_ARRAY_CLOSE(f.dw, s.dw, f.nw, 1e-4, 1e-5);
            CHECK_ARRAY_CLOSE(f.db, s.db, big[i].Cout, 1e-4, 1e-5);
        } else
            CHECK(!"run failed");
        free_run(&f), free_run(&s);
    }
}

static void test_deterministic_and_accumulating(void)
{
    /* several tiles per image (tiled path), several chunks (Winograd path), several column
     * blocks (pointwise path) */
    static const cfg pw = {2, 24, 30, 40, 20, 1, 1, {1, 1, 0, 0, 1, 1, 1}, 1, "pointwise blocks"};
    /* Winograd hands chunks (and groups of chunks for the weight gradient) to threads as they
     * come free: with 32-tile chunks this one has 20 chunks, and the repeated runs below see
     * different hand-outs; the results must not change */
    static const cfg wi = {4, 16, 40, 44, 16, 3, 3, {1, 1, 1, 1, 1, 1, 1}, 1, "winograd chunks"};
    setenv("LM_WINOGRAD_CHUNK_KB", "64", 1);
    const cfg *ks[3] = {&CFGS[NCFG - 3], &wi, &pw};
    for (int kk = 0; kk < 3; kk++) {
    const cfg *k = ks[kk];
    for (int nt = 1; nt <= 3; nt++) {
        run_out a = run_once(k, LM_CONV_PATH_AUTO, nt, 0);
        run_out b = run_once(k, LM_CONV_PATH_AUTO, nt, 0);
        for (int rep = 0; rep < 4 && nt > 1 && a.y && b.y; rep++) {
            run_out q = run_once(k, LM_CONV_PATH_AUTO, nt, 0);
            CHECK(q.y && memcmp(a.y, q.y, sizeof(float) * (size_t)a.ny) == 0 &&
                  memcmp(a.dx, q.dx, sizeof(float) * (size_t)a.nx) == 0 &&
                  memcmp(a.dw, q.dw, sizeof(float) * (size_t)a.nw) == 0);
            free_run(&q);
        }
        run_out p = run_once(k, LM_CONV_PATH_AUTO, nt, 1);
        if (!a.y || !b.y || !p.y) {
            CHECK(!"run failed");
            continue;
        }
        CHECK(memcmp(a.y, b.y, sizeof(float) * (size_t)a.ny) == 0);
        CHECK(memcmp(a.dx, b.dx, sizeof(float) * (size_t)a.nx) == 0);
        CHECK(memcmp(a.dw, b.dw, sizeof(float) * (size_t)a.nw) == 0);
        for (long i = 0; i < a.nx; i++) a.dx[i] += 1.0f;
        for (long i = 0; i < a.nw; i++) a.dw[i] += 1.0f;
        for (int i = 0; i < k->Cout; i++) a.db[i] += 1.0f;
        CHECK_ARRAY_CLOSE(p.dx, a.dx, a.nx, 1e-5, 1e-6);
        CHECK_ARRAY_CLOSE(p.dw, a.dw, a.nw, 1e-4, 1e-6);
        if (k->bias) CHECK_ARRAY_CLOSE(p.db, a.db, k->Cout, 1e-4, 1e-6);
        free_run(&a), free_run(&b), free_run(&p);
    }
    }
    unsetenv("LM_WINOGRAD_CHUNK_KB");
}

/* A strided (sliced) input is made contiguous first and gets its gradient through the view. */
static void test_strided_input(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 9);
    lm_tensor *xf = lm_tensor_uniform(&c, 4, (int[]){2, 3, 8, 10}, &r, -1, 1);
    lm_tensor *w = lm_tensor_uniform(&c, 4, (int[]){4, 3, 3, 3}, &r, -1, 1);
    lm_tensor_set_requires_grad(xf, 1);
    lm_tensor *xs = lm_slice(&c, xf, 3, 2, 7);
    lm_tensor *xc = lm_tensor_new4(&c, 2, 3, 8, 7);
    for (int b = 0; b < 2; b++)
        for (int ch = 0; ch < 3; ch++)
            for (int i = 0; i < 8; i++)
                for (int j = 0; j < 7; j++) *lm_at4(xc, b, ch, i, j) = *lm_at4(xf, b, ch, i, j + 2);
    lm_conv2d_opts o = {1, 1, 1, 1, 1, 1, 1};
    lm_tensor *y1 = lm_conv2d(&c, xs, w, NULL, &o), *y2 = lm_conv2d(&c, xc, w, NULL, &o);
    CHECK(y1 && y2);
    if (y1 && y2) CHECK_ARRAY_CLOSE(y1->data, y2->data, lm_tensor_numel(y1), 0, 0);
    CHECK(lm_backward(&c, y1, NULL) == LM_OK);
    CHECK(xf->grad && xf->grad->data[0] == 0.0f && xf->grad->data[2] != 0.0f);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* ---- errors -------------------------------------------------------------------------------- */
static void expect_fail(lm_ctx *c, lm_tensor *y, lm_status s, const char *extra)
{
    CHECK(y == NULL);
    CHECK_MSG(strstr(c->msg, "conv2d") != NULL, "message: %s", c->msg);
    if (extra) CHECK_MSG(strstr(c->msg, extra) != NULL, "message: %s (want %s)", c->msg, extra);
    CHECK_CTX_FAILED(c, s);
}

static void test_errors(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_zeros(&c, 4, (int[]){2, 6, 5, 5});
    lm_tensor *w = lm_tensor_zeros(&c, 4, (int[]){4, 6, 3, 3});
    lm_conv2d_opts g4 = {0, 0, 0, 0, 0, 0, 4}, g2 = {0, 0, 0, 0, 0, 0, 2};
    /* channel mismatch */
    expect_fail(&c, lm_conv2d(&c, x, lm_tensor_zeros(&c, 4, (int[]){4, 5, 3, 3}), NULL, NULL),
                LM_ERR_SHAPE, "2x6x5x5");
    /* Cin % groups */
    expect_fail(&c, lm_conv2d(&c, x, lm_tensor_zeros(&c, 4, (int[]){4, 1, 3, 3}), NULL, &g4),
                LM_ERR_SHAPE, "groups");
    /* Cout % groups */
    expect_fail(&c, lm_conv2d(&c, x, lm_tensor_zeros(&c, 4, (int[]){5, 3, 3, 3}), NULL, &g2),
                LM_ERR_SHAPE, NULL);
    /* kernel larger than the padded input: 5 + 2*1 < 9 */
    lm_conv2d_opts p1 = {0, 0, 1, 1, 0, 0, 0};
    expect_fail(&c, lm_conv2d(&c, x, lm_tensor_zeros(&c, 4, (int[]){4, 6, 9, 3}), NULL, &p1),
                LM_ERR_SHAPE, "larger");
    /* ... also through dilation: 3x3 dilation 3 spans 7 */
    lm_conv2d_opts d3 = {0, 0, 0, 0, 3, 3, 0};
    expect_fail(&c, lm_conv2d(&c, x, w, NULL, &d3), LM_ERR_SHAPE, "larger");
    /* wrong bias size, wrong bias rank */
    expect_fail(&c, lm_conv2d(&c, x, w, lm_tensor_zeros(&c, 1, (int[]){3}), NULL), LM_ERR_SHAPE,
                "bias");
    expect_fail(&c, lm_conv2d(&c, x, w, lm_tensor_zeros(&c, 2, (int[]){4, 1}), NULL),
                LM_ERR_SHAPE, "bias");
    /* not 4-D */
    expect_fail(&c, lm_conv2d(&c, lm_tensor_zeros(&c, 3, (int[]){6, 5, 5}), w, NULL, NULL),
                LM_ERR_SHAPE, NULL);
    /* bad options */
    lm_conv2d_opts neg = {-1, 1, 0, 0, 0, 0, 0}, negpad = {0, 0, -1, 0, 0, 0, 0};
    expect_fail(&c, lm_conv2d(&c, x, w, NULL, &neg), LM_ERR_ARG, NULL);
    expect_fail(&c, lm_conv2d(&c, x, w, NULL, &negpad), LM_ERR_ARG, NULL);
    /* NULL input (after an earlier failure) */
    CHECK(lm_conv2d(&c, NULL, w, NULL, NULL) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    /* the exact fit works: kernel = padded input -> 1x1 output */
    lm_tensor *y = lm_conv2d(&c, x, lm_tensor_zeros(&c, 4, (int[]){4, 6, 7, 7}), NULL, &p1);
    CHECK(y && y->shape[2] == 1 && y->shape[3] == 1);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

int main(void)
{
    RUN(test_hand_computed);
    RUN(test_forward_backward_vs_direct);
    RUN(test_winograd_vs_direct);
    RUN(test_winograd_bf16);
    RUN(test_weight_cache);
    RUN(test_pointwise_vs_direct);
    RUN(test_gradcheck);
    RUN(test_fast_matches_simple);
    RUN(test_deterministic_and_accumulating);
    RUN(test_strided_input);
    RUN(test_errors);
    return check_summary();
}

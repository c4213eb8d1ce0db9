/* test_fft2.c — the complex ops (tensor/ops/fft2.c, complex.c, area_sample.c): lm_fft2 against a
 * direct double-precision DFT on odd and even sizes, the inverse round trip, the adjoint
 * identity <A x, y> = <x, A^H y>, gradient checks of fft2 / ifft2 / polar / abs2 / cmul /
 * area_sample, area_sample against a direct evaluation of its definition, and shape errors. */
#include "tests/check.h"
#include "tensor/op_params.h"
#include <stdlib.h>

/* Direct DFT in double of B transforms of H x W (complex interleaved). */
static void ref_dft(const float *x, double *y, int B, int H, int W, int sign, double scale)
{
    for (int b = 0; b < B; b++)
        for (int k = 0; k < H; k++)
            for (int l = 0; l < W; l++) {
                double sr = 0, si = 0;
                for (int n = 0; n < H; n++)
                    for (int m = 0; m < W; m++) {
                        double a = sign * 2 * M_PI * ((double)(k * n % H) / H +
                                                      (double)(l * m % W) / W);
                        const float *v = x + 2 * (((long)b * H + n) * W + m);
                        sr += v[0] * cos(a) - v[1] * sin(a);
                        si += v[0] * sin(a) + v[1] * cos(a);
                    }
                double *o = y + 2 * (((long)b * H + k) * W + l);
                o[0] = scale * sr;
                o[1] = scale * si;
            }
}

static void test_fft2_matches_direct_dft(void)
{
    static const int sizes[][2] = {{1, 1}, {2, 3}, {4, 4}, {5, 7}, {6, 5}, {8, 12}, {9, 9}};
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 11);
    for (int s = 0; s < 7; s++) {
        int H = sizes[s][0], W = sizes[s][1], B = 3;
        lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){B, H, W, 2}, &r, -1, 1);
        long n = 2L * B * H * W;
        double *ref = malloc((size_t)n * sizeof(double));
        for (int inv = 0; inv < 2; inv++) {
            lm_tensor *y = lm_fft2(&c, x, inv);
            CHECK(y && lm_tensor_same_shape(x, y));
            if (!y) continue;
            ref_dft(x->data, ref, B, H, W, inv ? 1 : -1, inv ? 1.0 / (H * W) : 1.0);
            long bad = 0;
            for (long i = 0; i < n; i++) bad += !(fabs(y->data[i] - ref[i]) <= 2e-6 * (H * W));
            CHECK_MSG(bad == 0, "%s %d x %d: %ld of %ld off", inv ? "ifft2" : "fft2", H, W, bad,
                      n);
        }
        /* round trip */
        lm_tensor *z = lm_fft2(&c, lm_fft2(&c, x, 0), 1);
        if (z) CHECK_ARRAY_CLOSE(z->data, x->data, n, 1e-5, 1e-5);
        free(ref);
        lm_ctx_reset(&c);
    }
    /* a 5-D tensor: the leading dims all batch */
    lm_tensor *x = lm_tensor_uniform(&c, 5, (int[]){2, 3, 4, 6, 2}, &r, -1, 1);
    lm_tensor *y = lm_fft2(&c, x, 0);
    double *ref = malloc(2 * 6 * 24 * sizeof(double));
    ref_dft(x->data, ref, 6, 4, 6, -1, 1.0);
    long bad = 0;
    for (long i = 0; y && i < 2 * 6 * 24; i++) bad += !(fabs(y->data[i] - ref[i]) <= 1e-4);
    CHECK(y && bad == 0);
    free(ref);
    /* a delta at (1, 2) of a 4 x 8 grid: exp(-2 pi i (k / 4 + 2 l / 8)) */
    lm_tensor *d = lm_tensor_zeros(&c, 3, (int[]){4, 8, 2});
    d->data[2 * (1 * 8 + 2)] = 1;
    lm_tensor *D = lm_fft2(&c, d, 0);
    CHECK_CLOSE(D->data[2 * (1 * 8 + 1)], cos(-2 * M_PI * (0.25 + 0.25)), 1e-6, 0);
    CHECK_CLOSE(D->data[2 * (3 * 8 + 3) + 1], sin(-2 * M_PI * (0.75 + 0.75)), 1e-6, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* Backward of the forward transform applied to a delta gradient: the adjoint identity. */
static void test_fft2_adjoint(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_rng r;
    lm_rng_seed(&r, 5);
    for (int inv = 0; inv < 2; inv++) {
        lm_tensor *x = lm_tensor_uniform(&c, 3, (int[]){5, 6, 2}, &r, -1, 1);
        lm_tensor *w = lm_tensor_uniform(&c, 3, (int[]){5, 6, 2}, &r, -1, 1);
        lm_tensor_set_requires_grad(x, 1);
        lm_tensor *y = lm_fft2(&c, x, inv);
        CHECK(lm_backward(&c, y, w) == LM_OK);
        /* <w, A x> (real inner product of the interleaved vectors) = <A^T w, x> = <grad, x> */
        double lhs = 0, rhs = 0;
        for (int i = 0; i < 60; i++) lhs += (double)w->data[i] * y->data[i];
        for (int i = 0; i < 60; i++) rhs += (double)x->grad->data[i] * x->data[i];
        CHECK_CLOSE(rhs, lhs, 1e-4, 1e-5);
        lm_ctx_reset(&c);
    }
    lm_ctx_free(&c);
}

typedef struct sel { int k; } sel;
static lm_tensor *fn_ops(lm_ctx *c, lm_tensor *const *in, int nin, void *user)
{
    (void)nin;
    switch (((sel *)user)->k) {
    case 0: return lm_fft2(c, in[0], 0);
    case 1: return lm_fft2(c, in[0], 1);
    case 2: return lm_polar(c, in[0], in[1]);
    case 3: return lm_abs2(c, in[0]);
    case 4: return lm_cmul(c, in[0], in[1]);
    case 5: return lm_area_sample(c, in[0], 5, 3, (const double[]){0.7, 1.3});
    default: return lm_abs2(c, lm_fft2(c, lm_polar(c, in[0], in[1]), 0)); /* a pupil -> PSF */
    }
}

static void test_complex_gradcheck(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_rng r;
    lm_rng_seed(&r, 21);
    lm_gradcheck_opts o;
    lm_gradcheck_default_opts(&o);
    o.eps = 1e-3;
    o.atol = 2e-3;
    o.rtol = 1e-2;
    static const char *names[7] = {"fft2 even", "ifft2 odd", "polar", "abs2", "cmul", "area",
                                   "pupil"};
    int shapes[7][5] = {{2, 4, 6, 2}, {3, 5, 2}, {4, 5}, {3, 4, 2}, {2, 3, 4, 2}, {2, 12, 12},
                        {5, 7}};
    int nd[7] = {4, 3, 2, 3, 4, 3, 2};
    for (int k = 0; k < 7; k++) {
        lm_tensor *in[2] = {lm_tensor_uniform(&c, nd[k], shapes[k], &r, -1, 1), NULL};
        int nin = 1;
        if (k == 2 || k == 6) in[1] = lm_tensor_uniform(&c, nd[k], shapes[k], &r, -3, 3), nin = 2;
        if (k == 4) in[1] = lm_tensor_uniform(&c, 3, (int[]){3, 4, 2}, &r, -1, 1), nin = 2;
        for (int i = 0; i < nin; i++) lm_tensor_set_requires_grad(in[i], 1);
        sel s = {k};
        int before = check_failures_;
        CHECK_GRAD(&c, fn_ops, in, nin, &s, &o);
        if (check_failures_ != before) fprintf(stderr, "  op %s\n", names[k]);
        lm_ctx_reset(&c);
    }
    lm_ctx_free(&c);
}

static void test_complex_values(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *a = lm_tensor_from(&c, 1, (int[]){3}, (float[]){1, 2, 0.5f});
    lm_tensor *p = lm_tensor_from(&c, 1, (int[]){3}, (float[]){0, (float)(M_PI / 2), -1});
    lm_tensor *z = lm_polar(&c, a, p);
    CHECK(z && z->ndim == 2 && z->shape[1] == 2);
    CHECK_ARRAY_CLOSE(z->data, ((float[]){1, 0, 0, 2, 0.5f * cosf(-1), 0.5f * sinf(-1)}), 6,
                      1e-6, 0);
    lm_tensor *q = lm_abs2(&c, z);
    CHECK_ARRAY_CLOSE(q->data, ((float[]){1, 4, 0.25f}), 3, 1e-6, 1e-6);
    /* (1 + 2i)(3 - i) = 5 + 5i; (0 + 1i)(3 - i) = 1 + 3i; b repeated */
    lm_tensor *u = lm_tensor_from(&c, 2, (int[]){2, 2}, (float[]){1, 2, 0, 1});
    lm_tensor *v = lm_tensor_from(&c, 1, (int[]){2}, (float[]){3, -1});
    lm_tensor *w = lm_cmul(&c, u, v);
    CHECK_ARRAY_CLOSE(w->data, ((float[]){5, 5, 1, 3}), 4, 1e-6, 0);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* area_sample against its definition evaluated here (double), including wrapped negative
 * positions, an odd grid, and a window reaching past the grid (taps dropped). */
static double ref_area(const float *x, int N, double r, int S, int K, int i, int j)
{
    double acc = 0;
    for (int a = 0; a < K; a++)
        for (int b = 0; b < K; b++) {
            double u = r * (i - S / 2 + (a + 0.5) / K - 0.5);
            double v = r * (j - S / 2 + (b + 0.5) / K - 0.5);
            int y0 = (int)floor(u), x0 = (int)floor(v);
            if (y0 < -(N / 2) || y0 + 1 > N - N / 2 - 1 || x0 < -(N / 2) ||
                x0 + 1 > N - N / 2 - 1)
                continue;
            double ty = u - y0, tx = v - x0;
            for (int dy = 0; dy < 2; dy++)
                for (int dx = 0; dx < 2; dx++) {
                    int yy = ((y0 + dy) % N + N) % N, xx = ((x0 + dx) % N + N) % N;
                    acc += (dy ? ty : 1 - ty) * (dx ? tx : 1 - tx) * x[yy * N + xx];
                }
        }
    return acc;
}

static void test_area_sample_definition(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 4);
    int Ns[3] = {16, 15, 8};
    double ratios[3][2] = {{1.7, 0.9}, {2.2, 1.0}, {2.5, 3.1}};
    for (int t = 0; t < 3; t++) {
        int N = Ns[t], S = 5, K = 4;
        lm_tensor *x = lm_tensor_uniform(&c, 3, (int[]){2, N, N}, &r, 0, 1);
        lm_tensor *y = lm_area_sample(&c, x, S, K, ratios[t]);
        CHECK(y && y->shape[0] == 2 && y->shape[1] == S && y->shape[2] == S);
        if (!y) continue;
        long bad = 0;
        for (int b = 0; b < 2; b++)
            for (int i = 0; i < S; i++)
                for (int j = 0; j < S; j++) {
                    double e = ref_area(x->data + (long)b * N * N, N, ratios[t][b], S, K, i, j);
                    bad += !(fabs(y->data[(b * S + i) * S + j] - e) <= 1e-5 * (1 + fabs(e)));
                }
        CHECK_MSG(bad == 0, "N %d: %ld cells off", N, bad);
        lm_ctx_reset(&c);
    }
    /* the window's edge cells at ratio 3.1 on N = 8 reach past the grid: they lose taps */
    lm_tensor *one = lm_tensor_full(&c, 3, (int[]){1, 8, 8}, 1.0f);
    lm_tensor *y = lm_area_sample(&c, one, 5, 4, (const double[]){3.1});
    CHECK(y && y->data[12] == 16.0f && y->data[0] < 16.0f);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_complex_errors(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *x = lm_tensor_zeros(&c, 3, (int[]){4, 4, 3});
    CHECK(lm_fft2(&c, x, 0) == NULL && strstr(c.msg, "fft2: x is 4x4x3"));
    lm_ctx_clear_error(&c);
    CHECK(lm_fft2(&c, lm_tensor_zeros(&c, 2, (int[]){4, 2}), 1) == NULL &&
          strstr(c.msg, "ifft2"));
    lm_ctx_clear_error(&c);
    CHECK(lm_abs2(&c, lm_tensor_zeros(&c, 2, (int[]){4, 3})) == NULL && strstr(c.msg, "abs2"));
    lm_ctx_clear_error(&c);
    CHECK(lm_polar(&c, lm_tensor_zeros(&c, 1, (int[]){4}), lm_tensor_zeros(&c, 1, (int[]){3}))
          == NULL && strstr(c.msg, "polar"));
    lm_ctx_clear_error(&c);
    CHECK(lm_cmul(&c, lm_tensor_zeros(&c, 2, (int[]){4, 2}), lm_tensor_zeros(&c, 2, (int[]){3, 2}))
          == NULL && strstr(c.msg, "cmul"));
    lm_ctx_clear_error(&c);
    CHECK(lm_area_sample(&c, lm_tensor_zeros(&c, 3, (int[]){1, 4, 5}), 3, 2, (double[]){1}) ==
          NULL && strstr(c.msg, "area_sample"));
    lm_ctx_clear_error(&c);
    CHECK(lm_area_sample(&c, lm_tensor_zeros(&c, 3, (int[]){1, 4, 4}), 3, 2, (double[]){-1}) ==
          NULL && strstr(c.msg, "area_sample"));
    lm_ctx_clear_error(&c);
    CHECK(lm_fft2(&c, NULL, 0) == NULL && c.status);
    lm_ctx_free(&c);
}

int main(void)
{
    RUN(test_fft2_matches_direct_dft);
    RUN(test_fft2_adjoint);
    RUN(test_complex_values);
    RUN(test_complex_gradcheck);
    RUN(test_area_sample_definition);
    RUN(test_complex_errors);
    return check_summary();
}

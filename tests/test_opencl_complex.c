/* test_opencl_complex.c — the OpenCL twins of the complex ops (kernels-opencl/complex.cl) against
 * the CPU kernels: fft2 / ifft2 (direct DFT on the device vs FFTW) on odd and even sizes,
 * polar, abs2, cmul (both operands, b repeated), area_sample, and the pupil -> intensity chain.
 * Exit 77 only when no OpenCL platform exists. */
#include "tests/test_opencl_util.h"
#include "data/doe.h"

#define SHAPE(...) {__VA_ARGS__}

typedef struct sel { int k; } sel;
static lm_tensor *f_op(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n;
    switch (((sel *)u)->k) {
    case 0: return lm_fft2(c, in[0], 0);
    case 1: return lm_fft2(c, in[0], 1);
    case 2: return lm_polar(c, in[0], in[1]);
    case 3: return lm_abs2(c, in[0]);
    case 4: return lm_cmul(c, in[0], in[1]);
    case 5: return lm_area_sample(c, in[0], 7, 4, (const double[]){0.75, 1.25, 2.5});
    default: return lm_abs2(c, lm_fft2(c, lm_polar(c, in[0], in[1]), 0));
    }
}

static void test_fft(void)
{
    sel s0 = {0}, s1 = {1};
    agree_case a = {"fft2 8x12", f_op, &s0, 1, {4}, {SHAPE(3, 8, 12, 2)}, .atol = 1e-4,
                    .rtol = 1e-4};
    check_agree(&a, 1);
    agree_case b = {"fft2 7x5", f_op, &s0, 1, {5}, {SHAPE(2, 2, 7, 5, 2)}, .atol = 1e-4,
                    .rtol = 1e-4};
    check_agree(&b, 2);
    agree_case d = {"ifft2 9x16", f_op, &s1, 1, {3}, {SHAPE(9, 16, 2)}, .atol = 1e-5,
                    .rtol = 1e-4};
    check_agree(&d, 3);
}

static void test_elementwise(void)
{
    sel s2 = {2}, s3 = {3}, s4 = {4}, s6 = {6};
    agree_case p = {"polar", f_op, &s2, 2, {3, 3}, {SHAPE(3, 5, 7), SHAPE(3, 5, 7)}, {0, -9},
                    {1, 9}, .atol = 1e-5, .rtol = 1e-5};
    check_agree(&p, 4);
    agree_case q = {"polar (amp constant)", f_op, &s2, 2, {2, 2}, {SHAPE(40, 33), SHAPE(40, 33)},
                    .no_grad = {1, 0}, .atol = 1e-5, .rtol = 1e-5};
    check_agree(&q, 5);
    agree_case a = {"abs2", f_op, &s3, 1, {3}, {SHAPE(4, 50, 2)}, .atol = 1e-6, .rtol = 1e-5};
    check_agree(&a, 6);
    agree_case m = {"cmul repeated b", f_op, &s4, 2, {4, 3}, {SHAPE(3, 4, 5, 2), SHAPE(4, 5, 2)},
                    .atol = 1e-5, .rtol = 1e-5};
    check_agree(&m, 7);
    agree_case e = {"cmul same shape", f_op, &s4, 2, {2, 2}, {SHAPE(70, 2), SHAPE(70, 2)},
                    .atol = 1e-5, .rtol = 1e-5};
    check_agree(&e, 8);
    agree_case u = {"pupil -> |fft2|^2", f_op, &s6, 2, {3, 3}, {SHAPE(2, 6, 6), SHAPE(2, 6, 6)},
                    {0, -5}, {1, 5}, .atol = 1e-3, .rtol = 1e-4};
    check_agree(&u, 9);
}

static void test_area(void)
{
    sel s5 = {5};
    agree_case a = {"area_sample", f_op, &s5, 1, {3}, {SHAPE(3, 16, 16)}, {0}, {1}, .atol = 1e-5,
                    .rtol = 1e-5};
    check_agree(&a, 10);
}

/* The differentiable PSF of a small DOE (27 x 27 samples, grid 48) on the device and the CPU,
 * forward and the gradient w.r.t. the height map. */
static const char *const SMALL_DOE =
    "{\"version\": 1, \"aperture_mm\": 0.05, \"doe_pitch_um\": 2, \"grid\": 48, \"levels\": 0,"
    " \"material\": \"fused_silica\", \"profile\": {\"type\": \"fresnel_lens\", \"focal_mm\": 1,"
    " \"design_nm\": 550}, \"sensor_distance_mm\": 1, \"sensor_pitch_um\": 20, \"psf_size\": 5}";
static lm_tensor *f_psf(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n;
    return lm_doe_psf_t(c, u, in[0], (const double[]){430e-9, 640e-9}, 2);
}

static void test_doe_psf(void)
{
    lm_doe d;
    lm_err e = {0};
    CHECK_MSG(lm_doe_parse(SMALL_DOE, "small", &d, &e) == LM_OK, "%s", e.msg);
    if (!d.height) return;
    agree_case a = {"doe_psf 27x27 grid 48", f_psf, &d, 1, {2}, {SHAPE(27, 27)}, {0}, {1},
                    .atol = 2e-5, .rtol = 2e-3};
    check_agree(&a, 11);
    lm_doe_free(&d);
}

int main(void)
{
    int s = opencl_setup();
    if (s) return s;
    RUN(test_fft);
    RUN(test_elementwise);
    RUN(test_area);
    RUN(test_doe_psf);
    lm_cl_backend_free(clb_);
    return check_summary();
}

/* test_doe_psf.c — the differentiable PSF (data/doe_psf.c, lm_doe_psf_t): equal to doe.c's
 * lm_doe_psf for the bundled default DOE (grid 1536) and for a small one, its gradient with
 * respect to the height map by finite differences on the small DOE, a height change that
 * changes the PSF, and shape errors. */
#include "data/doe.h"
#include "tests/check.h"
#include <stdlib.h>

/* A small DOE: 27 x 27 samples of a Fresnel lens (f = z = 1 mm), grid 48, 20 um pixels, 5 x 5. */
static const char *const SMALL =
    "{\"version\": 1, \"aperture_mm\": 0.05, \"doe_pitch_um\": 2, \"grid\": 48, \"levels\": 0,"
    " \"material\": \"fused_silica\", \"profile\": {\"type\": \"fresnel_lens\", \"focal_mm\": 1,"
    " \"design_nm\": 550}, \"sensor_distance_mm\": 1, \"sensor_pitch_um\": 20, \"psf_size\": 5}";

static void compare(const lm_doe *d, const double *lam, int nb, double tol)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_err e = {0};
    lm_tensor *t = lm_doe_height_t(&c, d);
    lm_tensor *P = lm_doe_psf_t(&c, d, t, lam, nb);
    CHECK_CTX_OK(&c);
    int S = d->psf_size;
    float *ref = malloc((size_t)S * S * sizeof(float));
    for (int b = 0; P && b < nb; b++) {
        CHECK(lm_doe_psf(d, lam[b], ref, &e) == LM_OK);
        double peak = 0, worst = 0, sum = 0;
        for (int k = 0; k < S * S; k++) peak = ref[k] > peak ? ref[k] : peak;
        for (int k = 0; k < S * S; k++) {
            double dv = fabs(P->data[(size_t)b * S * S + k] - ref[k]);
            worst = dv > worst ? dv : worst;
            sum += P->data[(size_t)b * S * S + k];
        }
        CHECK_MSG(worst <= tol * peak, "%g nm: worst |diff| %.3g, peak %.3g", lam[b] * 1e9,
                  worst, peak);
        CHECK_CLOSE(sum, 1.0, 1e-4, 0);
        printf("  %g nm: peak %.5f, worst |diff| %.2e\n", lam[b] * 1e9, peak, worst);
    }
    free(ref);
    lm_ctx_free(&c);
}

static void test_default_matches_doe_c(void)
{
    lm_doe d;
    lm_err e = {0};
    CHECK_MSG(lm_doe_default(&d, &e) == LM_OK, "%s", e.msg);
    if (!d.height) return;
    compare(&d, (const double[]){400e-9, 550e-9, 700e-9}, 3, 1e-3);
    lm_doe_free(&d);
}

static void test_small_matches_doe_c(void)
{
    lm_doe d;
    lm_err e = {0};
    CHECK_MSG(lm_doe_parse(SMALL, "small", &d, &e) == LM_OK, "%s", e.msg);
    if (!d.height) return;
    CHECK(d.m == 27 && d.grid == 48);
    compare(&d, (const double[]){400e-9, 480e-9, 550e-9, 620e-9, 700e-9}, 5, 1e-4);
    lm_doe_free(&d);
}

typedef struct psf_user { const lm_doe *d; } psf_user;
static lm_tensor *fn_psf(lm_ctx *c, lm_tensor *const *in, int nin, void *user)
{
    (void)nin;
    return lm_doe_psf_t(c, ((psf_user *)user)->d, in[0], (const double[]){430e-9, 610e-9}, 2);
}

static void test_gradcheck_small(void)
{
    lm_doe d;
    lm_err e = {0};
    CHECK_MSG(lm_doe_parse(SMALL, "small", &d, &e) == LM_OK, "%s", e.msg);
    if (!d.height) return;
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_rng r;
    lm_rng_seed(&r, 9);
    /* a random height map (a lens would leave many elements of tiny gradient) */
    lm_tensor *t = lm_tensor_uniform(&c, 2, (int[]){d.m, d.m}, &r, 0, 1);
    lm_tensor_set_requires_grad(t, 1);
    lm_gradcheck_opts o;
    lm_gradcheck_default_opts(&o);
    o.eps = 2e-3;
    o.atol = 2e-4;
    o.rtol = 2e-2;
    o.max_checks = 200;
    psf_user u = {&d};
    CHECK_GRAD(&c, fn_psf, &t, 1, &u, &o);
    /* outside the aperture the height has no effect: zero gradient there */
    lm_ctx_reset(&c);
    t = lm_tensor_uniform(&c, 2, (int[]){d.m, d.m}, &r, 0, 1);
    lm_tensor_set_requires_grad(t, 1);
    lm_tensor *w = lm_tensor_uniform(&c, 3, (int[]){2, 5, 5}, &r, -1, 1);
    CHECK(lm_backward(&c, fn_psf(&c, &t, 1, &u), w) == LM_OK);
    int zero_out = 1, nonzero_in = 0;
    for (int k = 0; t->grad && k < d.m * d.m; k++) {
        if (!d.mask[k]) zero_out &= t->grad->data[k] == 0.0f;
        else nonzero_in += t->grad->data[k] != 0.0f;
    }
    CHECK(t->grad && zero_out && nonzero_in > 100);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
    lm_doe_free(&d);
}

static void test_errors(void)
{
    lm_doe d;
    lm_err e = {0};
    CHECK(lm_doe_parse(SMALL, "small", &d, &e) == LM_OK);
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *t = lm_tensor_zeros(&c, 2, (int[]){26, 27});
    CHECK(lm_doe_psf_t(&c, &d, t, (const double[]){5e-7}, 1) == NULL);
    CHECK_MSG(strstr(c.msg, "doe_psf: height map 26x27; this DOE has 27 x 27") != NULL, "%s",
              c.msg);
    lm_ctx_clear_error(&c);
    t = lm_tensor_zeros(&c, 2, (int[]){27, 27});
    CHECK(lm_doe_psf_t(&c, &d, t, (const double[]){-5e-7}, 1) == NULL && strstr(c.msg, "wavel"));
    lm_ctx_free(&c);
    lm_doe_free(&d);
}

int main(void)
{
    RUN(test_small_matches_doe_c);
    RUN(test_default_matches_doe_c);
    RUN(test_gradcheck_small);
    RUN(test_errors);
    return check_summary();
}

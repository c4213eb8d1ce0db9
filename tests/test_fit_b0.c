/* test_fit_b0.c — the two-bucket floor's fit with bucket 0's own noise level
 * (lm_lmmse_fit_ctl.b0_noise_ratio, train/fit_lmmse.h): without noise the ratio changes nothing
 * (level 0's filters are bit for bit those of the plain fit); at noise sd 0.05 its bucket-0
 * filters differ, and on held-out patches whose bucket 0 carries 0.3 x bucket 1's noise (as
 * under shot noise) the fit made for that ratio has a lower squared error than the plain fit;
 * a one-bucket model refuses the ratio. */
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include "tests/check.h"
#include "data/dataset.h"
#include "data/system.h"
#include "data/spectra.h"
#include "data/mosaic.h"
#include "models/model.h"
#include "tensor/rng.h"
#include "train/fit_lmmse.h"

#define O LM_MODEL_OUT_CHANNELS
enum { PH = 24, PW = 32, NP = 64, B = 16, HO = 32, LEVEL = 6 }; /* lm_lmmse_sigmas[6] = 0.05 */

static lm_system g_sys;
static lm_mosaic g_mo;
static char g_cave[1024];

static lm_dataset *open_data(int buckets, lm_err *e)
{
    const char *paths[1] = {g_cave};
    lm_dataset_cfg dc;
    lm_dataset_default_cfg(&dc);
    dc.paths = paths, dc.npaths = 1, dc.sys = &g_sys, dc.workers = 0;
    dc.patch_h = PH, dc.patch_w = PW, dc.noise_min = dc.noise_max = 0.0f;
    dc.buckets = buckets;
    return lm_dataset_open(&dc, e);
}

/* lmmse-5-b2 fitted on NP patches with bucket-0 noise ratio r (0: the plain fit). */
static lm_model *fit(double r, lm_err *e)
{
    lm_model *m = lm_model_create("lmmse-5-b2", &g_mo, 1, e);
    lm_dataset *d = m ? open_data(2, e) : NULL;
    lm_lmmse_fit_ctl ctl;
    memset(&ctl, 0, sizeof ctl);
    ctl.b0_noise_ratio = r;
    lm_lmmse_fit_report rep;
    lm_status st = d ? lm_lmmse_fit_ctl_run(m, d, PH, PW, NP, B, -1.0, NULL, &ctl, &rep, e)
                     : LM_ERR_ARG;
    lm_dataset_close(d);
    if (st) {
        lm_model_free(m);
        return NULL;
    }
    return m;
}

/* Interior squared error (channels 1..31) of m at noise sd s on bucket 1 and r s on bucket 0
 * (its noise level given), on the held-out patches. */
static double heldout_sse(lm_model *m, const float *raw, const float *tgt, float s, float r)
{
    float *x = malloc(sizeof(float) * HO * 2 * PH * PW);
    lm_rng g;
    lm_rng_seed(&g, 77);
    const size_t pl = (size_t)PH * PW;
    for (int b = 0; b < HO; b++)
        for (int c = 0; c < 2; c++)
            for (size_t i = 0; i < pl; i++) {
                const size_t k = ((size_t)b * 2 + c) * pl + i;
                x[k] = raw[k] + (c ? r * s : s) * lm_rng_normal(&g);
            }
    lm_ctx c;
    lm_ctx_init(&c, 2);
    m->noise_sigma = s;
    lm_tensor *y = lm_model_forward(&c, m, lm_tensor_from(&c, 4, (int[]){HO, 2, PH, PW}, x));
    CHECK_MSG(y != NULL, "%s", c.msg);
    double sse = 0;
    for (int b = 0; y && b < HO; b++)
        for (int ch = 1; ch <= 31; ch++)
            for (int Y = 2; Y < PH - 2; Y++)
                for (int X = 2; X < PW - 2; X++) {
                    const size_t i = (((size_t)b * O + ch) * PH + Y) * PW + X;
                    sse += ((double)y->data[i] - tgt[i]) * ((double)y->data[i] - tgt[i]);
                }
    lm_ctx_free(&c);
    free(x);
    return sse;
}

static void test_ratio(void)
{
    lm_err e;
    lm_err_clear(&e);
    lm_model *plain = fit(0.0, &e), *shot = plain ? fit(0.3, &e) : NULL;
    CHECK_MSG(plain && shot, "%s", e.msg);
    if (!plain || !shot) goto out;
    const char *names[3] = {"filters.weight", "filters.bucket0", "filters.bias"};
    for (int i = 0; i < 3; i++) {
        const lm_param *a = lm_params_find(&plain->params, names[i]);
        const lm_param *b = lm_params_find(&shot->params, names[i]);
        const size_t per = lm_tensor_numel(&a->t) / LM_LMMSE_LEVELS; /* one level */
        CHECK_MSG(!memcmp(a->t.data, b->t.data, sizeof(float) * per),
                  "%s: level 0 differs with the ratio", names[i]);
        if (i == 1)
            CHECK_MSG(memcmp(a->t.data + per * LEVEL, b->t.data + per * LEVEL,
                             sizeof(float) * per) != 0, "bucket-0 filters at sd 0.05 unchanged");
    }
    lm_dataset *d = open_data(2, &e);
    float *raw = malloc(sizeof(float) * HO * 2 * PH * PW), *tgt = malloc(sizeof(float) * HO * O * PH * PW);
    CHECK(d && raw && tgt && lm_dataset_batch(d, NP / HO, HO, raw, tgt, &e) == LM_OK);
    const float s = lm_lmmse_sigmas[LEVEL];
    const double ep = heldout_sse(plain, raw, tgt, s, 0.3f), es = heldout_sse(shot, raw, tgt, s, 0.3f);
    const double n = (double)HO * 31 * (PH - 4) * (PW - 4);
    printf("     held-out, bucket 0 at 0.3 x the noise of bucket 1 (sd %g): plain fit %.2f dB, "
           "fit for ratio 0.3 %.2f dB\n", (double)s, -10 * log10(ep / n), -10 * log10(es / n));
    CHECK_MSG(es < ep * 0.99, "ratio fit SSE %g not below the plain fit's %g", es, ep);
    free(raw), free(tgt);
    lm_dataset_close(d);
out:
    lm_model_free(plain), lm_model_free(shot);
}

static void test_one_bucket_refused(void)
{
    lm_err e;
    lm_err_clear(&e);
    lm_model *m = lm_model_create("lmmse-5", &g_mo, 1, &e);
    lm_dataset *d = open_data(1, &e);
    CHECK_MSG(m && d, "%s", e.msg);
    lm_lmmse_fit_ctl ctl;
    memset(&ctl, 0, sizeof ctl);
    ctl.b0_noise_ratio = 0.3;
    lm_lmmse_fit_report rep;
    if (m && d) {
        CHECK(lm_lmmse_fit_ctl_run(m, d, PH, PW, 16, B, -1.0, NULL, &ctl, &rep, &e) ==
              LM_ERR_ARG);
        CHECK_MSG(strstr(e.msg, "bucket-0 noise ratio"), "%s", e.msg);
    }
    lm_dataset_close(d);
    lm_model_free(m);
}

int main(void)
{
    char sysp[1024];
    lm_err e;
    lm_err_clear(&e);
    const char *sh = getenv("LM_SHARED_DIR");
    snprintf(g_cave, sizeof g_cave, "%s/data/cave", sh ? sh : "../shared");
    int ok = lm_data_path("systems/default.json", sysp, sizeof sysp, &e) == LM_OK &&
             lm_system_load(sysp, &g_sys, &e) == LM_OK &&
             lm_mosaic_from_system(&g_sys, &g_mo, &e) == LM_OK;
    CHECK_MSG(ok, "%s", e.msg);
    if (!ok) return check_summary();
    RUN(test_ratio);
    RUN(test_one_bucket_refused);
    lm_system_free(&g_sys);
    return check_summary();
}

/* conditions.c — adverse capture conditions and the 3-dB failure point (conditions.h).
 * What it is not: the study loop over scenes and models (study/conds.c). */
#include "infer/conditions.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include "data/forward.h"

static const char *const names[LM_COND_NFAMILIES] = {"photons", "saturation", "led_gain",
                                                     "dead_pixels", "motion"};
static const char *const units[LM_COND_NFAMILIES] = {
    "photo-electrons at full scale (Poisson)", "exposure (x, clipped at full well)",
    "LED gain error (+- %)", "dead pixels (% of the frame)", "motion (px/s)"};

const char *lm_cond_name(lm_cond_family f)
{
    return (int)f >= 0 && f < LM_COND_NFAMILIES ? names[f] : NULL;
}

int lm_cond_parse(const char *name)
{
    for (int i = 0; name && i < LM_COND_NFAMILIES; i++)
        if (!strcmp(names[i], name)) return i;
    return -1;
}

const char *lm_cond_unit(lm_cond_family f)
{
    return (int)f >= 0 && f < LM_COND_NFAMILIES ? units[f] : "";
}

double lm_cond_clean_level(lm_cond_family f)
{
    return f == LM_COND_SATURATION ? 1.0 : 0.0;
}

/* The levels of each family: photo-electrons as simulate --poisson, exposure factors, %,
 * px/s as eval --motion. */
static const double ranges[LM_COND_NFAMILIES][2] = {{0, 1e12}, {1, 1e6}, {0, 100}, {0, 100},
                                                    {0, 1e4}};

int lm_cond_range(lm_cond_family f, double *lo, double *hi)
{
    if ((int)f < 0 || f >= LM_COND_NFAMILIES) return -1;
    *lo = ranges[f][0], *hi = ranges[f][1];
    return 0;
}

int lm_cond_level_ok(lm_cond_family f, double v)
{
    double lo, hi;
    return lm_cond_range(f, &lo, &hi) == 0 && v >= lo && v <= hi; /* NaN is not */
}

int lm_cond_default_levels(lm_cond_family f, double *levels)
{
    static const double ph[] = {10000, 3000, 1000, 300, 100, 30};
    static const double sat[] = {1, 1.5, 2, 3, 4, 6, 8};
    static const double led[] = {0, 2, 5, 10, 15, 20};
    static const double dead[] = {0, 0.1, 0.5, 1, 2, 5};
    static const double mot[] = {0, 30, 60, 120, 240};
    static const double *const all[] = {ph, sat, led, dead, mot};
    static const int cnt[] = {6, 7, 6, 6, 5};
    if ((int)f < 0 || f >= LM_COND_NFAMILIES) return 0;
    memcpy(levels, all[f], sizeof(double) * (size_t)cnt[f]);
    return cnt[f];
}

int lm_cond_applies(lm_cond_family f, int rgb_input)
{
    return !rgb_input || (f != LM_COND_LED_GAIN && f != LM_COND_MOTION);
}

uint64_t lm_cond_stream(lm_cond_family f, double level)
{
    return 0xC0D0000000000000ull ^ ((uint64_t)(f + 1) << 40) ^ (uint64_t)llround(level * 1e4);
}

lm_status lm_cond_saturate(float *frame, size_t n, double exposure, float fs, lm_err *err)
{
    if (!(exposure >= 1.0) || !isfinite(exposure))
        return lm_err_set(err, LM_ERR_ARG, "conditions: exposure x%g (need >= 1)", exposure);
    float e = (float)exposure;
    for (size_t i = 0; i < n; i++) frame[i] = fminf(frame[i] * e, fs) / e;
    return LM_OK;
}

lm_status lm_cond_dead_pixels(float *frame, size_t n, double pct, float fs, lm_rng *rng,
                              size_t *ndead, lm_err *err)
{
    if (ndead) *ndead = 0;
    if (!(pct >= 0.0 && pct <= 100.0))
        return lm_err_set(err, LM_ERR_ARG, "conditions: %g %% dead pixels (need 0..100)", pct);
    size_t k = (size_t)llround(pct / 100.0 * (double)n);
    if (k == 0) return LM_OK;
    size_t *idx = malloc(sizeof *idx * n);
    if (!idx) return lm_err_set(err, LM_ERR_NOMEM, "conditions: out of memory");
    for (size_t i = 0; i < n; i++) idx[i] = i;
    for (size_t i = 0; i < k; i++) { /* partial Fisher-Yates: idx[0..k) is a uniform k-subset */
        size_t j = i + (size_t)(lm_rng_u64(rng) % (uint64_t)(n - i));
        size_t t = idx[i];
        idx[i] = idx[j];
        idx[j] = t;
        frame[idx[i]] = (lm_rng_u32(rng) & 1u) ? fs : 0.0f;
    }
    free(idx);
    if (ndead) *ndead = k;
    return LM_OK;
}

lm_status lm_cond_led_gains(const lm_system *sys, double pct, lm_rng *rng, lm_system *out,
                            double *factor, lm_err *err)
{
    memset(out, 0, sizeof *out);
    if (!(pct >= 0.0 && pct <= 100.0))
        return lm_err_set(err, LM_ERR_ARG, "conditions: LED gain error %g %% (need 0..100)", pct);
    lm_led *leds = calloc((size_t)sys->nleds, sizeof *leds);
    if (!leds) return lm_err_set(err, LM_ERR_NOMEM, "conditions: out of memory");
    *out = *sys; /* shares every other array with sys: never lm_system_free the copy */
    out->leds = leds;
    for (int l = 0; l < sys->nleds; l++) {
        leds[l] = sys->leds[l];
        leds[l].response = malloc(sizeof(float) * (size_t)sys->nbins);
        if (!leds[l].response) {
            lm_cond_system_free(out);
            return lm_err_set(err, LM_ERR_NOMEM, "conditions: out of memory");
        }
        double g = 1.0 + ((lm_rng_u32(rng) & 1u) ? pct : -pct) / 100.0;
        if (factor) factor[l] = g;
        leds[l].gain *= g;
        for (int b = 0; b < sys->nbins; b++)
            leds[l].response[b] = (float)(sys->leds[l].response[b] * g);
    }
    return LM_OK;
}

void lm_cond_system_free(lm_system *s)
{
    for (int l = 0; s->leds && l < s->nleds; l++) free(s->leds[l].response);
    free(s->leds);
    memset(s, 0, sizeof *s);
}

static lm_status bad_family(const lm_infer_model *im, lm_cond_family f, double level,
                            lm_err *err)
{
    if (!lm_cond_name(f))
        return lm_err_set(err, LM_ERR_ARG, "conditions: unknown family %d", (int)f);
    double lo = 0, hi = 0;
    lm_cond_range(f, &lo, &hi);
    if (!lm_cond_level_ok(f, level))
        return lm_err_set(err, LM_ERR_ARG, "conditions: %s level %g is out of range (%g..%g)",
                          lm_cond_name(f), level, lo, hi);
    if (!lm_cond_applies(f, lm_model_has(im->model, LM_CAP_RGB_INPUT)))
        return lm_err_set(err, LM_ERR_ARG, "conditions: %s does not apply to %s (RGB input)",
                          lm_cond_name(f), im->model->preset);
    return LM_OK;
}

lm_status lm_cond_simulate(const lm_infer_model *im, const lm_cube *truth, lm_cond_family f,
                           double level, const lm_rng *rng, float **frame, size_t *n,
                           lm_err *err)
{
    *frame = NULL;
    *n = 0;
    if (bad_family(im, f, level, err)) return err->status;
    if (f == LM_COND_MOTION)
        return lm_err_set(err, LM_ERR_ARG, "conditions: motion is scored by lm_cond_eval");
    lm_rng r = lm_rng_split(rng, lm_cond_stream(f, level));
    lm_noise_opts no;
    memset(&no, 0, sizeof no);
    if (f == LM_COND_PHOTONS) no.photons = level;
    lm_infer_model mim = *im; /* the model with the mis-calibrated system (simulation only) */
    lm_status st = LM_OK;
    if (f == LM_COND_LED_GAIN) st = lm_cond_led_gains(&im->sys, level, &r, &mim.sys, NULL, err);
    if (!st) st = lm_eval_simulate(&mim, truth, &no, &r, frame, n, err);
    if (f == LM_COND_LED_GAIN) lm_cond_system_free(&mim.sys);
    if (!st && f == LM_COND_SATURATION) st = lm_cond_saturate(*frame, *n, level, 1.0f, err);
    if (!st && f == LM_COND_DEAD_PIXELS)
        st = lm_cond_dead_pixels(*frame, *n, level, 1.0f, &r, NULL, err);
    if (st) free(*frame), *frame = NULL, *n = 0;
    return st;
}

lm_status lm_cond_eval(lm_ctx *c, const lm_infer_model *im, const lm_cube *truth,
                       lm_cond_family f, double level, const lm_tile_opts *to,
                       const lm_rng *rng, lm_metrics *m, lm_metrics *unaligned,
                       lm_metrics *still, lm_err *err)
{
    if (f == LM_COND_MOTION) {
        if (bad_family(im, f, level, err)) return err->status;
        lm_eval_motion mo;
        if (lm_eval_motion_run(c, im, truth, level, to, NULL, NULL, &mo, err)) return err->status;
        *m = mo.aligned;
        if (unaligned) *unaligned = mo.unaligned;
        if (still) *still = mo.still;
        return LM_OK;
    }
    float *frame;
    size_t n;
    if (lm_cond_simulate(im, truth, f, level, rng, &frame, &n, err)) return err->status;
    lm_cube pred;
    lm_status st = lm_eval_reconstruct(c, im, frame, truth->height, truth->width, to, 0, &pred,
                                       err);
    free(frame);
    if (st) return st;
    st = lm_metrics_compute(pred.data, truth->data, 31, truth->height, truth->width, 0, 31, m,
                            err);
    lm_cube_free(&pred);
    if (!st && unaligned) *unaligned = *m;
    if (!st && still) *still = *m;
    return st;
}

int lm_cond_crossing(const double *levels, const double *psnr, int n, double clean,
                     double drop, double *at)
{
    double thr = clean - drop;
    for (int i = 0; i < n; i++) {
        if (psnr[i] > thr) continue; /* NaN fails, +inf never does */
        if (i == 0 || !isfinite(psnr[i]) || !isfinite(psnr[i - 1])) {
            *at = levels[i];
        } else {
            double t = (psnr[i - 1] - thr) / (psnr[i - 1] - psnr[i]);
            *at = levels[i - 1] + t * (levels[i] - levels[i - 1]);
        }
        return 1;
    }
    *at = NAN;
    return 0;
}

/* conds.c — the failure study of a model (study.h) and the rainbow's per-row
 * peaks: per held-out scene the clean score and every (family, level) of the config
 * (infer/conditions.h), accumulated into means; then the record's "conditions" object with
 * each family's PSNR per level and its 3-dB point against the model's own clean PSNR.
 * What it is not: the condition models themselves (infer/conditions.c), the charts. */
#include <jansson.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include "data/synth.h"
#include "study/study.h"

void lm_study_cond_init(lm_study_cond_acc *a)
{
    memset(a, 0, sizeof *a);
}

lm_status lm_study_cond_add(lm_ctx *c, const lm_infer_model *im, const lm_study_cfg *cfg,
                            const lm_cube *truth, const lm_rng *rs, lm_study_cond_acc *a,
                            lm_err *err)
{
    lm_tile_opts to;
    lm_tile_default_opts(&to);
    lm_metrics m, u, st;
    if (lm_cond_eval(c, im, truth, LM_COND_PHOTONS, 0.0, &to, rs, &m, NULL, NULL, err))
        return err->status;
    lm_metrics_acc_add(&a->clean, &m);
    for (int i = 0; i < cfg->ncond; i++) {
        const lm_study_cond *sc = &cfg->cond[i];
        if (!lm_cond_applies(sc->family, lm_model_has(im->model, LM_CAP_RGB_INPUT))) continue;
        for (int k = 0; k < sc->nlevels; k++) {
            if (lm_cond_eval(c, im, truth, sc->family, sc->levels[k], &to, rs, &m, &u, &st,
                             err))
                return err->status;
            lm_metrics_acc_add(&a->m[i][k], &m);
            lm_metrics_acc_add(&a->u[i][k], &u);
            lm_metrics_acc_add(&a->s[i][k], &st);
        }
    }
    a->nscenes++;
    return LM_OK;
}

static json_t *jnum(double v)
{
    return isfinite(v) ? json_real(v) : json_null();
}

static json_t *family_json(const lm_study_cond *sc, const lm_study_cond_acc *a, int i,
                           double clean, double frame_period_us)
{
    json_t *lv = json_array();
    double psnr[LM_COND_MAX_LEVELS], at;
    for (int k = 0; k < sc->nlevels; k++) {
        lm_metrics m = lm_metrics_acc_mean(&a->m[i][k]);
        psnr[k] = m.psnr;
        json_t *o = json_pack("{s:f, s:o, s:o, s:o}", "level", sc->levels[k], "psnr",
                              jnum(m.psnr), "ssim", jnum(m.ssim), "sam", jnum(m.sam));
        if (sc->family == LM_COND_MOTION) {
            json_object_set_new(o, "psnr_unaligned",
                                jnum(lm_metrics_acc_mean(&a->u[i][k]).psnr));
            json_object_set_new(o, "psnr_static", jnum(lm_metrics_acc_mean(&a->s[i][k]).psnr));
            json_object_set_new(o, "px_per_frame",
                                json_real(sc->levels[k] * 1e-6 * frame_period_us));
        }
        json_array_append_new(lv, o);
    }
    int hit = lm_cond_crossing(sc->levels, psnr, sc->nlevels, clean, 3.0, &at);
    return json_pack("{s:s, s:s, s:b, s:o, s:o, s:b}", "family", lm_cond_name(sc->family),
                     "unit", lm_cond_unit(sc->family), "applies", 1, "levels", lv, "drop_3db",
                     hit ? json_real(at) : json_null(), "beyond_last_level", !hit);
}

json_t *lm_study_cond_json(const lm_study_cfg *cfg, const lm_infer_model *im,
                           const lm_study_cond_acc *a)
{
    lm_metrics cm = lm_metrics_acc_mean(&a->clean);
    json_t *fam = json_array();
    for (int i = 0; i < cfg->ncond; i++) {
        const lm_study_cond *sc = &cfg->cond[i];
        if (lm_cond_applies(sc->family, lm_model_has(im->model, LM_CAP_RGB_INPUT)))
            json_array_append_new(fam, family_json(sc, a, i, cm.psnr,
                                                   lm_system_frame_period_us(&im->sys)));
        else
            json_array_append_new(fam, json_pack("{s:s, s:s, s:b}", "family",
                                                 lm_cond_name(sc->family), "unit",
                                                 lm_cond_unit(sc->family), "applies", 0));
    }
    return json_pack("{s:i, s:o, s:f, s:o}", "scenes", a->nscenes, "clean_psnr", jnum(cm.psnr),
                     "drop_db", 3.0, "families", fam);
}

lm_status lm_study_rainbow_rows(lm_ctx *c, const lm_infer_model *im, int size, json_t *rb,
                                lm_err *err)
{
    lm_cube truth, pred;
    memset(&pred, 0, sizeof pred);
    lm_tile_opts to;
    lm_tile_default_opts(&to);
    float *frame = NULL;
    size_t n;
    lm_status st = lm_synth_rainbow(size, size, &truth, err);
    if (st) return st;
    st = lm_eval_prepare(&truth, im->model->mosaic.ty, im->model->mosaic.tx, err);
    if (!st) st = lm_eval_simulate(im, &truth, NULL, NULL, &frame, &n, err);
    if (!st) st = lm_eval_reconstruct(c, im, frame, truth.height, truth.width, &to, 0, &pred, err);
    json_t *rows = json_array();
    int H = truth.height, W = truth.width;
    for (int y = 0; !st && y < H; y++) {
        float spec[31];
        for (int b = 0; b < 31; b++) {
            const float *row = lm_cube_band(&pred, b) + (size_t)y * W;
            double s = 0.0;
            for (int x = 0; x < W; x++) s += row[x];
            spec[b] = (float)(s / W);
        }
        json_array_append_new(rows, json_pack("[f,f]", lm_synth_rainbow_peak(y, size),
                                              lm_eval_peak_nm(spec, 31, 400.0, 10.0)));
    }
    if (!st) json_object_set_new(rb, "rows_true_recovered_nm", rows);
    else json_decref(rows);
    free(frame);
    lm_cube_free(&pred);
    lm_cube_free(&truth);
    return st;
}

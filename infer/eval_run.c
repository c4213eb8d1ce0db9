/* eval_run.c — an evaluation run over scenes (eval_run.h).
 * What it is: model loading, scene listing and picking, the per-scene scores at the noise
 * levels and motion speeds, their means, the rainbow test and the training-set overlap.
 * What it is not: the per-scene scoring itself (eval.c), the result files (eval_write.c) or
 * printing (cli/cmd_eval.c). */
#include "infer/eval_run.h"
#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "data/cube_io.h"
#include "data/util.h"
#include "infer/raw.h"
#include "tensor/isa.h"

static const char *const split_names[] = {"test", "val", "train", "all"};

const char *lm_eval_split_name(int split) { return split_names[split]; }

void lm_eval_run_opts_default(lm_eval_run_opts *o)
{
    *o = (lm_eval_run_opts){.seed = 1, .rainbow = 256, .batch = 8, .nnoise = 5,
                            .k = {0.0f, 0.05f, 0.10f, 0.15f, 0.20f}, .nmk = 1,
                            .report_noise = -1, .auto_tol = 0.5};
}

int lm_eval_motion_rows(const lm_eval_run_opts *o) { return o->nmotion * o->nmk; }

int lm_eval_report_level(const lm_eval_run_opts *o)
{
    int best = -1;
    for (int n = 0; n < o->nnoise; n++) {
        double d = fabs(100.0 * o->k[n] - (o->report_noise >= 0 ? o->report_noise : 10.0));
        if (o->report_noise >= 0 ? d < 1e-4 : best < 0 || d < fabs(100.0 * o->k[best] - 10.0))
            best = n;
    }
    return best;
}

static void say(const lm_eval_run *r, const char *line)
{
    if (r->o->log) r->o->log(r->o->user, line);
}

/* --scenes: keep the named scenes, in the order named; a name not among DATA's is an error. */
static lm_status pick_scenes(lm_eval_run *r, lm_err *e)
{
    char *names = strdup(r->o->scenes), *save = NULL;
    lm_eval_scene_res *kept = calloc((size_t)r->nsc + 1, sizeof *kept);
    int nk = 0;
    lm_status st = names && kept ? LM_OK : lm_err_set(e, LM_ERR_NOMEM, "out of memory");
    for (char *t = st ? NULL : strtok_r(names, ",", &save); t && !st;
         t = strtok_r(NULL, ",", &save)) {
        int hit = -1;
        for (int i = 0; i < r->nsc && hit < 0; i++)
            if (!strcmp(r->sc[i].name, t)) hit = i;
        for (int j = 0; j < nk && hit >= 0; j++)
            if (!strcmp(kept[j].name, t)) hit = -2; /* named twice: once is enough */
        if (hit == -1) {
            char list[512] = "";
            for (int i = 0; i < r->nsc; i++)
                snprintf(list + strlen(list), sizeof list - strlen(list), "%s%s", i ? ", " : "",
                         r->sc[i].name);
            st = lm_err_set(e, LM_ERR_ARG, "--scenes: no scene '%s' among the %d given (%s)", t,
                            r->nsc, list);
        } else if (hit >= 0) {
            kept[nk++] = r->sc[hit];
        }
    }
    if (!st) {
        memcpy(r->sc, kept, sizeof *kept * (size_t)nk);
        r->nsc = nk;
    }
    free(kept);
    free(names);
    return st;
}

/* The scenes of the chosen split among those the DATA paths name: the dataset's list of that
 * split, or every list for `all`. A borrowed list (fewer than 3 scenes, no scene of its own
 * in that split) is skipped: its scenes are in their own split's list. */
static lm_status list_scenes(lm_eval_run *r, lm_err *e)
{
    lm_dataset_scene *ls;
    int nls;
    lm_status st = lm_dataset_list_scenes(r->o->data, r->o->ndata, &r->im.sys, r->o->mat_key,
                                          -1, &ls, &nls, e);
    if (st) return st;
    r->sc = calloc((size_t)nls + 1, sizeof *r->sc);
    if (!r->sc) {
        free(ls);
        return lm_err_set(e, LM_ERR_NOMEM, "out of memory");
    }
    for (int i = 0; i < nls; i++) {
        lm_eval_scene_res *s = &r->sc[r->nsc++];
        snprintf(s->name, sizeof s->name, "%s", ls[i].name);
        snprintf(s->path, sizeof s->path, "%s", ls[i].path);
        s->split = ls[i].split;
    }
    free(ls);
    static const lm_data_split want[3] = {LM_SPLIT_TEST, LM_SPLIT_VAL, LM_SPLIT_TRAIN};
    r->given = r->nsc;
    if (r->o->scenes) return pick_scenes(r, e);
    if (r->o->split < LM_EVAL_SPLIT_ALL) {
        r->nsc = 0;
        for (int i = 0; i < r->given; i++)
            if (r->sc[i].split == want[r->o->split]) r->sc[r->nsc++] = r->sc[i];
    }
    if (r->nsc == 0)
        return lm_err_set(e, LM_ERR_ARG, "no scene of split '%s' among the %d given (try "
                          "--split all)", split_names[r->o->split], r->given);
    return LM_OK;
}

/* A calibration's models: model 0 into r->im, the others into r->more; the choice per bin. */
static lm_status open_auto(lm_eval_run *r, lm_err *e)
{
    const char *cf = r->o->auto_file;
    lm_auto_calib *a = &r->cal;
    if (lm_infer_auto_load(cf, r->o->system, a, &r->im, r->more, r->im.auto_models, e))
        return e->status;
    lm_auto_choose(a, r->o->auto_tol, r->choice);
    r->im.auto_cal = a, r->im.auto_choice = r->choice;
    char line[2048];
    int k = snprintf(line, sizeof line, "auto (%s, tol %g dB), the model per %s bin:", cf,
                     r->o->auto_tol, lm_auto_measure_name(a->measure));
    for (int b = 0; b < a->nbins && k > 0 && (size_t)k < sizeof line; b++)
        k += snprintf(line + k, sizeof line - k, "%s [%.3g, %.3g) %s", b ? "," : "",
                      b ? a->edges[b - 1] : -INFINITY, b < a->nbins - 1 ? a->edges[b] : INFINITY,
                      a->models[r->choice[b]].label);
    say(r, line);
    return LM_OK;
}

lm_status lm_eval_run_open(lm_eval_run *r, const lm_eval_run_opts *o, lm_err *e)
{
    memset(r, 0, sizeof *r);
    r->o = o;
    if (o->auto_file && o->noise_oracle)
        return lm_err_set(e, LM_ERR_ARG, "--noise-oracle with --auto: a calibrated choice reads "
                          "each frame's estimated noise level");
    lm_status st = o->auto_file ? open_auto(r, e) : lm_infer_model_load(o->model, o->system,
                                                                         &r->im, e);
    if (st) return st;
    if (r->im.remap.active) {
        char line[3000], out[3100];
        lm_gain_remap_describe(&r->im.remap, r->im.system_path, r->im.model_system, line,
                               sizeof line);
        snprintf(out, sizeof out, "%s%s", line,
                 o->no_remap ? "; not applied (--no-gain-remap)" : "");
        say(r, out);
        if (o->no_remap) r->im.remap.active = 0;
    }
    r->im.noise_oracle = o->noise_oracle;
    r->im.sensor_clip = o->clip;
    r->im.sensor_bits = (int)o->bits;
    r->im.photons = o->photons, r->im.read_noise = (float)o->read_noise;
    r->im.auto_models[0] = r->im.model;
    return list_scenes(r, e);
}

/* The --motion speeds (at each --motion-noise level) on one prepared scene; rng: the scene's
 * noise generator. */
static lm_status scene_motion(lm_eval_run *r, lm_eval_scene_res *s, const lm_cube *cube,
                              const lm_rng *rng, lm_err *e)
{
    const lm_eval_run_opts *o = r->o;
    lm_status st = LM_OK;
    lm_err me;
    lm_err_clear(&me);
    lm_align_opts ao;
    lm_align_default_opts(&ao);
    ao.confidence = !o->align_plain;
    int k = 0;
    lm_rng mr = lm_rng_split(rng, 0x6d6f74696f6eULL); /* "motion": apart from the still rows' */
    for (; k < lm_eval_motion_rows(o) && !st; k++)
        st = lm_eval_motion_run_noise(&r->ctx, &r->im, cube, o->speed[k % o->nmotion],
                                      o->mk[k / o->nmotion], &mr, &r->to, NULL, &ao, &s->mo[k],
                                      &me);
    if (st) lm_err_set(e, st, "--motion %g px/s: %s", o->speed[(k - 1) % o->nmotion], me.msg);
    return st;
}

/* Means over the scenes of the motion rows. */
static void motion_means(lm_eval_run *r)
{
    for (int k = 0; k < lm_eval_motion_rows(r->o); k++) {
        lm_metrics_acc a, u, st;
        memset(&a, 0, sizeof a);
        memset(&u, 0, sizeof u);
        memset(&st, 0, sizeof st);
        for (int i = 0; i < r->nsc; i++) {
            lm_metrics_acc_add(&a, &r->sc[i].mo[k].aligned);
            lm_metrics_acc_add(&u, &r->sc[i].mo[k].unaligned);
            lm_metrics_acc_add(&st, &r->sc[i].mo[k].still);
        }
        r->mo_mean[k].speed = r->o->speed[k % r->o->nmotion];
        r->mo_mean[k].noise = r->o->mk[k / r->o->nmotion];
        r->mo_mean[k].px_per_frame = r->nsc ? r->sc[0].mo[k].px_per_frame : 0.0;
        r->mo_mean[k].aligned = lm_metrics_acc_mean(&a);
        r->mo_mean[k].unaligned = lm_metrics_acc_mean(&u);
        r->mo_mean[k].still = lm_metrics_acc_mean(&st);
    }
}

/* Scene s read, prepared and scored (still rows, then motion rows); base: the run's noise
 * generator. */
static lm_status eval_scene(lm_eval_run *r, lm_eval_scene_res *s, const lm_rng *base,
                            lm_err *e)
{
    lm_cube cube;
    lm_cube_read_opts ro; /* onto 31 bands 400-700 nm, as the dataset reads scenes */
    lm_cube_read_opts_default(&ro);
    ro.keep.count = 0;
    ro.mat_key = r->o->mat_key;
    lm_status st = lm_cube_read_with(s->path, &ro, &cube, e);
    if (st) return st;
    lm_err me;
    lm_err_clear(&me);
    st = lm_eval_prepare(&cube, r->im.model->mosaic.ty, r->im.model->mosaic.tx, &me);
    lm_rng rs = lm_rng_split(base, lm_fnv1a_str(LM_FNV1A_BASIS_SHORT, s->name));
    if (!st) st = lm_eval_scene_timed(&r->ctx, &r->im, &cube, r->o->k, r->o->nnoise, &r->to,
                                      &rs, s->m, s->sec, &me);
    if (!st) st = scene_motion(r, s, &cube, &rs, &me);
    s->height = cube.height;
    s->width = cube.width;
    lm_cube_free(&cube);
    return st ? lm_err_set(e, st, "%s: %s", s->path, me.msg) : LM_OK;
}

static lm_status eval_scenes(lm_eval_run *r, lm_err *e)
{
    lm_rng base;
    lm_rng_seed(&base, (uint64_t)r->o->seed);
    lm_metrics_acc acc[LM_EVAL_MAX_NOISE];
    memset(acc, 0, sizeof acc);
    for (int i = 0; i < r->nsc; i++) {
        lm_eval_scene_res *s = &r->sc[i];
        double t0 = omp_get_wtime();
        lm_status st = eval_scene(r, s, &base, e);
        if (st) return st;
        for (int n = 0; n < r->o->nnoise; n++) lm_metrics_acc_add(&acc[n], &s->m[n]);
        char line[400];
        snprintf(line, sizeof line, "scene %d/%d %s (%d x %d): %.2f s", i + 1, r->nsc, s->name,
                 s->width, s->height, omp_get_wtime() - t0);
        say(r, line);
    }
    for (int n = 0; n < r->o->nnoise; n++) {
        r->mean[n] = lm_metrics_acc_mean(&acc[n]);
        double t = 0.0;
        for (int i = 0; i < r->nsc; i++) t += r->sc[i].sec[n];
        r->mean_sec[n] = r->nsc ? t / r->nsc : 0.0;
    }
    motion_means(r);
    return LM_OK;
}

/* The compute context and the device the network runs on. */
static lm_status open_device(lm_eval_run *r, lm_err *e)
{
    char line[300];
    if (lm_ctx_init(&r->ctx, r->o->nthreads) != 0)
        return lm_err_set(e, LM_ERR_NOMEM, "out of memory (compute context)");
    r->have_ctx = 1;
    r->ctx.precision = r->o->precision;
    if (r->o->precision != LM_PRECISION_FP32) {
        snprintf(line, sizeof line, "precision: %s", lm_precision_describe(r->o->precision));
        say(r, line);
    }
    lm_status st = lm_tile_device_open(&r->dev, r->o->device, r->im.model, &r->ctx, e);
    if (st) return st;
    if (r->dev.backend->device != LM_DEVICE_CPU && r->im.auto_cal)
        return lm_err_set(e, LM_ERR_UNSUPPORTED, "--device %s: a calibrated choice (--auto) runs "
                          "on the CPU only", lm_tile_device_name(&r->dev));
    if (r->dev.backend->device != LM_DEVICE_CPU && !lm_model_has(r->im.model, LM_CAP_OPENCL)) {
        const lm_model *m = r->im.model;
        if (m->base && !lm_model_has(m->base, LM_CAP_OPENCL)) /* the base is what lacks them */
            return lm_err_set(e, LM_ERR_UNSUPPORTED, "--device %s: model %s+%s runs on the CPU "
                              "only (its base %s has no OpenCL kernels)",
                              lm_tile_device_name(&r->dev), m->preset, m->base->preset,
                              m->base->preset);
        return lm_err_set(e, LM_ERR_UNSUPPORTED, "--device %s: model %s runs on the CPU only "
                          "(its layers have no OpenCL kernels)", lm_tile_device_name(&r->dev),
                          m->preset);
    }
    if (r->dev.backend->device != LM_DEVICE_CPU) {
        snprintf(line, sizeof line, "device: %s", lm_tile_device_name(&r->dev));
        say(r, line);
    }
    return LM_OK;
}

/* Which scored scenes the model was trained on (stops at the first unknown: the model
 * records no training scenes). */
static void check_overlap(lm_eval_run *r)
{
    for (int i = 0; i < r->nsc; i++) {
        r->sc[i].trained = lm_eval_trained_on(&r->im, r->sc[i].path);
        for (int m = 1; r->im.auto_cal && m < r->cal.nmodels && r->sc[i].trained >= 0; m++) {
            const int t = lm_eval_trained_on(&r->more[m], r->sc[i].path); /* any of them */
            r->sc[i].trained = t < 0 ? t : r->sc[i].trained || t;
        }
        if (r->sc[i].trained < 0) {
            r->overlap_unknown = 1;
            return;
        }
    }
}

lm_status lm_eval_run_score(lm_eval_run *r, lm_err *e)
{
    lm_status st = open_device(r, e);
    if (st) return st;
    lm_tile_default_opts(&r->to);
    r->to.batch = (int)r->o->batch;
    if ((st = eval_scenes(r, e))) return st;
    lm_err me;
    lm_err_clear(&me);
    if (r->o->rainbow > 0 &&
        (st = lm_eval_rainbow_run(&r->ctx, &r->im, (int)r->o->rainbow, &r->to, &r->rb, &me)))
        return lm_err_set(e, st, "rainbow: %s", me.msg);
    check_overlap(r);
    return LM_OK;
}

void lm_eval_run_free(lm_eval_run *r)
{
    lm_tile_device_close(&r->dev);
    if (r->have_ctx) lm_ctx_free(&r->ctx);
    free(r->sc);
    lm_infer_model_free(&r->im);
    for (int m = 1; m < LM_AUTO_MAX_MODELS; m++) lm_infer_model_free(&r->more[m]);
    memset(r, 0, sizeof *r);
}

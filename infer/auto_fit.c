/* auto_fit.c — calibrating `--model auto` on held-out scenes (auto_fit.h).
 * What it is: model loading, scene listing, the per-scene samples, the fit and costs, the
 * held-out test of the fixed models and the auto choice, and the calibration file.
 * What it is not: the difficulty measure, the fit or the mixed-model fold themselves (auto.c),
 * or printing (cli/cmd_fit_auto.c). */
#define _XOPEN_SOURCE 700 /* realpath, strtok_r */
#include "infer/auto_fit.h"
#include <jansson.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "data/cube_io.h"
#include "data/dataset.h"
#include "data/synth.h"
#include "infer/eval.h"
#include "models/profile.h"

#define SYNTH_SEED_BASE 0xCA11B0000000ull /* procedural scenes: seed base + seed * 1e6 + i */
#define TEST_SEED_OFFSET 500000u            /* test scenes: seed base + seed * 1e6 + 5e5 + j */

static const char *const split_names[] = {"val", "test", "valtest", "all"};

const char *lm_auto_fit_split_name(int split) { return split_names[split]; }

int lm_auto_fit_split_parse(const char *name)
{
    for (int i = 0; i < 4; i++)
        if (!strcmp(name, split_names[i])) return i;
    return -1;
}

void lm_auto_fit_opts_default(lm_auto_fit_opts *o)
{
    *o = (lm_auto_fit_opts){.split = LM_AUTO_FIT_VALTEST, .sh = 198, .sw = 256, .bins = 8,
                            .measure = LM_AUTO_GRAD, .nnoise = 1, .seed = 1, .batch = 8, .ntol = 5,
                            .tol = {0, 0.25, 0.5, 1, 2}};
}

static void say(const lm_auto_fit_run *r, const char *line)
{
    if (r->o->log) r->o->log(r->o->user, line);
}

/* Model s loaded as the next one of the calibration. */
static lm_status load_model(lm_auto_fit_run *r, const char *s, lm_err *e)
{
    lm_auto_calib *a = &r->cal;
    if (a->nmodels == LM_AUTO_MAX_MODELS)
        return lm_err_set(e, LM_ERR_ARG, "--models: at most %d models", LM_AUTO_MAX_MODELS);
    lm_infer_model *im = &r->im[a->nmodels];
    lm_status st = lm_infer_model_load(s, NULL, im, e);
    if (st) return st;
    lm_auto_model *x = &a->models[a->nmodels];
    char *abs = realpath(im->weights, NULL); /* infer may run from another folder */
    snprintf(x->path, sizeof x->path, "%s", abs ? abs : im->weights);
    free(abs);
    lm_model_name(im->model, x->preset, sizeof x->preset); /* NET+BASE for residuals */
    r->models[a->nmodels++] = im->model;
    if (im->model->mosaic.ty != r->models[0]->mosaic.ty ||
        im->model->mosaic.tx != r->models[0]->mosaic.tx || lm_model_frames(im->model) != 1 ||
        im->model->in_channels != lm_model_buckets(im->model) ||
        lm_model_buckets(im->model) != lm_model_buckets(r->models[0]) ||
        im->model->out_channels != LM_MODEL_OUT_CHANNELS)
        return lm_err_set(e, LM_ERR_ARG, "--models: '%s' does not take the same coded frames "
                          "as '%s'", s, a->models[0].path);
    return LM_OK;
}

/* Split "A,B,C" and load each model. */
static lm_status load_models(lm_auto_fit_run *r, lm_err *e)
{
    char buf[8192], *save = NULL;
    if (snprintf(buf, sizeof buf, "%s", r->o->models) >= (int)sizeof buf)
        return lm_err_set(e, LM_ERR_ARG, "--models: list too long");
    size_t len = strlen(buf);
    if (!len || buf[0] == ',' || buf[len - 1] == ',' || strstr(buf, ",,"))
        return lm_err_set(e, LM_ERR_ARG, "--models '%s': an empty element (models separated by "
                          "single commas)", r->o->models);
    for (char *s = strtok_r(buf, ",", &save); s; s = strtok_r(NULL, ",", &save)) {
        lm_status st = load_model(r, s, e);
        if (st) return st;
    }
    if (r->cal.nmodels < 2) return lm_err_set(e, LM_ERR_ARG, "--models: give at least 2 models");
    return LM_OK;
}

/* The DATA scenes of the chosen split (lm_dataset_list_scenes; valtest: val, then test). */
static lm_status list_scenes(lm_auto_fit_run *r, lm_err *e)
{
    if (!r->o->ndata) return LM_OK;
    const int all[] = {-1}, valtest[] = {LM_SPLIT_VAL, LM_SPLIT_TEST}, val[] = {LM_SPLIT_VAL},
              test[] = {LM_SPLIT_TEST};
    const int split = r->o->split;
    const int *splits = split == LM_AUTO_FIT_ALL ? all : split == LM_AUTO_FIT_VALTEST ? valtest
                        : split == LM_AUTO_FIT_VAL ? val : test;
    int nsplits = split == LM_AUTO_FIT_VALTEST ? 2 : 1, total = 0;
    for (int k = 0; k < nsplits; k++) {
        lm_dataset_scene *sc = NULL;
        int n = 0;
        lm_status st = lm_dataset_list_scenes(r->o->data, r->o->ndata, &r->im[0].sys, NULL,
                                              splits[k], &sc, &n, e);
        if (st) return st;
        char (*grown)[1024] = realloc(r->scenes, ((size_t)total + n + 1) * sizeof *r->scenes);
        if (!grown) {
            free(sc);
            return lm_err_set(e, LM_ERR_NOMEM, "out of memory");
        }
        r->scenes = grown;
        for (int i = 0; i < n; i++) snprintf(r->scenes[total + i], 1024, "%s", sc[i].path);
        total += n;
        free(sc);
    }
    r->nscenes = total;
    if (!r->scenes) r->scenes = calloc(1, sizeof *r->scenes);
    if (!r->scenes) return lm_err_set(e, LM_ERR_NOMEM, "out of memory");
    if (!r->nscenes && !r->o->synth)
        return lm_err_set(e, LM_ERR_ARG, "no DATA scene of split '%s' among the %d DATA path(s) "
                          "(use --synth N for procedural held-out scenes, or --split all)",
                          split_names[split], r->o->ndata);
    return LM_OK;
}

lm_status lm_auto_fit_open(lm_auto_fit_run *r, const lm_auto_fit_opts *o, lm_err *e)
{
    memset(r, 0, sizeof *r);
    r->o = o;
    lm_status st = load_models(r, e);
    if (!st) st = list_scenes(r, e);
    if (st) return st;
    if (lm_ctx_init(&r->ctx, o->nthreads) != 0)
        return lm_err_set(e, LM_ERR_NOMEM, "out of memory (compute context)");
    r->have_ctx = 1;
    return LM_OK;
}

void lm_auto_fit_free(lm_auto_fit_run *r)
{
    if (r->have_ctx) lm_ctx_free(&r->ctx);
    for (int m = 0; m < LM_AUTO_MAX_MODELS; m++) lm_infer_model_free(&r->im[m]);
    free(r->scenes);
    free(r->d);
    free(r->mse);
    free(r->test);
    memset(r, 0, sizeof *r);
}

/* ---- calibration ------------------------------------------------------------------------ */
/* Scene i (DATA scenes first, then the procedural calibration ones, then the test ones)
 * prepared: cropped, max 1. */
static lm_status scene_cube(const lm_auto_fit_run *r, int i, lm_cube *cube, lm_err *e)
{
    const lm_mosaic *mo = &r->models[0]->mosaic;
    uint64_t k = (uint64_t)(i - r->nscenes); /* procedural index */
    if (k >= (uint64_t)r->o->synth) k = TEST_SEED_OFFSET + (k - (uint64_t)r->o->synth);
    lm_status st = i < r->nscenes
                       ? lm_cube_read(r->scenes[i], cube, e)
                       : lm_synth_scene(SYNTH_SEED_BASE + (uint64_t)r->o->seed * 1000000u + k,
                                        r->o->sh, r->o->sw, NULL, cube, e);
    return st ? st : lm_eval_prepare(cube, mo->ty, mo->tx, e);
}

/* Scene i's coded frame (the cube prepared) simulated at noise level q (noise stream
 * seed * 7919 + i + q * 104729). */
static lm_status scene_frame(const lm_auto_fit_run *r, int i, int q, const lm_cube *cube,
                             float **frame, lm_err *e)
{
    *frame = NULL;
    size_t nf;
    lm_noise_opts no = {.gauss_k = (float)(r->o->noise[q] / 100.0), .clip = r->o->clip,
                        .bits = (int)r->o->bits};
    lm_rng rng;
    lm_rng_seed(&rng, (uint64_t)r->o->seed * 7919u + (uint64_t)i + (uint64_t)q * 104729u);
    return lm_eval_simulate(&r->im[0], cube, &no, &rng, frame, &nf, e);
}

/* Make room for n more samples. */
static lm_status grow(lm_auto_fit_run *r, long n, lm_err *e)
{
    if (r->n + n <= r->cap) return LM_OK;
    long cap = 2 * (r->n + n);
    double *d = malloc(sizeof(double) * cap);
    double *m = malloc(sizeof(double) * cap * r->cal.nmodels);
    if (!d || !m) {
        free(d);
        free(m);
        return lm_err_set(e, LM_ERR_NOMEM, "out of memory");
    }
    if (r->n) memcpy(d, r->d, sizeof(double) * r->n);
    for (int k = 0; k < r->cal.nmodels; k++)
        if (r->n) memcpy(m + k * cap, r->mse + k * r->cap, sizeof(double) * r->n);
    free(r->d);
    free(r->mse);
    r->d = d, r->mse = m, r->cap = cap;
    return LM_OK;
}

/* One scene's samples at noise level q appended. */
static lm_status level_samples(lm_auto_fit_run *r, int i, int q, const lm_cube *c, lm_err *e)
{
    lm_cube cube = *c;
    float *frame;
    if (scene_frame(r, i, q, &cube, &frame, e)) return e->status;
    int nw = lm_auto_window_count(cube.height, cube.width, &r->to), nm = r->cal.nmodels;
    double *mse = malloc(sizeof(double) * nw * nm);
    lm_status st = mse && !grow(r, nw, e) ? LM_OK
                                          : lm_err_set(e, LM_ERR_NOMEM, "out of memory");
    if (!st)
        st = lm_auto_scene(&r->ctx, r->models, nm, r->cal.measure, frame, cube.data, cube.height,
                           cube.width, &r->to, r->d + r->n, mse, r->secs, e);
    for (int m = 0; m < nm && !st; m++)
        memcpy(r->mse + m * r->cap + r->n, mse + (size_t)m * nw, sizeof(double) * nw);
    if (!st) r->n += nw;
    free(mse);
    free(frame);
    return st;
}

/* Scene i read once and fn run on it at every noise level q. */
typedef lm_status (*level_fn)(lm_auto_fit_run *r, int i, int q, const lm_cube *cube, lm_err *e);
static lm_status each_level(lm_auto_fit_run *r, int i, level_fn fn, lm_err *e)
{
    lm_cube cube;
    if (scene_cube(r, i, &cube, e)) return e->status;
    lm_status st = LM_OK;
    for (int q = 0; q < r->o->nnoise && !st; q++) st = fn(r, i, q, &cube, e);
    lm_cube_free(&cube);
    return st;
}

/* Every model's seconds per window (from the samples) and MACs per window. */
static void model_costs(lm_auto_fit_run *r)
{
    lm_auto_calib *a = &r->cal;
    for (int m = 0; m < a->nmodels; m++) {
        lm_profile p;
        lm_err pe;
        lm_err_clear(&pe);
        a->models[m].cost = r->secs[m] / (double)r->n;
        if (a->models[m].cost <= 0.0) a->models[m].cost = 1e-9;
        if (!lm_model_profile(r->models[m], 1, r->to.win_h, r->to.win_w, &p, &pe)) {
            a->models[m].macs = p.total_macs;
            lm_profile_free(&p);
        }
    }
}

lm_status lm_auto_fit_calibrate(lm_auto_fit_run *r, lm_err *e)
{
    lm_tile_default_opts(&r->to);
    r->to.batch = (int)r->o->batch;
    lm_auto_calib *a = &r->cal;
    a->measure = r->o->measure;
    a->win_h = r->to.win_h, a->win_w = r->to.win_w, a->stride_y = r->to.stride_y,
    a->stride_x = r->to.stride_x;
    int total = r->nscenes + (int)r->o->synth;
    for (int i = 0; i < total; i++) {
        double t0 = omp_get_wtime();
        lm_err se;
        lm_err_clear(&se);
        char line[1200];
        if (each_level(r, i, level_samples, &se))
            return lm_err_set(e, se.status, "scene %d (%s): %s", i + 1,
                              i < r->nscenes ? r->scenes[i] : "procedural", se.msg);
        snprintf(line, sizeof line, "scene %d/%d: %.2f s", i + 1, total, omp_get_wtime() - t0);
        say(r, line);
    }
    model_costs(r);
    /* the samples are stored with stride cap per model: pack them for the fit */
    for (int m = 1; m < a->nmodels; m++)
        memmove(r->mse + m * r->n, r->mse + m * r->cap, sizeof(double) * r->n);
    lm_err fe;
    lm_err_clear(&fe);
    lm_status st = lm_auto_fit(a, r->d, r->mse, r->n, (int)r->o->bins, &fe);
    return st ? lm_err_set(e, st, "%s (use fewer --bins or more scenes)", fe.msg) : LM_OK;
}

/* ---- the held-out test ------------------------------------------------------------------ */
long lm_auto_test_row_windows(const lm_auto_test_row *w, int nm)
{
    long n = 0;
    for (int m = 0; m < nm; m++) n += w->win[m];
    return n;
}

double lm_auto_test_row_est(const lm_auto_fit_run *r, const lm_auto_test_row *w)
{
    double s = 0.0;
    long n = lm_auto_test_row_windows(w, r->cal.nmodels);
    for (int m = 0; m < r->cal.nmodels; m++)
        s += n ? (double)w->win[m] / n * r->cal.models[m].cost : 0.0;
    return s * r->test->wpf;
}

/* One row on a test scene's frame; d: the windows' difficulties, wm: scratch. */
static lm_status test_row_run(lm_auto_fit_run *r, lm_auto_test_row *w, const float *frame,
                              const lm_cube *cube, const double *d, int *wm, double tdiff,
                              lm_err *e)
{
    const lm_auto_calib *a = &r->cal;
    const int H = cube->height, W = cube->width, n = lm_auto_window_count(H, W, &r->to);
    lm_cube pred;
    lm_status st;
    double t0 = omp_get_wtime();
    if (w->model >= 0) {
        st = lm_tile_infer(&r->ctx, r->models[w->model], frame, H, W, &r->to, &pred, e);
        w->win[w->model] += st ? 0 : n;
    } else {
        for (int j = 0; j < n; j++) wm[j] = w->choice[lm_auto_bin(a, d[j])];
        st = lm_auto_infer(&r->ctx, r->models, a->nmodels, wm, frame, H, W, &r->to, &pred,
                           w->win, e);
    }
    w->wall += omp_get_wtime() - t0 + (w->model < 0 ? tdiff : 0.0);
    if (st) return st;
    w->psnr += lm_metric_psnr(pred.data, cube->data, 31, H, W, 0, 31);
    lm_cube_free(&pred);
    return LM_OK;
}

/* One test scene at noise level q through every row that runs (auto rows with a repeated
 * choice do not). */
static lm_status test_level(lm_auto_fit_run *r, int i, int q, const lm_cube *c, lm_err *e)
{
    lm_auto_test *t = r->test;
    const lm_mosaic *mo = &r->models[0]->mosaic;
    lm_cube cube = *c;
    float *frame;
    if (scene_frame(r, i, q, &cube, &frame, e)) return e->status;
    const int H = cube.height, W = cube.width, n = lm_auto_window_count(H, W, &r->to);
    double *d = malloc(sizeof(double) * n);
    int *wm = malloc(sizeof(int) * n);
    lm_status st = d && wm ? LM_OK : lm_err_set(e, LM_ERR_NOMEM, "out of memory");
    double t0 = omp_get_wtime();
    if (!st) st = lm_auto_frame_difficulty(r->cal.measure, frame, H, W, mo->ty, mo->tx, &r->to,
                                           lm_nthreads(&r->ctx), d, e);
    const double tdiff = omp_get_wtime() - t0;
    t->windows += st ? 0 : n;
    for (int k = 0; k < t->nrows && !st; k++)
        if (t->rows[k].same < 0)
            st = test_row_run(r, &t->rows[k], frame, &cube, d, wm, tdiff, e);
    free(d);
    free(wm);
    free(frame);
    return st;
}

/* The rows: the fixed models, then auto per tolerance (a choice already made is reused). */
static void test_rows(lm_auto_fit_run *r)
{
    const lm_auto_calib *a = &r->cal;
    lm_auto_test *t = r->test;
    for (int m = 0; m < a->nmodels; m++) {
        lm_auto_test_row *w = &t->rows[t->nrows++];
        w->model = m, w->same = -1;
        for (int b = 0; b < a->nbins; b++) w->choice[b] = m;
    }
    for (int k = 0; k < r->o->ntol; k++) {
        lm_auto_test_row *w = &t->rows[t->nrows];
        w->model = -1, w->same = -1, w->tol = r->o->tol[k];
        lm_auto_choose(a, w->tol, w->choice);
        for (int j = a->nmodels; j < t->nrows && w->same < 0; j++)
            if (!memcmp(t->rows[j].choice, w->choice, sizeof(int) * a->nbins)) w->same = j;
        t->nrows++;
    }
}

/* Means over the scenes; a row with a repeated choice takes its earlier row's results. */
static void test_means(lm_auto_fit_run *r)
{
    lm_auto_test *t = r->test;
    for (int k = 0; k < t->nrows; k++) {
        lm_auto_test_row *w = &t->rows[k];
        if (w->same >= 0) {
            int same = w->same;
            double tol = w->tol;
            *w = t->rows[same];
            w->same = same, w->tol = tol;
        } else {
            w->psnr /= (double)r->o->test_synth * r->o->nnoise;
        }
    }
    t->best = 0;
    for (int m = 1; m < r->cal.nmodels; m++)
        if (t->rows[m].psnr > t->rows[t->best].psnr) t->best = m;
    lm_tile_opts vga = r->to;
    t->wpf = lm_auto_window_count(480, 640, &vga);
}

lm_status lm_auto_fit_test(lm_auto_fit_run *r, lm_err *e)
{
    if (!r->o->test_synth) return LM_OK;
    r->test = calloc(1, sizeof *r->test);
    if (!r->test) return lm_err_set(e, LM_ERR_NOMEM, "out of memory");
    test_rows(r);
    const int first = r->nscenes + (int)r->o->synth;
    for (int i = 0; i < (int)r->o->test_synth; i++) {
        double t0 = omp_get_wtime();
        lm_err se;
        lm_err_clear(&se);
        char line[200];
        if (each_level(r, first + i, test_level, &se))
            return lm_err_set(e, se.status, "test scene %d: %s", i + 1, se.msg);
        snprintf(line, sizeof line, "test scene %d/%lld: %.2f s", i + 1, r->o->test_synth,
                 omp_get_wtime() - t0);
        say(r, line);
    }
    test_means(r);
    return LM_OK;
}

/* One row of the "test" member. */
static json_t *test_row_json(const lm_auto_fit_run *r, const lm_auto_test_row *w)
{
    const lm_auto_calib *a = &r->cal;
    const lm_auto_test_row *b = &r->test->rows[r->test->best];
    long n = lm_auto_test_row_windows(w, a->nmodels);
    json_t *share = json_array(), *choice = json_array();
    for (int m = 0; m < a->nmodels; m++)
        json_array_append_new(share, json_real(n ? (double)w->win[m] / n : 0.0));
    for (int c = 0; c < a->nbins; c++) json_array_append_new(choice, json_integer(w->choice[c]));
    json_t *o = json_pack("{s:s, s:f, s:f, s:f, s:o, s:o, s:f, s:f, s:f, s:f}", "kind",
                          w->model >= 0 ? "fixed" : "auto", "psnr_db", w->psnr,
                          "psnr_vs_best_db", w->psnr - b->psnr, "calib_psnr_db",
                          lm_auto_expected_psnr(a, w->choice, 0), "share", share, "choice",
                          choice, "est_s_per_frame", lm_auto_test_row_est(r, w), "measured_s",
                          w->wall, "measured_s_per_frame",
                          n ? w->wall * r->test->wpf / n : 0.0, "speedup_est",
                          lm_auto_test_row_est(r, b) / lm_auto_test_row_est(r, w));
    if (!o) return NULL;
    if (w->model >= 0) json_object_set_new(o, "model", json_string(a->models[w->model].preset));
    else json_object_set_new(o, "tol_db", json_real(w->tol));
    if (w->same >= 0) json_object_set_new(o, "same_choice_as_row", json_integer(w->same));
    return o;
}

/* The "test" member of the calibration file. */
static json_t *test_json(const lm_auto_fit_run *r)
{
    const lm_auto_test *t = r->test;
    json_t *rows = json_array();
    for (int k = 0; k < t->nrows; k++) json_array_append_new(rows, test_row_json(r, &t->rows[k]));
    json_t *test = json_pack("{s:I, s:[i,i], s:I, s:i, s:i, s:s, s:o}", "scenes",
                             (json_int_t)r->o->test_synth, "size", r->o->sh, r->o->sw, "windows",
                             (json_int_t)t->windows, "windows_per_640x480", t->wpf, "threads",
                             omp_get_max_threads(), "best", r->cal.models[t->best].preset,
                             "rows", rows);
    return json_pack("{s:o}", "test", test);
}

/* The calibration as saved to path: models under path's folder named relative to it (the
 * folder and its models move together), the others by absolute path. */
static void saved_paths(const lm_auto_fit_run *r, const char *path, lm_auto_calib *c)
{
    *c = r->cal;
    char dir[1024];
    const char *slash = strrchr(path, '/');
    snprintf(dir, sizeof dir, "%.*s", slash ? (int)(slash - path) : 1, slash ? path : ".");
    char *abs = realpath(*dir ? dir : "/", NULL);
    const size_t n = abs ? strlen(abs) : 0;
    for (int m = 0; abs && m < c->nmodels; m++) {
        char *p = c->models[m].path;
        if (n > 1 && !strncmp(p, abs, n) && p[n] == '/') memmove(p, p + n + 1, strlen(p + n));
    }
    free(abs);
}

lm_status lm_auto_fit_save(const lm_auto_fit_run *r, const char *path, lm_err *e)
{
    json_t *extra = r->test ? test_json(r) : json_object(), *levels = json_array();
    for (int q = 0; levels && q < r->o->nnoise; q++)
        json_array_append_new(levels, json_real(r->o->noise[q]));
    if (!extra || !levels || json_object_set_new(extra, "noise_percent", levels) ||
        json_object_set_new(extra, "clip", json_boolean(r->o->clip)) ||
        json_object_set_new(extra, "bits", json_integer(r->o->bits))) {
        json_decref(extra);
        return lm_err_set(e, LM_ERR_NOMEM, "out of memory");
    }
    lm_auto_calib c;
    saved_paths(r, path, &c);
    lm_status st = lm_auto_save_ext(path, &c, extra, e);
    json_decref(extra);
    return st;
}

/* bound.c — the spectral bound: per-pixel maps from every LED's response to the 31 bands,
 * fitted on training scenes and scored on held-out ones (infer/bound.h). */
#include "infer/bound.h"
#include "data/cube_io.h"
#include "data/spectra.h"
#include "data/util.h"
#include "infer/eval.h"
#include "tensor/linalg.h"
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define NB 31 /* output bands */
#define MAX_F 2048 /* features */

const char *lm_bound_map_name(int map)
{
    return map == LM_BOUND_QUADRATIC ? "quadratic" : "linear";
}

int lm_bound_features(int nleds, int map)
{
    return 1 + nleds + (map == LM_BOUND_QUADRATIC ? nleds * (nleds + 1) / 2 : 0);
}

lm_status lm_bound_fit_init(lm_bound_fit *f, int nleds, int map, lm_err *err)
{
    memset(f, 0, sizeof *f);
    if (nleds < 1 || (map != LM_BOUND_LINEAR && map != LM_BOUND_QUADRATIC) ||
        lm_bound_features(nleds, map) > MAX_F)
        return lm_err_set(err, LM_ERR_ARG, "bound: %d LEDs are too many for the %s map (at "
                          "most %d features)", nleds, lm_bound_map_name(map), MAX_F);
    f->map = map;
    f->nleds = nleds;
    f->nf = lm_bound_features(nleds, map);
    f->A = calloc((size_t)f->nf * f->nf, sizeof *f->A);
    f->B = calloc((size_t)f->nf * NB, sizeof *f->B);
    f->W = calloc((size_t)f->nf * NB, sizeof *f->W);
    if (!f->A || !f->B || !f->W) {
        lm_bound_fit_free(f);
        return lm_err_set(err, LM_ERR_NOMEM, "bound: out of memory");
    }
    return LM_OK;
}

void lm_bound_fit_free(lm_bound_fit *f)
{
    free(f->A);
    free(f->B);
    free(f->W);
    memset(f, 0, sizeof *f);
}

lm_status lm_bound_responses(const lm_system *sys, const lm_cube *cube31, float k,
                             const lm_rng *rng, float **resp, lm_err *err)
{
    *resp = NULL;
    if (!(k >= 0.0f) || (k > 0.0f && !rng))
        return lm_err_set(err, LM_ERR_ARG, "bound: noise level %g needs a generator", (double)k);
    if (sys->nbins != 41 || fabsf(sys->grid_start - 380.0f) > 0.5f ||
        fabsf(sys->grid_step - 10.0f) > 0.5f)
        return lm_err_set(err, LM_ERR_SHAPE, "bound: the system's grid must be 380 nm + 10 nm x "
                          "41 bins to read a 31-band cube (has %d bins)", sys->nbins);
    lm_cube c41;
    lm_status st = lm_cube_mirror41(cube31, &c41, err);
    if (st) return st;
    const int L = sys->nleds, H = c41.height, W = c41.width;
    const size_t np = (size_t)H * W;
    float *r = malloc(sizeof(float) * (size_t)L * np);
    if (!r) {
        lm_cube_free(&c41);
        return lm_err_set(err, LM_ERR_NOMEM, "bound: out of memory");
    }
    for (int l = 0; l < L; l++) {
        const float *a = lm_system_response(sys, l);
        float *o = r + (size_t)l * np;
        for (size_t i = 0; i < np; i++) {
            double s = 0.0;
            for (int b = 0; b < 41; b++) s += (double)a[b] * c41.data[(size_t)b * np + i];
            o[i] = (float)s;
        }
    }
    lm_cube_free(&c41);
    if (k > 0.0f) {
        float mx = 0.0f; /* the coded frame's largest clean value */
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++) {
                const float v = r[(size_t)lm_system_pixel_led(sys, y, x) * np + (size_t)y * W + x];
                if (v > mx) mx = v;
            }
        lm_rng g = *rng;
        const float sd = k * mx;
        for (size_t i = 0; i < (size_t)L * np; i++) r[i] += sd * lm_rng_normal(&g);
    }
    *resp = r;
    return LM_OK;
}

/* The features of pixel i (np pixels per plane) into f. */
static void features(const lm_bound_fit *fit, const float *resp, size_t np, size_t i, double *f)
{
    const int L = fit->nleds;
    f[0] = 1.0;
    for (int l = 0; l < L; l++) f[1 + l] = resp[(size_t)l * np + i];
    if (fit->map != LM_BOUND_QUADRATIC) return;
    /* products over the pixel's total response: degree 1 in brightness, as the linear terms
     * are, so a map fitted on bright pixels holds for dim ones */
    double s = 0.0;
    for (int l = 0; l < L; l++) s += fabs(f[1 + l]);
    const double inv = 1.0 / (s > 1e-6 ? s : 1e-6);
    int q = 1 + L;
    for (int a = 0; a < L; a++)
        for (int b = a; b < L; b++) f[q++] = f[1 + a] * f[1 + b] * inv;
}

void lm_bound_add(lm_bound_fit *fit, const float *resp, const lm_cube *truth)
{
    const int nf = fit->nf;
    const size_t np = (size_t)truth->height * truth->width;
    double f[MAX_F];
    for (size_t i = 0; i < np; i++) {
        features(fit, resp, np, i, f);
        for (int a = 0; a < nf; a++) {
            double *row = fit->A + (size_t)a * nf;
            const double fa = f[a];
            for (int b = 0; b <= a; b++) row[b] += fa * f[b];
            double *br = fit->B + (size_t)a * NB;
            for (int c = 0; c < NB; c++) br[c] += fa * truth->data[(size_t)c * np + i];
        }
    }
    fit->pixels += (long)np;
}

lm_status lm_bound_solve(lm_bound_fit *fit, double ridge, lm_err *err)
{
    const int nf = fit->nf;
    if (fit->pixels <= 0 || !(ridge >= 0.0))
        return lm_err_set(err, LM_ERR_ARG, "bound: nothing to fit (%ld pixels, ridge %g)",
                          fit->pixels, ridge);
    double *A = malloc(sizeof(double) * (size_t)nf * nf);
    if (!A) return lm_err_set(err, LM_ERR_NOMEM, "bound: out of memory");
    double tr = 0.0;
    for (int a = 0; a < nf; a++) tr += fit->A[(size_t)a * nf + a];
    const double lam = ridge * tr / nf;
    for (int a = 0; a < nf; a++)
        for (int b = 0; b <= a; b++) {
            const double v = fit->A[(size_t)a * nf + b] + (a == b ? lam : 0.0);
            A[(size_t)a * nf + b] = v;
            A[(size_t)b * nf + a] = v;
        }
    memcpy(fit->W, fit->B, sizeof(double) * (size_t)nf * NB);
    const int bad = lm_cholesky(A, nf);
    if (!bad) lm_cholesky_solve(A, nf, fit->W, NB);
    free(A);
    if (bad)
        return lm_err_set(err, LM_ERR_NUMERIC, "bound: the %s map's normal equations are "
                          "singular (raise --ridge, now %g)", lm_bound_map_name(fit->map), ridge);
    return LM_OK;
}

void lm_bound_predict(const lm_bound_fit *fit, const float *resp, int H, int W, float *out)
{
    const int nf = fit->nf;
    const size_t np = (size_t)H * W;
    double f[MAX_F];
    for (size_t i = 0; i < np; i++) {
        features(fit, resp, np, i, f);
        for (int c = 0; c < NB; c++) {
            double s = 0.0;
            for (int a = 0; a < nf; a++) s += f[a] * fit->W[(size_t)a * NB + c];
            out[(size_t)c * np + i] = (float)s;
        }
    }
}

const double lm_bound_ridge_grid[LM_BOUND_RIDGES] = {1e-9, 1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3};

void lm_bound_run_opts_default(lm_bound_run_opts *o)
{
    memset(o, 0, sizeof *o);
    o->split = LM_SPLIT_TEST;
    o->nnoise = 1;
    o->ridge = -1.0;
    o->seed = 1;
}

static void say(const lm_bound_run_opts *o, const char *fmt, ...)
    __attribute__((format(printf, 2, 3)));
static void say(const lm_bound_run_opts *o, const char *fmt, ...)
{
    if (!o->log) return;
    char line[1400];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(line, sizeof line, fmt, ap);
    va_end(ap);
    o->log(o->user, line);
}

/* Scene s read onto 31 bands and prepared as eval prepares it (cropped to the tile, divided
 * by its maximum); then its responses at level k (the noise seeded per scene and level). */
static lm_status load_scene(const lm_bound_run_opts *o, const lm_system *sys,
                            const lm_dataset_scene *s, lm_cube *cube, lm_err *e)
{
    lm_cube_read_opts ro;
    lm_cube_read_opts_default(&ro);
    ro.keep.count = 0;
    ro.mat_key = o->mat_key;
    lm_status st = lm_cube_read_with(s->path, &ro, cube, e);
    if (st) return st;
    lm_err me;
    lm_err_clear(&me);
    st = lm_eval_prepare(cube, sys->tile_rows, sys->tile_cols, &me);
    if (st) {
        lm_cube_free(cube);
        return lm_err_set(e, st, "%s: %s", s->path, me.msg);
    }
    return LM_OK;
}

static lm_status scene_responses(const lm_bound_run_opts *o, const lm_system *sys,
                                 const lm_dataset_scene *s, const lm_cube *cube, int level,
                                 float **resp, lm_err *e)
{
    lm_rng base, rs;
    lm_rng_seed(&base, (uint64_t)o->seed);
    rs = lm_rng_split(&base, lm_fnv1a_str(LM_FNV1A_BASIS_SHORT, s->name));
    rs = lm_rng_split(&rs, (uint64_t)level);
    lm_err me;
    lm_err_clear(&me);
    lm_status st = lm_bound_responses(sys, cube, o->k[level], &rs, resp, &me);
    return st ? lm_err_set(e, st, "%s: %s", s->path, me.msg) : LM_OK;
}

/* The scenes of one split at one noise level, held in memory. */
typedef struct scene_set {
    int n;
    lm_cube *cube;
    float **resp;
    const char **path, **name;
} scene_set;

static void set_free(scene_set *ss)
{
    for (int i = 0; i < ss->n; i++) {
        lm_cube_free(&ss->cube[i]);
        free(ss->resp[i]);
    }
    free(ss->cube);
    free(ss->resp);
    free(ss->path);
    free(ss->name);
    memset(ss, 0, sizeof *ss);
}

static lm_status set_load(const lm_bound_run_opts *o, const lm_system *sys,
                          const lm_dataset_scene *ls, int nls, lm_data_split split, int level,
                          scene_set *ss, lm_err *e)
{
    memset(ss, 0, sizeof *ss);
    ss->cube = calloc((size_t)nls + 1, sizeof *ss->cube);
    ss->resp = calloc((size_t)nls + 1, sizeof *ss->resp);
    ss->path = calloc((size_t)nls + 1, sizeof *ss->path);
    ss->name = calloc((size_t)nls + 1, sizeof *ss->name);
    if (!ss->cube || !ss->resp || !ss->path || !ss->name) {
        set_free(ss);
        return lm_err_set(e, LM_ERR_NOMEM, "bound: out of memory");
    }
    for (int i = 0; i < nls; i++) {
        if (ls[i].split != split) continue;
        lm_status st = load_scene(o, sys, &ls[i], &ss->cube[ss->n], e);
        if (st) return st;
        ss->path[ss->n] = ls[i].path;
        ss->name[ss->n] = ls[i].name;
        st = scene_responses(o, sys, &ls[i], &ss->cube[ss->n], level, &ss->resp[ss->n], e);
        ss->n++; /* freed by set_free from here on */
        if (st) return st;
    }
    return LM_OK;
}

/* The mean metrics of a fitted map over a set of scenes; with per (not NULL), also each
 * scene's, into per[i].m[map][level]. */
static lm_status set_score(const lm_bound_fit *fit, const scene_set *ss, lm_metrics *out,
                           lm_bound_scene *per, int level, lm_err *e)
{
    lm_metrics_acc acc;
    memset(&acc, 0, sizeof acc);
    for (int i = 0; i < ss->n; i++) {
        const int H = ss->cube[i].height, W = ss->cube[i].width;
        float *pred = malloc(sizeof(float) * NB * (size_t)H * W);
        if (!pred) return lm_err_set(e, LM_ERR_NOMEM, "bound: out of memory");
        lm_bound_predict(fit, ss->resp[i], H, W, pred);
        lm_metrics mt;
        lm_err me;
        lm_err_clear(&me);
        lm_status st = lm_metrics_compute(pred, ss->cube[i].data, NB, H, W, 0, NB, &mt, &me);
        free(pred);
        if (st) return lm_err_set(e, st, "%s: %s", ss->path[i], me.msg);
        if (per) {
            snprintf(per[i].name, sizeof per[i].name, "%s", ss->name[i]);
            per[i].m[fit->map][level] = mt;
        }
        lm_metrics_acc_add(&acc, &mt);
    }
    *out = lm_metrics_acc_mean(&acc);
    return LM_OK;
}

/* The ridge of a map: o->ridge when given (>= 0), else the grid's best on the validation
 * scenes (a singular solve skips that ridge). */
static lm_status pick_ridge(const lm_bound_run_opts *o, lm_bound_fit *fit, const scene_set *val,
                            double *ridge, lm_err *e)
{
    if (o->ridge >= 0.0) return *ridge = o->ridge, LM_OK;
    double best = -1.0, best_psnr = -1e300;
    for (int g = 0; g < LM_BOUND_RIDGES; g++) {
        lm_err se;
        lm_err_clear(&se);
        const double r = lm_bound_ridge_grid[g];
        lm_status st = lm_bound_solve(fit, r, &se);
        if (st == LM_ERR_NUMERIC) continue;
        if (st) return lm_err_set(e, st, "%s", se.msg);
        lm_metrics m;
        if ((st = set_score(fit, val, &m, NULL, 0, e))) return st;
        if (m.psnr > best_psnr) best_psnr = m.psnr, best = r;
    }
    if (best < 0.0)
        return lm_err_set(e, LM_ERR_NUMERIC, "bound: the %s map's normal equations are "
                          "singular at every ridge", lm_bound_map_name(fit->map));
    *ridge = best;
    return LM_OK;
}

/* Fit both maps at one noise level on the training scenes (ridges chosen on the validation
 * scenes), then score the chosen split. */
static lm_status run_level(const lm_bound_run_opts *o, const lm_system *sys,
                           const lm_dataset_scene *ls, int nls, int level, lm_bound_result *res,
                           lm_err *e)
{
    lm_bound_fit fit[LM_BOUND_MAPS];
    memset(fit, 0, sizeof fit);
    scene_set val, scored;
    memset(&val, 0, sizeof val);
    memset(&scored, 0, sizeof scored);
    lm_status st = LM_OK;
    for (int m = 0; m < LM_BOUND_MAPS && !st; m++)
        st = lm_bound_fit_init(&fit[m], sys->nleds, m, e);
    for (int i = 0; i < nls && !st; i++) {
        if (ls[i].split != LM_SPLIT_TRAIN) continue;
        lm_cube cube;
        float *resp = NULL;
        st = load_scene(o, sys, &ls[i], &cube, e);
        if (st) break;
        st = scene_responses(o, sys, &ls[i], &cube, level, &resp, e);
        for (int m = 0; m < LM_BOUND_MAPS && !st; m++) lm_bound_add(&fit[m], resp, &cube);
        free(resp);
        lm_cube_free(&cube);
    }
    res->train_pixels = fit[0].pixels;
    if (!st && o->ridge < 0.0) st = set_load(o, sys, ls, nls, LM_SPLIT_VAL, level, &val, e);
    if (!st) st = set_load(o, sys, ls, nls, (lm_data_split)o->split, level, &scored, e);
    for (int m = 0; m < LM_BOUND_MAPS && !st; m++) {
        double r = 0.0;
        st = pick_ridge(o, &fit[m], &val, &r, e);
        if (!st) st = lm_bound_solve(&fit[m], r, e);
        if (!st && scored.n != res->nscored)
            st = lm_err_set(e, LM_ERR_ARG, "bound: %d scored scenes read, %d listed", scored.n,
                            res->nscored);
        if (!st) st = set_score(&fit[m], &scored, &res->m[m][level], res->scene, level, e);
        res->ridge[m][level] = r;
    }
    set_free(&val);
    set_free(&scored);
    for (int m = 0; m < LM_BOUND_MAPS; m++) lm_bound_fit_free(&fit[m]);
    return st;
}

void lm_bound_result_free(lm_bound_result *res)
{
    free(res->scene);
    res->scene = NULL;
}

lm_status lm_bound_run(const lm_bound_run_opts *o, lm_bound_result *res, lm_err *e)
{
    memset(res, 0, sizeof *res);
    if (o->nnoise < 1 || o->nnoise > LM_BOUND_MAX_NOISE)
        return lm_err_set(e, LM_ERR_ARG, "bound: %d noise levels (1 to %d)", o->nnoise,
                          LM_BOUND_MAX_NOISE);
    if (o->split != LM_SPLIT_TEST && o->split != LM_SPLIT_VAL)
        return lm_err_set(e, LM_ERR_ARG, "bound: the scored split must be test or val");
    lm_system sys;
    lm_status st = o->system ? lm_system_load(o->system, &sys, e) : lm_system_default(&sys, e);
    if (st) return st;
    lm_dataset_scene *ls = NULL;
    int nls = 0;
    st = lm_dataset_list_scenes(o->data, o->ndata, &sys, o->mat_key, -1, &ls, &nls, e);
    if (!st) {
        for (int i = 0; i < nls; i++) {
            res->ntrain += ls[i].split == LM_SPLIT_TRAIN;
            res->nscored += ls[i].split == (lm_data_split)o->split;
            res->nval += ls[i].split == LM_SPLIT_VAL;
        }
        if (!res->ntrain)
            st = lm_err_set(e, LM_ERR_ARG, "no training scenes among the %d given (the maps are "
                            "fitted on the training split)", nls);
        else if (o->ridge < 0.0 && !res->nval)
            st = lm_err_set(e, LM_ERR_ARG, "no validation scenes among the %d given to choose "
                            "the ridge on (give --ridge)", nls);
        else if (!res->nscored)
            st = lm_err_set(e, LM_ERR_ARG, "no scene of split '%s' among the %d given",
                            o->split == LM_SPLIT_VAL ? "val" : "test", nls);
    }
    if (!st && !(res->scene = calloc((size_t)res->nscored, sizeof *res->scene)))
        st = lm_err_set(e, LM_ERR_NOMEM, "bound: out of memory");
    res->nleds = sys.nleds;
    for (int l = 0; l < o->nnoise && !st; l++) {
        say(o, "noise %g %%: fitting on %d training scene(s), scoring %d", 100.0 * o->k[l],
            res->ntrain, res->nscored);
        st = run_level(o, &sys, ls, nls, l, res, e);
    }
    free(ls);
    lm_system_free(&sys);
    if (st) lm_bound_result_free(res);
    return st;
}

/* cmd_calibrate.c — `lumosaic calibrate`: the calibration file of `lumosaic infer --model auto`.
 * What it is: load the models, take held-out scenes (DATA scenes of the val / test splits by
 * name hash, and/or --synth N procedural scenes whose seeds are not drawn by training), simulate
 * each scene's coded frame, record per window the difficulty and every model's error
 * (lm_auto_scene), fit expected PSNR per difficulty bin (lm_auto_fit), store each model's
 * measured seconds per window and MACs, write the JSON and print the per-bin table.
 * What it is not: the selection or the inference (infer/auto.h, cli/cmd_infer.c). */
#define _XOPEN_SOURCE 700 /* realpath */
#include <limits.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "data/cube_io.h"
#include "data/dataset.h"
#include "data/synth.h"
#include "infer/auto.h"
#include "infer/eval.h"
#include "models/profile.h"

#define SYNTH_SEED_BASE 0xCA11B0000000ull /* procedural scenes: seed base + seed * 1e6 + i */

static void help(void)
{
    printf("usage: lumosaic calibrate --models RUN,RUN[,...] [DATA...] [--synth N]\n"
           "                          --output FILE [--split val|test|valtest|all] [--bins B]\n"
           "                          [--measure grad|relgrad] [--noise PERCENT] [--seed S]\n"
           "                          [--synth-size HxW] [--batch N] [--threads T]\n\n"
           "Calibrate 'lumosaic infer --model auto': on held-out scenes, per 66 x 64 window\n"
           "(stride 30 x 32), record a cheap difficulty of the coded frame and each model's\n"
           "error (K-weighted MSE on 400-700 nm); fit each model's expected PSNR per difficulty\n"
           "bin (quantiles) and measure its cost (seconds per window on this machine; MACs for\n"
           "information). Writes FILE (JSON) and prints the table per bin.\n\n"
           "  --models LIST    2..8 training run folders or .safetensors files, comma-separated\n"
           "  DATA...          scene files or folders; only scenes of --split are used\n"
           "  --split S        which DATA scenes (by name hash, as training): val, test,\n"
           "                   valtest (default: both held-out splits) or all\n"
           "  --synth N        add N procedural scenes (default 0; seeds disjoint from the\n"
           "                   random 64-bit seeds training draws)\n"
           "  --synth-size HxW procedural scene size (default 198x256)\n"
           "  --output FILE    calibration file to write (JSON)\n"
           "  --bins B         difficulty bins (1..32; default 8)\n"
           "  --measure M      difficulty: grad = mean same-phase absolute difference\n"
           "                   (default), relgrad = grad / mean level\n"
           "  --noise PERCENT  Gaussian noise k of the simulated frames (default 0)\n"
           "  --seed S         noise and procedural scene seed (default 1)\n"
           "  --batch N        windows per network call (1..4096; default 8)\n"
           "  --threads T      OpenMP threads (1..1024; default: all cores)\n"
           "  --help           this text\n");
}

typedef struct cal_opts {
    const char *models, *output, *split_s, *measure_s, *size_s;
    const char **data;
    int ndata, split, measure, sh, sw;
    long long synth, bins, seed, batch, threads;
    double noise;
} cal_opts;

static int parse_opt(lm_cli *c, cal_opts *o)
{
    int r;
    if ((r = lm_cli_value(c, "--models", &o->models)) ||
        (r = lm_cli_value(c, "--output", &o->output)) ||
        (r = lm_cli_value(c, "--split", &o->split_s)) ||
        (r = lm_cli_value(c, "--measure", &o->measure_s)) ||
        (r = lm_cli_value(c, "--synth-size", &o->size_s)) ||
        (r = lm_cli_int(c, "--synth", 0, 100000, &o->synth)) ||
        (r = lm_cli_int(c, "--bins", 1, LM_AUTO_MAX_BINS, &o->bins)) ||
        (r = lm_cli_int(c, "--seed", 0, LLONG_MAX / 2000000, &o->seed)) ||
        (r = lm_cli_int(c, "--batch", 1, 4096, &o->batch)) ||
        (r = lm_cli_int(c, "--threads", 1, 1024, &o->threads)) ||
        (r = lm_cli_real(c, "--noise", 0.0, 100.0, &o->noise)))
        return r < 0 ? 2 : 1;
    return 0;
}

static int check_opts(lm_cli *c, cal_opts *o)
{
    static const char *const splits[] = {"val", "test", "valtest", "all", NULL};
    if (!o->models) return lm_cli_error(c, "--models is required (see 'lumosaic calibrate --help')");
    if (!o->output) return lm_cli_error(c, "--output is required (see 'lumosaic calibrate --help')");
    if (!o->ndata && !o->synth)
        return lm_cli_error(c, "no scenes: give DATA (held-out scenes) and/or --synth N");
    o->split = 2;
    if (o->split_s) {
        o->split = -1;
        for (int i = 0; splits[i]; i++)
            if (!strcmp(o->split_s, splits[i])) o->split = i;
        if (o->split < 0)
            return lm_cli_error(c, "--split '%s': use val, test, valtest or all", o->split_s);
    }
    o->measure = lm_auto_measure_parse(o->measure_s ? o->measure_s : "grad");
    if (o->measure < 0)
        return lm_cli_error(c, "--measure '%s': use grad or relgrad", o->measure_s);
    o->sh = 198, o->sw = 256;
    if (o->size_s && (sscanf(o->size_s, "%dx%d", &o->sh, &o->sw) != 2 || o->sh < 66 ||
                      o->sw < 64 || o->sh > 4096 || o->sw > 4096))
        return lm_cli_error(c, "--synth-size '%s': want HxW, at least 66x64", o->size_s);
    return 1;
}

/* 1: run, 0: help printed, 2: bad usage (printed). */
static int parse(lm_cli *c, cal_opts *o)
{
    *o = (cal_opts){.bins = 8, .seed = 1, .batch = 8};
    o->data = calloc((size_t)c->argc + 1, sizeof *o->data);
    if (!o->data) return lm_cli_error(c, "out of memory");
    while (!lm_cli_done(c)) {
        if (lm_cli_is_help(c)) {
            help();
            return 0;
        }
        int r = parse_opt(c, o);
        if (r == 2) return 2;
        if (r == 1) continue;
        if (lm_cli_positional(c, o->data, &o->ndata)) return 2;
    }
    return check_opts(c, o);
}

typedef struct cal_run {
    const lm_cli *c;
    const cal_opts *o;
    lm_infer_model im[LM_AUTO_MAX_MODELS];
    lm_model *models[LM_AUTO_MAX_MODELS];
    lm_auto_calib cal;
    lm_ctx ctx;
    char (*scenes)[1024];
    int nscenes;
    double *d, *mse, secs[LM_AUTO_MAX_MODELS];  /* samples: n, nmodels x cap */
    long n, cap;
} cal_run;

/* Split "A,B,C" and load each model. 0 ok, else an exit status (printed). */
static int load_models(cal_run *r, lm_err *e)
{
    char buf[8192];
    if (snprintf(buf, sizeof buf, "%s", r->o->models) >= (int)sizeof buf)
        return lm_cli_error(r->c, "--models: list too long");
    lm_auto_calib *a = &r->cal;
    for (char *s = strtok(buf, ","); s; s = strtok(NULL, ",")) {
        if (a->nmodels == LM_AUTO_MAX_MODELS)
            return lm_cli_error(r->c, "--models: at most %d models", LM_AUTO_MAX_MODELS);
        lm_infer_model *im = &r->im[a->nmodels];
        if (lm_infer_model_load(s, NULL, im, e)) return lm_cli_error(r->c, "%s", e->msg);
        lm_auto_model *x = &a->models[a->nmodels];
        char *abs = realpath(im->weights, NULL); /* infer may run from another folder */
        snprintf(x->path, sizeof x->path, "%s", abs ? abs : im->weights);
        free(abs);
        snprintf(x->preset, sizeof x->preset, "%s", im->model->preset);
        r->models[a->nmodels++] = im->model;
        if (im->model->mosaic.ty != r->models[0]->mosaic.ty ||
            im->model->mosaic.tx != r->models[0]->mosaic.tx ||
            im->model->in_channels != 1 || im->model->out_channels != LM_MODEL_OUT_CHANNELS)
            return lm_cli_error(r->c, "--models: '%s' does not take the same coded frames as "
                                "'%s'", s, a->models[0].path);
    }
    if (a->nmodels < 2) return lm_cli_error(r->c, "--models: give at least 2 models");
    return 0;
}

/* The DATA scenes of the chosen split. 0 ok, else an exit status (printed). */
static int list_scenes(cal_run *r, lm_err *e)
{
    if (!r->o->ndata) return 0;
    lm_dataset_cfg cfg;
    lm_dataset_default_cfg(&cfg);
    cfg.paths = r->o->data;
    cfg.npaths = r->o->ndata;
    cfg.sys = &r->im[0].sys;
    cfg.workers = 0;
    cfg.synth_fraction = 0.0f;
    lm_dataset *d = lm_dataset_open(&cfg, e);
    if (!d) return lm_cli_error(r->c, "%s", e->msg);
    int total = 0;
    for (int k = 0; k < 3; k++) total += lm_dataset_num_scenes(d, (lm_data_split)k);
    r->scenes = calloc((size_t)total + 1, sizeof *r->scenes);
    for (int k = 0; k < 3 && r->scenes; k++)
        for (int i = 0; i < lm_dataset_num_scenes(d, (lm_data_split)k); i++) {
            lm_data_split s = lm_dataset_split_of(lm_dataset_scene_name(d, (lm_data_split)k, i));
            const char *p = lm_dataset_scene_path(d, (lm_data_split)k, i);
            int keep = r->o->split == 3 || (r->o->split == 2 && s != LM_SPLIT_TRAIN) ||
                       (r->o->split == 0 && s == LM_SPLIT_VAL) ||
                       (r->o->split == 1 && s == LM_SPLIT_TEST);
            for (int j = 0; j < r->nscenes && keep; j++)
                if (!strcmp(r->scenes[j], p)) keep = 0;
            if (keep) snprintf(r->scenes[r->nscenes++], 1024, "%s", p);
        }
    lm_dataset_close(d);
    if (!r->scenes) return lm_cli_error(r->c, "out of memory"), 1;
    if (!r->nscenes && !r->o->synth)
        return lm_cli_error(r->c, "no DATA scene of split '%s' among the %d given (use --synth "
                            "N for procedural held-out scenes, or --split all)",
                            r->o->split_s ? r->o->split_s : "valtest", total);
    return 0;
}

/* Scene i (DATA scenes first, then procedural) prepared: cropped, max 1. */
static lm_status scene_cube(cal_run *r, int i, lm_cube *cube, lm_err *e)
{
    const lm_mosaic *mo = &r->models[0]->mosaic;
    lm_status st = i < r->nscenes
                       ? lm_cube_read(r->scenes[i], cube, e)
                       : lm_synth_scene(SYNTH_SEED_BASE + (uint64_t)r->o->seed * 1000000u +
                                            (uint64_t)(i - r->nscenes),
                                        r->o->sh, r->o->sw, NULL, cube, e);
    return st ? st : lm_eval_prepare(cube, mo->ty, mo->tx, e);
}

/* Make room for n more samples. */
static lm_status grow(cal_run *r, long n, lm_err *e)
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

/* One scene's samples appended. */
static lm_status scene_samples(cal_run *r, int i, const lm_tile_opts *to, lm_err *e)
{
    lm_cube cube;
    if (scene_cube(r, i, &cube, e)) return e->status;
    float *frame = NULL;
    size_t nf;
    lm_noise_opts no = {.gauss_k = (float)(r->o->noise / 100.0)};
    lm_rng rng;
    lm_rng_seed(&rng, (uint64_t)r->o->seed * 7919u + (uint64_t)i);
    lm_status st = lm_eval_simulate(&r->im[0], &cube, &no, &rng, &frame, &nf, e);
    int nw = lm_auto_window_count(cube.height, cube.width, to), nm = r->cal.nmodels;
    double *mse = st ? NULL : malloc(sizeof(double) * nw * nm);
    if (!st && (!mse || grow(r, nw, e)))
        st = lm_err_set(e, LM_ERR_NOMEM, "out of memory");
    if (!st)
        st = lm_auto_scene(&r->ctx, r->models, nm, r->cal.measure, frame, cube.data, cube.height,
                           cube.width, to, r->d + r->n, mse, r->secs, e);
    for (int m = 0; m < nm && !st; m++)
        memcpy(r->mse + m * r->cap + r->n, mse + (size_t)m * nw, sizeof(double) * nw);
    if (!st) r->n += nw;
    free(mse);
    free(frame);
    lm_cube_free(&cube);
    return st;
}

static void print_table(const cal_run *r)
{
    const lm_auto_calib *a = &r->cal;
    printf("%ld windows from %d scene(s); measure %s\n", r->n, r->nscenes + (int)r->o->synth,
           lm_auto_measure_name(a->measure));
    printf("model cost: ");
    for (int m = 0; m < a->nmodels; m++)
        printf("%s%s %.3g ms/window (%.3g MMAC)", m ? ", " : "", a->models[m].preset,
               1e3 * a->models[m].cost, a->models[m].macs / 1e6);
    printf("\n%-24s %8s", "difficulty bin", "windows");
    for (int m = 0; m < a->nmodels; m++) printf(" %10.10s", a->models[m].preset);
    printf("   (expected PSNR, dB)\n");
    for (int b = 0; b < a->nbins; b++) {
        char lo[16] = "-inf", hi[16] = "inf", rng[40];
        if (b > 0) snprintf(lo, sizeof lo, "%.4g", a->edges[b - 1]);
        if (b < a->nbins - 1) snprintf(hi, sizeof hi, "%.4g", a->edges[b]);
        snprintf(rng, sizeof rng, "[%s, %s)", lo, hi);
        printf("%-24s %8ld", rng, a->windows[b]);
        for (int m = 0; m < a->nmodels; m++) printf(" %10.2f", a->models[m].psnr[b]);
        printf("\n");
    }
}

static int calibrate(cal_run *r, lm_err *e)
{
    lm_tile_opts to;
    lm_tile_default_opts(&to);
    to.batch = (int)r->o->batch;
    lm_auto_calib *a = &r->cal;
    a->measure = (lm_auto_measure)r->o->measure;
    a->win_h = to.win_h, a->win_w = to.win_w, a->stride_y = to.stride_y,
    a->stride_x = to.stride_x;
    int total = r->nscenes + (int)r->o->synth;
    for (int i = 0; i < total; i++) {
        double t0 = omp_get_wtime();
        if (scene_samples(r, i, &to, e))
            return lm_cli_error(r->c, "scene %d (%s): %s", i + 1,
                                i < r->nscenes ? r->scenes[i] : "procedural", e->msg),
                   e->status == LM_ERR_NOMEM ? 1 : 2;
        fprintf(stderr, "scene %d/%d: %.2f s\n", i + 1, total, omp_get_wtime() - t0);
    }
    for (int m = 0; m < a->nmodels; m++) {
        lm_profile p;
        a->models[m].cost = r->secs[m] / (double)r->n;
        if (a->models[m].cost <= 0.0) a->models[m].cost = 1e-9;
        if (!lm_model_profile(r->models[m], 1, to.win_h, to.win_w, &p, e)) {
            a->models[m].macs = p.total_macs;
            lm_profile_free(&p);
        }
    }
    /* the samples are stored with stride cap per model: pack them for the fit */
    for (int m = 1; m < a->nmodels; m++)
        memmove(r->mse + m * r->n, r->mse + m * r->cap, sizeof(double) * r->n);
    if (lm_auto_fit(a, r->d, r->mse, r->n, (int)r->o->bins, e))
        return lm_cli_error(r->c, "%s (use fewer --bins or more scenes)", e->msg);
    if (lm_auto_save(r->o->output, a, e)) return lm_cli_error(r->c, "%s", e->msg), 1;
    print_table(r);
    return 0;
}

int lm_cmd_calibrate(int argc, char **argv)
{
    lm_cli c;
    cal_opts o;
    lm_cli_init(&c, "lumosaic calibrate", argc, argv);
    int rc = parse(&c, &o);
    if (rc != 1) {
        free(o.data);
        return rc;
    }
    if (o.threads > 0) omp_set_num_threads((int)o.threads);
    cal_run r;
    memset(&r, 0, sizeof r);
    r.c = &c;
    r.o = &o;
    lm_err e;
    lm_err_clear(&e);
    rc = load_models(&r, &e);
    if (!rc) rc = list_scenes(&r, &e);
    if (!rc && lm_ctx_init(&r.ctx, (int)o.threads) != 0) {
        lm_cli_error(&c, "out of memory (compute context)");
        rc = 1;
    } else if (!rc) {
        rc = calibrate(&r, &e);
        lm_ctx_free(&r.ctx);
    }
    for (int m = 0; m < LM_AUTO_MAX_MODELS; m++) lm_infer_model_free(&r.im[m]);
    free(r.scenes);
    free(r.d);
    free(r.mse);
    free(o.data);
    return rc;
}

/* cmd_fit_auto.c — `lumosaic fit-auto`: the calibration file of `lumosaic infer --model auto`.
 * What it is: load the models, take held-out scenes (DATA scenes of the dataset's val / test
 * splits, as training splits them, and/or --synth N procedural scenes whose seeds are not
 * drawn by training), simulate each scene's coded frame, record per window the difficulty
 * and every model's error (lm_auto_scene), fit expected PSNR per difficulty bin (lm_auto_fit),
 * store each model's measured seconds per window and MACs, write the JSON and print the
 * per-bin table.
 * With --test-synth N: N more procedural scenes (a seed stream disjoint from the calibration
 * scenes') reconstructed by every model alone and by the auto choice at each --test-tol (the
 * selection of `infer --model auto`: lm_auto_bin / lm_auto_choose per window, lm_auto_infer),
 * scored by PSNR against the truth (31 bands, scene divided by its maximum, as eval), with the
 * share of windows per model, the seconds per 640 x 480 frame estimated from the calibrated
 * per-window costs and the measured wall time; printed and stored as "test" in the JSON.
 * What it is not: the selection or the inference (infer/auto.h, cli/cmd_infer.c). */
#define _XOPEN_SOURCE 700 /* realpath */
#include <jansson.h>
#include <limits.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include "cli/cli_util.h"
#include "data/util.h"
#include "cli/commands.h"
#include "data/cube_io.h"
#include "data/dataset.h"
#include "data/synth.h"
#include "infer/auto.h"
#include "infer/eval.h"
#include "models/profile.h"

#define SYNTH_SEED_BASE 0xCA11B0000000ull /* procedural scenes: seed base + seed * 1e6 + i */
#define TEST_SEED_OFFSET 500000u            /* test scenes: seed base + seed * 1e6 + 5e5 + j */
#define MAX_TOL 16

static void help(void)
{
    printf("usage: lumosaic fit-auto --models RUN,RUN[,...] [DATA...] [--synth N]\n"
           "                          --output FILE [--split val|test|valtest|all] [--bins B]\n"
           "                          [--measure grad|relgrad] [--noise PERCENT] [--seed S]\n"
           "                          [--synth-size HxW] [--batch N] [--threads T]\n"
           "                          [--test-synth N] [--test-tol LIST]\n\n"
           "Calibrate 'lumosaic infer --model auto': on held-out scenes, per 66 x 64 window\n"
           "(stride 30 x 32), record a cheap difficulty of the coded frame and each model's\n"
           "error (K-weighted MSE on 400-700 nm); fit each model's expected PSNR per difficulty\n"
           "bin (quantiles) and measure its cost (seconds per window on this machine; MACs for\n"
           "information). Writes FILE (JSON) and prints the table per bin.\n\n"
           "  --models LIST    2..8 training run folders or .safetensors files, comma-separated\n"
           "  DATA...          scene files or folders; only scenes of --split are used\n"
           "  --split S        which DATA scenes (the dataset's split, as training): val, test,\n"
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
           "  --test-synth N   after fitting, measure on N more procedural scenes (default 0;\n"
           "                   seeds disjoint from training's and the calibration scenes'):\n"
           "                   every model alone and auto at each --test-tol, PSNR, share of\n"
           "                   windows per model, seconds per 640x480 frame (estimated from\n"
           "                   the per-window costs, and measured); table + \"test\" in FILE\n"
           "  --test-tol LIST  tolerances in dB for --test-synth (default 0,0.25,0.5,1,2)\n"
           "  --batch N        windows per network call (1..4096; default 8)\n"
           "  --threads T      OpenMP threads (1..1024; default: all cores)\n"
           "  --help           this text\n");
}

typedef struct cal_opts {
    const char *models, *output, *split_s, *measure_s, *size_s, *tol_s;
    const char **data;
    int ndata, split, measure, sh, sw, ntol;
    long long synth, bins, batch, test_synth;
    lm_cli_common com; /* --threads, --seed */
    double noise, tol[MAX_TOL];
} cal_opts;

static int parse_opt(lm_cli *c, cal_opts *o)
{
    int r;
    if ((r = lm_cli_value(c, "--models", &o->models)) ||
        (r = lm_cli_value(c, "--output", &o->output)) ||
        (r = lm_cli_value(c, "--split", &o->split_s)) ||
        (r = lm_cli_value(c, "--measure", &o->measure_s)) ||
        (r = lm_cli_value(c, "--synth-size", &o->size_s)) ||
        (r = lm_cli_value(c, "--test-tol", &o->tol_s)) ||
        (r = lm_cli_int(c, "--test-synth", 0, 100000, &o->test_synth)) ||
        (r = lm_cli_int(c, "--synth", 0, 100000, &o->synth)) ||
        (r = lm_cli_int(c, "--bins", 1, LM_AUTO_MAX_BINS, &o->bins)) ||
        (r = lm_cli_common_opt(c, LM_CLI_THREADS | LM_CLI_SEED, LLONG_MAX / 2000000, &o->com)) ||
        (r = lm_cli_int(c, "--batch", 1, 4096, &o->batch)) ||
        (r = lm_cli_real(c, "--noise", 0.0, 100.0, &o->noise)))
        return r < 0 ? 2 : 1;
    return 0;
}

/* --test-tol LIST into o->tol. 0 ok, else 2 (printed). */
static int parse_tol(lm_cli *c, cal_opts *o)
{
    const char *s = o->tol_s ? o->tol_s : "0,0.25,0.5,1,2";
    char why[128];
    o->ntol = lm_parse_list(s, 0, 1e6, o->tol, MAX_TOL, why, sizeof why);
    if (o->ntol < 0)
        return o->ntol = 0, lm_cli_error(c, "--test-tol '%s': %s (tolerances in dB, e.g. "
                                         "0,0.5,1)", s, why);
    return 0;
}

static int check_opts(lm_cli *c, cal_opts *o)
{
    static const char *const splits[] = {"val", "test", "valtest", "all", NULL};
    if (!o->models) return lm_cli_error(c, "--models is required (see 'lumosaic fit-auto --help')");
    if (!o->output) return lm_cli_error(c, "--output is required (see 'lumosaic fit-auto --help')");
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
    if (o->size_s && (lm_cli_parse_size(o->size_s, 64, 4096, &o->sh, &o->sw) || o->sh < 66))
        return lm_cli_error(c, "--synth-size '%s': want HxW, from 66x64 to 4096x4096",
                            o->size_s);
    if (parse_tol(c, o)) return 2;
    struct stat sb; /* an output that cannot be written is known before the fit */
    if (stat(o->output, &sb) == 0 && !S_ISREG(sb.st_mode))
        return lm_cli_error(c, "--output %s: exists and is not a file", o->output);
    return 1;
}

/* 1: run, 0: help printed, 2: bad usage (printed). */
static int parse(lm_cli *c, cal_opts *o)
{
    *o = (cal_opts){.bins = 8, .com.seed = 1, .batch = 8};
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
    size_t len = strlen(buf);
    if (!len || buf[0] == ',' || buf[len - 1] == ',' || strstr(buf, ",,"))
        return lm_cli_error(r->c, "--models '%s': an empty element (models separated by single "
                            "commas)", r->o->models);
    for (char *s = strtok(buf, ","); s; s = strtok(NULL, ",")) {
        if (a->nmodels == LM_AUTO_MAX_MODELS)
            return lm_cli_error(r->c, "--models: at most %d models", LM_AUTO_MAX_MODELS);
        lm_infer_model *im = &r->im[a->nmodels];
        if (lm_infer_model_load(s, NULL, im, e)) return lm_cli_error(r->c, "%s", e->msg);
        lm_auto_model *x = &a->models[a->nmodels];
        char *abs = realpath(im->weights, NULL); /* infer may run from another folder */
        snprintf(x->path, sizeof x->path, "%s", abs ? abs : im->weights);
        free(abs);
        lm_model_name(im->model, x->preset, sizeof x->preset); /* NET+BASE for residuals */
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

/* The DATA scenes of the chosen split (lm_dataset_list_scenes; valtest: val, then test).
 * 0 ok, else an exit status (printed). */
static int list_scenes(cal_run *r, lm_err *e)
{
    if (!r->o->ndata) return 0;
    const int all[] = {-1}, valtest[] = {LM_SPLIT_VAL, LM_SPLIT_TEST}, val[] = {LM_SPLIT_VAL},
              test[] = {LM_SPLIT_TEST};
    const int *splits = r->o->split == 3 ? all : r->o->split == 2 ? valtest
                        : r->o->split == 0 ? val : test;
    int nsplits = r->o->split == 2 ? 2 : 1, total = 0;
    for (int k = 0; k < nsplits; k++) {
        lm_dataset_scene *sc = NULL;
        int n = 0;
        if (lm_dataset_list_scenes(r->o->data, r->o->ndata, &r->im[0].sys, NULL, splits[k], &sc,
                                   &n, e))
            return lm_cli_error(r->c, "%s", e->msg);
        char (*grown)[1024] = realloc(r->scenes, ((size_t)total + n + 1) * sizeof *r->scenes);
        if (!grown) {
            free(sc);
            return lm_cli_error(r->c, "out of memory"), 1;
        }
        r->scenes = grown;
        for (int i = 0; i < n; i++) snprintf(r->scenes[total + i], 1024, "%s", sc[i].path);
        total += n;
        free(sc);
    }
    r->nscenes = total;
    if (!r->scenes) r->scenes = calloc(1, sizeof *r->scenes);
    if (!r->scenes) return lm_cli_error(r->c, "out of memory"), 1;
    if (!r->nscenes && !r->o->synth)
        return lm_cli_error(r->c, "no DATA scene of split '%s' among the %d DATA path(s) (use "
                            "--synth N for procedural held-out scenes, or --split all)",
                            r->o->split_s ? r->o->split_s : "valtest", r->o->ndata);
    return 0;
}

/* Scene i (DATA scenes first, then the --synth procedural ones, then the --test-synth ones)
 * prepared: cropped, max 1. */
static lm_status scene_cube(cal_run *r, int i, lm_cube *cube, lm_err *e)
{
    const lm_mosaic *mo = &r->models[0]->mosaic;
    uint64_t k = (uint64_t)(i - r->nscenes); /* procedural index */
    if (k >= (uint64_t)r->o->synth) k = TEST_SEED_OFFSET + (k - (uint64_t)r->o->synth);
    lm_status st = i < r->nscenes
                       ? lm_cube_read(r->scenes[i], cube, e)
                       : lm_synth_scene(SYNTH_SEED_BASE + (uint64_t)r->o->com.seed * 1000000u + k,
                                        r->o->sh, r->o->sw, NULL, cube, e);
    return st ? st : lm_eval_prepare(cube, mo->ty, mo->tx, e);
}

/* Scene i prepared and its coded frame simulated (noise stream seed * 7919 + i). */
static lm_status scene_frame(cal_run *r, int i, lm_cube *cube, float **frame, lm_err *e)
{
    *frame = NULL;
    if (scene_cube(r, i, cube, e)) return e->status;
    size_t nf;
    lm_noise_opts no = {.gauss_k = (float)(r->o->noise / 100.0)};
    lm_rng rng;
    lm_rng_seed(&rng, (uint64_t)r->o->com.seed * 7919u + (uint64_t)i);
    lm_status st = lm_eval_simulate(&r->im[0], cube, &no, &rng, frame, &nf, e);
    if (st) lm_cube_free(cube);
    return st;
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
    float *frame;
    if (scene_frame(r, i, &cube, &frame, e)) return e->status;
    int nw = lm_auto_window_count(cube.height, cube.width, to), nm = r->cal.nmodels;
    double *mse = malloc(sizeof(double) * nw * nm);
    lm_status st = mse && !grow(r, nw, e) ? LM_OK
                                          : lm_err_set(e, LM_ERR_NOMEM, "out of memory");
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

/* ---- --test-synth: auto against the fixed models on scenes not calibrated on ------------- */
typedef struct test_row {
    int model;                    /* fixed rows: the model; auto rows: -1 */
    double tol;                   /* auto rows */
    int choice[LM_AUTO_MAX_BINS]; /* model per bin (fixed rows: `model` everywhere) */
    int same;                     /* auto row with the choice of an earlier auto row, or -1 */
    double psnr;                  /* sum over the scenes, then the mean */
    long win[LM_AUTO_MAX_MODELS];
    double wall;                  /* seconds: difficulty (auto) + reconstruction */
} test_row;

typedef struct test_run {
    test_row rows[LM_AUTO_MAX_MODELS + MAX_TOL];
    int nrows, best;              /* best: the fixed row of the highest mean PSNR */
    long windows;                 /* windows of the test scenes */
    int wpf;                      /* windows per 640 x 480 frame */
} test_run;

static long row_windows(const test_row *w, int nm)
{
    long n = 0;
    for (int m = 0; m < nm; m++) n += w->win[m];
    return n;
}

/* Seconds per 640 x 480 frame from the calibrated per-window costs and the row's shares. */
static double row_est(const cal_run *r, const test_run *t, const test_row *w)
{
    double s = 0.0;
    long n = row_windows(w, r->cal.nmodels);
    for (int m = 0; m < r->cal.nmodels; m++)
        s += n ? (double)w->win[m] / n * r->cal.models[m].cost : 0.0;
    return s * t->wpf;
}

/* One test scene through every row that runs (auto rows with a repeated choice do not). */
static lm_status test_scene(cal_run *r, test_run *t, int i, const lm_tile_opts *to, lm_err *e)
{
    const lm_auto_calib *a = &r->cal;
    const lm_mosaic *mo = &r->models[0]->mosaic;
    lm_cube cube, pred;
    float *frame;
    if (scene_frame(r, i, &cube, &frame, e)) return e->status;
    const int H = cube.height, W = cube.width, n = lm_auto_window_count(H, W, to);
    double *d = malloc(sizeof(double) * n);
    int *wm = malloc(sizeof(int) * n);
    lm_status st = d && wm ? LM_OK : lm_err_set(e, LM_ERR_NOMEM, "out of memory");
    double t0 = omp_get_wtime();
    if (!st) st = lm_auto_frame_difficulty(a->measure, frame, H, W, mo->ty, mo->tx, to,
                                           lm_nthreads(&r->ctx), d, e);
    const double tdiff = omp_get_wtime() - t0;
    t->windows += st ? 0 : n;
    for (int k = 0; k < t->nrows && !st; k++) {
        test_row *w = &t->rows[k];
        if (w->same >= 0) continue;
        t0 = omp_get_wtime();
        if (w->model >= 0) {
            st = lm_tile_infer(&r->ctx, r->models[w->model], frame, H, W, to, &pred, e);
            w->win[w->model] += st ? 0 : n;
        } else {
            for (int j = 0; j < n; j++) wm[j] = w->choice[lm_auto_bin(a, d[j])];
            st = lm_auto_infer(&r->ctx, r->models, a->nmodels, wm, frame, H, W, to, &pred,
                               w->win, e);
        }
        w->wall += omp_get_wtime() - t0 + (w->model < 0 ? tdiff : 0.0);
        if (st) break;
        w->psnr += lm_metric_psnr(pred.data, cube.data, 31, H, W, 0, 31);
        lm_cube_free(&pred);
    }
    free(d);
    free(wm);
    free(frame);
    lm_cube_free(&cube);
    return st;
}

/* The rows (fixed models, then auto per tolerance), every test scene, the means. 0 ok, else an
 * exit status (printed). */
static int test_models(cal_run *r, test_run *t, const lm_tile_opts *to, lm_err *e)
{
    const lm_auto_calib *a = &r->cal;
    const int nm = a->nmodels, first = r->nscenes + (int)r->o->synth;
    memset(t, 0, sizeof *t);
    for (int m = 0; m < nm; m++) {
        test_row *w = &t->rows[t->nrows++];
        w->model = m, w->same = -1;
        for (int b = 0; b < a->nbins; b++) w->choice[b] = m;
    }
    for (int k = 0; k < r->o->ntol; k++) {
        test_row *w = &t->rows[t->nrows];
        w->model = -1, w->same = -1, w->tol = r->o->tol[k];
        lm_auto_choose(a, w->tol, w->choice);
        for (int j = nm; j < t->nrows && w->same < 0; j++)
            if (!memcmp(t->rows[j].choice, w->choice, sizeof(int) * a->nbins)) w->same = j;
        t->nrows++;
    }
    for (int i = 0; i < (int)r->o->test_synth; i++) {
        double t0 = omp_get_wtime();
        if (test_scene(r, t, first + i, to, e))
            return lm_cli_error(r->c, "test scene %d: %s", i + 1, e->msg),
                   lm_cli_exit_status(e->status);
        fprintf(stderr, "test scene %d/%lld: %.2f s\n", i + 1, r->o->test_synth,
                omp_get_wtime() - t0);
    }
    for (int k = 0; k < t->nrows; k++) {
        test_row *w = &t->rows[k];
        if (w->same >= 0) {
            int same = w->same;
            double tol = w->tol;
            *w = t->rows[same];
            w->same = same, w->tol = tol;
        } else {
            w->psnr /= (double)r->o->test_synth;
        }
    }
    t->best = 0;
    for (int m = 1; m < nm; m++)
        if (t->rows[m].psnr > t->rows[t->best].psnr) t->best = m;
    lm_tile_opts vga = *to;
    t->wpf = lm_auto_window_count(480, 640, &vga);
    return 0;
}

static void row_name(const cal_run *r, const test_row *w, char *s, size_t n)
{
    if (w->model >= 0) snprintf(s, n, "%s", r->cal.models[w->model].preset);
    else snprintf(s, n, "auto tol %g", w->tol);
}

static void print_test(const cal_run *r, const test_run *t)
{
    const lm_auto_calib *a = &r->cal;
    const test_row *b = &t->rows[t->best];
    printf("\ntest: %lld procedural scene(s) of %dx%d not calibrated on, %ld windows; "
           "%d windows per 640x480 frame; %d thread(s)\n", r->o->test_synth, r->o->sh,
           r->o->sw, t->windows, t->wpf, omp_get_max_threads());
    printf("%-16s %8s %7s %8s %10s %10s %8s %8s  %s\n", "row", "PSNR dB", "vs best", "calib dB",
           "est s/fr", "meas s/fr", "speedup", "wall s", "windows per model");
    for (int k = 0; k < t->nrows; k++) {
        const test_row *w = &t->rows[k];
        char name[64];
        row_name(r, w, name, sizeof name);
        long n = row_windows(w, a->nmodels);
        printf("%-16s %8.3f %7.3f %8.3f %10.4f %10.4f %7.2fx %8.2f ", name, w->psnr,
               w->psnr - b->psnr, lm_auto_expected_psnr(a, w->choice, 0), row_est(r, t, w),
               n ? w->wall * t->wpf / n : 0.0, row_est(r, t, b) / row_est(r, t, w), w->wall);
        for (int m = 0; m < a->nmodels; m++) /* the models that ran */
            if (w->win[m]) printf(" %s %.1f%%", a->models[m].preset, 100.0 * w->win[m] / n);
        if (w->same >= 0) printf("  (same choice as tol %g: reused)", t->rows[w->same].tol);
        printf("\n");
    }
    printf("vs best / speedup: against always %s (the best fixed model on these scenes; speedup "
           "from the estimated seconds). est: calibrated network seconds per window x windows; "
           "meas: wall time of the test reconstructions (difficulty, fold and all) per 640x480 "
           "frame\n", a->models[t->best].preset);
}

/* The "test" member of the calibration file. */
static json_t *test_json(const cal_run *r, const test_run *t)
{
    const lm_auto_calib *a = &r->cal;
    const test_row *b = &t->rows[t->best];
    json_t *rows = json_array();
    for (int k = 0; k < t->nrows; k++) {
        const test_row *w = &t->rows[k];
        long n = row_windows(w, a->nmodels);
        json_t *share = json_array(), *choice = json_array();
        for (int m = 0; m < a->nmodels; m++)
            json_array_append_new(share, json_real(n ? (double)w->win[m] / n : 0.0));
        for (int c = 0; c < a->nbins; c++)
            json_array_append_new(choice, json_integer(w->choice[c]));
        json_t *o = json_pack("{s:s, s:f, s:f, s:f, s:o, s:o, s:f, s:f, s:f, s:f}", "kind",
                              w->model >= 0 ? "fixed" : "auto", "psnr_db", w->psnr,
                              "psnr_vs_best_db", w->psnr - b->psnr, "calib_psnr_db",
                              lm_auto_expected_psnr(a, w->choice, 0), "share", share, "choice",
                              choice, "est_s_per_frame", row_est(r, t, w),
                              "measured_s", w->wall, "measured_s_per_frame",
                              n ? w->wall * t->wpf / n : 0.0, "speedup_est",
                              row_est(r, t, b) / row_est(r, t, w));
        if (w->model >= 0)
            json_object_set_new(o, "model", json_string(a->models[w->model].preset));
        else
            json_object_set_new(o, "tol_db", json_real(w->tol));
        if (w->same >= 0) json_object_set_new(o, "same_choice_as_row", json_integer(w->same));
        json_array_append_new(rows, o);
    }
    json_t *test = json_pack("{s:I, s:[i,i], s:I, s:i, s:i, s:s, s:o}", "scenes",
                             (json_int_t)r->o->test_synth, "size", r->o->sh, r->o->sw, "windows",
                             (json_int_t)t->windows, "windows_per_640x480", t->wpf, "threads",
                             omp_get_max_threads(), "best", a->models[t->best].preset, "rows",
                             rows);
    return json_pack("{s:o}", "test", test);
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
                   lm_cli_exit_status(e->status);
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
    print_table(r);
    fflush(stdout);
    test_run *t = r->o->test_synth ? calloc(1, sizeof *t) : NULL;
    if (r->o->test_synth && !t) return lm_cli_error(r->c, "out of memory"), 1;
    int rc = t ? test_models(r, t, &to, e) : 0;
    json_t *extra = !rc && t ? test_json(r, t) : NULL;
    if (!rc && t && !extra) lm_cli_error(r->c, "out of memory"), rc = 1;
    if (!rc && lm_auto_save_ext(r->o->output, a, extra, e))
        lm_cli_error(r->c, "%s", e->msg), rc = 1;
    if (!rc && t) print_test(r, t);
    json_decref(extra);
    free(t);
    return rc;
}

int lm_cmd_fit_auto(int argc, char **argv)
{
    lm_cli c;
    cal_opts o;
    lm_cli_init(&c, "lumosaic fit-auto", argc, argv);
    int rc = parse(&c, &o);
    if (rc != 1) {
        free(o.data);
        return rc;
    }
    lm_cli_common_apply(&o.com);
    cal_run r;
    memset(&r, 0, sizeof r);
    r.c = &c;
    r.o = &o;
    lm_err e;
    lm_err_clear(&e);
    rc = load_models(&r, &e);
    if (!rc) rc = list_scenes(&r, &e);
    if (!rc && lm_ctx_init(&r.ctx, (int)o.com.threads) != 0) {
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

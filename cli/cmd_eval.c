/* cmd_eval.c — `lumosaic eval`: score a trained model on scenes (system.md §10) and on the
 * rainbow scene (§7).
 * What it is: list the scenes of the given paths (data/dataset.h), keep the chosen split (the
 * dataset's split lists, as in training; `all` keeps every scene), per scene crop to the tile
 * and normalise by its own maximum, simulate the model's sensor frame at each noise level
 * (Gaussian, k % of the largest clean value, seeded per scene name and level): the coded
 * frame, or for the passive RGB
 * baseline (MST++, in_channels 3) the RGB camera image; reconstruct (patch-wise, infer/tile.h,
 * or whole-frame for MST++) and score PSNR / SSIM / MAE / SAM on the 31 bands (infer/eval.h);
 * with --motion, per scene and speed a 3-frame coded video of the scene translating at that
 * speed, its middle frame reconstructed with and without temporal alignment (for RGB models:
 * one motion-blurred camera frame, aligned = unaligned; lm_eval_motion_run), scored on the
 * region that stays in view beside a static reference; then the rainbow
 * peak-wavelength test. Prints tables
 * (rows: noise levels / speeds, means over scenes) and writes eval.json + eval.csv (+
 * eval_motion.csv with --motion) into --output atomically (a staging folder renamed into place).
 * --device opencl runs the network on an OpenCL device (weights uploaded once, lm_tile_device;
 * MST++ models run on the CPU only).
 * --scenes names the scored scenes instead of a split; each scored scene whose content the
 * checkpoint lists among its training scenes gets a warning line (after the scores, so that an
 * error stays the only line); the reconstruction's seconds per frame are reported per level.
 * A --system of other LED gains than the model's is simulated as the camera and its frames
 * rescaled to the model's gains (infer/eval.h), unless --no-gain-remap.
 * What it is not: training-time validation (train/), or a benchmark of speed. */
#include <errno.h>
#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "data/cube_io.h"
#include "data/dataset.h"
#include "data/util.h"
#include "infer/eval.h"
#include "infer/report.h"
#include "tensor/isa.h"

static void help(void)
{
    printf("usage: lumosaic eval --model RUN DATA... [--split test|val|train|all]\n"
           "                     [--noise 0,5,10,15,20] [--output DIR] [--seed S]\n"
           "                     [--threads T] [--rainbow SIZE] [--batch N] [--system FILE]\n"
           "                     [--motion 0,60,120,240] [--motion-noise 0,10]\n"
           "                     [--align confident|plain] [--precision fp32|bf16]\n"
           "                     [--device cpu|opencl] [--mat-key NAME] [--scenes NAMES]\n"
           "                     [--report [--report-noise K]]\n\n"
           "Score a trained model (docs/system.md, Metrics): each scene is cropped to the tile,\n"
           "divided by its own maximum, simulated at each noise level and reconstructed\n"
           "patch-wise; PSNR (peak 1), SSIM, MAE and SAM (degrees) on the 31 bands 400-700 nm.\n"
           "RGB models (the MST++ baseline) see the scene through an RGB camera (Nikon D5100,\n"
           "D65, white balanced) instead and reconstruct the whole frame at once.\n"
           "Then the rainbow scene: per row, the recovered peak wavelength (parabolic fit\n"
           "around the largest band of the row's mean spectrum) against the true one.\n"
           "s/frame: the reconstruction's seconds per frame (simulation and scoring not\n"
           "counted). A scored scene that the model was trained on (its content hash is among\n"
           "those the checkpoint records) gets a warning line: its score is not held out.\n\n"
           "  --model RUN      a training run folder or a .safetensors written by 'lumosaic train'\n"
           "  DATA...          scenes (CAVE folders, .mat, spectral .exr) or folders of scenes;\n"
           "                   bands other than 31 at 400-700 nm are resampled (docs/system.md)\n"
           "  --mat-key NAME   the .mat variable holding each cube (default: automatic)\n"
           "  --split S        test (default), val, train (the dataset's split, as in training:\n"
           "                   scene groups ranked by hash, 10%% test, 10%% val) or all\n"
           "  --scenes NAMES   score these scenes (comma-separated names, as the table prints\n"
           "                   them) among DATA's, whatever their split (not with --split)\n"
           "  --noise LIST     Gaussian noise levels in %% of the largest clean value\n"
           "                   (default 0,5,10,15,20; at most %d levels, each 0..100)\n"
           "  --output DIR     write DIR/eval.json and DIR/eval.csv (DIR must not exist, or be\n"
           "                   empty; written atomically). Without it only the table is printed\n"
           "  --seed S         noise seed (default 1)\n"
           "  --threads T      OpenMP threads (1..1024; default: all cores)\n"
           "  --rainbow SIZE   rainbow scene size (0 = skip, else 66..4096; default 256)\n"
           "  --batch N        windows per network call (1..4096; default 8)\n"
           "  --system FILE    system description (default: the one recorded in the model).\n"
           "                   One that differs from the model's only in LED gains (a\n"
           "                   calibrated system) is simulated as the camera and its frames\n"
           "                   rescaled per tile phase to the model's gains (one line says so)\n"
           "  --no-gain-remap  with such a --system: give its frames to the model as they are\n"
           "                   (what the rescaling gains, measured)\n"
           "  --motion LIST    also score moving scenes: speeds in px/s (0..10000, at most %d),\n"
           "                   each a 3-frame noise-free coded video of the scene translating\n"
           "                   along (0.8, 0.6); the middle frame is reconstructed with and\n"
           "                   without temporal alignment and scored against the scene at its\n"
           "                   lime instant (sub-images must be >= 24 x 24), over the region\n"
           "                   that stays in view in all three frames (a margin of the motion\n"
           "                   over two frame periods plus two tiles), beside the static\n"
           "                   reference (that scene as a still frame). RGB models: one\n"
           "                   camera frame blurred over the exposure, nothing to align\n"
           "                   (aligned = unaligned). Multi-frame models (\"-mf3\"): the\n"
           "                   three frames stacked, aligned onto the middle one or as\n"
           "                   recorded. Default: off\n"
           "  --motion-noise L the --motion rows at these noise levels too (%%, at most %d;\n"
           "                   each frame its own draw, k x its maximum; coded models only;\n"
           "                   default 0 = noise-free)\n"
           "  --align A        confident (default): a pixel keeps its unaligned value where\n"
           "                   the flow is inconsistent forward-backward (data/align.h);\n"
           "                   plain: warp every pixel\n"
           "  --device D       where the network runs: cpu or opencl (default: env LM_DEVICE,\n"
           "                   else cpu); the weights are copied to the device once;\n"
           "                   MST++ models run on the CPU only\n"
           "  --clip           clip the noisy frame to [0, 1] (full scale) as a sensor or a\n"
           "                   16-bit PNG frame holds it (default: off, negatives kept)\n"
           "  --bits N         quantise the frame to N bits (16: a PNG frame; default 0 = off)\n"
           "  --photons P      shot noise at every level: P photo-electrons at full scale (the\n"
           "                   brightest LED's white response), before the Gaussian k (0 = off)\n"
           "  --read-noise E   read noise: E electrons with --photons, else a fraction of full\n"
           "                   scale (0 = off)\n"
           "  --noise-oracle   models that read the noise level (lmmse, residuals on it) get\n"
           "                   the simulated level instead of estimating it from the frame\n"
           LM_CLI_PRECISION_HELP
           "  --report         also write DIR/report.html (see 'lumosaic report --help') and\n"
           "                   what it shows: the first scene's reconstruction and truth at\n"
           "                   one noise level (sample_recon.exr, sample_truth.exr, negatives\n"
           "                   clamped to 0; sample.json) and rainbow.csv (peak per row);\n"
           "                   needs --output; reconstructs that scene once more\n"
           "  --report-noise K the sample's noise level in %%, one of --noise (default: the\n"
           "                   level nearest 10)\n"
           "  --help           this text\n", LM_EVAL_MAX_NOISE, LM_EVAL_MAX_MOTION,
           LM_EVAL_MAX_MOTION_NOISE);
}

typedef struct eval_opts {
    const char *model, *output, *system, *mat_key, *scenes;
    lm_cli_common com; /* --threads, --device, --seed */
    const char **data;
    int ndata, split; /* split: 0 test, 1 val, 2 train, 3 all */
    int split_given;
    float k[LM_EVAL_MAX_NOISE];
    int nnoise;
    double speed[LM_EVAL_MAX_MOTION];
    int nmotion;
    float mk[LM_EVAL_MAX_MOTION_NOISE]; /* --motion-noise levels (fractions) */
    int nmk;
    long long rainbow, batch;
    int noise_oracle, clip, align_plain, report, no_remap;
    double report_noise; /* --report-noise in %, -1 = the level nearest 10 % */
    long long bits;
    double photons, read_noise;
} eval_opts;

static const char *const split_names[] = {"test", "val", "train", "all", NULL};
static const char *const align_names[] = {"confident", "plain", NULL};

/* A list of noise levels in % into k (fractions), at most max; flag names the option. */
static int parse_levels(lm_cli *c, const char *flag, const char *s, float *k, int *n, int max)
{
    double v[64];
    char why[128];
    *n = lm_parse_list(s, 0, 100, v, max < 64 ? max : 64, why, sizeof why);
    if (*n < 0)
        return *n = 0, lm_cli_error(c, "%s '%s': %s (levels in %% from 0 to 100, e.g. 0,5,10)",
                                    flag, s, why);
    for (int i = 0; i < *n; i++) k[i] = (float)(v[i] / 100.0);
    return 0;
}

static int parse_noise(lm_cli *c, const char *s, eval_opts *o)
{
    return parse_levels(c, "--noise", s, o->k, &o->nnoise, LM_EVAL_MAX_NOISE);
}

static int parse_motion(lm_cli *c, const char *s, eval_opts *o)
{
    char why[128];
    o->nmotion = lm_parse_list(s, 0, 10000, o->speed, LM_EVAL_MAX_MOTION, why, sizeof why);
    if (o->nmotion < 0)
        return o->nmotion = 0, lm_cli_error(c, "--motion '%s': %s (speeds in px/s from 0 to "
                                            "10000, e.g. 0,60,240)", s, why);
    return 0;
}

static int parse_opt(lm_cli *c, eval_opts *o)
{
    const char *noise = NULL, *motion = NULL, *mnoise = NULL;
    int r;
    if ((r = lm_cli_value(c, "--model", &o->model)) ||
        (r = lm_cli_value(c, "--output", &o->output)) ||
        (r = lm_cli_value(c, "--system", &o->system)) ||
        (r = lm_cli_value(c, "--mat-key", &o->mat_key)) ||
        (r = lm_cli_value(c, "--scenes", &o->scenes)) ||
        (r = lm_cli_common_opt(c, LM_CLI_THREADS | LM_CLI_DEVICE | LM_CLI_SEED | LM_CLI_PRECISION,
                               (long long)1 << 62, &o->com)) ||
        ((r = lm_cli_choice(c, "--split", split_names, &o->split)) && (o->split_given = 1)) ||
        (r = lm_cli_choice(c, "--align", align_names, &o->align_plain)) ||
        (r = lm_cli_int(c, "--rainbow", 0, 4096, &o->rainbow)) ||
        (r = lm_cli_int(c, "--batch", 1, 4096, &o->batch)) ||
        (r = lm_cli_value(c, "--noise", &noise)) ||
        (r = lm_cli_value(c, "--motion", &motion)) ||
        (r = lm_cli_value(c, "--motion-noise", &mnoise)) ||
        (r = lm_cli_flag(c, "--noise-oracle", &o->noise_oracle)) ||
        (r = lm_cli_flag(c, "--report", &o->report)) ||
        (r = lm_cli_real(c, "--report-noise", 0, 100, &o->report_noise)) ||
        (r = lm_cli_flag(c, "--no-gain-remap", &o->no_remap)) ||
        (r = lm_cli_flag(c, "--clip", &o->clip)) ||
        (r = lm_cli_int(c, "--bits", 0, 24, &o->bits)) ||
        (r = lm_cli_real(c, "--photons", 0, 1e12, &o->photons)) ||
        (r = lm_cli_real(c, "--read-noise", 0, 1e6, &o->read_noise))) {
        if (r < 0) return 2;
        if (noise && parse_noise(c, noise, o)) return 2;
        if (motion && parse_motion(c, motion, o)) return 2;
        if (mnoise && parse_levels(c, "--motion-noise", mnoise, o->mk, &o->nmk,
                                   LM_EVAL_MAX_MOTION_NOISE))
            return 2;
        return 1;
    }
    return 0;
}

/* The --noise level of the report's sample: --report-noise's, else the one nearest 10 %
 * (-1: --report-noise is not a level). */
static int report_level(const eval_opts *o)
{
    int best = -1;
    for (int n = 0; n < o->nnoise; n++) {
        double d = fabs(100.0 * o->k[n] - (o->report_noise >= 0 ? o->report_noise : 10.0));
        if (o->report_noise >= 0 ? d < 1e-4 : best < 0 || d < fabs(100.0 * o->k[best] - 10.0))
            best = n;
    }
    return best;
}

/* 1: run, 0: help printed, 2: bad usage (printed). */
static int parse(lm_cli *c, eval_opts *o)
{
    *o = (eval_opts){.com.seed = 1, .rainbow = 256, .batch = 8, .nnoise = 5,
                     .k = {0.0f, 0.05f, 0.10f, 0.15f, 0.20f}, .nmk = 1, .report_noise = -1};
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
    if (!o->model) return lm_cli_error(c, "--model is required (see 'lumosaic eval --help')");
    if (!o->ndata)
        return lm_cli_error(c, "no DATA given: name scenes or folders of scenes "
                               "(see 'lumosaic eval --help')");
    if (o->report && !o->output)
        return lm_cli_error(c, "--report needs --output (the report goes into DIR)");
    if (o->report_noise >= 0 && !o->report)
        return lm_cli_error(c, "--report-noise needs --report");
    if (o->report_noise >= 0 && report_level(o) < 0)
        return lm_cli_error(c, "--report-noise %g is not one of the --noise levels",
                            o->report_noise);
    if (o->scenes && o->split_given)
        return lm_cli_error(c, "--scenes names the scenes to score: give it or --split, not both");
    if (o->scenes && !o->scenes[0]) return lm_cli_error(c, "--scenes: no names given");
    if (o->rainbow > 0 && o->rainbow < 66)
        return lm_cli_error(c, "--rainbow %lld: need 0 (skip) or at least 66 (the window)",
                            o->rainbow);
    return 1;
}

typedef struct scene_res {
    char name[256], path[1024];
    lm_data_split split; /* the dataset's split of the scene (never a borrowed one) */
    int height, width;
    lm_metrics m[LM_EVAL_MAX_NOISE];
    double sec[LM_EVAL_MAX_NOISE]; /* reconstruction seconds of the frame at each level */
    lm_eval_motion mo[LM_EVAL_MAX_MOTION * LM_EVAL_MAX_MOTION_NOISE]; /* noise-major */
} scene_res;

typedef struct eval_run {
    const lm_cli *c;
    const eval_opts *o;
    lm_infer_model im;
    lm_ctx ctx;
    int have_ctx;
    lm_tile_device dev;
    scene_res *sc;
    int nsc;
    lm_metrics mean[LM_EVAL_MAX_NOISE];
    double mean_sec[LM_EVAL_MAX_NOISE];
    lm_eval_motion mo_mean[LM_EVAL_MAX_MOTION * LM_EVAL_MAX_MOTION_NOISE];
    lm_eval_rainbow rb;
    char tmp[1100]; /* staging folder of --output ("" until created) */
} eval_run;

static int fail(const lm_cli *c, const lm_err *e)
{
    lm_cli_error(c, "%s", e->msg);
    return lm_cli_exit_status(e->status);
}

/* --scenes: keep the named scenes, in the order named; a name not among DATA's is an error
 * (printed; its status returned). */
static int pick_scenes(eval_run *r)
{
    char *names = strdup(r->o->scenes), *save = NULL;
    scene_res *kept = calloc((size_t)r->nsc + 1, sizeof *kept);
    int nk = 0, rc = 0;
    if (!names || !kept) rc = (lm_cli_error(r->c, "out of memory"), 1);
    for (char *t = rc ? NULL : strtok_r(names, ",", &save); t && !rc; t = strtok_r(NULL, ",", &save)) {
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
            rc = lm_cli_error(r->c, "--scenes: no scene '%s' among the %d given (%s)", t, r->nsc,
                              list);
        } else if (hit >= 0) {
            kept[nk++] = r->sc[hit];
        }
    }
    if (!rc) {
        memcpy(r->sc, kept, sizeof *kept * (size_t)nk);
        r->nsc = nk;
    }
    free(kept);
    free(names);
    return rc;
}

/* A warning line for each scored scene the model was trained on (by content); one note when
 * the model records no training scenes. */
static void warn_overlap(const eval_run *r)
{
    for (int i = 0; i < r->nsc; i++) {
        int t = lm_eval_trained_on(&r->im, r->sc[i].path);
        if (t < 0) {
            fprintf(stderr, "lumosaic eval: note: %s records no training scenes: overlap with "
                    "the scored scenes is not checked\n", r->im.weights);
            return;
        }
        if (t > 0)
            fprintf(stderr, "lumosaic eval: warning: scene %s (%s) was in the model's training "
                    "set: its score is not a held-out score\n", r->sc[i].name, r->sc[i].path);
    }
}

/* The scenes of the chosen split among those the DATA paths name: the dataset's list of that
 * split, or every list for `all`. A borrowed list (fewer than 3 scenes, no scene of its own
 * in that split) is skipped: its scenes are in their own split's list. */
static int list_scenes(eval_run *r, lm_err *e)
{
    lm_dataset_scene *ls;
    int nls;
    if (lm_dataset_list_scenes((const char *const *)r->o->data, r->o->ndata, &r->im.sys,
                               r->o->mat_key, -1, &ls, &nls, e))
        return fail(r->c, e);
    r->sc = calloc((size_t)nls + 1, sizeof *r->sc);
    if (!r->sc) {
        free(ls);
        return lm_cli_error(r->c, "out of memory"), 1;
    }
    for (int i = 0; i < nls; i++) {
        scene_res *s = &r->sc[r->nsc++];
        snprintf(s->name, sizeof s->name, "%s", ls[i].name);
        snprintf(s->path, sizeof s->path, "%s", ls[i].path);
        s->split = ls[i].split;
    }
    free(ls);
    static const lm_data_split want[3] = {LM_SPLIT_TEST, LM_SPLIT_VAL, LM_SPLIT_TRAIN};
    int given = r->nsc;
    if (r->o->scenes) return pick_scenes(r);
    if (r->o->split < 3) {
        r->nsc = 0;
        for (int i = 0; i < given; i++)
            if (r->sc[i].split == want[r->o->split]) r->sc[r->nsc++] = r->sc[i];
    }
    if (r->nsc == 0)
        return lm_cli_error(r->c, "no scene of split '%s' among the %d given (try --split all)",
                            split_names[r->o->split], given);
    return 0;
}

/* Motion rows: every --motion-noise level by every --motion speed, noise-major. */
static int motion_rows(const eval_opts *o) { return o->nmotion * o->nmk; }

/* The --motion speeds (at each --motion-noise level) on one prepared scene; rng: the scene's
 * noise generator. */
static lm_status scene_motion(eval_run *r, scene_res *s, const lm_cube *cube,
                              const lm_tile_opts *to, const lm_rng *rng, lm_err *e)
{
    lm_status st = LM_OK;
    lm_err me;
    lm_err_clear(&me);
    lm_align_opts ao;
    lm_align_default_opts(&ao);
    ao.confidence = !r->o->align_plain;
    int k = 0;
    lm_rng mr = lm_rng_split(rng, 0x6d6f74696f6eULL); /* "motion": apart from the still rows' */
    for (; k < motion_rows(r->o) && !st; k++)
        st = lm_eval_motion_run_noise(&r->ctx, &r->im, cube, r->o->speed[k % r->o->nmotion],
                                      r->o->mk[k / r->o->nmotion], &mr, to, NULL, &ao,
                                      &s->mo[k], &me);
    if (st) lm_err_set(e, st, "--motion %g px/s: %s", r->o->speed[(k - 1) % r->o->nmotion], me.msg);
    return st;
}

/* Means over the scenes of the motion rows. */
static void motion_means(eval_run *r)
{
    for (int k = 0; k < motion_rows(r->o); k++) {
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

static int eval_scenes(eval_run *r, const lm_tile_opts *to, lm_err *e)
{
    lm_rng base;
    lm_rng_seed(&base, (uint64_t)r->o->com.seed);
    lm_metrics_acc acc[LM_EVAL_MAX_NOISE];
    memset(acc, 0, sizeof acc);
    for (int i = 0; i < r->nsc; i++) {
        scene_res *s = &r->sc[i];
        double t0 = omp_get_wtime();
        lm_cube cube;
        lm_cube_read_opts ro; /* onto 31 bands 400-700 nm, as the dataset reads scenes */
        lm_cube_read_opts_default(&ro);
        ro.keep.count = 0;
        ro.mat_key = r->o->mat_key;
        if (lm_cube_read_with(s->path, &ro, &cube, e)) return fail(r->c, e);
        lm_status st = lm_eval_prepare(&cube, r->im.model->mosaic.ty, r->im.model->mosaic.tx, e);
        lm_rng rs = lm_rng_split(&base, lm_fnv1a_str(LM_FNV1A_BASIS_SHORT, s->name));
        if (!st) st = lm_eval_scene_timed(&r->ctx, &r->im, &cube, r->o->k, r->o->nnoise, to,
                                          &rs, s->m, s->sec, e);
        if (!st) st = scene_motion(r, s, &cube, to, &rs, e);
        s->height = cube.height;
        s->width = cube.width;
        lm_cube_free(&cube);
        if (st) {
            lm_cli_error(r->c, "%s: %s", s->path, e->msg);
            return lm_cli_exit_status(st);
        }
        for (int n = 0; n < r->o->nnoise; n++) lm_metrics_acc_add(&acc[n], &s->m[n]);
        fprintf(stderr, "scene %d/%d %s (%d x %d): %.2f s\n", i + 1, r->nsc, s->name, s->width,
                s->height, omp_get_wtime() - t0);
    }
    for (int n = 0; n < r->o->nnoise; n++) {
        r->mean[n] = lm_metrics_acc_mean(&acc[n]);
        double t = 0.0;
        for (int i = 0; i < r->nsc; i++) t += r->sc[i].sec[n];
        r->mean_sec[n] = r->nsc ? t / r->nsc : 0.0;
    }
    motion_means(r);
    return 0;
}

static void print_table(const eval_run *r)
{
    if (r->o->scenes) printf("%d scene(s), chosen by --scenes\n", r->nsc);
    else printf("%d scene(s), split %s\n", r->nsc, split_names[r->o->split]);
    printf("%9s %10s %8s %9s %9s %9s\n", "noise %", "PSNR dB", "SSIM", "MAE", "SAM deg",
           "s/frame");
    for (int n = 0; n < r->o->nnoise; n++)
        printf("%9g %10.3f %8.4f %9.5f %9.3f %9.3f\n", 100.0 * r->o->k[n], r->mean[n].psnr,
               r->mean[n].ssim, r->mean[n].mae, r->mean[n].sam, r->mean_sec[n]);
    if (r->o->nmotion) {
        printf("motion (3-frame video, middle frame, in-view region; means over scenes; "
               "alignment %s)\n", align_names[r->o->align_plain]);
        printf("%7s %11s %8s %11s %12s %14s %8s %10s %11s %13s\n", "noise %", "motion px/s",
               "px/frame", "PSNR static", "PSNR aligned", "PSNR unaligned", "SSIM al",
               "SSIM unal", "SAM aligned", "SAM unaligned");
        for (int k = 0; k < motion_rows(r->o); k++) {
            const lm_eval_motion *m = &r->mo_mean[k];
            printf("%7g %11g %8.3g %11.3f %12.3f %14.3f %8.4f %10.4f %11.3f %13.3f\n",
                   100.0 * m->noise, m->speed, m->px_per_frame, m->still.psnr, m->aligned.psnr,
                   m->unaligned.psnr, m->aligned.ssim, m->unaligned.ssim, m->aligned.sam,
                   m->unaligned.sam);
        }
    }
    if (r->o->rainbow > 0)
        printf("rainbow %d x %d: peak error mean %.2f nm, max %.2f nm (row %d); PSNR %.3f dB\n",
               r->rb.width, r->rb.height, r->rb.mean_err_nm, r->rb.max_err_nm, r->rb.worst_row,
               r->rb.m.psnr);
}

/* JSON string body: the characters that need escaping in paths. */
static void json_str(FILE *f, const char *s)
{
    fputc('"', f);
    for (; *s; s++) {
        if (*s == '"' || *s == '\\') fprintf(f, "\\%c", *s);
        else if ((unsigned char)*s < 0x20) fprintf(f, "\\u%04x", (unsigned char)*s);
        else fputc(*s, f);
    }
    fputc('"', f);
}

static void json_metrics(FILE *f, const eval_opts *o, const lm_metrics *m, const double *sec,
                         const char *ind)
{
    for (int n = 0; n < o->nnoise; n++)
        fprintf(f, "%s{\"noise_percent\": %g, \"psnr\": %.6f, \"ssim\": %.6f, \"mae\": %.8f, "
                   "\"sam\": %.6f, \"seconds_per_frame\": %.6f}%s\n", ind, 100.0 * o->k[n],
                m[n].psnr, m[n].ssim, m[n].mae, m[n].sam, sec[n], n + 1 < o->nnoise ? "," : "");
}

static void json_motion(FILE *f, const eval_opts *o, const lm_eval_motion *m, const char *ind)
{
    for (int k = 0; k < motion_rows(o); k++)
        fprintf(f, "%s{\"noise_percent\": %g, \"speed_px_s\": %g, \"px_per_frame\": %.6f, "
                   "\"psnr_static\": %.6f, "
                   "\"psnr_aligned\": %.6f, \"psnr_unaligned\": %.6f, "
                   "\"ssim_aligned\": %.6f, \"ssim_unaligned\": %.6f, \"mae_aligned\": %.8f, "
                   "\"mae_unaligned\": %.8f, \"sam_aligned\": %.6f, \"sam_unaligned\": %.6f}%s\n",
                ind, 100.0 * m[k].noise, m[k].speed, m[k].px_per_frame, m[k].still.psnr,
                m[k].aligned.psnr,
                m[k].unaligned.psnr, m[k].aligned.ssim,
                m[k].unaligned.ssim, m[k].aligned.mae, m[k].unaligned.mae, m[k].aligned.sam,
                m[k].unaligned.sam, k + 1 < motion_rows(o) ? "," : "");
}

/* A path as an absolute one (the result file is read from anywhere), as given if it does not
 * resolve. */
static void json_path(FILE *f, const char *p)
{
    char *abs = realpath(p, NULL);
    json_str(f, abs ? abs : p);
    free(abs);
}

static void write_json(FILE *f, const eval_run *r)
{
    const eval_opts *o = r->o;
    char name[160];
    fprintf(f, "{\n  \"model\": ");
    json_path(f, r->im.weights);
    fprintf(f, ",\n  \"preset\": ");
    json_str(f, lm_model_name(r->im.model, name, sizeof name));
    fprintf(f, ",\n  \"split\": \"%s\",\n  \"seed\": %lld,\n  \"noise_percent\": [",
            o->scenes ? "chosen" : split_names[o->split], o->com.seed);
    for (int n = 0; n < o->nnoise; n++) fprintf(f, "%s%g", n ? ", " : "", 100.0 * o->k[n]);
    fprintf(f, "],\n  \"photons\": %.10g,\n  \"read_noise\": %.10g", o->photons, o->read_noise);
    fprintf(f, ",\n  \"precision\": \"%s\"", o->com.precision == LM_PRECISION_BF16 ? "bf16" : "fp32");
    fprintf(f, ",\n  \"scenes\": [\n");
    for (int i = 0; i < r->nsc; i++) {
        fprintf(f, "    {\"name\": ");
        json_str(f, r->sc[i].name);
        fprintf(f, ", \"path\": ");
        json_path(f, r->sc[i].path);
        fprintf(f, ", \"height\": %d, \"width\": %d, \"results\": [\n", r->sc[i].height,
                r->sc[i].width);
        json_metrics(f, o, r->sc[i].m, r->sc[i].sec, "      ");
        fprintf(f, "    ]");
        if (o->nmotion) {
            fprintf(f, ", \"motion\": [\n");
            json_motion(f, o, r->sc[i].mo, "      ");
            fprintf(f, "    ]");
        }
        fprintf(f, "}%s\n", i + 1 < r->nsc ? "," : "");
    }
    fprintf(f, "  ],\n  \"mean\": [\n");
    json_metrics(f, o, r->mean, r->mean_sec, "    ");
    fprintf(f, "  ]");
    if (o->nmotion) {
        fprintf(f, ",\n  \"motion_speeds_px_s\": [");
        for (int k = 0; k < o->nmotion; k++) fprintf(f, "%s%g", k ? ", " : "", o->speed[k]);
        fprintf(f, "],\n  \"motion_noise_percent\": [");
        for (int k = 0; k < o->nmk; k++) fprintf(f, "%s%g", k ? ", " : "", 100.0 * o->mk[k]);
        fprintf(f, "],\n  \"motion_mean\": [\n");
        json_motion(f, o, r->mo_mean, "    ");
        fprintf(f, "  ]");
    }
    if (o->rainbow > 0)
        fprintf(f, ",\n  \"rainbow\": {\"size\": %d, \"height\": %d, \"width\": %d, "
                   "\"peak_error_mean_nm\": %.4f, \"peak_error_max_nm\": %.4f, \"worst_row\": %d, "
                   "\"psnr\": %.6f, \"ssim\": %.6f, \"mae\": %.8f, \"sam\": %.6f}",
                r->rb.size, r->rb.height, r->rb.width, r->rb.mean_err_nm, r->rb.max_err_nm,
                r->rb.worst_row, r->rb.m.psnr, r->rb.m.ssim, r->rb.m.mae, r->rb.m.sam);
    fprintf(f, "\n}\n");
}

static void write_csv(FILE *f, const eval_run *r)
{
    fprintf(f, "scene,noise_percent,psnr,ssim,mae,sam\n");
    for (int i = 0; i <= r->nsc; i++) {
        const lm_metrics *m = i < r->nsc ? r->sc[i].m : r->mean;
        for (int n = 0; n < r->o->nnoise; n++)
            fprintf(f, "%s,%g,%.6f,%.6f,%.8f,%.6f\n", i < r->nsc ? r->sc[i].name : "mean",
                    100.0 * r->o->k[n], m[n].psnr, m[n].ssim, m[n].mae, m[n].sam);
    }
}

static void write_motion_csv(FILE *f, const eval_run *r)
{
    fprintf(f, "scene,motion_px_s,px_per_frame,psnr_static,psnr_aligned,psnr_unaligned,"
               "ssim_aligned,ssim_unaligned,"
               "mae_aligned,mae_unaligned,sam_aligned,sam_unaligned,noise_percent\n");
    for (int i = 0; i <= r->nsc; i++) {
        const lm_eval_motion *m = i < r->nsc ? r->sc[i].mo : r->mo_mean;
        for (int k = 0; k < motion_rows(r->o); k++)
            fprintf(f, "%s,%g,%.6f,%.6f,%.6f,%.6f,%.6f,%.6f,%.8f,%.8f,%.6f,%.6f,%g\n",
                    i < r->nsc ? r->sc[i].name : "mean", m[k].speed, m[k].px_per_frame,
                    m[k].still.psnr, m[k].aligned.psnr,
                    m[k].unaligned.psnr, m[k].aligned.ssim, m[k].unaligned.ssim,
                    m[k].aligned.mae, m[k].unaligned.mae, m[k].aligned.sam, m[k].unaligned.sam,
                    100.0 * m[k].noise);
    }
}

/* --report: the sample files and report.html into the staging folder. */
static int write_report(eval_run *r, const lm_tile_opts *to)
{
    lm_err e;
    lm_err_clear(&e);
    char page[1200];
    snprintf(page, sizeof page, "%s/report.html", r->tmp);
    const scene_res *s = &r->sc[0];
    if (lm_report_eval_files(&r->ctx, &r->im, s->path, s->name, r->o->mat_key, r->o->com.seed,
                             r->o->k[report_level(r->o)], to, r->o->rainbow > 0 ? &r->rb : NULL,
                             r->tmp, &e) ||
        lm_report_write(r->tmp, page, NULL, NULL, &e)) {
        lm_cli_error(r->c, "report: %s", e.msg);
        return lm_cli_exit_status(e.status);
    }
    return 0;
}

/* Into the staging folder, then renamed onto --output. */
static int write_outputs(eval_run *r, const lm_tile_opts *to)
{
    char path[1200];
    const char *tmp = r->tmp;
    static const char *const names[3] = {"eval.json", "eval.csv", "eval_motion.csv"};
    for (int k = 0; k < (r->o->nmotion ? 3 : 2); k++) {
        snprintf(path, sizeof path, "%s/%s", tmp, names[k]);
        FILE *f = fopen(path, "w");
        if (f) {
            if (k == 2) write_motion_csv(f, r);
            else if (k) write_csv(f, r);
            else write_json(f, r);
        }
        if (!f || ferror(f) | fclose(f)) {
            lm_cli_error(r->c, "%s: cannot write: %s", path, strerror(errno));
            return LM_EXIT_FAILED;
        }
    }
    if (r->o->report) {
        int rc = write_report(r, to);
        if (rc) return rc;
    }
    int rc = lm_cli_commit_dir(r->c, tmp, r->o->output) ? 1 : 0;
    r->tmp[0] = '\0'; /* renamed, or removed by lm_cli_commit_dir on failure */
    return rc;
}

static int run(eval_run *r)
{
    lm_err e;
    lm_err_clear(&e);
    if (lm_infer_model_load(r->o->model, r->o->system, &r->im, &e)) return fail(r->c, &e);
    if (r->im.remap.active) {
        char line[3000];
        lm_gain_remap_describe(&r->im.remap, r->im.system_path, r->im.model_system, line,
                               sizeof line);
        fprintf(stderr, "%s%s\n", line, r->o->no_remap ? "; not applied (--no-gain-remap)" : "");
        if (r->o->no_remap) r->im.remap.active = 0;
    }
    r->im.noise_oracle = r->o->noise_oracle;
    r->im.sensor_clip = r->o->clip;
    r->im.sensor_bits = (int)r->o->bits;
    r->im.photons = r->o->photons, r->im.read_noise = (float)r->o->read_noise;
    int rc = list_scenes(r, &e);
    if (rc) return rc;
    if (r->o->output && (rc = lm_cli_stage_dir(r->c, r->o->output, r->tmp, sizeof r->tmp))) {
        r->tmp[0] = '\0';
        return rc;
    }
    if (lm_ctx_init(&r->ctx, (int)r->o->com.threads) != 0)
        return lm_cli_error(r->c, "out of memory (compute context)"), 1;
    r->have_ctx = 1;
    r->ctx.precision = r->o->com.precision;
    if (r->o->com.precision != LM_PRECISION_FP32)
        fprintf(stderr, "precision: %s\n", lm_precision_describe(r->o->com.precision));
    if (lm_tile_device_open(&r->dev, r->o->com.device, r->im.model, &r->ctx, &e)) return fail(r->c, &e);
    if (r->dev.backend->device != LM_DEVICE_CPU && !lm_model_has(r->im.model, LM_CAP_OPENCL))
        return lm_cli_error(r->c, "--device %s: MST++ models (%s) run on the CPU only",
                            lm_tile_device_name(&r->dev), r->im.model->preset), 2;
    if (r->dev.backend->device != LM_DEVICE_CPU)
        fprintf(stderr, "device: %s\n", lm_tile_device_name(&r->dev));
    lm_tile_opts to;
    lm_tile_default_opts(&to);
    to.batch = (int)r->o->batch;
    if ((rc = eval_scenes(r, &to, &e))) return rc;
    if (r->o->rainbow > 0 &&
        lm_eval_rainbow_run(&r->ctx, &r->im, (int)r->o->rainbow, &to, &r->rb, &e)) {
        lm_cli_error(r->c, "rainbow: %s", e.msg);
        return lm_cli_exit_status(e.status);
    }
    warn_overlap(r); /* after the scores: an error stays the only line */
    print_table(r);
    return r->o->output ? write_outputs(r, &to) : 0;
}

int lm_cmd_eval(int argc, char **argv)
{
    lm_cli c;
    eval_opts o;
    lm_cli_init(&c, "lumosaic eval", argc, argv);
    int rc = parse(&c, &o);
    if (rc == 1) {
        lm_cli_common_apply(&o.com);
        if (lm_cli_signals_init(&c, 0)) {
            free(o.data);
            return lm_cli_error(&c, "cannot install signal handlers"), 1;
        }
        eval_run r;
        memset(&r, 0, sizeof r);
        r.c = &c;
        r.o = &o;
        rc = run(&r);
        if (r.tmp[0]) lm_cli_remove_tree(r.tmp);
        lm_tile_device_close(&r.dev);
        if (r.have_ctx) lm_ctx_free(&r.ctx);
        free(r.sc);
        lm_infer_model_free(&r.im);
    }
    free(o.data);
    return rc;
}

/* cmd_eval.c — `lumosaic eval`: score a trained model on scenes (system.md §10) and on the
 * rainbow scene (§7).
 * What it is: option parsing, the help text, the staging folder of --output (renamed into
 * place at the end), the progress lines on stderr, the overlap warnings (after the scores, so
 * that an error stays the only line) and the tables (rows: noise levels / speeds, means over
 * scenes).
 * What it is not: the evaluation (infer/eval_run.h: scenes, noise levels, motion, means,
 * rainbow), its files (infer/eval_write.h), training-time validation (train/), or a benchmark
 * of speed. */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "data/util.h"
#include "infer/eval_run.h"
#include "infer/eval_write.h"

static void help(void)
{
    printf("usage: lumosaic eval --model RUN DATA... [--split test|val|train|all]\n"
           "                     [--noise 0,5,10,15,20] [--output DIR] [--seed S]\n"
           "                     [--threads T] [--rainbow SIZE] [--batch N] [--system FILE]\n"
           "                     [--motion 0,60,120,240] [--motion-noise 0,10]\n"
           "                     [--align confident|plain] [--precision fp32|bf16]\n"
           "                     [--device cpu|opencl] [--mat-key NAME] [--scenes NAMES]\n"
           "                     [--report [--report-noise K]] [--auto FILE [--auto-tol DB]]\n\n"
           "Score a trained model (docs/system.md, Metrics): each scene is cropped to the tile,\n"
           "divided by its own maximum, simulated at each noise level and reconstructed\n"
           "patch-wise; PSNR (peak 1), SSIM, MAE and SAM (degrees) on the 31 bands 400-700 nm.\n"
           "RGB models (the MST++ baseline) see the scene through an RGB camera (Nikon D5100,\n"
           "D65, white balanced) instead and reconstruct the whole frame at once.\n"
           "Then the rainbow scene: per row, the recovered peak wavelength (parabolic fit\n"
           "around the largest band of the row's mean spectrum) against the true one.\n"
           "s/frame: the reconstruction's seconds per frame (simulation and scoring not\n"
           "counted). A scored scene that the model was trained on (its content hash is among\n"
           "those the checkpoint records) gets a warning line: its score is not held out (one\n"
           "line names them all when there are more than three).\n\n"
           "  --model RUN      a training run folder or a .safetensors written by 'lumosaic train';\n"
           "                   or 'auto' with --auto\n"
           "  --auto FILE      with --model auto: a calibration written by 'lumosaic fit-auto';\n"
           "                   each frame reconstructed as 'infer --model auto --auto FILE' does\n"
           "                   (per window the cheapest model within --auto-tol dB of the best\n"
           "                   expected PSNR; models of one bucket count, CPU)\n"
           "  --auto-tol DB    accuracy the choice may give up per window, in dB of expected\n"
           "                   PSNR (>= 0; default 0.5; 0 = always the best model)\n"
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
           "                   MST++ models and lmmse-guide-b2 (and residuals on it) run\n"
           "                   on the CPU only\n"
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
    lm_eval_run_opts run; /* what the library runs */
    const char *output;
    lm_cli_common com;    /* --threads, --device, --seed, --precision */
    const char **data;
    int ndata, split_given, report;
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

/* --motion: speeds in px/s. */
static int parse_motion(lm_cli *c, const char *s, eval_opts *o)
{
    char why[128];
    int n = lm_parse_list(s, 0, 10000, o->run.speed, LM_EVAL_MAX_MOTION, why, sizeof why);
    o->run.nmotion = n < 0 ? 0 : n;
    return n < 0 ? lm_cli_error(c, "--motion '%s': %s (speeds in px/s from 0 to 10000, e.g. "
                                "0,60,240)", s, why) : 0;
}

static int parse_opt(lm_cli *c, eval_opts *o)
{
    const char *noise = NULL, *motion = NULL, *mnoise = NULL;
    int r;
    if ((r = lm_cli_value(c, "--model", &o->run.model)) ||
        (r = lm_cli_value(c, "--auto", &o->run.auto_file)) ||
        (r = lm_cli_real(c, "--auto-tol", 0.0, 1e6, &o->run.auto_tol)) ||
        (r = lm_cli_value(c, "--output", &o->output)) ||
        (r = lm_cli_value(c, "--system", &o->run.system)) ||
        (r = lm_cli_value(c, "--mat-key", &o->run.mat_key)) ||
        (r = lm_cli_value(c, "--scenes", &o->run.scenes)) ||
        (r = lm_cli_common_opt(c, LM_CLI_THREADS | LM_CLI_DEVICE | LM_CLI_SEED | LM_CLI_PRECISION,
                               (long long)1 << 62, &o->com)) ||
        ((r = lm_cli_choice(c, "--split", split_names, &o->run.split)) && (o->split_given = 1)) ||
        (r = lm_cli_choice(c, "--align", align_names, &o->run.align_plain)) ||
        (r = lm_cli_int(c, "--rainbow", 0, 4096, &o->run.rainbow)) ||
        (r = lm_cli_int(c, "--batch", 1, 4096, &o->run.batch)) ||
        (r = lm_cli_value(c, "--noise", &noise)) ||
        (r = lm_cli_value(c, "--motion", &motion)) ||
        (r = lm_cli_value(c, "--motion-noise", &mnoise)) ||
        (r = lm_cli_flag(c, "--noise-oracle", &o->run.noise_oracle)) ||
        (r = lm_cli_flag(c, "--report", &o->report)) ||
        (r = lm_cli_real(c, "--report-noise", 0, 100, &o->run.report_noise)) ||
        (r = lm_cli_flag(c, "--no-gain-remap", &o->run.no_remap)) ||
        (r = lm_cli_flag(c, "--clip", &o->run.clip)) ||
        (r = lm_cli_int(c, "--bits", 0, 24, &o->run.bits)) ||
        (r = lm_cli_real(c, "--photons", 0, 1e12, &o->run.photons)) ||
        (r = lm_cli_real(c, "--read-noise", 0, 1e6, &o->run.read_noise))) {
        if (r < 0) return 2;
        if (noise && parse_levels(c, "--noise", noise, o->run.k, &o->run.nnoise,
                                  LM_EVAL_MAX_NOISE))
            return 2;
        if (motion && parse_motion(c, motion, o)) return 2;
        if (mnoise && parse_levels(c, "--motion-noise", mnoise, o->run.mk, &o->run.nmk,
                                   LM_EVAL_MAX_MOTION_NOISE))
            return 2;
        return 1;
    }
    return 0;
}

/* 1: run, 0: help printed, 2: bad usage (printed). */
static int parse(lm_cli *c, eval_opts *o)
{
    *o = (eval_opts){.com.seed = 1};
    lm_eval_run_opts_default(&o->run);
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
    if (!o->run.model) return lm_cli_error(c, "--model is required (see 'lumosaic eval --help')");
    const int is_auto = !strcmp(o->run.model, "auto");
    if (is_auto && !o->run.auto_file)
        return lm_cli_error(c, "--model auto needs --auto FILE (a calibration written by "
                               "'lumosaic fit-auto')");
    if (o->run.auto_file && !is_auto)
        return lm_cli_error(c, "--auto is only for --model auto");
    if (!o->ndata)
        return lm_cli_error(c, "no DATA given: name scenes or folders of scenes "
                               "(see 'lumosaic eval --help')");
    if (o->report && !o->output)
        return lm_cli_error(c, "--report needs --output (the report goes into DIR)");
    if (o->run.report_noise >= 0 && !o->report)
        return lm_cli_error(c, "--report-noise needs --report");
    if (o->run.report_noise >= 0 && lm_eval_report_level(&o->run) < 0)
        return lm_cli_error(c, "--report-noise %g is not one of the --noise levels",
                            o->run.report_noise);
    if (o->run.scenes && o->split_given)
        return lm_cli_error(c, "--scenes names the scenes to score: give it or --split, not both");
    if (o->run.scenes && !o->run.scenes[0]) return lm_cli_error(c, "--scenes: no names given");
    if (o->run.rainbow > 0 && o->run.rainbow < 66)
        return lm_cli_error(c, "--rainbow %lld: need 0 (skip) or at least 66 (the window)",
                            o->run.rainbow);
    return 1;
}

static void log_line(void *user, const char *line)
{
    (void)user;
    fprintf(stderr, "%s\n", line);
}

/* A warning line for each scored scene the model was trained on (by content), or one line
 * naming them when there are more than three (e.g. --split train); one note when the model
 * records no training scenes. */
static void warn_overlap(const lm_eval_run *r)
{
    if (r->overlap_unknown) {
        fprintf(stderr, "lumosaic eval: note: %s records no training scenes: overlap with "
                "the scored scenes is not checked\n", r->im.weights);
        return;
    }
    int n = 0;
    for (int i = 0; i < r->nsc; i++) n += r->sc[i].trained > 0;
    if (n > 3) {
        fprintf(stderr, "lumosaic eval: warning: %d of the %d scored scenes were in the model's "
                "training set (", n, r->nsc);
        for (int i = 0, k = 0; i < r->nsc; i++)
            if (r->sc[i].trained > 0) fprintf(stderr, "%s%s", k++ ? ", " : "", r->sc[i].name);
        fprintf(stderr, "): their scores are not held-out scores\n");
        return;
    }
    for (int i = 0; i < r->nsc; i++)
        if (r->sc[i].trained > 0)
            fprintf(stderr, "lumosaic eval: warning: scene %s (%s) was in the model's training "
                    "set: its score is not a held-out score\n", r->sc[i].name, r->sc[i].path);
}

static void print_motion(const lm_eval_run *r)
{
    printf("motion (3-frame video, middle frame, in-view region; means over scenes; "
           "alignment %s)\n", align_names[r->o->align_plain]);
    printf("%7s %11s %8s %11s %12s %14s %8s %10s %11s %13s\n", "noise %", "motion px/s",
           "px/frame", "PSNR static", "PSNR aligned", "PSNR unaligned", "SSIM al",
           "SSIM unal", "SAM aligned", "SAM unaligned");
    for (int k = 0; k < lm_eval_motion_rows(r->o); k++) {
        const lm_eval_motion *m = &r->mo_mean[k];
        printf("%7g %11g %8.3g %11.3f %12.3f %14.3f %8.4f %10.4f %11.3f %13.3f\n",
               100.0 * m->noise, m->speed, m->px_per_frame, m->still.psnr, m->aligned.psnr,
               m->unaligned.psnr, m->aligned.ssim, m->unaligned.ssim, m->aligned.sam,
               m->unaligned.sam);
    }
}

static void print_table(const lm_eval_run *r)
{
    if (r->o->scenes) printf("%d scene(s), chosen by --scenes\n", r->nsc);
    else printf("%d scene(s), split %s\n", r->nsc, split_names[r->o->split]);
    printf("%9s %10s %8s %9s %9s %9s\n", "noise %", "PSNR dB", "SSIM", "MAE", "SAM deg",
           "s/frame");
    for (int n = 0; n < r->o->nnoise; n++)
        printf("%9g %10.3f %8.4f %9.5f %9.3f %9.3f\n", 100.0 * r->o->k[n], r->mean[n].psnr,
               r->mean[n].ssim, r->mean[n].mae, r->mean[n].sam, r->mean_sec[n]);
    if (r->o->nmotion) print_motion(r);
    if (r->o->rainbow > 0)
        printf("rainbow %d x %d: peak error mean %.2f nm, max %.2f nm (row %d); PSNR %.3f dB\n",
               r->rb.width, r->rb.height, r->rb.mean_err_nm, r->rb.max_err_nm, r->rb.worst_row,
               r->rb.m.psnr);
}

static int fail(const lm_cli *c, const lm_err *e)
{
    lm_cli_error(c, "%s", e->msg);
    return lm_cli_exit_status(e->status);
}

/* The run, scored with --output staged first; the results written into the staging folder,
 * then renamed onto --output. Returns the exit status; tmp: the staging folder ("" if none
 * is left to remove). */
static int run(const lm_cli *c, const eval_opts *o, lm_eval_run *r, char *tmp, size_t n)
{
    lm_err e;
    lm_err_clear(&e);
    if (lm_eval_run_open(r, &o->run, &e)) return fail(c, &e);
    int rc = o->output ? lm_cli_stage_dir(c, o->output, tmp, n) : 0;
    if (rc) {
        tmp[0] = '\0';
        return rc;
    }
    if (lm_eval_run_score(r, &e)) return fail(c, &e);
    warn_overlap(r); /* after the scores: an error stays the only line */
    print_table(r);
    if (!o->output) return 0;
    if (lm_eval_write(r, tmp, o->report, &e)) return fail(c, &e);
    rc = lm_cli_commit_dir(c, tmp, o->output) ? 1 : 0;
    tmp[0] = '\0'; /* renamed, or removed by lm_cli_commit_dir on failure */
    return rc;
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
        o.run.data = o.data, o.run.ndata = o.ndata;
        o.run.seed = o.com.seed, o.run.nthreads = (int)o.com.threads;
        o.run.device = o.com.device, o.run.precision = o.com.precision;
        o.run.log = log_line;
        lm_eval_run r;
        char tmp[1100] = "";
        rc = run(&c, &o, &r, tmp, sizeof tmp);
        if (tmp[0]) lm_cli_remove_tree(tmp);
        lm_eval_run_free(&r);
    }
    free(o.data);
    return rc;
}

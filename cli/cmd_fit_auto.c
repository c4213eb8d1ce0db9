/* cmd_fit_auto.c — `lumosaic fit-auto`: the calibration file of `lumosaic infer --model auto`.
 * What it is: option parsing, the help text, progress lines on stderr, the per-bin table and
 * the held-out test's table.
 * What it is not: the calibration or the test (infer/auto_fit.h), the selection or the
 * inference (infer/auto.h). */
#include <limits.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "data/util.h"
#include "infer/auto_fit.h"

static void help(void)
{
    printf("usage: lumosaic fit-auto --models RUN,RUN[,...] [DATA...] [--synth N]\n"
           "                          --output FILE [--split val|test|valtest|all] [--bins B]\n"
           "                          [--measure grad|relgrad|noise] [--noise LIST] [--clip]\n"
           "                          [--bits N] [--seed S]\n"
           "                          [--synth-size HxW] [--batch N] [--threads T]\n"
           "                          [--test-synth N] [--test-tol LIST]\n\n"
           "Calibrate 'lumosaic infer --model auto': on held-out scenes, per 66 x 64 window\n"
           "(stride 30 x 32), record a cheap difficulty of the coded frame and each model's\n"
           "error (K-weighted MSE on 400-700 nm); fit each model's expected PSNR per difficulty\n"
           "bin (quantiles) and measure its cost (seconds per window on this machine; MACs for\n"
           "information). Writes FILE (JSON) and prints the table per bin.\n\n"
           "  --models LIST    2..8 training run folders or .safetensors files, comma-separated,\n"
           "                   that read the same frames (all one-bucket, or all two-bucket:\n"
           "                   their frames are simulated with bucket 0)\n"
           "  DATA...          scene files or folders; only scenes of --split are used\n"
           "  --split S        which DATA scenes (the dataset's split, as training): val, test,\n"
           "                   valtest (default: both held-out splits) or all\n"
           "  --synth N        add N procedural scenes (default 0; seeds disjoint from the\n"
           "                   random 64-bit seeds training draws)\n"
           "  --synth-size HxW procedural scene size (default 198x256)\n"
           "  --output FILE    calibration file to write (JSON)\n"
           "  --bins B         difficulty bins (1..32; default 8)\n"
           "  --measure M      difficulty: grad = mean same-phase absolute difference\n"
           "                   (default), relgrad = grad / mean level, noise = the\n"
           "                   frame's estimated noise level (one choice per frame: e.g. a\n"
           "                   network for clean frames beside one for noisy ones; give\n"
           "                   --noise several levels)\n"
           "  --noise LIST     Gaussian noise k of the simulated frames, in %%; every scene\n"
           "                   at each level, e.g. 0,5,10,20 (1 to 8 levels; default 0)\n"
           "  --clip           clip the noisy frames to [0, 1] (full scale) as a sensor or a\n"
           "                   16-bit PNG file holds them, as 'eval --clip' (default: off,\n"
           "                   negatives kept): calibrate for the frames the models will read\n"
           "  --bits N         quantise the frames to N bits (16: a PNG frame; default 0 = off)\n"
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
    lm_auto_fit_opts run; /* what the library runs */
    const char *output, *split_s, *measure_s, *size_s, *tol_s, *noise_s;
    const char **data;
    lm_cli_common com;    /* --threads, --seed */
} cal_opts;

static int parse_opt(lm_cli *c, cal_opts *o)
{
    int r;
    if ((r = lm_cli_value(c, "--models", &o->run.models)) ||
        (r = lm_cli_value(c, "--output", &o->output)) ||
        (r = lm_cli_value(c, "--split", &o->split_s)) ||
        (r = lm_cli_value(c, "--measure", &o->measure_s)) ||
        (r = lm_cli_value(c, "--synth-size", &o->size_s)) ||
        (r = lm_cli_value(c, "--test-tol", &o->tol_s)) ||
        (r = lm_cli_int(c, "--test-synth", 0, 100000, &o->run.test_synth)) ||
        (r = lm_cli_int(c, "--synth", 0, 100000, &o->run.synth)) ||
        (r = lm_cli_int(c, "--bins", 1, LM_AUTO_MAX_BINS, &o->run.bins)) ||
        (r = lm_cli_common_opt(c, LM_CLI_THREADS | LM_CLI_SEED, LLONG_MAX / 2000000, &o->com)) ||
        (r = lm_cli_int(c, "--batch", 1, 4096, &o->run.batch)) ||
        (r = lm_cli_flag(c, "--clip", &o->run.clip)) ||
        (r = lm_cli_int(c, "--bits", 0, 24, &o->run.bits)) ||
        (r = lm_cli_value(c, "--noise", &o->noise_s)))
        return r < 0 ? 2 : 1;
    return 0;
}

/* --test-tol LIST into the tolerances. 0 ok, else 2 (printed). */
static int parse_tol(lm_cli *c, cal_opts *o)
{
    const char *s = o->tol_s ? o->tol_s : "0,0.25,0.5,1,2";
    char why[128];
    int n = lm_parse_list(s, 0, 1e6, o->run.tol, LM_AUTO_FIT_MAX_TOL, why, sizeof why);
    o->run.ntol = n < 0 ? 0 : n;
    return n < 0 ? lm_cli_error(c, "--test-tol '%s': %s (tolerances in dB, e.g. 0,0.5,1)", s,
                                why) : 0;
}

static int check_opts(lm_cli *c, cal_opts *o)
{
    lm_auto_fit_opts *r = &o->run;
    if (!r->models) return lm_cli_error(c, "--models is required (see 'lumosaic fit-auto --help')");
    if (!o->output) return lm_cli_error(c, "--output is required (see 'lumosaic fit-auto --help')");
    if (!r->ndata && !r->synth)
        return lm_cli_error(c, "no scenes: give DATA (held-out scenes) and/or --synth N");
    if (o->split_s && (r->split = lm_auto_fit_split_parse(o->split_s)) < 0)
        return lm_cli_error(c, "--split '%s': use val, test, valtest or all", o->split_s);
    int measure = lm_auto_measure_parse(o->measure_s ? o->measure_s : "grad");
    if (measure < 0)
        return lm_cli_error(c, "--measure '%s': use grad, relgrad or noise", o->measure_s);
    r->measure = (lm_auto_measure)measure;
    if (o->size_s && (lm_cli_parse_size(o->size_s, 64, 4096, &r->sh, &r->sw) || r->sh < 66))
        return lm_cli_error(c, "--synth-size '%s': want HxW, from 66x64 to 4096x4096",
                            o->size_s);
    if (parse_tol(c, o)) return 2;
    if (o->noise_s) {
        char why[128];
        int n = lm_parse_list(o->noise_s, 0, 100, r->noise, LM_AUTO_FIT_MAX_NOISE, why, sizeof why);
        if (n < 0)
            return lm_cli_error(c, "--noise '%s': %s (levels in %%, e.g. 0,5,10,20)", o->noise_s,
                                why);
        r->nnoise = n;
    }
    struct stat sb; /* an output that cannot be written is known before the fit */
    if (stat(o->output, &sb) == 0 && !S_ISREG(sb.st_mode))
        return lm_cli_error(c, "--output %s: exists and is not a file", o->output);
    return 1;
}

/* 1: run, 0: help printed, 2: bad usage (printed). */
static int parse(lm_cli *c, cal_opts *o)
{
    *o = (cal_opts){.com.seed = 1};
    lm_auto_fit_opts_default(&o->run);
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
        if (lm_cli_positional(c, o->data, &o->run.ndata)) return 2;
    }
    return check_opts(c, o);
}

static void print_table(const lm_auto_fit_run *r)
{
    const lm_auto_fit_opts *o = r->o;
    const lm_auto_calib *a = &r->cal;
    printf("%ld windows from %d scene(s) at %d noise level(s); measure %s", r->n,
           r->nscenes + (int)o->synth, o->nnoise, lm_auto_measure_name(a->measure));
    if (o->clip) printf("; frames clipped to [0, 1]");
    if (o->bits) printf("; frames quantised to %lld bits", o->bits);
    printf("\n");
    printf("model cost: ");
    for (int m = 0; m < a->nmodels; m++)
        printf("%s%s %.3g ms/window (%.3g MMAC)", m ? ", " : "", a->models[m].label,
               1e3 * a->models[m].cost, a->models[m].macs / 1e6);
    /* each model's column as wide as its label: labels of one lineage share long prefixes */
    int width[LM_AUTO_MAX_MODELS];
    printf("\n%-24s %8s", "difficulty bin", "windows");
    for (int m = 0; m < a->nmodels; m++) {
        int len = (int)strlen(a->models[m].label);
        width[m] = len > 10 ? len : 10;
        printf(" %*s", width[m], a->models[m].label);
    }
    printf("   (expected PSNR, dB)\n");
    for (int b = 0; b < a->nbins; b++) {
        char lo[16] = "-inf", hi[16] = "inf", rng[40];
        if (b > 0) snprintf(lo, sizeof lo, "%.4g", a->edges[b - 1]);
        if (b < a->nbins - 1) snprintf(hi, sizeof hi, "%.4g", a->edges[b]);
        snprintf(rng, sizeof rng, "[%s, %s)", lo, hi);
        printf("%-24s %8ld", rng, a->windows[b]);
        for (int m = 0; m < a->nmodels; m++) printf(" %*.2f", width[m], a->models[m].psnr[b]);
        printf("\n");
    }
}

static void row_name(const lm_auto_fit_run *r, const lm_auto_test_row *w, char *s, size_t n)
{
    if (w->model >= 0) snprintf(s, n, "%s", r->cal.models[w->model].label);
    else snprintf(s, n, "auto tol %g", w->tol);
}

static void print_test(const lm_auto_fit_run *r, const lm_auto_test *t)
{
    const lm_auto_fit_opts *o = r->o;
    const lm_auto_calib *a = &r->cal;
    const lm_auto_test_row *b = &t->rows[t->best];
    printf("\ntest: %lld procedural scene(s) of %dx%d not calibrated on, %ld windows; "
           "%d windows per 640x480 frame; %d thread(s)\n", o->test_synth, o->sh,
           o->sw, t->windows, t->wpf, omp_get_max_threads());
    printf("%-16s %8s %7s %8s %10s %10s %8s %8s  %s\n", "row", "PSNR dB", "vs best", "calib dB",
           "est s/fr", "meas s/fr", "speedup", "wall s", "windows per model");
    for (int k = 0; k < t->nrows; k++) {
        const lm_auto_test_row *w = &t->rows[k];
        char name[64];
        row_name(r, w, name, sizeof name);
        long n = lm_auto_test_row_windows(w, a->nmodels);
        printf("%-16s %8.3f %7.3f %8.3f %10.4f %10.4f %7.2fx %8.2f ", name, w->psnr,
               w->psnr - b->psnr, lm_auto_expected_psnr(a, w->choice, 0), lm_auto_test_row_est(r, w),
               n ? w->wall * t->wpf / n : 0.0, lm_auto_test_row_est(r, b) / lm_auto_test_row_est(r, w), w->wall);
        for (int m = 0; m < a->nmodels; m++) /* the models that ran */
            if (w->win[m]) printf(" %s %.1f%%", a->models[m].label, 100.0 * w->win[m] / n);
        if (w->same >= 0) printf("  (same choice as tol %g: reused)", t->rows[w->same].tol);
        printf("\n");
    }
    printf("vs best / speedup: against always %s (the best fixed model on these scenes; speedup "
           "from the estimated seconds). est: calibrated network seconds per window x windows; "
           "meas: wall time of the test reconstructions (difficulty, fold and all) per 640x480 "
           "frame\n", a->models[t->best].label);
}

static void log_line(void *user, const char *line)
{
    (void)user;
    fprintf(stderr, "%s\n", line);
}

static int fail(const lm_cli *c, const lm_err *e)
{
    lm_cli_error(c, "%s", e->msg);
    return lm_cli_exit_status(e->status);
}

/* Calibrate, print the table, test, save, print the test. Returns the exit status. */
static int run(const lm_cli *c, const cal_opts *o, lm_auto_fit_run *r)
{
    lm_err e;
    lm_err_clear(&e);
    if (lm_auto_fit_open(r, &o->run, &e) || lm_auto_fit_calibrate(r, &e)) return fail(c, &e);
    print_table(r);
    fflush(stdout);
    if (lm_auto_fit_test(r, &e)) return fail(c, &e);
    if (lm_auto_fit_save(r, o->output, &e))
        return lm_cli_error(c, "%s", e.msg), LM_EXIT_FAILED;
    if (r->test) print_test(r, r->test);
    return 0;
}

int lm_cmd_fit_auto(int argc, char **argv)
{
    lm_cli c;
    cal_opts o;
    lm_cli_init(&c, "lumosaic fit-auto", argc, argv);
    int rc = parse(&c, &o);
    if (rc == 1) {
        lm_cli_common_apply(&o.com);
        o.run.data = o.data;
        o.run.seed = o.com.seed, o.run.nthreads = (int)o.com.threads;
        o.run.log = log_line;
        lm_auto_fit_run r;
        rc = run(&c, &o, &r);
        lm_auto_fit_free(&r);
    }
    free(o.data);
    return rc;
}

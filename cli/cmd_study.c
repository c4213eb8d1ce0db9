/* cmd_study.c — `lumosaic study`: the speed-against-accuracy study (study/study.h): train every
 * preset of a study config with the same budget, evaluate, time, count, and write
 * results.{json,csv,md} plus gnuplot charts (study/charts.h) into the output folder. Re-running
 * resumes: presets whose runs/<preset>/result.json exists are not run again.
 * What it is not: the study itself (study/), or `lumosaic eval` on one model. */
#include <jansson.h>
#include <malloc.h>
#include <omp.h>
#include <stdio.h>
#include <string.h>
#include <sys/stat.h>
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "study/charts.h"
#include "study/study.h"
#include "train/dist.h"

static void help(void)
{
    printf("usage: lumosaic study --config STUDY.json [--output DIR] [--threads T] [--jobs J]\n"
           "                      [--no-charts] [--dry-run] [--quiet]\n\n"
           "Speed against accuracy: every preset of the config is trained with the same budget\n"
           "into DIR/runs/<preset>/, scored on the held-out scenes (the data's test split, or\n"
           "procedural scenes when it is empty) at each noise level, run through the rainbow\n"
           "test, timed on a 640 x 480 frame (fastest of a few runs) and counted (parameters,\n"
           "multiply-adds per frame). With \"conditions\" in the config each model is also\n"
           "scored under adverse captures (photon budget, saturation, LED gain error, dead\n"
           "pixels, motion) and the level where it loses 3 dB is reported; with\n"
           "\"narrowband_sweep\" one preset is trained at several synthetic shares and run\n"
           "through the rainbow test. Writes DIR/results.json, results.csv, results.md and\n"
           "DIR/charts/ (data, gnuplot scripts, PNG and SVG). Running again resumes: presets\n"
           "with a DIR/runs/<preset>/result.json are skipped, interrupted training continues.\n\n"
           "  --config FILE  study config (see study/ci.json, study/full.json)\n"
           "  --output DIR   output folder (default: the config's \"output\")\n"
           "  --threads T    compute threads (1..1024; default: all cores; with --jobs, each\n"
           "                 training's threads, default cores / J)\n"
           "  --jobs J       train J presets side by side (1..64; default 1), each in a worker\n"
           "                 process; evaluation and timing stay serial, after the training.\n"
           "                 Use it with \"clock\": \"cpu\" in the config's training fields, so\n"
           "                 that runs sharing the machine get the same budget of CPU time\n"
           "  --worker NAME  (used by --jobs) train the one preset NAME and exit\n"
           "  --stop-seconds S  (with --worker) stop at S seconds of training time\n"
           "  --no-charts    do not draw charts (gnuplot not needed)\n"
           "  --dry-run      check the config and print the plan; nothing is run or written\n"
           "  --quiet        no training progress\n"
           "  --help         this text\n\n"
           "SIGINT/SIGTERM: the training in progress (every worker's, with --jobs: each gets the\n"
           "signal) finishes its iteration and checkpoints, the study waits for the workers and\n"
           "exits 130/143; running it again continues (a second signal stops at once).\n"
           "Exit status: 0 done, 1 a run or the charts failed (e.g. gnuplot missing), 2 bad\n"
           "options, config or data.\n");
}

typedef struct study_args {
    const char *config, *output, *worker;
    long long jobs;
    lm_cli_common com; /* --threads, --quiet */
    double stop;                /* --stop-seconds (-1: not given) */
    int no_charts, dry_run;
} study_args;

static int parse(lm_cli *c, study_args *a)
{
    while (!lm_cli_done(c)) {
        int r;
        if (lm_cli_is_help(c)) {
            help();
            return 0;
        }
        if ((r = lm_cli_value(c, "--config", &a->config)) ||
            (r = lm_cli_value(c, "--output", &a->output)) ||
            (r = lm_cli_common_opt(c, LM_CLI_THREADS | LM_CLI_QUIET, 0, &a->com)) ||
            (r = lm_cli_int(c, "--jobs", 1, 64, &a->jobs)) ||
            (r = lm_cli_value(c, "--worker", &a->worker)) ||
            (r = lm_cli_real(c, "--stop-seconds", 0, 1e9, &a->stop)) ||
            (r = lm_cli_flag(c, "--no-charts", &a->no_charts)) ||
            (r = lm_cli_flag(c, "--dry-run", &a->dry_run))) {
            if (r < 0) return 2;
            continue;
        }
        return lm_cli_unknown(c);
    }
    if (!a->config) return lm_cli_error(c, "--config is required (see 'lumosaic study --help')");
    if (a->stop >= 0 && !a->worker) return lm_cli_error(c, "--stop-seconds needs --worker");
    return 1;
}

/* Bad config or data (including missing scene files): 2; a failed run (memory, NaN loss, an
 * output that cannot be written): 1. */
static int status_code(lm_status st)
{
    return st == LM_ERR_NUMERIC ? LM_EXIT_FAILED : lm_cli_exit_status(st);
}

static void print_summary(const lm_study *s, const char *dir)
{
    printf("%-14s %12s %10s %10s\n", "model", "params", "s/frame", "PSNR dB");
    for (size_t i = 0; i < json_array_size(s->runs); i++) {
        json_t *r = json_array_get(s->runs, i);
        json_t *l0 = json_array_get(json_object_get(json_object_get(r, "eval"), "levels"), 0);
        printf("%-14s %12lld %10.3f %10.3f\n", json_string_value(json_object_get(r, "preset")),
               (long long)json_integer_value(json_object_get(r, "params")),
               json_number_value(json_object_get(r, "seconds_per_frame")),
               json_number_value(json_object_get(l0, "psnr")));
    }
    printf("results: %s/results.md\n", dir);
}

static int print_plan(const lm_study_cfg *cfg, const char *dir)
{
    const lm_train_cfg *t = &cfg->train;
    printf("study %s -> %s\npresets:", cfg->path, dir);
    for (int i = 0; i < cfg->npresets; i++) printf(" %s", cfg->presets[i]);
    printf("\ntraining: %ld iterations, patch %dx%d, batch %d x %d, lr %g, narrowband synthetic "
           "share %g, procedural share %g, seed %llu\ndata:", t->iterations, t->patch_h,
           t->patch_w, t->batch, t->accum_steps, (double)t->lr, (double)t->synth_fraction,
           (double)lm_train_procedural_share(t), (unsigned long long)t->seed);
    for (int i = 0; i < t->ndata; i++) printf(" %s", t->data[i]);
    printf("\nnoise %%:");
    for (int k = 0; k < cfg->nnoise; k++) printf(" %g", 100.0 * cfg->noise[k]);
    printf("\nheld-out fallback: %d procedural scenes %dx%d; rainbow %d; timed frame %dx%d, %d "
           "runs\n", cfg->eval_scenes, cfg->eval_h, cfg->eval_w, cfg->rainbow, cfg->frame_h,
           cfg->frame_w, cfg->timing_repeats);
    for (int i = 0; i < cfg->ncond; i++) {
        printf("condition %s:", lm_cond_name(cfg->cond[i].family));
        for (int k = 0; k < cfg->cond[i].nlevels; k++) printf(" %g", cfg->cond[i].levels[k]);
        printf(" (%s)\n", lm_cond_unit(cfg->cond[i].family));
    }
    if (cfg->ncond && cfg->cond_scenes)
        printf("conditions on the first %d held-out scene(s)\n", cfg->cond_scenes);
    else if (cfg->ncond)
        printf("conditions on every held-out scene\n");
    if (cfg->nnb) {
        printf("narrowband sweep: %s at synthetic shares", cfg->nb_preset);
        for (int i = 0; i < cfg->nnb; i++) printf(" %g", (double)cfg->nb_fraction[i]);
        printf("\n");
    }
    return 0;
}

static int run(lm_cli *c, const study_args *a, const lm_study_cfg *cfg, const char *dir)
{
    lm_err e = {0};
    lm_study s;
    lm_study_opts o = {.threads = (int)a->com.threads, .progress = !a->com.quiet, .log = stderr,
                       .jobs = a->jobs > 1 ? (int)a->jobs : 1, .interrupt = lm_cli_signal_flag(),
                       .hold = lm_cli_signals_hold, .track = lm_cli_signals_track};
    lm_status st = lm_study_run(cfg, dir, &o, &s, &e);
    if (st) {
        int sig = atomic_load(lm_cli_signal_flag());
        if (sig) { /* whatever the status: the run stopped on the signal */
            lm_cli_error(c, "interrupted (%s): %s (run the study again to continue)",
                         lm_cli_signal_name(sig), st == LM_ERR_INTERRUPTED ? e.msg
                         : "stopped; the finished runs and checkpoints are kept");
            return 128 + sig;
        }
        lm_cli_error(c, "%s", e.msg);
        return status_code(st);
    }
    if (lm_dist_rank() > 0) { /* under mpirun: rank 0 scores and writes */
        lm_study_free(&s);
        return 0;
    }
    int charts = !a->no_charts, rc = 0;
    if (charts && (lm_charts_write(cfg, &s, dir, &e) || lm_charts_render(dir, &e))) {
        lm_cli_error(c, "%s", e.msg);
        charts = 0, rc = 1;
    }
    if (lm_study_write(cfg, &s, dir, charts, &e)) {
        lm_cli_error(c, "%s", e.msg);
        rc = 1;
    }
    if (!rc) print_summary(&s, dir);
    lm_study_free(&s);
    return rc;
}

/* The study's folder, for the line a second signal prints. */
static char study_dir[LM_TRAIN_PATH_LEN];

static void stop_note(char *buf, size_t n)
{
    snprintf(buf, n, "the runs' last checkpoints in %s/runs are kept", study_dir);
}

/* --worker NAME: one preset's training for a study run with --jobs. */
static int worker(lm_cli *c, const study_args *a, const lm_study_cfg *cfg, const char *dir)
{
    double stop = a->stop > 0 ? a->stop : 0.0;
    lm_cli_common_apply(&a->com);
    mallopt(M_MMAP_THRESHOLD, 128 * 1024);
    lm_study_opts o = {.threads = (int)a->com.threads, .progress = !a->com.quiet, .log = stderr,
                       .jobs = 1, .interrupt = lm_cli_signal_flag(), .hold = lm_cli_signals_hold};
    lm_err e = {0};
    lm_status st = lm_study_train_one(cfg, dir, a->worker, stop, &o, &e);
    int sig = atomic_load(lm_cli_signal_flag());
    if (st == LM_ERR_INTERRUPTED && sig) {
        lm_cli_error(c, "interrupted (%s): %s", lm_cli_signal_name(sig), e.msg);
        return 128 + sig;
    }
    if (st) lm_cli_error(c, "%s", e.msg);
    return st ? status_code(st) : sig ? 128 + sig : 0;
}

int lm_cmd_study(int argc, char **argv)
{
    lm_cli c;
    study_args a = {.stop = -1};
    lm_cli_init(&c, "lumosaic study", argc, argv);
    int r = parse(&c, &a);
    if (r != 1) return r;
    static lm_study_cfg cfg; /* large (training paths): not on the stack */
    lm_err e = {0};
    if (lm_study_cfg_load(&cfg, a.config, &e)) return lm_cli_error(&c, "%s", e.msg);
    const char *dir = a.output ? a.output : cfg.output[0] ? cfg.output : NULL;
    if (!dir)
        return lm_cli_error(&c, "no output folder: pass --output DIR or set \"output\" in %s",
                            a.config);
    if (a.dry_run) { /* the plan's paths are checked as a run would find them */
        struct stat sb;
        for (int i = 0; i < cfg.train.ndata; i++)
            if (stat(cfg.train.data[i], &sb) != 0)
                return lm_cli_error(&c, "data %s: no such file or folder", cfg.train.data[i]);
        if (cfg.train.system[0] && stat(cfg.train.system, &sb) != 0)
            return lm_cli_error(&c, "system %s: no such file", cfg.train.system);
        if (stat(dir, &sb) == 0 && !S_ISDIR(sb.st_mode))
            return lm_cli_error(&c, "output %s: exists and is not a folder", dir);
        return print_plan(&cfg, dir);
    }
    /* SIGINT / SIGTERM: training checkpoints and the study stops (workers get the signal and
     * are waited for); a second signal stops at once, after any checkpoint being written */
    if (lm_cli_signals_init(&c, 1)) return lm_cli_error(&c, "cannot install signal handlers"), 1;
    snprintf(study_dir, sizeof study_dir, "%s", dir);
    lm_cli_signals_note(stop_note);
    if (a.worker) return worker(&c, &a, &cfg, dir);
    lm_dist_init(NULL, NULL); /* under mpirun: presets trained by the ranks in turn */
    if (!a.no_charts && !lm_charts_gnuplot_available()) {
        fprintf(stderr, "lumosaic study: gnuplot not found on PATH (install gnuplot, or pass "
                        "--no-charts)\n");
        return 1;
    }
    lm_cli_common_apply(&a.com);
    /* As in `lumosaic train`: a fixed mmap threshold keeps big per-step buffers off the heap. */
    mallopt(M_MMAP_THRESHOLD, 128 * 1024);
    int rc = run(&c, &a, &cfg, dir);
    lm_study_cfg_free(&cfg);
    return rc;
}

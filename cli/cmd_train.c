/* cmd_train.c — `lumosaic train`: train a reconstruction network from a JSON run config and/or
 * flags (every config field is also a flag), with checkpoints, validation, a CSV log and
 * `--resume DIR` to continue a run exactly. What it is not: the loop (train/train.c). */
#include <dirent.h>
#include <errno.h>
#include <limits.h>
#include <malloc.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "train/dist.h"
#include "train/train.h"

static void help(void)
{
    printf("usage: lumosaic train [--config RUN.json] [--resume DIR] [--fork DIR --output NEW]\n"
           "                      [options]\n\n"
           "Train a network (Adam, L1 on the 33-channel target, gradient accumulation) on scenes\n"
           "simulated through the system description, mixed with synthetic spectra. Values come\n"
           "from the defaults (the paper's), then --config, then the flags below. The run folder\n"
           "(--output) receives config.json, model.safetensors, optimizer.safetensors and log.csv.\n\n"
           "  --config FILE                  JSON run config (\"version\": 1 and any fields below,\n"
           "                                 with '_' for '-'; data/system paths are relative to it)\n"
           "  --resume DIR                   continue the run in DIR from its last checkpoint (its\n"
           "                                 config.json; flags override, e.g. --iterations); a\n"
           "                                 folder without one starts again from its config; the\n"
           "                                 flags given are written to its config.json\n"
           "  --fork DIR                     continue the run in DIR in a new run folder (--output):\n"
           "                                 its checkpoint, optimizer state and log copied, its\n"
           "                                 config with the flags given (e.g. another augmentation\n"
           "                                 or --iterations for a shorter schedule); DIR is left as\n"
           "                                 it is, so both can go on and be compared\n"
           "  --stop-after N                 stop after N iterations of this invocation\n"
           "  --quiet                        no progress output\n");
    lm_train_cfg_print_help(stdout);
    printf("  --help                         this text\n\n"
           "SIGINT/SIGTERM: the current iteration finishes, a checkpoint is written, exit 130/143\n"
           "(a second signal stops at once, after any checkpoint being written; the run folder\n"
           "always resumes: a checkpoint of iteration 0 is written before training starts).\n"
           "Exit status: 0 done, 1 training failed (e.g. NaN loss: the last good checkpoint is\n"
           "kept; an output that cannot be written), 2 bad options, config or data.\n");
}

typedef struct train_args {
    const char *config, *resume, *fork;
    long long stop_after;
    lm_cli_common com; /* --quiet (threads, device and seed are run-config fields) */
} train_args;

/* First pass: --config / --resume / --help (they decide where the values start from). */
static int first_pass(lm_cli *c, train_args *a)
{
    while (!lm_cli_done(c)) {
        int r;
        if (lm_cli_is_help(c)) {
            help();
            return 0;
        }
        if ((r = lm_cli_value(c, "--config", &a->config)) ||
            (r = lm_cli_value(c, "--resume", &a->resume)) ||
            (r = lm_cli_value(c, "--fork", &a->fork))) {
            if (r < 0) return 2;
            continue;
        }
        c->i++;
    }
    return 1;
}

/* Second pass: every other option, applied over the loaded config. */
static int second_pass(lm_cli *c, train_args *a, lm_train_cfg *cfg)
{
    while (!lm_cli_done(c)) {
        int r;
        const char *v;
        if ((r = lm_cli_value(c, "--config", &v)) || (r = lm_cli_value(c, "--resume", &v)) ||
            (r = lm_cli_value(c, "--fork", &v)) || (r = lm_cli_int(c, "--stop-after", 1, 1000000000000LL, &a->stop_after)) ||
            (r = lm_cli_common_opt(c, LM_CLI_QUIET, 0, &a->com))) {
            if (r < 0) return 2;
            continue;
        }
        const char *arg = c->argv[c->i];
        if (!strcmp(arg, "--optimise-doe")) { /* = --doe-optimise 1 */
            cfg->doe_optimise = 1;
            c->i++;
            continue;
        }
        char key[64];
        size_t kl = strcspn(arg + 2, "=");
        if (strncmp(arg, "--", 2) || kl >= sizeof key) return lm_cli_unknown(c);
        memcpy(key, arg + 2, kl);
        key[kl] = 0;
        if (!lm_train_cfg_has(key)) return lm_cli_unknown(c);
        char flag[72];
        snprintf(flag, sizeof flag, "--%s", key);
        if ((r = lm_cli_value(c, flag, &v)) < 0) return 2;
        lm_err e = {0};
        if (lm_train_cfg_set(cfg, key, v, &e)) return lm_cli_error(c, "%s", e.msg);
    }
    return 1;
}

/* The run folder, for the line a second signal prints. */
static char run_dir[LM_TRAIN_PATH_LEN];

static void stop_note(char *buf, size_t n)
{
    char p[LM_TRAIN_PATH_LEN + 32];
    snprintf(p, sizeof p, "%s/model.safetensors", run_dir);
    if (access(p, F_OK) == 0) {
        snprintf(buf, n, "the last checkpoint in %s is kept (continue with --resume %s)", run_dir,
                 run_dir);
        return;
    }
    snprintf(p, sizeof p, "%s/config.json", run_dir);
    if (access(p, F_OK) == 0)
        snprintf(buf, n, "%s has no checkpoint yet (--resume %s starts the run again)", run_dir,
                 run_dir);
    else
        snprintf(buf, n, "no run folder was written");
}

static int load_base(lm_cli *c, const train_args *a, lm_train_cfg *cfg)
{
    lm_err e = {0};
    lm_train_cfg_default(cfg);
    if (a->resume && a->fork)
        return lm_cli_error(c, "--resume and --fork: give one (--fork DIR --output NEW continues "
                            "DIR in NEW)");
    if (a->fork && a->config)
        return lm_cli_error(c, "--fork and --config: the fork starts from DIR's config; give "
                            "the fields to change as flags");
    const char *from = a->resume ? a->resume : a->fork;
    if (from) {
        char path[LM_TRAIN_PATH_LEN + 16];
        snprintf(path, sizeof path, "%s/config.json", from);
        if (lm_train_cfg_load(cfg, path, &e)) return lm_cli_error(c, "%s", e.msg);
        snprintf(cfg->output, sizeof cfg->output, "%s", from);
    }
    if (a->config && lm_train_cfg_load(cfg, a->config, &e)) return lm_cli_error(c, "%s", e.msg);
    return 1;
}

/* Copy the file src to dst (n: what to call it in an error). 0, or 1 with the error printed. */
static int copy_file(lm_cli *c, const char *src, const char *dst)
{
    FILE *in = fopen(src, "rb"), *out = in ? fopen(dst, "wb") : NULL;
    int ok = in && out;
    char buf[1 << 16];
    size_t n;
    while (ok && (n = fread(buf, 1, sizeof buf, in)) > 0) ok = fwrite(buf, 1, n, out) == n;
    ok = ok && !ferror(in);
    if (in) fclose(in);
    if (out && fclose(out) != 0) ok = 0;
    if (!ok) lm_cli_error(c, "--fork: cannot copy %s to %s: %s", src, dst, strerror(errno));
    return !ok;
}

/* --fork SRC: the new run folder cfg->output (which must not hold a run) with SRC's checkpoint,
 * optimizer state, log and any other top-level file (a QDO run's DOE state) copied, and cfg
 * (SRC's config with the flags) as its config.json; staged, so nothing half-made is left.
 * Returns 1 to go on and resume it, else the exit status (error printed). */
static int make_fork(lm_cli *c, const char *src, const char *src_out, lm_train_cfg *cfg)
{
    char a[PATH_MAX], b[PATH_MAX], p[LM_TRAIN_PATH_LEN + 600], q[LM_TRAIN_PATH_LEN + 600];
    if (!strcmp(cfg->output, src_out))
        return lm_cli_error(c, "--fork %s: give the new run folder with --output", src);
    if (realpath(src, a) && realpath(cfg->output, b) && !strcmp(a, b))
        return lm_cli_error(c, "--fork %s: --output is the same folder", src);
    snprintf(p, sizeof p, "%s/model.safetensors", src);
    snprintf(q, sizeof q, "%s/optimizer.safetensors", src);
    if (access(p, F_OK) != 0 || access(q, F_OK) != 0)
        return lm_cli_error(c, "--fork %s: no checkpoint there (model.safetensors and "
                            "optimizer.safetensors) to continue from", src);
    char tmp[LM_TRAIN_PATH_LEN + 64];
    int r = lm_cli_stage_dir(c, cfg->output, tmp, sizeof tmp);
    if (r) return r;
    DIR *dir = opendir(src);
    int bad = !dir;
    if (bad) lm_cli_error(c, "--fork %s: cannot read the folder: %s", src, strerror(errno));
    for (struct dirent *e; !bad && (e = readdir(dir));) {
        struct stat st;
        snprintf(p, sizeof p, "%s/%s", src, e->d_name);
        if (e->d_name[0] == '.' || !strcmp(e->d_name, "config.json") || stat(p, &st) != 0 ||
            !S_ISREG(st.st_mode))
            continue; /* folders (snapshots/, eval outputs) stay with the original */
        snprintf(q, sizeof q, "%s/%s", tmp, e->d_name);
        bad = copy_file(c, p, q);
    }
    if (dir) closedir(dir);
    lm_err e = {0};
    snprintf(q, sizeof q, "%s/config.json", tmp);
    if (!bad && lm_train_cfg_save(cfg, q, &e)) {
        lm_cli_error(c, "%s", e.msg);
        bad = 1;
    }
    if (bad) {
        lm_cli_remove_tree(tmp);
        return LM_EXIT_FAILED;
    }
    return lm_cli_commit_dir(c, tmp, cfg->output) ? LM_EXIT_FAILED : 1;
}

int lm_cmd_train(int argc, char **argv)
{
    lm_cli c;
    train_args a = {0};
    lm_train_cfg cfg;
    lm_cli_init(&c, "lumosaic train", argc, argv);
    /* under mpirun: data-parallel ranks (train/dist.h); rank 0 writes and prints */
    int rank = lm_dist_init(NULL, NULL) > 1 ? lm_dist_rank() : 0;
    int r = first_pass(&c, &a);
    if (r == 1) r = load_base(&c, &a, &cfg);
    static char src_out[LM_TRAIN_PATH_LEN], fork_dir[LM_TRAIN_PATH_LEN];
    snprintf(src_out, sizeof src_out, "%s", cfg.output);
    if (r == 1) {
        lm_cli_init(&c, "lumosaic train", argc, argv);
        r = second_pass(&c, &a, &cfg);
    }
    if (r != 1) return r;
    if (a.fork && lm_dist_size() > 1)
        return lm_cli_error(&c, "--fork under mpirun: make the fork in one process (--fork DIR "
                            "--output NEW --stop-after 1), then --resume NEW under mpirun");
    if (a.fork) {
        lm_err e0 = {0};
        if (lm_train_cfg_validate(&cfg, &e0)) return lm_cli_error(&c, "%s", e0.msg);
        if (rank == 0 && (r = make_fork(&c, a.fork, src_out, &cfg)) != 1) return r;
        snprintf(fork_dir, sizeof fork_dir, "%s", cfg.output);
        a.resume = fork_dir; /* the fork is resumed like any run folder */
        if (!a.com.quiet && rank == 0)
            printf("train: %s continues %s (its checkpoint, optimizer state and log)\n",
                   fork_dir, a.fork);
    }
    if (a.resume) snprintf(cfg.output, sizeof cfg.output, "%s", a.resume);
    const lm_train_recipe *rec = lm_train_cfg_apply_recipe(&cfg);
    lm_err e = {0};
    if (lm_train_cfg_validate(&cfg, &e)) return lm_cli_error(&c, "%s", e.msg);
    if (rec && !a.resume && !a.com.quiet && rank == 0) /* stdout: errors stay one line */
        fprintf(stdout, "train: %s%s: the preset's recipe where not given: lr %g, batch %d x %d, "
                "%s schedule to %g after %ld warm-up updates (--recipe paper: the paper's)\n",
                cfg.model, cfg.base[0] ? " on a base" : "", (double)cfg.lr, cfg.batch,
                cfg.accum_steps, cfg.schedule, (double)cfg.lr_min, cfg.warmup);
    char ck[LM_TRAIN_PATH_LEN + 32];
    snprintf(ck, sizeof ck, "%s/model.safetensors", cfg.output);
    if (!a.resume && access(ck, F_OK) == 0)
        return lm_cli_error(&c, "%s already holds a checkpoint (continue it with --resume %s, "
                            "or choose another --output)", cfg.output, cfg.output);
    /* a run stopped before its first checkpoint: it starts again from its config */
    int restart = a.resume && access(ck, F_OK) != 0;
    if (restart && !a.com.quiet && rank == 0)
        printf("train: %s has no checkpoint yet: the run starts from its beginning\n",
               cfg.output);
    snprintf(run_dir, sizeof run_dir, "%s", cfg.output);
    /* A fixed mmap threshold: glibc's dynamic one moves big per-step buffers onto the heap,
     * where trimming and regrowing them made steps 2-30x slower here (bench_train). */
    mallopt(M_MMAP_THRESHOLD, 128 * 1024);
    if (lm_cli_signals_init(&c, 1)) return lm_cli_error(&c, "cannot install signal handlers"), 1;
    lm_cli_signals_note(stop_note);
    lm_train_opts o = {.resume = restart ? NULL : a.resume, .stop_after = (long)a.stop_after,
                       .progress = !a.com.quiet && rank == 0, .interrupt = lm_cli_signal_flag(),
                       .hold = lm_cli_signals_hold, .restart = restart, .data_parallel = 1};
    lm_train_result res;
    /* a fork that fails before its first update (its checkpoint still the parent's) is removed:
     * nothing half-made is left (an interrupted one stays, to resume) */
    char *fork_it = NULL;
    if (a.fork && rank == 0) fork_it = lm_safetensors_meta(ck, "iteration", &(lm_err){0});
    lm_status st = lm_train_session(&cfg, &o, &res, &e);
    int sig = atomic_load(lm_cli_signal_flag());
    if (st && fork_it && !(st == LM_ERR_INTERRUPTED && sig)) {
        char *now = lm_safetensors_meta(ck, "iteration", &(lm_err){0});
        if (now && !strcmp(now, fork_it)) lm_cli_remove_tree(fork_dir);
        free(now);
    }
    free(fork_it);
    if (st == LM_ERR_INTERRUPTED && sig) {
        lm_cli_error(&c, "interrupted (%s): %s", lm_cli_signal_name(sig), e.msg);
        return 128 + sig;
    }
    if (st) { /* a NaN loss is the run failing (1), not bad input */
        if (rank) lm_cli_error(&c, "rank %d: %s", rank, e.msg);
        else lm_cli_error(&c, "%s", e.msg);
        return st == LM_ERR_NUMERIC ? LM_EXIT_FAILED : lm_cli_exit_status(st);
    }
    if (rank) return sig ? 128 + sig : 0; /* rank 0 reports */
    if (sig) { /* SIGINT / SIGTERM: the step finished and the checkpoint is on disk */
        if (res.closed_form && res.interrupted)
            lm_cli_error(&c, "interrupted (%s): the closed-form fit stopped reading after %ld of "
                         "%ld training patches and was solved from them; the model is written "
                         "to %s", lm_cli_signal_name(sig), res.fit_patches,
                         res.fit_patches_asked, cfg.output);
        else if (res.closed_form)
            lm_cli_error(&c, "interrupted (%s) as the fit ended: the model is written to %s",
                         lm_cli_signal_name(sig), cfg.output);
        else if (res.interrupted)
            lm_cli_error(&c, "interrupted (%s) at iteration %ld: checkpoint written to %s "
                         "(continue with --resume %s)", lm_cli_signal_name(sig),
                         res.iterations_done, cfg.output, cfg.output);
        else
            lm_cli_error(&c, "interrupted (%s) as the run ended: checkpoint written to %s",
                         lm_cli_signal_name(sig), cfg.output);
        return 128 + sig;
    }
    if (res.closed_form) {
        printf("fitted %s in closed form (%.1f s); fit.json has every noise level\n", cfg.model,
               res.seconds);
        if (res.budget_spent)
            printf("the time budget (--minutes %g) ended the reading after %ld of %ld training "
                   "patches\n", (double)cfg.minutes, res.fit_patches, res.fit_patches_asked);
        if (res.validated)
            printf("validation (clean, interior pixels): PSNR %.3f dB\n", res.val.psnr);
        printf("checkpoint: %s\n", ck);
        return 0;
    }
    printf("trained %s for %ld iterations (%.1f s this run), final loss %.6f\n", cfg.model,
           res.iterations_done, res.seconds, res.last_loss);
    if (lm_dist_size() > 1)
        printf("data-parallel: %d processes x batch %d (global batch %d); gradient sums took "
               "%.2f s on rank 0\n", lm_dist_size(), cfg.batch, lm_dist_size() * cfg.batch,
               lm_dist_comm_seconds());
    if (res.validated)
        printf("validation: PSNR %.3f dB  SSIM %.4f  MAE %.5f  SAM %.3f deg\n", res.val.psnr,
               res.val.ssim, res.val.mae, res.val.sam);
    printf("checkpoint: %s\n", ck);
    return 0;
}

/* test_train_reliability.c — the training loop under failures: a log.csv that cannot
 * be written (the file-size limit reached, as on a full disk) stops the run with the message; a
 * fresh run that fails before its first iteration (a batch that cannot be read, a NaN at once)
 * leaves no run folder; an interrupt flag (what `lumosaic train` sets on SIGINT/SIGTERM) ends
 * the run after the current iteration with a checkpoint that resumes. */
#define _GNU_SOURCE
#include "tests/check.h"
#include "tests/fixture.h"
#include "data/mosaic.h"
#include "train/train.h"
#include <signal.h>
#include <stdlib.h>
#include <sys/resource.h>
#include <unistd.h>

/* A deterministic in-memory source: batch `fail_at` returns an error (-1: never), batches from
 * `nan_from` hold a NaN (-1: never); batch `limit_at` lowers the file-size limit to log.csv's
 * size (-1: never); batch `flag_at` sets *flag (-1: never). */
typedef struct src {
    int H, W;
    long fail_at, nan_from, limit_at, flag_at;
    const char *log_path;
    atomic_int *flag;
} src;

static lm_status batch(void *u, long index, int B, float *raw, float *tgt, lm_err *e)
{
    src *s = u;
    size_t n = (size_t)s->H * s->W;
    if (index == s->fail_at) return lm_err_set(e, LM_ERR_FORMAT, "scene.png: corrupt");
    for (int b = 0; b < B; b++) {
        for (size_t i = 0; i < n; i++) raw[b * n + i] = 0.2f + 0.1f * (float)((i + b) % 7);
        for (size_t i = 0; i < 33 * n; i++) tgt[b * 33 * n + i] = 0.3f + 0.01f * (float)(i % 5);
        if (s->nan_from >= 0 && index >= s->nan_from) raw[b * n] = NAN;
    }
    if (index == s->limit_at) {
        struct rlimit rl;
        getrlimit(RLIMIT_FSIZE, &rl);
        rl.rlim_cur = (rlim_t)file_size(s->log_path);
        setrlimit(RLIMIT_FSIZE, &rl);
    }
    if (index == s->flag_at) atomic_store(s->flag, SIGINT);
    return LM_OK;
}

static lm_mosaic g_mosaic;

static lm_train_cfg small_cfg(const char *out)
{
    lm_train_cfg c;
    lm_train_cfg_default(&c);
    snprintf(c.model, sizeof c.model, "linear");
    snprintf(c.output, sizeof c.output, "%s", out);
    c.synth_fraction = 1;
    c.patch_h = 12, c.patch_w = 12;
    c.batch = 2, c.accum_steps = 1, c.iterations = 20;
    c.threads = 1, c.val_interval = 0, c.checkpoint_interval = 0;
    return c;
}

static lm_status run(const lm_train_cfg *c, src *s, const lm_train_opts *o, lm_train_result *r,
                     lm_err *e)
{
    lm_model *m = lm_model_create("linear", &g_mosaic, 1, e);
    if (!m) return e->status;
    lm_train_source so = {s, batch, NULL, NULL, NULL};
    lm_status st = lm_train_run(c, m, &so, o, r, e);
    lm_model_free(m);
    return st;
}

static void test_log_write_failure(void)
{
    char out[1024], log[1100];
    tpath(out, "logfail");
    snprintf(log, sizeof log, "%s/log.csv", out);
    lm_train_cfg c = small_cfg(out);
    c.checkpoint_interval = 2; /* a checkpoint exists when the log fails */
    src s = {12, 12, -1, -1, 5, -1, log, NULL};
    signal(SIGXFSZ, SIG_IGN); /* writes past the limit fail with EFBIG instead */
    lm_train_result r;
    lm_err e = {0};
    lm_status st = run(&c, &s, NULL, &r, &e);
    struct rlimit rl;
    getrlimit(RLIMIT_FSIZE, &rl);
    rl.rlim_cur = rl.rlim_max;
    setrlimit(RLIMIT_FSIZE, &rl);
    CHECK_MSG(st == LM_ERR_WRITE && strstr(e.msg, "log.csv: cannot write: File too large") &&
              strstr(e.msg, "training stopped") && strstr(e.msg, "iteration 4"),
              "status %d: %s", (int)st, e.msg);
    CHECK(r.iterations_done == 6); /* iteration 6 (batch 5) could not be logged */
}

static void test_failed_start_leaves_nothing(void)
{
    char out[1100], top[1024];
    tpath(top, "fresh");
    snprintf(out, sizeof out, "%s/sub/run", top);
    lm_train_cfg c = small_cfg(out);
    src bad = {12, 12, 0, -1, -1, -1, NULL, NULL};
    lm_train_result r;
    lm_err e = {0};
    CHECK(run(&c, &bad, NULL, &r, &e) == LM_ERR_FORMAT && strstr(e.msg, "corrupt"));
    CHECK_MSG(access(top, F_OK) != 0, "%s left behind", top);
    /* a NaN at once: the same; an existing folder is kept, its other files too */
    tpath(top, "kept");
    snprintf(out, sizeof out, "%s", top);
    mkdir(out, 0777);
    char other[1200];
    snprintf(other, sizeof other, "%s/notes.txt", out);
    FILE *f = fopen(other, "w");
    if (f) fclose(f);
    c = small_cfg(out);
    src nan = {12, 12, -1, 0, -1, -1, NULL, NULL};
    lm_err_clear(&e);
    CHECK(run(&c, &nan, NULL, &r, &e) == LM_ERR_NUMERIC);
    char cfgp[1200];
    snprintf(cfgp, sizeof cfgp, "%s/config.json", out);
    CHECK(access(out, F_OK) == 0 && access(other, F_OK) == 0 && access(cfgp, F_OK) != 0);
    /* a failure after the first iteration keeps the run (its log says what happened) */
    tpath(top, "later");
    snprintf(out, sizeof out, "%s", top);
    c = small_cfg(out);
    src late = {12, 12, 3, -1, -1, -1, NULL, NULL};
    lm_err_clear(&e);
    CHECK(run(&c, &late, NULL, &r, &e) == LM_ERR_FORMAT);
    snprintf(cfgp, sizeof cfgp, "%s/log.csv", out);
    CHECK(access(cfgp, F_OK) == 0);
}

static void test_interrupt_flag(void)
{
    char out[1024];
    tpath(out, "interrupted");
    lm_train_cfg c = small_cfg(out);
    atomic_int flag = 0;
    src s = {12, 12, -1, -1, -1, 6, NULL, &flag};
    lm_train_opts o = {0};
    o.interrupt = &flag;
    lm_train_result r;
    lm_err e = {0};
    CHECK_MSG(run(&c, &s, &o, &r, &e) == LM_OK, "%s", e.msg);
    CHECK(r.interrupted == SIGINT && r.iterations_done == 7); /* batch 6 is iteration 7 */
    lm_model *m = lm_model_create("linear", &g_mosaic, 1, &e);
    long it = 0;
    CHECK(m && lm_train_load_checkpoint(out, m, NULL, &it, NULL, NULL, &e) == LM_OK && it == 7);
    lm_model_free(m);
    /* and the run resumes from there to its end */
    src s2 = {12, 12, -1, -1, -1, -1, NULL, NULL};
    lm_train_opts o2 = {0};
    o2.resume = out;
    lm_err_clear(&e);
    CHECK_MSG(run(&c, &s2, &o2, &r, &e) == LM_OK && r.iterations_done == 20 && !r.interrupted,
              "%s", e.msg);
}

int main(void)
{
    snprintf(tmpdir, sizeof tmpdir, "/tmp/lm_train_rel_XXXXXX");
    if (!mkdtemp(tmpdir)) return 1;
    lm_system sys;
    lm_err e = {0};
    if (lm_system_default(&sys, &e) || lm_mosaic_from_system(&sys, &g_mosaic, &e)) {
        fprintf(stderr, "%s\n", e.msg);
        return 1;
    }
    lm_system_free(&sys);
    RUN(test_log_write_failure);
    RUN(test_failed_start_leaves_nothing);
    RUN(test_interrupt_flag);
    fixture_cleanup();
    return check_summary();
}

/* test_opencl_train.c — `lumosaic train --device`: the training loop on the OpenCL backend
 * against the CPU. han-tiny trains for a few iterations (2 batches accumulated per update,
 * validation twice) from the same seed and the same in-memory batches on both devices; the
 * per-iteration losses (log.csv), the validation metrics and the final weights must agree:
 *   losses: |cl - cpu| <= 1e-5 |cpu|;  validation PSNR: within 0.01 dB;
 *   weights: the weight updates (final - initial) agree in norm, |d_cl - d_cpu|_2 <= 1e-3
 *   |d_cpu|_2 — elementwise bounds are useless here because Adam moves every weight by about
 *   lr per step whatever its gradient's size, so a near-zero gradient whose sign differs
 *   between the two summation orders gives a 2 lr difference; a device step that lost or
 *   doubled the gradients gives differences of the order of |d_cpu| itself.
 * Also: the config field (default from $LM_DEVICE, validation, JSON round trip) and the CLI
 * (--device bogus and an unavailable device: one line, exit 2).
 * `test_opencl_train --time [N]` prints the time per iteration of han-tiny at batch 4 of 66x64
 * on both devices instead. Exit 77 only when no OpenCL platform exists. */
#include "tests/check.h"
#include "kernels-opencl/cl_backend.h"
#include "train/train.h"
#include <limits.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <unistd.h>

#if defined(__SANITIZE_ADDRESS__)
/* The OpenCL driver keeps JIT allocations past exit (as kernels-opencl/lsan-opencl.supp). */
const char *__lsan_default_suppressions(void);
const char *__lsan_default_suppressions(void)
{
    return "leak:libpocl.so\nleak:libLLVM\nleak:libOpenCL.so\n";
}
#endif

#define LOSS_RTOL 1e-5
#define PSNR_TOL 0.01
#define UPDATE_RTOL 1e-3

/* ---- an in-memory source: random frames and targets, a pure function of the index ------- */
typedef struct rsrc {
    int H, W, neval;
} rsrc;

static void fill(const rsrc *s, uint64_t seed, int B, float *raw, float *tgt)
{
    lm_rng r;
    lm_rng_seed(&r, seed);
    long n = (long)B * s->H * s->W;
    lm_rng_fill_uniform(&r, raw, n, 0.0f, 1.0f);
    lm_rng_fill_uniform(&r, tgt, n * 33, 0.0f, 1.0f);
}
static lm_status r_batch(void *u, long index, int B, float *raw, float *tgt, lm_err *e)
{
    (void)e;
    fill(u, 100 + (uint64_t)index, B, raw, tgt);
    return LM_OK;
}
static int r_count(void *u) { return ((rsrc *)u)->neval; }
static lm_status r_eval(void *u, int i, float *raw, float *tgt, lm_err *e)
{
    (void)e;
    fill(u, 9000 + (uint64_t)i, 1, raw, tgt);
    return LM_OK;
}

static char g_tmp[256];

static void run_cfg(lm_train_cfg *cfg, const char *device, const char *name)
{
    lm_train_cfg_default(cfg);
    snprintf(cfg->model, sizeof cfg->model, "han-tiny");
    snprintf(cfg->device, sizeof cfg->device, "%s", device);
    snprintf(cfg->output, sizeof cfg->output, "%s/%s", g_tmp, name);
    cfg->synth_fraction = 1;
    cfg->patch_h = 12, cfg->patch_w = 12;
    cfg->batch = 2, cfg->accum_steps = 2, cfg->iterations = 4;
    cfg->lr = 1e-3f;
    cfg->threads = 2;
    cfg->val_interval = 2, cfg->checkpoint_interval = 0;
}

/* Train a fresh han-tiny (seed 7) on `device`; returns the model (weights after training). */
static lm_model *train_on(const char *device, rsrc *s, lm_train_result *res, float **w0)
{
    lm_train_cfg cfg;
    run_cfg(&cfg, device, device);
    lm_mosaic mo;
    lm_mosaic_default(&mo);
    lm_err e = {0};
    lm_model *m = lm_model_create("han-tiny", &mo, 7, &e);
    CHECK_MSG(m != NULL, "%s", e.msg);
    if (!m) return NULL;
    if (w0) {
        *w0 = malloc(m->params.total * sizeof(float));
        memcpy(*w0, m->params.data, m->params.total * sizeof(float));
    }
    lm_train_source src = {s, r_batch, r_count, r_eval, NULL};
    CHECK_MSG(lm_train_run(&cfg, m, &src, NULL, res, &e) == LM_OK, "%s: %s", device, e.msg);
    return m;
}

/* Losses of log.csv (one per iteration); returns how many. */
static int read_losses(const char *device, double *loss, int max)
{
    char path[320], line[256];
    snprintf(path, sizeof path, "%s/%s/log.csv", g_tmp, device);
    FILE *f = fopen(path, "r");
    CHECK_MSG(f != NULL, "cannot open %s", path);
    int n = 0;
    while (f && fgets(line, sizeof line, f) && n < max) {
        long it;
        double l;
        if (sscanf(line, "%ld,%lf", &it, &l) == 2) loss[n++] = l;
    }
    if (f) fclose(f);
    return n;
}

static void test_devices_agree(void)
{
    rsrc s = {12, 12, 3};
    lm_train_result rc, rg;
    float *w0 = NULL;
    lm_model *mc = train_on("cpu", &s, &rc, &w0);
    lm_model *mg = train_on("opencl", &s, &rg, NULL);
    if (!mc || !mg || check_failures_) goto out;
    double lc[16], lg[16], worst = 0;
    int nc = read_losses("cpu", lc, 16), ng = read_losses("opencl", lg, 16);
    CHECK(nc == 4 && ng == 4);
    for (int i = 0; i < nc && i < ng; i++) {
        double d = fabs(lg[i] - lc[i]);
        worst = fmax(worst, d / fabs(lc[i]));
        CHECK_MSG(d <= LOSS_RTOL * fabs(lc[i]), "iteration %d: loss cpu %.8g opencl %.8g", i + 1,
                  lc[i], lg[i]);
    }
    CHECK_MSG(fabs(lc[3] - lc[0]) > 1e-2 * lc[0], "the run does not learn: %g -> %g", lc[0],
              lc[3]);
    CHECK(rc.validated && rg.validated);
    CHECK_CLOSE(rg.val.psnr, rc.val.psnr, PSNR_TOL, 0);
    double dd = 0, dn = 0, wmax = 0;
    size_t n = mc->params.total;
    for (size_t i = 0; i < n; i++) {
        double uc = (double)mc->params.data[i] - w0[i], ug = (double)mg->params.data[i] - w0[i];
        dd += (ug - uc) * (ug - uc);
        dn += uc * uc;
        wmax = fmax(wmax, fabs((double)mg->params.data[i] - mc->params.data[i]));
    }
    printf("     han-tiny, 4 iterations x 2 batches: worst loss rel diff %.2e; val PSNR cpu %.4f "
           "opencl %.4f dB; weight updates |d_cl-d_cpu|/|d_cpu| = %.2e (|d_cpu| %.3e, %zu "
           "weights); worst weight diff %.2e (lr %.0e)\n", worst, rc.val.psnr, rg.val.psnr,
           sqrt(dd / dn), sqrt(dn), n, wmax, 1e-3);
    CHECK(dn > 0);
    CHECK_MSG(dd <= UPDATE_RTOL * UPDATE_RTOL * dn, "weight updates differ: %.3e of %.3e",
              sqrt(dd), sqrt(dn));
    CHECK_MSG(wmax <= 2 * 4 * 1e-3 * 1.01, "a weight moved further than Adam can: %.3e", wmax);
out:
    free(w0);
    lm_model_free(mc);
    lm_model_free(mg);
}

/* ---- the config field ----------------------------------------------------------------- */
static void test_config_field(void)
{
    lm_train_cfg cfg;
    lm_err e = {0};
    setenv("LM_DEVICE", "opencl", 1);
    lm_train_cfg_default(&cfg);
    CHECK(!strcmp(cfg.device, "opencl"));
    unsetenv("LM_DEVICE");
    lm_train_cfg_default(&cfg);
    CHECK(!strcmp(cfg.device, "cpu"));
    cfg.synth_fraction = 1;
    CHECK(lm_train_cfg_set(&cfg, "device", "opencl", &e) == LM_OK);
    CHECK(lm_train_cfg_validate(&cfg, &e) == LM_OK);
    char path[320];
    snprintf(path, sizeof path, "%s/cfg.json", g_tmp);
    CHECK_MSG(lm_train_cfg_save(&cfg, path, &e) == LM_OK, "%s", e.msg);
    lm_train_cfg back;
    lm_train_cfg_default(&back);
    CHECK_MSG(lm_train_cfg_load(&back, path, &e) == LM_OK, "%s", e.msg);
    CHECK(!strcmp(back.device, "opencl"));
    CHECK(lm_train_cfg_set(&cfg, "device", "bogus", &e) == LM_OK);
    CHECK(lm_train_cfg_validate(&cfg, &e) == LM_ERR_ARG);
    CHECK_MSG(strstr(e.msg, "'device'") && strstr(e.msg, "bogus"), "%s", e.msg);
}

/* ---- the CLI -------------------------------------------------------------------------- */
/* Runs `env ENV lumosaic train ARGS` (stderr captured); returns the exit status. */
static int run_cli(const char *env, const char *args, char *out, size_t n)
{
    char exe[PATH_MAX], cmd[2 * PATH_MAX];
    ssize_t k = readlink("/proc/self/exe", exe, sizeof exe - 1);
    if (k <= 0) return -1;
    exe[k] = 0;
    char *slash = strrchr(exe, '/');
    if (!slash) return -1;
    *slash = 0;
    snprintf(cmd, sizeof cmd, "env ASAN_OPTIONS=detect_leaks=0 %s '%s/lumosaic' train %s "
             "--synth-fraction 1 --output '%s/cli' 2>&1", env, exe, args, g_tmp);
    FILE *p = popen(cmd, "r");
    if (!p) return -1;
    size_t got = fread(out, 1, n - 1, p);
    out[got] = 0;
    int st = pclose(p);
    return WIFEXITED(st) ? WEXITSTATUS(st) : -1;
}

static int lines(const char *s)
{
    int n = 0;
    for (; *s; s++) n += *s == '\n';
    return n;
}

static void test_cli_rejects(void)
{
    char out[4096];
    int rc = run_cli("", "--device bogus", out, sizeof out);
    CHECK_MSG(rc == 2, "--device bogus: exit %d: %s", rc, out);
    CHECK_MSG(lines(out) == 1 && strstr(out, "'device'") && strstr(out, "bogus"), "%s", out);
    rc = run_cli("LM_DEVICE=bogus", "", out, sizeof out);
    CHECK_MSG(rc == 2 && lines(out) == 1 && strstr(out, "bogus"), "LM_DEVICE=bogus: %d %s", rc,
              out);
    rc = run_cli("LM_OPENCL_DEVICE=999", "--device opencl --quiet --model han-tiny", out,
                 sizeof out);
    CHECK_MSG(rc == 2, "unavailable device: exit %d: %s", rc, out);
    CHECK_MSG(lines(out) == 1 && strstr(out, "device 'opencl' is not available"), "%s", out);
}

/* ---- time per iteration (not a test) --------------------------------------------------- */
static void time_devices(int iters)
{
    rsrc s = {66, 64, 0};
    for (int d = 0; d < 2; d++) {
        const char *dev = d ? "opencl" : "cpu";
        lm_train_cfg cfg;
        run_cfg(&cfg, dev, dev);
        cfg.patch_h = 66, cfg.patch_w = 64, cfg.batch = 4, cfg.accum_steps = 1;
        cfg.iterations = iters + 1, cfg.val_interval = 0;
        lm_mosaic mo;
        lm_mosaic_default(&mo);
        lm_err e = {0};
        lm_model *m = lm_model_create("han-tiny", &mo, 7, &e);
        lm_train_source src = {&s, r_batch, r_count, r_eval, NULL};
        lm_train_result r1, r2;
        lm_train_opts o = {.stop_after = 1};
        lm_status st = m ? lm_train_run(&cfg, m, &src, &o, &r1, &e) : e.status; /* warm-up */
        o.stop_after = 0;
        o.resume = cfg.output;
        if (!st) st = lm_train_run(&cfg, m, &src, &o, &r2, &e);
        if (st) printf("%s: %s\n", dev, e.msg);
        else printf("han-tiny B=4 66x64 on %-6s: %.1f ms per iteration (%d iterations)\n", dev,
                    1e3 * r2.seconds / iters, iters);
        lm_model_free(m);
    }
}

static void cleanup(void)
{
    char cmd[300];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", g_tmp);
    if (system(cmd) != 0) fprintf(stderr, "cannot remove %s\n", g_tmp);
}

int main(int argc, char **argv)
{
    if (lm_cl_platform_count() == 0) {
        printf("skipped: no OpenCL platform (clGetPlatformIDs found none)\n");
        return 77;
    }
    snprintf(g_tmp, sizeof g_tmp, "/tmp/lm_train_opencl_XXXXXX");
    if (!mkdtemp(g_tmp)) return 1;
    unsetenv("LM_DEVICE");
    if (argc > 1 && !strcmp(argv[1], "--time")) {
        time_devices(argc > 2 ? atoi(argv[2]) : 5);
        cleanup();
        return 0;
    }
    RUN(test_config_field);
    RUN(test_cli_rejects);
    RUN(test_devices_agree);
    cleanup();
    return check_summary();
}

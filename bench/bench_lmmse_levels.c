/* bench_lmmse_levels.c — how much the lmmse floor loses by meeting noise levels between the
 * ones it was fitted for, and by estimating the level (the target: "within 0.5 dB of a filter
 * fitted for exactly that level").
 * What it is: one data set opened as `train --model lmmse` opens it (defaults of the run config:
 * 66 x 64 patches, synthetic share 0.33, seed 1, 4096 clean patches, ridge and share chosen on the
 * validation split), the family fitted at the bundled levels (lm_lmmse_sigmas); then, for each
 * noise level k, a second model fitted the same way at levels that hold exactly the sd each test
 * scene's frame has at k (k x its clean maximum, as eval draws it). Every real test scene is
 * scored as `eval` scores it (same frames, same noise) three ways:
 *   estimated  the family, the level estimated from the frame (what `infer` and `eval` do)
 *   interp     the family, the true level given (the interpolation between fitted levels alone)
 *   exact      the filter fitted for exactly that level, the true level given
 * and the means over the test scenes are printed per k, with the gaps estimated - exact and
 * interp - exact. Fit times are printed too.
 * What it is not: a test (it takes minutes); the fitted levels of a checkpoint never change
 * (lm_lmmse_set_levels is for this measurement, and checkpoints refuse such models).
 * Usage: bench_lmmse_levels [--noise 0,1,2.5,...] [--threads N] DATA... */
#include "data/cube_io.h"
#include "data/dataset.h"
#include "data/mosaic.h"
#include "data/system.h"
#include "data/util.h"
#include "infer/eval.h"
#include "infer/model_io.h"
#include "tensor/tensor.h"
#include "train/fit_lmmse.h"
#include "train/train.h"
#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define MAX_K 16
#define MAX_SCENES 64

static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return (double)t.tv_sec + 1e-9 * (double)t.tv_nsec;
}

static int die(const lm_err *e)
{
    fprintf(stderr, "bench_lmmse_levels: %s\n", e->msg);
    return 1;
}

static lm_model *fit(const lm_system *sys, lm_dataset *d, const lm_train_cfg *cfg,
                     const float *levels, double *secs, lm_err *e)
{
    lm_mosaic mo;
    if (lm_mosaic_from_system(sys, &mo, e)) return NULL;
    lm_model *m = lm_model_create("lmmse", &mo, cfg->seed, e);
    if (!m) return NULL;
    if (levels && lm_lmmse_set_levels(m, levels, e)) return lm_model_free(m), NULL;
    lm_noise_opts sensor;
    memset(&sensor, 0, sizeof sensor);
    lm_lmmse_fit_report rep;
    double t0 = now();
    if (lm_lmmse_fit(m, d, cfg->patch_h, cfg->patch_w, cfg->fit_patches, cfg->batch,
                     cfg->fit_synth, &sensor, &rep, e))
        return lm_model_free(m), NULL;
    *secs = now() - t0;
    lm_params_set_requires_grad(&m->params, 0);
    return m;
}

/* Mean PSNR over the scenes of model m at noise k: oracle 1 = the true level given. */
static int score(lm_ctx *c, lm_infer_model *im, lm_model *m, int oracle, lm_cube *scenes,
                 const char *const *names, int ns, float k, double *psnr, lm_err *e)
{
    im->model = m;
    im->noise_oracle = oracle;
    m->noise_given = -1.0f;
    lm_tile_opts to;
    lm_tile_default_opts(&to);
    lm_rng base;
    lm_rng_seed(&base, 1); /* eval's default --seed, split per scene name as eval does */
    double sum = 0.0;
    for (int s = 0; s < ns; s++) {
        lm_rng rng = lm_rng_split(&base, lm_fnv1a_str(LM_FNV1A_BASIS_SHORT, names[s]));
        lm_metrics mt;
        if (lm_eval_scene(c, im, &scenes[s], &k, 1, &to, &rng, &mt, e)) return 1;
        psnr[s] = mt.psnr;
        sum += mt.psnr;
    }
    psnr[ns] = sum / ns;
    m->noise_given = -1.0f;
    return 0;
}

int main(int argc, char **argv)
{
    float ks[MAX_K] = {0.0f, 0.01f, 0.025f, 0.05f, 0.075f, 0.1f, 0.125f, 0.15f, 0.2f};
    int nk = 9, threads = 2, a = 1;
    for (; a < argc && argv[a][0] == '-'; a++) {
        if (!strcmp(argv[a], "--threads") && a + 1 < argc) {
            threads = atoi(argv[++a]);
        } else if (!strcmp(argv[a], "--noise") && a + 1 < argc) {
            nk = 0;
            for (char *t = strtok(argv[++a], ","); t && nk < MAX_K; t = strtok(NULL, ","))
                ks[nk++] = (float)(atof(t) / 100.0);
        } else {
            fprintf(stderr, "usage: bench_lmmse_levels [--noise 0,1,2.5,... (%%)] [--threads N] "
                    "DATA...\n");
            return 2;
        }
    }
    if (a >= argc || threads < 1 || threads > 64 || nk < 1) {
        fprintf(stderr, "usage: bench_lmmse_levels [--noise 0,1,2.5,... (%%)] [--threads N] "
                "DATA...\n");
        return 2;
    }
    omp_set_num_threads(threads);
    lm_err e = {0};
    lm_train_cfg cfg;
    lm_train_cfg_default(&cfg);
    lm_infer_model im;
    memset(&im, 0, sizeof im);
    if (lm_system_default(&im.sys, &e)) return die(&e);
    for (int i = a; i < argc; i++)
        if (lm_train_cfg_set(&cfg, "data", argv[i], &e)) return die(&e);
    lm_dataset *d = lm_train_open_data(&cfg, &im.sys, 1, &e); /* clean: the fit adds noise */
    if (!d) return die(&e);
    int ns = lm_dataset_num_scenes(d, LM_SPLIT_TEST);
    if (ns < 1 || ns > MAX_SCENES) {
        fprintf(stderr, "bench_lmmse_levels: %d test scenes (need 1..%d)\n", ns, MAX_SCENES);
        return 1;
    }
    lm_cube scenes[MAX_SCENES];
    const char *names[MAX_SCENES];
    double cmax[MAX_SCENES];
    lm_mosaic mo;
    if (lm_mosaic_from_system(&im.sys, &mo, &e)) return die(&e);
    printf("test scenes:");
    for (int s = 0; s < ns; s++) {
        if (lm_cube_read(lm_dataset_scene_path(d, LM_SPLIT_TEST, s), &scenes[s], &e) ||
            lm_eval_prepare(&scenes[s], mo.ty, mo.tx, &e))
            return die(&e);
        names[s] = lm_dataset_scene_name(d, LM_SPLIT_TEST, s);
        printf(" %s", names[s]);
    }
    printf("\n");
    double secs;
    lm_model *fam = fit(&im.sys, d, &cfg, NULL, &secs, &e);
    if (!fam) return die(&e);
    printf("family (the bundled %d levels) fitted in %.1f s\n", LM_LMMSE_LEVELS, secs);
    /* each scene's clean coded maximum: the noise sd at k is k x that */
    im.model = fam;
    for (int s = 0; s < ns; s++) {
        float *fr;
        size_t n;
        if (lm_eval_simulate(&im, &scenes[s], NULL, NULL, &fr, &n, &e)) return die(&e);
        float mx = 0.0f;
        for (size_t i = 0; i < n; i++) mx = fr[i] > mx ? fr[i] : mx;
        cmax[s] = mx;
        free(fr);
    }
    lm_ctx c;
    if (lm_ctx_init(&c, threads)) return fprintf(stderr, "bench_lmmse_levels: no context\n"), 1;
    printf("%7s %10s %10s %10s %12s %12s %8s\n", "noise %", "estimated", "interp", "exact",
           "est - exact", "int - exact", "fit s");
    double worst_e = 0.0, worst_i = 0.0;
    for (int q = 0; q < nk; q++) {
        const float k = ks[q];
        /* levels: 0, the scenes' sd at k (sorted, distinct), then the bundled levels above */
        float lv[LM_LMMSE_LEVELS], sd[MAX_SCENES];
        int nl = 1;
        lv[0] = 0.0f;
        for (int s = 0; s < ns; s++) sd[s] = (float)(k * cmax[s]);
        for (int s = 0; s < ns; s++)
            for (int t = s + 1; t < ns; t++)
                if (sd[t] < sd[s]) { float x = sd[s]; sd[s] = sd[t]; sd[t] = x; }
        for (int s = 0; s < ns && k > 0.0f; s++)
            if (sd[s] > lv[nl - 1] && nl < LM_LMMSE_LEVELS) lv[nl++] = sd[s];
        for (int l = 0; l < LM_LMMSE_LEVELS && nl < LM_LMMSE_LEVELS; l++)
            if (lm_lmmse_sigmas[l] > lv[nl - 1]) lv[nl++] = lm_lmmse_sigmas[l];
        while (nl < LM_LMMSE_LEVELS) { lv[nl] = lv[nl - 1] * 1.5f + 0.01f; nl++; }
        double pe[MAX_SCENES + 1], pi[MAX_SCENES + 1], px[MAX_SCENES + 1];
        lm_model *ex = fit(&im.sys, d, &cfg, lv, &secs, &e);
        if (!ex) return die(&e);
        if (score(&c, &im, fam, 0, scenes, names, ns, k, pe, &e) ||
            score(&c, &im, fam, 1, scenes, names, ns, k, pi, &e) ||
            score(&c, &im, ex, 1, scenes, names, ns, k, px, &e))
            return die(&e);
        lm_model_free(ex);
        printf("%7.2f %10.2f %10.2f %10.2f %12.2f %12.2f %8.1f\n", 100.0 * k, pe[ns], pi[ns],
               px[ns], pe[ns] - px[ns], pi[ns] - px[ns], secs);
        fflush(stdout);
        for (int s = 0; s < ns; s++) {
            worst_e = fmin(worst_e, pe[s] - px[s]);
            worst_i = fmin(worst_i, pi[s] - px[s]);
        }
    }
    printf("worst scene gap: estimated - exact %.2f dB, interpolated - exact %.2f dB\n", worst_e,
           worst_i);
    im.model = NULL;
    lm_model_free(fam);
    lm_ctx_free(&c);
    for (int s = 0; s < ns; s++) lm_cube_free(&scenes[s]);
    lm_dataset_close(d);
    lm_system_free(&im.sys);
    return 0;
}

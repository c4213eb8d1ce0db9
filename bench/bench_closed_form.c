/* bench_closed_form.c — is a nonlinear closed-form fit worth building? Fits, per tile phase,
 * ridge regressions from the raw K x K window to the 33 channels on clean training patches
 * (the lmmse floor's normal equations) and the same with D random ReLU features of the window
 * appended (h = relu(R w + b), R ~ N(0, 1/K^2) shared by the phases: a random-features
 * approximation of a kernel ridge regression), and prints the validation PSNR of both (31 bands,
 * interior pixels, clean), with the fit times. A measurement tool, not a test.
 * Usage: bench_closed_form DATA... [--patches N] [--features D] [--window K] [--noise K]
 *   --noise: Gaussian noise k x the patch maximum added to training and validation patches
 *   (sampled, the same for both fits). */
#include "data/dataset.h"
#include "data/spectra.h"
#include "data/system.h"
#include "tensor/rng.h"
#include "train/fit_lmmse.h"
#include <cblas.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define O 33

static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

typedef struct acc { double *A, *B, yy[O]; long n; } acc;

static int K = 11, D = 256, PH = 66, PW = 64, F; /* F = K*K + D + 1 */
static float *R, *Rb;

/* Features of the window at (y, x): K*K raw values, D relu features, 1. */
static void features(const float *raw, int y, int x, int d, double *out)
{
    const int r = K / 2, KK = K * K;
    float w[31 * 31];
    for (int u = 0; u < K; u++)
        for (int v = 0; v < K; v++) w[u * K + v] = raw[(y - r + u) * PW + (x - r + v)];
    for (int i = 0; i < KK; i++) out[i] = w[i];
    for (int j = 0; j < d; j++) {
        float s = Rb[j];
        for (int i = 0; i < KK; i++) s += R[(size_t)j * KK + i] * w[i];
        out[KK + j] = s > 0 ? s : 0;
    }
    out[KK + d] = 1.0;
}

static void accumulate(acc *a, int nf, int d, const float *raw, const float *tgt, int nb, double *X,
                       double *Y)
{
    const int r = K / 2;
    for (int p = 0; p < 12; p++) {
        long n = 0;
        for (int b = 0; b < nb; b++)
            for (int y = r; y < PH - r; y++)
                for (int x = r; x < PW - r; x++) {
                    if ((y % 3) * 4 + x % 4 != p) continue;
                    features(raw + (size_t)b * PH * PW, y, x, d, X + n * nf);
                    for (int c = 0; c < O; c++)
                        Y[n * O + c] = tgt[((size_t)b * O + c) * PH * PW + y * PW + x];
                    n++;
                }
        cblas_dsyrk(CblasRowMajor, CblasUpper, CblasTrans, nf, (int)n, 1.0, X, nf, 1.0, a[p].A, nf);
        cblas_dgemm(CblasRowMajor, CblasTrans, CblasNoTrans, nf, O, (int)n, 1.0, X, nf, Y, O, 1.0,
                    a[p].B, O);
        for (long k = 0; k < n * O; k++) a[p].yy[k % O] += Y[k] * Y[k];
        a[p].n += n;
    }
}

/* Ridge solve (Cholesky) and validation SSE on channels 1..31. */
static double fit_val(const acc *t, const acc *v, int nf, double lam, double *W, double *L)
{
    double sse = 0;
    for (int p = 0; p < 12; p++) {
        double scale = 0;
        for (int a = 0; a < nf - 1; a++) scale += t[p].A[a * nf + a];
        scale /= (nf - 1);
        if (!lm_ridge_solve(t[p].A, t[p].B, nf, O, lam * scale, W, L)) return INFINITY;
        for (int c = 1; c <= 31; c++) {
            double wb = 0, waw = 0;
            for (int a = 0; a < nf; a++) {
                double row = 0;
                for (int b = 0; b < nf; b++)
                    row += (a <= b ? v[p].A[a * nf + b] : v[p].A[b * nf + a]) * W[b * O + c];
                wb += W[a * O + c] * v[p].B[a * O + c];
                waw += W[a * O + c] * row;
            }
            sse += v[p].yy[c] - 2 * wb + waw;
        }
    }
    return sse;
}

static acc *acc_new(int nf)
{
    acc *a = calloc(12, sizeof *a);
    for (int p = 0; p < 12; p++) {
        a[p].A = calloc((size_t)nf * nf, sizeof(double));
        a[p].B = calloc((size_t)nf * O, sizeof(double));
    }
    return a;
}

static void add_noise(float *raw, int nb, float k, lm_rng *r)
{
    for (int b = 0; b < nb; b++) {
        float *p = raw + (size_t)b * PH * PW, mx = 0;
        for (int i = 0; i < PH * PW; i++) mx = p[i] > mx ? p[i] : mx;
        for (int i = 0; i < PH * PW; i++) p[i] += k * mx * lm_rng_normal(r);
    }
}

int main(int argc, char **argv)
{
    const char *paths[16];
    int np = 0;
    long patches = 2048;
    float noise = 0;
    for (int i = 1; i < argc; i++) {
        if (!strcmp(argv[i], "--patches") && i + 1 < argc) patches = atol(argv[++i]);
        else if (!strcmp(argv[i], "--features") && i + 1 < argc) D = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--window") && i + 1 < argc) K = atoi(argv[++i]);
        else if (!strcmp(argv[i], "--noise") && i + 1 < argc) noise = (float)atof(argv[++i]);
        else if (np < 16) paths[np++] = argv[i];
    }
    lm_err e = {0};
    char sp[1024];
    lm_system sys;
    if (lm_data_path("systems/default.json", sp, sizeof sp, &e) || lm_system_load(sp, &sys, &e))
        return fprintf(stderr, "%s\n", e.msg), 2;
    lm_dataset_cfg dc;
    lm_dataset_default_cfg(&dc);
    dc.paths = paths, dc.npaths = np, dc.sys = &sys;
    dc.noise_min = dc.noise_max = dc.val_noise = 0;
    dc.val_patches = 64;
    lm_dataset *d = lm_dataset_open(&dc, &e);
    if (!d) return fprintf(stderr, "%s\n", e.msg), 2;
    F = K * K + D + 1;
    lm_rng r;
    lm_rng_seed(&r, 7);
    R = malloc(sizeof(float) * (size_t)D * K * K + 4);
    Rb = malloc(sizeof(float) * (size_t)D + 4);
    for (long i = 0; i < (long)D * K * K; i++) R[i] = lm_rng_normal(&r) / (float)K;
    for (int j = 0; j < D; j++) Rb[j] = 0.1f * lm_rng_normal(&r);
    const int B = 16;
    float *raw = malloc(sizeof(float) * B * PH * PW), *tgt = malloc(sizeof(float) * B * O * PH * PW);
    double *X = malloc(sizeof(double) * B * PH * PW / 12 * 2 * F), *Y = malloc(sizeof(double) * B * PH * PW / 6 * O);
    int nfs[2] = {K * K + 1, F};
    for (int v = 0; v < 2; v++) {
        int nf = nfs[v], dd = v ? D : 0;
        double t0 = now();
        acc *ta = acc_new(nf), *va = acc_new(nf);
        lm_rng nr;
        lm_rng_seed(&nr, 11);
        for (long k = 0; k < patches / B; k++) {
            if (lm_dataset_batch(d, k, B, raw, tgt, &e)) return fprintf(stderr, "%s\n", e.msg), 1;
            if (noise > 0) add_noise(raw, B, noise, &nr);
            accumulate(ta, nf, dd, raw, tgt, B, X, Y);
        }
        for (int i = 0; i < lm_dataset_eval_count(d, LM_SPLIT_VAL); i++) {
            if (lm_dataset_eval_sample(d, LM_SPLIT_VAL, i, raw, tgt, &e)) return 1;
            if (noise > 0) add_noise(raw, 1, noise, &nr);
            accumulate(va, nf, dd, raw, tgt, 1, X, Y);
        }
        double *W = malloc(sizeof(double) * nf * O), *L = malloc(sizeof(double) * nf * nf);
        long nv = 0;
        for (int p = 0; p < 12; p++) nv += va[p].n;
        double best = INFINITY, bl = 0;
        for (double lam = 1e-8; lam < 20; lam *= 10) {
            double s = fit_val(ta, va, nf, lam, W, L);
            if (s < best) best = s, bl = lam;
        }
        printf("%-22s features %4d  val PSNR %.3f dB (ridge %g)  %.1f s\n",
               v ? "window + random relu" : "window (lmmse)", nf, -10 * log10(best / (31.0 * nv)),
               bl, now() - t0);
        fflush(stdout);
    }
    lm_dataset_close(d);
    return 0;
}

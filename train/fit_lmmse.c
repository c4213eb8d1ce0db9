/* fit_lmmse.c — the closed-form fit of the lmmse floor (models/lmmse.c).
 *
 * Per tile phase p, over the interior pixels of clean training patches drawn by the same loader
 * as SGD training (flips, synthetic share): feature x = the K x K raw window (row-major) and a
 * 1, target y = the 33 channels at the pixel. Accumulated in double: A_p = sum x x^T,
 * B_p = sum x y^T, N_p = rows. Gaussian noise of sd s on the raw input adds s^2 N_p to the
 * window part of A_p's diagonal in expectation, so every noise level of the family is fitted
 * from the same clean statistics, exactly (no sampled noise):
 *     W_p(s) = (A_p + (s^2 + lambda) N_p D)^-1 B_p,   D = diag(1 on window entries, 0 on bias).
 * The ridge lambda (relative to the mean window second moment) is chosen per noise level on the
 * validation split's statistics (its squared error is a quadratic form in W, computed exactly
 * on channels 1..31, the metric's bands); without a validation split it is fixed and said so.
 * Real and synthetic training patches keep separate statistics; the synthetic share of the
 * mixture (5 % .. a half) is chosen per level on the validation split too (by coordinate descent
 * with the ridge), unless given: synthetic spectra widen what the filter has seen (narrow
 * spectra: the rainbow), but a linear filter spends its few coefficients on whatever the
 * mixture holds, and the validation split is real scenes.
 * With random features (lmmse-rf, D > 0) the features of noisy inputs are nonlinear in the
 * noise, so the statistics are accumulated again, with sampled noise, at six of the levels
 * (0, 0.005, 0.02, 0.05, 0.15, 0.3), and the levels between are interpolated linearly. The
 * panchromatic guide's features (lmmse-K-gG-b2, both buckets) are fitted the same way.
 * Both buckets (lmmse-b2: the loader opened with buckets 2): x = the K x K window of bucket 1,
 * then that of bucket 0 / (LEDs - 1), then the 1. The analytic noise term puts the same s^2 on
 * every window entry of both planes: the same noise sd in the stored units of either bucket
 * (their clean maxima are alike: both are 1 for white), where the loader draws k x each
 * bucket's own maximum. Bucket 0's stored maximum (a mean over eleven LEDs) is at most about
 * bucket 1's (the brightest LED's), so this overstates its noise a little: a conservative
 * filter, not a tuned one (per-plane levels would be a refinement).
 * What it is not: the model (models/lmmse.c) or SGD training (train.c). */
#include "train/fit_lmmse.h"
#include "data/dataset.h"
#include "tensor/linalg.h"
#include "tensor/rng.h"
#include <cblas.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>

#define NRIDGE 10
static const double ridge_grid[NRIDGE] = {1e-8, 1e-7, 1e-6, 1e-5, 1e-4, 1e-3, 1e-2, 1e-1, 1,
                                           10};
#define RIDGE_DEFAULT 1e-5
#define O LM_MODEL_OUT_CHANNELS

typedef struct stats {     /* one phase */
    double *A, *B;          /* F1 x F1 (upper triangle filled), F1 x 33 */
    double yy[O];           /* sum y_c^2 */
    long n;
} stats;

typedef struct fitter {
    int K, D, F1, P, ty, tx, ph, pw;
    int C;                  /* input planes: 1, or 2 (both buckets) */
    double b0_ratio;        /* bucket 0's noise sd over bucket 1's in the analytic term */
    stats *tr, *ts, *va;    /* training (real scenes), training (synthetic), validation */
    stats mix;              /* scratch: a mixture of tr and ts for one phase */
    lm_dataset *d;          /* the training patches' kinds */
    double synth;           /* synthetic share of the statistics (< 0: by validation) */
    double *X, *Y;          /* gather buffers: rows x F1, rows x 33 */
    long cap;
    const float *feat;      /* D > 0: feature maps of the batch, nb x D x ph x pw */
    int clip, bits;         /* sensor: applied after sampled noise */
    const lm_lmmse_fit_ctl *ctl; /* progress, interruption, budget (never NULL) */
    double c0, t0, shown;   /* budget clock and wall clock at the start; last progress line */
    long done, total;       /* training patches read, over every pass / to read */
    int pass, passes;       /* accumulation pass (1-based) and how many there are */
    int stopped;            /* 1: no more training patches (budget or interruption) */
    lm_lmmse_fit_report *rep;
} fitter;

static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

/* The budget's clock: the wall, or the process's CPU time. */
static double budget_clock(const fitter *f)
{
    struct timespec t;
    if (!f->ctl->cpu_clock || clock_gettime(CLOCK_PROCESS_CPUTIME_ID, &t)) return now();
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

static void fmt_time(char *buf, size_t n, double s)
{
    if (!(s >= 0) || s > 1e7) snprintf(buf, n, "?");
    else if (s >= 3600) snprintf(buf, n, "%dh%02dm", (int)(s / 3600), (int)fmod(s / 60, 60));
    else snprintf(buf, n, "%dm%02ds", (int)(s / 60), (int)fmod(s, 60));
}

/* A progress line: after the first batch, then every 10 s (and the last, final = 1). */
static void show_progress(fitter *f, int final)
{
    FILE *out = f->ctl->progress;
    double t = now(), el = t - f->t0;
    if (!out || (!final && f->shown > 0 && t - f->shown < 10.0)) return;
    f->shown = t;
    double rate = el > 0 ? f->done / el : 0, left = rate > 0 ? (f->total - f->done) / rate : -1;
    if (f->ctl->budget_s > 0) { /* the budget ends the accumulation at the latest */
        double rest = f->ctl->budget_s - (budget_clock(f) - f->c0);
        if (rest < 0) rest = 0;
        if (left < 0 || rest < left) left = rest;
    }
    char els[32], eta[32], pass[32] = "";
    fmt_time(els, sizeof els, el);
    fmt_time(eta, sizeof eta, left);
    const char *name = f->ctl->name ? f->ctl->name : "lmmse";
    if (f->passes > 1) snprintf(pass, sizeof pass, " (pass %d of %d)", f->pass, f->passes);
    if (final)
        fprintf(out, "train: fitting %s: %ld of %ld training patches read in %s%s\n", name,
                f->done, f->total, els, f->rep->interrupted ? " (interrupted: solving with them)"
                : f->rep->budget_spent ? " (the time budget is spent: solving with them)" : "");
    else
        fprintf(out, "train: fitting %s: %ld/%ld training patches read%s  elapsed %s  ETA %s\n",
                name, f->done, f->total, pass, els, eta);
    fflush(out);
}

/* Whether to stop reading training patches: interrupted, or the budget spent. */
static int stop_reading(fitter *f)
{
    int sig = f->ctl->interrupt ? atomic_load(f->ctl->interrupt) : 0;
    if (sig) f->rep->interrupted = sig;
    else if (f->ctl->budget_s > 0 && budget_clock(f) - f->c0 >= f->ctl->budget_s)
        f->rep->budget_spent = 1;
    else return 0;
    f->stopped = 1;
    return 1;
}

static lm_status fitter_init(fitter *f, const lm_model *m, int ph, int pw, int batch, lm_err *err)
{
    memset(f, 0, sizeof *f);
    f->K = lm_lmmse_window(m);
    f->D = lm_lmmse_features(m);
    f->C = lm_model_buckets(m) == 2 ? 2 : 1;
    f->F1 = f->C * f->K * f->K + f->D + 1;
    f->ty = m->mosaic.ty, f->tx = m->mosaic.tx, f->P = f->ty * f->tx;
    f->ph = ph, f->pw = pw;
    if (ph < f->K + f->ty || pw < f->K + f->tx)
        return lm_err_set(err, LM_ERR_ARG, "lmmse fit: patch %dx%d too small for the %dx%d "
                          "window", ph, pw, f->K, f->K);
    f->cap = (long)batch * ((ph / f->ty + 1) * (pw / f->tx + 1));
    f->tr = calloc((size_t)f->P, sizeof *f->tr);
    f->ts = calloc((size_t)f->P, sizeof *f->ts);
    f->va = calloc((size_t)f->P, sizeof *f->va);
    f->X = malloc(sizeof(double) * f->cap * f->F1);
    f->Y = malloc(sizeof(double) * f->cap * O);
    f->mix.A = calloc((size_t)f->F1 * f->F1, sizeof(double));
    f->mix.B = calloc((size_t)f->F1 * O, sizeof(double));
    int ok = f->tr && f->ts && f->va && f->X && f->Y && f->mix.A && f->mix.B;
    for (int p = 0; ok && p < f->P; p++) {
        stats *s[3] = {&f->tr[p], &f->ts[p], &f->va[p]};
        for (int k = 0; k < 3 && ok; k++) {
            s[k]->A = calloc((size_t)f->F1 * f->F1, sizeof(double));
            s[k]->B = calloc((size_t)f->F1 * O, sizeof(double));
            ok = s[k]->A && s[k]->B;
        }
    }
    return ok ? LM_OK : lm_err_set(err, LM_ERR_NOMEM, "lmmse fit: out of memory");
}

static void fitter_free(fitter *f)
{
    for (int p = 0; p < f->P && f->tr && f->ts && f->va; p++) {
        free(f->tr[p].A), free(f->tr[p].B), free(f->ts[p].A), free(f->ts[p].B);
        free(f->va[p].A), free(f->va[p].B);
    }
    free(f->tr), free(f->ts), free(f->va), free(f->X), free(f->Y), free(f->mix.A), free(f->mix.B);
}

/* Rows of phase p from the patches idx[0..nb) (raw: patches x C x ph x pw, target: patches x
 * 33 x ph x pw; idx NULL: 0..nb-1) into X, Y. */
static long gather(fitter *f, int p, const float *raw, const float *tgt, const int *idx, int nb)
{
    const int r = f->K / 2, ph = f->ph, pw = f->pw, i = p / f->tx, j = p % f->tx;
    const size_t plane = (size_t)ph * pw;
    long n = 0;
    for (int q = 0; q < nb; q++) {
        const int b = idx ? idx[q] : q;
        const float *rb = raw + (size_t)b * f->C * plane, *tb = tgt + (size_t)b * O * plane;
        int y0 = r + ((i - r) % f->ty + f->ty) % f->ty, x0 = r + ((j - r) % f->tx + f->tx) % f->tx;
        for (int y = y0; y < ph - r; y += f->ty)
            for (int x = x0; x < pw - r; x += f->tx, n++) {
                double *xr = f->X + n * f->F1;
                const int KK = f->K * f->K;
                for (int q = 0; q < f->C; q++)
                    for (int u = 0; u < f->K; u++)
                        for (int v = 0; v < f->K; v++)
                            xr[q * KK + u * f->K + v] =
                                rb[q * plane + (size_t)(y - r + u) * pw + (x - r + v)];
                const float *fb = f->feat + (size_t)b * f->D * plane + (size_t)y * pw + x;
                for (int d = 0; d < f->D; d++) xr[f->C * KK + d] = fb[d * plane];
                xr[f->F1 - 1] = 1.0;
                for (int c = 0; c < O; c++) f->Y[n * O + c] = tb[c * plane + (size_t)y * pw + x];
            }
    }
    return n;
}

static void accumulate(fitter *f, stats *st, const float *raw, const float *tgt, const int *idx,
                       int nb)
{
    for (int p = 0; p < f->P; p++) {
        long n = gather(f, p, raw, tgt, idx, nb);
        if (n == 0) continue;
        stats *s = &st[p];
        cblas_dsyrk(CblasRowMajor, CblasUpper, CblasTrans, f->F1, (int)n, 1.0, f->X, f->F1, 1.0,
                    s->A, f->F1);
        cblas_dgemm(CblasRowMajor, CblasTrans, CblasNoTrans, f->F1, O, (int)n, 1.0, f->X, f->F1,
                    f->Y, O, 1.0, s->B, O);
        for (long k = 0; k < n * O; k++) s->yy[k % O] += f->Y[k] * f->Y[k];
        s->n += n;
    }
}

/* Training patches first .. first+nb-1 of the batch: the real scenes' into f->tr, the
 * synthetic ones into f->ts. */
static lm_status accumulate_train(fitter *f, long first, const float *raw, const float *tgt,
                                  int nb, int *idx, lm_err *err)
{
    int nr = 0, ns = 0;
    for (int b = 0; b < nb; b++) {
        lm_dataset_sample_info in;
        lm_status st = lm_dataset_sample_info_get(f->d, LM_SPLIT_TRAIN, first + b, &in, err);
        if (st) return st;
        if (in.kind == LM_SAMPLE_SCENE) idx[nr++] = b;
        else idx[nb - 1 - ns++] = b;
    }
    if (nr) accumulate(f, f->tr, raw, tgt, idx, nr);
    if (ns) accumulate(f, f->ts, raw, tgt, idx + nr, ns);
    return LM_OK;
}

/* Solve (A + add D) W = B by Cholesky, D = identity except its last diagonal entry (the bias
 * row is not regularised). A: n x n, upper triangle read (row-major); B, W: n x m; L: n x n
 * scratch. Returns 0 when the matrix is not positive definite. */
/* (A + diag) W = B, diag: `add` on the window entries below `split`, add0 on those from
 * split to n - 2 (bucket 0's window), nothing on the bias (the last). */
static int ridge_solve(const double *A, const double *B, int n, int m, double add, double add0,
                       int split, double *W, double *L)
{
    for (int a = 0; a < n; a++)
        for (int b = a; b < n; b++)
            L[b * n + a] = A[a * n + b] + (a == b && a < n - 1 ? a < split ? add : add0 : 0);
    if (lm_cholesky(L, n)) return 0;
    memcpy(W, B, sizeof(double) * n * m);
    lm_cholesky_solve(L, n, W, m);
    return 1;
}

/* The normal equations of one phase at noise sd s (bucket 0's window: b0_ratio x s) with
 * ridge term r (already scaled by the rows). */
static int solve(const fitter *f, const stats *t, double s, double r, double *W, double *L)
{
    const double n = (double)t->n, s0 = f->b0_ratio * s;
    const int split = f->C == 2 && f->D == 0 ? f->K * f->K : f->F1;
    return ridge_solve(t->A, t->B, f->F1, O, s * s * n + r, s0 * s0 * n + r, split, W, L);
}

/* Squared error of W on the validation statistics at noise sd s, channels 1..31. */
static double val_sse(const fitter *f, const stats *v, const double *W, double s)
{
    const int n = f->F1, split = f->C == 2 && f->D == 0 ? f->K * f->K : n;
    const double r2 = f->b0_ratio * f->b0_ratio;
    double e = 0;
    for (int c = 1; c <= 31; c++) {
        double wb = 0, waw = 0, ww = 0;
        for (int a = 0; a < n; a++) {
            double wa = W[a * O + c], row = 0;
            wb += wa * v->B[a * O + c];
            for (int b = 0; b < n; b++) {
                double aab = a <= b ? v->A[a * n + b] : v->A[b * n + a];
                row += aab * W[b * O + c];
            }
            waw += wa * row;
            if (a < n - 1) ww += (a < split ? 1.0 : r2) * wa * wa;
        }
        e += v->yy[c] - 2 * wb + waw + s * s * (double)v->n * ww;
    }
    return e;
}

/* Mean window second moment of phase p (the ridge's scale). */
static double window_scale(const fitter *f, const stats *s)
{
    double t = 0;
    for (int a = 0; a < f->F1 - 1; a++) t += s->A[a * f->F1 + a];
    return t / (f->F1 - 1) / (s->n > 0 ? s->n : 1);
}

/* f->mix = phase p's training statistics with synthetic share w of the mixture (each kind
 * normalised by its rows; only one kind: that kind). */
static const stats *mixture(fitter *f, int p, double w)
{
    const stats *r = &f->tr[p], *y = &f->ts[p];
    if (y->n == 0 || (w <= 0 && r->n > 0)) return r;
    if (r->n == 0 || w >= 1) return y;
    const double N = (double)(r->n + y->n), a = (1 - w) * N / (double)r->n, b = w * N / (double)y->n;
    stats *m = &f->mix;
    for (long k = 0; k < (long)f->F1 * f->F1; k++) m->A[k] = a * r->A[k] + b * y->A[k];
    for (long k = 0; k < (long)f->F1 * O; k++) m->B[k] = a * r->B[k] + b * y->B[k];
    for (int c = 0; c < O; c++) m->yy[c] = a * r->yy[c] + b * y->yy[c];
    m->n = r->n + y->n;
    return m;
}

/* Validation squared error over every phase of the filters for noise sd s, ridge lam and
 * synthetic share w (INFINITY when a system is not positive definite). */
static double level_sse(fitter *f, double s, double lam, double w, double *W, double *L)
{
    double sse = 0;
    for (int p = 0; p < f->P && isfinite(sse); p++) {
        const stats *t = mixture(f, p, w);
        const double r = lam * window_scale(f, t) * (double)t->n;
        sse = solve(f, t, s, r, W, L) ? sse + val_sse(f, &f->va[p], W, s) : INFINITY;
    }
    return sse;
}

/* The shares tried; at least 5 %: the validation split is real scenes and alone picks 0 at
 * most levels, which forgets narrow spectra (lmmse on the rainbow, peak error mean / max:
 * share 0 6.4 / 32.9 nm, 0.02 3.7 / 29.4 nm, 0.05 3.0 / 17.8 nm, 0.1 2.6 / 13.6 nm, 0.33
 * 2.7 / 9.8 nm; real test split at noise 0: 35.92, 35.99, 35.73, 35.40, 34.48 dB). */
static const double synth_grid[] = {0.05, 0.1, 0.2, 0.35, 0.5};
#define NSYNTH (int)(sizeof synth_grid / sizeof synth_grid[0])

/* Fit every level (D = 0: all from the clean statistics; D > 0: only `level`, whose noise
 * the statistics already hold, with s = 0 in the analytic term), ridge and synthetic share by
 * validation (or the defaults: the ridge's, and the share the data holds), filters into the
 * model; coef (P x F1 x 33) keeps them when non-NULL. */
static lm_status fit_levels(fitter *f, lm_model *m, int have_val, int level, double *coef,
                            lm_lmmse_fit_report *rep, lm_err *err)
{
    const double t0 = now();
    double *W = malloc(sizeof(double) * f->F1 * O), *L = malloc(sizeof(double) * f->F1 * f->F1);
    if (!W || !L) return free(W), free(L), lm_err_set(err, LM_ERR_NOMEM, "lmmse fit: out of memory");
    lm_status st = LM_OK;
    long nval = 0, nr = 0, ns = 0;
    for (int p = 0; p < f->P; p++) nval += f->va[p].n, nr += f->tr[p].n, ns += f->ts[p].n;
    const double natural = nr + ns > 0 ? (double)ns / (double)(nr + ns) : 0;
    const float *sig = lm_lmmse_levels(m);
    for (int l = 0; l < LM_LMMSE_LEVELS && !st; l++) {
        if (level >= 0 && l != level) continue;
        const double s = level >= 0 ? 0.0 : sig[l];
        double lam = RIDGE_DEFAULT, w = f->synth >= 0 ? f->synth : natural, best_sse = INFINITY;
        /* coordinate descent: ridge at the natural share, share at that ridge, ridge again */
        for (int pass = 0; have_val && pass < 3; pass++) {
            int ridge_pass = pass != 1;
            int n = ridge_pass ? NRIDGE : nr && ns && f->synth < 0 ? NSYNTH : 0;
            for (int g = 0; g < n; g++) {
                double lg = ridge_pass ? ridge_grid[g] : lam, wg = ridge_pass ? w : synth_grid[g];
                double sse = level_sse(f, s, lg, wg, W, L);
                if (sse < best_sse) best_sse = sse, lam = lg, w = wg;
            }
        }
        rep->ridge[l] = lam;
        rep->synth_weight[l] = nr && ns ? w : ns ? 1.0 : 0.0;
        rep->val_psnr[l] = isfinite(best_sse) ? -10.0 * log10(best_sse / (31.0 * (double)nval))
                                              : NAN;
        for (int p = 0; p < f->P && !st; p++) {
            const stats *t = mixture(f, p, w);
            const double r = lam * window_scale(f, t) * (double)t->n;
            if (!solve(f, t, s, r, W, L))
                st = lm_err_set(err, LM_ERR_NUMERIC, "lmmse fit: phase %d, noise %g: normal "
                                "equations not positive definite (too few samples?)", p, s);
            else st = lm_lmmse_set_filter(m, l, p, W, err);
            if (coef) memcpy(coef + (size_t)p * f->F1 * O, W, sizeof(double) * f->F1 * O);
        }
    }
    free(W), free(L);
    rep->seconds_solve += now() - t0;
    return st;
}

/* Feature maps of nb raw patches into buf (D > 0). */
static lm_status features(fitter *f, lm_model *m, lm_ctx *c, const float *raw, int nb, float *buf,
                          lm_err *err)
{
    lm_ctx_reset(c);
    lm_tensor *x = lm_tensor_from(c, 4, (int[]){nb, f->C, f->ph, f->pw}, (float *)raw);
    lm_tensor *h = lm_lmmse_feature_maps(c, m, x);
    if (!h || lm_tensor_read(c, h, buf)) {
        lm_err_set(err, lm_ctx_status(c), "lmmse fit: %s", lm_ctx_message(c));
        lm_ctx_clear_error(c);
        return err->status;
    }
    f->feat = buf;
    return LM_OK;
}

/* Gaussian noise of sd s added to n values (sampled: the features are nonlinear), then the
 * sensor's clipping to [0, 1] and quantisation. */
static void add_noise(const fitter *f, float *raw, size_t n, double s, lm_rng *r)
{
    const float L = f->bits ? (float)((1u << f->bits) - 1) : 0.0f;
    for (size_t i = 0; i < n; i++) {
        float v = raw[i] + (s > 0 ? (float)s * lm_rng_normal(r) : 0.0f);
        if (f->clip || L > 0) v = v < 0 ? 0 : v > 1 ? 1 : v;
        if (L > 0) v = rintf(v * L) / L;
        raw[i] = v;
    }
}

static void stats_clear(fitter *f)
{
    for (int p = 0; p < f->P; p++) {
        stats *s[3] = {&f->tr[p], &f->ts[p], &f->va[p]};
        for (int k = 0; k < 3; k++) {
            memset(s[k]->A, 0, sizeof(double) * f->F1 * f->F1);
            memset(s[k]->B, 0, sizeof(double) * f->F1 * O);
            memset(s[k]->yy, 0, sizeof s[k]->yy);
            s[k]->n = 0;
        }
    }
}

/* One pass over the training and validation patches at noise sd s (sampled). */
static lm_status accumulate_all(fitter *f, lm_model *m, lm_ctx *c, lm_dataset *d, long patches,
                                int batch, double s, uint64_t seed, float *raw, float *tgt,
                                float *fbuf, lm_err *err)
{
    lm_rng r;
    lm_rng_seed(&r, seed);
    const size_t plane = (size_t)f->ph * f->pw * f->C; /* one sample's raw floats */
    long nbatches = (patches + batch - 1) / batch;
    int *idx = malloc(sizeof(int) * (size_t)batch);
    lm_status st = idx ? LM_OK : lm_err_set(err, LM_ERR_NOMEM, "lmmse fit: out of memory");
    long read = 0;
    for (long k = 0; k < nbatches && !st; k++) {
        if (k > 0 && stop_reading(f)) break; /* at least one batch: the system is solvable */
        int nb = (int)(k + 1 < nbatches ? batch : patches - k * batch);
        if ((st = lm_dataset_batch(d, k, batch, raw, tgt, err))) break;
        add_noise(f, raw, nb * plane, s, &r);
        if (f->D && (st = features(f, m, c, raw, nb, fbuf, err))) break;
        st = accumulate_train(f, k * batch, raw, tgt, nb, idx, err);
        read += nb, f->done += nb;
        show_progress(f, 0);
    }
    if (f->pass == 1) f->rep->patches = read;
    if (!st && f->pass == f->passes) show_progress(f, 1);
    int nv = lm_dataset_eval_count(d, LM_SPLIT_VAL);
    for (int i = 0; i < nv && !st; i++) {
        if ((st = lm_dataset_eval_sample(d, LM_SPLIT_VAL, i, raw, tgt, err))) break;
        add_noise(f, raw, plane, s, &r);
        if (f->D && (st = features(f, m, c, raw, 1, fbuf, err))) break;
        accumulate(f, f->va, raw, tgt, NULL, 1);
    }
    free(idx);
    return st;
}

/* D > 0: levels fitted with sampled noise; the others interpolated linearly in sd between
 * them (what inference between fitted levels does anyway). */
static const int rf_levels[] = {0, 2, 4, 6, 9, 11};
#define N_RF_LEVELS (int)(sizeof rf_levels / sizeof rf_levels[0])

static lm_status fit_features(fitter *f, lm_model *m, lm_dataset *d, long patches, int batch,
                              float *raw, float *tgt, lm_lmmse_fit_report *rep, lm_err *err)
{
    lm_ctx c;
    if (lm_ctx_init(&c, 0)) return lm_err_set(err, LM_ERR_NOMEM, "lmmse fit: no context");
    const size_t per = (size_t)f->P * f->F1 * O;
    float *fbuf = malloc(sizeof(float) * ((size_t)batch * f->D * f->ph * f->pw + 1));
    double *coef = malloc(sizeof(double) * per * N_RF_LEVELS);
    lm_status st = fbuf && coef ? LM_OK : lm_err_set(err, LM_ERR_NOMEM, "lmmse fit: no memory");
    int nv = lm_dataset_eval_count(d, LM_SPLIT_VAL);
    const float *sig = lm_lmmse_levels(m);
    f->passes = N_RF_LEVELS;
    f->total = patches * N_RF_LEVELS;
    double budget = f->ctl->budget_s;
    for (int q = 0; q < N_RF_LEVELS && !st; q++) {
        const int l = rf_levels[q];
        stats_clear(f);
        f->pass = q + 1;
        /* the first pass takes its share of the budget; the others read as many patches */
        lm_lmmse_fit_ctl one = *f->ctl;
        const lm_lmmse_fit_ctl *keep = f->ctl;
        if (q == 0) one.budget_s = budget / N_RF_LEVELS;
        else one.budget_s = 0;
        f->ctl = &one;
        st = accumulate_all(f, m, &c, d, q ? rep->patches : patches, batch, sig[l],
                            0x5eed0000u + l, raw, tgt, fbuf, err);
        f->ctl = keep;
        if (!st && q == 0) f->total = rep->patches * N_RF_LEVELS;
        if (!st && rep->interrupted && q + 1 < N_RF_LEVELS)
            st = lm_err_set(err, LM_ERR_INTERRUPTED, "the closed-form fit of %s was stopped in "
                            "pass %d of %d (each noise level of the family is read again); "
                            "nothing was fitted", m->preset, q + 1, N_RF_LEVELS);
        if (!st) st = fit_levels(f, m, nv > 0, l, coef + per * q, rep, err);
    }
    double *w = st ? NULL : malloc(sizeof(double) * f->F1 * O);
    for (int q = 0; w && q + 1 < N_RF_LEVELS && !st; q++)
        for (int l = rf_levels[q] + 1; l < rf_levels[q + 1] && !st; l++) {
            double s0 = sig[rf_levels[q]], s1 = sig[rf_levels[q + 1]];
            double t = (sig[l] - s0) / (s1 - s0);
            rep->ridge[l] = NAN, rep->val_psnr[l] = NAN, rep->synth_weight[l] = NAN;
            for (int p = 0; p < f->P && !st; p++) {
                const double *a = coef + per * q + (size_t)p * f->F1 * O, *b = a + per;
                for (int k = 0; k < f->F1 * O; k++) w[k] = (1 - t) * a[k] + t * b[k];
                st = lm_lmmse_set_filter(m, l, p, w, err);
            }
        }
    free(w), free(fbuf), free(coef);
    lm_ctx_free(&c);
    return st;
}

lm_status lm_lmmse_fit(lm_model *m, lm_dataset *d, int ph, int pw, long patches, int batch,
                       double synth, const lm_noise_opts *sensor, lm_lmmse_fit_report *rep, lm_err *err)
{
    return lm_lmmse_fit_ctl_run(m, d, ph, pw, patches, batch, synth, sensor, NULL, rep, err);
}

lm_status lm_lmmse_fit_ctl_run(lm_model *m, lm_dataset *d, int ph, int pw, long patches,
                               int batch, double synth, const lm_noise_opts *sensor,
                               const lm_lmmse_fit_ctl *ctl, lm_lmmse_fit_report *rep,
                               lm_err *err)
{
    static const lm_lmmse_fit_ctl none;
    memset(rep, 0, sizeof *rep);
    rep->patches_asked = patches;
    if (!lm_lmmse_window(m))
        return lm_err_set(err, LM_ERR_ARG, "lmmse fit: model %s is not an lmmse model", m->preset);
    if (patches < 1 || batch < 1)
        return lm_err_set(err, LM_ERR_ARG, "lmmse fit: %ld patches in batches of %d", patches,
                          batch);
    if (lm_dataset_buckets(d) != (lm_model_buckets(m) == 2 ? 2 : 1))
        return lm_err_set(err, LM_ERR_ARG, "lmmse fit: model %s reads %d bucket(s), the data "
                          "gives %d", m->preset, lm_model_buckets(m), lm_dataset_buckets(d));
    fitter f;
    double t0 = now();
    lm_status st = fitter_init(&f, m, ph, pw, batch, err);
    float *raw = malloc(sizeof(float) * batch * ph * pw * (lm_model_buckets(m) == 2 ? 2 : 1));
    float *tgt = malloc(sizeof(float) * batch * O * ph * pw);
    if (!st && (!raw || !tgt)) st = lm_err_set(err, LM_ERR_NOMEM, "lmmse fit: out of memory");
    int nv = lm_dataset_eval_count(d, LM_SPLIT_VAL);
    if (sensor) f.clip = sensor->clip, f.bits = sensor->bits;
    f.d = d;
    f.synth = synth;
    f.ctl = ctl ? ctl : &none;
    f.b0_ratio = f.ctl->b0_noise_ratio > 0 ? f.ctl->b0_noise_ratio : 1.0;
    if (!st && f.b0_ratio != 1.0 && (f.C != 2 || f.D > 0 || f.clip || f.bits))
        st = lm_err_set(err, LM_ERR_ARG, "lmmse fit: a bucket-0 noise ratio is for the "
                        "analytic noise of a two-bucket floor without features or sensor "
                        "model (lmmse-b2, lmmse-K-b2), not %s%s", m->preset,
                        f.clip || f.bits ? " with clipping or quantisation" : "");
    f.rep = rep;
    f.t0 = now(), f.c0 = budget_clock(&f);
    f.pass = f.passes = 1;
    f.total = patches;
    if (!st && (f.D > 0 || f.clip || f.bits)) {
        st = fit_features(&f, m, d, patches, batch, raw, tgt, rep, err);
    } else if (!st) {
        st = accumulate_all(&f, m, NULL, d, patches, batch, 0.0, 0, raw, tgt, NULL, err);
        if (!st) st = fit_levels(&f, m, nv > 0, -1, NULL, rep, err);
    }
    rep->val_patches = nv;
    for (int p = 0; p < f.P; p++) rep->rows += f.tr[p].n + f.ts[p].n;
    rep->seconds = now() - t0;
    fitter_free(&f);
    free(raw), free(tgt);
    return st;
}

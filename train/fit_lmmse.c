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
 * What it is not: the model (models/lmmse.c) or SGD training (train.c). */
#include "train/fit_lmmse.h"
#include "data/dataset.h"
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
    int K, F1, P, ty, tx, ph, pw;
    stats *tr, *va;
    double *X, *Y;          /* gather buffers: rows x F1, rows x 33 */
    long cap;
} fitter;

static double now(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

static lm_status fitter_init(fitter *f, const lm_model *m, int ph, int pw, int batch, lm_err *err)
{
    memset(f, 0, sizeof *f);
    f->K = lm_lmmse_window(m);
    f->F1 = f->K * f->K + 1;
    f->ty = m->mosaic.ty, f->tx = m->mosaic.tx, f->P = f->ty * f->tx;
    f->ph = ph, f->pw = pw;
    if (ph < f->K + f->ty || pw < f->K + f->tx)
        return lm_err_set(err, LM_ERR_ARG, "lmmse fit: patch %dx%d too small for the %dx%d "
                          "window", ph, pw, f->K, f->K);
    f->cap = (long)batch * ((ph / f->ty + 1) * (pw / f->tx + 1));
    f->tr = calloc((size_t)f->P, sizeof *f->tr);
    f->va = calloc((size_t)f->P, sizeof *f->va);
    f->X = malloc(sizeof(double) * f->cap * f->F1);
    f->Y = malloc(sizeof(double) * f->cap * O);
    int ok = f->tr && f->va && f->X && f->Y;
    for (int p = 0; ok && p < f->P; p++) {
        stats *s[2] = {&f->tr[p], &f->va[p]};
        for (int k = 0; k < 2 && ok; k++) {
            s[k]->A = calloc((size_t)f->F1 * f->F1, sizeof(double));
            s[k]->B = calloc((size_t)f->F1 * O, sizeof(double));
            ok = s[k]->A && s[k]->B;
        }
    }
    return ok ? LM_OK : lm_err_set(err, LM_ERR_NOMEM, "lmmse fit: out of memory");
}

static void fitter_free(fitter *f)
{
    for (int p = 0; p < f->P && f->tr && f->va; p++) {
        free(f->tr[p].A), free(f->tr[p].B), free(f->va[p].A), free(f->va[p].B);
    }
    free(f->tr), free(f->va), free(f->X), free(f->Y);
}

/* Rows of phase p from nb patches (raw nb x ph x pw, target nb x 33 x ph x pw) into X, Y. */
static long gather(fitter *f, int p, const float *raw, const float *tgt, int nb)
{
    const int r = f->K / 2, ph = f->ph, pw = f->pw, i = p / f->tx, j = p % f->tx;
    const size_t plane = (size_t)ph * pw;
    long n = 0;
    for (int b = 0; b < nb; b++) {
        const float *rb = raw + b * plane, *tb = tgt + (size_t)b * O * plane;
        int y0 = r + ((i - r) % f->ty + f->ty) % f->ty, x0 = r + ((j - r) % f->tx + f->tx) % f->tx;
        for (int y = y0; y < ph - r; y += f->ty)
            for (int x = x0; x < pw - r; x += f->tx, n++) {
                double *xr = f->X + n * f->F1;
                for (int u = 0; u < f->K; u++)
                    for (int v = 0; v < f->K; v++)
                        xr[u * f->K + v] = rb[(size_t)(y - r + u) * pw + (x - r + v)];
                xr[f->F1 - 1] = 1.0;
                for (int c = 0; c < O; c++) f->Y[n * O + c] = tb[c * plane + (size_t)y * pw + x];
            }
    }
    return n;
}

static void accumulate(fitter *f, stats *st, const float *raw, const float *tgt, int nb)
{
    for (int p = 0; p < f->P; p++) {
        long n = gather(f, p, raw, tgt, nb);
        stats *s = &st[p];
        cblas_dsyrk(CblasRowMajor, CblasUpper, CblasTrans, f->F1, (int)n, 1.0, f->X, f->F1, 1.0,
                    s->A, f->F1);
        cblas_dgemm(CblasRowMajor, CblasTrans, CblasNoTrans, f->F1, O, (int)n, 1.0, f->X, f->F1,
                    f->Y, O, 1.0, s->B, O);
        for (long k = 0; k < n * O; k++) s->yy[k % O] += f->Y[k] * f->Y[k];
        s->n += n;
    }
}

/* Solve (A + add D) W = B by Cholesky (A's upper triangle); W is F1 x 33. Returns 0 if the
 * matrix is not positive definite. */
static int solve(const fitter *f, const stats *s, double add, double *W, double *L)
{
    const int n = f->F1;
    for (int a = 0; a < n; a++)
        for (int b = a; b < n; b++) L[b * n + a] = s->A[a * n + b] + (a == b && a < n - 1 ? add : 0);
    for (int j = 0; j < n; j++) { /* lower Cholesky in place */
        double d = L[j * n + j];
        for (int k = 0; k < j; k++) d -= L[j * n + k] * L[j * n + k];
        if (!(d > 0)) return 0;
        d = sqrt(d);
        L[j * n + j] = d;
        for (int i = j + 1; i < n; i++) {
            double v = L[i * n + j];
            for (int k = 0; k < j; k++) v -= L[i * n + k] * L[j * n + k];
            L[i * n + j] = v / d;
        }
    }
    memcpy(W, s->B, sizeof(double) * n * O);
    for (int c = 0; c < O; c++) {
        for (int i = 0; i < n; i++) { /* forward */
            double v = W[i * O + c];
            for (int k = 0; k < i; k++) v -= L[i * n + k] * W[k * O + c];
            W[i * O + c] = v / L[i * n + i];
        }
        for (int i = n - 1; i >= 0; i--) { /* backward with L^T */
            double v = W[i * O + c];
            for (int k = i + 1; k < n; k++) v -= L[k * n + i] * W[k * O + c];
            W[i * O + c] = v / L[i * n + i];
        }
    }
    return 1;
}

/* Squared error of W on the validation statistics at noise sd s, channels 1..31. */
static double val_sse(const fitter *f, const stats *v, const double *W, double s)
{
    const int n = f->F1;
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
            if (a < n - 1) ww += wa * wa;
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

/* Fit every level: ridge by validation (or the default), filters into the model. */
static lm_status fit_levels(fitter *f, lm_model *m, int have_val, lm_lmmse_fit_report *rep,
                            lm_err *err)
{
    double *W = malloc(sizeof(double) * f->F1 * O), *L = malloc(sizeof(double) * f->F1 * f->F1);
    if (!W || !L) return free(W), free(L), lm_err_set(err, LM_ERR_NOMEM, "lmmse fit: out of memory");
    lm_status st = LM_OK;
    long nval = 0;
    for (int p = 0; p < f->P; p++) nval += f->va[p].n;
    for (int l = 0; l < LM_LMMSE_LEVELS && !st; l++) {
        const double s = lm_lmmse_sigmas[l];
        int best = -1;
        double best_sse = INFINITY;
        for (int g = 0; have_val && g < NRIDGE; g++) {
            double sse = 0;
            for (int p = 0; p < f->P && isfinite(sse); p++) {
                const stats *t = &f->tr[p];
                double add = (s * s + ridge_grid[g] * window_scale(f, t)) * (double)t->n;
                sse = solve(f, t, add, W, L) ? sse + val_sse(f, &f->va[p], W, s) : INFINITY;
            }
            if (sse < best_sse) best_sse = sse, best = g;
        }
        double lam = best >= 0 ? ridge_grid[best] : RIDGE_DEFAULT;
        rep->ridge[l] = lam;
        rep->val_psnr[l] = best >= 0 ? -10.0 * log10(best_sse / (31.0 * (double)nval)) : NAN;
        for (int p = 0; p < f->P && !st; p++) {
            const stats *t = &f->tr[p];
            double add = (s * s + lam * window_scale(f, t)) * (double)t->n;
            if (!solve(f, t, add, W, L))
                st = lm_err_set(err, LM_ERR_NUMERIC, "lmmse fit: phase %d, noise %g: normal "
                                "equations not positive definite (too few samples?)", p, s);
            else st = lm_lmmse_set_filter(m, l, p, W, err);
        }
    }
    free(W), free(L);
    return st;
}

lm_status lm_lmmse_fit(lm_model *m, lm_dataset *d, int ph, int pw, long patches, int batch,
                       lm_lmmse_fit_report *rep, lm_err *err)
{
    memset(rep, 0, sizeof *rep);
    if (!lm_lmmse_window(m))
        return lm_err_set(err, LM_ERR_ARG, "lmmse fit: model %s is not an lmmse model", m->preset);
    if (patches < 1 || batch < 1)
        return lm_err_set(err, LM_ERR_ARG, "lmmse fit: %ld patches in batches of %d", patches,
                          batch);
    fitter f;
    double t0 = now();
    lm_status st = fitter_init(&f, m, ph, pw, batch, err);
    float *raw = malloc(sizeof(float) * batch * ph * pw);
    float *tgt = malloc(sizeof(float) * batch * O * ph * pw);
    if (!st && (!raw || !tgt)) st = lm_err_set(err, LM_ERR_NOMEM, "lmmse fit: out of memory");
    long nbatches = (patches + batch - 1) / batch;
    for (long k = 0; k < nbatches && !st; k++) {
        int nb = (int)(k + 1 < nbatches ? batch : patches - k * batch);
        if (!(st = lm_dataset_batch(d, k, batch, raw, tgt, err))) accumulate(&f, f.tr, raw, tgt, nb);
    }
    int nv = lm_dataset_eval_count(d, LM_SPLIT_VAL);
    for (int i = 0; i < nv && !st; i++)
        if (!(st = lm_dataset_eval_sample(d, LM_SPLIT_VAL, i, raw, tgt, err)))
            accumulate(&f, f.va, raw, tgt, 1);
    rep->patches = patches;
    rep->val_patches = nv;
    for (int p = 0; p < f.P; p++) rep->rows += f.tr[p].n;
    if (!st) st = fit_levels(&f, m, nv > 0, rep, err);
    rep->seconds = now() - t0;
    fitter_free(&f);
    free(raw), free(tgt);
    return st;
}

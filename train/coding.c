/* coding.c — learned coding: allocation and tile map chosen through the closed-form linear
 * reconstruction (see coding.h). */
#include "train/coding.h"
#include "data/calib.h"
#include "data/cube_io.h"
#include "data/dataset.h"
#include "data/doe.h"
#include "data/forward.h"
#include "data/spectra.h"
#include "tensor/linalg.h"
#include "tensor/rng.h"
#include <cblas.h>
#include <fftw3.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define NB LM_CODING_BANDS

static int pmod(int a, int n) { return ((a % n) + n) % n; }

void lm_coding_from_system(const lm_system *sys, lm_coding *c)
{
    memset(c, 0, sizeof *c);
    c->rows = sys->tile_rows, c->cols = sys->tile_cols;
    for (int t = 0; t < c->rows * c->cols; t++) c->tile_led[t] = sys->tile_led[t];
    for (int l = 0; l < sys->nleds; l++) c->subframes[l] = sys->leds[l].subframes;
}

/* ---- scenes ------------------------------------------------------------------------------ */

void lm_coding_data_free(lm_coding_data *d)
{
    for (int i = 0; d->scenes && i < d->nscenes; i++)
        free(d->scenes[i].u), free(d->scenes[i].y);
    free(d->scenes);
    memset(d, 0, sizeof *d);
}

/* One scene: 31 bands divided by the maximum, per-LED images a_l . mirror41(r). */
static lm_status load_scene(const lm_system *sys, const lm_dataset_scene *ds,
                            lm_coding_scene *sc, lm_err *err)
{
    lm_cube_read_opts o;
    lm_cube_read_opts_default(&o);
    o.keep.count = 0; /* 31 bands 400..700 only */
    lm_cube c31 = {0}, c41 = {0};
    lm_status st = lm_cube_read_with(ds->path, &o, &c31, err);
    if (st) return st;
    float mx = lm_cube_max(&c31);
    if (c31.bands != NB || !(mx > 0.0f) || !isfinite(mx)) {
        st = lm_err_set(err, LM_ERR_FORMAT, "%s: %d bands, maximum %g: a scene needs 31 bands "
                        "and a positive maximum", ds->path, c31.bands, (double)mx);
        lm_cube_free(&c31);
        return st;
    }
    const size_t n = (size_t)c31.height * c31.width;
    for (size_t i = 0; i < (size_t)NB * n; i++) c31.data[i] /= mx;
    st = lm_cube_mirror41(&c31, &c41, err);
    if (!st && (c41.bands != sys->nbins))
        st = lm_err_set(err, LM_ERR_SHAPE, "coding: the system's grid has %d bins, the scenes "
                        "41 (use the default 380/10/41 grid)", sys->nbins);
    if (!st) {
        snprintf(sc->name, sizeof sc->name, "%s", ds->name);
        sc->split = ds->split;
        sc->height = c31.height, sc->width = c31.width;
        sc->u = calloc((size_t)sys->nleds * n, sizeof(float));
        if (!sc->u) st = lm_err_set(err, LM_ERR_NOMEM, "coding: out of memory");
    }
    for (int l = 0; !st && l < sys->nleds; l++) {
        const float *a = sys->leds[l].response;
        float *u = sc->u + (size_t)l * n;
        for (int b = 0; b < c41.bands; b++) {
            const float *band = lm_cube_band(&c41, b);
            const float w = a[b];
            for (size_t i = 0; i < n; i++) u[i] += w * band[i];
        }
    }
    lm_cube_free(&c41);
    if (!st) sc->y = c31.data; /* keeps the 31 bands */
    else lm_cube_free(&c31);
    return st;
}

lm_status lm_coding_data_load(const char *const *paths, int npaths, const lm_system *sys,
                              lm_coding_data *d, lm_err *err)
{
    memset(d, 0, sizeof *d);
    lm_dataset_scene *list = NULL;
    int n = 0;
    lm_status st = lm_dataset_list_scenes(paths, npaths, sys, NULL, -1, &list, &n, err);
    if (st) return st;
    d->nleds = sys->nleds;
    d->scenes = calloc(n > 0 ? (size_t)n : 1, sizeof *d->scenes);
    if (!d->scenes) st = lm_err_set(err, LM_ERR_NOMEM, "coding: out of memory");
    for (int i = 0; !st && i < n; i++) {
        st = load_scene(sys, &list[i], &d->scenes[i], err);
        if (!st) d->nscenes++;
    }
    free(list);
    int have[3] = {0};
    for (int i = 0; i < d->nscenes; i++) have[d->scenes[i].split]++;
    if (!st && (!have[LM_SPLIT_TRAIN] || !have[LM_SPLIT_TEST]))
        st = lm_err_set(err, LM_ERR_ARG, "coding: the data has %d training and %d test scenes; "
                        "the search needs both (at least 5 scenes: the 80/10/10 split)",
                        have[LM_SPLIT_TRAIN], have[LM_SPLIT_TEST]);
    if (st) lm_coding_data_free(d);
    return st;
}

/* ---- stationary statistics (FFT cross-correlations) ------------------------------------- */

void lm_coding_stats_free(lm_coding_stats *st)
{
    free(st->R), free(st->Q);
    memset(st, 0, sizeof *st);
}

/* Per scene: sums of U_l(x) U_m(x + D) over the pixels where both are inside, and of
 * U_l(x + d) y_c(x), added into Rs / Qs; counts per offset into Rn / Qn. */
typedef struct corr_ws {
    int ph, pw, fw;           /* padded size, complex width pw / 2 + 1 */
    float *real;              /* ph x pw */
    fftwf_complex *spec;      /* (L + 31) spectra */
    fftwf_complex *prod;      /* one product */
    fftwf_plan fwd, inv;
} corr_ws;

static lm_status corr_init(corr_ws *w, int H, int W, int K, int L, lm_err *err)
{
    memset(w, 0, sizeof *w);
    w->ph = H + K, w->pw = W + K, w->fw = w->pw / 2 + 1;
    const size_t nr = (size_t)w->ph * w->pw, nc = (size_t)w->ph * w->fw;
    w->real = fftwf_alloc_real(nr);
    w->spec = fftwf_alloc_complex(nc * (size_t)(L + NB));
    w->prod = fftwf_alloc_complex(nc);
    if (!w->real || !w->spec || !w->prod)
        return lm_err_set(err, LM_ERR_NOMEM, "coding: out of memory (FFT buffers)");
    lm_fftw_lock();
    w->fwd = fftwf_plan_dft_r2c_2d(w->ph, w->pw, w->real, w->spec, FFTW_ESTIMATE);
    w->inv = fftwf_plan_dft_c2r_2d(w->ph, w->pw, w->prod, w->real, FFTW_ESTIMATE);
    lm_fftw_unlock();
    if (!w->fwd || !w->inv) return lm_err_set(err, LM_ERR_NOMEM, "coding: FFTW plan failed");
    return LM_OK;
}

static void corr_free(corr_ws *w)
{
    lm_fftw_lock();
    if (w->fwd) fftwf_destroy_plan(w->fwd);
    if (w->inv) fftwf_destroy_plan(w->inv);
    lm_fftw_unlock();
    fftwf_free(w->real), fftwf_free(w->spec), fftwf_free(w->prod);
}

/* spectrum k of plane img (H x W) zero-padded */
static void corr_spectrum(corr_ws *w, const float *img, int H, int W, int k)
{
    memset(w->real, 0, sizeof(float) * (size_t)w->ph * w->pw);
    for (int y = 0; y < H; y++) memcpy(w->real + (size_t)y * w->pw, img + (size_t)y * W,
                                       sizeof(float) * (size_t)W);
    fftwf_execute_dft_r2c(w->fwd, w->real, w->spec + (size_t)k * w->ph * w->fw);
}

/* real = sum_x f_a(x) f_b(x + D) for every D (circular, unnormalised x N) */
static void corr_pair(corr_ws *w, int a, int b)
{
    const size_t nc = (size_t)w->ph * w->fw;
    /* (re, im) pairs: fftwf_complex may be a C99 complex type or float[2] */
    const float *A = (const float *)(w->spec + (size_t)a * nc);
    const float *B = (const float *)(w->spec + (size_t)b * nc);
    float *Z = (float *)w->prod;
    for (size_t i = 0; i < nc; i++) { /* conj(A) B */
        const float ar = A[2 * i], ai = A[2 * i + 1], br = B[2 * i], bi = B[2 * i + 1];
        Z[2 * i] = ar * br + ai * bi;
        Z[2 * i + 1] = ar * bi - ai * br;
    }
    fftwf_execute_dft_c2r(w->inv, w->prod, w->real);
}

static float corr_at(const corr_ws *w, int dy, int dx)
{
    return w->real[(size_t)pmod(dy, w->ph) * w->pw + pmod(dx, w->pw)] /
           (float)((size_t)w->ph * w->pw);
}

lm_status lm_coding_stats_compute(const lm_coding_data *d, int K, lm_coding_stats *st,
                                  lm_err *err)
{
    memset(st, 0, sizeof *st);
    if (K < 3 || K > 15 || K % 2 == 0)
        return lm_err_set(err, LM_ERR_ARG, "coding: window %d must be odd, 3..15", K);
    const int L = d->nleds, D = 2 * K - 1, r = K / 2, M = K - 1;
    st->K = K, st->nleds = L, st->D = D;
    st->R = calloc((size_t)D * D * L * L, sizeof(double));
    st->Q = calloc((size_t)K * K * L * NB, sizeof(double));
    if (!st->R || !st->Q) {
        lm_coding_stats_free(st);
        return lm_err_set(err, LM_ERR_NOMEM, "coding: out of memory (statistics)");
    }
    double mu[LM_SYSTEM_MAX_LEDS] = {0}, yb[NB] = {0}, yy = 0, npx = 0;
    lm_status s = LM_OK;
    for (int i = 0; !s && i < d->nscenes; i++) {
        const lm_coding_scene *sc = &d->scenes[i];
        const int H = sc->height, W = sc->width;
        if (sc->split != LM_SPLIT_TRAIN || H <= 2 * K || W <= 2 * K) continue;
        const size_t n = (size_t)H * W;
        corr_ws w;
        s = corr_init(&w, H, W, K, L, err);
        for (int k = 0; !s && k < L + NB; k++)
            corr_spectrum(&w, k < L ? sc->u + (size_t)k * n : sc->y + (size_t)(k - L) * n, H,
                          W, k);
        for (int l = 0; !s && l < L; l++)
            for (int m = l; m < L; m++) {
                corr_pair(&w, l, m); /* sum U_l(x) U_m(x + D) */
                for (int dy = -M; dy <= M; dy++)
                    for (int dx = -M; dx <= M; dx++) {
                        double v = corr_at(&w, dy, dx);
                        size_t o = (size_t)(dy + M) * D + (dx + M);
                        st->R[(o * L + l) * L + m] += v;
                        if (m != l) { /* R_ml(D) = R_lm(-D) */
                            size_t o2 = (size_t)(-dy + M) * D + (-dx + M);
                            st->R[(o2 * L + m) * L + l] += v;
                        }
                    }
            }
        for (int c = 0; !s && c < NB; c++)
            for (int l = 0; l < L; l++) {
                corr_pair(&w, L + c, l); /* sum y_c(x) U_l(x + d) */
                for (int dy = -r; dy <= r; dy++)
                    for (int dx = -r; dx <= r; dx++)
                        st->Q[(((size_t)(dy + r) * K + (dx + r)) * L + l) * NB + c] +=
                            corr_at(&w, dy, dx);
            }
        for (int l = 0; !s && l < L; l++)
            for (size_t j = 0; j < n; j++) mu[l] += sc->u[(size_t)l * n + j];
        for (int c = 0; !s && c < NB; c++)
            for (size_t j = 0; j < n; j++) {
                double v = sc->y[(size_t)c * n + j];
                yb[c] += v, yy += v * v;
            }
        npx += (double)(H + 2 * r) * (W + 2 * r); /* the window centres that see the scene */
        corr_free(&w);
    }
    if (!s && npx == 0)
        s = lm_err_set(err, LM_ERR_ARG, "coding: no training scene larger than %d x %d", 2 * K,
                       2 * K);
    if (!s) {
        for (size_t q = 0; q < (size_t)D * D * L * L; q++) st->R[q] /= npx;
        for (size_t q = 0; q < (size_t)K * K * L * NB; q++) st->Q[q] /= npx;
        for (int l = 0; l < L; l++) st->mu[l] = mu[l] / npx;
        for (int c = 0; c < NB; c++) st->ybar[c] = yb[c] / npx;
        st->yy = yy / npx;
        st->pixels = npx;
        double diag = 0;
        for (int l = 0; l < L; l++) diag += st->R[((size_t)(M * D + M) * L + l) * L + l] / L;
        st->ridge = 1e-6 * diag;
    }
    if (s) lm_coding_stats_free(st);
    return s;
}

/* ---- the objective ----------------------------------------------------------------------- */

/* One tile phase (py, px): its error and (g non-NULL) gradient contributions per LED scale. */
static int phase_objective(const lm_coding_stats *st, const lm_coding *c, const double *scale,
                           const lm_coding_noise *nz, int py, int px, double *err_out, double *g,
                           double *work)
{
    const int K = st->K, L = st->nleds, D = st->D, r = K / 2, M = K - 1, F = K * K, F1 = F + 1;
    double *Mh = work, *A = Mh + (size_t)F1 * F1, *B = A + (size_t)F1 * F1;
    double *Bh = B + (size_t)F1 * NB, *Wt = Bh + (size_t)F1 * NB, *SW = Wt + (size_t)F1 * NB;
    double *MSW = SW + (size_t)F1 * NB;
    int led[15 * 15], oy[15 * 15], ox[15 * 15];
    double s[15 * 15 + 1];
    for (int j = 0; j < F; j++) {
        oy[j] = j / K - r, ox[j] = j % K - r;
        led[j] = c->tile_led[pmod(py + oy[j], c->rows) * c->cols + pmod(px + ox[j], c->cols)];
        s[j] = scale[led[j]];
    }
    s[F] = 1.0;
    const double inv_ph = 1.0 / nz->photons, rn = nz->read_noise / nz->photons;
    for (int j = 0; j < F; j++) {
        for (int k = 0; k < F; k++) {
            size_t o = (size_t)(oy[k] - oy[j] + M) * D + (ox[k] - ox[j] + M);
            Mh[(size_t)j * F1 + k] = st->R[(o * L + led[j]) * L + led[k]];
        }
        Mh[(size_t)j * F1 + F] = Mh[(size_t)F * F1 + j] = st->mu[led[j]];
        size_t q = ((size_t)(oy[j] + r) * K + (ox[j] + r)) * L + led[j];
        for (int ch = 0; ch < NB; ch++) Bh[(size_t)j * NB + ch] = st->Q[q * NB + ch];
    }
    Mh[(size_t)F * F1 + F] = 1.0;
    for (int ch = 0; ch < NB; ch++) Bh[(size_t)F * NB + ch] = st->ybar[ch];
    for (int j = 0; j < F1; j++) {
        for (int k = 0; k < F1; k++) A[(size_t)j * F1 + k] = s[j] * s[k] * Mh[(size_t)j * F1 + k];
        if (j < F) /* noise (expected variance) and ridge */
            A[(size_t)j * F1 + j] += s[j] * st->mu[led[j]] * inv_ph + rn * rn + st->ridge;
        for (int ch = 0; ch < NB; ch++) B[(size_t)j * NB + ch] = s[j] * Bh[(size_t)j * NB + ch];
    }
    if (lm_cholesky(A, F1)) return -1;
    memcpy(Wt, B, sizeof(double) * (size_t)F1 * NB);
    lm_cholesky_solve(A, F1, Wt, NB);
    double tr = 0;
    for (size_t i = 0; i < (size_t)F1 * NB; i++) tr += B[i] * Wt[i];
    *err_out = st->yy - tr;
    if (!g) return 0;
    for (int j = 0; j < F1; j++) /* S W */
        for (int ch = 0; ch < NB; ch++) SW[(size_t)j * NB + ch] = s[j] * Wt[(size_t)j * NB + ch];
    memset(MSW, 0, sizeof(double) * (size_t)F1 * NB); /* M^ S W (plain loops: called from
                                                       * OpenMP threads) */
    for (int j = 0; j < F1; j++)
        for (int k = 0; k < F1; k++) {
            const double m = Mh[(size_t)j * F1 + k];
            for (int ch = 0; ch < NB; ch++) MSW[(size_t)j * NB + ch] += m * SW[(size_t)k * NB + ch];
        }
    for (int j = 0; j < F; j++) {
        double t = 0, w2 = 0;
        for (int ch = 0; ch < NB; ch++) {
            const double w = Wt[(size_t)j * NB + ch];
            t += w * (-2.0 * Bh[(size_t)j * NB + ch] + 2.0 * MSW[(size_t)j * NB + ch]);
            w2 += w * w;
        }
        g[led[j]] += t + st->mu[led[j]] * inv_ph * w2;
    }
    return 0;
}

static size_t phase_work(const lm_coding_stats *st)
{
    const size_t F1 = (size_t)st->K * st->K + 1;
    return 2 * F1 * F1 + 5 * F1 * NB;
}

double lm_coding_objective(const lm_coding_stats *st, const lm_coding *c, const double *paper,
                           const lm_coding_noise *nz, double *grad)
{
    const int P = c->rows * c->cols, L = st->nleds;
    double scale[LM_SYSTEM_MAX_LEDS], errs[LM_SYSTEM_MAX_TILE];
    double gp[LM_SYSTEM_MAX_TILE][LM_SYSTEM_MAX_LEDS];
    int bad = 0;
    for (int l = 0; l < L; l++) scale[l] = c->subframes[l] / paper[l];
    const size_t nw = phase_work(st);
    #pragma omp parallel reduction(+ : bad)
    {
        double *work = malloc(sizeof(double) * nw);
        #pragma omp for schedule(static)
        for (int p = 0; p < P; p++) {
            memset(gp[p], 0, sizeof gp[p]);
            if (!work || phase_objective(st, c, scale, nz, p / c->cols, p % c->cols, &errs[p],
                                         grad ? gp[p] : NULL, work))
                bad++;
        }
        free(work);
    }
    if (bad) return -1.0;
    double e = 0; /* summed in phase order: the same at any thread count */
    for (int p = 0; p < P; p++) e += errs[p];
    if (grad)
        for (int l = 0; l < L; l++) {
            double t = 0;
            for (int p = 0; p < P; p++) t += gp[p][l];
            grad[l] = t / (P * (double)NB) / paper[l]; /* d/ds_l -> d/dn_l */
        }
    return e / (P * (double)NB);
}

/* ---- the searches ------------------------------------------------------------------------ */

void lm_coding_search_default_opts(lm_coding_search_opts *o)
{
    o->adam_steps = 300;
    o->adam_lr = 0.05;
    o->anneal_steps = 1500;
    o->rounds = 2;
    o->seed = 1;
    o->verbose = 0;
}

static double paper_total(const double *paper, int L)
{
    double t = 0;
    for (int l = 0; l < L; l++) t += paper[l];
    return t;
}

/* Largest remainders: integers >= 1 summing to total, closest to x. */
static void round_alloc(const double *x, int L, int total, double *out)
{
    double rem[LM_SYSTEM_MAX_LEDS];
    int sum = 0;
    for (int l = 0; l < L; l++) {
        double v = x[l] < 1.0 ? 1.0 : x[l];
        out[l] = floor(v), rem[l] = v - out[l], sum += (int)out[l];
    }
    while (sum < total) {
        int b = 0;
        for (int l = 1; l < L; l++) if (rem[l] > rem[b]) b = l;
        out[b] += 1, rem[b] = -1, sum++;
    }
    while (sum > total) { /* the floors at 1 overshot: take from the largest */
        int b = 0;
        for (int l = 1; l < L; l++) if (out[l] > out[b]) b = l;
        if (out[b] <= 1) break; /* total < L: cannot happen for a loaded system */
        out[b] -= 1, sum--;
    }
}

typedef struct cand {
    double pred;
    int i, j;
} cand;

static int cand_cmp(const void *a, const void *b)
{
    const cand *x = a, *y = b;
    if (x->pred != y->pred) return x->pred < y->pred ? -1 : 1;
    return x->i != y->i ? x->i - y->i : x->j - y->j; /* a total order: qsort is not stable */
}

lm_status lm_coding_optimise_allocation(const lm_coding_stats *st, lm_coding *c,
                                        const double *paper, const lm_coding_noise *nz,
                                        const lm_coding_search_opts *o, lm_err *err)
{
    const int L = st->nleds;
    const double T = paper_total(paper, L);
    double th[LM_SYSTEM_MAX_LEDS], m1[LM_SYSTEM_MAX_LEDS] = {0}, m2[LM_SYSTEM_MAX_LEDS] = {0};
    double g[LM_SYSTEM_MAX_LEDS], best[LM_SYSTEM_MAX_LEDS];
    for (int l = 0; l < L; l++) th[l] = log(c->subframes[l] > 0.5 ? c->subframes[l] : 0.5);
    lm_coding trial = *c;
    double best_e = lm_coding_objective(st, c, paper, nz, NULL);
    if (best_e < 0) return lm_err_set(err, LM_ERR_NUMERIC, "coding: the start is singular");
    memcpy(best, c->subframes, sizeof best);
    for (int it = 1; it <= o->adam_steps; it++) {
        double mx = th[0], z = 0, p[LM_SYSTEM_MAX_LEDS];
        for (int l = 1; l < L; l++) mx = th[l] > mx ? th[l] : mx;
        for (int l = 0; l < L; l++) p[l] = exp(th[l] - mx), z += p[l];
        for (int l = 0; l < L; l++) p[l] /= z, trial.subframes[l] = T * p[l];
        double e = lm_coding_objective(st, &trial, paper, nz, g);
        if (e < 0) break;
        if (e < best_e) best_e = e, memcpy(best, trial.subframes, sizeof best);
        double pg = 0;
        for (int l = 0; l < L; l++) pg += p[l] * g[l];
        for (int l = 0; l < L; l++) { /* softmax chain rule, then Adam */
            double gt = T * p[l] * (g[l] - pg) / best_e; /* relative: scale-free steps */
            m1[l] = 0.9 * m1[l] + 0.1 * gt, m2[l] = 0.999 * m2[l] + 0.001 * gt * gt;
            double mh = m1[l] / (1 - pow(0.9, it)), vh = m2[l] / (1 - pow(0.999, it));
            th[l] -= o->adam_lr * mh / (sqrt(vh) + 1e-12);
        }
        if (o->verbose && (it % 50 == 0 || it == o->adam_steps))
            fprintf(stderr, "coding: allocation step %d: PSNR proxy %.3f dB\n", it,
                    -10 * log10(e));
    }
    /* integers, then single-sub-frame moves while one helps (candidates ranked by gradient) */
    round_alloc(best, L, (int)lround(T), trial.subframes);
    double e = lm_coding_objective(st, &trial, paper, nz, g);
    for (int moves = 0; e >= 0 && moves < 400; moves++) {
        cand cs[LM_SYSTEM_MAX_LEDS * LM_SYSTEM_MAX_LEDS];
        int nc = 0;
        for (int i = 0; i < L; i++) /* one sub-frame from i to j: first-order change g_j - g_i */
            for (int j = 0; j < L; j++)
                if (i != j && trial.subframes[i] >= 2)
                    cs[nc++] = (cand){g[j] - g[i], i, j};
        qsort(cs, (size_t)nc, sizeof *cs, cand_cmp);
        if (nc > 16) nc = 16;
        double be = e;
        int bi = -1;
        for (int k = 0; k < nc; k++) {
            lm_coding t2 = trial;
            t2.subframes[cs[k].i] -= 1, t2.subframes[cs[k].j] += 1;
            double e2 = lm_coding_objective(st, &t2, paper, nz, NULL);
            if (e2 >= 0 && e2 < be) be = e2, bi = k;
        }
        if (bi < 0) break;
        trial.subframes[cs[bi].i] -= 1, trial.subframes[cs[bi].j] += 1;
        e = lm_coding_objective(st, &trial, paper, nz, g);
    }
    if (e < 0) return lm_err_set(err, LM_ERR_NUMERIC, "coding: a system became singular");
    if (o->verbose)
        fprintf(stderr, "coding: integer allocation: PSNR proxy %.3f dB\n", -10 * log10(e));
    memcpy(c->subframes, trial.subframes, sizeof c->subframes);
    return LM_OK;
}

lm_status lm_coding_optimise_map(const lm_coding_stats *st, lm_coding *c, const double *paper,
                                 const lm_coding_noise *nz, const lm_coding_search_opts *o,
                                 lm_err *err)
{
    const int P = c->rows * c->cols;
    lm_rng r;
    lm_rng_seed(&r, o->seed ^ 0x636f64696e67ULL); /* "coding" */
    for (int round = 0; round < o->rounds; round++) {
        lm_coding cur = *c, best = *c;
        double e = lm_coding_objective(st, &cur, paper, nz, NULL), be = e;
        if (e < 0) return lm_err_set(err, LM_ERR_NUMERIC, "coding: the start is singular");
        const double t0 = 0.003 * e, t1 = 1e-5 * e;
        for (int it = 0; it < o->anneal_steps && P > 1; it++) {
            const double T = t0 * pow(t1 / t0, (double)it / (o->anneal_steps > 1 ? o->anneal_steps - 1 : 1));
            int a = (int)(lm_rng_uniform(&r) * P) % P, b = (int)(lm_rng_uniform(&r) * P) % P;
            float u = lm_rng_uniform(&r);
            if (cur.tile_led[a] == cur.tile_led[b]) continue;
            lm_coding t = cur;
            t.tile_led[a] = cur.tile_led[b], t.tile_led[b] = cur.tile_led[a];
            double e2 = lm_coding_objective(st, &t, paper, nz, NULL);
            if (e2 < 0) continue;
            if (e2 < e || u < exp(-(e2 - e) / T)) {
                cur = t, e = e2;
                if (e < be) best = cur, be = e;
            }
        }
        if (o->verbose)
            fprintf(stderr, "coding: map round %d: PSNR proxy %.3f dB\n", round + 1,
                    -10 * log10(be));
        *c = best;
        lm_status s = lm_coding_optimise_allocation(st, c, paper, nz, o, err);
        if (s) return s;
    }
    return LM_OK;
}

/* ---- real-scene validation ---------------------------------------------------------------- */

/* Coded clean frame of scene sc under coding c (origin on the tile grid). */
static void coded_frame(const lm_coding_scene *sc, const lm_coding *c, const double *paper,
                        float *out)
{
    const int H = sc->height, W = sc->width;
    const size_t n = (size_t)H * W;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            int l = c->tile_led[(y % c->rows) * c->cols + x % c->cols];
            out[(size_t)y * W + x] =
                (float)(c->subframes[l] / paper[l]) * sc->u[(size_t)l * n + (size_t)y * W + x];
        }
}

#define CHUNK 1024

lm_status lm_coding_validate(const lm_coding_data *d, int K, const lm_coding *c,
                             const double *paper, const lm_coding_noise *nz, uint64_t seed,
                             double *psnr, double *val, double *test, double *fit_mse,
                             lm_err *err)
{
    const int P = c->rows * c->cols, F = K * K, F1 = F + 1, r = K / 2;
    double *A = calloc((size_t)P * F1 * F1, sizeof(double));
    double *B = calloc((size_t)P * F1 * NB, sizeof(double)), cnt[LM_SYSTEM_MAX_TILE] = {0};
    double yy[LM_SYSTEM_MAX_TILE] = {0}, *Ac = malloc(sizeof(double) * (size_t)F1 * F1);
    double fit_se = 0, fit_n = 0;
    double *X = malloc(sizeof(double) * CHUNK * F1), *Y = malloc(sizeof(double) * CHUNK * NB);
    double *Wt = malloc(sizeof(double) * (size_t)P * F1 * NB);
    int maxn = 0;
    for (int i = 0; i < d->nscenes; i++)
        if (d->scenes[i].height * d->scenes[i].width > maxn)
            maxn = d->scenes[i].height * d->scenes[i].width;
    float *frame = malloc(sizeof(float) * (size_t)maxn);
    lm_status st = A && B && X && Y && Wt && frame && Ac ? LM_OK
                   : lm_err_set(err, LM_ERR_NOMEM, "coding: out of memory (validation)");
    /* normal equations per phase over every interior pixel of the training scenes */
    for (int i = 0; !st && i < d->nscenes; i++) {
        const lm_coding_scene *sc = &d->scenes[i];
        const int H = sc->height, W = sc->width;
        const size_t n = (size_t)H * W;
        if (sc->split != LM_SPLIT_TRAIN || H <= K || W <= K) continue;
        coded_frame(sc, c, paper, frame);
        for (int p = 0; p < P; p++) {
            const int py = p / c->cols, px = p % c->cols;
            int rows = 0;
            for (int y = r + pmod(py - r, c->rows); y < H - r; y += c->rows)
                for (int x = r + pmod(px - r, c->cols); x < W - r; x += c->cols) {
                    double *f = X + (size_t)rows * F1;
                    for (int u = 0; u < K; u++)
                        for (int v = 0; v < K; v++)
                            f[u * K + v] = frame[(size_t)(y + u - r) * W + (x + v - r)];
                    f[F] = 1.0;
                    for (int ch = 0; ch < NB; ch++) {
                        const double t = sc->y[(size_t)ch * n + (size_t)y * W + x];
                        Y[(size_t)rows * NB + ch] = t;
                        yy[p] += t * t;
                    }
                    if (++rows == CHUNK) {
                        cblas_dsyrk(CblasRowMajor, CblasUpper, CblasTrans, F1, rows, 1.0, X, F1,
                                    1.0, A + (size_t)p * F1 * F1, F1);
                        cblas_dgemm(CblasRowMajor, CblasTrans, CblasNoTrans, F1, NB, rows, 1.0,
                                    X, F1, Y, NB, 1.0, B + (size_t)p * F1 * NB, NB);
                        cnt[p] += rows;
                        rows = 0;
                    }
                }
            if (rows) {
                cblas_dsyrk(CblasRowMajor, CblasUpper, CblasTrans, F1, rows, 1.0, X, F1, 1.0,
                            A + (size_t)p * F1 * F1, F1);
                cblas_dgemm(CblasRowMajor, CblasTrans, CblasNoTrans, F1, NB, rows, 1.0, X, F1,
                            Y, NB, 1.0, B + (size_t)p * F1 * NB, NB);
                cnt[p] += rows;
            }
        }
    }
    /* solve: means, the noise's expected variance on the diagonal, a small ridge */
    const double inv_ph = 1.0 / nz->photons, rn = nz->read_noise / nz->photons;
    for (int p = 0; !st && p < P; p++) {
        double *Ap = A + (size_t)p * F1 * F1, *Bp = B + (size_t)p * F1 * NB;
        if (!(cnt[p] > 0)) {
            st = lm_err_set(err, LM_ERR_ARG, "coding: no training pixels for phase %d", p);
            break;
        }
        for (int j = 0; j < F1; j++)
            for (int k = j; k < F1; k++)
                Ap[(size_t)k * F1 + j] = Ap[(size_t)j * F1 + k] /= cnt[p];
        for (size_t q = 0; q < (size_t)F1 * NB; q++) Bp[q] /= cnt[p];
        double diag = 0;
        for (int j = 0; j < F; j++) diag += Ap[(size_t)j * F1 + j] / F;
        for (int j = 0; j < F; j++)
            Ap[(size_t)j * F1 + j] += Ap[(size_t)j * F1 + F] * inv_ph + rn * rn;
        memcpy(Ac, Ap, sizeof(double) * (size_t)F1 * F1); /* for the fit's own error */
        for (int j = 0; j < F; j++) Ap[(size_t)j * F1 + j] += 1e-6 * diag;
        if (lm_cholesky(Ap, F1)) {
            st = lm_err_set(err, LM_ERR_NUMERIC, "coding: phase %d's normal equations are "
                            "singular", p);
            break;
        }
        const double *w = Wt + (size_t)p * F1 * NB;
        memcpy(Wt + (size_t)p * F1 * NB, Bp, sizeof(double) * (size_t)F1 * NB);
        lm_cholesky_solve(Ap, F1, Wt + (size_t)p * F1 * NB, NB);
        /* expected training error: E|y|^2 - 2 tr(W^T B) + tr(W^T A W) (noise included) */
        double e = yy[p] / cnt[p];
        for (int j = 0; j < F1; j++)
            for (int ch = 0; ch < NB; ch++) {
                double aw = 0;
                for (int k = 0; k < F1; k++) aw += Ac[(size_t)j * F1 + k] * w[(size_t)k * NB + ch];
                e += w[(size_t)j * NB + ch] * (aw - 2 * Bp[(size_t)j * NB + ch]);
            }
        fit_se += e * cnt[p], fit_n += cnt[p] * NB;
    }
    if (fit_mse) *fit_mse = fit_n > 0 ? fit_se / fit_n : NAN;
    /* score the validation and test scenes with drawn noise */
    double sum[3] = {0}, num[3] = {0};
    for (int i = 0; !st && i < d->nscenes; i++) {
        const lm_coding_scene *sc = &d->scenes[i];
        const int H = sc->height, W = sc->width;
        const size_t n = (size_t)H * W;
        psnr[i] = NAN;
        if (sc->split == LM_SPLIT_TRAIN || H <= K || W <= K) continue;
        coded_frame(sc, c, paper, frame);
        lm_noise_opts no = {0};
        no.photons = nz->photons, no.read_noise = (float)nz->read_noise, no.full_scale = 1.0f;
        lm_rng rng;
        lm_rng_seed(&rng, seed * 0x9E3779B97F4A7C15ULL + (uint64_t)i);
        if ((st = lm_forward_noise(frame, H, W, &no, &rng, 1, err))) break;
        double se = 0;
        long m = 0;
        #pragma omp parallel for schedule(static) reduction(+ : se, m)
        for (int y = r; y < H - r; y++) {
            double f[15 * 15 + 1];
            for (int x = r; x < W - r; x++) {
                const int p = (y % c->rows) * c->cols + x % c->cols;
                const double *w = Wt + (size_t)p * F1 * NB;
                for (int u = 0; u < K; u++)
                    for (int v = 0; v < K; v++)
                        f[u * K + v] = frame[(size_t)(y + u - r) * W + (x + v - r)];
                f[F] = 1.0;
                for (int ch = 0; ch < NB; ch++) {
                    double e = 0;
                    for (int j = 0; j < F1; j++) e += f[j] * w[(size_t)j * NB + ch];
                    e -= sc->y[(size_t)ch * n + (size_t)y * W + x];
                    se += e * e;
                }
                m += NB;
            }
        }
        psnr[i] = 10 * log10((double)m / se);
        sum[sc->split] += psnr[i], num[sc->split] += 1;
    }
    *val = num[LM_SPLIT_VAL] ? sum[LM_SPLIT_VAL] / num[LM_SPLIT_VAL] : NAN;
    *test = num[LM_SPLIT_TEST] ? sum[LM_SPLIT_TEST] / num[LM_SPLIT_TEST] : NAN;
    free(A), free(B), free(X), free(Y), free(Wt), free(frame), free(Ac);
    return st;
}

lm_status lm_coding_write_system(const lm_system *sys, const lm_coding *c, const char *name,
                                 const char *note, const char *out_path, lm_err *err)
{
    double gains[LM_SYSTEM_MAX_LEDS];
    int sub[LM_SYSTEM_MAX_LEDS];
    for (int l = 0; l < sys->nleds; l++) {
        gains[l] = sys->leds[l].gain;
        sub[l] = (int)lround(c->subframes[l]);
        if (sub[l] < 1 || fabs(c->subframes[l] - sub[l]) > 1e-9)
            return lm_err_set(err, LM_ERR_ARG, "coding: LED %s has %g sub-frames; a system "
                              "needs a positive integer", sys->leds[l].name, c->subframes[l]);
    }
    if (c->rows != sys->tile_rows || c->cols != sys->tile_cols)
        return lm_err_set(err, LM_ERR_ARG, "coding: tile %dx%d, the system's %dx%d", c->rows,
                          c->cols, sys->tile_rows, sys->tile_cols);
    lm_system_edit ed = {.gains = gains, .subframes = sub, .tile_led = c->tile_led,
                         .name = name, .note = note};
    return lm_system_write_edit(sys, &ed, out_path, err);
}

/* forward.c — static coded-frame simulation (closed form per tile phase) and sensor noise.
 * What it is: per-row weight tables (one per tile row phase: nbins x width floats for each
 * bucket) so that the inner loop is a plain multiply-add over a row; OpenMP over rows, fixed
 * per-pixel summation order (bins in order), per-row random streams.
 * What it is not: the per-sub-frame sum (that is the tests' reference) or motion. */
#include "data/forward.h"
#include "data/spectra.h"
#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

static int threads_of(int nthreads) { return nthreads > 0 ? nthreads : omp_get_max_threads(); }

static lm_status check_cube(const lm_system *s, const lm_cube *c, int y0, int x0, lm_err *err)
{
    if (!c->data || c->height < 1 || c->width < 1)
        return lm_err_set(err, LM_ERR_SHAPE, "forward: empty cube");
    if (c->bands != s->nbins)
        return lm_err_set(err, LM_ERR_SHAPE, "forward: cube has %d bands, the system's grid has "
                          "%d: give 31 bands on 400-700 nm (mirrored to the grid) or the grid's %d",
                          c->bands, s->nbins, s->nbins);
    for (int b = 0; b < c->bands; b++) {
        float want = s->grid_start + s->grid_step * (float)b;
        if (fabsf(c->wavelength[b] - want) > 0.01f * s->grid_step)
            return lm_err_set(err, LM_ERR_SHAPE, "forward: cube band %d is at %g nm, the system's "
                              "grid has %g nm", b, c->wavelength[b], want);
    }
    if (y0 < 0 || x0 < 0)
        return lm_err_set(err, LM_ERR_ARG, "forward: negative sensor offset (%d, %d)", y0, x0);
    return LM_OK;
}

/* tab[(ty * nbins + b) * W + x] = weight of bin b at column x of a row with tile-row phase ty:
 * a_{l} (bucket 1) or the sum of the other LEDs' a (bucket 0), l = LED of that tile phase. */
static void weight_tables(const lm_system *s, int x0, int W, float *tab1, float *tab0)
{
    int nb = s->nbins;
    double *total = calloc((size_t)nb, sizeof(double));
    if (total)
        for (int l = 0; l < s->nleds; l++)
            for (int b = 0; b < nb; b++) total[b] += s->leds[l].response[b];
    for (int ty = 0; ty < s->tile_rows; ty++)
        for (int x = 0; x < W; x++) {
            int l = s->tile_led[ty * s->tile_cols + (x + x0) % s->tile_cols];
            const float *a = s->leds[l].response;
            for (int b = 0; b < nb; b++) {
                size_t i = ((size_t)ty * nb + b) * W + x;
                tab1[i] = a[b];
                if (tab0) tab0[i] = total ? (float)(total[b] - a[b]) : 0.0f;
            }
        }
    free(total);
}

/* out[x] = sum_b tab[b * W + x] * band_b_row[x], b in order. Returns 1 if any out is not finite. */
static int row_dot(const lm_cube *c, int y, const float *tab, int nb, float *out)
{
    int W = c->width;
    size_t plane = (size_t)c->height * W;
    const float *r = c->data + (size_t)y * W;
    for (int x = 0; x < W; x++) out[x] = 0.0f;
    for (int b = 0; b < nb; b++) {
        const float *rb = r + b * plane, *wb = tab + (size_t)b * W;
        for (int x = 0; x < W; x++) out[x] += wb[x] * rb[x];
    }
    int bad = 0;
    for (int x = 0; x < W; x++) bad |= !isfinite(out[x]);
    return bad;
}

lm_status lm_forward_clean(const lm_system *sys, const lm_cube *cube, int y0, int x0,
                           float *bucket1, float *bucket0, int nthreads, lm_err *err)
{
    lm_status st = check_cube(sys, cube, y0, x0, err);
    if (st != LM_OK) return st;
    int H = cube->height, W = cube->width, nb = sys->nbins;
    size_t tab_n = (size_t)sys->tile_rows * nb * W;
    float *tab1 = malloc(tab_n * sizeof(float));
    float *tab0 = bucket0 ? malloc(tab_n * sizeof(float)) : NULL;
    if (!tab1 || (bucket0 && !tab0)) {
        free(tab1);
        free(tab0);
        return lm_err_set(err, LM_ERR_NOMEM, "forward: out of memory (%d x %d frame)", H, W);
    }
    weight_tables(sys, x0, W, tab1, tab0);
    int bad = 0;
#pragma omp parallel for schedule(static) num_threads(threads_of(nthreads)) reduction(| : bad)
    for (int y = 0; y < H; y++) {
        size_t t = (size_t)((y + y0) % sys->tile_rows) * nb * W;
        bad |= row_dot(cube, y, tab1 + t, nb, bucket1 + (size_t)y * W);
        if (tab0) bad |= row_dot(cube, y, tab0 + t, nb, bucket0 + (size_t)y * W);
    }
    free(tab1);
    free(tab0);
    if (bad)
        return lm_err_set(err, LM_ERR_NUMERIC, "forward: the cube holds NaN or infinite values");
    return LM_OK;
}

/* ---- noise ------------------------------------------------------------------------------- */
static double unif53(lm_rng *r)
{
    return (double)(lm_rng_u64(r) >> 11) * (1.0 / 9007199254740992.0);
}

/* Hormann (1993), "The transformed rejection method for generating Poisson random variables"
 * (PTRS), valid for lambda >= 10. */
static double poisson_ptrs(lm_rng *r, double lam)
{
    double slam = sqrt(lam), loglam = log(lam);
    double b = 0.931 + 2.53 * slam, a = -0.059 + 0.02483 * b;
    double invalpha = 1.1239 + 1.1328 / (b - 3.4), vr = 0.9277 - 3.6224 / (b - 2.0);
    for (;;) {
        double u = unif53(r) - 0.5, v = unif53(r), us = 0.5 - fabs(u);
        double k = floor((2.0 * a / us + b) * u + lam + 0.43);
        if (us >= 0.07 && v <= vr) return k;
        if (k < 0.0 || (us < 0.013 && v > us)) continue;
        int sg;
        if (log(v) + log(invalpha) - log(a / (us * us) + b) <=
            -lam + k * loglam - lgamma_r(k + 1.0, &sg))
            return k;
    }
}

double lm_forward_poisson(lm_rng *r, double lambda)
{
    if (!(lambda > 0.0)) return 0.0;
    if (lambda >= 10.0) return poisson_ptrs(r, lambda);
    double limit = exp(-lambda), prod = unif53(r);
    double k = 0.0;
    while (prod > limit) {
        prod *= unif53(r);
        k += 1.0;
    }
    return k;
}

static lm_status check_noise(const lm_noise_opts *o, const lm_rng *rng, lm_err *err)
{
    if (!(o->gauss_k >= 0.0f) || !isfinite(o->gauss_k) || !(o->photons >= 0.0) ||
        !isfinite(o->photons) || !(o->read_noise >= 0.0f) || !isfinite(o->read_noise) ||
        !(o->full_scale >= 0.0f) || !isfinite(o->full_scale))
        return lm_err_set(err, LM_ERR_ARG, "forward: noise options must be finite and >= 0 "
                          "(gauss_k %g, photons %g, read_noise %g, full_scale %g)", o->gauss_k,
                          o->photons, o->read_noise, o->full_scale);
    if (o->bits < 0 || o->bits > 24)
        return lm_err_set(err, LM_ERR_ARG, "forward: quantisation bits %d outside 0..24", o->bits);
    int random = o->gauss_k > 0.0f || o->photons > 0.0 || o->read_noise > 0.0f;
    if (random && !rng)
        return lm_err_set(err, LM_ERR_ARG, "forward: noise requested without a random generator");
    return LM_OK;
}

static float image_max(const float *img, long n, int nt)
{
    float m = 0.0f;
#pragma omp parallel for schedule(static) num_threads(nt) reduction(max : m)
    for (long i = 0; i < n; i++)
        if (img[i] > m) m = img[i];
    return m;
}

/* Steps 1-6 of lm_noise_opts on one row, drawing from r. */
static void noise_row(float *v, int W, const lm_noise_opts *o, float fs, float gauss_sd,
                      lm_rng *r)
{
    double per_e = o->photons > 0.0 ? fs / o->photons : 0.0; /* signal per electron */
    float read_sd = o->read_noise * (o->photons > 0.0 ? (float)per_e : fs);
    float levels = o->bits > 0 ? (float)((1L << o->bits) - 1) : 0.0f;
    for (int x = 0; x < W; x++) {
        float y = v[x];
        if (o->photons > 0.0) y = (float)(lm_forward_poisson(r, y / per_e) * per_e);
        if (o->clip && y > fs) y = fs;
        if (read_sd > 0.0f) y += read_sd * lm_rng_normal(r);
        if (gauss_sd > 0.0f) y += gauss_sd * lm_rng_normal(r);
        if (o->clip) y = y < 0.0f ? 0.0f : (y > fs ? fs : y);
        if (levels > 0.0f) {
            float q = roundf(y / fs * levels);
            q = q < 0.0f ? 0.0f : (q > levels ? levels : q);
            y = q * fs / levels;
        }
        v[x] = y;
    }
}

lm_status lm_forward_noise(float *img, int height, int width, const lm_noise_opts *o,
                           lm_rng *rng, int nthreads, lm_err *err)
{
    lm_status st = check_noise(o, rng, err);
    if (st != LM_OK) return st;
    if (height < 1 || width < 1)
        return lm_err_set(err, LM_ERR_ARG, "forward: noise on an empty %d x %d image", height,
                          width);
    int nt = threads_of(nthreads);
    float fs = o->full_scale > 0.0f ? o->full_scale : 1.0f;
    float gauss_sd = o->gauss_k > 0.0f ? o->gauss_k * image_max(img, (long)height * width, nt)
                                       : 0.0f;
    lm_rng base;
    memset(&base, 0, sizeof base);
    if (rng) {
        base = *rng;
        lm_rng_u64(rng); /* the next call draws from different streams */
    }
#pragma omp parallel for schedule(static) num_threads(nt)
    for (int y = 0; y < height; y++) {
        lm_rng r = lm_rng_split(&base, (uint64_t)y);
        noise_row(img + (size_t)y * width, width, o, fs, gauss_sd, &r);
    }
    return LM_OK;
}

/* ---- whole simulation -------------------------------------------------------------------- */
lm_noise_opts lm_forward_bucket0_noise(const lm_noise_opts *o, int nleds)
{
    lm_noise_opts b = *o;
    const float f = nleds > 1 ? (float)(nleds - 1) : 1.0f;
    b.full_scale = (o->full_scale > 0.0f ? o->full_scale : 1.0f) * f;
    b.photons = o->photons * f;
    if (!(o->photons > 0.0)) b.read_noise = o->read_noise / f; /* a fraction of the full scale */
    return b;
}

lm_status lm_forward_simulate(const lm_system *sys, const lm_cube *cube,
                              const lm_forward_opts *o, lm_rng *rng, float *bucket1,
                              float *bucket0, lm_err *err)
{
    lm_status st = lm_forward_clean(sys, cube, o->y0, o->x0, bucket1, bucket0, o->nthreads, err);
    if (st == LM_OK)
        st = lm_forward_noise(bucket1, cube->height, cube->width, &o->noise, rng, o->nthreads,
                              err);
    lm_noise_opts n0 = lm_forward_bucket0_noise(&o->noise, sys->nleds);
    if (st == LM_OK && bucket0)
        st = lm_forward_noise(bucket0, cube->height, cube->width, &n0, rng, o->nthreads, err);
    return st;
}

lm_status lm_forward_simulate31(const lm_system *sys, const lm_cube *cube31,
                                const lm_forward_opts *o, lm_rng *rng, float *bucket1,
                                float *bucket0, lm_err *err)
{
    lm_cube c41;
    lm_status st = lm_cube_mirror41(cube31, &c41, err);
    if (st != LM_OK) return st;
    st = lm_forward_simulate(sys, &c41, o, rng, bucket1, bucket0, err);
    lm_cube_free(&c41);
    return st;
}

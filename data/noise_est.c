/* noise_est.c — blind Gaussian noise estimate of a raw mosaic frame (see noise_est.h).
 * What it is: three passes over the frame — a scan (finite check, min/max, largest 2 x 2
 * same-phase mean), a histogram of the texture score of every interior pixel (fixes the score
 * thresholds of the nested darkest sets), and the residual pass that files each |r| into a
 * log-spaced histogram of its shell — then the sequential pooling of shells on the histograms.
 * The two passes over the residuals run on OpenMP threads, each filling its own histograms;
 * every histogram holds integers (counts, and each bin's sum of r^2 in fixed point relative to
 * the bin's lower edge: r^2 / edge^2 is in [1, 1.07), kept to 2^-32), so the merge is exact and
 * the estimate does not depend on the thread count.
 * What it is not: a per-pixel noise map.
 *
 * Constants: the block size, score weight, shell sizes, trimming, test level and peak rules were
 * chosen by measurement on frames simulated from the 27 CAVE scenes of $LM_SHARED_DIR/data (see
 * tests/test_noise_est.c --report); these two are derived:
 *  - NE_RSE: relative standard deviation of a variance estimate from n residuals is
 *    NE_RSE / sqrt(n). For the mean of r^2 over a contiguous region of the Laplacian residual
 *    field it is sqrt(2 * sum of squared correlations) = sqrt(2 * (1 + 2 (4/6)^2 + 2 (1/6)^2)^2)
 *    = 2.75 (neighbouring residuals share pixels: correlation -2/3 at lag 1, 1/6 at lag 2).
 *  - NE_TRIM_M2 = E[Z^2 | |Z| < c] with P(|Z| < c) = NE_TRIM = 0.9, c = 1.6448536:
 *    1 - 2 c phi(c) / 0.9 = 0.6230173, so the trimmed moment is unbiased for Gaussian noise. */
#include "data/noise_est.h"
#include <math.h>
#include <omp.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#define NE_SHELLS 5          /* darkest 1/16, then shells up to 1/8, 1/4, 1/2, all */
#define NE_SCORE_BINS 16384  /* texture-score histogram over [frame min, frame max] */
#define NE_OCT_BINS 32       /* |r| histogram: bins per octave (mantissa's top 5 bits) */
#define NE_OCTAVES 40        /* |r| / frame range in [2^-36, 2^4); below goes to bin 0 */
#define NE_RBINS (1 + NE_OCT_BINS * NE_OCTAVES)
#define NE_MIN_SAMPLES 512   /* the first pool holds at least this many residuals */
#define NE_GRAD_WEIGHT 2.0f  /* texture score = mean + 2 (|gx| + |gy|) */
#define NE_TRIM 0.9
#define NE_TRIM_M2 0.6230173
#define NE_RSE 2.75
#define NE_Z 2.0             /* a shell joins the pool unless 2 standard errors above it */
#define NE_PEAK_SWITCH 0.02f /* sigma / max below this: peak from the raw maximum */
#define NE_NARROW 3.0f       /* max - largest 2 x 2 mean above 3 sigma: a narrow maximum, */
#define NE_NARROW_MAX 0.06f  /* trusted only while sigma < 6 % of the frame maximum */

#define NE_FIX 4294967296.0 /* 2^32: fixed-point unit of (|r| / bin edge)^2 */

typedef struct ne_hist {
    long n;
    long count[NE_RBINS];
    int64_t sum[NE_RBINS]; /* per bin: sum of (|r| r_scale / edge)^2 x 2^32 (ne_edge) */
} ne_hist;

/* Lower edge of |r| bin b in units of |r| r_scale (bin 0: everything below 2^-36). */
static double ne_edge(int b)
{
    if (b == 0) return ldexp(1.0, -36);
    int oct = (b - 1) / NE_OCT_BINS, m = (b - 1) % NE_OCT_BINS;
    return ldexp(1.0 + (double)m / NE_OCT_BINS, oct - 36);
}

typedef struct ne_frame {
    const float *raw;
    int height, width, th, tw;
    float lo, hi;     /* frame min and max */
    float box_max;    /* largest 2 x 2 same-phase mean */
    float score_lo, score_scale; /* score bin = (score - score_lo) * score_scale */
    float r_scale;    /* |r| is binned as |r| * r_scale (1 / frame range) */
    int floor_on;     /* the frame is clipped at its minimum (a sensor or file floor) */
    float floor_mean; /* then windows touching the floor, or darker than this, are left out */
} ne_frame;

/* One interior row y (x = tile_w .. width - tile_w - 1, n values): the residual r of each 3 x 3
 * same-phase window (the Laplacian-like mask / 6: std sigma for white noise) and the score bin
 * of its texture predictor, window mean + 2 (|Sobel x| + |Sobel y|) / 8. Mean and Sobel masks
 * are orthogonal to the residual's, hence independent of its noise. Writes r[n], sb[n]. */
static void ne_row(const ne_frame *f, int y, float *r, int *sb)
{
    const float *c = f->raw + (long)y * f->width + f->tw;
    const long sy = (long)f->th * f->width, sx = f->tw;
    const int n = f->width - 2 * f->tw;
    const float lo = f->score_lo, scale = f->score_scale, top = NE_SCORE_BINS - 1;
#pragma omp simd
    for (int i = 0; i < n; i++) {
        const float *q = c + i;
        float a00 = q[-sy - sx], a01 = q[-sy], a02 = q[-sy + sx];
        float a10 = q[-sx], a11 = q[0], a12 = q[sx];
        float a20 = q[sy - sx], a21 = q[sy], a22 = q[sy + sx];
        float t = a00 - 2 * a01 + a02, m = a10 - 2 * a11 + a12, b = a20 - 2 * a21 + a22;
        r[i] = (t - 2 * m + b) * (1.0f / 6);
        float mean = (a00 + a01 + a02 + a10 + a11 + a12 + a20 + a21 + a22) * (1.0f / 9);
        float gx = (a02 - a00) + 2 * (a12 - a10) + (a22 - a20);
        float gy = (a20 - a00) + 2 * (a21 - a01) + (a22 - a02);
        float score = mean + NE_GRAD_WEIGHT * 0.125f * (fabsf(gx) + fabsf(gy));
        float bin = (score - lo) * scale;
        bin = bin > 0 ? bin : 0;
        sb[i] = (int)(bin < top ? bin : top);
        if (f->floor_on) { /* clipped noise is not Gaussian: keep such windows out */
#define NE_MIN(a, b) ((a) < (b) ? (a) : (b)) /* finite values: no libm call */
            float mn = NE_MIN(NE_MIN(NE_MIN(a00, a01), NE_MIN(a02, a10)),
                              NE_MIN(NE_MIN(a11, a12), NE_MIN(NE_MIN(a20, a21), a22)));
#undef NE_MIN
            if (mn <= f->lo || mean < f->floor_mean) sb[i] = -1;
        }
    }
}

/* Log-spaced bin of |r| * r_scale: octave from the float exponent, 32 steps from the mantissa's
 * top bits; below 2^-36 is bin 0, from 2^4 up the last bin. */
static inline int ne_r_bin(float v)
{
    uint32_t bits;
    memcpy(&bits, &v, sizeof bits);
    int oct = (int)((bits >> 23) & 0xff) - (127 - 36);
    int bin = 1 + oct * NE_OCT_BINS + (int)((bits >> 18) & (NE_OCT_BINS - 1));
    return oct < 0 ? 0 : oct >= NE_OCTAVES ? NE_RBINS - 1 : bin;
}

/* Pass 1: min, max and the largest 2 x 2 same-phase mean (mean of (y, x), (y, x + tile_w),
 * (y + tile_h, x), (y + tile_h, x + tile_w)). Returns the index of the first non-finite value,
 * or -1 (then f->lo, hi, box_max are set). */
static long ne_scan(ne_frame *f)
{
    const float *p = f->raw;
    const long sy = (long)f->th * f->width;
    /* eight running minima / maxima / probes, one per lane: compare-and-select loops that
     * every compiler vectorises at any instruction set (a reduction over a ternary is not
     * vectorised by clang without -ffast-math); min and max are exact in any order */
    enum { NL = 8 };
    float lo8[NL], hi8[NL], box8[NL];
    for (int l = 0; l < NL; l++) lo8[l] = hi8[l] = p[0], box8[l] = -INFINITY;
    for (int y = 0; y < f->height; y++) {
        const float *row = p + (long)y * f->width;
        float nan8[NL] = {0};
        int x = 0;
        for (; x + NL <= f->width; x += NL)
            for (int l = 0; l < NL; l++) {
                const float v = row[x + l];
                lo8[l] = v < lo8[l] ? v : lo8[l], hi8[l] = v > hi8[l] ? v : hi8[l]; /* min/max */
                nan8[l] += v * 0.0f; /* NaN if any value is NaN or inf */
            }
        for (; x < f->width; x++) {
            const float v = row[x];
            lo8[0] = v < lo8[0] ? v : lo8[0], hi8[0] = v > hi8[0] ? v : hi8[0];
            nan8[0] += v * 0.0f;
        }
        float nan_probe = 0;
        for (int l = 0; l < NL; l++) nan_probe += nan8[l];
        if (nan_probe != 0 || nan_probe != nan_probe)
            for (x = 0; x < f->width; x++)
                if (!isfinite(row[x])) return (long)y * f->width + x;
        if (y + f->th >= f->height) continue;
        const int nb = f->width - f->tw;
        x = 0;
        for (; x + NL <= nb; x += NL)
            for (int l = 0; l < NL; l++) {
                const float *q = row + x + l;
                const float v = 0.25f * (q[0] + q[f->tw] + q[sy] + q[sy + f->tw]);
                box8[l] = v > box8[l] ? v : box8[l];
            }
        for (; x < nb; x++) {
            const float *q = row + x;
            const float v = 0.25f * (q[0] + q[f->tw] + q[sy] + q[sy + f->tw]);
            box8[0] = v > box8[0] ? v : box8[0];
        }
    }
    float lo = lo8[0], hi = hi8[0], box = box8[0];
    for (int l = 1; l < NL; l++) {
        lo = lo8[l] < lo ? lo8[l] : lo, hi = hi8[l] > hi ? hi8[l] : hi;
        box = box8[l] > box ? box8[l] : box;
    }
    f->lo = lo, f->hi = hi, f->box_max = box;
    return -1;
}

/* Per-thread scratch: one row's residuals and score bins. */
typedef struct ne_rows {
    float *r;
    int *sb;
} ne_rows;

/* Pass 2: histogram of the score bins of the interior pixels (per thread, then summed). Returns
 * their count. hist_t: nthreads histograms of NE_SCORE_BINS, zeroed. */
static long ne_score_hist(const ne_frame *f, const ne_rows *rows, long *hist_t, int nthreads,
                          long *hist)
{
    const int n = f->width - 2 * f->tw;
    long used = 0;
    #pragma omp parallel num_threads(nthreads) reduction(+ : used)
    {
        const int t = omp_get_thread_num();
        float *r = rows[t].r;
        int *sb = rows[t].sb;
        long *h = hist_t + (size_t)t * NE_SCORE_BINS;
        #pragma omp for schedule(static)
        for (int y = f->th; y < f->height - f->th; y++) {
            ne_row(f, y, r, sb);
            for (int i = 0; i < n; i++)
                if (sb[i] >= 0) h[sb[i]]++, used++;
        }
    }
    for (int t = 0; t < nthreads; t++)
        for (int b = 0; b < NE_SCORE_BINS; b++) hist[b] += hist_t[(size_t)t * NE_SCORE_BINS + b];
    return used;
}

/* Last score bin of each shell but the last: shell j holds the darkest 2^(j-4) of n (whole
 * bins, so a shell may hold more, and a later one nothing). */
static void ne_thresholds(const long *hist, long n, int *last_bin)
{
    long cum = 0;
    int b = 0;
    for (int j = 0; j < NE_SHELLS - 1; j++) {
        double want = ldexp((double)n, j - (NE_SHELLS - 1));
        while (b < NE_SCORE_BINS - 1 && cum + hist[b] < want) cum += hist[b++];
        last_bin[j] = b;
    }
}

/* Pass 3: file every residual into the |r| histogram of its shell (per thread: shell_t holds
 * NE_SHELLS histograms per thread, zeroed; summed into shell). */
static void ne_residual_hist(const ne_frame *f, const int *last_bin, const ne_rows *rows,
                             ne_hist *shell_t, int nthreads, ne_hist *shell)
{
    const int n = f->width - 2 * f->tw;
    const float rs = f->r_scale;
    double inv_edge[NE_RBINS];
    for (int b = 0; b < NE_RBINS; b++) inv_edge[b] = 1.0 / ne_edge(b);
    #pragma omp parallel num_threads(nthreads)
    {
        const int t = omp_get_thread_num();
        float *r = rows[t].r;
        int *sb = rows[t].sb;
        ne_hist *sh = shell_t + (size_t)t * NE_SHELLS;
        #pragma omp for schedule(static)
        for (int y = f->th; y < f->height - f->th; y++) {
            ne_row(f, y, r, sb);
            for (int i = 0; i < n; i++) {
                if (sb[i] < 0) continue;
                int j = 0;
                for (int k = 0; k < NE_SHELLS - 1; k++) j += sb[i] > last_bin[k];
                float v = fabsf(r[i]) * rs;
                int rb = ne_r_bin(v);
                double q = v * inv_edge[rb];
                q = q < 1024.0 ? q : 1024.0; /* |r| rs <= 8/3 < 2^4: only a guard */
                sh[j].count[rb]++;
                sh[j].sum[rb] += (int64_t)(q * q * NE_FIX);
            }
        }
    }
    for (int t = 0; t < nthreads; t++)
        for (int j = 0; j < NE_SHELLS; j++) {
            const ne_hist *h = shell_t + (size_t)t * NE_SHELLS + j;
            for (int b = 0; b < NE_RBINS; b++)
                shell[j].count[b] += h->count[b], shell[j].sum[b] += h->sum[b];
        }
    for (int j = 0; j < NE_SHELLS; j++)
        for (int b = 0; b < NE_RBINS; b++) shell[j].n += shell[j].count[b];
}

static void ne_hist_add(ne_hist *to, const ne_hist *h)
{
    to->n += h->n;
    for (int b = 0; b < NE_RBINS; b++) to->count[b] += h->count[b], to->sum[b] += h->sum[b];
}

/* sigma^2 from the smallest NE_TRIM of the |r| in h (a partial last bin counts pro rata), in
 * units of (r r_scale)^2. */
static double ne_trimmed_var(const ne_hist *h)
{
    double keep = NE_TRIM * h->n, cum = 0, s = 0;
    for (int b = 0; b < NE_RBINS && cum < keep; b++) {
        if (!h->count[b]) continue;
        double take = fmin((double)h->count[b], keep - cum), e = ne_edge(b);
        s += (double)h->sum[b] / NE_FIX * e * e * (take / h->count[b]);
        cum += take;
    }
    return keep > 0 ? s / keep / NE_TRIM_M2 : 0.0;
}

/* Pool the darkest shells (at least NE_MIN_SAMPLES residuals), then add each next shell while
 * its variance is within NE_Z standard errors of the pool's. Returns sigma^2. */
static double ne_pool(const ne_hist *shell, long n, ne_hist *pool, float *fraction)
{
    memset(pool, 0, sizeof *pool);
    int j = 0;
    while (j < NE_SHELLS && pool->n < NE_MIN_SAMPLES) ne_hist_add(pool, &shell[j++]);
    double s = ne_trimmed_var(pool);
    for (; j < NE_SHELLS; j++) {
        if (!shell[j].n) continue;
        double tol = NE_Z * NE_RSE * sqrt(1.0 / pool->n + 1.0 / shell[j].n);
        if (ne_trimmed_var(&shell[j]) > s * (1 + tol)) break;
        ne_hist_add(pool, &shell[j]);
        s = ne_trimmed_var(pool);
    }
    *fraction = n > 0 ? (float)((double)pool->n / n) : 0.0f;
    return s;
}

static lm_status ne_check(const float *raw, int height, int width, int tile_h, int tile_w,
                          const lm_noise_info *out, lm_err *err)
{
    if (!raw || !out) return lm_err_set(err, LM_ERR_ARG, "noise: NULL frame or result");
    if (tile_h < 1 || tile_w < 1)
        return lm_err_set(err, LM_ERR_ARG, "noise: tile %d x %d must be at least 1 x 1", tile_h,
                          tile_w);
    if (height <= 0 || width <= 0 || height % tile_h || width % tile_w)
        return lm_err_set(err, LM_ERR_SHAPE,
                          "noise: frame %d x %d is not a positive multiple of the %d x %d tile",
                          height, width, tile_h, tile_w);
    if (height / tile_h < 3 || width / tile_w < 3)
        return lm_err_set(err, LM_ERR_SHAPE,
                          "noise: frame %d x %d too small: each tile phase needs 3 x 3 pixels "
                          "(at least %d x %d)", height, width, 3 * tile_h, 3 * tile_w);
    return LM_OK;
}

/* Robust maximum of the clean frame. Low noise (sigma <= 2 % of the frame maximum), or a
 * maximum more than 3 sigma above every 2 x 2 mean while sigma < 6 % of it (a narrow highlight,
 * which smoothing would lose): the frame maximum minus 2 sigma. Otherwise (a bright plateau,
 * whose raw maximum is the largest of many noisy values): the largest 2 x 2 same-phase mean
 * minus sigma (the typical excess of the largest of many such means, sd sigma / 2, over their
 * clean value on the CAVE frames; more for very large plateaus at high noise). */
static float ne_peak(const ne_frame *f, float sigma)
{
    int narrow = f->hi - f->box_max > NE_NARROW * sigma && sigma < NE_NARROW_MAX * f->hi;
    if (sigma <= NE_PEAK_SWITCH * f->hi || narrow) return f->hi - 2 * sigma;
    return f->box_max - sigma;
}

/* A clip floor: at least 1 in 1000 pixels (and 16) exactly at the frame's minimum. */
static int ne_has_floor(const ne_frame *f)
{
    long n = (long)f->height * f->width, at = 0;
    for (long i = 0; i < n; i++) at += f->raw[i] == f->lo;
    return at >= 16 && at * 1000 >= n;
}

/* Scratch of an estimate on nthreads threads: the summed histograms (shells, pool, scores),
 * then per thread its shells, its score histogram and one row of residuals and score bins. */
typedef struct ne_scratch {
    ne_hist *shell, *pool, *shell_t;
    long *score, *score_t;
    ne_rows rows[LM_NOISE_MAX_THREADS];
    int nthreads;
} ne_scratch;

static size_t ne_bytes(int width, int nthreads)
{
    const size_t w = (size_t)(width > 0 ? width : 0);
    return (size_t)(NE_SHELLS + 1) * sizeof(ne_hist) + NE_SCORE_BINS * sizeof(long) +
           (size_t)nthreads * (NE_SHELLS * sizeof(ne_hist) + NE_SCORE_BINS * sizeof(long) +
                               w * (sizeof(float) + sizeof(int)));
}

static void ne_layout(void *mem, int width, int nthreads, ne_scratch *s)
{
    char *p = mem;
    s->nthreads = nthreads;
    s->shell = (ne_hist *)p, p += NE_SHELLS * sizeof(ne_hist);
    s->pool = (ne_hist *)p, p += sizeof(ne_hist);
    s->shell_t = (ne_hist *)p, p += (size_t)nthreads * NE_SHELLS * sizeof(ne_hist);
    s->score = (long *)p, p += NE_SCORE_BINS * sizeof(long);
    s->score_t = (long *)p, p += (size_t)nthreads * NE_SCORE_BINS * sizeof(long);
    for (int t = 0; t < nthreads; t++) {
        s->rows[t].r = (float *)p, p += (size_t)width * sizeof(float);
        s->rows[t].sb = (int *)p, p += (size_t)width * sizeof(int);
    }
}

/* One estimate with the frame's current exclusion; returns sigma (fraction and n set). */
static float ne_once(ne_frame *f, ne_scratch *s, lm_noise_info *out, long *n_used)
{
    const int T = s->nthreads;
    memset(s->shell, 0, (NE_SHELLS + 1 + (size_t)T * NE_SHELLS) * sizeof(ne_hist));
    memset(s->score, 0, (1 + (size_t)T) * NE_SCORE_BINS * sizeof(long));
    long n = ne_score_hist(f, s->rows, s->score_t, T, s->score);
    *n_used = n;
    if (n < NE_MIN_SAMPLES && f->floor_on) return -1.0f;
    int last_bin[NE_SHELLS - 1];
    ne_thresholds(s->score, n, last_bin);
    ne_residual_hist(f, last_bin, s->rows, s->shell_t, T, s->shell);
    return (float)(sqrt(ne_pool(s->shell, n, s->pool, &out->fraction)) / f->r_scale);
}

/* sigma and peak of a checked, scanned frame; scratch holds the histograms. A frame clipped at
 * its minimum (a 16-bit PNG of a noisy frame: negatives are 0) reads low near the floor, where
 * the noise is cut: such frames are estimated again without the windows that touch the floor or
 * whose mean is below 1.5 sigma of the previous estimate, until it settles (at most 4 rounds). */
static void ne_estimate(ne_frame *f, ne_scratch *s, lm_noise_info *out)
{
    float range = f->hi - f->lo;
    f->score_lo = f->lo;
    f->score_scale = NE_SCORE_BINS / range;
    f->r_scale = 1.0f / range;
    long n;
    float sigma = ne_once(f, s, out, &n);
    f->floor_on = ne_has_floor(f);
    for (int round = 0; f->floor_on && round < 4; round++) {
        f->floor_mean = f->lo + 1.5f * sigma;
        lm_noise_info keep = *out;
        float s2 = ne_once(f, s, out, &n);
        if (s2 < 0) { /* too few windows left: keep the last estimate */
            *out = keep;
            break;
        }
        int settled = fabsf(s2 - sigma) <= 0.01f * sigma;
        sigma = s2;
        if (settled) break;
    }
    out->sigma = sigma;
    out->peak = ne_peak(f, sigma);
}

size_t lm_noise_scratch_bytes(int width) { return ne_bytes(width, 1); }

/* Threads for a frame of `rows` rows: the OpenMP default (1 inside a parallel region), at most
 * one per 16 rows and LM_NOISE_MAX_THREADS. The result does not depend on it. */
static int ne_threads(int rows)
{
    int t = omp_in_parallel() ? 1 : omp_get_max_threads();
    if (t > rows / 16) t = rows / 16;
    if (t > LM_NOISE_MAX_THREADS) t = LM_NOISE_MAX_THREADS;
    return t < 1 ? 1 : t;
}

/* Checks, scan and estimate: sigma, peak and fraction (level left 0). scratch:
 * lm_noise_scratch_bytes(width) bytes of the caller's (one thread), or NULL (allocated here,
 * for ne_threads threads). */
static lm_status ne_run(const float *raw, int height, int width, int tile_h, int tile_w,
                        void *scratch, lm_noise_info *out, lm_err *err)
{
    lm_status s = ne_check(raw, height, width, tile_h, tile_w, out, err);
    if (s != LM_OK) return s;
    memset(out, 0, sizeof *out);
    ne_frame f = {.raw = raw, .height = height, .width = width, .th = tile_h, .tw = tile_w};
    long bad = ne_scan(&f);
    if (bad >= 0)
        return lm_err_set(err, LM_ERR_NUMERIC, "noise: non-finite value at (x=%ld, y=%ld)",
                          bad % width, bad / width);
    if (!(f.hi > f.lo)) { /* a constant frame: no noise, the peak is its value */
        out->peak = f.hi, out->fraction = 1.0f;
        return LM_OK;
    }
    const int T = scratch ? 1 : ne_threads(height - 2 * tile_h);
    size_t bytes = ne_bytes(width, T);
    void *own = scratch ? NULL : malloc(bytes);
    if (!scratch && !own)
        return lm_err_set(err, LM_ERR_NOMEM, "noise: out of memory (%zu bytes)", bytes);
    ne_scratch sc;
    ne_layout(scratch ? scratch : own, width, T, &sc);
    ne_estimate(&f, &sc, out);
    free(own);
    return LM_OK;
}

lm_status lm_noise_analyze(const float *raw, int height, int width, int tile_h, int tile_w,
                           lm_noise_info *out, lm_err *err)
{
    lm_status s = ne_run(raw, height, width, tile_h, tile_w, NULL, out, err);
    if (s != LM_OK) return s;
    if (!(out->peak > 0))
        return lm_err_set(err, LM_ERR_NUMERIC,
                          "noise: no positive signal (robust peak %g), level undefined",
                          (double)out->peak);
    out->level = out->sigma / out->peak;
    return LM_OK;
}

float lm_noise_estimate(const float *raw, int height, int width, int tile_h, int tile_w)
{
    lm_noise_info info;
    lm_status s = ne_run(raw, height, width, tile_h, tile_w, NULL, &info, NULL);
    return s == LM_OK ? info.sigma : (float)s;
}

float lm_noise_estimate_scratch(const float *raw, int height, int width, int tile_h, int tile_w,
                                void *scratch)
{
    lm_noise_info info;
    lm_status s = ne_run(raw, height, width, tile_h, tile_w, scratch, &info, NULL);
    return s == LM_OK ? info.sigma : (float)s;
}

float lm_noise_level(const float *raw, int height, int width, int tile_h, int tile_w)
{
    lm_noise_info info;
    lm_status s = lm_noise_analyze(raw, height, width, tile_h, tile_w, &info, NULL);
    return s == LM_OK ? info.level : (float)s;
}

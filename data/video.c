/* video.c — the video forward model: motion, warping, and coded frames of a moving scene.
 * What it is: an inverse map per instant (precomputed as a small affine transform plus the
 * regions' positions), bilinear taps with snapping and edge clamping, and the per-LED temporal
 * averaging. Bucket 1 is built as an "effective cube" (each pixel's spectrum averaged over its
 * own LED's instants) that goes through lm_forward_clean, so a still scene gives exactly the
 * static model; bucket 0 sums the other LEDs' averaged spectra per pixel (double accumulation).
 * Spectra are averaged in double; OpenMP over rows, no reductions across rows, so results do not
 * depend on the thread count.
 * What it is not: the static closed form or the noise (forward.c). */
#include "data/video.h"
#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>

static int threads_of(int nthreads) { return nthreads > 0 ? nthreads : omp_get_max_threads(); }

/* The inverse map at one instant: q = c + M (p - shift - c) for the background; regions at
 * their current centres, showing the input shifted by their displacement. */
typedef struct xform {
    double cx, cy, tx, ty, m00, m01, m10, m11;
    int nregions;
    const lm_motion_region *regions;
    double rcx[LM_VIDEO_MAX_REGIONS], rcy[LM_VIDEO_MAX_REGIONS];
    double rdx[LM_VIDEO_MAX_REGIONS], rdy[LM_VIDEO_MAX_REGIONS];
} xform;

static void xform_init(xform *f, const lm_motion *m, int H, int W, double t)
{
    f->cx = m->has_centre ? m->cx : 0.5 * (W - 1);
    f->cy = m->has_centre ? m->cy : 0.5 * (H - 1);
    f->tx = m->vx * t;
    f->ty = m->vy * t;
    double th = -m->rot_deg_s * t * (M_PI / 180.0);
    double s = pow(1.0 + m->zoom_pct_s / 100.0, -t);
    double c = cos(th), sn = sin(th);
    f->m00 = s * c;
    f->m01 = -s * sn;
    f->m10 = s * sn;
    f->m11 = s * c;
    f->nregions = m->nregions;
    f->regions = m->regions;
    for (int r = 0; r < m->nregions; r++) {
        f->rdx[r] = m->regions[r].vx * t;
        f->rdy[r] = m->regions[r].vy * t;
        f->rcx[r] = m->regions[r].cx + f->rdx[r];
        f->rcy[r] = m->regions[r].cy + f->rdy[r];
    }
}

static int region_has(const lm_motion_region *g, double dx, double dy)
{
    double hx = 0.5 * g->w, hy = 0.5 * g->h;
    if (g->shape == LM_REGION_ELLIPSE) return (dx / hx) * (dx / hx) + (dy / hy) * (dy / hy) <= 1.0;
    return fabs(dx) <= hx && fabs(dy) <= hy;
}

static void xform_apply(const xform *f, double x, double y, double *sx, double *sy)
{
    for (int r = f->nregions - 1; r >= 0; r--)
        if (region_has(&f->regions[r], x - f->rcx[r], y - f->rcy[r])) {
            *sx = x - f->rdx[r];
            *sy = y - f->rdy[r];
            return;
        }
    double px = x - f->tx - f->cx, py = y - f->ty - f->cy;
    *sx = f->cx + f->m00 * px + f->m01 * py;
    *sy = f->cy + f->m10 * px + f->m11 * py;
}

void lm_motion_source(const lm_motion *m, int height, int width, double t_s, double x, double y,
                      double *sx, double *sy)
{
    xform f;
    xform_init(&f, m, height, width, t_s);
    xform_apply(&f, x, y, sx, sy);
}

/* Clamp to [0, n-1], snap to a pixel centre within 1e-9, split into index and fraction. */
static void axis_taps(double s, int n, int *i0, int *i1, double *frac)
{
    s = s < 0.0 ? 0.0 : (s > n - 1 ? n - 1 : s);
    double f0 = floor(s), fr = s - f0;
    if (fr < 1e-9) fr = 0.0;
    else if (fr > 1.0 - 1e-9) {
        f0 += 1.0;
        fr = 0.0;
    }
    *i0 = (int)f0;
    *i1 = *i0 + 1 < n ? *i0 + 1 : *i0;
    *frac = fr;
}

typedef struct taps {
    long idx[4];
    double w[4];
} taps;

static void taps_at(const xform *f, int H, int W, int x, int y, taps *tp)
{
    double sx, sy, fx, fy;
    int x0, x1, y0, y1;
    xform_apply(f, x, y, &sx, &sy);
    axis_taps(sx, W, &x0, &x1, &fx);
    axis_taps(sy, H, &y0, &y1, &fy);
    tp->idx[0] = (long)y0 * W + x0;
    tp->idx[1] = (long)y0 * W + x1;
    tp->idx[2] = (long)y1 * W + x0;
    tp->idx[3] = (long)y1 * W + x1;
    tp->w[0] = (1.0 - fy) * (1.0 - fx);
    tp->w[1] = (1.0 - fy) * fx;
    tp->w[2] = fy * (1.0 - fx);
    tp->w[3] = fy * fx;
}

/* acc[b] += spectrum of the scene at the taps, every band b. */
static void taps_add(const lm_cube *c, const taps *tp, double *acc)
{
    size_t plane = (size_t)c->height * c->width;
    for (int b = 0; b < c->bands; b++) {
        const float *v = c->data + b * plane;
        acc[b] += tp->w[0] * v[tp->idx[0]] + tp->w[1] * v[tp->idx[1]] +
                  tp->w[2] * v[tp->idx[2]] + tp->w[3] * v[tp->idx[3]];
    }
}

lm_status lm_motion_check(const lm_motion *m, lm_err *err)
{
    double v[] = {m->vx, m->vy, m->rot_deg_s, m->zoom_pct_s, m->cx, m->cy};
    for (int i = 0; i < 6; i++)
        if (!isfinite(v[i]))
            return lm_err_set(err, LM_ERR_ARG, "video: motion: non-finite parameter");
    if (!(m->zoom_pct_s > -100.0))
        return lm_err_set(err, LM_ERR_ARG, "video: motion: zoom %g %%/s must be > -100",
                          m->zoom_pct_s);
    if (m->nregions < 0 || m->nregions > LM_VIDEO_MAX_REGIONS)
        return lm_err_set(err, LM_ERR_ARG, "video: motion: %d regions (0..%d allowed)",
                          m->nregions, LM_VIDEO_MAX_REGIONS);
    for (int r = 0; r < m->nregions; r++) {
        const lm_motion_region *g = &m->regions[r];
        double rv[] = {g->cx, g->cy, g->w, g->h, g->vx, g->vy};
        for (int i = 0; i < 6; i++)
            if (!isfinite(rv[i]))
                return lm_err_set(err, LM_ERR_ARG, "video: motion: region %d: non-finite "
                                  "parameter", r);
        if (!(g->w > 0.0) || !(g->h > 0.0))
            return lm_err_set(err, LM_ERR_ARG, "video: motion: region %d: size %g x %g must "
                              "be > 0", r, g->w, g->h);
        if (g->shape != LM_REGION_RECT && g->shape != LM_REGION_ELLIPSE)
            return lm_err_set(err, LM_ERR_ARG, "video: motion: region %d: unknown shape", r);
    }
    return LM_OK;
}

lm_status lm_video_warp(const lm_cube *src, const lm_motion *m, double t_s, lm_cube *out,
                        int nthreads, lm_err *err)
{
    memset(out, 0, sizeof *out);
    lm_status st = lm_motion_check(m, err);
    if (st != LM_OK) return st;
    if (!isfinite(t_s)) return lm_err_set(err, LM_ERR_ARG, "video: warp at a non-finite time");
    if (!src->data || src->bands < 1 || src->height < 1 || src->width < 1)
        return lm_err_set(err, LM_ERR_ARG, "video: warp of an empty cube");
    int H = src->height, W = src->width, nb = src->bands;
    if (lm_cube_alloc(out, nb, H, W, 0.0f, 0.0f) != LM_OK)
        return lm_err_set(err, LM_ERR_NOMEM, "video: out of memory (%d x %d x %d cube)", nb, H,
                          W);
    memcpy(out->wavelength, src->wavelength, sizeof out->wavelength);
    xform f;
    xform_init(&f, m, H, W, t_s);
    size_t plane = (size_t)H * W;
#pragma omp parallel for schedule(static) num_threads(threads_of(nthreads))
    for (int y = 0; y < H; y++) {
        double acc[LM_CUBE_MAX_BANDS];
        taps tp;
        for (int x = 0; x < W; x++) {
            memset(acc, 0, sizeof(double) * nb);
            taps_at(&f, H, W, x, y, &tp);
            taps_add(src, &tp, acc);
            for (int b = 0; b < nb; b++) out->data[b * plane + (size_t)y * W + x] = (float)acc[b];
        }
    }
    return LM_OK;
}

double lm_video_frame_start_us(const lm_system *sys, int frame)
{
    return frame * lm_system_frame_period_us(sys);
}

double lm_video_led_instant_us(const lm_system *sys, int led, int k, int samples)
{
    const lm_led *l = &sys->leds[led];
    return l->start_us + (k + 0.5) / samples * (l->end_us - l->start_us);
}

double lm_video_gt_time_us(const lm_system *sys)
{
    return lm_system_led_centre_us(sys, lm_system_reference_led(sys));
}

/* Per-LED, per-instant transforms of one frame: xf[l * K + k]. */
static xform *frame_xforms(const lm_system *sys, const lm_motion *m, int H, int W, int frame,
                           int K)
{
    xform *xf = malloc(sizeof(xform) * (size_t)sys->nleds * K);
    if (!xf) return NULL;
    double t0 = lm_video_frame_start_us(sys, frame);
    for (int l = 0; l < sys->nleds; l++)
        for (int k = 0; k < K; k++)
            xform_init(&xf[l * K + k], m, H, W,
                       1e-6 * (t0 + lm_video_led_instant_us(sys, l, k, K)));
    return xf;
}

/* eff: each pixel's spectrum averaged over its own LED's instants. */
static void effective_cube(const lm_system *sys, const lm_cube *c, const xform *xf, int K,
                           int y0, int x0, lm_cube *eff, int nt)
{
    int H = c->height, W = c->width, nb = c->bands;
    size_t plane = (size_t)H * W;
#pragma omp parallel for schedule(static) num_threads(nt)
    for (int y = 0; y < H; y++) {
        double acc[LM_CUBE_MAX_BANDS];
        taps tp;
        for (int x = 0; x < W; x++) {
            int l = lm_system_pixel_led(sys, y + y0, x + x0);
            memset(acc, 0, sizeof(double) * nb);
            for (int k = 0; k < K; k++) {
                taps_at(&xf[l * K + k], H, W, x, y, &tp);
                taps_add(c, &tp, acc);
            }
            for (int b = 0; b < nb; b++)
                eff->data[b * plane + (size_t)y * W + x] = (float)(acc[b] / K);
        }
    }
}

/* bucket0[p] = sum over LEDs l != l(p) of a_l . (mean over l's instants of the scene at p). */
static void bucket0_moving(const lm_system *sys, const lm_cube *c, const xform *xf, int K,
                           int y0, int x0, float *bucket0, int nt)
{
    int H = c->height, W = c->width, nb = c->bands;
#pragma omp parallel for schedule(static) num_threads(nt)
    for (int y = 0; y < H; y++) {
        double acc[LM_CUBE_MAX_BANDS];
        taps tp;
        for (int x = 0; x < W; x++) {
            int lp = lm_system_pixel_led(sys, y + y0, x + x0);
            double sum = 0.0;
            for (int l = 0; l < sys->nleds; l++) {
                if (l == lp) continue;
                memset(acc, 0, sizeof(double) * nb);
                for (int k = 0; k < K; k++) {
                    taps_at(&xf[l * K + k], H, W, x, y, &tp);
                    taps_add(c, &tp, acc);
                }
                const float *a = sys->leds[l].response;
                for (int b = 0; b < nb; b++) sum += a[b] * (acc[b] / K);
            }
            bucket0[(size_t)y * W + x] = (float)sum;
        }
    }
}

static lm_status check_video(const lm_system *sys, const lm_cube *cube, const lm_video_opts *o,
                             int frame, lm_err *err)
{
    lm_status st = lm_motion_check(&o->motion, err);
    if (st != LM_OK) return st;
    if (o->samples < 0 || o->samples > LM_VIDEO_MAX_SAMPLES)
        return lm_err_set(err, LM_ERR_ARG, "video: %d samples per LED window (1..%d allowed)",
                          o->samples, LM_VIDEO_MAX_SAMPLES);
    if (frame < 0) return lm_err_set(err, LM_ERR_ARG, "video: negative frame index %d", frame);
    if (o->y0 < 0 || o->x0 < 0)
        return lm_err_set(err, LM_ERR_ARG, "video: negative sensor offset (%d, %d)", o->y0, o->x0);
    /* the static model's checks: bands on the grid, offsets, non-empty cube */
    if (!cube->data || cube->height < 1 || cube->width < 1)
        return lm_err_set(err, LM_ERR_SHAPE, "forward: empty cube");
    if (cube->bands != sys->nbins)
        return lm_err_set(err, LM_ERR_SHAPE, "forward: cube has %d bands, the system's grid has "
                          "%d (mirror 31-band cubes first)", cube->bands, sys->nbins);
    return LM_OK;
}

static lm_status buckets(const lm_system *sys, const lm_cube *cube, const lm_video_opts *o,
                         int frame, float *bucket1, float *bucket0, lm_err *err)
{
    int H = cube->height, W = cube->width, nt = threads_of(o->nthreads);
    int K = o->samples > 0 ? o->samples : LM_VIDEO_DEFAULT_SAMPLES;
    lm_cube eff;
    xform *xf = frame_xforms(sys, &o->motion, H, W, frame, K);
    if (!xf || lm_cube_alloc(&eff, cube->bands, H, W, 0.0f, 0.0f) != LM_OK) {
        free(xf);
        return lm_err_set(err, LM_ERR_NOMEM, "video: out of memory (%d x %d frame)", H, W);
    }
    memcpy(eff.wavelength, cube->wavelength, sizeof eff.wavelength);
    /* the static model validates the cube (grid, offsets, finite values) on eff */
    effective_cube(sys, cube, xf, K, o->y0, o->x0, &eff, nt);
    lm_status st = lm_forward_clean(sys, &eff, o->y0, o->x0, bucket1, NULL, nt, err);
    lm_cube_free(&eff);
    if (st == LM_OK && bucket0) bucket0_moving(sys, cube, xf, K, o->y0, o->x0, bucket0, nt);
    free(xf);
    return st;
}

lm_status lm_video_frame(const lm_system *sys, const lm_cube *cube, const lm_video_opts *o,
                         int frame, lm_rng *rng, float *bucket1, float *bucket0, lm_cube *gt,
                         lm_err *err)
{
    if (gt) memset(gt, 0, sizeof *gt);
    lm_status st = check_video(sys, cube, o, frame, err);
    if (st == LM_OK) st = buckets(sys, cube, o, frame, bucket1, bucket0, err);
    int H = cube->height, W = cube->width;
    if (st == LM_OK) st = lm_forward_noise(bucket1, H, W, &o->noise, rng, o->nthreads, err);
    lm_noise_opts n0 = lm_forward_bucket0_noise(&o->noise, sys->nleds);
    if (st == LM_OK && bucket0) st = lm_forward_noise(bucket0, H, W, &n0, rng, o->nthreads, err);
    if (st == LM_OK && gt) {
        double t = 1e-6 * (lm_video_frame_start_us(sys, frame) + lm_video_gt_time_us(sys));
        st = lm_video_warp(cube, &o->motion, t, gt, o->nthreads, err);
    }
    return st;
}

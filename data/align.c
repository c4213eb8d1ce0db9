/* align.c — temporal alignment of LED sub-images (see align.h for the scheme).
 * What it is: timestamps from the system description (window centres over the frame period),
 * the per-plane choice of frames and interpolation time, the edge-frame fallbacks, the
 * confidence blend, and tile-phase (un)shuffling of raw frames.
 * What it is not: the flow itself (flow.c). */
#include "data/align.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

lm_status lm_align_phase_times(const lm_system *s, float *t, int *ref, lm_err *e)
{
    if (!s || !t || !ref) return lm_err_set(e, LM_ERR_ARG, "align: NULL argument");
    /* frames start frame_period_us apart: the same LED of frames i and i + 1 is one period
     * apart, so one period is the unit of the flow's time axis */
    double period = lm_system_frame_period_us(s);
    int nph = s->tile_rows * s->tile_cols, rl = lm_system_reference_led(s);
    *ref = -1;
    for (int p = 0; p < nph; p++) {
        int led = lm_system_tile_led(s, p);
        t[p] = (float)(lm_system_led_centre_us(s, led) / period);
        if (led == rl && *ref < 0) *ref = p;
    }
    if (*ref < 0)
        return lm_err_set(e, LM_ERR_ARG, "align: system '%s': its reference LED %s is not in "
                          "the tile", s->name, s->leds[rl].name);
    return LM_OK;
}

void lm_align_default_opts(lm_align_opts *o)
{
    o->confidence = 1;
    o->fb_tol = 2.0f;
}

/* out <- cur + c (out - cur), c from the flows fc = F_{cur->n}, fn = F_{n->cur} (align.h). */
static void blend_confidence(const float *cur, const float *fc, const float *fn, int h, int w,
                             float tau, const lm_align_opts *ao, float *out)
{
    long n = (long)h * w;
    float at = fabsf(tau), lo = 0.5f * ao->fb_tol, hi = ao->fb_tol;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            long i = (long)y * w + x;
            float u = fc[i], v = fc[n + i];
            float bx = (float)x + u, by = (float)y + v;
            float eu = u + lm_flow_sample(fn, h, w, bx, by);
            float ev = v + lm_flow_sample(fn + n, h, w, bx, by);
            float d = at * sqrtf(eu * eu + ev * ev); /* position error the warp would make */
            float c = d <= lo ? 1.0f : d >= hi ? 0.0f : (hi - d) / (hi - lo);
            out[i] = cur[i] + c * (out[i] - cur[i]);
        }
}

/* The neighbour plane p uses: +1 frame i+1, -1 frame i-1, 0 none (copy). */
static int plane_side(const float *prev, const float *next, float tau)
{
    if (tau == 0.0f || (!prev && !next)) return 0;
    if (tau > 0.0f) return next ? 1 : -1;
    return prev ? -1 : 1;
}

/* Flows of one plane against neighbour nb: fc = F_{cur->nb} always; fn = F_{nb->cur} when
 * `both` (the interpolation or the confidence needs it). */
static lm_status pair_flows(const float *cur, const float *nb, int h, int w, int both,
                            const lm_flow_opts *o, float *fc, float *fn, lm_err *e)
{
    lm_status s = lm_flow_compute(cur, nb, h, w, o, fc, e);
    if (!s && both) s = lm_flow_compute(nb, cur, h, w, o, fn, e);
    return s;
}

/* One plane with neighbour nb (dt = +1: frame i+1, -1: frame i-1) at relative time tau, from
 * the flows fc = F_{cur->nb} and fn = F_{nb->cur} (fn read only when tau points towards nb or
 * the confidence is on): interpolation between the two frames when tau points towards nb, else
 * frame i's plane warped alone under linear motion, out(p) = cur(p - (tau / dt) F_{i->n}(p));
 * then the confidence blend. */
static lm_status align_pair_flows(const float *cur, const float *nb, float dt, int h, int w,
                                  float tau, const lm_flow_opts *o, const lm_align_opts *ao,
                                  const float *fc, const float *fn, float *out, lm_err *e)
{
    int nt = o && o->nthreads > 0 ? o->nthreads : 1, towards = tau * dt > 0.0f;
    lm_status s = LM_OK;
    if (towards && dt > 0.0f)
        s = lm_flow_interpolate_flows(cur, nb, h, w, tau, fc, fn, nt, out, e);
    else if (towards)
        s = lm_flow_interpolate_flows(nb, cur, h, w, 1.0f + tau, fn, fc, nt, out, e);
    else
        lm_flow_warp_cubic(cur, h, w, fc, -tau / dt, out, nt);
    if (!s && ao->confidence) blend_confidence(cur, fc, fn, h, w, tau, ao, out);
    return s;
}

/* The same computing the flows into f (4n floats). */
static lm_status align_pair(const float *cur, const float *nb, float dt, int h, int w,
                            float tau, const lm_flow_opts *o, const lm_align_opts *ao, float *f,
                            float *out, lm_err *e)
{
    long n = (long)h * w;
    float *fc = f, *fn = f + 2 * n;
    lm_status s = pair_flows(cur, nb, h, w, tau * dt > 0.0f || ao->confidence, o, fc, fn, e);
    if (!s) s = align_pair_flows(cur, nb, dt, h, w, tau, o, ao, fc, fn, out, e);
    return s;
}

/* The arguments lm_align_frame and lm_align_stack share, checked. */
static lm_status check_args(const float *cur, const float *t, const float *out, int np, int h,
                            int w, int ref, lm_err *e)
{
    if (!cur || !t || !out) return lm_err_set(e, LM_ERR_ARG, "align: NULL frame, times or output");
    if (np < 1 || ref < 0 || ref >= np)
        return lm_err_set(e, LM_ERR_ARG, "align: reference plane %d outside 0..%d", ref, np - 1);
    if (h <= 0 || w <= 0)
        return lm_err_set(e, LM_ERR_SHAPE, "align: empty sub-images %dx%d", h, w);
    return LM_OK;
}

lm_status lm_align_frame(const float *prev, const float *cur, const float *next, int np, int h,
                         int w, const float *t, int ref, const lm_flow_opts *o,
                         const lm_align_opts *ao, float *out, lm_err *e)
{
    lm_status cs = check_args(cur, t, out, np, h, w, ref, e);
    if (cs) return cs;
    lm_align_opts dao;
    if (!ao) lm_align_default_opts(&dao), ao = &dao;
    size_t n = (size_t)h * (size_t)w;
    float *f = malloc(sizeof(float) * 4 * n);
    if (!f) return lm_err_set(e, LM_ERR_NOMEM, "align: out of memory");
    lm_status s = LM_OK;
    for (int p = 0; p < np && !s; p++) {
        int side = plane_side(prev, next, t[ref] - t[p]);
        if (!side) {
            memcpy(out + p * n, cur + p * n, sizeof(float) * n);
            continue;
        }
        lm_err pe = {0};
        s = align_pair(cur + p * n, (side > 0 ? next : prev) + p * n, (float)side, h, w,
                       t[ref] - t[p], o, ao, f, out + p * n, &pe);
        if (s) lm_err_set(e, s, "align: plane %d: %s", p, pe.msg);
    }
    free(f);
    return s;
}

/* Neighbour plane nb (frame i + dt) moved onto frame i's plane at the reference instant:
 * out(x) = nb(x + (1 - tau / dt) F_{i->nb}(x)) (bicubic), then blended towards fallback (the
 * aligned current plane) where the flows disagree, as blend_confidence does with the warp's
 * scale 1 - tau / dt. */
static void warp_neighbour(const float *nb, const float *fallback, float dt, int h, int w,
                           float tau, const float *fc, const float *fn, const lm_flow_opts *o,
                           const lm_align_opts *ao, float *out)
{
    int nt = o && o->nthreads > 0 ? o->nthreads : 1;
    float sc = 1.0f - tau / dt;
    lm_flow_warp_cubic(nb, h, w, fc, sc, out, nt);
    if (ao->confidence) blend_confidence(fallback, fc, fn, h, w, sc, ao, out);
}

lm_status lm_align_stack(const float *prev, const float *cur, const float *next, int np, int h,
                         int w, const float *t, int ref, const lm_flow_opts *o,
                         const lm_align_opts *ao, float *out, lm_err *e)
{
    lm_status cs = check_args(cur, t, out, np, h, w, ref, e);
    if (cs) return cs;
    lm_align_opts dao;
    if (!ao) lm_align_default_opts(&dao), ao = &dao;
    size_t n = (size_t)h * (size_t)w, fr = (size_t)np * n;
    float *f = malloc(sizeof(float) * 8 * n); /* F_{i->i-1}, F_{i-1->i}, F_{i->i+1}, F_{i+1->i} */
    if (!f) return lm_err_set(e, LM_ERR_NOMEM, "align: out of memory");
    float *fp[2] = {f, f + 2 * n}, *fx[2] = {f + 4 * n, f + 6 * n};
    lm_status s = LM_OK;
    for (int p = 0; p < np && !s; p++) {
        const float *c = cur + p * n, *nbs[2] = {prev ? prev + p * n : NULL,
                                                 next ? next + p * n : NULL};
        float *al = out + p * n, tau = t[ref] - t[p];
        lm_err pe = {0};
        for (int k = 0; k < 2 && !s; k++) /* the flows of both neighbours */
            if (nbs[k]) s = pair_flows(c, nbs[k], h, w, 1, o, k ? fx[0] : fp[0],
                                       k ? fx[1] : fp[1], &pe);
        /* plane 0: frame i aligned exactly as lm_align_frame does (same side, same flows) */
        int side = plane_side(prev, next, tau);
        if (!s && !side) memcpy(al, c, sizeof(float) * n);
        else if (!s)
            s = align_pair_flows(c, side > 0 ? nbs[1] : nbs[0], (float)side, h, w, tau, o, ao,
                                 side > 0 ? fx[0] : fp[0], side > 0 ? fx[1] : fp[1], al, &pe);
        for (int k = 0; k < 2 && !s; k++) { /* planes 1, 2: frame i - 1, frame i + 1 */
            float *dst = out + (size_t)(1 + k) * fr + p * n;
            if (!nbs[k]) memcpy(dst, al, sizeof(float) * n); /* missing: the current, aligned */
            else warp_neighbour(nbs[k], al, k ? 1.0f : -1.0f, h, w, tau, k ? fx[0] : fp[0],
                                k ? fx[1] : fp[1], o, ao, dst);
        }
        if (s) lm_err_set(e, s, "align: plane %d: %s", p, pe.msg);
    }
    free(f);
    return s;
}

lm_status lm_align_stack_frames(const lm_system *sys, const float *prev, const float *cur,
                                const float *next, int height, int width, int aligned,
                                const lm_flow_opts *o, const lm_align_opts *ao, float *out,
                                lm_err *e)
{
    if (!sys || !cur || !out) return lm_err_set(e, LM_ERR_ARG, "align: NULL system, frame or output");
    const int ty = sys->tile_rows, tx = sys->tile_cols, np = ty * tx;
    if (ty <= 0 || tx <= 0 || height <= 0 || width <= 0 || height % ty || width % tx)
        return lm_err_set(e, LM_ERR_SHAPE,
                          "align: frame %dx%d is not a positive multiple of the %dx%d tile",
                          height, width, ty, tx);
    const int h = height / ty, w = width / tx;
    const size_t n = (size_t)height * width;
    lm_flow_opts dfo;
    if (!o) lm_flow_default_opts(&dfo, LM_FLOW_MEDIUM);
    if (!o) o = &dfo;
    if (!aligned || h < lm_flow_min_size(o) || w < lm_flow_min_size(o)) {
        const float *src[3] = {cur, prev ? prev : cur, next ? next : cur};
        for (int q = 0; q < 3; q++) memcpy(out + q * n, src[q], sizeof(float) * n);
        return LM_OK;
    }
    int ref;
    float t[LM_SYSTEM_MAX_TILE];
    float *pl = malloc(sizeof(float) * 6 * n);
    if (!pl) return lm_err_set(e, LM_ERR_NOMEM, "align: out of memory");
    lm_status s = lm_align_phase_times(sys, t, &ref, e);
    const float *fr[3] = {prev, cur, next};
    for (int f = 0; f < 3 && !s; f++)
        if (fr[f]) s = lm_align_unshuffle(fr[f], height, width, ty, tx, pl + f * n, e);
    if (!s) s = lm_align_stack(prev ? pl : NULL, pl + n, next ? pl + 2 * n : NULL, np, h, w, t,
                               ref, o, ao, pl + 3 * n, e);
    for (int q = 0; q < 3 && !s; q++)
        s = lm_align_remosaic(pl + (3 + q) * n, h, w, ty, tx, out + q * n, e);
    free(pl);
    return s;
}

lm_status lm_align_unshuffle(const float *raw, int height, int width, int ty, int tx,
                             float *planes, lm_err *e)
{
    if (ty <= 0 || tx <= 0 || height <= 0 || width <= 0 || height % ty || width % tx)
        return lm_err_set(e, LM_ERR_SHAPE,
                          "align: frame %dx%d is not a positive multiple of the %dx%d tile",
                          height, width, ty, tx);
    int h = height / ty, w = width / tx;
    for (int y = 0; y < height; y++)
        for (int x = 0; x < width; x++)
            planes[((size_t)((y % ty) * tx + x % tx) * h + y / ty) * w + x / tx] =
                raw[(size_t)y * width + x];
    return LM_OK;
}

lm_status lm_align_remosaic(const float *planes, int h, int w, int ty, int tx, float *raw,
                            lm_err *e)
{
    if (ty <= 0 || tx <= 0 || h <= 0 || w <= 0)
        return lm_err_set(e, LM_ERR_SHAPE, "align: bad remosaic sizes %dx%d planes, %dx%d tile",
                          h, w, ty, tx);
    int width = w * tx;
    for (int y = 0; y < h * ty; y++)
        for (int x = 0; x < width; x++)
            raw[(size_t)y * width + x] =
                planes[((size_t)((y % ty) * tx + x % tx) * h + y / ty) * w + x / tx];
    return LM_OK;
}

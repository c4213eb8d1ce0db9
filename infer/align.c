/* align.c — temporal alignment of LED sub-images (see align.h for the scheme).
 * What it is: timestamps from the system description (window centres over the frame period), the per-plane choice of frames and
 * interpolation time, the edge-frame fallbacks, and tile-phase (un)shuffling of raw frames.
 * What it is not: the flow itself (flow.c). */
#include "infer/align.h"
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

/* Frame i's plane alone, warped under linear motion with the flow to neighbour n at relative
 * time dt (+1 or -1): out(p) = cur(p - (tau / dt) F_{i->n}(p)). */
static lm_status warp_one_sided(const float *cur, const float *nb, int h, int w, float tau,
                                float dt, const lm_flow_opts *o, float *out, lm_err *e)
{
    float *f = malloc(sizeof(float) * 2 * (size_t)h * (size_t)w);
    if (!f) return lm_err_set(e, LM_ERR_NOMEM, "align: out of memory");
    lm_status s = lm_flow_compute(cur, nb, h, w, o, f, e);
    if (!s) lm_flow_warp(cur, h, w, f, -tau / dt, out, o && o->nthreads > 0 ? o->nthreads : 1);
    free(f);
    return s;
}

/* One plane: the pair of frames and the time, or a fallback (see align.h). */
static lm_status align_plane(const float *prev, const float *cur, const float *next, int h,
                             int w, float tau, const lm_flow_opts *o, float *out, lm_err *e)
{
    size_t n = (size_t)h * (size_t)w;
    if (tau == 0.0f || (!prev && !next)) {
        memcpy(out, cur, n * sizeof *out);
        return LM_OK;
    }
    if (tau > 0.0f) {
        if (next) return lm_flow_interpolate(cur, next, h, w, tau, o, out, e);
        return warp_one_sided(cur, prev, h, w, tau, -1.0f, o, out, e);
    }
    if (prev) return lm_flow_interpolate(prev, cur, h, w, 1.0f + tau, o, out, e);
    return warp_one_sided(cur, next, h, w, tau, 1.0f, o, out, e);
}

lm_status lm_align_frame(const float *prev, const float *cur, const float *next, int np, int h,
                         int w, const float *t, int ref, const lm_flow_opts *o, float *out,
                         lm_err *e)
{
    if (!cur || !t || !out) return lm_err_set(e, LM_ERR_ARG, "align: NULL frame, times or output");
    if (np < 1 || ref < 0 || ref >= np)
        return lm_err_set(e, LM_ERR_ARG, "align: reference plane %d outside 0..%d", ref, np - 1);
    if (h <= 0 || w <= 0)
        return lm_err_set(e, LM_ERR_SHAPE, "align: empty sub-images %dx%d", h, w);
    size_t n = (size_t)h * (size_t)w;
    for (int p = 0; p < np; p++) {
        const float *pp = prev ? prev + p * n : NULL, *nx = next ? next + p * n : NULL;
        lm_err pe = {0};
        lm_status s = align_plane(pp, cur + p * n, nx, h, w, t[ref] - t[p], o, out + p * n, &pe);
        if (s) return lm_err_set(e, s, "align: plane %d: %s", p, pe.msg);
    }
    return LM_OK;
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

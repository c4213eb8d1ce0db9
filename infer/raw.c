/* raw.c — a camera's frame made into the frame a model reads (see raw.h).
 * What it is not: model loading or file reading. */
#include "infer/raw.h"
#include <math.h>
#include <stdio.h>
#include <string.h>

/* sum_b a[b] */
static double white(const float *a, int n)
{
    double s = 0.0;
    for (int b = 0; b < n; b++) s += a[b];
    return s;
}

/* Sensor, grid, LEDs and tile map: the same in both (0), else the error. */
static lm_status same_layout(const lm_system *m, const lm_system *c, lm_err *err)
{
    if (m->width != c->width || m->height != c->height)
        return lm_err_set(err, LM_ERR_ARG, "another sensor: %d x %d, the model's system %d x %d",
                          c->width, c->height, m->width, m->height);
    if (m->nbins != c->nbins || fabsf(m->grid_start - c->grid_start) > 1e-3f ||
        fabsf(m->grid_step - c->grid_step) > 1e-3f)
        return lm_err_set(err, LM_ERR_ARG, "another wavelength grid than the model's system");
    if (m->nleds != c->nleds)
        return lm_err_set(err, LM_ERR_ARG, "other LEDs: %d, the model's system has %d",
                          c->nleds, m->nleds);
    if (m->tile_rows != c->tile_rows || m->tile_cols != c->tile_cols)
        return lm_err_set(err, LM_ERR_ARG, "another tile map: %d x %d, the model's system "
                          "%d x %d", c->tile_rows, c->tile_cols, m->tile_rows, m->tile_cols);
    for (int t = 0; t < m->tile_rows * m->tile_cols; t++) {
        const char *a = c->leds[c->tile_led[t]].name, *b = m->leds[m->tile_led[t]].name;
        if (strcmp(a, b))
            return lm_err_set(err, LM_ERR_ARG, "another tile map: position (%d, %d) holds %s, "
                              "the model's system %s", t / m->tile_cols, t % m->tile_cols, a, b);
    }
    return LM_OK;
}

/* a0 / a for LED l of the model (lc: the same LED in the camera's system), or < 0 with err. */
static double led_ratio(const lm_system *m, int l, const lm_system *c, int lc, lm_err *err)
{
    const float *a0 = m->leds[l].response, *a = c->leds[lc].response;
    double w0 = white(a0, m->nbins), w = white(a, m->nbins);
    if (!(w > 0.0) || !(w0 > 0.0)) {
        lm_err_set(err, LM_ERR_ARG, "LED '%s' has no response (gain 0) in %s", m->leds[l].name,
                   w > 0.0 ? "the model's system" : c->path);
        return -1.0;
    }
    double r = w0 / w, peak = 0.0;
    for (int b = 0; b < m->nbins; b++) peak = a0[b] > peak ? a0[b] : peak;
    for (int b = 0; b < m->nbins; b++)
        if (fabs(a0[b] - r * a[b]) > 1e-4 * peak) {
            lm_err_set(err, LM_ERR_ARG, "LED '%s' has another emission or sensor QE (its "
                       "response at %g nm is not a rescaled copy of the model's)",
                       m->leds[l].name, m->grid_start + m->grid_step * b);
            return -1.0;
        }
    return r;
}

lm_status lm_gain_remap_init(const lm_system *model, const lm_system *camera, lm_gain_remap *out,
                             lm_err *err)
{
    memset(out, 0, sizeof *out);
    lm_status st = same_layout(model, camera, err);
    if (st) return st;
    double ratio[LM_SYSTEM_MAX_LEDS];
    for (int l = 0; l < model->nleds; l++) {
        int lc = lm_system_led_index(camera, model->leds[l].name);
        if (lc < 0)
            return lm_err_set(err, LM_ERR_ARG, "other LEDs: no '%s' in %s", model->leds[l].name,
                              camera->path);
        ratio[l] = led_ratio(model, l, camera, lc, err);
        if (ratio[l] < 0.0) return memset(out, 0, sizeof *out), err->status;
    }
    out->ty = model->tile_rows;
    out->tx = model->tile_cols;
    int np = out->ty * out->tx;
    double ss = 0.0;
    out->min = out->max = (float)ratio[model->tile_led[0]];
    for (int t = 0; t < np; t++) {
        float s = (float)ratio[model->tile_led[t]];
        out->scale[t] = s;
        out->min = s < out->min ? s : out->min;
        out->max = s > out->max ? s : out->max;
        out->active |= fabsf(s - 1.0f) > 1e-6f;
        ss += (double)s * s;
    }
    out->noise_scale = (float)sqrt(ss / np);
    return LM_OK;
}

float lm_gain_remap_frame(const lm_gain_remap *g, const float *in, int planes, int height,
                          int width, float k, float *out)
{
    const size_t n = (size_t)height * width;
    if (!g->active) {
        if (out != in) memcpy(out, in, sizeof(float) * n * planes);
        return k;
    }
    float mx_in = 0.0f, mx_out = 0.0f;
    for (int p = 0; p < planes; p++)
        for (int y = 0; y < height; y++) {
            const float *s = g->scale + (y % g->ty) * g->tx;
            const float *src = in + p * n + (size_t)y * width;
            float *dst = out + p * n + (size_t)y * width;
            for (int x = 0; x < width; x++) {
                float v = src[x], w = v * s[x % g->tx];
                if (p == 0) {
                    mx_in = v > mx_in ? v : mx_in;
                    mx_out = w > mx_out ? w : mx_out;
                }
                dst[x] = w;
            }
        }
    if (k < 0.0f) return k;
    return mx_out > 0.0f ? k * mx_in * g->noise_scale / mx_out : k;
}

void lm_gain_remap_describe(const lm_gain_remap *g, const char *camera, const char *model_sys,
                            char *buf, size_t n)
{
    snprintf(buf, n, "gains: %s has other LED gains than the model's system %s: each tile phase "
             "is rescaled to the model's gains (x%.3f..x%.3f, noise x%.3f)", camera, model_sys,
             g->min, g->max, g->noise_scale);
}

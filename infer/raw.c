/* raw.c — a camera's frame made into the frame a model reads (see raw.h).
 * What it is not: model loading or file reading. */
#include "infer/raw.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
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

/* ---- raw-frame conventions ------------------------------------------------------------ */
int lm_raw_opts_any(const lm_raw_opts *o)
{
    return o->bits || o->msb || o->black != 0.0 || o->dark || o->flat;
}

/* The file's code of a value as lm_frame_read normalised it. */
static double code_of(const lm_frame *f, float v)
{
    return (double)v * ((1 << f->bits) - 1);
}

/* The full-scale code in the file's units and the divisor that makes B-bit codes of it. */
static void code_range(const lm_raw_opts *o, const lm_frame *f, double *full, double *unit)
{
    int b = o->bits ? o->bits : f->bits;
    *unit = o->bits && o->msb ? (double)(1 << (f->bits - b)) : 1.0;
    *full = (double)((1 << b) - 1);
}

/* f's values to B-bit codes (bits and alignment checked). */
static lm_status to_codes(const lm_raw_opts *o, lm_frame *f, const char *path, lm_err *err)
{
    if (f->is_float) {
        if (o->bits)
            return lm_err_set(err, LM_ERR_FORMAT, "%s: --bits is for integer files (this one "
                              "holds floats, read as they are)", path);
        return LM_OK;
    }
    if (o->bits > f->bits)
        return lm_err_set(err, LM_ERR_FORMAT, "%s: %d-bit file, --bits %d", path, f->bits,
                          o->bits);
    double full, unit;
    code_range(o, f, &full, &unit);
    const size_t n = (size_t)f->height * f->width;
    for (size_t i = 0; i < n; i++) {
        double c = floor(code_of(f, f->data[i]) + 0.5);
        if (o->bits && o->msb && fmod(c, unit) != 0.0)
            return lm_err_set(err, LM_ERR_FORMAT, "%s: pixel (%zu, %zu) reads %.0f, not a "
                              "multiple of %.0f: not %d-bit MSB-aligned data (LSB-aligned? drop "
                              "--msb)", path, i / f->width, i % f->width, c, unit, o->bits);
        c /= unit;
        if (c > full)
            return lm_err_set(err, LM_ERR_FORMAT, "%s: pixel (%zu, %zu) reads %.0f, above the "
                              "%d-bit range: MSB-aligned data? (add --msb)", path,
                              i / f->width, i % f->width, c, o->bits);
        f->data[i] = (float)c;
    }
    return LM_OK;
}

lm_status lm_raw_apply(const lm_raw *r, lm_frame *f, const char *path, lm_err *err)
{
    const lm_raw_opts *o = &r->o;
    if (!lm_raw_opts_any(o)) return LM_OK;
    lm_status st = to_codes(o, f, path, err);
    if (st) return st;
    double full = 1.0, unit;
    if (!f->is_float) code_range(o, f, &full, &unit);
    const double black = f->is_float ? o->black / full : o->black;
    const size_t n = (size_t)f->height * f->width;
    for (size_t i = 0; i < n; i++) {
        double x = ((double)f->data[i] - black) / (full - black);
        if (r->dark) x = (x - r->dark[i]) / (1.0 - r->dark_mean);
        if (r->gain) x /= r->gain[i];
        f->data[i] = (float)x;
    }
    return LM_OK;
}

double lm_raw_saturated(const lm_raw_opts *o, const lm_frame *f, uint8_t *mask)
{
    const size_t n = (size_t)f->height * f->width;
    double full = 1.0, unit = 1.0;
    if (!f->is_float) {
        code_range(o, f, &full, &unit);
        full *= unit; /* in the file's codes */
    }
    size_t k = 0;
    for (size_t i = 0; i < n; i++) {
        int s = f->is_float ? f->data[i] >= 1.0f : code_of(f, f->data[i]) >= full - 0.5;
        k += s;
        if (mask) mask[i] = (uint8_t)s;
    }
    return n ? (double)k / n : 0.0;
}

/* The average of every frame of spec, converted (r's options so far), into *out. */
static lm_status average(const lm_raw *r, const char *what, const char *spec, float **out,
                         lm_err *err)
{
    lm_frame_seq seq;
    *out = NULL;
    lm_status st = lm_frame_seq_open(spec, &seq, err);
    if (st) return st;
    const size_t n = (size_t)r->height * r->width;
    double *acc = calloc(n, sizeof *acc);
    if (!acc) st = lm_err_set(err, LM_ERR_NOMEM, "%s: out of memory", spec);
    if (!st && (seq.height != r->height || seq.width != r->width))
        st = lm_err_set(err, LM_ERR_SHAPE, "%s: %s frame is %d x %d, the frames %d x %d",
                        seq.paths[0], what, seq.width, seq.height, r->width, r->height);
    for (int k = 0; k < seq.count && !st; k++) {
        lm_frame f;
        if ((st = lm_frame_seq_read(&seq, k, &f, err))) break;
        st = lm_raw_apply(r, &f, seq.paths[k], err);
        for (size_t i = 0; i < n && !st; i++) acc[i] += f.data[i];
        lm_frame_free(&f);
    }
    float *avg = st ? NULL : malloc(sizeof(float) * n);
    if (!st && !avg) st = lm_err_set(err, LM_ERR_NOMEM, "%s: out of memory", spec);
    for (size_t i = 0; avg && i < n; i++) avg[i] = (float)(acc[i] / seq.count);
    free(acc);
    lm_frame_seq_free(&seq);
    *out = avg;
    return st;
}

/* The flat's per-pixel gain: each pixel over its phase's mean. */
static lm_status flat_gain(lm_raw *r, float *flat, lm_err *err)
{
    const int np = r->ty * r->tx;
    double sum[LM_SYSTEM_MAX_TILE] = {0};
    long cnt[LM_SYSTEM_MAX_TILE] = {0};
    for (int y = 0; y < r->height; y++)
        for (int x = 0; x < r->width; x++) {
            int t = (y % r->ty) * r->tx + x % r->tx;
            sum[t] += flat[(size_t)y * r->width + x];
            cnt[t]++;
        }
    for (int t = 0; t < np; t++)
        if (!(sum[t] > 0.0))
            return lm_err_set(err, LM_ERR_ARG, "%s: flat frame: tile phase (%d, %d) has no "
                              "signal (mean %g): not a lit white target", r->o.flat, t / r->tx,
                              t % r->tx, cnt[t] ? sum[t] / cnt[t] : 0.0);
    for (int y = 0; y < r->height; y++)
        for (int x = 0; x < r->width; x++) {
            int t = (y % r->ty) * r->tx + x % r->tx;
            float *g = &flat[(size_t)y * r->width + x];
            *g = (float)(*g / (sum[t] / cnt[t]));
            if (!(*g >= 0.05f)) *g = 1.0f, r->flat_skipped++;
        }
    r->gain = flat;
    return LM_OK;
}

/* Under 1 % of the flat's pixels saturated (a flat must not clip). */
static lm_status flat_saturation(const lm_raw *r, lm_err *err)
{
    lm_frame_seq seq;
    lm_status st = lm_frame_seq_open(r->o.flat, &seq, err);
    for (int k = 0; k < seq.count && !st; k++) {
        lm_frame f;
        if ((st = lm_frame_seq_read(&seq, k, &f, err))) break;
        double s = lm_raw_saturated(&r->o, &f, NULL);
        if (s > 0.01)
            st = lm_err_set(err, LM_ERR_ARG, "%s: flat frame: %.1f %% of the pixels saturated "
                            "(a flat must stay below full scale: shorter exposure)",
                            seq.paths[k], 100.0 * s);
        lm_frame_free(&f);
    }
    if (seq.count) lm_frame_seq_free(&seq);
    return st;
}

lm_status lm_raw_init(lm_raw *r, const lm_raw_opts *o, int height, int width, int ty, int tx,
                      lm_err *err)
{
    memset(r, 0, sizeof *r);
    r->height = height, r->width = width, r->ty = ty, r->tx = tx;
    if (o->bits < 0 || o->bits > 16)
        return lm_err_set(err, LM_ERR_ARG, "--bits %d: need 1..16", o->bits);
    if (o->msb && !o->bits) return lm_err_set(err, LM_ERR_ARG, "--msb needs --bits");
    double full = o->bits ? (double)((1 << o->bits) - 1) : 65535.0;
    if (!(o->black >= 0.0 && o->black < full))
        return lm_err_set(err, LM_ERR_ARG, "--black-level %g: need 0 up to below full scale "
                          "(%g)", o->black, full);
    if (o->black != 0.0 && o->dark)
        return lm_err_set(err, LM_ERR_ARG, "--black-level and --dark: give one (dark frames "
                          "hold the black level)");
    r->o = *o;
    r->o.dark = r->o.flat = NULL; /* the dark frames are read without themselves */
    float *dark = NULL, *flat = NULL;
    lm_status st = o->dark ? average(r, "dark", o->dark, &dark, err) : LM_OK;
    if (!st && dark) {
        double m = 0.0;
        for (size_t i = 0; i < (size_t)height * width; i++) m += dark[i];
        r->dark = dark;
        r->dark_mean = (float)(m / ((size_t)height * width));
        if (!(r->dark_mean < 0.5f))
            st = lm_err_set(err, LM_ERR_ARG, "%s: dark frames average %.0f %% of full scale: "
                            "not dark frames", o->dark, 100.0 * r->dark_mean);
    }
    r->o.dark = o->dark;
    if (!st && o->flat) {
        r->o.flat = o->flat;
        st = flat_saturation(r, err);
        r->o.flat = NULL;
        if (!st) st = average(r, "flat", o->flat, &flat, err);
        r->o.flat = o->flat;
        if (!st) st = flat_gain(r, flat, err);
        if (st) free(flat);
    }
    if (st) lm_raw_free(r);
    return st;
}

void lm_raw_free(lm_raw *r)
{
    free(r->dark);
    free(r->gain);
    memset(r, 0, sizeof *r);
}

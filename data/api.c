/* api.c — the public C API (include/lumosaic.h): status text, version, system descriptions,
 * cubes and their sRGB previews, simulation and metrics, each a thin layer over the library's
 * own functions (data/system.h, data/cube_io.h, data/srgb.h, data/forward.h, data/metrics.h)
 * that checks the arguments and turns the library's errors into the API's.
 * What it is not: models and reconstruction (infer/api.c). */
#include <math.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "data/api_internal.h"
#include "data/cube_io.h"
#include "data/forward.h"
#include "data/metrics.h"
#include "data/limits.h"
#include "data/spectra.h"
#include "data/srgb.h"
#include "tensor/rng.h"

_Static_assert(LM_API_OK == (int)LM_OK && LM_API_ERR_SHAPE == (int)LM_ERR_SHAPE &&
               LM_API_ERR_ARG == (int)LM_ERR_ARG && LM_API_ERR_NOMEM == (int)LM_ERR_NOMEM &&
               LM_API_ERR_IO == (int)LM_ERR_IO && LM_API_ERR_FORMAT == (int)LM_ERR_FORMAT &&
               LM_API_ERR_BACKEND == (int)LM_ERR_BACKEND &&
               LM_API_ERR_NUMERIC == (int)LM_ERR_NUMERIC &&
               LM_API_ERR_UNSUPPORTED == (int)LM_ERR_UNSUPPORTED &&
               LM_API_ERR_WRITE == (int)LM_ERR_WRITE,
               "the API's status codes are the library's");

#define STR_(x) #x
#define STR(x) STR_(x)

lm_api_status lm_api_fail(lm_api_error *err, lm_api_status s, const char *fmt, ...)
{
    if (!err) return s;
    err->status = s;
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(err->message, sizeof err->message, fmt, ap);
    va_end(ap);
    return s;
}

lm_api_status lm_api_from_err(const lm_err *e, lm_api_error *err)
{
    return lm_api_fail(err, (lm_api_status)e->status, "%s",
                       e->msg[0] ? e->msg : lm_status_str(e->status));
}

lm_api_status lm_api_ok(lm_api_error *err)
{
    if (err) err->status = LM_API_OK, err->message[0] = 0;
    return LM_API_OK;
}

const char *lm_api_status_str(lm_api_status s)
{
    return s == LM_API_OK ? "ok" : lm_status_str((lm_status)s);
}

const char *lm_api_version(int *major, int *minor, int *patch)
{
    if (major) *major = LM_API_VERSION_MAJOR;
    if (minor) *minor = LM_API_VERSION_MINOR;
    if (patch) *patch = LM_API_VERSION_PATCH;
    return STR(LM_API_VERSION_MAJOR) "." STR(LM_API_VERSION_MINOR) "." STR(LM_API_VERSION_PATCH);
}

/* ---- systems ---------------------------------------------------------------------------- */
lm_api_status lm_api_system_load(const char *path, lm_api_system **out, lm_api_error *err)
{
    if (!out) return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_system_load: out is NULL");
    *out = NULL;
    lm_api_system *s = calloc(1, sizeof *s);
    if (!s) return lm_api_fail(err, LM_API_ERR_NOMEM, "lm_api_system_load: out of memory");
    lm_err e;
    lm_err_clear(&e);
    if ((path && path[0]) ? lm_system_load(path, &s->sys, &e) : lm_system_default(&s->sys, &e)) {
        lm_system_free(&s->sys);
        free(s);
        return lm_api_from_err(&e, err);
    }
    *out = s;
    return lm_api_ok(err);
}

void lm_api_system_free(lm_api_system *sys)
{
    if (!sys) return;
    lm_system_free(&sys->sys);
    free(sys);
}

lm_api_status lm_api_system_info(const lm_api_system *sys, int *leds, int *tile_rows,
                                 int *tile_cols, lm_api_error *err)
{
    if (!sys) return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_system_info: sys is NULL");
    if (leds) *leds = sys->sys.nleds;
    if (tile_rows) *tile_rows = sys->sys.tile_rows;
    if (tile_cols) *tile_cols = sys->sys.tile_cols;
    return lm_api_ok(err);
}

/* ---- cubes ------------------------------------------------------------------------------ */
static lm_api_cube *cube_new(void)
{
    return calloc(1, sizeof(lm_api_cube));
}

lm_api_status lm_api_cube_read(const char *path, const char *mat_key, lm_api_cube **out,
                               lm_api_error *err)
{
    if (!out) return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_cube_read: out is NULL");
    *out = NULL;
    if (!path) return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_cube_read: path is NULL");
    lm_api_cube *c = cube_new();
    if (!c) return lm_api_fail(err, LM_API_ERR_NOMEM, "%s: out of memory", path);
    lm_cube_read_opts ro;
    lm_cube_read_opts_default(&ro);
    ro.mat_key = mat_key;
    lm_err e;
    lm_err_clear(&e);
    if (lm_cube_read_with(path, &ro, &c->cube, &e)) {
        free(c);
        return lm_api_from_err(&e, err);
    }
    *out = c;
    return lm_api_ok(err);
}

lm_api_status lm_api_cube_write(const char *path, const lm_api_cube *cube, lm_api_error *err)
{
    if (!path || !cube)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_cube_write: %s is NULL",
                           path ? "cube" : "path");
    lm_err e;
    lm_err_clear(&e);
    if (lm_cube_write_exr(path, &cube->cube, &e)) return lm_api_from_err(&e, err);
    return lm_api_ok(err);
}

lm_api_status lm_api_cube_create(int bands, int height, int width, const float *wavelengths,
                                 lm_api_cube **out, lm_api_error *err)
{
    if (!out) return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_cube_create: out is NULL");
    *out = NULL;
    if (bands < 1 || bands > LM_CUBE_MAX_BANDS || height < 1 || width < 1 ||
        height > LM_MAX_IMAGE_SIDE || width > LM_MAX_IMAGE_SIDE ||
        (long long)bands * height * width > LM_MAX_CUBE_VALUES)
        return lm_api_fail(err, LM_API_ERR_SHAPE, "lm_api_cube_create: %d x %d x %d: bands "
                           "1..%d, sizes 1..%d, at most %lld values", bands, height, width,
                           LM_CUBE_MAX_BANDS, LM_MAX_IMAGE_SIDE, (long long)LM_MAX_CUBE_VALUES);
    lm_api_cube *c = cube_new();
    if (!c || lm_cube_alloc(&c->cube, bands, height, width, 400.0f, 10.0f)) {
        free(c);
        return lm_api_fail(err, LM_API_ERR_NOMEM, "lm_api_cube_create: out of memory");
    }
    if (wavelengths) memcpy(c->cube.wavelength, wavelengths, sizeof(float) * bands);
    *out = c;
    return lm_api_ok(err);
}

lm_api_status lm_api_cube_crop(const lm_api_cube *cube, int y0, int x0, int height, int width,
                               lm_api_cube **out, lm_api_error *err)
{
    if (!out) return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_cube_crop: out is NULL");
    *out = NULL;
    if (!cube) return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_cube_crop: cube is NULL");
    const lm_cube *s = &cube->cube;
    if (y0 < 0 || x0 < 0 || height < 1 || width < 1 || height > s->height - y0 ||
        width > s->width - x0)
        return lm_api_fail(err, LM_API_ERR_SHAPE, "lm_api_cube_crop: rows %d..%d, columns "
                           "%d..%d are not inside the %d x %d cube", y0, y0 + height - 1, x0,
                           x0 + width - 1, s->height, s->width);
    lm_api_status st = lm_api_cube_create(s->bands, height, width, s->wavelength, out, err);
    if (st) return st;
    lm_cube *d = &(*out)->cube;
    for (int b = 0; b < s->bands; b++)
        for (int y = 0; y < height; y++)
            memcpy(lm_cube_band(d, b) + (size_t)y * width,
                   lm_cube_band(s, b) + (size_t)(y0 + y) * s->width + x0, sizeof(float) * width);
    return LM_API_OK;
}

void lm_api_cube_free(lm_api_cube *cube)
{
    if (!cube) return;
    lm_cube_free(&cube->cube);
    free(cube);
}

lm_api_status lm_api_cube_shape(const lm_api_cube *cube, int *bands, int *height, int *width,
                                lm_api_error *err)
{
    if (!cube) return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_cube_shape: cube is NULL");
    if (bands) *bands = cube->cube.bands;
    if (height) *height = cube->cube.height;
    if (width) *width = cube->cube.width;
    return lm_api_ok(err);
}

float *lm_api_cube_data(lm_api_cube *cube)
{
    return cube ? cube->cube.data : NULL;
}

const float *lm_api_cube_wavelengths(const lm_api_cube *cube)
{
    return cube ? cube->cube.wavelength : NULL;
}

lm_api_status lm_api_cube_srgb(const lm_api_cube *cube, float exposure, float *rgb, size_t n,
                               lm_api_error *err)
{
    if (!cube || !rgb)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_cube_srgb: %s is NULL",
                           !cube ? "cube" : "rgb");
    const lm_cube *c = &cube->cube;
    if (n < (size_t)3 * c->height * c->width)
        return lm_api_fail(err, LM_API_ERR_SHAPE, "lm_api_cube_srgb: a buffer of %zu values "
                           "for a %d x %d x 3 image", n, c->height, c->width);
    lm_err e;
    lm_err_clear(&e);
    if (lm_srgb_render_cube(c, exposure, NULL, rgb, &e)) return lm_api_from_err(&e, err);
    return lm_api_ok(err);
}

/* ---- simulation ------------------------------------------------------------------------- */
lm_api_status lm_api_simulate(const lm_api_system *sys, const lm_api_cube *cube,
                              const lm_api_noise *noise, uint64_t seed, int threads,
                              float *bucket1, float *bucket0, size_t n, lm_api_error *err)
{
    if (!sys || !cube || !bucket1)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_simulate: %s is NULL",
                           !sys ? "sys" : !cube ? "cube" : "bucket1");
    const lm_cube *c = &cube->cube;
    if (n < (size_t)c->height * c->width)
        return lm_api_fail(err, LM_API_ERR_SHAPE, "lm_api_simulate: buffers of %zu values for "
                           "a %d x %d frame", n, c->height, c->width);
    if (threads < 0 || threads > 1024)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_simulate: threads %d (0..1024)",
                           threads);
    lm_forward_opts fo = {.nthreads = threads};
    if (noise)
        fo.noise = (lm_noise_opts){(float)noise->gauss_k, noise->photons,
                                   (float)noise->read_noise, noise->clip, noise->bits, 0.0f};
    lm_rng rng;
    lm_rng_seed(&rng, seed);
    lm_err e;
    lm_err_clear(&e);
    const lm_system *s = &sys->sys;
    lm_status st = c->bands == LM_GRID31_COUNT
                       ? lm_forward_simulate31(s, c, &fo, &rng, bucket1, bucket0, &e)
                       : lm_forward_simulate(s, c, &fo, &rng, bucket1, bucket0, &e);
    if (st) return lm_api_from_err(&e, err);
    if (bucket0 && s->nleds > 1) { /* stored / (LEDs - 1), as `simulate --bucket0` writes it */
        const float f = (float)(1.0 / (s->nleds - 1));
        for (size_t i = 0; i < (size_t)c->height * c->width; i++) bucket0[i] *= f;
    }
    return lm_api_ok(err);
}

/* ---- metrics ---------------------------------------------------------------------------- */
lm_api_status lm_api_metrics_compute(const float *pred, const float *truth, int bands,
                                     int height, int width, lm_api_metrics *out,
                                     lm_api_error *err)
{
    if (!pred || !truth || !out)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_metrics_compute: %s is NULL",
                           !pred ? "pred" : !truth ? "truth" : "out");
    if (bands < 1 || height < 1 || width < 1)
        return lm_api_fail(err, LM_API_ERR_SHAPE, "lm_api_metrics_compute: size %d x %d x %d",
                           bands, height, width);
    const size_t n = (size_t)bands * height * width;
    for (int k = 0; k < 2; k++) {
        const float *a = k ? truth : pred;
        for (size_t i = 0; i < n; i++)
            if (!isfinite(a[i]))
                return lm_api_fail(err, LM_API_ERR_NUMERIC, "lm_api_metrics_compute: %s holds "
                                   "%g at band %zu, row %zu, column %zu", k ? "truth" : "pred",
                                   (double)a[i], i / ((size_t)height * width),
                                   i / width % height, i % width);
    }
    lm_metrics m;
    lm_err e;
    lm_err_clear(&e);
    if (lm_metrics_compute(pred, truth, bands, height, width, 0, bands, &m, &e))
        return lm_api_from_err(&e, err);
    *out = (lm_api_metrics){m.psnr, m.ssim, m.mae, m.sam};
    return lm_api_ok(err);
}

/* api.c — the public C API's models and reconstruction (include/lumosaic.h): a model loaded by
 * lm_infer_model_load with a compute context of its own, and one frame from memory buffers
 * (16-bit or float, one or two buckets) through lm_recon_frame, the path `lumosaic infer`
 * takes, clamped at 0 as infer writes it (or not, as eval scores it).
 * What it is not: systems, cubes, simulation or metrics (data/api.c); alignment of sequences
 * or the per-window model choice (`lumosaic infer` only). */
#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>
#include "data/api_internal.h"
#include "data/limits.h"
#include "infer/model_io.h"
#include "infer/recon.h"

struct lm_api_model {
    lm_infer_model im;
    lm_ctx ctx;
    lm_recon_opts ro;
    int threads; /* 0 = all cores */
    int clamp;   /* outputs below 0 set to 0 */
    float *in;   /* the model's input planes for one frame (grown as needed) */
    size_t in_cap;
};

lm_api_status lm_api_model_load(const char *path, const lm_api_system *sys,
                                lm_api_model **out, lm_api_error *err)
{
    if (!out) return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_load: out is NULL");
    *out = NULL;
    if (!path) return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_load: path is NULL");
    lm_api_model *m = calloc(1, sizeof *m);
    if (!m) return lm_api_fail(err, LM_API_ERR_NOMEM, "%s: out of memory", path);
    lm_err e;
    lm_err_clear(&e);
    if (lm_infer_model_load(path, sys ? sys->sys.path : NULL, &m->im, &e)) {
        free(m);
        return lm_api_from_err(&e, err);
    }
    if (lm_ctx_init(&m->ctx, 0)) {
        lm_infer_model_free(&m->im);
        free(m);
        return lm_api_fail(err, LM_API_ERR_NOMEM, "%s: out of memory (compute context)", path);
    }
    lm_recon_default_opts(&m->ro);
    m->clamp = 1;
    m->im.model->noise_given = -1.0f;
    *out = m;
    return lm_api_ok(err);
}

void lm_api_model_free(lm_api_model *model)
{
    if (!model) return;
    lm_ctx_free(&model->ctx);
    lm_infer_model_free(&model->im);
    free(model->in);
    free(model);
}

lm_api_status lm_api_model_info(const lm_api_model *model, const char **preset, int *buckets,
                                int *tile_rows, int *tile_cols, lm_api_error *err)
{
    if (!model) return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_info: model is NULL");
    const lm_model *m = model->im.model;
    if (preset) *preset = m->preset;
    if (buckets) *buckets = lm_model_buckets(m);
    if (tile_rows) *tile_rows = m->mosaic.ty;
    if (tile_cols) *tile_cols = m->mosaic.tx;
    return lm_api_ok(err);
}

lm_api_status lm_api_model_set_threads(lm_api_model *model, int threads, lm_api_error *err)
{
    if (!model)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_set_threads: model is NULL");
    if (threads < 0 || threads > LM_MAX_THREADS)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_set_threads: %d threads "
                           "(0..%d; 0 = all cores)", threads, LM_MAX_THREADS);
    model->threads = threads;
    model->ctx.nthreads = threads > 0 ? threads : omp_get_num_procs();
    return lm_api_ok(err);
}

lm_api_status lm_api_model_set_noise_level(lm_api_model *model, double level,
                                           lm_api_error *err)
{
    if (!model)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_set_noise_level: model is NULL");
    if (!(level <= 1.0)) /* NaN too */
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_set_noise_level: level %g (0..1,"
                           " or negative to estimate it)", level);
    model->im.model->noise_given = level < 0 ? -1.0f : (float)level;
    return lm_api_ok(err);
}

lm_api_status lm_api_model_set_patchwise(lm_api_model *model, int patchwise,
                                         lm_api_error *err)
{
    if (!model)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_set_patchwise: model is NULL");
    model->ro.tiles = patchwise != 0;
    return lm_api_ok(err);
}

lm_api_status lm_api_model_set_precision(lm_api_model *model, lm_api_precision precision,
                                         lm_api_error *err)
{
    if (!model)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_set_precision: model is NULL");
    if (precision != LM_API_PRECISION_FP32 && precision != LM_API_PRECISION_BF16)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_set_precision: precision %d (one "
                           "of LM_API_PRECISION_FP32, LM_API_PRECISION_BF16)", (int)precision);
    model->ctx.precision = precision == LM_API_PRECISION_BF16 ? LM_PRECISION_BF16
                                                             : LM_PRECISION_FP32;
    return lm_api_ok(err);
}

lm_api_status lm_api_model_set_clamp(lm_api_model *model, int clamp, lm_api_error *err)
{
    if (!model)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_set_clamp: model is NULL");
    model->clamp = clamp != 0;
    return lm_api_ok(err);
}

/* Check the frame against the model; 0 or the status (err set). */
static lm_api_status check_frame(const lm_api_model *model, const lm_api_frame *f,
                                 lm_api_error *err)
{
    const lm_model *m = model->im.model;
    if (!f->bucket1)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_reconstruct: frame->bucket1 is NULL");
    if (f->type != LM_API_PIXEL_U16 && f->type != LM_API_PIXEL_F32)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_reconstruct: frame->type %d (one of "
                           "LM_API_PIXEL_U16, LM_API_PIXEL_F32)", (int)f->type);
    if (f->height < 1 || f->width < 1 || f->height > LM_MAX_IMAGE_SIDE ||
        f->width > LM_MAX_IMAGE_SIDE || (long long)f->height * f->width > LM_MAX_FRAME_PIXELS)
        return lm_api_fail(err, LM_API_ERR_SHAPE, "lm_api_reconstruct: frame %d x %d (at most "
                           "%lld pixels)", f->width, f->height, (long long)LM_MAX_FRAME_PIXELS);
    if (lm_model_has(m, LM_CAP_RGB_INPUT) || lm_model_frames(m) != 1)
        return lm_api_fail(err, LM_API_ERR_UNSUPPORTED, "model %s reads %s: one coded frame is "
                           "not its input", m->preset, lm_model_frames(m) != 1
                           ? "three frames of a video" : "an RGB image");
    const int two = lm_model_buckets(m) == 2;
    if (two && !f->bucket0)
        return lm_api_fail(err, LM_API_ERR_ARG, "model %s reads both buckets: frame->bucket0 "
                           "is NULL", m->preset);
    if (!two && f->bucket0)
        return lm_api_fail(err, LM_API_ERR_ARG, "model %s reads bucket 1 only: frame->bucket0 "
                           "must be NULL", m->preset);
    lm_err e;
    lm_err_clear(&e);
    if (lm_recon_check(m, f->height, f->width, &e)) return lm_api_from_err(&e, err);
    if (f->type == LM_API_PIXEL_F32)
        for (int k = 0; k < 1 + two; k++) {
            const float *p = k ? f->bucket0 : f->bucket1;
            for (size_t i = 0; i < (size_t)f->height * f->width; i++)
                if (!isfinite(p[i]))
                    return lm_api_fail(err, LM_API_ERR_NUMERIC, "lm_api_reconstruct: frame->%s "
                                       "holds %g at row %zu, column %zu", k ? "bucket0" :
                                       "bucket1", (double)p[i], i / f->width, i % f->width);
        }
    return LM_API_OK;
}

/* The model's input planes (bucket 1, then bucket 0) as floats; *in points at them (the
 * caller's buffer itself for one float plane). */
static lm_api_status frame_input(lm_api_model *model, const lm_api_frame *f, const float **in,
                                 lm_api_error *err)
{
    const size_t n = (size_t)f->height * f->width;
    const int planes = f->bucket0 ? 2 : 1;
    if (f->type == LM_API_PIXEL_F32 && planes == 1) {
        *in = f->bucket1;
        return LM_API_OK;
    }
    if (model->in_cap < planes * n) {
        float *p = realloc(model->in, sizeof(float) * planes * n);
        if (!p) return lm_api_fail(err, LM_API_ERR_NOMEM, "lm_api_reconstruct: out of memory "
                                   "(%d x %d frame)", f->width, f->height);
        model->in = p;
        model->in_cap = planes * n;
    }
    for (int k = 0; k < planes; k++) {
        const void *src = k ? f->bucket0 : f->bucket1;
        float *dst = model->in + k * n;
        if (f->type == LM_API_PIXEL_F32) {
            memcpy(dst, src, sizeof(float) * n);
        } else { /* as the frame readers normalise 16-bit samples */
            const uint16_t *u = src;
            for (size_t i = 0; i < n; i++) dst[i] = (float)u[i] / 65535.0f;
        }
    }
    *in = model->in;
    return LM_API_OK;
}

/* The frame to a new 31-band cube (clamped at 0 unless the model says not to). */
static lm_api_status reconstruct(lm_api_model *model, const lm_api_frame *f, lm_cube *cube,
                                 lm_api_error *err)
{
    memset(cube, 0, sizeof *cube);
    const float *in = NULL;
    lm_api_status st = check_frame(model, f, err);
    if (!st) st = frame_input(model, f, &in, err);
    if (st) return st;
    lm_err e;
    lm_err_clear(&e);
    lm_ctx_clear_error(&model->ctx);
    const int prev = omp_get_max_threads(); /* this thread's OpenMP default, restored below */
    omp_set_num_threads(model->ctx.nthreads);
    lm_status ls = lm_recon_camera_frame(&model->ctx, &model->im, in, f->height, f->width,
                                         &model->ro, cube, &e);
    omp_set_num_threads(prev);
    lm_ctx_reset(&model->ctx);
    lm_ctx_clear_error(&model->ctx);
    if (ls) return lm_api_from_err(&e, err);
    if (model->clamp) lm_recon_clamp(cube);
    return LM_API_OK;
}

lm_api_status lm_api_reconstruct(lm_api_model *model, const lm_api_frame *frame, float *cube,
                                 size_t n, float *wavelengths, lm_api_error *err)
{
    if (!model || !frame || !cube)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_reconstruct: %s is NULL",
                           !model ? "model" : !frame ? "frame" : "cube");
    if (frame->height > 0 && frame->width > 0 &&
        n < (size_t)31 * (size_t)frame->height * (size_t)frame->width)
        return lm_api_fail(err, LM_API_ERR_SHAPE, "lm_api_reconstruct: a buffer of %zu values "
                           "for a 31 x %d x %d cube", n, frame->height, frame->width);
    lm_cube c;
    lm_api_status st = reconstruct(model, frame, &c, err);
    if (st) return st;
    memcpy(cube, c.data, sizeof(float) * c.bands * c.height * c.width);
    if (wavelengths) memcpy(wavelengths, c.wavelength, sizeof(float) * c.bands);
    lm_cube_free(&c);
    return lm_api_ok(err);
}

lm_api_status lm_api_reconstruct_cube(lm_api_model *model, const lm_api_frame *frame,
                                      lm_api_cube **out, lm_api_error *err)
{
    if (!out) return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_reconstruct_cube: out is NULL");
    *out = NULL;
    if (!model || !frame)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_reconstruct_cube: %s is NULL",
                           !model ? "model" : "frame");
    lm_api_cube *c = calloc(1, sizeof *c);
    if (!c) return lm_api_fail(err, LM_API_ERR_NOMEM, "lm_api_reconstruct_cube: out of memory");
    lm_api_status st = reconstruct(model, frame, &c->cube, err);
    if (st) {
        free(c);
        return st;
    }
    *out = c;
    return lm_api_ok(err);
}

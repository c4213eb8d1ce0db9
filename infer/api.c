/* api.c — the public C API's models and reconstruction (include/lumosaic.h): a model is a frame
 * pipeline without frames (infer/pipeline.h: a model file, the bundled model, or a calibrated
 * per-window choice, with a compute context of its own); one frame from memory buffers (16-bit
 * or float, one or two buckets) through the run's path, or a sequence attached as a frame source
 * (aligned in time, stacked for multi-frame models), the path `lumosaic infer` takes, clamped at
 * 0 as infer writes it (or not, as eval scores it).
 * What it is not: systems, cubes, simulation or metrics (data/api.c); reading frame files, raw
 * camera conversion or writing outputs (`lumosaic infer`). */
#include <math.h>
#include <omp.h>
#include <stdlib.h>
#include <string.h>
#include "data/api_internal.h"
#include "data/limits.h"
#include "infer/average.h"
#include "infer/convert.h"
#include "infer/pipeline.h"
#include "infer/recon.h"

struct lm_api_model {
    lm_pipe *p;  /* the model(s), context and options; frames attached per sequence */
    int threads; /* 0 = all cores */
    int clamp;   /* outputs below 0 set to 0 */
    float *in;   /* the model's input planes for one frame (grown as needed) */
    size_t in_cap;
};

/* A model from pipeline options (what: the caller's name for messages). */
static lm_api_status model_open(lm_pipe_opts *po, const lm_api_system *sys, const char *what,
                                lm_api_model **out, lm_api_error *err)
{
    lm_api_model *m = calloc(1, sizeof *m);
    if (!m) return lm_api_fail(err, LM_API_ERR_NOMEM, "%s: out of memory", what);
    po->system = sys ? sys->sys.path : NULL;
    po->device = "cpu";
    lm_err e;
    lm_err_clear(&e);
    if (lm_pipe_open(po, &m->p, &e)) {
        free(m);
        return lm_api_from_err(&e, err);
    }
    m->clamp = 1;
    *out = m;
    return lm_api_ok(err);
}

lm_api_status lm_api_model_load(const char *path, const lm_api_system *sys,
                                lm_api_model **out, lm_api_error *err)
{
    if (!out) return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_load: out is NULL");
    *out = NULL;
    if (!path) return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_load: path is NULL");
    if (!strcmp(path, "auto"))
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_load: \"auto\" is "
                           "lm_api_model_load_bundled or lm_api_model_load_auto");
    lm_pipe_opts po;
    lm_pipe_default_opts(&po);
    po.model = path;
    return model_open(&po, sys, path, out, err);
}

lm_api_status lm_api_model_average(const char *const *paths, int n, const char *out_path,
                                   lm_api_error *err)
{
    if (!paths || !out_path)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_average: paths or out_path is "
                           "NULL");
    for (int i = 0; i < n && n <= LM_AVERAGE_MAX; i++)
        if (!paths[i])
            return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_average: paths[%d] is NULL",
                               i);
    lm_err e;
    lm_err_clear(&e);
    if (lm_model_average(paths, n, out_path, &e)) return lm_api_from_err(&e, err);
    return lm_api_ok(err);
}

lm_api_status lm_api_model_convert(const char *in_path, const char *out_path, int fp16,
                                   lm_api_error *err)
{
    if (!in_path || !out_path)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_convert: in_path or out_path is "
                           "NULL");
    lm_err e;
    lm_err_clear(&e);
    if (lm_model_convert(in_path, out_path, fp16 ? LM_STORE_F16 : LM_STORE_F32, NULL, &e))
        return lm_api_from_err(&e, err);
    return lm_api_ok(err);
}

lm_api_status lm_api_model_load_bundled(int buckets, const lm_api_system *sys,
                                        lm_api_model **out, lm_api_error *err)
{
    if (!out) return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_load_bundled: out is NULL");
    *out = NULL;
    if (buckets != 1 && buckets != 2)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_load_bundled: %d buckets (1 or "
                           "2)", buckets);
    lm_pipe_opts po;
    lm_pipe_default_opts(&po);
    po.model = "auto";
    po.bundled_buckets = buckets;
    return model_open(&po, sys, "bundled model", out, err);
}

lm_api_status lm_api_model_load_auto(const char *calibration, double tol_db,
                                     const lm_api_system *sys, lm_api_model **out,
                                     lm_api_error *err)
{
    if (!out) return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_load_auto: out is NULL");
    *out = NULL;
    if (!calibration)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_load_auto: calibration is NULL");
    if (!(tol_db >= 0.0 && tol_db <= 1e6)) /* NaN too */
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_load_auto: tolerance %g dB "
                           "(0..1e6)", tol_db);
    lm_pipe_opts po;
    lm_pipe_default_opts(&po);
    po.model = "auto";
    po.auto_file = calibration;
    po.auto_tol = tol_db;
    return model_open(&po, sys, calibration, out, err);
}

void lm_api_model_free(lm_api_model *model)
{
    if (!model) return;
    lm_pipe_close(model->p);
    free(model->in);
    free(model);
}

lm_api_status lm_api_model_info(const lm_api_model *model, const char **preset, int *buckets,
                                int *tile_rows, int *tile_cols, lm_api_error *err)
{
    if (!model) return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_info: model is NULL");
    const lm_model *m = model->p->im.model;
    if (preset) *preset = model->p->is_auto ? "auto" : m->preset;
    if (buckets) *buckets = lm_model_buckets(m); /* auto: its calibration's models' */
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
    model->p->o.threads = threads;
    model->p->ctx.nthreads = threads > 0 ? threads : omp_get_num_procs();
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
    lm_pipe *p = model->p;
    p->o.noise_level = level < 0 ? -1.0 : level;
    for (int k = 0; k < (p->is_auto ? p->cal.nmodels : 1); k++)
        (k ? p->more[k].model : p->im.model)->noise_given = (float)p->o.noise_level;
    return lm_api_ok(err);
}

lm_api_status lm_api_model_set_patchwise(lm_api_model *model, int patchwise,
                                         lm_api_error *err)
{
    if (!model)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_model_set_patchwise: model is NULL");
    model->p->o.tiles = patchwise != 0;
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
    model->p->ctx.precision = precision == LM_API_PRECISION_BF16 ? LM_PRECISION_BF16
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

/* Check the frame against the model (fn: the caller's name; seq: a frame of a sequence, so
 * multi-frame models take it); 0 or the status (err set). */
static lm_api_status check_frame(const lm_api_model *model, const lm_api_frame *f,
                                 const char *fn, int seq, lm_api_error *err)
{
    const lm_model *m = model->p->im.model;
    if (!f->bucket1) return lm_api_fail(err, LM_API_ERR_ARG, "%s: frame->bucket1 is NULL", fn);
    if (f->type != LM_API_PIXEL_U16 && f->type != LM_API_PIXEL_F32)
        return lm_api_fail(err, LM_API_ERR_ARG, "%s: frame->type %d (one of LM_API_PIXEL_U16, "
                           "LM_API_PIXEL_F32)", fn, (int)f->type);
    if (f->height < 1 || f->width < 1 || f->height > LM_MAX_IMAGE_SIDE ||
        f->width > LM_MAX_IMAGE_SIDE || (long long)f->height * f->width > LM_MAX_FRAME_PIXELS)
        return lm_api_fail(err, LM_API_ERR_SHAPE, "%s: frame %d x %d (at most %lld pixels)", fn,
                           f->width, f->height, (long long)LM_MAX_FRAME_PIXELS);
    if (lm_model_has(m, LM_CAP_RGB_INPUT) || (!seq && lm_model_frames(m) != 1))
        return lm_api_fail(err, LM_API_ERR_UNSUPPORTED, "model %s reads %s: one coded frame is "
                           "not its input", m->preset, lm_model_frames(m) != 1
                           ? "three frames of a video (lm_api_reconstruct_sequence)"
                           : "an RGB image");
    const int two = lm_model_buckets(m) == 2;
    if (two && !f->bucket0)
        return lm_api_fail(err, LM_API_ERR_ARG, "model %s reads both buckets: frame->bucket0 "
                           "is NULL", model->p->is_auto ? "auto" : m->preset);
    if (!two && f->bucket0)
        return lm_api_fail(err, LM_API_ERR_ARG, "model %s reads bucket 1 only: frame->bucket0 "
                           "must be NULL", model->p->is_auto ? "auto" : m->preset);
    lm_err e;
    lm_err_clear(&e);
    if (lm_recon_check(m, f->height, f->width, &e)) return lm_api_from_err(&e, err);
    if (f->type == LM_API_PIXEL_F32)
        for (int k = 0; k < 1 + two; k++) {
            const float *p = k ? f->bucket0 : f->bucket1;
            for (size_t i = 0; i < (size_t)f->height * f->width; i++)
                if (!isfinite(p[i]))
                    return lm_api_fail(err, LM_API_ERR_NUMERIC, "%s: frame->%s holds %g at row "
                                       "%zu, column %zu", fn, k ? "bucket0" : "bucket1",
                                       (double)p[i], i / f->width, i % f->width);
        }
    return LM_API_OK;
}

/* One plane of a frame as floats (16-bit samples normalised as the frame readers do). */
static void plane_to_float(const lm_api_frame *f, const void *src, float *dst)
{
    const size_t n = (size_t)f->height * f->width;
    if (f->type == LM_API_PIXEL_F32) {
        memcpy(dst, src, sizeof(float) * n);
    } else {
        const uint16_t *u = src;
        for (size_t i = 0; i < n; i++) dst[i] = (float)u[i] / 65535.0f;
    }
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
    for (int k = 0; k < planes; k++) plane_to_float(f, k ? f->bucket0 : f->bucket1,
                                                    model->in + k * n);
    *in = model->in;
    return LM_API_OK;
}

/* Before a reconstruction: the model's threads for this thread's OpenMP calls; returns the
 * thread's own default, for after(). */
static int before(lm_api_model *model)
{
    lm_ctx_clear_error(&model->p->ctx);
    const int prev = omp_get_max_threads();
    omp_set_num_threads(model->p->ctx.nthreads);
    return prev;
}

static void after(lm_api_model *model, int prev)
{
    omp_set_num_threads(prev);
    lm_ctx_reset(&model->p->ctx);
    lm_ctx_clear_error(&model->p->ctx);
}

/* The frame to a new 31-band cube (clamped at 0 unless the model says not to). */
static lm_api_status reconstruct(lm_api_model *model, const lm_api_frame *f, lm_cube *cube,
                                 lm_api_error *err)
{
    memset(cube, 0, sizeof *cube);
    const float *in = NULL;
    lm_api_status st = check_frame(model, f, "lm_api_reconstruct", 0, err);
    if (!st) st = frame_input(model, f, &in, err);
    if (st) return st;
    lm_err e;
    lm_err_clear(&e);
    const int prev = before(model);
    lm_status ls = lm_pipe_reconstruct(model->p, in, f->height, f->width, cube, &e);
    after(model, prev);
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

/* ---- sequences: the caller's frames as a frame source --------------------------------- */
typedef struct mem_src {
    const lm_api_frame *frames;
    int bucket0;   /* the planes read: bucket1 (0) or bucket0 (1) */
    char name[64]; /* the last name given */
} mem_src;

static lm_status mem_read(void *self, int i, lm_frame *f, lm_err *e)
{
    const mem_src *s = self;
    const lm_api_frame *fr = &s->frames[i];
    *f = (lm_frame){.height = fr->height, .width = fr->width,
                    .bits = fr->type == LM_API_PIXEL_U16 ? 16 : 32,
                    .is_float = fr->type == LM_API_PIXEL_F32};
    f->data = malloc(sizeof(float) * (size_t)fr->height * fr->width);
    if (!f->data) return lm_err_set(e, LM_ERR_NOMEM, "frame %d: out of memory", i);
    plane_to_float(fr, s->bucket0 ? fr->bucket0 : fr->bucket1, f->data);
    return LM_OK;
}

static const char *mem_name(void *self, int i)
{
    mem_src *s = self;
    snprintf(s->name, sizeof s->name, "frame %d%s", i, s->bucket0 ? " (bucket 0)" : "");
    return s->name;
}

/* Every frame checked and of frame 0's size and type. */
static lm_api_status check_sequence(const lm_api_model *model, const lm_api_frame *frames,
                                    int count, size_t n, lm_api_error *err)
{
    const char *fn = "lm_api_reconstruct_sequence";
    for (int i = 0; i < count; i++) {
        const lm_api_frame *f = &frames[i];
        lm_api_error fe;
        lm_api_status st = check_frame(model, f, fn, 1, &fe);
        if (st) return lm_api_fail(err, st, "frame %d: %s", i, fe.message);
        if (f->height != frames[0].height || f->width != frames[0].width ||
            f->type != frames[0].type)
            return lm_api_fail(err, LM_API_ERR_SHAPE, "%s: frame %d is %d x %d (type %d), "
                               "frame 0 %d x %d (type %d)", fn, i, f->width, f->height,
                               (int)f->type, frames[0].width, frames[0].height,
                               (int)frames[0].type);
    }
    const size_t need = (size_t)count * 31 * frames[0].height * frames[0].width;
    if (n < need)
        return lm_api_fail(err, LM_API_ERR_SHAPE, "%s: a buffer of %zu values for %d cubes of "
                           "31 x %d x %d", fn, n, count, frames[0].height, frames[0].width);
    return LM_API_OK;
}

/* The attached frames into cube (count x 31 x H x W), clamped unless the model says not to. */
static lm_status run_sequence(lm_api_model *model, int count, float *cube, float *wl,
                              lm_err *e)
{
    for (int i = 0; i < count; i++) {
        lm_cube c;
        if (lm_pipe_frame(model->p, i, &c, NULL, e)) return e->status;
        if (model->clamp) lm_recon_clamp(&c);
        const size_t nc = (size_t)c.bands * c.height * c.width;
        memcpy(cube + (size_t)i * nc, c.data, sizeof(float) * nc);
        if (wl && i == 0) memcpy(wl, c.wavelength, sizeof(float) * c.bands);
        lm_cube_free(&c);
        lm_ctx_reset(&model->p->ctx);
    }
    return LM_OK;
}

lm_api_status lm_api_reconstruct_sequence(lm_api_model *model, const lm_api_frame *frames,
                                          int count, int align, float *cube, size_t n,
                                          float *wavelengths, lm_api_error *err)
{
    if (!model || !frames || !cube)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_reconstruct_sequence: %s is NULL",
                           !model ? "model" : !frames ? "frames" : "cube");
    if (count < 1)
        return lm_api_fail(err, LM_API_ERR_ARG, "lm_api_reconstruct_sequence: %d frames (at "
                           "least 1)", count);
    lm_api_status st = check_sequence(model, frames, count, n, err);
    if (st) return st;
    mem_src s1 = {.frames = frames}, s0 = {.frames = frames, .bucket0 = 1};
    lm_frame_src src = {.count = count, .height = frames[0].height, .width = frames[0].width,
                        .self = &s1, .read = mem_read, .name = mem_name};
    lm_frame_src src0 = src;
    src0.self = &s0;
    lm_err e;
    lm_err_clear(&e);
    const int prev = before(model);
    model->p->o.no_align = !align;
    lm_status ls = lm_pipe_attach(model->p, &src, frames[0].bucket0 ? &src0 : NULL, &e);
    if (!ls) ls = run_sequence(model, count, cube, wavelengths, &e);
    lm_pipe_detach(model->p);
    after(model, prev);
    return ls ? lm_api_from_err(&e, err) : lm_api_ok(err);
}

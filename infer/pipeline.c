/* pipeline.c — opening and closing a frame pipeline (infer/pipeline.h): the model (a path,
 * the bundled one, or a calibrated per-window choice), the frames (files or sources), bucket 0,
 * the raw-camera conversion, the checks, the compute context and device.
 * What it is not: the per-frame work, alignment and stacking (pipeline_frame.c). */
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include "infer/pipeline.h"
#include "infer/pipeline_internal.h"
#include "infer/recon.h"
#include "tensor/isa.h"

void lm_pipe_default_opts(lm_pipe_opts *o)
{
    memset(o, 0, sizeof *o);
    o->auto_tol = 0.5;
    o->noise_level = -1.0;
    o->batch = 8;
}

void lm_pipe_say(const lm_pipe *p, lm_pipe_note kind, const char *fmt, ...)
{
    if (!p->o.msg) return;
    char line[3200];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(line, sizeof line, fmt, ap);
    va_end(ap);
    p->o.msg(p->o.msg_user, kind, line);
}

lm_status lm_pipe_restate(lm_err *e, const char *prefix)
{
    char msg[sizeof e->msg];
    snprintf(msg, sizeof msg, "%s", e->msg);
    lm_status st = e->status;
    lm_err_clear(e);
    return lm_err_set(e, st, "%s: %s", prefix, msg);
}

static lm_status seq_read(void *self, int i, lm_frame *f, lm_err *e)
{
    return lm_frame_seq_read(self, i, f, e);
}

static const char *seq_name(void *self, int i)
{
    return ((const lm_frame_seq *)self)->paths[i];
}

void lm_frame_src_from_seq(lm_frame_src *s, lm_frame_seq *seq)
{
    *s = (lm_frame_src){.count = seq->count, .height = seq->height, .width = seq->width,
                        .first_index = seq->first_index, .self = seq, .read = seq_read,
                        .name = seq_name};
}

/* A calibration: its models (model 0 into p->im), the choice per bin. */
static lm_status open_auto(lm_pipe *p, lm_err *e)
{
    lm_auto_calib *a = &p->cal;
    if (lm_infer_auto_load(p->o.auto_file, p->o.system, a, &p->im, p->more, p->models, e))
        return e->status;
    lm_auto_choose(a, p->o.auto_tol, p->choice);
    snprintf(p->model_path, sizeof p->model_path, "%s", p->o.auto_file);
    return LM_OK;
}

/* The model: a calibration's, the bundled one for `buckets` buckets ("auto"), or a path. */
static lm_status open_models(lm_pipe *p, int buckets, lm_err *e)
{
    if (!p->o.model) return lm_err_set(e, LM_ERR_ARG, "no model given");
    const int is_auto_name = !strcmp(p->o.model, "auto");
    p->is_auto = is_auto_name && p->o.auto_file;
    if (p->o.auto_file && !is_auto_name)
        return lm_err_set(e, LM_ERR_ARG, "a calibration is only for the model \"auto\"");
    if (p->is_auto) return open_auto(p, e);
    if (is_auto_name) {
        if (lm_infer_bundled_model(buckets, p->model_path, sizeof p->model_path, e))
            return e->status;
    } else {
        snprintf(p->model_path, sizeof p->model_path, "%s", p->o.model);
    }
    if (lm_infer_model_load(p->model_path, p->o.system, &p->im, e)) return e->status;
    p->im.model->noise_given = (float)p->o.noise_level;
    return LM_OK;
}

/* Bucket 1's frames: the saturation record, the raw-camera conversion, the gain remap note. */
static lm_status attach_frames(lm_pipe *p, const lm_frame_src *src, int files, lm_err *e)
{
    p->src = *src;
    p->sat = malloc(sizeof(double) * (src->count > 0 ? src->count : 1));
    if (!p->sat) return lm_err_set(e, LM_ERR_NOMEM, "out of memory");
    for (int i = 0; i < src->count; i++) p->sat[i] = -1.0;
    if (lm_raw_opts_any(&p->o.raw)) {
        if (lm_model_buckets(p->im.model) == 2)
            return lm_err_set(e, LM_ERR_ARG, "%s (model %s reads both buckets)", files
                              ? "--bits, --black-level, --dark and --flat are for one-bucket "
                                "frames" : "raw-camera conversion is for one-bucket frames",
                              p->im.model->preset);
        if (lm_raw_init(&p->raw, &p->o.raw, src->height, src->width, p->im.sys.tile_rows,
                        p->im.sys.tile_cols, e))
            return e->status;
        if (p->raw.flat_skipped)
            lm_pipe_say(p, LM_PIPE_WARNING, "%ld pixels of the flat are under 5 %% of their "
                        "tile phase's mean: left uncorrected", p->raw.flat_skipped);
    }
    if (!p->is_auto && p->im.remap.active) {
        char line[3000];
        lm_gain_remap_describe(&p->im.remap, p->im.system_path, p->im.model_system, line,
                               sizeof line);
        lm_pipe_say(p, LM_PIPE_INFO, "%s", line);
    }
    return LM_OK;
}

/* Bucket 0 (src0, count 0: none) against bucket 1; a one-bucket model refuses it. */
static lm_status attach_bucket0(lm_pipe *p, const lm_frame_src *src0, const char *spec,
                                lm_err *e)
{
    const int two = lm_model_buckets(p->im.model) == 2;
    if (!two) return LM_OK;
    if (src0->count != p->src.count)
        return lm_err_set(e, LM_ERR_ARG, "%s%s: %d frames, the input has %d", spec ?
                          "--bucket0 " : "bucket 0", spec ? spec : "", src0->count,
                          p->src.count);
    if (src0->height != p->src.height || src0->width != p->src.width)
        return lm_err_set(e, LM_ERR_SHAPE, "%s: bucket 0 is %d x %d, bucket 1 (%s) %d x %d",
                          src0->name(src0->self, 0), src0->width, src0->height,
                          p->src.name(p->src.self, 0), p->src.width, p->src.height);
    p->src0 = *src0;
    p->in2 = malloc(sizeof(float) * 2 * (size_t)p->src.height * p->src.width);
    if (!p->in2) return lm_err_set(e, LM_ERR_NOMEM, "out of memory (%d x %d frame)",
                                   p->src.width, p->src.height);
    if (p->src.count > 1 && !p->o.no_align)
        lm_pipe_say(p, LM_PIPE_WARNING, "bucket 0 is not aligned in time: the two-bucket model "
                    "%s reconstructs the frames without temporal alignment", p->im.model->preset);
    return LM_OK;
}

/* The frame size against the model, the multi-frame and alignment buffers. */
static lm_status prepare(lm_pipe *p, lm_err *e)
{
    if (lm_recon_check(p->im.model, p->src.height, p->src.width, e))
        return lm_pipe_restate(e, p->src.name(p->src.self, 0));
    if (lm_pipe_mf_init(p, e)) return e->status;
    return lm_pipe_align_init(p, e);
}

/* The compute context and the device. */
static lm_status start(lm_pipe *p, lm_err *e)
{
    if (lm_ctx_init(&p->ctx, p->o.threads) != 0)
        return lm_err_set(e, LM_ERR_NOMEM, "out of memory (compute context)");
    p->have_ctx = 1;
    p->ctx.precision = p->o.precision;
    if (p->o.precision != LM_PRECISION_FP32)
        lm_pipe_say(p, LM_PIPE_INFO, "precision: %s", lm_precision_describe(p->o.precision));
    if (p->is_auto ? lm_tile_device_open_models(&p->dev, p->o.device, p->models,
                                                p->cal.nmodels, &p->ctx, e)
                   : lm_tile_device_open(&p->dev, p->o.device, p->im.model, &p->ctx, e))
        return e->status;
    if (p->dev.backend->device != LM_DEVICE_CPU)
        lm_pipe_say(p, LM_PIPE_INFO, "device: %s", lm_tile_device_name(&p->dev));
    return LM_OK;
}

/* The bucket0/ folder (or file, or pattern) beside the input's frames/: the input path with
 * its last "frames" component renamed; "" when the input has none or it does not exist. */
static void bucket0_beside(const char *input, char *out, size_t n)
{
    out[0] = 0;
    const char *hit = NULL;
    for (const char *p = strstr(input, "frames"); p; p = strstr(p + 1, "frames"))
        if ((p == input || p[-1] == '/') && (p[6] == 0 || p[6] == '/')) hit = p;
    if (!hit) return;
    int k = snprintf(out, n, "%.*sbucket0%s", (int)(hit - input), input, hit + 6);
    if (k < 0 || (size_t)k >= n) {
        out[0] = 0;
        return;
    }
    char dir[1100]; /* it must exist: the folder itself, or the folder holding the file(s) */
    snprintf(dir, sizeof dir, "%.*sbucket0", (int)(hit - input), input);
    struct stat st;
    if (stat(dir, &st) != 0 || !S_ISDIR(st.st_mode)) out[0] = 0;
}

/* Files: bucket 0 from spec, else beside the input (two-bucket models only). */
static lm_status files_bucket0(lm_pipe *p, const char *input, const char *spec, lm_err *e)
{
    lm_frame_src none = {0};
    if (lm_model_buckets(p->im.model) != 2) {
        if (spec)
            return lm_err_set(e, LM_ERR_ARG, "--bucket0: model %s reads bucket 1 only "
                              "(two-bucket models are the \"-b2\" presets)",
                              p->is_auto ? "auto (its calibration's)" : p->im.model->preset);
        return attach_bucket0(p, &none, NULL, e);
    }
    char found[1100];
    if (!spec) {
        bucket0_beside(input, found, sizeof found);
        if (!found[0])
            return lm_err_set(e, LM_ERR_ARG, "model %s reads both buckets: give --bucket0 (no "
                              "bucket0/ folder beside the input's frames/)", p->im.model->preset);
        spec = found;
    }
    if (lm_frame_seq_open(spec, &p->seq0, e)) return lm_pipe_restate(e, "--bucket0");
    lm_frame_src s0;
    lm_frame_src_from_seq(&s0, &p->seq0);
    return attach_bucket0(p, &s0, spec, e);
}

static lm_status open_files(lm_pipe *p, const char *input, const char *bucket0, lm_err *e)
{
    char beside[1100] = "";
    if (!bucket0) bucket0_beside(input, beside, sizeof beside);
    if (open_models(p, bucket0 || beside[0] ? 2 : 1, e)) return e->status;
    if (lm_frame_seq_open(input, &p->seq, e)) return e->status;
    snprintf(p->input, sizeof p->input, "%s", input);
    lm_frame_src s;
    lm_frame_src_from_seq(&s, &p->seq);
    if (attach_frames(p, &s, 1, e) || files_bucket0(p, input, bucket0, e) || prepare(p, e))
        return e->status;
    return start(p, e);
}

static lm_status pipe_new(const lm_pipe_opts *o, lm_pipe **out, lm_err *e)
{
    *out = calloc(1, sizeof **out);
    if (!*out) return lm_err_set(e, LM_ERR_NOMEM, "out of memory");
    (*out)->o = *o;
    (*out)->al.next_i = -1;
    return LM_OK;
}

lm_status lm_pipe_open_files(const lm_pipe_opts *o, const char *input, const char *bucket0,
                             lm_pipe **out, lm_err *e)
{
    if (pipe_new(o, out, e)) return e->status;
    if (open_files(*out, input, bucket0, e)) {
        lm_pipe_close(*out);
        *out = NULL;
        return e->status;
    }
    return LM_OK;
}

lm_status lm_pipe_open(const lm_pipe_opts *o, lm_pipe **out, lm_err *e)
{
    if (pipe_new(o, out, e)) return e->status;
    const int buckets = o->bundled_buckets ? o->bundled_buckets : 1;
    if (open_models(*out, buckets, e) || start(*out, e)) {
        lm_pipe_close(*out);
        *out = NULL;
        return e->status;
    }
    return LM_OK;
}

lm_status lm_pipe_attach(lm_pipe *p, const lm_frame_src *src, const lm_frame_src *src0,
                         lm_err *e)
{
    lm_pipe_detach(p);
    lm_frame_src none = {0};
    const int two = lm_model_buckets(p->im.model) == 2;
    if (two && !src0)
        return lm_err_set(e, LM_ERR_ARG, "model %s reads both buckets: bucket 0 is missing",
                          p->im.model->preset);
    if (!two && src0)
        return lm_err_set(e, LM_ERR_ARG, "model %s reads bucket 1 only: bucket 0 must not be "
                          "given", p->is_auto ? "auto" : p->im.model->preset);
    lm_status st = attach_frames(p, src, 0, e);
    if (!st) st = attach_bucket0(p, src0 ? src0 : &none, NULL, e);
    if (!st) st = prepare(p, e);
    if (st) lm_pipe_detach(p);
    return st;
}

void lm_pipe_detach(lm_pipe *p)
{
    lm_pipe_align_free(&p->al);
    lm_frame_seq_free(&p->seq);
    lm_frame_seq_free(&p->seq0);
    free(p->in2);
    free(p->sat);
    lm_raw_free(&p->raw);
    p->in2 = NULL;
    p->sat = NULL;
    memset(&p->raw, 0, sizeof p->raw);
    memset(&p->src, 0, sizeof p->src);
    memset(&p->src0, 0, sizeof p->src0);
}

void lm_pipe_close(lm_pipe *p)
{
    if (!p) return;
    lm_pipe_detach(p);
    lm_tile_device_close(&p->dev);
    if (p->have_ctx) lm_ctx_free(&p->ctx);
    lm_infer_model_free(&p->im);
    for (int m = 1; m < LM_AUTO_MAX_MODELS; m++) lm_infer_model_free(&p->more[m]);
    free(p);
}

void lm_pipe_model_line(const lm_pipe *p, char *out, size_t n)
{
    if (p->is_auto) {
        if (n) out[0] = 0;
        return;
    }
    char name[160];
    snprintf(out, n, "model %s (%s%s): %s", lm_model_name(p->im.model, name, sizeof name),
             p->im.weights, strcmp(p->o.model, "auto") ? "" : ", picked by --model auto",
             p->src0.count ? "both buckets" : "bucket 1");
}

int lm_pipe_count(const lm_pipe *p) { return p->src.count; }

const char *lm_pipe_frame_name(const lm_pipe *p, int i) { return p->src.name(p->src.self, i); }

void lm_pipe_auto_summarize(const lm_pipe *p, lm_pipe_auto_summary *s)
{
    memset(s, 0, sizeof *s);
    const lm_auto_calib *a = &p->cal;
    s->nmodels = a->nmodels;
    for (int m = 0; m < a->nmodels; m++) {
        s->preset[m] = a->models[m].label;
        s->windows[m] = p->windows[m];
        s->total += p->windows[m];
        if (m && lm_auto_expected_psnr(a, NULL, m) > lm_auto_expected_psnr(a, NULL, s->best))
            s->best = m;
    }
    s->psnr_choice = lm_auto_expected_psnr(a, p->choice, 0);
    s->psnr_best = lm_auto_expected_psnr(a, NULL, s->best);
}

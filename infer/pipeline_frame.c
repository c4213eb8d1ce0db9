/* pipeline_frame.c — one frame through the frame pipeline (infer/pipeline.h): read (raw
 * conversion, saturation share), aligned in time with its neighbours (each frame's LED
 * sub-images moved to its lime timestamp with frames i-1, i, i+1 and re-mosaicked; only three
 * frames' sub-images held, read one frame ahead) or stacked with them for multi-frame models
 * (lm_align_stack_frames: the first and last frame take frame i for the missing neighbour),
 * paired with bucket 0, and reconstructed by the model's path or per window (--model auto).
 * What it is not: opening the run (pipeline.c), the flow or alignment scheme (data/align.c). */
#include <omp.h>
#include <stdlib.h>
#include <string.h>
#include "infer/pipeline.h"
#include "infer/pipeline_internal.h"
#include "infer/recon.h"
#include "data/noise_est.h"

/* Read frame i of bucket 1 converted to the system's scale (infer/raw.h), its share of
 * saturated pixels noted in p->sat[i]. */
static lm_status read_frame(lm_pipe *p, int i, lm_frame *f, lm_err *e)
{
    if (p->src.read(p->src.self, i, f, e)) return e->status;
    p->sat[i] = lm_raw_saturated(&p->o.raw, f, NULL);
    if (lm_raw_apply(&p->raw, f, p->src.name(p->src.self, i), e)) {
        lm_frame_free(f);
        return e->status;
    }
    return LM_OK;
}

void lm_pipe_align_free(lm_pipe_align *a)
{
    for (int k = 0; k < 3; k++) free(a->buf[k]), free(a->fr[k]);
    free(a->mf3);
    free(a->t);
    free(a->aligned);
    free(a->raw);
    memset(a, 0, sizeof *a);
    a->next_i = -1;
}

static void flow_opts(const lm_pipe *p, lm_flow_opts *fo)
{
    lm_flow_default_opts(fo, LM_FLOW_MEDIUM);
    fo->nthreads = p->o.threads > 0 ? p->o.threads : omp_get_max_threads();
}

lm_status lm_pipe_mf_init(lm_pipe *p, lm_err *e)
{
    lm_pipe_align *a = &p->al;
    if (p->is_auto || lm_model_frames(p->im.model) == 1) return LM_OK;
    if (p->src.count < 2)
        return lm_err_set(e, LM_ERR_ARG, "%s: model %s reads three frames (the current one and "
                          "its neighbours): give a sequence of at least 2 frames",
                          p->input[0] ? p->input : p->src.name(p->src.self, 0),
                          p->im.model->preset);
    size_t n = (size_t)p->src.height * p->src.width;
    for (int k = 0; k < 3; k++) a->fr[k] = malloc(sizeof(float) * n);
    a->mf3 = malloc(sizeof(float) * 3 * n);
    if (!a->fr[0] || !a->fr[1] || !a->fr[2] || !a->mf3)
        return lm_err_set(e, LM_ERR_NOMEM, "out of memory (multi-frame buffers)");
    a->mf = 1;
    flow_opts(p, &a->fo);
    const lm_system *s = &p->im.sys;
    int need = lm_flow_min_size(&a->fo);
    if (!p->o.no_align && (p->src.height / s->tile_rows < need ||
                           p->src.width / s->tile_cols < need))
        lm_pipe_say(p, LM_PIPE_WARNING, "sub-images %dx%d are smaller than %dx%d: the frames "
                    "are stacked without temporal alignment", p->src.width / s->tile_cols,
                    p->src.height / s->tile_rows, need, need);
    return LM_OK;
}

/* Multi-frame models: frame i's stacked input in al.mf3 (frames read as needed). */
static lm_status mf_step(lm_pipe *p, int i, lm_err *e)
{
    lm_pipe_align *a = &p->al;
    const float *fr[3] = {NULL, NULL, NULL};
    for (int k = 0; k < 3; k++) {
        int j = i - 1 + k;
        if (j < 0 || j >= p->src.count) continue;
        lm_frame f;
        if (read_frame(p, j, &f, e)) return e->status;
        memcpy(a->fr[k], f.data, sizeof(float) * (size_t)f.height * f.width);
        lm_frame_free(&f);
        fr[k] = a->fr[k];
    }
    lm_err ae;
    lm_err_clear(&ae);
    if (lm_align_stack_frames(&p->im.sys, fr[0], fr[1], fr[2], p->src.height, p->src.width,
                              !p->o.no_align, &a->fo, NULL, a->mf3, &ae))
        return lm_err_set(e, ae.status, "%s: %s", p->src.name(p->src.self, i), ae.msg);
    return LM_OK;
}

lm_status lm_pipe_align_init(lm_pipe *p, lm_err *e)
{
    lm_pipe_align *a = &p->al;
    const lm_system *s = &p->im.sys;
    if (a->mf || p->o.no_align || p->src.count < 2 || p->src0.count) return LM_OK;
    a->ty = s->tile_rows;
    a->tx = s->tile_cols;
    a->np = a->ty * a->tx;
    a->ph = p->src.height / a->ty;
    a->pw = p->src.width / a->tx;
    flow_opts(p, &a->fo);
    int need = lm_flow_min_size(&a->fo);
    if (a->ph < need || a->pw < need) {
        lm_pipe_say(p, LM_PIPE_WARNING, "sub-images %dx%d are smaller than %dx%d: frames are "
                    "reconstructed without temporal alignment", a->pw, a->ph, need, need);
        return LM_OK;
    }
    size_t n = (size_t)a->np * a->ph * a->pw;
    a->t = malloc(sizeof(float) * a->np);
    a->aligned = malloc(sizeof(float) * n);
    a->raw = malloc(sizeof(float) * n);
    for (int k = 0; k < 3; k++) a->buf[k] = malloc(sizeof(float) * n);
    if (!a->t || !a->aligned || !a->raw || !a->buf[0] || !a->buf[1] || !a->buf[2])
        return lm_err_set(e, LM_ERR_NOMEM, "out of memory (alignment buffers)");
    if (lm_align_phase_times(s, a->t, &a->ref, e)) return e->status;
    a->on = 1;
    return LM_OK;
}

/* Read frame i and unshuffle it into dst (np planes). */
static lm_status load_planes(lm_pipe *p, int i, float *dst, lm_err *e)
{
    lm_frame f;
    if (read_frame(p, i, &f, e)) return e->status;
    lm_status st = lm_align_unshuffle(f.data, f.height, f.width, p->al.ty, p->al.tx, dst, e);
    lm_frame_free(&f);
    return st;
}

/* Frame i aligned and re-mosaicked into al.raw; cur = frame i and next = frame i + 1 loaded
 * (frame i - 1 as prev). Frames i - 1 and i are read unless the previous call was frame i - 1. */
static lm_status align_step(lm_pipe *p, int i, lm_err *e)
{
    lm_pipe_align *a = &p->al;
    if (i != a->next_i) {
        a->cur = a->buf[i % 3];
        if (load_planes(p, i, a->cur, e)) return e->status;
        a->prev = i > 0 ? a->buf[(i - 1) % 3] : NULL;
        if (i > 0 && load_planes(p, i - 1, a->prev, e)) return e->status;
    }
    a->next_i = -1;
    if (i + 1 < p->src.count) {
        a->next = a->buf[(i + 1) % 3];
        if (load_planes(p, i + 1, a->next, e)) return e->status;
    } else {
        a->next = NULL;
    }
    lm_err ae;
    lm_err_clear(&ae);
    if (lm_align_frame(a->prev, a->cur, a->next, a->np, a->ph, a->pw, a->t, a->ref, &a->fo,
                       NULL, a->aligned, &ae) ||
        lm_align_remosaic(a->aligned, a->ph, a->pw, a->ty, a->tx, a->raw, &ae))
        return lm_err_set(e, ae.status, "%s: %s", p->src.name(p->src.self, i), ae.msg);
    a->prev = a->cur; /* i -> prev, i + 1 -> cur */
    a->cur = a->next;
    a->next_i = i + 1;
    return LM_OK;
}

/* Frame i's input to the network: stacked, aligned, or read as is into *f. */
static lm_status frame_input(lm_pipe *p, int i, lm_frame *f, const float **data, lm_err *e)
{
    memset(f, 0, sizeof *f);
    if (p->al.mf) {
        if (mf_step(p, i, e)) return e->status;
        *data = p->al.mf3;
        return LM_OK;
    }
    if (p->al.on) {
        if (align_step(p, i, e)) return e->status;
        *data = p->al.raw;
        return LM_OK;
    }
    if (read_frame(p, i, f, e)) return e->status;
    *data = f->data;
    return LM_OK;
}

/* A calibrated choice on one frame (lm_auto_run), its share of windows per model said. */
static lm_status auto_frame(lm_pipe *p, const float *in, int H, int W, const lm_tile_opts *to,
                            lm_cube *cube, lm_err *e)
{
    const lm_auto_calib *a = &p->cal;
    long win[LM_AUTO_MAX_MODELS] = {0};
    int n = 0;
    lm_status st = lm_auto_run(&p->ctx, a, p->choice, p->models, in, H, W, to, cube, &n, win, e);
    if (!st) {
        char line[1200];
        int k = snprintf(line, sizeof line, "auto:");
        for (int m = 0; m < a->nmodels; m++) {
            if (k >= 0 && (size_t)k < sizeof line)
                k += snprintf(line + k, sizeof line - k, " %s %.0f%%", a->models[m].label,
                              100.0 * win[m] / n);
            p->windows[m] += win[m];
        }
        lm_pipe_say(p, LM_PIPE_INFO, "%s of %d windows (%s)", line, n,
                    p->src0.count ? "both buckets" : "bucket 1");
    }
    return st;
}

/* Two-bucket models: frame i's bucket 0 after bucket 1 (in) in p->in2; *in points at it.
 * bits, is_float: bucket 1's frame (bits 0: not known). */
static lm_status with_bucket0(lm_pipe *p, int i, const float **in, int H, int W, int bits,
                              int is_float, lm_err *e)
{
    if (!p->src0.count) return LM_OK;
    lm_frame f0;
    if (p->src0.read(p->src0.self, i, &f0, e)) return e->status;
    lm_status st = LM_OK;
    const char *n0 = p->src0.name(p->src0.self, i), *n1 = p->src.name(p->src.self, i);
    if (f0.height != H || f0.width != W)
        st = lm_err_set(e, LM_ERR_SHAPE, "%s: bucket 0 is %d x %d, bucket 1 (%s) %d x %d", n0,
                        f0.width, f0.height, n1, W, H);
    else if (bits && (f0.bits != bits || f0.is_float != is_float))
        st = lm_err_set(e, LM_ERR_FORMAT, "%s: bucket 0 is %d-bit%s, bucket 1 (%s) %d-bit%s: the "
                        "two buckets of a frame come from one read-out, in one format", n0,
                        f0.bits, f0.is_float ? " float" : "", n1, bits,
                        is_float ? " float" : "");
    if (!st) {
        const size_t n = (size_t)H * W;
        memcpy(p->in2, *in, sizeof(float) * n);
        memcpy(p->in2 + n, f0.data, sizeof(float) * n);
        *in = p->in2;
    }
    lm_frame_free(&f0);
    return st;
}

lm_status lm_pipe_reconstruct(lm_pipe *p, const float *in, int H, int W, lm_cube *cube,
                              lm_err *e)
{
    if (p->is_auto) {
        lm_tile_opts to;
        lm_tile_default_opts(&to);
        to.batch = p->o.batch;
        return auto_frame(p, in, H, W, &to, cube, e);
    }
    lm_recon_opts ro = {.batch = p->o.batch, .tiles = p->o.tiles};
    return lm_recon_camera_frame(&p->ctx, &p->im, in, H, W, &ro, cube, e);
}

/* Once per run: a noisy frame clipped at 0 (as a 16-bit PNG or TIFF holds it: at least 1 in
 * 1000 pixels, and 16, exactly 0, none below) given to a model that records having been
 * trained on unclipped samples only (a calibrated choice: when all of its models do). Its dark
 * areas come out biased (such a network loses 3.6 dB at 10 % noise on them: docs/results.md,
 * "Clipped frames"). */
static void clip_note(lm_pipe *p, int i, const float *in, int H, int W)
{
    if (p->clip_warned || p->im.clipped != 0.0) return;
    for (int m = 1; p->is_auto && m < p->cal.nmodels; m++)
        if (p->more[m].clipped != 0.0) return;
    const size_t n = (size_t)H * W;
    size_t zeros = 0;
    for (size_t k = 0; k < n; k++) {
        if (in[k] < 0.0f) return; /* negatives kept: not clipped */
        zeros += in[k] == 0.0f;
    }
    if (zeros < 16 || zeros * 1000 < n) return;
    lm_noise_info ni;
    lm_err ne = {0};
    const lm_mosaic *mo = &p->im.model->mosaic;
    if (lm_noise_analyze(in, H, W, mo->ty, mo->tx, &ni, &ne) || !(ni.level >= 0.02f)) return;
    p->clip_warned = 1;
    lm_pipe_say(p, LM_PIPE_WARNING, "%s: noisy (about %.0f %%) and clipped at 0, as a 16-bit "
                "file holds it; %s%s%s%s trained on unclipped samples, so dark areas come "
                "out too bright: a model trained on clipped samples too (train's clip_fraction) "
                "reads such frames", p->src.name(p->src.self, i), 100.0 * ni.level,
                p->is_auto ? "the calibrated models were" : "", p->is_auto ? "" : "model ",
                p->is_auto ? "" : p->im.model->preset, p->is_auto ? "" : " was");
}

lm_status lm_pipe_frame(lm_pipe *p, int i, lm_cube *cube, lm_pipe_info *info, lm_err *e)
{
    memset(cube, 0, sizeof *cube);
    if (i < 0 || i >= p->src.count)
        return lm_err_set(e, LM_ERR_ARG, "frame %d of %d", i, p->src.count);
    double t0 = omp_get_wtime();
    lm_frame f;
    const float *in = NULL;
    lm_status st = frame_input(p, i, &f, &in, e);
    double ta = omp_get_wtime();
    const int H = f.height ? f.height : p->src.height, W = f.width ? f.width : p->src.width;
    if (!st) clip_note(p, i, in, H, W);
    if (!st) st = with_bucket0(p, i, &in, H, W, f.height ? f.bits : 0, f.is_float, e);
    if (!st && lm_pipe_reconstruct(p, in, H, W, cube, e))
        st = lm_pipe_restate(e, p->src.name(p->src.self, i));
    lm_frame_free(&f);
    if (info)
        *info = (lm_pipe_info){.align_s = ta - t0, .recon_s = omp_get_wtime() - ta,
                               .aligned = p->al.on || (p->al.mf && !p->o.no_align),
                               .saturated = p->sat[i]};
    return st;
}

lm_status lm_pipe_saturation_mask(lm_pipe *p, int i, lm_frame *mask, lm_err *e)
{
    if (p->src.read(p->src.self, i, mask, e)) return e->status;
    const size_t n = (size_t)mask->height * mask->width;
    uint8_t *m = malloc(n);
    if (!m) {
        lm_frame_free(mask);
        return lm_err_set(e, LM_ERR_NOMEM, "out of memory (saturation mask)");
    }
    lm_raw_saturated(&p->o.raw, mask, m);
    for (size_t k = 0; k < n; k++) mask->data[k] = m[k];
    free(m);
    return LM_OK;
}

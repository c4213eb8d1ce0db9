/* eval.c — evaluation of a trained model on prepared cubes and on the rainbow scene (see
 * eval.h). What it is not: scene listing or output (eval_run.c, eval_write.c). */
#include "infer/eval.h"
#include <inttypes.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "data/dataset.h"
#include "data/forward.h"
#include "data/spectra.h"
#include "data/synth.h"
#include "data/rgbcam.h"
#include "data/video.h"
#include "data/align.h"
#include "infer/whole.h"

static double now_s(void)
{
    struct timespec t;
    clock_gettime(CLOCK_MONOTONIC, &t);
    return t.tv_sec + 1e-9 * t.tv_nsec;
}

static int is_rgb(const lm_infer_model *im) { return lm_model_has(im->model, LM_CAP_RGB_INPUT); }

/* Planes of the frame the model takes: 3 (RGB), 2 (both buckets), 3 (three frames) or 1
 * (bucket 1). */
static int planes_of(const lm_infer_model *im)
{
    return is_rgb(im) ? 3 : lm_model_coded_planes(im->model);
}

/* The multi-frame input of frames fr[0..2] (i-1, i, i+1; each H x W) into out (3 x H x W):
 * lm_align_stack_frames (fo NULL = the medium flow with nthreads). */
static lm_status mf_input(const lm_system *sys, float *const fr[3], int H, int W, int aligned,
                          const lm_flow_opts *fo, const lm_align_opts *ao, int nthreads,
                          float *out, lm_err *err)
{
    lm_flow_opts dfo;
    if (!fo) {
        lm_flow_default_opts(&dfo, LM_FLOW_MEDIUM);
        dfo.nthreads = nthreads > 0 ? nthreads : 1;
        fo = &dfo;
    }
    return lm_align_stack_frames(sys, fr[0], fr[1], fr[2], H, W, aligned, fo, ao, out, err);
}

/* lm_eval_simulate with an explicit thread count and a mutable rng (advanced). */
static lm_status simulate(const lm_infer_model *im, const lm_cube *truth,
                          const lm_noise_opts *noise, lm_rng *rng, int nthreads, float *frame,
                          lm_err *err)
{
    if (truth->bands != 31)
        return lm_err_set(err, LM_ERR_SHAPE, "eval: the cube needs 31 bands at 400..700 nm "
                          "(has %d bands)", truth->bands);
    if (is_rgb(im) && lm_model_has(im->model, LM_CAP_QDO_OPTICS)) {
        lm_qdocam *q = im->qdo;
        lm_noise_opts none = {0};
        lm_status st = q ? LM_OK : lm_infer_qdocam(NULL, &q, err); /* (a model not from a file) */
        if (!st) st = lm_qdocam_simulate(q, truth->data, truth->height, truth->width,
                                         noise ? noise : &none, rng, frame, nthreads, err);
        if (q && q != im->qdo) {
            lm_qdocam_free(q);
            free(q);
        }
        return st;
    }
    if (is_rgb(im)) {
        lm_rgbcam cam;
        if (lm_rgbcam_load(&cam, NULL, LM_RGBCAM_D65, err)) return err->status;
        lm_noise_opts none;
        memset(&none, 0, sizeof none);
        return lm_rgbcam_simulate(&cam, truth->data, truth->height, truth->width,
                                  noise ? noise : &none, rng, frame, nthreads, err);
    }
    const int two = lm_model_buckets(im->model) == 2;
    if (im->model->in_channels != lm_model_coded_planes(im->model))
        return lm_err_set(err, LM_ERR_ARG, "eval: model %s takes %d input channels (need 1, 2 "
                          "or 3)", im->model->preset, im->model->in_channels);
    lm_forward_opts fo;
    memset(&fo, 0, sizeof fo);
    if (noise) fo.noise = *noise;
    fo.nthreads = nthreads;
    const size_t npx = (size_t)truth->height * truth->width;
    if (lm_model_frames(im->model) == 3) { /* a still video: frames i-1, i, i+1, own noise */
        float *fr = malloc(sizeof(float) * 3 * npx), *f3[3];
        if (!fr) return lm_err_set(err, LM_ERR_NOMEM, "eval: out of memory");
        lm_status st = LM_OK;
        for (int f = 0; f < 3 && !st; f++) {
            f3[f] = fr + f * npx;
            st = lm_forward_simulate31(&im->sys, truth, &fo, rng, f3[f], NULL, err);
        }
        if (!st) st = mf_input(&im->sys, f3, truth->height, truth->width, 1, NULL, NULL,
                               nthreads, frame, err);
        free(fr);
        return st;
    }
    /* both buckets: the same noise model on each (bucket 0's own maximum and full scale),
     * bucket 0 then stored / (LEDs - 1) as simulate --bucket0 writes it */
    lm_status st = lm_forward_simulate31(&im->sys, truth, &fo, rng, frame, two ? frame + npx
                                         : NULL, err);
    const float f = im->sys.nleds > 1 ? 1.0f / (float)(im->sys.nleds - 1) : 1.0f;
    for (size_t i = 0; two && !st && i < npx; i++) frame[npx + i] *= f;
    return st;
}

lm_status lm_eval_simulate(const lm_infer_model *im, const lm_cube *truth,
                           const lm_noise_opts *noise, const lm_rng *rng, float **frame,
                           size_t *n, lm_err *err)
{
    *frame = NULL;
    *n = 0;
    if (!im || !im->model)
        return lm_err_set(err, LM_ERR_ARG, "eval: simulate: no model");
    size_t cnt = (size_t)planes_of(im) * truth->height * truth->width;
    float *f = malloc(sizeof(float) * (cnt ? cnt : 1));
    if (!f) return lm_err_set(err, LM_ERR_NOMEM, "eval: out of memory");
    lm_rng r;
    if (rng) r = *rng;
    else lm_rng_seed(&r, 0);
    lm_status st = simulate(im, truth, noise, rng ? &r : NULL, 0, f, err);
    if (st) {
        free(f);
        return st;
    }
    *frame = f;
    *n = cnt;
    return LM_OK;
}

lm_status lm_eval_reconstruct(lm_ctx *c, const lm_infer_model *im, const float *frame,
                              int height, int width, const lm_tile_opts *to, int whole,
                              lm_cube *out, lm_err *err)
{
    memset(out, 0, sizeof *out);
    lm_model *m = im ? im->model : NULL;
    if (!m) return lm_err_set(err, LM_ERR_ARG, "eval: reconstruct: no model");
    if (lm_model_has(m, LM_CAP_WHOLE_FRAME)) { /* global attention: the whole frame at once */
        if (m->out_channels != 31)
            return lm_err_set(err, LM_ERR_ARG, "eval: model %s has %d output channels (need 31)",
                              m->preset, m->out_channels);
        if (height <= 0 || width <= 0)
            return lm_err_set(err, LM_ERR_SHAPE, "eval: frame %d x %d", width, height);
        if (lm_cube_alloc(out, 31, height, width, 400.0f, 10.0f))
            return lm_err_set(err, LM_ERR_NOMEM, "eval: out of memory");
        lm_status st = lm_mst_reconstruct(m, frame, height, width, out->data, lm_nthreads(c),
                                          err);
        if (st) lm_cube_free(out);
        return st;
    }
    if (m->in_channels != lm_model_coded_planes(m))
        return lm_err_set(err, LM_ERR_ARG, "eval: model %s takes %d input channels and is not "
                          "MST++", m->preset, m->in_channels);
    if (im->auto_cal) { /* the calibrated choice per window (one-bucket models, the same gains) */
        if (im->remap.active)
            return lm_err_set(err, LM_ERR_ARG, "eval: a calibrated choice does not rescale "
                              "frames of other LED gains");
        return lm_auto_run(c, im->auto_cal, im->auto_choice, im->auto_models, frame, height,
                           width, to, out, NULL, NULL, err);
    }
    float *mapped = NULL, given = m->noise_given;
    if (im->remap.active) { /* frames of the camera's gains, rescaled to the model's */
        const int planes = lm_model_coded_planes(m);
        mapped = malloc(sizeof(float) * planes * (size_t)height * width);
        if (!mapped) return lm_err_set(err, LM_ERR_NOMEM, "eval: out of memory");
        m->noise_given = lm_gain_remap_frame(&im->remap, frame, planes, height, width, given,
                                             mapped);
        frame = mapped;
    }
    lm_status st = whole && lm_whole_halo(m) > 0
                       ? lm_whole_infer(c, m, frame, height, width, out, err)
                       : lm_tile_infer(c, m, frame, height, width, to, out, err);
    m->noise_given = given;
    free(mapped);
    return st;
}

lm_status lm_eval_prepare(lm_cube *cube, int ty, int tx, lm_err *err)
{
    if (cube->bands != 31 || fabsf(cube->wavelength[0] - 400.0f) > 0.5f ||
        fabsf(cube->wavelength[30] - 700.0f) > 0.5f)
        return lm_err_set(err, LM_ERR_SHAPE, "eval: the cube needs 31 bands at 400..700 nm "
                          "(has %d bands)", cube->bands);
    if (ty <= 0 || tx <= 0 || cube->height < ty || cube->width < tx)
        return lm_err_set(err, LM_ERR_SHAPE, "eval: the cube (%d x %d) is smaller than the "
                          "%d x %d mosaic tile", cube->width, cube->height, tx, ty);
    int H = cube->height - cube->height % ty, W = cube->width - cube->width % tx;
    float mx = lm_cube_max(cube);
    if (!(mx > 0.0f) || !isfinite(mx))
        return lm_err_set(err, LM_ERR_NUMERIC, "eval: the cube's maximum is %g (need > 0)",
                          (double)mx);
    float inv = 1.0f / mx;
    /* Compact in place: row (b, y) moves to an index <= its old one, so forward order is safe. */
    for (int b = 0; b < cube->bands; b++)
        for (int y = 0; y < H; y++) {
            const float *src = cube->data + ((size_t)b * cube->height + y) * cube->width;
            float *dst = cube->data + ((size_t)b * H + y) * W;
            for (int x = 0; x < W; x++) dst[x] = src[x] * inv;
        }
    cube->height = H;
    cube->width = W;
    return LM_OK;
}

/* Simulate the frame of truth with noise k from rng, reconstruct, score; keep: NULL, or where
 * the reconstruction goes (else it is freed). */
static lm_status eval_one(lm_ctx *c, const lm_infer_model *im, const lm_cube *truth, float k,
                          const lm_tile_opts *to, lm_rng *rng, float *frame, lm_metrics *out,
                          lm_cube *keep, double *seconds, lm_err *err)
{
    lm_noise_opts no;
    memset(&no, 0, sizeof no);
    no.gauss_k = k;
    no.clip = im->sensor_clip;
    no.bits = im->sensor_bits;
    no.photons = im->photons, no.read_noise = im->read_noise; /* before the Gaussian k */
    float clean_max = 0.0f;
    const size_t npx = (size_t)truth->height * truth->width;
    lm_status st = LM_OK;
    if (im->noise_oracle && im->model->noise_input) { /* the true sd: k x the clean maximum */
        st = simulate(im, truth, NULL, NULL, lm_nthreads(c), frame, err);
        for (size_t i = 0; !st && i < npx; i++) clean_max = frame[i] > clean_max ? frame[i] : clean_max;
    }
    if (!st) st = simulate(im, truth, &no, rng, lm_nthreads(c), frame, err);
    if (st) return st;
    if (im->noise_oracle && im->model->noise_input) { /* noise_given is relative to the frame's max */
        float mx = 0.0f;
        for (size_t i = 0; i < npx; i++) mx = frame[i] > mx ? frame[i] : mx;
        im->model->noise_given = mx > 0.0f ? k * clean_max / mx : 0.0f;
    }
    lm_cube pred;
    double t0 = now_s();
    st = lm_eval_reconstruct(c, im, frame, truth->height, truth->width, to, 0, &pred, err);
    if (st) return st;
    if (seconds) *seconds = now_s() - t0;
    st = lm_metrics_compute(pred.data, truth->data, 31, truth->height, truth->width, 0, 31, out,
                            err);
    if (!st && keep) *keep = pred;
    else lm_cube_free(&pred);
    return st;
}

lm_status lm_eval_scene(lm_ctx *c, const lm_infer_model *im, const lm_cube *truth,
                        const float *k, int nnoise, const lm_tile_opts *to, const lm_rng *rng,
                        lm_metrics *out, lm_err *err)
{
    return lm_eval_scene_timed(c, im, truth, k, nnoise, to, rng, out, NULL, err);
}

int lm_eval_trained_on(const lm_infer_model *im, const char *path)
{
    if (!im->train_scenes) return -1;
    char h[24];
    snprintf(h, sizeof h, "%016" PRIx64, lm_scene_content_hash(path));
    for (const char *p = strstr(im->train_scenes, h); p; p = strstr(p + 1, h))
        if ((p == im->train_scenes || p[-1] == ',') && (p[16] == ',' || p[16] == 0)) return 1;
    return 0;
}

lm_status lm_eval_scene_timed(lm_ctx *c, const lm_infer_model *im, const lm_cube *truth,
                              const float *k, int nnoise, const lm_tile_opts *to,
                              const lm_rng *rng, lm_metrics *out, double *seconds, lm_err *err)
{
    if (nnoise < 1 || nnoise > LM_EVAL_MAX_NOISE)
        return lm_err_set(err, LM_ERR_ARG, "eval: %d noise levels (need 1..%d)", nnoise,
                          LM_EVAL_MAX_NOISE);
    for (int i = 0; i < nnoise; i++)
        if (!(k[i] >= 0.0f) || !isfinite(k[i]))
            return lm_err_set(err, LM_ERR_ARG, "eval: noise level %g is not >= 0", (double)k[i]);
    float *frame = malloc(sizeof(float) * planes_of(im) * (size_t)truth->height *
                          truth->width);
    if (!frame) return lm_err_set(err, LM_ERR_NOMEM, "eval: out of memory");
    lm_status st = LM_OK;
    for (int i = 0; i < nnoise && !st; i++) {
        /* keyed on the level, not its position: 10 % draws the same noise in any list */
        lm_rng r = lm_rng_split(rng, (uint64_t)llround((double)k[i] * 1e6));
        st = eval_one(c, im, truth, k[i], to, &r, frame, &out[i], NULL,
                      seconds ? &seconds[i] : NULL, err);
    }
    free(frame);
    return st;
}

lm_status lm_eval_scene_one(lm_ctx *c, const lm_infer_model *im, const lm_cube *truth, float k,
                            const lm_tile_opts *to, const lm_rng *rng, lm_metrics *out,
                            lm_cube *pred, lm_err *err)
{
    memset(pred, 0, sizeof *pred);
    if (!(k >= 0.0f) || !isfinite(k))
        return lm_err_set(err, LM_ERR_ARG, "eval: noise level %g is not >= 0", (double)k);
    float *frame = malloc(sizeof(float) * planes_of(im) * (size_t)truth->height *
                          truth->width);
    if (!frame) return lm_err_set(err, LM_ERR_NOMEM, "eval: out of memory");
    lm_rng r = lm_rng_split(rng, (uint64_t)llround((double)k * 1e6));
    lm_status st = eval_one(c, im, truth, k, to, &r, frame, out, pred, NULL, err);
    free(frame);
    return st;
}

#define MOTION_FRAMES LM_EVAL_MOTION_FRAMES

/* Buffers of one motion run: frames, their sub-images, the aligned frame. */
typedef struct motion_buf {
    float *raw[MOTION_FRAMES], *planes[MOTION_FRAMES], *aligned, *remos;
    float *mf;      /* multi-frame models: their 3 x H x W input */
    lm_cube truth;  /* frame 1's lime-instant scene, 31 bands */
} motion_buf;

static void motion_buf_free(motion_buf *b)
{
    for (int i = 0; i < MOTION_FRAMES; i++) {
        free(b->raw[i]);
        free(b->planes[i]);
    }
    free(b->aligned);
    free(b->remos);
    free(b->mf);
    lm_cube_free(&b->truth);
}

/* Simulate the frames (noise-free) and frame 1's truth (bins 400..700 of its scene). */
static lm_status motion_simulate(const lm_infer_model *im, const lm_cube *cube31, double speed,
                                 int nthreads, motion_buf *b, lm_err *err)
{
    lm_cube c41, gt;
    if (lm_cube_mirror41(cube31, &c41, err)) return err->status;
    lm_video_opts vo;
    memset(&vo, 0, sizeof vo);
    vo.motion.vx = speed * LM_EVAL_MOTION_DIR_X;
    vo.motion.vy = speed * LM_EVAL_MOTION_DIR_Y;
    vo.nthreads = nthreads;
    lm_status st = LM_OK;
    for (int i = 0; i < MOTION_FRAMES && !st; i++) {
        st = lm_video_frame(&im->sys, &c41, &vo, i, NULL, b->raw[i], NULL, i == 1 ? &gt : NULL,
                            err);
        if (!st && i == 1) {
            if (lm_cube_alloc(&b->truth, 31, gt.height, gt.width, 400.0f, 10.0f))
                st = lm_err_set(err, LM_ERR_NOMEM, "eval: out of memory");
            else
                memcpy(b->truth.data, lm_cube_band(&gt, 2),
                       sizeof(float) * 31 * (size_t)gt.height * gt.width);
            lm_cube_free(&gt);
        }
    }
    lm_cube_free(&c41);
    return st;
}

/* Frame 1 aligned to its lime instant with frames 0 and 2, re-mosaicked into b->remos. */
static lm_status motion_align(const lm_system *sys, int H, int W, const lm_flow_opts *fo,
                              const lm_align_opts *ao, motion_buf *b, lm_err *err)
{
    int ty = sys->tile_rows, tx = sys->tile_cols, np = ty * tx, ref;
    float t[LM_SYSTEM_MAX_TILE];
    lm_status st = lm_align_phase_times(sys, t, &ref, err);
    for (int i = 0; i < MOTION_FRAMES && !st; i++)
        st = lm_align_unshuffle(b->raw[i], H, W, ty, tx, b->planes[i], err);
    if (!st) st = lm_align_frame(b->planes[0], b->planes[1], b->planes[2], np, H / ty, W / tx,
                                 t, ref, fo, ao, b->aligned, err);
    if (!st) st = lm_align_remosaic(b->aligned, H / ty, W / tx, ty, tx, b->remos, err);
    return st;
}

void lm_eval_motion_region(const lm_system *sys, double speed, int height, int width, int *y0,
                           int *x0, int *h, int *w)
{
    double span = 1e-6 * lm_system_frame_period_us(sys) * (MOTION_FRAMES - 1);
    int my = (int)ceil(fabs(speed * LM_EVAL_MOTION_DIR_Y) * span - 1e-9) +
             LM_EVAL_MOTION_SUPPORT_TILES * sys->tile_rows;
    int mx = (int)ceil(fabs(speed * LM_EVAL_MOTION_DIR_X) * span - 1e-9) +
             LM_EVAL_MOTION_SUPPORT_TILES * sys->tile_cols;
    *y0 = my;
    *x0 = mx;
    *h = height - 2 * my > 0 ? height - 2 * my : 0;
    *w = width - 2 * mx > 0 ? width - 2 * mx : 0;
}

/* Metrics of pred against truth (31 x H x W each) over the region of out (y0, x0, h, w). */
static lm_status region_metrics(const float *pred, const float *truth, int H, int W,
                                const lm_eval_motion *r, lm_metrics *m, lm_err *err)
{
    size_t n = (size_t)31 * r->height * r->width;
    float *a = malloc(sizeof(float) * 2 * (n ? n : 1)), *b = a + n;
    if (!a) return lm_err_set(err, LM_ERR_NOMEM, "eval: out of memory");
    for (int k = 0; k < 31; k++)
        for (int y = 0; y < r->height; y++) {
            size_t src = ((size_t)k * H + r->y0 + y) * W + r->x0;
            size_t dst = ((size_t)k * r->height + y) * r->width;
            memcpy(a + dst, pred + src, sizeof(float) * r->width);
            memcpy(b + dst, truth + src, sizeof(float) * r->width);
        }
    lm_status st = lm_metrics_compute(a, b, 31, r->height, r->width, 0, 31, m, err);
    free(a);
    return st;
}

/* Reconstruct frame (H x W, the layout of lm_eval_simulate) and score it against truth over
 * the region of r. */
static lm_status score_region(lm_ctx *c, const lm_infer_model *im, const float *frame,
                              const lm_tile_opts *to, const lm_cube *truth,
                              const lm_eval_motion *r, lm_metrics *m, lm_err *err)
{
    lm_cube pred;
    int H = truth->height, W = truth->width;
    lm_status st = lm_eval_reconstruct(c, im, frame, H, W, to, 0, &pred, err);
    if (st) return st;
    st = region_metrics(pred.data, truth->data, H, W, r, m, err);
    lm_cube_free(&pred);
    return st;
}

/* The static reference: truth as a still frame (a multi-frame model: three still frames),
 * with the noise no (NULL = none) from rng, reconstructed, scored. */
static lm_status score_still(lm_ctx *c, const lm_infer_model *im, const lm_tile_opts *to,
                             const lm_cube *truth, const lm_noise_opts *no, lm_rng *rng,
                             lm_eval_motion *r, lm_err *err)
{
    size_t n = (size_t)planes_of(im) * truth->height * truth->width;
    float *frame = malloc(sizeof(float) * n);
    if (!frame) return lm_err_set(err, LM_ERR_NOMEM, "eval: out of memory");
    lm_status st = simulate(im, truth, no, no ? rng : NULL, lm_nthreads(c), frame, err);
    if (!st) st = score_region(c, im, frame, to, truth, r, &r->still, err);
    free(frame);
    return st;
}

/* Instants (seconds) across frame 1's exposure for the RGB camera: the exposure split into
 * LM_VIDEO_DEFAULT_SAMPLES parts per LED (at most LM_VIDEO_MAX_SAMPLES), the midpoints. */
static int rgb_instants(const lm_system *sys, double *t)
{
    int n = LM_VIDEO_DEFAULT_SAMPLES * sys->nleds;
    if (n > LM_VIDEO_MAX_SAMPLES) n = LM_VIDEO_MAX_SAMPLES;
    if (n < 1) n = 1;
    double t0 = lm_video_frame_start_us(sys, 1), len = lm_system_exposure_us(sys);
    for (int k = 0; k < n; k++) t[k] = (t0 + (k + 0.5) / n * len) * 1e-6;
    return n;
}

/* The RGB camera's frame 1: the moving scene averaged over the exposure (motion blur), then
 * rendered noise-free; truth = the scene at frame 1's lime instant, as for coded models. */
static lm_status motion_rgb(lm_ctx *c, const lm_infer_model *im, const lm_cube *cube,
                            const lm_motion *mo, const lm_tile_opts *to, lm_eval_motion *out,
                            lm_err *err)
{
    int H = cube->height, W = cube->width, nt = lm_nthreads(c);
    size_t n = (size_t)31 * H * W;
    double t[LM_VIDEO_MAX_SAMPLES];
    int ns = rgb_instants(&im->sys, t);
    lm_cube acc, gt, w;
    memset(&gt, 0, sizeof gt);
    if (lm_cube_alloc(&acc, 31, H, W, 400.0f, 10.0f))
        return lm_err_set(err, LM_ERR_NOMEM, "eval: out of memory");
    float *frame = malloc(sizeof(float) * 3 * (size_t)H * W);
    double *sum = calloc(n, sizeof(double)); /* exact for a still scene: mean = the cube */
    lm_status st = frame && sum ? LM_OK : lm_err_set(err, LM_ERR_NOMEM, "eval: out of memory");
    for (int k = 0; k < ns && !st; k++) {
        st = lm_video_warp(cube, mo, t[k], &w, nt, err);
        if (st) break;
        for (size_t i = 0; i < n; i++) sum[i] += w.data[i];
        lm_cube_free(&w);
    }
    for (size_t i = 0; i < n && !st; i++) acc.data[i] = (float)(sum[i] / ns);
    free(sum);
    if (!st) st = simulate(im, &acc, NULL, NULL, nt, frame, err);
    double tg = (lm_video_frame_start_us(&im->sys, 1) + lm_video_gt_time_us(&im->sys)) * 1e-6;
    if (!st) st = lm_video_warp(cube, mo, tg, &gt, nt, err);
    if (!st) st = score_region(c, im, frame, to, &gt, out, &out->unaligned, err);
    out->aligned = out->unaligned; /* one camera frame, nothing to align */
    if (!st) st = score_still(c, im, to, &gt, NULL, NULL, out, err);
    lm_cube_free(&gt);
    lm_cube_free(&acc);
    free(frame);
    return st;
}

/* The buffers of a coded motion run; LM_ERR_NOMEM if any is missing. */
static lm_status motion_alloc(motion_buf *b, size_t n, lm_err *err)
{
    memset(b, 0, sizeof *b);
    int ok = 1;
    for (int i = 0; i < MOTION_FRAMES; i++) {
        b->raw[i] = malloc(sizeof(float) * n);
        b->planes[i] = malloc(sizeof(float) * n);
        ok = ok && b->raw[i] && b->planes[i];
    }
    b->aligned = malloc(sizeof(float) * n);
    b->remos = malloc(sizeof(float) * n);
    b->mf = malloc(sizeof(float) * 3 * n);
    return ok && b->aligned && b->remos && b->mf ? LM_OK
                                        : lm_err_set(err, LM_ERR_NOMEM, "eval: out of memory");
}

lm_status lm_eval_motion_run(lm_ctx *c, const lm_infer_model *im, const lm_cube *truth,
                             double speed, const lm_tile_opts *to, const lm_flow_opts *fo,
                             const lm_align_opts *ao, lm_eval_motion *out, lm_err *err)
{
    return lm_eval_motion_run_noise(c, im, truth, speed, 0.0f, NULL, to, fo, ao, out, err);
}

lm_status lm_eval_motion_run_noise(lm_ctx *c, const lm_infer_model *im, const lm_cube *truth,
                                   double speed, float k, const lm_rng *rng,
                                   const lm_tile_opts *to, const lm_flow_opts *fo,
                                   const lm_align_opts *ao, lm_eval_motion *out, lm_err *err)
{
    memset(out, 0, sizeof *out);
    out->speed = speed;
    out->noise = k;
    if (!(speed >= 0.0) || !isfinite(speed))
        return lm_err_set(err, LM_ERR_ARG, "eval: motion speed %g px/s (need >= 0)", speed);
    if (!(k >= 0.0f) || !isfinite(k))
        return lm_err_set(err, LM_ERR_ARG, "eval: motion noise level %g (need >= 0)", (double)k);
    int H = truth->height, W = truth->width;
    out->px_per_frame = speed * 1e-6 * lm_system_frame_period_us(&im->sys);
    lm_eval_motion_region(&im->sys, speed, H, W, &out->y0, &out->x0, &out->height, &out->width);
    if (out->height < LM_SSIM_WIN || out->width < LM_SSIM_WIN)
        return lm_err_set(err, LM_ERR_SHAPE, "eval: motion at %g px/s: the %d x %d scene keeps "
                          "%d x %d pixels in view over the video (need %d x %d)", speed, W, H,
                          out->width, out->height, LM_SSIM_WIN, LM_SSIM_WIN);
    if (lm_model_buckets(im->model) == 2)
        return lm_err_set(err, LM_ERR_ARG, "eval: the motion test aligns bucket 1's LED "
                          "sub-images only: not for the two-bucket model %s", im->model->preset);
    if (is_rgb(im) && k > 0.0f)
        return lm_err_set(err, LM_ERR_ARG, "eval: motion rows with noise are for coded models "
                          "(not %s)", im->model->preset);
    if (is_rgb(im)) {
        lm_motion mo;
        memset(&mo, 0, sizeof mo);
        mo.vx = speed * LM_EVAL_MOTION_DIR_X;
        mo.vy = speed * LM_EVAL_MOTION_DIR_Y;
        return motion_rgb(c, im, truth, &mo, to, out, err);
    }
    lm_flow_opts dfo;
    if (!fo) {
        lm_flow_default_opts(&dfo, LM_FLOW_MEDIUM);
        dfo.nthreads = lm_nthreads(c);
        fo = &dfo;
    }
    /* noise (k > 0): each frame its own draw, in frame order, then the still reference's */
    lm_noise_opts no;
    memset(&no, 0, sizeof no);
    no.gauss_k = k, no.clip = im->sensor_clip, no.bits = im->sensor_bits;
    no.photons = im->photons, no.read_noise = im->read_noise;
    lm_rng r0, r;
    if (rng) r0 = *rng;
    else lm_rng_seed(&r0, 0);
    r = lm_rng_split(&r0, (uint64_t)llround((double)k * 1e6));
    motion_buf b;
    lm_status st = motion_alloc(&b, (size_t)H * W, err);
    if (!st) st = motion_simulate(im, truth, speed, lm_nthreads(c), &b, err);
    for (int i = 0; i < MOTION_FRAMES && !st && k > 0.0f; i++)
        st = lm_forward_noise(b.raw[i], H, W, &no, &r, lm_nthreads(c), err);
    if (lm_model_frames(im->model) == 3) { /* the stacked input, aligned or as recorded */
        if (!st) st = mf_input(&im->sys, b.raw, H, W, 0, fo, ao, lm_nthreads(c), b.mf, err);
        if (!st) st = score_region(c, im, b.mf, to, &b.truth, out, &out->unaligned, err);
        if (!st) st = mf_input(&im->sys, b.raw, H, W, 1, fo, ao, lm_nthreads(c), b.mf, err);
        if (!st) st = score_region(c, im, b.mf, to, &b.truth, out, &out->aligned, err);
    } else {
        if (!st) st = motion_align(&im->sys, H, W, fo, ao, &b, err);
        if (!st) st = score_region(c, im, b.raw[1], to, &b.truth, out, &out->unaligned, err);
        if (!st) st = score_region(c, im, b.remos, to, &b.truth, out, &out->aligned, err);
    }
    if (!st) st = score_still(c, im, to, &b.truth, k > 0.0f ? &no : NULL, &r, out, err);
    motion_buf_free(&b);
    return st;
}

double lm_eval_peak_nm(const float *spec, int n, double wl0, double step)
{
    int m = 0;
    for (int i = 1; i < n; i++)
        if (spec[i] > spec[m]) m = i;
    double pos = m;
    if (m > 0 && m < n - 1) {
        double a = spec[m - 1], b = spec[m], d = spec[m + 1];
        double den = a - 2.0 * b + d;
        if (den < 0.0) pos = m + 0.5 * (a - d) / den;
    }
    return wl0 + pos * step;
}

/* Per row: the row-averaged reconstructed spectrum's peak against the true peak. */
static void rainbow_errors(const lm_cube *pred, int size, lm_eval_rainbow *out)
{
    int H = pred->height, W = pred->width;
    double sum = 0.0;
    out->max_err_nm = -1.0;
    for (int y = 0; y < H; y++) {
        float spec[31];
        for (int b = 0; b < 31; b++) {
            const float *row = lm_cube_band(pred, b) + (size_t)y * W;
            double s = 0.0;
            for (int x = 0; x < W; x++) s += row[x];
            spec[b] = (float)(s / W);
        }
        double peak = lm_eval_peak_nm(spec, 31, 400.0, 10.0), want = lm_synth_rainbow_peak(y, size);
        double e = fabs(peak - want);
        if (y < LM_EVAL_RAINBOW_MAX_ROWS) {
            out->row_true_nm[y] = (float)want;
            out->row_peak_nm[y] = (float)peak;
        }
        sum += e;
        if (e > out->max_err_nm) {
            out->max_err_nm = e;
            out->worst_row = y;
        }
    }
    out->mean_err_nm = sum / H;
}

lm_status lm_eval_rainbow_run(lm_ctx *c, const lm_infer_model *im, int size,
                              const lm_tile_opts *to, lm_eval_rainbow *out, lm_err *err)
{
    memset(out, 0, sizeof *out);
    out->size = size;
    if (size < 2) return lm_err_set(err, LM_ERR_ARG, "eval: rainbow size %d (need >= 2)", size);
    lm_cube truth;
    lm_status st = lm_synth_rainbow(size, size, &truth, err);
    if (st) return st;
    st = lm_eval_prepare(&truth, im->model->mosaic.ty, im->model->mosaic.tx, err);
    float *frame = st ? NULL : malloc(sizeof(float) * planes_of(im) *
                                      (size_t)truth.height * truth.width);
    if (!st && !frame) st = lm_err_set(err, LM_ERR_NOMEM, "eval: out of memory");
    lm_cube pred;
    memset(&pred, 0, sizeof pred);
    if (!st) st = simulate(im, &truth, NULL, NULL, lm_nthreads(c), frame, err);
    if (!st) st = lm_eval_reconstruct(c, im, frame, truth.height, truth.width, to, 0, &pred, err);
    if (!st) st = lm_metrics_compute(pred.data, truth.data, 31, truth.height, truth.width, 0, 31,
                                     &out->m, err);
    if (!st) {
        out->height = truth.height;
        out->width = truth.width;
        rainbow_errors(&pred, size, out);
    }
    lm_cube_free(&pred);
    free(frame);
    lm_cube_free(&truth);
    return st;
}

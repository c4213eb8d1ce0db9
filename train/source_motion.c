/* source_motion.c — training batches with moving scenes: the dataset's own
 * samples (same scenes, split, tile-aligned patch positions, flips, noise level k), of which a
 * share `fraction` of the real-scene ones is replaced by the same patch seen moving during the
 * exposure, as the video forward model simulates it (data/video.h): each LED's pixels average
 * the scene over that LED's own window (`samples` instants), the target is the scene at the
 * ground-truth instant (the centre of the reference LED's window). Motion per sample: a
 * translation at a speed uniform in [0, speed] px/s in a uniform direction, and a rotation about
 * the patch centre uniform in [-rotation, rotation] deg/s.
 * Cheaper than lm_video_frame on the cube, with the same result up to float rounding: the
 * forward model is linear per band and so is bilinear warping, so the crop's 41 bins are first
 * reduced to the LEDs' images U_l = a_l . r, and each pixel samples only its own LED's image at
 * its LED's instants (one plane per pixel instead of 41 bands per instant).
 * Noise: Gaussian, k x the largest clean value of the patch, as the dataset's (plus its clip /
 * bits options), drawn from (seed, sample index). Deterministic: batch `index` is a pure function
 * of (seed, index). Validation samples stay static (motion is scored by `eval --motion`).
 * Multi-frame samples (frames 3, the "-mf3" models' input; train.h): every sample is three
 * coded frames i-1, i, i+1 of the same patch (moving or, for the rest, still), each with its
 * own noise, aligned by lm_align_stack (data/align.h) exactly as inference aligns a video.
 * What it is not: occlusion by moving regions (global motion only). */
#include "train/train.h"
#include "data/align.h"
#include "data/cube_io.h"
#include "data/dataset.h"
#include "data/spectra.h"
#include "data/video.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

typedef struct motion_src {
    lm_dataset *d;
    const lm_system *sys;
    lm_train_motion_opts o;
    int ph, pw;
    uint64_t seed;
    lm_cube *scenes;       /* training scenes, loaded on first use (31 bands, / maximum) */
    int nscenes;
    int frames;            /* 1, or 3: multi-frame samples */
    float t[LM_SYSTEM_MAX_TILE]; /* multi-frame: phase times and reference phase (align.h) */
    int ref;
    lm_flow_opts fo;       /* the flow inference uses by default (medium preset), 1 thread */
} motion_src;

static lm_status scene(motion_src *s, int i, const lm_cube **out, lm_err *err)
{
    if (!s->scenes[i].data) {
        lm_cube_read_opts o;
        lm_cube_read_opts_default(&o);
        o.keep.count = 0;
        const char *path = lm_dataset_scene_path(s->d, LM_SPLIT_TRAIN, i);
        lm_status st = lm_cube_read_with(path, &o, &s->scenes[i], err);
        if (st) return st;
        float mx = lm_cube_max(&s->scenes[i]);
        if (s->scenes[i].bands != 31 || !(mx > 0.0f) || !isfinite(mx)) {
            lm_cube_free(&s->scenes[i]);
            return lm_err_set(err, LM_ERR_FORMAT, "%s: not a 31-band scene with a positive "
                              "maximum", path);
        }
        size_t n = (size_t)31 * s->scenes[i].height * s->scenes[i].width;
        for (size_t k = 0; k < n; k++) s->scenes[i].data[k] /= mx;
    }
    *out = &s->scenes[i];
    return LM_OK;
}

/* Bilinear sample of plane p (H x W) at (x, y), positions clamped to the plane. */
static float bilinear(const float *p, int H, int W, double x, double y)
{
    x = x < 0 ? 0 : x > W - 1 ? W - 1 : x;
    y = y < 0 ? 0 : y > H - 1 ? H - 1 : y;
    int x0 = (int)x, y0 = (int)y;
    int x1 = x0 + 1 < W ? x0 + 1 : x0, y1 = y0 + 1 < H ? y0 + 1 : y0;
    double fx = x - x0, fy = y - y0;
    double a = p[(size_t)y0 * W + x0] * (1 - fx) + p[(size_t)y0 * W + x1] * fx;
    double b = p[(size_t)y1 * W + x0] * (1 - fx) + p[(size_t)y1 * W + x1] * fx;
    return (float)(a * (1 - fy) + b * fy);
}

/* The LED images U_l = a_l . r of the 31-band crop (L x H x W, calloc'ed into *u). */
static lm_status led_images(const lm_system *sys, const lm_cube *c31, float **u, lm_err *err)
{
    const int L = sys->nleds, H = c31->height, W = c31->width;
    lm_cube c41 = {0};
    *u = NULL;
    lm_status st = lm_cube_mirror41(c31, &c41, err);
    if (!st && !(*u = calloc((size_t)L * H * W, sizeof **u)))
        st = lm_err_set(err, LM_ERR_NOMEM, "motion source: out of memory");
    for (int l = 0; !st && l < L; l++) {
        const float *a = sys->leds[l].response;
        float *ul = *u + (size_t)l * H * W;
        for (int b = 0; b < c41.bands; b++) {
            const float *band = lm_cube_band(&c41, b);
            for (size_t k = 0; k < (size_t)H * W; k++) ul[k] += a[b] * band[k];
        }
    }
    lm_cube_free(&c41);
    return st;
}

/* Rows [py, py + ph) x columns [px, px + pw) of the coded frame whose exposure starts t0 s
 * after the motion's time origin: each pixel its LED's image at its LED's instants + t0. */
static void render_raw(const lm_system *sys, const float *u, int H, int W, const lm_motion *m,
                       int S, double t0, int py, int px, int ph, int pw, float *raw)
{
    for (int y = 0; y < ph; y++)
        for (int x = 0; x < pw; x++) {
            const int l = lm_system_pixel_led(sys, y, x);
            double acc = 0;
            for (int k = 0; k < S; k++) {
                double sx, sy, t = t0 + lm_video_led_instant_us(sys, l, k, S) * 1e-6;
                lm_motion_source(m, H, W, t, px + x, py + y, &sx, &sy);
                acc += bilinear(u + (size_t)l * H * W, H, W, sx, sy);
            }
            raw[(size_t)y * pw + x] = (float)(acc / S);
        }
}

/* The 33-channel target of the patch: the scene at the ground-truth instant + t0. */
static lm_status render_target(const lm_system *sys, const lm_cube *c31, const lm_motion *m,
                               double t0, int py, int px, int ph, int pw, float *target,
                               lm_err *err)
{
    const int H = c31->height, W = c31->width;
    lm_cube g31 = {0}, g41 = {0}, t33 = {0};
    lm_status st = lm_cube_alloc(&g31, 31, ph, pw, 400.0f, 10.0f);
    const double tg = t0 + lm_video_gt_time_us(sys) * 1e-6;
    for (int y = 0; !st && y < ph; y++)
        for (int x = 0; x < pw; x++) {
            double sx, sy;
            lm_motion_source(m, H, W, tg, px + x, py + y, &sx, &sy);
            for (int b = 0; b < 31; b++)
                lm_cube_band(&g31, b)[(size_t)y * pw + x] =
                    bilinear(lm_cube_band(c31, b), H, W, sx, sy);
        }
    if (!st) st = lm_cube_mirror41(&g31, &g41, err);
    if (!st) st = lm_cube_target33(&g41, &t33, err);
    if (!st) memcpy(target, t33.data, sizeof(float) * LM_TARGET_CHANNELS * ph * pw);
    lm_cube_free(&g31), lm_cube_free(&g41), lm_cube_free(&t33);
    return st;
}

lm_status lm_train_motion_render(const lm_system *sys, const lm_cube *c31, const lm_motion *m,
                                 int samples, int py, int px, int ph, int pw, float *raw,
                                 float *target, lm_err *err)
{
    const int H = c31->height, W = c31->width;
    if (c31->bands != 31 || py < 0 || px < 0 || py + ph > H || px + pw > W || samples < 1)
        return lm_err_set(err, LM_ERR_ARG, "motion: a %dx%d patch at (%d, %d) of a %d-band "
                          "%dx%d crop, %d samples", ph, pw, py, px, c31->bands, H, W, samples);
    float *u = NULL;
    lm_status st = led_images(sys, c31, &u, err);
    if (!st) render_raw(sys, u, H, W, m, samples, 0.0, py, px, ph, pw, raw);
    free(u);
    if (!st) st = render_target(sys, c31, m, 0.0, py, px, ph, pw, target, err);
    return st;
}

/* One moving sample: raw (ph x pw) and target (33 x ph x pw) of sample i's patch. */
static lm_status moving_sample(motion_src *s, long i, const lm_dataset_sample_info *info,
                               lm_rng *r, float *raw, float *target, lm_err *err)
{
    const lm_system *sys = s->sys;
    const int ph = s->ph, pw = s->pw;
    const lm_cube *sc = NULL;
    lm_status st = scene(s, info->scene, &sc, err);
    if (st) return st;
    /* the motion */
    const double speed = s->o.speed * lm_rng_uniform(r), dir = 2 * M_PI * lm_rng_uniform(r);
    const double rot = s->o.rotation * (2 * lm_rng_uniform(r) - 1);
    const double t_end = sys->nsubframes * sys->subframe_us * 1e-6; /* exposure, s */
    const double reach = 0.5 * sqrt((double)ph * ph + (double)pw * pw);
    const int M = (int)ceil(speed * t_end + fabs(rot) * M_PI / 180 * t_end * reach) + 2;
    /* the crop: the patch and M pixels around it, inside the scene */
    const int y0 = info->y0 - M > 0 ? info->y0 - M : 0, x0 = info->x0 - M > 0 ? info->x0 - M : 0;
    const int y1 = info->y0 + ph + M < sc->height ? info->y0 + ph + M : sc->height;
    const int x1 = info->x0 + pw + M < sc->width ? info->x0 + pw + M : sc->width;
    const int H = y1 - y0, W = x1 - x0;
    lm_cube c31 = {0};
    st = lm_cube_alloc(&c31, 31, H, W, 400.0f, 10.0f);
    for (int b = 0; !st && b < 31; b++) /* flips of the whole crop, as the dataset flips */
        for (int y = 0; y < H; y++) {
            const float *src = lm_cube_band(sc, b) +
                               (size_t)(y0 + (info->flip_v ? H - 1 - y : y)) * sc->width + x0;
            float *dst = lm_cube_band(&c31, b) + (size_t)y * W;
            for (int x = 0; x < W; x++) dst[x] = src[info->flip_h ? W - 1 - x : x];
        }
    /* the patch's place in the (flipped) crop */
    const int py = info->flip_v ? y1 - (info->y0 + ph) : info->y0 - y0;
    const int px = info->flip_h ? x1 - (info->x0 + pw) : info->x0 - x0;
    lm_motion m = {0};
    m.vx = speed * cos(dir), m.vy = speed * sin(dir), m.rot_deg_s = rot;
    m.has_centre = 1, m.cx = px + (pw - 1) / 2.0, m.cy = py + (ph - 1) / 2.0;
    if (!st) st = lm_train_motion_render(sys, &c31, &m, s->o.samples, py, px, ph, pw, raw, target,
                                         err);
    if (!st && (info->noise_k > 0.0f || s->o.clip || s->o.bits || s->o.photons > 0.0f ||
                s->o.read_noise > 0.0f)) {
        lm_noise_opts no = {0};
        no.gauss_k = info->noise_k, no.clip = s->o.clip, no.bits = s->o.bits;
        no.photons = s->o.photons, no.read_noise = s->o.read_noise;
        lm_rng nr = lm_rng_split(r, (uint64_t)i);
        st = lm_forward_noise(raw, ph, pw, &no, &nr, 1, err);
    }
    lm_cube_free(&c31);
    return st;
}

static lm_status motion_batch(void *user, long index, int B, float *raw, float *target,
                              lm_err *err)
{
    motion_src *s = user;
    lm_status st = lm_dataset_batch(s->d, index, B, raw, target, err);
    const size_t plane = (size_t)s->ph * s->pw;
    lm_rng base;
    lm_rng_seed(&base, s->seed ^ 0x6d6f74696f6eULL); /* "motion" */
    for (int j = 0; !st && j < B; j++) {
        const long i = index * B + j;
        lm_rng r = lm_rng_split(&base, (uint64_t)i);
        if (!(lm_rng_uniform(&r) < s->o.fraction)) continue;
        lm_dataset_sample_info info;
        if ((st = lm_dataset_sample_info_get(s->d, LM_SPLIT_TRAIN, i, &info, err))) break;
        if (info.kind != LM_SAMPLE_SCENE) continue; /* synthetic samples stay static */
        st = moving_sample(s, i, &info, &r, raw + j * plane,
                           target + (size_t)j * LM_TARGET_CHANNELS * plane, err);
    }
    return st;
}

/* ---- multi-frame samples ----------------------------------------------------------------- */

/* Noise of frame f (0, 1, 2 = i-1, i, i+1) of training sample i: Gaussian k x that frame's
 * largest clean value (+ the sensor options), from lm_rng_split(seed ^ "mfnoise", 3 i + f). */
static lm_status mf_noise(const motion_src *s, long i, int f, float k, float *img, int h, int w,
                          lm_err *err)
{
    if (!(k > 0.0f || s->o.clip || s->o.bits || s->o.photons > 0.0f || s->o.read_noise > 0.0f))
        return LM_OK;
    lm_noise_opts no = {0};
    no.gauss_k = k, no.clip = s->o.clip, no.bits = s->o.bits;
    no.photons = s->o.photons, no.read_noise = s->o.read_noise;
    lm_rng nr;
    lm_train_mf_noise_rng(s->seed, i, f, &nr);
    return lm_forward_noise(img, h, w, &no, &nr, 1, err);
}

/* Planes of the three frames fr[0..2] (each wh x ww) aligned (s->o.align) onto frame 1, then
 * rows [my, my + ph) x columns [mx, mx + pw) of each into raw (plane 0: frame i aligned,
 * plane 1: frame i-1, plane 2: frame i+1). */
static lm_status mf_stack(const motion_src *s, float *const fr[3], int wh, int ww, int my,
                          int mx, float *raw, lm_err *err)
{
    const int ty = s->sys->tile_rows, tx = s->sys->tile_cols, np = ty * tx, ph = s->ph,
              pw = s->pw;
    const size_t n = (size_t)wh * ww;
    float *buf = NULL;
    const float *src[3] = {fr[1], fr[0], fr[2]};
    lm_status st = LM_OK;
    if (s->o.align) {
        if (!(buf = malloc(sizeof(float) * 7 * n)))
            return lm_err_set(err, LM_ERR_NOMEM, "motion source: out of memory");
        float *pl = buf, *st3 = buf + 3 * n, *rm = buf + 6 * n; /* planes, stack, remosaic */
        for (int f = 0; f < 3 && !st; f++)
            st = lm_align_unshuffle(fr[f], wh, ww, ty, tx, pl + f * n, err);
        if (!st) st = lm_align_stack(pl, pl + n, pl + 2 * n, np, wh / ty, ww / tx, s->t, s->ref,
                                     &s->fo, NULL, st3, err);
        for (int q = 0; q < 3 && !st; q++) { /* re-mosaicked in place of the unshuffled frames */
            st = lm_align_remosaic(st3 + q * n, wh / ty, ww / tx, ty, tx, rm, err);
            memcpy(pl + q * n, rm, sizeof(float) * n);
            src[q] = pl + q * n;
        }
    }
    for (int q = 0; q < 3 && !st; q++)
        for (int y = 0; y < ph; y++)
            memcpy(raw + ((size_t)q * ph + y) * pw, src[q] + (size_t)(my + y) * ww + mx,
                   sizeof(float) * pw);
    free(buf);
    return st;
}

/* A real-scene multi-frame sample: the patch inside a window of LM_TRAIN_MF_MARGIN_Y /
 * LM_TRAIN_MF_MARGIN_X more rows / columns each side (the flow needs sub-images of at least
 * lm_flow_min_size; inference has whole frames), rendered at frames i-1, i, i+1 (exposures
 * starting one frame period apart; motion `speed` px/s at `dir`, `rot` deg/s; still for speed
 * = rot = 0), each with its own noise; the target is frame i's at its ground-truth instant.
 * Outside the scene the crop repeats the border. */
static lm_status mf_scene_sample(motion_src *s, long i, const lm_dataset_sample_info *info,
                                 double speed, double dir, double rot, float *raw,
                                 float *target, lm_err *err)
{
    const lm_system *sys = s->sys;
    const int ph = s->ph, pw = s->pw;
    int my, mx;
    lm_train_mf_margins(sys, ph, pw, &my, &mx);
    const int wh = ph + 2 * my, ww = pw + 2 * mx;
    const lm_cube *sc = NULL;
    lm_status st = scene(s, info->scene, &sc, err);
    if (st) return st;
    const double T = lm_system_frame_period_us(sys) * 1e-6;
    const double t_end = sys->nsubframes * sys->subframe_us * 1e-6;
    const double reach = 0.5 * sqrt((double)wh * wh + (double)ww * ww);
    const int M = (int)ceil(speed * (T + t_end) + fabs(rot) * M_PI / 180 * (T + t_end) * reach) + 2;
    const int H = wh + 2 * M, W = ww + 2 * M;
    lm_cube c31 = {0};
    float *u = NULL, *fr = malloc(sizeof(float) * 3 * (size_t)wh * ww);
    st = fr ? lm_cube_alloc(&c31, 31, H, W, 400.0f, 10.0f)
            : lm_err_set(err, LM_ERR_NOMEM, "motion source: out of memory");
    for (int b = 0; !st && b < 31; b++) /* the patch's flips extended to the crop, clamped */
        for (int Y = 0; Y < H; Y++) {
            int y = Y - M - my, sy = info->flip_v ? info->y0 + ph - 1 - y : info->y0 + y;
            sy = sy < 0 ? 0 : sy >= sc->height ? sc->height - 1 : sy;
            const float *row = lm_cube_band(sc, b) + (size_t)sy * sc->width;
            float *dst = lm_cube_band(&c31, b) + (size_t)Y * W;
            for (int X = 0; X < W; X++) {
                int x = X - M - mx, sx = info->flip_h ? info->x0 + pw - 1 - x : info->x0 + x;
                dst[X] = row[sx < 0 ? 0 : sx >= sc->width ? sc->width - 1 : sx];
            }
        }
    lm_motion m = {0};
    m.vx = speed * cos(dir), m.vy = speed * sin(dir), m.rot_deg_s = rot;
    m.has_centre = 1, m.cx = M + mx + (pw - 1) / 2.0, m.cy = M + my + (ph - 1) / 2.0;
    if (!st) st = led_images(sys, &c31, &u, err);
    float *f3[3] = {fr, fr + (size_t)wh * ww, fr + 2 * (size_t)wh * ww};
    for (int f = 0; f < 3 && !st; f++) {
        render_raw(sys, u, H, W, &m, s->o.samples, (f - 1) * T, M, M, wh, ww, f3[f]);
        st = mf_noise(s, i, f, info->noise_k, f3[f], wh, ww, err);
    }
    if (!st) st = render_target(sys, &c31, &m, 0.0, M + my, M + mx, ph, pw, target, err);
    if (!st) st = mf_stack(s, f3, wh, ww, my, mx, raw, err);
    free(u);
    free(fr);
    lm_cube_free(&c31);
    return st;
}

/* A synthetic (still) multi-frame sample: the dataset's clean patch, three noise draws; no
 * alignment (a 66 x 64 patch's sub-images are below the flow's minimum size, and the scene is
 * still). */
static lm_status mf_synth_sample(motion_src *s, long i, const lm_dataset_sample_info *info,
                                 float *raw, float *target, lm_err *err)
{
    const size_t n = (size_t)s->ph * s->pw;
    lm_status st = lm_dataset_sample_clean(s->d, i, raw + n, target, err);
    if (!st) memcpy(raw, raw + n, sizeof(float) * n);
    if (!st) memcpy(raw + 2 * n, raw + n, sizeof(float) * n);
    const int fi[3] = {1, 0, 2}; /* plane q holds frame fi[q] */
    for (int q = 0; q < 3 && !st; q++)
        st = mf_noise(s, i, fi[q], info->noise_k, raw + q * n, s->ph, s->pw, err);
    return st;
}

static lm_status mf_batch(void *user, long index, int B, float *raw, float *target, lm_err *err)
{
    motion_src *s = user;
    const size_t plane = (size_t)s->ph * s->pw;
    lm_rng base;
    lm_rng_seed(&base, s->seed ^ 0x6d6f74696f6eULL); /* "motion": the single-frame draws */
    lm_status st = LM_OK;
    for (int j = 0; !st && j < B; j++) {
        const long i = index * B + j;
        lm_rng r = lm_rng_split(&base, (uint64_t)i);
        const int moving = lm_rng_uniform(&r) < s->o.fraction;
        lm_dataset_sample_info info;
        if ((st = lm_dataset_sample_info_get(s->d, LM_SPLIT_TRAIN, i, &info, err))) break;
        float *rj = raw + (size_t)j * 3 * plane, *tj = target + (size_t)j * LM_TARGET_CHANNELS * plane;
        if (info.kind != LM_SAMPLE_SCENE) {
            st = mf_synth_sample(s, i, &info, rj, tj, err);
            continue;
        }
        double speed = 0, dir = 0, rot = 0; /* drawn as the single-frame source draws them */
        if (moving) {
            speed = s->o.speed * lm_rng_uniform(&r), dir = 2 * M_PI * lm_rng_uniform(&r);
            rot = s->o.rotation * (2 * lm_rng_uniform(&r) - 1);
        }
        st = mf_scene_sample(s, i, &info, speed, dir, rot, rj, tj, err);
    }
    return st;
}

void lm_train_mf_margins(const lm_system *sys, int ph, int pw, int *my, int *mx)
{
    lm_flow_opts o;
    lm_flow_default_opts(&o, LM_FLOW_MEDIUM);
    const int ty = sys->tile_rows, tx = sys->tile_cols, need = lm_flow_min_size(&o);
    *my = LM_TRAIN_MF_MARGIN_Y, *mx = LM_TRAIN_MF_MARGIN_X;
    while ((ph + 2 * *my) / ty < need) *my += ty; /* whole tiles: phases kept */
    while ((pw + 2 * *mx) / tx < need) *mx += tx;
}

void lm_train_mf_noise_rng(uint64_t seed, long i, int f, lm_rng *out)
{
    lm_rng base;
    lm_rng_seed(&base, seed ^ 0x6d666e6f697365ULL); /* "mfnoise" */
    *out = lm_rng_split(&base, (uint64_t)(3 * i + f));
}

/* Validation stays still: the validation sample as all three frames (the same noise draw). */
static lm_status mf_eval(void *u, int i, float *raw, float *target, lm_err *err)
{
    motion_src *s = u;
    const size_t n = (size_t)s->ph * s->pw;
    lm_status st = lm_dataset_eval_sample(s->d, LM_SPLIT_VAL, i, raw, target, err);
    if (!st) memcpy(raw + n, raw, sizeof(float) * n), memcpy(raw + 2 * n, raw, sizeof(float) * n);
    return st;
}

static int motion_count(void *u)
{
    return lm_dataset_eval_count(((motion_src *)u)->d, LM_SPLIT_VAL);
}

static lm_status motion_eval(void *u, int i, float *raw, float *target, lm_err *err)
{
    return lm_dataset_eval_sample(((motion_src *)u)->d, LM_SPLIT_VAL, i, raw, target, err);
}

lm_status lm_train_source_motion_open(lm_train_source *src, lm_dataset *d, const lm_system *sys,
                                      const lm_train_motion_opts *o, int patch_h, int patch_w,
                                      uint64_t seed, lm_err *err)
{
    memset(src, 0, sizeof *src);
    if (!d || !sys || !o || o->fraction < 0 || o->fraction > 1 || o->speed < 0 ||
        o->rotation < 0 || o->samples < 1 || o->samples > LM_VIDEO_MAX_SAMPLES ||
        (o->frames != 0 && o->frames != 1 && o->frames != 3))
        return lm_err_set(err, LM_ERR_ARG, "motion source: fraction in [0, 1], speed and "
                          "rotation >= 0, samples 1..%d, frames 1 or 3", LM_VIDEO_MAX_SAMPLES);
    if (o->frames == 3 && (patch_h % sys->tile_rows || patch_w % sys->tile_cols))
        return lm_err_set(err, LM_ERR_ARG, "motion source: multi-frame patches must be whole "
                          "tiles (%dx%d, tile %dx%d)", patch_h, patch_w, sys->tile_rows,
                          sys->tile_cols);
    motion_src *s = calloc(1, sizeof *s);
    int n = lm_dataset_num_scenes(d, LM_SPLIT_TRAIN);
    if (s) s->scenes = calloc(n > 0 ? (size_t)n : 1, sizeof *s->scenes);
    if (!s || !s->scenes) {
        free(s);
        return lm_err_set(err, LM_ERR_NOMEM, "motion source: out of memory");
    }
    s->d = d, s->sys = sys, s->o = *o, s->ph = patch_h, s->pw = patch_w, s->seed = seed;
    s->nscenes = n;
    s->frames = o->frames == 3 ? 3 : 1;
    lm_flow_default_opts(&s->fo, LM_FLOW_MEDIUM);
    s->fo.nthreads = 1;
    if (s->frames == 3 && lm_align_phase_times(sys, s->t, &s->ref, err)) {
        free(s->scenes);
        free(s);
        return err->status;
    }
    *src = s->frames == 3 ? (lm_train_source){s, mf_batch, motion_count, mf_eval, NULL}
                          : (lm_train_source){s, motion_batch, motion_count, motion_eval, NULL};
    return LM_OK;
}

void lm_train_source_motion_close(lm_train_source *src)
{
    motion_src *s = src ? src->user : NULL;
    if (s) {
        for (int i = 0; i < s->nscenes; i++) lm_cube_free(&s->scenes[i]);
        free(s->scenes);
    }
    free(s);
    if (src) memset(src, 0, sizeof *src);
}

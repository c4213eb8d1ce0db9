/* cmd_infer.c — `lumosaic infer`: coded frames to 31-band spectral cubes with a trained model.
 * What it is: load the model (infer/model_io.h), read one frame or a sequence (data/frames.h),
 * reconstruct each frame patch-wise (infer/tile.h), write DIR/cube_NNNN.exr (Fichet spectral
 * EXR, 400-700 nm) and an sRGB preview DIR/srgb_NNNN.png per frame into a staging folder that is
 * renamed into place at the end, so a failure leaves nothing half-written. Network outputs below
 * 0 are clamped to 0 before writing (reflectance is non-negative and the EXR writer rejects
 * negative values). A sequence of >= 2 frames is temporally aligned first unless --no-align
 * (system.md §9, data/align.h): each frame's LED sub-images are moved to its lime timestamp
 * with frames i-1, i, i+1 (edge frames as align.h says) and re-mosaicked before reconstruction;
 * only three frames' sub-images are held at a time (read one frame ahead). --device opencl runs
 * the network on an OpenCL device, the weights uploaded once for the run (lm_tile_device).
 * Models with a finite receptive field (linear, rt-*: lm_whole_halo > 0) run on the whole frame
 * in strips (infer/whole.h) unless --tiles (the choice: infer/recon.h). --model auto picks a
 * model per window from a calibration file (infer/auto.h, `lumosaic fit-auto`) and prints the
 * share of each model.
 * Two-bucket models ("-b2" presets) read bucket 0 too: --bucket0 (a frame, pattern or folder
 * like --input, the same count and size), else the bucket0/ folder `simulate --bucket0` writes
 * beside frames/ (the input path with its last "frames" component renamed); bucket 0 is not
 * aligned in time, so such sequences are reconstructed without alignment (a warning). They run
 * in whole-frame strips of both planes like their one-bucket forms (lmmse-b2 without its
 * one-plane host path).
 * Multi-frame models ("-mf3" presets) read frame i with its neighbours: lm_align_stack_frames
 * (data/align.h, the path eval and the training loader use) stacks frame i aligned and frames
 * i-1, i+1 moved onto it; the first (last) frame has no frame i-1 (i+1) and gets frame i
 * aligned in that plane instead (as align.h's edge rule). With --no-align, or sub-images below
 * the flow's minimum, the frames are stacked as recorded (the same duplicates at the ends).
 * They need a sequence of at least two frames (a single frame is refused, exit 2).
 * A camera's own frames (infer/raw.h): --bits / --msb / --black-level / --dark / --flat convert
 * each frame of bucket 1 as it is read, the share of saturated pixels of each is on its progress
 * line (--saturation-mask writes them); a --system of other LED gains than the model's has each
 * frame rescaled per tile phase to the model's gains (lm_recon_camera_frame).
 * What it is not: the flow or the alignment scheme themselves (data/flow.c, data/align.c). */
#include <omp.h>
#include <sys/stat.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "train/dist.h"
#include "data/cube_io.h"
#include "data/frames.h"
#include "data/image.h"
#include "data/srgb.h"
#include "data/align.h"
#include "infer/auto.h"
#include "infer/model_io.h"
#include "infer/raw.h"
#include "infer/recon.h"
#include "infer/tile.h"
#include "tensor/isa.h"

static void help(void)
{
    printf("usage: lumosaic infer --model RUN --input FRAMES --output DIR [--batch N]\n"
           "                      [--threads T] [--system FILE] [--no-align] [--tiles]\n"
           "                      [--device cpu|opencl] [--auto FILE --auto-tol DB]\n"
           "                      [--bucket0 FRAMES] [--precision fp32|bf16]\n"
           "                      [--bits B [--msb]] [--black-level V | --dark FRAMES]\n"
           "                      [--flat FRAMES] [--saturation-mask]\n\n"
           "Reconstruct 31-band cubes (400-700 nm) from coded frames with a trained model,\n"
           "patch-wise: 66 x 64 windows, stride 30 x 32, on the tile grid, blended by a raised-\n"
           "cosine weight; models with a finite receptive field (linear, rt-8, rt-16) instead\n"
           "run on the whole frame in strips (same result away from window borders, ~4x less\n"
           "work) unless --tiles. Writes DIR/cube_NNNN.exr (spectral OpenEXR, channels T.<nm>nm;\n"
           "negative outputs clamped to 0) and DIR/srgb_NNNN.png (D65 preview) per frame.\n\n"
           "  --model RUN      a training run folder (its model.safetensors) or a .safetensors\n"
           "                   file written by 'lumosaic train'; or 'auto': without --auto,\n"
           "                   the bundled two-bucket model when bucket 0 is there (--bucket0,\n"
           "                   or a bucket0/ folder beside the input's frames/), else the\n"
           "                   bundled single-bucket model (models/demo/, or LM_MODELS_DIR);\n"
           "                   with --auto, per window, the cheapest calibrated model whose\n"
           "                   expected PSNR is within --auto-tol dB of the best model's\n"
           "                   (patch-wise only; prints the share of windows per model).\n"
           "                   One line names the model used and the buckets it read\n"
           "  --auto FILE      calibration written by 'lumosaic fit-auto' (for --model auto)\n"
           "  --auto-tol DB    accuracy the auto choice may give up per window, in dB of\n"
           "                   expected PSNR (>= 0; default 0.5; 0 = always the best model)\n"
           "  --tiles          patch-wise even for models that can run on the whole frame\n"
           "  --input FRAMES   one coded frame (.png/.tif/.exr), a numbered pattern\n"
           "                   (frame_%%04d.png) or a folder of frames; the size must be a\n"
           "                   multiple of the mosaic tile and at least 66 x 64\n"
           "  --bucket0 FRAMES two-bucket models (\"-b2\" presets): bucket 0 of the same frames,\n"
           "                   stored / (LEDs - 1) as 'simulate --bucket0' writes it (a file,\n"
           "                   pattern or folder; same count and size as --input). Default:\n"
           "                   the bucket0/ folder beside the input's frames/ folder\n"
           "  --output DIR     output folder (must not exist, or be empty); written atomically\n"
           "  --batch N        windows per network call (1..4096; default 8)\n"
           "  --threads T      OpenMP threads (1..1024; default: all cores)\n"
           "  --system FILE    system description of the camera (default: the one recorded in\n"
           "                   the model). One that differs from the model's only in LED gains\n"
           "                   or allocations (a 'lumosaic calibrate' output) is accepted: each\n"
           "                   tile phase of every frame is rescaled to the model's gains (and\n"
           "                   the noise level with it; one line says so). Another tile map,\n"
           "                   other LEDs or another sensor are refused\n"
           "  --no-align       do not align a sequence in time. By default, for 2 or more\n"
           "                   frames, each LED sub-image is moved to the frame's lime-LED\n"
           "                   time by optical flow to the neighbouring frames (needs\n"
           "                   sub-images of at least 24 x 24 pixels; smaller frames are\n"
           "                   reconstructed unaligned, with a warning). Multi-frame\n"
           "                   models (\"-mf3\") need 2 or more frames and read each frame\n"
           "                   aligned with its neighbours moved onto it (the first and last\n"
           "                   frame: itself for the missing one); --no-align stacks them\n"
           "                   as recorded\n"
           "  --device D       where the network runs: cpu or opencl (default: env LM_DEVICE,\n"
           "                   else cpu); the weights are copied to the device once\n"
           "  --noise-level K  for models that read the noise level (lmmse and residuals on\n"
           "                   it): Gaussian noise sd = K x the frame's maximum (0..1), as\n"
           "                   simulate --noise K. Default: estimated from each frame\n"
           LM_CLI_PRECISION_HELP
           "Raw frames from a camera (one-bucket models; defaults: none of these). A frame's\n"
           "value 1.0 is full scale, the largest code: the system's white (info --system).\n"
           "  --bits B         integer files hold B-bit data (1..16), e.g. 12-bit in a 16-bit\n"
           "                   PNG/TIFF: LSB-aligned (codes 0..2^B-1) unless --msb; code\n"
           "                   2^B-1 is full scale. A code outside that layout is an error\n"
           "  --msb            the B bits are the file's high bits (codes x 2^(16-B))\n"
           "  --black-level V  subtract V (in B-bit codes; float files: in their units):\n"
           "                   (code - V) / (full scale - V)\n"
           "  --dark FRAMES    dark frames (file, pattern or folder; averaged), subtracted per\n"
           "                   pixel: (x - dark) / (1 - mean dark); not with --black-level\n"
           "  --flat FRAMES    frames of a white target (averaged, dark-subtracted): each\n"
           "                   pixel divided by its gain, the flat over its tile phase's mean\n"
           "                   (each LED keeps its level); pixels under 5 %% of it are left\n"
           "  --saturation-mask  also write DIR/saturated_NNNN.png (65535 where a pixel is at\n"
           "                   full scale, else 0). Every frame's progress line gives the\n"
           "                   share of saturated pixels\n"
           "  --help           this text\n");
}

typedef struct infer_opts {
    const char *model, *input, *output, *system, *auto_file, *bucket0;
    lm_cli_common com; /* --threads, --device */
    lm_raw_opts raw;   /* --bits, --msb, --black-level, --dark, --flat */
    int sat_mask;
    long long batch;
    double auto_tol, noise_level;
    int no_align, tiles, is_auto;
} infer_opts;

/* 1: run, 0: help printed, 2: bad usage (printed). */
static int parse(lm_cli *c, infer_opts *o)
{
    *o = (infer_opts){.batch = 8, .auto_tol = 0.5, .noise_level = -1.0};
    long long bits = 0;
    while (!lm_cli_done(c)) {
        int r;
        if (lm_cli_is_help(c)) {
            help();
            return 0;
        }
        if ((r = lm_cli_value(c, "--model", &o->model)) ||
            (r = lm_cli_value(c, "--input", &o->input)) ||
            (r = lm_cli_value(c, "--output", &o->output)) ||
            (r = lm_cli_value(c, "--system", &o->system)) ||
            (r = lm_cli_value(c, "--auto", &o->auto_file)) ||
            (r = lm_cli_value(c, "--bucket0", &o->bucket0)) ||
            (r = lm_cli_real(c, "--auto-tol", 0.0, 1e6, &o->auto_tol)) ||
            (r = lm_cli_real(c, "--noise-level", 0.0, 1.0, &o->noise_level)) ||
            (r = lm_cli_flag(c, "--tiles", &o->tiles)) ||
            (r = lm_cli_int(c, "--bits", 1, 16, &bits)) ||
            (r = lm_cli_flag(c, "--msb", &o->raw.msb)) ||
            (r = lm_cli_real(c, "--black-level", 0.0, 65535.0, &o->raw.black)) ||
            (r = lm_cli_value(c, "--dark", &o->raw.dark)) ||
            (r = lm_cli_value(c, "--flat", &o->raw.flat)) ||
            (r = lm_cli_flag(c, "--saturation-mask", &o->sat_mask)) ||
            (r = lm_cli_int(c, "--batch", 1, 4096, &o->batch)) ||
            (r = lm_cli_common_opt(c, LM_CLI_THREADS | LM_CLI_DEVICE | LM_CLI_PRECISION, 0, &o->com)) ||
            (r = lm_cli_flag(c, "--no-align", &o->no_align))) {
            if (r < 0) return 2;
            continue;
        }
        return lm_cli_unknown(c);
    }
    o->raw.bits = (int)bits;
    if (o->raw.msb && !bits) return lm_cli_error(c, "--msb needs --bits B");
    if (!o->model) return lm_cli_error(c, "--model is required (see 'lumosaic infer --help')");
    if (!o->input) return lm_cli_error(c, "--input is required (see 'lumosaic infer --help')");
    if (!o->output) return lm_cli_error(c, "--output is required (see 'lumosaic infer --help')");
    o->is_auto = !strcmp(o->model, "auto") && o->auto_file; /* else a bundled model, below */
    if (!o->is_auto && o->auto_file)
        return lm_cli_error(c, "--auto is only for --model auto");
    return 1;
}

/* Exit status for a library error (lm_cli_exit_status); runtime: a failure of this program's
 * own work whatever the status (1). */
static int fail(const lm_cli *c, const lm_err *e, int runtime)
{
    lm_cli_error(c, "%s", e->msg);
    return runtime ? LM_EXIT_FAILED : lm_cli_exit_status(e->status);
}

/* Temporal alignment state: the sub-images (np planes of ph x pw) of frames i-1, i, i+1. */
typedef struct infer_align {
    int on;
    int np, ph, pw, ty, tx, ref;
    float *t;                /* np normalised timestamps */
    lm_flow_opts fo;
    float *prev, *cur, *next; /* np * ph * pw each; prev / next NULL-able views */
    float *buf[3];           /* the storage behind prev / cur / next */
    float *aligned, *raw;    /* aligned planes, re-mosaicked frame */
    int mf;                  /* multi-frame model: raw frames below, the stacked input in mf3 */
    float *fr[3], *mf3;      /* frames i-1, i, i+1 (H x W each); 3 x H x W */
} infer_align;

typedef struct infer_run {
    const lm_cli *c;
    const infer_opts *o;
    const char *model_path; /* --model, or the bundled model --model auto picked */
    int said_model;         /* the model line is printed */
    lm_infer_model im;
    lm_infer_model more[LM_AUTO_MAX_MODELS]; /* auto: models 1.. (model 0 is im) */
    lm_model *models[LM_AUTO_MAX_MODELS];
    lm_auto_calib cal;
    int choice[LM_AUTO_MAX_BINS];
    long windows[LM_AUTO_MAX_MODELS];
    lm_frame_seq seq;
    lm_frame_seq seq0;   /* two-bucket models: bucket 0 of the frames (count 0 otherwise) */
    float *in2;          /* two-bucket models: bucket 1 then bucket 0, 2 x H x W */
    lm_srgb srgb;
    lm_raw raw;          /* --bits, --black-level, --dark, --flat */
    double *sat;         /* per frame: the share of saturated pixels (-1: not read here) */
    lm_ctx ctx;
    lm_tile_device dev;
    float *rgb;
    infer_align al;
    char tmp[1100];
    int first, end;  /* the frames this process reconstructs: [first, end) */
} infer_run;

/* Frame i's saturated pixels (1.0, else 0) as DIR/saturated_NNNN.png (the frame read again). */
static int write_mask(infer_run *r, int i, int number, lm_err *e)
{
    lm_frame f;
    if (lm_frame_seq_read(&r->seq, i, &f, e)) return fail(r->c, e, 0);
    const size_t n = (size_t)f.height * f.width;
    uint8_t *m = malloc(n);
    if (!m) {
        lm_frame_free(&f);
        return lm_cli_error(r->c, "out of memory (saturation mask)"), 1;
    }
    lm_raw_saturated(&r->o->raw, &f, m);
    for (size_t k = 0; k < n; k++) f.data[k] = m[k];
    free(m);
    char path[1200];
    snprintf(path, sizeof path, "%s/saturated_%04d.png", r->tmp, number);
    lm_status st = lm_frame_write(path, f.height, f.width, f.data, e);
    lm_frame_free(&f);
    return st ? fail(r->c, e, 1) : 0;
}

/* Read frame i of the sequence converted to the system's scale (--bits, --black-level, --dark,
 * --flat; infer/raw.h), its share of saturated pixels noted in r->sat[i]. */
static lm_status read_frame(infer_run *r, int i, lm_frame *f, lm_err *e)
{
    if (lm_frame_seq_read(&r->seq, i, f, e)) return e->status;
    r->sat[i] = lm_raw_saturated(&r->o->raw, f, NULL);
    if (lm_raw_apply(&r->raw, f, r->seq.paths[i], e)) {
        lm_frame_free(f);
        return e->status;
    }
    return LM_OK;
}

/* Write one reconstructed cube (clamped to >= 0) and its sRGB preview into the staging dir. */
static int write_frame(infer_run *r, lm_cube *cube, int number, lm_err *e)
{
    lm_recon_clamp(cube);
    char path[1200];
    snprintf(path, sizeof path, "%s/cube_%04d.exr", r->tmp, number);
    if (lm_cube_write_exr(path, cube, e)) return fail(r->c, e, 1);
    snprintf(path, sizeof path, "%s/srgb_%04d.png", r->tmp, number);
    if (lm_srgb_render(&r->srgb, cube, 1.0f, NULL, r->rgb, e) ||
        lm_image_write_rgb8(path, cube->width, cube->height, r->rgb, e))
        return fail(r->c, e, 1);
    return r->o->sat_mask ? write_mask(r, number - r->seq.first_index, number, e) : 0;
}

static void align_free(infer_align *a)
{
    for (int k = 0; k < 3; k++) free(a->buf[k]), free(a->fr[k]);
    free(a->mf3);
    free(a->t);
    free(a->aligned);
    free(a->raw);
    memset(a, 0, sizeof *a);
}

/* Multi-frame models: the stacking buffers and checks. 0 ok, else an exit status (printed). */
static int mf_init(infer_run *r)
{
    infer_align *a = &r->al;
    if (r->o->is_auto || lm_model_frames(r->im.model) == 1) return 0;
    if (r->seq.count < 2)
        return lm_cli_error(r->c, "%s: model %s reads three frames (the current one and its "
                            "neighbours): give a sequence of at least 2 frames", r->o->input,
                            r->im.model->preset);
    size_t n = (size_t)r->seq.height * r->seq.width;
    for (int k = 0; k < 3; k++) a->fr[k] = malloc(sizeof(float) * n);
    a->mf3 = malloc(sizeof(float) * 3 * n);
    if (!a->fr[0] || !a->fr[1] || !a->fr[2] || !a->mf3) {
        lm_cli_error(r->c, "out of memory (multi-frame buffers)");
        return 1;
    }
    a->mf = 1;
    lm_flow_default_opts(&a->fo, LM_FLOW_MEDIUM);
    a->fo.nthreads = r->o->com.threads > 0 ? (int)r->o->com.threads : omp_get_max_threads();
    const lm_system *s = &r->im.sys;
    int need = lm_flow_min_size(&a->fo);
    if (!r->o->no_align && (r->seq.height / s->tile_rows < need || r->seq.width / s->tile_cols < need))
        fprintf(stderr, "lumosaic infer: warning: sub-images %dx%d are smaller than %dx%d: "
                "the frames are stacked without temporal alignment\n", r->seq.width /
                s->tile_cols, r->seq.height / s->tile_rows, need, need);
    return 0;
}

/* Multi-frame models: frame i's stacked input in al.mf3 (frames read as needed). */
static lm_status mf_step(infer_run *r, int i, lm_err *e)
{
    infer_align *a = &r->al;
    const float *fr[3] = {NULL, NULL, NULL};
    for (int k = 0; k < 3; k++) {
        int j = i - 1 + k;
        if (j < 0 || j >= r->seq.count) continue;
        lm_frame f;
        if (read_frame(r, j, &f, e)) return e->status;
        memcpy(a->fr[k], f.data, sizeof(float) * (size_t)f.height * f.width);
        lm_frame_free(&f);
        fr[k] = a->fr[k];
    }
    lm_err ae;
    lm_err_clear(&ae);
    if (lm_align_stack_frames(&r->im.sys, fr[0], fr[1], fr[2], r->seq.height, r->seq.width,
                              !r->o->no_align, &a->fo, NULL, a->mf3, &ae))
        return lm_err_set(e, ae.status, "%s: %s", r->seq.paths[i], ae.msg);
    return LM_OK;
}

/* Decide whether to align and allocate its buffers. 0 ok, else an exit status (printed). */
static int align_init(infer_run *r, lm_err *e)
{
    infer_align *a = &r->al;
    const lm_system *s = &r->im.sys;
    if (a->mf || r->o->no_align || r->seq.count < 2 || r->seq0.count) return 0;
    a->ty = s->tile_rows;
    a->tx = s->tile_cols;
    a->np = a->ty * a->tx;
    a->ph = r->seq.height / a->ty;
    a->pw = r->seq.width / a->tx;
    lm_flow_default_opts(&a->fo, LM_FLOW_MEDIUM);
    a->fo.nthreads = r->o->com.threads > 0 ? (int)r->o->com.threads : omp_get_max_threads();
    int need = lm_flow_min_size(&a->fo);
    if (a->ph < need || a->pw < need) {
        fprintf(stderr, "lumosaic infer: warning: sub-images %dx%d are smaller than %dx%d: "
                "frames are reconstructed without temporal alignment\n", a->pw, a->ph, need,
                need);
        return 0;
    }
    size_t n = (size_t)a->np * a->ph * a->pw;
    a->t = malloc(sizeof(float) * a->np);
    a->aligned = malloc(sizeof(float) * n);
    a->raw = malloc(sizeof(float) * n);
    for (int k = 0; k < 3; k++) a->buf[k] = malloc(sizeof(float) * n);
    if (!a->t || !a->aligned || !a->raw || !a->buf[0] || !a->buf[1] || !a->buf[2]) {
        lm_cli_error(r->c, "out of memory (alignment buffers)");
        return 1;
    }
    if (lm_align_phase_times(s, a->t, &a->ref, e)) return fail(r->c, e, 0);
    a->on = 1;
    return 0;
}

/* Read frame i of the sequence and unshuffle it into dst (np planes). */
static lm_status load_planes(infer_run *r, int i, float *dst, lm_err *e)
{
    lm_frame f;
    if (read_frame(r, i, &f, e)) return e->status;
    lm_status st = lm_align_unshuffle(f.data, f.height, f.width, r->al.ty, r->al.tx, dst, e);
    lm_frame_free(&f);
    return st;
}

/* Frame i aligned and re-mosaicked into al.raw; keeps cur = frame i, next = frame i + 1 loaded
 * (frame i - 1 stays as prev). On entry cur holds frame i (and next frame i+1 if i > 0). */
static lm_status align_step(infer_run *r, int i, lm_err *e)
{
    infer_align *a = &r->al;
    if (i == r->first) { /* this process's first frame (MPI ranks take blocks of frames) */
        a->cur = a->buf[i % 3];
        if (load_planes(r, i, a->cur, e)) return e->status;
        a->prev = i > 0 ? a->buf[(i - 1) % 3] : NULL;
        if (i > 0 && load_planes(r, i - 1, a->prev, e)) return e->status;
    }
    if (i + 1 < r->seq.count) {
        a->next = a->buf[(i + 1) % 3];
        if (load_planes(r, i + 1, a->next, e)) return e->status;
    } else {
        a->next = NULL;
    }
    lm_err ae;
    lm_err_clear(&ae);
    if (lm_align_frame(a->prev, a->cur, a->next, a->np, a->ph, a->pw, a->t, a->ref, &a->fo,
                       NULL, a->aligned, &ae) ||
        lm_align_remosaic(a->aligned, a->ph, a->pw, a->ty, a->tx, a->raw, &ae))
        return lm_err_set(e, ae.status, "%s: %s", r->seq.paths[i], ae.msg);
    return LM_OK;
}

/* Frame i's input to the network: aligned, or read as is into *f. *data points at it. */
static lm_status frame_input(infer_run *r, int i, lm_frame *f, const float **data, lm_err *e)
{
    memset(f, 0, sizeof *f);
    if (r->al.mf) {
        if (mf_step(r, i, e)) return e->status;
        *data = r->al.mf3;
        return LM_OK;
    }
    if (r->al.on) {
        if (align_step(r, i, e)) return e->status;
        *data = r->al.raw;
        return LM_OK;
    }
    if (read_frame(r, i, f, e)) return e->status;
    *data = f->data;
    return LM_OK;
}

/* --model auto on one frame: difficulty per window, its bin's model, the mixed fold. */
static lm_status auto_frame(infer_run *r, const float *in, int H, int W, lm_tile_opts *to,
                            lm_cube *cube, lm_err *e)
{
    const lm_auto_calib *a = &r->cal;
    to->win_h = a->win_h, to->win_w = a->win_w, to->stride_y = a->stride_y,
    to->stride_x = a->stride_x;
    const lm_mosaic *mo = &r->im.model->mosaic;
    if (lm_tile_check(to, H, W, mo->ty, mo->tx, e)) return e->status;
    int n = lm_auto_window_count(H, W, to);
    double *d = malloc(sizeof(double) * n);
    int *wm = malloc(sizeof(int) * n);
    lm_status st = d && wm ? LM_OK : lm_err_set(e, LM_ERR_NOMEM, "out of memory");
    if (!st) st = lm_auto_frame_difficulty(a->measure, in, H, W, mo->ty, mo->tx, to,
                                           lm_nthreads(&r->ctx), d, e);
    for (int i = 0; i < n && !st; i++) wm[i] = r->choice[lm_auto_bin(a, d[i])];
    long win[LM_AUTO_MAX_MODELS] = {0};
    if (!st) st = lm_auto_infer(&r->ctx, r->models, a->nmodels, wm, in, H, W, to, cube, win, e);
    if (!st) {
        fprintf(stderr, "auto:");
        for (int m = 0; m < a->nmodels; m++) {
            fprintf(stderr, " %s %.0f%%", a->models[m].preset, 100.0 * win[m] / n);
            r->windows[m] += win[m];
        }
        fprintf(stderr, " of %d windows\n", n);
    }
    free(d);
    free(wm);
    return st;
}

/* Two-bucket models: frame i's bucket 0 after bucket 1 (in) in r->in2; *in points at it. */
/* bits, is_float: bucket 1's frame (bits 0: not known) */
static lm_status with_bucket0(infer_run *r, int i, const float **in, int H, int W, int bits,
                              int is_float, lm_err *e)
{
    if (!r->seq0.count) return LM_OK;
    lm_frame f0;
    if (lm_frame_seq_read(&r->seq0, i, &f0, e)) return e->status;
    lm_status st = LM_OK;
    if (f0.height != H || f0.width != W)
        st = lm_err_set(e, LM_ERR_SHAPE, "%s: bucket 0 is %d x %d, bucket 1 (%s) %d x %d",
                        r->seq0.paths[i], f0.width, f0.height, r->seq.paths[i], W, H);
    else if (bits && (f0.bits != bits || f0.is_float != is_float))
        st = lm_err_set(e, LM_ERR_FORMAT, "%s: bucket 0 is %d-bit%s, bucket 1 (%s) %d-bit%s: the "
                        "two buckets of a frame come from one read-out, in one format",
                        r->seq0.paths[i], f0.bits, f0.is_float ? " float" : "",
                        r->seq.paths[i], bits, is_float ? " float" : "");
    if (!st) {
        const size_t n = (size_t)H * W;
        memcpy(r->in2, *in, sizeof(float) * n);
        memcpy(r->in2 + n, f0.data, sizeof(float) * n);
        *in = r->in2;
    }
    lm_frame_free(&f0);
    return st;
}

/* One frame to a 31-band cube by the run's path: auto, or the fixed model's (infer/recon.h:
 * whole frame or windows). A camera of other gains than the model's: the frame rescaled per
 * tile phase first (infer/raw.h), with the given noise level. */
static lm_status reconstruct(infer_run *r, const float *in, int H, int W, lm_cube *cube,
                             lm_err *e)
{
    if (r->o->is_auto) {
        lm_tile_opts to;
        lm_tile_default_opts(&to);
        to.batch = (int)r->o->batch;
        return auto_frame(r, in, H, W, &to, cube, e);
    }
    lm_recon_opts ro = {.batch = (int)r->o->batch, .tiles = r->o->tiles};
    return lm_recon_camera_frame(&r->ctx, &r->im, in, H, W, &ro, cube, e);
}

/* The share of windows per model over the run and the calibration's expected PSNR. */
static void auto_summary(const infer_run *r)
{
    const lm_auto_calib *a = &r->cal;
    long tot = 0;
    for (int m = 0; m < a->nmodels; m++) tot += r->windows[m];
    int best = 0;
    for (int m = 1; m < a->nmodels; m++)
        if (lm_auto_expected_psnr(a, NULL, m) > lm_auto_expected_psnr(a, NULL, best)) best = m;
    printf("auto (tol %g dB): %ld windows:", r->o->auto_tol, tot);
    for (int m = 0; m < a->nmodels; m++)
        printf(" %s %.1f%%", a->models[m].preset, tot ? 100.0 * r->windows[m] / tot : 0.0);
    printf("\ncalibration: expected PSNR %.2f dB with this choice, %.2f dB always %s\n",
           lm_auto_expected_psnr(a, r->choice, 0), lm_auto_expected_psnr(a, NULL, best),
           a->models[best].preset);
}

static int run_frames(infer_run *r)
{
    lm_err e;
    lm_err_clear(&e);
    for (int i = r->first; i < r->end; i++) {
        double t0 = omp_get_wtime();
        lm_frame f;
        lm_cube cube;
        const float *in = NULL;
        lm_status st = frame_input(r, i, &f, &in, &e);
        if (st) {
            lm_frame_free(&f);
            return fail(r->c, &e, 0);
        }
        double ta = omp_get_wtime();
        const int H = f.height ? f.height : r->seq.height, W = f.width ? f.width : r->seq.width;
        st = with_bucket0(r, i, &in, H, W, f.height ? f.bits : 0, f.is_float, &e);
        if (st) {
            lm_frame_free(&f);
            return fail(r->c, &e, 0);
        }
        st = reconstruct(r, in, H, W, &cube, &e);
        lm_frame_free(&f);
        double t1 = omp_get_wtime();
        if (st) {
            lm_cli_error(r->c, "%s: %s", r->seq.paths[i], e.msg);
            return lm_cli_exit_status(st);
        }
        int rc = write_frame(r, &cube, r->seq.first_index + i, &e);
        lm_cube_free(&cube);
        if (rc) return rc;
        if (r->al.on) { /* rotate: i -> prev, i + 1 -> cur */
            r->al.prev = r->al.cur;
            r->al.cur = r->al.next;
        }
        double t2 = omp_get_wtime();
        char al[48] = "alignment off";
        if (r->al.on || (r->al.mf && !r->o->no_align))
            snprintf(al, sizeof al, "alignment %.2f s", ta - t0);
        if (!r->o->is_auto && !r->said_model) { /* which model, and what it read (once, with
                                                  * the first frame done: an error stays alone) */
            char name[160];
            fprintf(stderr, "model %s (%s%s): %s\n", lm_model_name(r->im.model, name, sizeof name),
                    r->im.weights, strcmp(r->o->model, "auto") ? "" : ", picked by --model auto",
                    r->seq0.count ? "both buckets" : "bucket 1");
            r->said_model = 1;
        }
        fprintf(stderr, "frame %d/%d %s: %.2f s (%s, reconstruction %.2f s, writing %.2f s); "
                "saturated %.3f %%\n", i + 1, r->seq.count, r->seq.paths[i], t2 - t0, al,
                t1 - ta, t2 - t1, 100.0 * r->sat[i]);
    }
    if (r->o->is_auto) auto_summary(r);
    return 0;
}

/* Everything that can be checked before any output is created: model, frames, frame size. */
/* --model auto: the calibration, its models (model 0 into r->im), the choice per bin. */
static int open_auto(infer_run *r, lm_err *e)
{
    lm_auto_calib *a = &r->cal;
    if (lm_auto_load(r->o->auto_file, a, e)) return fail(r->c, e, 0);
    for (int m = 0; m < a->nmodels; m++) {
        lm_infer_model *im = m ? &r->more[m] : &r->im;
        if (lm_infer_model_load(a->models[m].path, r->o->system, im, e))
            return lm_cli_error(r->c, "%s: model %d: %s", r->o->auto_file, m, e->msg);
        r->models[m] = im->model;
        if (im->remap.active)
            return lm_cli_error(r->c, "--model auto: %s has other LED gains than model '%s' "
                                "was trained with: give that model with --model (its frames "
                                "are rescaled to its gains)", im->system_path,
                                a->models[m].path);
        if (lm_model_buckets(im->model) == 2)
            return lm_cli_error(r->c, "%s: model '%s' reads both buckets: --model auto takes "
                                "one-bucket models only", r->o->auto_file, a->models[m].path);
        if (lm_model_frames(im->model) != 1)
            return lm_cli_error(r->c, "%s: model '%s' reads three frames: --model auto takes "
                                "one-frame models only", r->o->auto_file, a->models[m].path);
        if (im->model->mosaic.ty != r->im.model->mosaic.ty ||
            im->model->mosaic.tx != r->im.model->mosaic.tx ||
            im->model->out_channels != LM_MODEL_OUT_CHANNELS)
            return lm_cli_error(r->c, "%s: models '%s' and '%s' do not fit the same system",
                                r->o->auto_file, a->models[0].path, a->models[m].path);
    }
    lm_auto_choose(a, r->o->auto_tol, r->choice);
    return 0;
}

static int open_bucket0(infer_run *r, lm_err *e);

static void bucket0_beside(const char *input, char *out, size_t n);

/* --model auto without a calibration: the bundled two-bucket model when bucket 0 is there
 * (--bucket0, or a bucket0/ folder beside the input's frames/), else the single-bucket one. */
static int pick_bundled(infer_run *r, lm_err *e)
{
    static char path[1200];
    char beside[1100] = "";
    if (!r->o->bucket0) bucket0_beside(r->o->input, beside, sizeof beside);
    const int two = r->o->bucket0 || beside[0];
    if (lm_infer_bundled_model(two ? 2 : 1, path, sizeof path, e)) return fail(r->c, e, 0);
    r->model_path = path;
    return 0;
}

static int open_inputs(infer_run *r, lm_err *e)
{
    r->model_path = r->o->model;
    if (!r->o->is_auto && !strcmp(r->o->model, "auto")) {
        int rc = pick_bundled(r, e);
        if (rc) return rc;
    }
    if (r->o->is_auto) {
        int rc = open_auto(r, e);
        if (rc) return rc;
    } else if (lm_infer_model_load(r->model_path, r->o->system, &r->im, e)) {
        return fail(r->c, e, 0);
    } else {
        r->im.model->noise_given = (float)r->o->noise_level;
    }
    if (lm_frame_seq_open(r->o->input, &r->seq, e)) return fail(r->c, e, 0);
    r->sat = malloc(sizeof(double) * r->seq.count);
    if (!r->sat) return lm_cli_error(r->c, "out of memory"), 1;
    for (int i = 0; i < r->seq.count; i++) r->sat[i] = -1.0;
    if (lm_raw_opts_any(&r->o->raw)) {
        if (!r->o->is_auto && lm_model_buckets(r->im.model) == 2)
            return lm_cli_error(r->c, "--bits, --black-level, --dark and --flat are for one-bucket "
                                "frames (model %s reads both buckets)", r->im.model->preset);
        if (lm_raw_init(&r->raw, &r->o->raw, r->seq.height, r->seq.width, r->im.sys.tile_rows,
                        r->im.sys.tile_cols, e))
            return fail(r->c, e, 0);
        if (r->raw.flat_skipped)
            fprintf(stderr, "lumosaic infer: warning: %ld pixels of the flat are under 5 %% of "
                    "their tile phase's mean: left uncorrected\n", r->raw.flat_skipped);
    }
    if (!r->o->is_auto && r->im.remap.active) {
        char line[3000];
        lm_gain_remap_describe(&r->im.remap, r->im.system_path, r->im.model_system, line,
                               sizeof line);
        fprintf(stderr, "%s\n", line);
    }
    int rc = open_bucket0(r, e);
    if (rc) return rc;
    if (lm_recon_check(r->im.model, r->seq.height, r->seq.width, e))
        return lm_cli_error(r->c, "%s: %s", r->seq.paths[0], e->msg);
    float wl[31];
    for (int b = 0; b < 31; b++) wl[b] = 400.0f + 10.0f * b;
    if (lm_srgb_init(&r->srgb, wl, 31, e)) return fail(r->c, e, 1);
    r->rgb = malloc(sizeof(float) * 3 * (size_t)r->seq.height * r->seq.width);
    if (!r->rgb) {
        lm_cli_error(r->c, "out of memory (%d x %d frame)", r->seq.width, r->seq.height);
        return 1;
    }
    rc = mf_init(r);
    return rc ? rc : align_init(r, e);
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

/* Two-bucket models: open bucket 0 (--bucket0, else beside frames/) and check it against the
 * input; a one-bucket model refuses --bucket0. 0 or an exit status (printed). */
static int open_bucket0(infer_run *r, lm_err *e)
{
    const int two = !r->o->is_auto && lm_model_buckets(r->im.model) == 2;
    if (!two) {
        if (r->o->bucket0)
            return lm_cli_error(r->c, "--bucket0: model %s reads bucket 1 only (two-bucket "
                                "models are the \"-b2\" presets)", r->im.model->preset);
        return 0;
    }
    char found[1100];
    const char *spec = r->o->bucket0;
    if (!spec) {
        bucket0_beside(r->o->input, found, sizeof found);
        if (!found[0])
            return lm_cli_error(r->c, "model %s reads both buckets: give --bucket0 (no bucket0/ "
                                "folder beside the input's frames/)", r->im.model->preset);
        spec = found;
    }
    if (lm_frame_seq_open(spec, &r->seq0, e))
        return lm_cli_error(r->c, "--bucket0: %s", e->msg);
    if (r->seq0.count != r->seq.count)
        return lm_cli_error(r->c, "--bucket0 %s: %d frames, the input has %d", spec,
                            r->seq0.count, r->seq.count);
    if (r->seq0.height != r->seq.height || r->seq0.width != r->seq.width)
        return lm_cli_error(r->c, "%s: bucket 0 is %d x %d, bucket 1 (%s) %d x %d",
                            r->seq0.paths[0], r->seq0.width, r->seq0.height, r->seq.paths[0],
                            r->seq.width, r->seq.height);
    r->in2 = malloc(sizeof(float) * 2 * (size_t)r->seq.height * r->seq.width);
    if (!r->in2) return lm_cli_error(r->c, "out of memory (%d x %d frame)", r->seq.width,
                                     r->seq.height), 1;
    if (r->seq.count > 1 && !r->o->no_align)
        fprintf(stderr, "lumosaic infer: warning: bucket 0 is not aligned in time: the two-bucket "
                "model %s reconstructs the frames without temporal alignment\n",
                r->im.model->preset);
    return 0;
}

/* Under mpirun: rank r of N reconstructs the block of frames [r n / N, (r + 1) n / N) (it
 * reads the neighbours that alignment needs itself) into rank 0's staging folder; rank 0
 * renames it into place once every rank has finished, or removes it when any failed.
 * rc: this rank's status so far. Returns the job's status (the worst rank's). */
static int run_ranks(infer_run *r, int rc)
{
    int rank = lm_dist_rank(), n = lm_dist_size();
    long v[2] = {rc, (long)getpid()};
    if (rank == 0 && !rc) v[0] = rc = lm_cli_stage_dir(r->c, r->o->output, r->tmp, sizeof r->tmp);
    long any = rc; /* every rank opened its inputs, and rank 0 staged the output */
    lm_dist_max_long(&any, 1);
    lm_dist_bcast_long(v, 2);
    if (rank > 0) snprintf(r->tmp, sizeof r->tmp, "%s.tmp.%ld", r->o->output, v[1]);
    if (any) {
        if (rank == 0 && !rc) lm_cli_remove_tree(r->tmp);
        return rc ? rc : (int)any;
    }
    r->first = (int)((long)r->seq.count * rank / n);
    r->end = (int)((long)r->seq.count * (rank + 1) / n);
    rc = run_frames(r);
    any = rc;
    lm_dist_max_long(&any, 1);
    if (rank > 0) return rc ? rc : (int)any;
    if (any) lm_cli_remove_tree(r->tmp);
    else if (lm_cli_commit_dir(r->c, r->tmp, r->o->output)) rc = 1;
    return rc ? rc : (int)any;
}

int lm_cmd_infer(int argc, char **argv)
{
    lm_cli c;
    infer_opts o;
    lm_cli_init(&c, "lumosaic infer", argc, argv);
    int rc = parse(&c, &o);
    if (rc != 1) return rc;
    lm_dist_init(NULL, NULL); /* under mpirun: the frames are spread over the ranks */
    lm_cli_common_apply(&o.com);
    if (lm_cli_signals_init(&c, 0)) return lm_cli_error(&c, "cannot install signal handlers"), 1;
    infer_run r;
    memset(&r, 0, sizeof r);
    r.c = &c;
    r.o = &o;
    lm_err e;
    lm_err_clear(&e);
    rc = open_inputs(&r, &e);
    int have_ctx = 0;
    if (!rc && lm_ctx_init(&r.ctx, (int)o.com.threads) != 0) {
        lm_cli_error(&c, "out of memory (compute context)");
        rc = 1;
    } else if (!rc) {
        have_ctx = 1;
        r.ctx.precision = o.com.precision;
        if (o.com.precision != LM_PRECISION_FP32)
            fprintf(stderr, "precision: %s\n", lm_precision_describe(o.com.precision));
        if (o.is_auto ? lm_tile_device_open_models(&r.dev, o.com.device, r.models,
                                                   r.cal.nmodels, &r.ctx, &e)
                      : lm_tile_device_open(&r.dev, o.com.device, r.im.model, &r.ctx, &e))
            rc = fail(&c, &e, 0);
        else if (r.dev.backend->device != LM_DEVICE_CPU)
            fprintf(stderr, "device: %s\n", lm_tile_device_name(&r.dev));
    }
    if (lm_dist_size() > 1) rc = run_ranks(&r, rc);
    else {
        r.end = r.seq.count;
        if (!rc) rc = lm_cli_stage_dir(&c, o.output, r.tmp, sizeof r.tmp);
        if (!rc) {
            rc = run_frames(&r);
            if (rc) lm_cli_remove_tree(r.tmp);
            else if (lm_cli_commit_dir(&c, r.tmp, o.output)) rc = 1;
        }
    }
    lm_tile_device_close(&r.dev);
    if (have_ctx) lm_ctx_free(&r.ctx);
    free(r.rgb);
    align_free(&r.al);
    lm_frame_seq_free(&r.seq);
    lm_frame_seq_free(&r.seq0);
    free(r.in2);
    free(r.sat);
    lm_raw_free(&r.raw);
    lm_infer_model_free(&r.im);
    for (int m = 1; m < LM_AUTO_MAX_MODELS; m++) lm_infer_model_free(&r.more[m]);
    return rc;
}

/* cmd_infer.c — `lumosaic infer`: coded frames to 31-band spectral cubes with a trained model.
 * What it is: the options and help of the command; the frame pipeline (infer/pipeline.h: the
 * model or --model auto, frames and bucket 0, raw-camera conversion, temporal alignment,
 * multi-frame stacking, the device) opened on the files given, and its frames written by
 * cli/infer_out.c (DIR/cube_NNNN.exr, srgb_NNNN.png, saturated_NNNN.png, atomically; progress
 * lines; the auto summary; MPI ranks).
 * What it is not: the pipeline itself or the writing of outputs. */
#include <stdio.h>
#include <string.h>
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "cli/infer_out.h"
#include "infer/pipeline.h"
#include "train/dist.h"

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
           "                   (patch-wise only; prints the share of windows per model\n"
           "                   and the buckets read; a calibration of two-bucket models\n"
           "                   reads bucket 0 as --bucket0 says).\n"
           "                   One line names the model used and the buckets it read\n"
           "  --auto FILE      calibration written by 'lumosaic fit-auto' (for --model auto)\n"
           "  --auto-tol DB    accuracy the auto choice may give up per window, in dB of\n"
           "                   expected PSNR (>= 0; default 0.5; 0 = always the best model)\n"
           "  --tiles          patch-wise even for models that can run on the whole frame\n"
           "  --input FRAMES   one coded frame (.png/.tif/.exr), a numbered pattern\n"
           "                   (frame_%%04d.png) or a folder of frames; the size must be a\n"
           "                   multiple of the mosaic tile and at least 3 x 3 tiles (9 x 12);\n"
           "                   below 66 x 64 one window covers the frame\n"
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

/* The pipeline's options from the command's. */
static void pipe_opts(const infer_opts *o, lm_pipe_opts *po)
{
    lm_pipe_default_opts(po);
    po->model = o->model;
    po->auto_file = o->auto_file;
    po->auto_tol = o->auto_tol;
    po->system = o->system;
    po->noise_level = o->noise_level;
    po->no_align = o->no_align;
    po->tiles = o->tiles;
    po->batch = (int)o->batch;
    po->raw = o->raw;
    po->threads = (int)o->com.threads;
    po->device = o->com.device;
    po->precision = o->com.precision;
    po->msg = lm_infer_out_msg;
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
    lm_pipe_opts po;
    pipe_opts(&o, &po);
    lm_pipe *p = NULL;
    lm_err e;
    lm_err_clear(&e);
    rc = 0;
    if (lm_pipe_open_files(&po, o.input, o.bucket0, &p, &e)) {
        lm_cli_error(&c, "%s", e.msg);
        rc = lm_cli_exit_status(e.status);
    }
    lm_infer_out w = {.c = &c, .output = o.output};
    if (!rc) rc = lm_infer_out_init(&w, &c, p, o.output, o.sat_mask, o.auto_tol);
    rc = lm_infer_out_run(&w, rc);
    lm_infer_out_free(&w);
    lm_pipe_close(p);
    return rc;
}

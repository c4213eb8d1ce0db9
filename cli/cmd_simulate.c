/* cmd_simulate.c — `lumosaic simulate`: coded frames (static, or a video of a moving scene)
 * from a spectral cube, with their ground truth.
 * What it is: option parsing, cube preparation (crop to the tile, 31 bands mirrored to the
 * system's 41 bins), lm_forward_simulate / lm_video_frame per frame, and the output folder:
 *   frames/frame_NNNN.<png|tif|exr>   bucket 1 (the coded frame)
 *   bucket0/frame_NNNN.<ext>          bucket 0 (--bucket0)
 *   gt/gt_NNNN.exr, gt/gt_NNNN.png    ground truth (spectral EXR, 31 bands 400-700 nm; sRGB)
 *   simulate.json                     what was done (system, noise, seed, motion, files)
 * written into "<DIR>.tmp.<pid>" and renamed onto DIR at the end (nothing is left on failure).
 * What it is not: the models (data/forward.c, data/video.c) or the readers (data/cube_io.c). */
#include <jansson.h>
#include <errno.h>
#include <math.h>
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#include "cli/cli_util.h"
#include "data/util.h"
#include "cli/commands.h"
#include "data/cube_io.h"
#include "data/frames.h"
#include "data/image.h"
#include "data/qdocam.h"
#include "data/spectra.h"
#include "data/srgb.h"
#include "data/video.h"

static const char *const FORMATS[] = {"png", "tiff", "exr", NULL};
static const char *const EXTS[] = {"png", "tif", "exr"};

static void help(void)
{
    printf(
        "usage: lumosaic simulate --input CUBE --output DIR [options]\n\n"
        "Simulate coded-exposure frames of a spectral cube with the imaging system's forward\n"
        "model (static, or a video of a moving scene) and write them with their ground truth.\n\n"
        "  --input CUBE        CAVE folder, .mat (ARAD/KAUST/ICVL/Harvard) or spectral .exr;\n"
        "                      31 bands 400-700 nm (mirrored to 41 bins 380-780 nm), the\n"
        "                      system's grid, or any bands covering 420-680 nm (resampled to\n"
        "                      400-700 nm; wavelengths from the file or a sidecar\n"
        "                      CUBE.wavelengths.txt, docs/guide/training.md)\n"
        "  --mat-key NAME      the .mat variable holding the cube (default: the first of cube,\n"
        "                      hsi, rad, ref, ...)\n"
        "  --output DIR        output folder (must not exist, or be empty): frames/, bucket0/,\n"
        "                      gt/ (spectral EXR + sRGB PNG per frame), simulate.json\n"
        "  --system FILE       system description JSON (default: the bundled prototype)\n"
        "  --crop              crop (top-left kept) to the largest multiple of the tile size;\n"
        "                      without it a size that is not a multiple is an error\n"
        "  --noise K           Gaussian noise, sigma = K x the frame's largest value (0..1)\n"
        "  --poisson PHOTONS   shot noise with PHOTONS photo-electrons at full scale (0..1e12)\n"
        "  --read-noise E      read noise: electrons with --poisson, else a fraction of full\n"
        "                      scale (0..1e6)\n"
        "  --clip              clip at full well (before read noise) and to [0, full scale]\n"
        "  --bits N            quantise to N bits (1..24; default: only the file's 16 bits)\n"
        "  --bucket0           also write bucket 0 (the complement: all other LEDs' light),\n"
        "                      stored divided by (LEDs - 1) so that white is 1 as in bucket 1\n"
        "  --seed S            noise seed (0..2^63-1; default 1)\n"
        "  --format F          frame files: png (16-bit, default), tiff (16-bit), exr (float)\n"
        "  --video             simulate a video of a moving scene\n"
        "  --frames N          video frames (1..10000; default 8), 30 fps as the system says\n"
        "  --samples K         instants averaged per LED window, motion blur (1..64; default 4)\n"
        "  --motion SPEC       scene motion (repeat to combine), velocities per second:\n"
        "                        translate:VX,VY              pixels/s\n"
        "                        rotate:DEG[,CX,CY]           degrees/s, clockwise as displayed,\n"
        "                                                     about the image centre or (CX, CY)\n"
        "                        zoom:PCT[,CX,CY]             percent/s (compounded, > -100)\n"
        "                        region:SHAPE,CX,CY,W,H,VX,VY a rect|ellipse region centred at\n"
        "                                                     (CX, CY), W x H pixels, moving at\n"
        "                                                     (VX, VY) pixels/s over the rest\n"
        "  --doe FILE|default  the QDO baseline's camera instead: the cube's 400-700 nm bands\n"
        "                      through this DOE (a description, e.g. a training run's doe.json,\n"
        "                      or the bundled one) onto the RGB sensor, with the noise options;\n"
        "                      frames/frame_0000.exr (float R, G, B) and .png (8-bit preview,\n"
        "                      linear, clipped); no --video or --bucket0\n"
        "  --threads T         OpenMP threads (1..1024; default: all cores)\n"
        "  --help              this text\n\n"
        "Frame i starts at i x the frame period; its ground truth is the scene at the centre of\n"
        "the Lime LED's window.\n"
        "Exit status: 0 done, 1 failure while writing, 2 bad usage or input, 130/143 interrupted\n"
        "(SIGINT/SIGTERM: the staging folder is removed).\n");
}

typedef struct sim_opts {
    const char *input, *output, *system, *mat_key, *doe;
    int crop, clip, bucket0, video, format;
    double noise, photons, read_noise;
    long long bits, frames, samples;
    lm_cli_common com; /* --threads, --seed */
    lm_motion motion;
    int nmotion;
} sim_opts;

/* Parse "a,b,c" into up to max reals, each in -1e6..1e6; returns the count or -1. */
static int parse_reals(const char *s, double *v, int max)
{
    char why[128];
    return lm_parse_list(s, -1e6, 1e6, v, max, why, sizeof why);
}

static int set_centre(lm_motion *m, const double *v, int n)
{
    if (n == 1) return 0;
    if (n != 3 || (m->has_centre && (m->cx != v[1] || m->cy != v[2]))) return -1;
    m->has_centre = 1;
    m->cx = v[1];
    m->cy = v[2];
    return 0;
}

/* One --motion SPEC into m. 0 ok, -1 error printed. */
static int parse_motion(const lm_cli *c, const char *spec, lm_motion *m)
{
    double v[7];
    int n, bad = 0;
    if (!strncmp(spec, "translate:", 10)) {
        bad = (n = parse_reals(spec + 10, v, 2)) != 2;
        if (!bad) m->vx = v[0], m->vy = v[1];
    } else if (!strncmp(spec, "rotate:", 7)) {
        bad = (n = parse_reals(spec + 7, v, 3)) < 1 || set_centre(m, v, n) != 0;
        if (!bad) m->rot_deg_s = v[0];
    } else if (!strncmp(spec, "zoom:", 5)) {
        bad = (n = parse_reals(spec + 5, v, 3)) < 1 || set_centre(m, v, n) != 0 || v[0] <= -100;
        if (!bad) m->zoom_pct_s = v[0];
    } else if (!strncmp(spec, "region:rect,", 12) || !strncmp(spec, "region:ellipse,", 15)) {
        int ell = spec[7] == 'e';
        bad = (n = parse_reals(spec + (ell ? 15 : 12), v, 6)) != 6 || v[2] <= 0 || v[3] <= 0 ||
              m->nregions == LM_VIDEO_MAX_REGIONS;
        if (!bad)
            m->regions[m->nregions++] = (lm_motion_region){
                ell ? LM_REGION_ELLIPSE : LM_REGION_RECT, v[0], v[1], v[2], v[3], v[4], v[5]};
    } else
        bad = 1;
    if (bad)
        lm_cli_error(c, "--motion: invalid '%s' (translate:VX,VY | rotate:DEG[,CX,CY] | "
                     "zoom:PCT[,CX,CY] with PCT > -100 | region:rect|ellipse,CX,CY,W,H,VX,VY "
                     "with W, H > 0, every number in -1e6..1e6, at most %d regions; one "
                     "rotate/zoom centre)", spec, LM_VIDEO_MAX_REGIONS);
    return bad ? -1 : 0;
}

/* One option at the cursor: 1 matched, 0 unknown, -1 error printed. */
static int parse_one(lm_cli *c, sim_opts *o)
{
    const char *s;
    int r;
    if ((r = lm_cli_value(c, "--input", &o->input)) ||
        (r = lm_cli_value(c, "--mat-key", &o->mat_key)) ||
        (r = lm_cli_value(c, "--output", &o->output)) ||
        (r = lm_cli_value(c, "--system", &o->system)) || (r = lm_cli_flag(c, "--crop", &o->crop)) ||
        (r = lm_cli_value(c, "--doe", &o->doe)) ||
        (r = lm_cli_flag(c, "--clip", &o->clip)) ||
        (r = lm_cli_flag(c, "--bucket0", &o->bucket0)) ||
        (r = lm_cli_flag(c, "--video", &o->video)) ||
        (r = lm_cli_real(c, "--noise", 0, 1, &o->noise)) ||
        (r = lm_cli_real(c, "--poisson", 0, 1e12, &o->photons)) ||
        (r = lm_cli_real(c, "--read-noise", 0, 1e6, &o->read_noise)) ||
        (r = lm_cli_int(c, "--bits", 1, 24, &o->bits)) ||
        (r = lm_cli_common_opt(c, LM_CLI_THREADS | LM_CLI_SEED, 0x7fffffffffffffffLL, &o->com)) ||
        (r = lm_cli_choice(c, "--format", FORMATS, &o->format)))
        return r;
    if ((r = lm_cli_int(c, "--frames", 1, 10000, &o->frames)) ||
        (r = lm_cli_int(c, "--samples", 1, LM_VIDEO_MAX_SAMPLES, &o->samples)))
        return r;
    if ((r = lm_cli_value(c, "--motion", &s)) <= 0) return r;
    o->nmotion++;
    return parse_motion(c, s, &o->motion) == 0 ? 1 : -1;
}

/* 1: run, 0: help printed, 2: bad usage (printed). */
static int parse(lm_cli *c, sim_opts *o)
{
    memset(o, 0, sizeof *o);
    o->com.seed = 1;
    o->frames = -1;
    o->samples = -1;
    while (!lm_cli_done(c)) {
        if (lm_cli_is_help(c)) {
            help();
            return 0;
        }
        int r = parse_one(c, o);
        if (r < 0) return 2;
        if (r == 0) return lm_cli_unknown(c);
    }
    if (!o->input) return lm_cli_error(c, "--input is required (see 'lumosaic simulate --help')");
    if (!o->output)
        return lm_cli_error(c, "--output is required (see 'lumosaic simulate --help')");
    if (!o->video && (o->frames >= 0 || o->samples >= 0 || o->nmotion))
        return lm_cli_error(c, "--frames, --samples and --motion need --video");
    if (o->doe && (o->video || o->bucket0))
        return lm_cli_error(c, "--doe (the QDO camera's RGB image) takes no --video or --bucket0");
    if (o->frames < 0) o->frames = o->video ? 8 : 1;
    if (o->samples < 0) o->samples = LM_VIDEO_DEFAULT_SAMPLES;
    return 1;
}

/* ---- cube preparation ----------------------------------------------------------------- */
static int on_grid(const lm_cube *c, int n, float start, float step)
{
    if (c->bands != n) return 0;
    for (int b = 0; b < n; b++)
        if (fabsf(c->wavelength[b] - (start + step * b)) > 0.01f * step) return 0;
    return 1;
}

/* Copy bands [b0, b0 + nb) of rows/cols [0, h) x [0, w) of src into a new cube. */
static lm_status sub_cube(const lm_cube *src, int b0, int nb, int h, int w, lm_cube *out)
{
    if (lm_cube_alloc(out, nb, h, w, 0, 0) != LM_OK) return LM_ERR_NOMEM;
    for (int b = 0; b < nb; b++) {
        out->wavelength[b] = src->wavelength[b0 + b];
        for (int y = 0; y < h; y++)
            memcpy(lm_cube_band(out, b) + (size_t)y * w,
                   lm_cube_band(src, b0 + b) + (size_t)y * src->width, sizeof(float) * w);
    }
    return LM_OK;
}

/* gt: the 31 bands 400-700 nm (or every band when the input has no such run), cropped;
 * sim: the cube on the system's grid. Returns 0, 1 (runtime) or 2 (bad input), printed. */
static int prepare(const lm_cli *c, const sim_opts *o, const lm_system *sys, const lm_cube *in,
                   lm_cube *gt, lm_cube *sim)
{
    int tr = sys->tile_rows, tc = sys->tile_cols, H = in->height, W = in->width;
    int h = H / tr * tr, w = W / tc * tc, b0 = 0, nb = in->bands;
    if ((h != H || w != W) && !o->crop)
        return lm_cli_error(c, "%s: size %d x %d (H x W) is not a multiple of the %d x %d tile "
                            "(--crop crops it to %d x %d)", o->input, H, W, tr, tc, h, w);
    if (h == 0 || w == 0)
        return lm_cli_error(c, "%s: size %d x %d is smaller than the %d x %d tile", o->input, H,
                            W, tr, tc);
    int is31 = on_grid(in, LM_GRID31_COUNT, LM_GRID31_START, 10.0f);
    int isgrid = on_grid(in, sys->nbins, sys->grid_start, sys->grid_step);
    if (!is31 && !isgrid)
        return lm_cli_error(c, "%s: %d bands from %g to %g nm: simulate needs 31 bands 400-700 "
                            "nm or the system's grid (%d bins from %g nm, step %g)", o->input,
                            in->bands, in->wavelength[0], in->wavelength[in->bands - 1],
                            sys->nbins, sys->grid_start, sys->grid_step);
    if (!isgrid && (sys->nbins != LM_GRID41_COUNT || sys->grid_start != LM_GRID41_START ||
                    sys->grid_step != LM_GRID41_STEP))
        return lm_cli_error(c, "%s: 31-band cubes are mirrored to 41 bins 380-780 nm, but the "
                            "system '%s' uses %d bins from %g nm", o->input, sys->path,
                            sys->nbins, sys->grid_start);
    for (int b = 0; isgrid && b + LM_GRID31_COUNT <= in->bands; b++) /* find 400..700 */
        if (fabsf(in->wavelength[b] - LM_GRID31_START) < 0.1f &&
            fabsf(in->wavelength[b + 30] - 700.0f) < 0.1f) {
            b0 = b;
            nb = LM_GRID31_COUNT;
        }
    memset(sim, 0, sizeof *sim);
    if (sub_cube(in, b0, nb, h, w, gt) != LM_OK) return lm_cli_error(c, "out of memory"), 1;
    lm_err e;
    lm_err_clear(&e);
    lm_status st = isgrid ? sub_cube(in, 0, in->bands, h, w, sim) : lm_cube_mirror41(gt, sim, &e);
    if (st != LM_OK) {
        lm_cube_free(gt);
        return st == LM_ERR_NOMEM ? (lm_cli_error(c, "out of memory"), LM_EXIT_FAILED)
                                  : lm_cli_error(c, "%s: %s", o->input, e.msg);
    }
    return 0;
}

/* ---- simulation and output ------------------------------------------------------------ */
typedef struct sim_run {
    const sim_opts *o;
    const lm_system *sys;
    lm_cube gt0, sim;     /* cropped input: ground-truth bands, and on the system's grid */
    char tmp[1024];       /* staging folder */
    json_t *files;        /* per-frame entries of simulate.json */
    float *b1, *b0, *rgb;
    lm_qdocam *qdo;       /* --doe: the QDO camera (b1 then holds 3 planes) */
    lm_rng rng;
} sim_run;

static int out_path(const lm_cli *c, const sim_run *r, const char *rel, char *buf, size_t n)
{
    int k = snprintf(buf, n, "%s/%s", r->tmp, rel);
    if (k < 0 || (size_t)k >= n) return lm_cli_error(c, "%s/%s: path too long", r->tmp, rel), 1;
    return 0;
}

/* Coded frame(s) of frame i and its ground truth (a cube warped to the GT instant, or gt0). */
static lm_status simulate_one(const sim_run *r, int i, lm_rng *rng, lm_cube *gt, lm_err *e)
{
    const sim_opts *o = r->o;
    lm_noise_opts nz = {(float)o->noise, o->photons, (float)o->read_noise, o->clip, (int)o->bits,
                        0.0f};
    if (r->qdo) {
        *gt = r->gt0;
        return lm_qdocam_simulate(r->qdo, r->gt0.data, gt->height, gt->width, &nz, rng, r->b1,
                                  (int)o->com.threads, e);
    }
    if (!o->video) {
        lm_forward_opts fo = {.noise = nz, .nthreads = (int)o->com.threads};
        *gt = r->gt0;
        return lm_forward_simulate(r->sys, &r->sim, &fo, rng, r->b1, o->bucket0 ? r->b0 : NULL, e);
    }
    lm_video_opts vo = {.motion = o->motion, .samples = (int)o->samples, .noise = nz,
                        .nthreads = (int)o->com.threads};
    lm_status st = lm_video_frame(r->sys, &r->sim, &vo, i, rng, r->b1, o->bucket0 ? r->b0 : NULL,
                                  NULL, e);
    double t = 1e-6 * (lm_video_frame_start_us(r->sys, i) + lm_video_gt_time_us(r->sys));
    return st ? st : lm_video_warp(&r->gt0, &o->motion, t, gt, (int)o->com.threads, e);
}

/* Bucket 0 sees every other LED: its files hold bucket 0 / (LEDs - 1), white = 1 like bucket 1
 * (so it fits 16-bit files); simulate.json records the factor. */
static double bucket0_scale(const lm_system *s)
{
    return s->nleds > 1 ? 1.0 / (s->nleds - 1) : 1.0;
}

static const float *scale_bucket0(const sim_run *r, long n)
{
    float f = (float)bucket0_scale(r->sys);
    for (long i = 0; i < n; i++) r->b0[i] *= f;
    return r->b0;
}

/* Write the files of one frame; returns 0 or 1 (error printed). */
static int write_files(const lm_cli *c, sim_run *r, int i, const lm_cube *gt, json_t *entry)
{
    const char *ext = EXTS[r->o->format];
    char rel[4][64], path[1100];
    snprintf(rel[0], sizeof rel[0], "frames/frame_%04d.%s", i, ext);
    snprintf(rel[1], sizeof rel[1], "bucket0/frame_%04d.%s", i, ext);
    snprintf(rel[2], sizeof rel[2], "gt/gt_%04d.exr", i);
    snprintf(rel[3], sizeof rel[3], "gt/gt_%04d.png", i);
    const char *keys[4] = {"coded", "bucket0", "gt", "preview"};
    int H = gt->height, W = gt->width;
    lm_err e;
    lm_err_clear(&e);
    if (r->qdo) { /* the RGB image: float EXR and an 8-bit preview */
        snprintf(rel[0], sizeof rel[0], "frames/frame_%04d.exr", i);
        snprintf(rel[1], sizeof rel[1], "frames/frame_%04d.png", i);
        static const char *const names[3] = {"R", "G", "B"};
        size_t n = (size_t)H * W;
        for (size_t p = 0; p < n; p++)
            for (int ch = 0; ch < 3; ch++) r->rgb[3 * p + ch] = r->b1[ch * n + p];
        if (out_path(c, r, rel[0], path, sizeof path)) return 1;
        lm_status st = lm_image_write_exr(path, W, H, 3, names, r->b1, NULL, &e);
        if (st == LM_OK && out_path(c, r, rel[1], path, sizeof path)) return 1;
        if (st == LM_OK) st = lm_image_write_rgb8(path, W, H, r->rgb, &e);
        if (st != LM_OK) return lm_cli_error(c, "%s", e.msg), 1;
        json_object_set_new(entry, "rgb", json_string(rel[0]));
        json_object_set_new(entry, "rgb_preview", json_string(rel[1]));
    }
    for (int k = r->qdo ? 2 : 0; k < 4; k++) {
        if (k == 1 && !r->o->bucket0) continue;
        if (out_path(c, r, rel[k], path, sizeof path)) return 1;
        lm_status st;
        if (k == 0) st = lm_frame_write(path, H, W, r->b1, &e);
        else if (k == 1) st = lm_frame_write(path, H, W, scale_bucket0(r, H * W), &e);
        else if (k == 2) st = lm_cube_write_exr(path, gt, &e);
        else {
            st = lm_srgb_render_cube(gt, 1.0f, NULL, r->rgb, &e);
            if (st == LM_OK) st = lm_image_write_rgb8(path, W, H, r->rgb, &e);
        }
        if (st != LM_OK) return lm_cli_error(c, "%s", e.msg), 1;
        json_object_set_new(entry, keys[k], json_string(rel[k]));
    }
    return 0;
}

static int run_frames(const lm_cli *c, sim_run *r)
{
    int n = (int)r->o->frames, tty = isatty(STDERR_FILENO) && n > 1;
    for (int i = 0; i < n; i++) {
        lm_cube gt;
        lm_err e;
        lm_err_clear(&e);
        if (simulate_one(r, i, &r->rng, &gt, &e) != LM_OK)
            return lm_cli_error(c, "%s: %s", r->o->input, e.msg), 1;
        double t0 = lm_video_frame_start_us(r->sys, i);
        json_t *entry = json_pack("{s:i, s:f, s:o}", "index", i, "start_us", t0, "gt_time_us",
                                  r->o->video ? json_real(t0 + lm_video_gt_time_us(r->sys))
                                              : json_null());
        int bad = !entry || write_files(c, r, i, &gt, entry);
        if (gt.data != r->gt0.data) lm_cube_free(&gt);
        if (bad) {
            json_decref(entry);
            return 1;
        }
        json_array_append_new(r->files, entry);
        if (tty) fprintf(stderr, "\rlumosaic simulate: frame %d/%d", i + 1, n);
    }
    if (tty) fputc('\n', stderr);
    return 0;
}

static json_t *motion_json(const lm_motion *m)
{
    json_t *regions = json_array();
    for (int k = 0; k < m->nregions; k++) {
        const lm_motion_region *g = &m->regions[k];
        json_array_append_new(regions, json_pack("{s:s, s:[f,f], s:[f,f], s:[f,f]}", "shape",
                                                 g->shape == LM_REGION_ELLIPSE ? "ellipse" : "rect",
                                                 "centre", g->cx, g->cy, "size", g->w, g->h,
                                                 "velocity_px_s", g->vx, g->vy));
    }
    json_t *centre = m->has_centre ? json_pack("[f,f]", m->cx, m->cy) : json_null();
    return json_pack("{s:[f,f], s:f, s:f, s:o, s:o}", "translate_px_s", m->vx, m->vy,
                     "rotate_deg_s", m->rot_deg_s, "zoom_pct_s", m->zoom_pct_s, "centre", centre,
                     "regions", regions);
}

static json_t *summary_json(const sim_run *r, const lm_cube *in)
{
    const sim_opts *o = r->o;
    const lm_system *s = r->sys;
    json_t *video = json_null();
    if (o->video)
        video = json_pack("{s:I, s:I, s:f, s:f, s:o}", "frames", o->frames, "samples",
                          o->samples, "frame_period_us", s->frame_period_us, "gt_offset_us",
                          lm_video_gt_time_us(s), "motion", motion_json(&o->motion));
    return json_pack(
        "{s:i, s:s, s:s, s:s, s:[i,i], s:[i,i], s:{s:s, s:s, s:[i,i], s:f, s:f}, "
        "s:{s:f, s:f, s:f, s:b, s:I}, s:I, s:s, s:b, s:f, s:o, s:O}",
        "version", 1, "command", "simulate", "lumosaic", LM_VERSION, "input", o->input,
        "input_size_hw", in->height, in->width, "size_hw", r->gt0.height, r->gt0.width,
        "system", "path", s->path, "name", s->name, "tile", s->tile_rows, s->tile_cols,
        "exposure_us", lm_system_exposure_us(s), "frame_period_us", s->frame_period_us,
        "noise", "gauss_k", o->noise, "photons", o->photons, "read_noise", o->read_noise, "clip",
        o->clip, "bits", o->bits, "seed", o->com.seed, "format", FORMATS[o->format], "bucket0",
        o->bucket0, "bucket0_scale", bucket0_scale(s), "video", video, "frames", r->files);
}

/* --doe: the QDO camera of that DOE (its 31 PSFs); the cube must hold the 400-700 nm bands.
 * Returns 0 or the exit status (error printed). */
static int open_qdo(const lm_cli *c, const sim_opts *o, sim_run *r)
{
    if (r->gt0.bands != LM_GRID31_COUNT)
        return lm_cli_error(c, "%s: --doe needs the 31 bands 400-700 nm (the cube has %d)",
                            o->input, r->gt0.bands);
    lm_doe doe;
    lm_err e;
    lm_err_clear(&e);
    lm_status st = strcmp(o->doe, "default") ? lm_doe_load(o->doe, &doe, &e)
                                             : lm_doe_default(&doe, &e);
    if (st) return lm_cli_error(c, "--doe: %s", e.msg), lm_cli_exit_status(st);
    r->qdo = calloc(1, sizeof *r->qdo);
    st = r->qdo ? lm_qdocam_init(r->qdo, &doe, LM_RGBCAM_D65, &e)
                : lm_err_set(&e, LM_ERR_NOMEM, "out of memory");
    lm_doe_free(&doe);
    if (st) {
        free(r->qdo);
        r->qdo = NULL;
        return lm_cli_error(c, "--doe: %s", e.msg), lm_cli_exit_status(st);
    }
    return 0;
}

/* Everything after the inputs are loaded; returns the exit status. */
static int run(const lm_cli *c, sim_run *r, const lm_cube *in)
{
    size_t n = (size_t)r->gt0.height * r->gt0.width;
    r->b1 = malloc(sizeof(float) * 3 * n);
    r->b0 = malloc(sizeof(float) * n);
    r->rgb = malloc(sizeof(float) * 3 * n);
    r->files = json_array();
    if (!r->b1 || !r->b0 || !r->rgb || !r->files) return lm_cli_error(c, "out of memory"), 1;
    int status = lm_cli_stage_dir(c, r->o->output, r->tmp, sizeof r->tmp);
    if (status) return status;
    const char *subs[3] = {"frames", "gt", r->o->bucket0 ? "bucket0" : NULL};
    char path[1100];
    for (int k = 0; k < 3 && !status && subs[k]; k++)
        if ((status = out_path(c, r, subs[k], path, sizeof path)) == 0 && mkdir(path, 0777))
            status = (lm_cli_error(c, "%s: cannot create a folder: %s", path, strerror(errno)),
                      LM_EXIT_FAILED);
    lm_rng_seed(&r->rng, (uint64_t)r->o->com.seed);
    if (!status) status = run_frames(c, r);
    json_t *js = status ? NULL : summary_json(r, in);
    if (js && r->o->doe) json_object_set_new(js, "doe", json_string(r->o->doe));
    if (!status && (out_path(c, r, "simulate.json", path, sizeof path) ||
                    !js || json_dump_file(js, path, JSON_INDENT(2) | JSON_REAL_PRECISION(10))))
        status = (lm_cli_error(c, "%s: cannot write the summary: %s", path,
                               js ? strerror(errno) : "out of memory"), LM_EXIT_FAILED);
    json_decref(js);
    if (status) lm_cli_remove_tree(r->tmp);
    else if (lm_cli_commit_dir(c, r->tmp, r->o->output)) status = 1;
    if (!status)
        printf("lumosaic simulate: %d frame(s) of %d x %d written to %s\n", (int)r->o->frames,
               r->gt0.height, r->gt0.width, r->o->output);
    return status;
}

int lm_cmd_simulate(int argc, char **argv)
{
    lm_cli c;
    sim_opts o;
    lm_cli_init(&c, "lumosaic simulate", argc, argv);
    int status = parse(&c, &o);
    if (status != 1) return status;
    lm_cli_common_apply(&o.com);
    if (lm_cli_signals_init(&c, 0)) return lm_cli_error(&c, "cannot install signal handlers"), 1;
    lm_system sys;
    lm_cube in;
    lm_err e;
    lm_err_clear(&e);
    if ((o.system ? lm_system_load(o.system, &sys, &e) : lm_system_default(&sys, &e)) != LM_OK) {
        lm_system_free(&sys);
        return lm_cli_error(&c, "%s", e.msg);
    }
    lm_cube_read_opts ro; /* other grids resampled to 31 bands; the system's kept */
    lm_cube_read_opts_default(&ro);
    ro.mat_key = o.mat_key;
    ro.keep = (lm_grid){sys.nbins, sys.grid_start, sys.grid_step};
    if (lm_cube_read_with(o.input, &ro, &in, &e) != LM_OK) {
        lm_system_free(&sys);
        return lm_cli_error(&c, "%s", e.msg), lm_cli_exit_status(e.status);
    }
    sim_run r = {.o = &o, .sys = &sys};
    status = prepare(&c, &o, &sys, &in, &r.gt0, &r.sim);
    if (!status && o.doe) status = open_qdo(&c, &o, &r);
    if (!status) status = run(&c, &r, &in);
    json_decref(r.files);
    free(r.b1), free(r.b0), free(r.rgb);
    if (r.qdo) lm_qdocam_free(r.qdo);
    free(r.qdo);
    lm_cube_free(&r.gt0);
    lm_cube_free(&r.sim);
    lm_cube_free(&in);
    lm_system_free(&sys);
    return status;
}

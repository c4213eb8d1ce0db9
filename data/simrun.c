/* simrun.c — a simulation run written into a folder (simrun.h).
 * What it is: input preparation (crop, grid checks, 31 -> 41 bins), the per-frame simulation
 * (static, video, or the QDO camera), the frame / bucket 0 / ground-truth files and
 * simulate.json.
 * What it is not: option parsing, printing, or the staging of the output folder
 * (cli/cmd_simulate.c). */
#include "data/simrun.h"
#include <errno.h>
#include <jansson.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include "data/cube_io.h"
#include "data/frames.h"
#include "data/image.h"
#include "data/spectra.h"
#include "data/srgb.h"

static const char *const FORMATS[] = {"png", "tiff", "exr"};
static const char *const EXTS[] = {"png", "tif", "exr"};

const char *lm_simrun_format_name(lm_simrun_format f) { return FORMATS[f]; }

void lm_simrun_opts_default(lm_simrun_opts *o)
{
    memset(o, 0, sizeof *o);
    o->frames = 1;
    o->samples = LM_VIDEO_DEFAULT_SAMPLES;
    o->seed = 1;
}

lm_status lm_simrun_read(const char *path, const char *mat_key, const lm_system *sys,
                         lm_cube *in, lm_err *e)
{
    lm_cube_read_opts ro; /* other grids resampled to 31 bands; the system's kept */
    lm_cube_read_opts_default(&ro);
    ro.mat_key = mat_key;
    ro.keep = (lm_grid){sys->nbins, sys->grid_start, sys->grid_step};
    return lm_cube_read_with(path, &ro, in, e);
}

/* ---- input preparation ------------------------------------------------------------------ */
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

/* The input's size and bands against the system: LM_OK, or LM_ERR_SHAPE with the reason.
 * *isgrid: the cube is on the system's grid (else 31 bands 400-700 nm). */
static lm_status check_input(const lm_simrun_opts *o, const lm_system *sys, const lm_cube *in,
                             int *isgrid, lm_err *e)
{
    int tr = sys->tile_rows, tc = sys->tile_cols, H = in->height, W = in->width;
    int h = H / tr * tr, w = W / tc * tc;
    if ((h != H || w != W) && !o->crop)
        return lm_err_set(e, LM_ERR_SHAPE, "%s: size %d x %d (H x W) is not a multiple of the "
                          "%d x %d tile (--crop crops it to %d x %d)", o->input, H, W, tr, tc,
                          h, w);
    if (h == 0 || w == 0)
        return lm_err_set(e, LM_ERR_SHAPE, "%s: size %d x %d is smaller than the %d x %d tile",
                          o->input, H, W, tr, tc);
    int is31 = on_grid(in, LM_GRID31_COUNT, LM_GRID31_START, 10.0f);
    *isgrid = on_grid(in, sys->nbins, sys->grid_start, sys->grid_step);
    if (!is31 && !*isgrid)
        return lm_err_set(e, LM_ERR_SHAPE, "%s: %d bands from %g to %g nm: simulate needs 31 "
                          "bands 400-700 nm or the system's grid (%d bins from %g nm, step %g)",
                          o->input, in->bands, in->wavelength[0],
                          in->wavelength[in->bands - 1], sys->nbins, sys->grid_start,
                          sys->grid_step);
    if (!*isgrid && (sys->nbins != LM_GRID41_COUNT || sys->grid_start != LM_GRID41_START ||
                     sys->grid_step != LM_GRID41_STEP))
        return lm_err_set(e, LM_ERR_SHAPE, "%s: 31-band cubes are mirrored to 41 bins 380-780 "
                          "nm, but the system '%s' uses %d bins from %g nm", o->input, sys->path,
                          sys->nbins, sys->grid_start);
    return LM_OK;
}

/* gt0: the 31 bands 400-700 nm (or every band when the input has no such run), cropped;
 * sim: the cube on the system's grid. */
static lm_status prepare(lm_simrun *r, const lm_cube *in, lm_err *e)
{
    const lm_system *sys = r->sys;
    int isgrid, b0 = 0, nb = in->bands;
    lm_status st = check_input(r->o, sys, in, &isgrid, e);
    if (st) return st;
    int h = in->height / sys->tile_rows * sys->tile_rows;
    int w = in->width / sys->tile_cols * sys->tile_cols;
    for (int b = 0; isgrid && b + LM_GRID31_COUNT <= in->bands; b++) /* find 400..700 */
        if (fabsf(in->wavelength[b] - LM_GRID31_START) < 0.1f &&
            fabsf(in->wavelength[b + 30] - 700.0f) < 0.1f) {
            b0 = b;
            nb = LM_GRID31_COUNT;
        }
    if (sub_cube(in, b0, nb, h, w, &r->gt0) != LM_OK)
        return lm_err_set(e, LM_ERR_NOMEM, "out of memory");
    lm_err me;
    lm_err_clear(&me);
    st = isgrid ? sub_cube(in, 0, in->bands, h, w, &r->sim) : lm_cube_mirror41(&r->gt0, &r->sim,
                                                                                &me);
    if (st == LM_ERR_NOMEM) return lm_err_set(e, st, "out of memory");
    if (st) return lm_err_set(e, st, "%s: %s", r->o->input, me.msg);
    return LM_OK;
}

/* The QDO camera of the DOE (its 31 PSFs); the cube must hold the 400-700 nm bands. */
static lm_status open_qdo(lm_simrun *r, lm_err *e)
{
    const lm_simrun_opts *o = r->o;
    if (r->gt0.bands != LM_GRID31_COUNT)
        return lm_err_set(e, LM_ERR_SHAPE, "%s: --doe needs the 31 bands 400-700 nm (the cube "
                          "has %d)", o->input, r->gt0.bands);
    lm_doe doe;
    lm_err me;
    lm_err_clear(&me);
    lm_status st = strcmp(o->doe, "default") ? lm_doe_load(o->doe, &doe, &me)
                                             : lm_doe_default(&doe, &me);
    if (st) return lm_err_set(e, st, "--doe: %s", me.msg);
    r->qdo = calloc(1, sizeof *r->qdo);
    st = r->qdo ? lm_qdocam_init(r->qdo, &doe, LM_RGBCAM_D65, &me)
                : lm_err_set(&me, LM_ERR_NOMEM, "out of memory");
    lm_doe_free(&doe);
    if (st) {
        free(r->qdo);
        r->qdo = NULL;
        return lm_err_set(e, st, "--doe: %s", me.msg);
    }
    return LM_OK;
}

lm_status lm_simrun_init(lm_simrun *r, const lm_simrun_opts *opts, const lm_system *sys,
                         const lm_cube *in, lm_err *e)
{
    memset(r, 0, sizeof *r);
    r->o = opts;
    r->sys = sys;
    r->in_height = in->height;
    r->in_width = in->width;
    lm_status st = prepare(r, in, e);
    if (!st && opts->doe) st = open_qdo(r, e);
    if (st) return st;
    size_t n = (size_t)r->gt0.height * r->gt0.width;
    r->b1 = malloc(sizeof(float) * 3 * n);
    r->b0 = malloc(sizeof(float) * n);
    r->rgb = malloc(sizeof(float) * 3 * n);
    if (!r->b1 || !r->b0 || !r->rgb) return lm_err_set(e, LM_ERR_NOMEM, "out of memory");
    return LM_OK;
}

void lm_simrun_free(lm_simrun *r)
{
    free(r->b1), free(r->b0), free(r->rgb);
    if (r->qdo) lm_qdocam_free(r->qdo);
    free(r->qdo);
    lm_cube_free(&r->gt0);
    lm_cube_free(&r->sim);
    memset(r, 0, sizeof *r);
}

/* ---- simulation and output -------------------------------------------------------------- */
/* Coded frame(s) of frame i and its ground truth (a cube warped to the GT instant, or gt0). */
static lm_status simulate_one(const lm_simrun *r, int i, lm_rng *rng, lm_cube *gt, lm_err *e)
{
    const lm_simrun_opts *o = r->o;
    lm_noise_opts nz = {(float)o->noise, o->photons, (float)o->read_noise, o->clip, (int)o->bits,
                        0.0f};
    if (r->qdo) {
        *gt = r->gt0;
        return lm_qdocam_simulate(r->qdo, r->gt0.data, gt->height, gt->width, &nz, rng, r->b1,
                                  o->nthreads, e);
    }
    if (!o->video) {
        lm_forward_opts fo = {.noise = nz, .nthreads = o->nthreads};
        *gt = r->gt0;
        return lm_forward_simulate(r->sys, &r->sim, &fo, rng, r->b1, o->bucket0 ? r->b0 : NULL, e);
    }
    lm_video_opts vo = {.motion = o->motion, .samples = (int)o->samples, .noise = nz,
                        .nthreads = o->nthreads};
    lm_status st = lm_video_frame(r->sys, &r->sim, &vo, i, rng, r->b1, o->bucket0 ? r->b0 : NULL,
                                  NULL, e);
    double t = 1e-6 * (lm_video_frame_start_us(r->sys, i) + lm_video_gt_time_us(r->sys));
    return st ? st : lm_video_warp(&r->gt0, &o->motion, t, gt, o->nthreads, e);
}

/* Bucket 0 sees every other LED: its files hold bucket 0 / (LEDs - 1), white = 1 like bucket 1
 * (so it fits 16-bit files); simulate.json records the factor. */
static double bucket0_scale(const lm_system *s)
{
    return s->nleds > 1 ? 1.0 / (s->nleds - 1) : 1.0;
}

static const float *scale_bucket0(const lm_simrun *r, long n)
{
    float f = (float)bucket0_scale(r->sys);
    for (long i = 0; i < n; i++) r->b0[i] *= f;
    return r->b0;
}

static lm_status out_path(const char *dir, const char *rel, char *buf, size_t n, lm_err *e)
{
    int k = snprintf(buf, n, "%s/%s", dir, rel);
    if (k < 0 || (size_t)k >= n) return lm_err_set(e, LM_ERR_WRITE, "%s/%s: path too long", dir,
                                                   rel);
    return LM_OK;
}

/* The QDO camera's RGB image of frame i: float EXR and an 8-bit preview. */
static lm_status write_rgb(const lm_simrun *r, const char *dir, int i, int H, int W,
                           json_t *entry, lm_err *e)
{
    static const char *const names[3] = {"R", "G", "B"};
    char rel[2][64], path[1100];
    snprintf(rel[0], sizeof rel[0], "frames/frame_%04d.exr", i);
    snprintf(rel[1], sizeof rel[1], "frames/frame_%04d.png", i);
    size_t n = (size_t)H * W;
    for (size_t p = 0; p < n; p++)
        for (int ch = 0; ch < 3; ch++) r->rgb[3 * p + ch] = r->b1[ch * n + p];
    lm_status st = out_path(dir, rel[0], path, sizeof path, e);
    if (!st) st = lm_image_write_exr(path, W, H, 3, names, r->b1, NULL, e);
    if (!st) st = out_path(dir, rel[1], path, sizeof path, e);
    if (!st) st = lm_image_write_rgb8(path, W, H, r->rgb, e);
    if (st) return st;
    json_object_set_new(entry, "rgb", json_string(rel[0]));
    json_object_set_new(entry, "rgb_preview", json_string(rel[1]));
    return LM_OK;
}

/* Write the files of one frame, recorded in entry. */
static lm_status write_files(const lm_simrun *r, const char *dir, int i, const lm_cube *gt,
                             json_t *entry, lm_err *e)
{
    const char *ext = EXTS[r->o->format];
    char rel[4][64], path[1100];
    snprintf(rel[0], sizeof rel[0], "frames/frame_%04d.%s", i, ext);
    snprintf(rel[1], sizeof rel[1], "bucket0/frame_%04d.%s", i, ext);
    snprintf(rel[2], sizeof rel[2], "gt/gt_%04d.exr", i);
    snprintf(rel[3], sizeof rel[3], "gt/gt_%04d.png", i);
    const char *keys[4] = {"coded", "bucket0", "gt", "preview"};
    int H = gt->height, W = gt->width;
    lm_status st = r->qdo ? write_rgb(r, dir, i, H, W, entry, e) : LM_OK;
    for (int k = r->qdo ? 2 : 0; k < 4 && !st; k++) {
        if (k == 1 && !r->o->bucket0) continue;
        if ((st = out_path(dir, rel[k], path, sizeof path, e))) break;
        if (k == 0) st = lm_frame_write(path, H, W, r->b1, e);
        else if (k == 1) st = lm_frame_write(path, H, W, scale_bucket0(r, H * W), e);
        else if (k == 2) st = lm_cube_write_exr(path, gt, e);
        else {
            st = lm_srgb_render_cube(gt, 1.0f, NULL, r->rgb, e);
            if (st == LM_OK) st = lm_image_write_rgb8(path, W, H, r->rgb, e);
        }
        if (!st) json_object_set_new(entry, keys[k], json_string(rel[k]));
    }
    return st;
}

/* Every frame: simulated, written, appended to files. */
static lm_status run_frames(const lm_simrun *r, const char *dir, json_t *files, lm_err *e)
{
    int n = (int)r->o->frames;
    lm_rng rng;
    lm_rng_seed(&rng, (uint64_t)r->o->seed);
    for (int i = 0; i < n; i++) {
        lm_cube gt;
        lm_err me;
        lm_err_clear(&me);
        lm_status st = simulate_one(r, i, &rng, &gt, &me);
        if (st) return lm_err_set(e, st, "%s: %s", r->o->input, me.msg);
        double t0 = lm_video_frame_start_us(r->sys, i);
        json_t *entry = json_pack("{s:i, s:f, s:o}", "index", i, "start_us", t0, "gt_time_us",
                                  r->o->video ? json_real(t0 + lm_video_gt_time_us(r->sys))
                                              : json_null());
        st = entry ? write_files(r, dir, i, &gt, entry, e)
                   : lm_err_set(e, LM_ERR_NOMEM, "out of memory");
        if (gt.data != r->gt0.data) lm_cube_free(&gt);
        if (st) {
            json_decref(entry);
            return st;
        }
        json_array_append_new(files, entry);
        if (r->o->progress) r->o->progress(r->o->user, i + 1, n);
    }
    return LM_OK;
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

static json_t *summary_json(const lm_simrun *r, json_t *files)
{
    const lm_simrun_opts *o = r->o;
    const lm_system *s = r->sys;
    json_t *video = json_null();
    if (o->video)
        video = json_pack("{s:I, s:I, s:f, s:f, s:o}", "frames", o->frames, "samples",
                          o->samples, "frame_period_us", s->frame_period_us, "gt_offset_us",
                          lm_video_gt_time_us(s), "motion", motion_json(&o->motion));
    json_t *js = json_pack(
        "{s:i, s:s, s:s, s:s, s:[i,i], s:[i,i], s:{s:s, s:s, s:[i,i], s:f, s:f}, "
        "s:{s:f, s:f, s:f, s:b, s:I}, s:I, s:s, s:b, s:f, s:o, s:O}",
        "version", 1, "command", "simulate", "lumosaic", LM_VERSION, "input", o->input,
        "input_size_hw", r->in_height, r->in_width, "size_hw", r->gt0.height, r->gt0.width,
        "system", "path", s->path, "name", s->name, "tile", s->tile_rows, s->tile_cols,
        "exposure_us", lm_system_exposure_us(s), "frame_period_us", s->frame_period_us,
        "noise", "gauss_k", o->noise, "photons", o->photons, "read_noise", o->read_noise, "clip",
        o->clip, "bits", o->bits, "seed", o->seed, "format", FORMATS[o->format], "bucket0",
        o->bucket0, "bucket0_scale", bucket0_scale(s), "video", video, "frames", files);
    if (js && o->doe) json_object_set_new(js, "doe", json_string(o->doe));
    return js;
}

/* frames/, gt/ and bucket0/ (when written) in dir. */
static lm_status make_folders(const lm_simrun *r, const char *dir, lm_err *e)
{
    const char *subs[3] = {"frames", "gt", r->o->bucket0 ? "bucket0" : NULL};
    char path[1100];
    for (int k = 0; k < 3 && subs[k]; k++) {
        lm_status st = out_path(dir, subs[k], path, sizeof path, e);
        if (st) return st;
        if (mkdir(path, 0777))
            return lm_err_set(e, LM_ERR_WRITE, "%s: cannot create a folder: %s", path,
                              strerror(errno));
    }
    return LM_OK;
}

lm_status lm_simrun_write(lm_simrun *r, const char *dir, lm_err *e)
{
    json_t *files = json_array();
    if (!files) return lm_err_set(e, LM_ERR_NOMEM, "out of memory");
    lm_status st = make_folders(r, dir, e);
    if (!st) st = run_frames(r, dir, files, e);
    json_t *js = st ? NULL : summary_json(r, files);
    char path[1100];
    if (!st) st = out_path(dir, "simulate.json", path, sizeof path, e);
    if (!st && (!js || json_dump_file(js, path, JSON_INDENT(2) | JSON_REAL_PRECISION(10))))
        st = lm_err_set(e, LM_ERR_WRITE, "%s: cannot write the summary: %s", path,
                        js ? strerror(errno) : "out of memory");
    json_decref(js);
    json_decref(files);
    return st;
}

/* cmd_simulate.c — `lumosaic simulate`: coded frames (static, or a video of a moving scene)
 * from a spectral cube, with their ground truth.
 * What it is: option parsing, the help text, the staging folder ("<DIR>.tmp.<pid>", renamed
 * onto DIR at the end: nothing is left on failure), progress and the closing line.
 * What it is not: the simulation or its files (data/simrun.h), the models (data/forward.c,
 * data/video.c) or the readers (data/cube_io.c). */
#include <stdio.h>
#include <string.h>
#include <unistd.h>
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "data/simrun.h"
#include "data/util.h"

static const char *const FORMATS[] = {"png", "tiff", "exr", NULL};

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
    lm_simrun_opts run; /* what the library runs */
    const char *output, *system, *mat_key;
    int format;
    lm_cli_common com;  /* --threads, --seed */
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
    if ((r = lm_cli_value(c, "--input", &o->run.input)) ||
        (r = lm_cli_value(c, "--mat-key", &o->mat_key)) ||
        (r = lm_cli_value(c, "--output", &o->output)) ||
        (r = lm_cli_value(c, "--system", &o->system)) || (r = lm_cli_flag(c, "--crop", &o->run.crop)) ||
        (r = lm_cli_value(c, "--doe", &o->run.doe)) ||
        (r = lm_cli_flag(c, "--clip", &o->run.clip)) ||
        (r = lm_cli_flag(c, "--bucket0", &o->run.bucket0)) ||
        (r = lm_cli_flag(c, "--video", &o->run.video)) ||
        (r = lm_cli_real(c, "--noise", 0, 1, &o->run.noise)) ||
        (r = lm_cli_real(c, "--poisson", 0, 1e12, &o->run.photons)) ||
        (r = lm_cli_real(c, "--read-noise", 0, 1e6, &o->run.read_noise)) ||
        (r = lm_cli_int(c, "--bits", 1, 24, &o->run.bits)) ||
        (r = lm_cli_common_opt(c, LM_CLI_THREADS | LM_CLI_SEED, 0x7fffffffffffffffLL, &o->com)) ||
        (r = lm_cli_choice(c, "--format", FORMATS, &o->format)))
        return r;
    if ((r = lm_cli_int(c, "--frames", 1, 10000, &o->run.frames)) ||
        (r = lm_cli_int(c, "--samples", 1, LM_VIDEO_MAX_SAMPLES, &o->run.samples)))
        return r;
    if ((r = lm_cli_value(c, "--motion", &s)) <= 0) return r;
    o->nmotion++;
    return parse_motion(c, s, &o->run.motion) == 0 ? 1 : -1;
}

/* 1: run, 0: help printed, 2: bad usage (printed). */
static int parse(lm_cli *c, sim_opts *o)
{
    memset(o, 0, sizeof *o);
    o->com.seed = 1;
    o->run.frames = -1;
    o->run.samples = -1;
    while (!lm_cli_done(c)) {
        if (lm_cli_is_help(c)) {
            help();
            return 0;
        }
        int r = parse_one(c, o);
        if (r < 0) return 2;
        if (r == 0) return lm_cli_unknown(c);
    }
    if (!o->run.input) return lm_cli_error(c, "--input is required (see 'lumosaic simulate --help')");
    if (!o->output)
        return lm_cli_error(c, "--output is required (see 'lumosaic simulate --help')");
    if (!o->run.video && (o->run.frames >= 0 || o->run.samples >= 0 || o->nmotion))
        return lm_cli_error(c, "--frames, --samples and --motion need --video");
    if (o->run.doe && (o->run.video || o->run.bucket0))
        return lm_cli_error(c, "--doe (the QDO camera's RGB image) takes no --video or --bucket0");
    if (o->run.frames < 0) o->run.frames = o->run.video ? 8 : 1;
    if (o->run.samples < 0) o->run.samples = LM_VIDEO_DEFAULT_SAMPLES;
    return 1;
}

/* Frame progress on a terminal: one line rewritten in place. */
static void progress(void *user, int done, int total)
{
    (void)user;
    fprintf(stderr, "\rlumosaic simulate: frame %d/%d", done, total);
    if (done == total) fputc('\n', stderr);
}

/* The run into a staging folder renamed onto --output; returns the exit status. */
static int run(const lm_cli *c, const sim_opts *o, lm_simrun *r)
{
    char tmp[1024];
    int status = lm_cli_stage_dir(c, o->output, tmp, sizeof tmp);
    if (status) return status;
    lm_err e;
    lm_err_clear(&e);
    if (lm_simrun_write(r, tmp, &e)) {
        lm_cli_error(c, "%s", e.msg);
        lm_cli_remove_tree(tmp);
        return LM_EXIT_FAILED;
    }
    if (lm_cli_commit_dir(c, tmp, o->output)) return LM_EXIT_FAILED;
    printf("lumosaic simulate: %d frame(s) of %d x %d written to %s\n", (int)o->run.frames,
           r->gt0.height, r->gt0.width, o->output);
    return 0;
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
    o.run.format = (lm_simrun_format)o.format;
    o.run.seed = o.com.seed;
    o.run.nthreads = (int)o.com.threads;
    if (isatty(STDERR_FILENO) && o.run.frames > 1) o.run.progress = progress;
    lm_system sys;
    lm_cube in;
    lm_err e;
    lm_err_clear(&e);
    if ((o.system ? lm_system_load(o.system, &sys, &e) : lm_system_default(&sys, &e)) != LM_OK) {
        lm_system_free(&sys);
        return lm_cli_error(&c, "%s", e.msg);
    }
    if (lm_simrun_read(o.run.input, o.mat_key, &sys, &in, &e) != LM_OK) {
        lm_system_free(&sys);
        return lm_cli_error(&c, "%s", e.msg), lm_cli_exit_status(e.status);
    }
    lm_simrun r;
    if (lm_simrun_init(&r, &o.run, &sys, &in, &e) != LM_OK)
        status = (lm_cli_error(&c, "%s", e.msg), lm_cli_exit_status(e.status));
    else
        status = run(&c, &o, &r);
    lm_simrun_free(&r);
    lm_cube_free(&in);
    lm_system_free(&sys);
    return status;
}

/* cmd_render.c — `lumosaic render`: a spectral cube to an sRGB PNG (D65, CIE 1931 2-degree).
 * What it is: read any cube lm_cube_read takes, render with lm_srgb_render_cube, write an 8-bit
 * PNG atomically. What it is not: tone mapping or white balance (--exposure only scales). */
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "data/cube_io.h"
#include "data/image.h"
#include "data/srgb.h"

static void help(void)
{
    printf("usage: lumosaic render --input CUBE --output PNG [--exposure X] [--threads T]\n"
           "                       [--mat-key NAME]\n\n"
           "Render a spectral cube as an sRGB image: illuminant D65, CIE 1931 2-degree observer,\n"
           "sRGB primaries and transfer curve, 8-bit PNG. Values are reflectances (1 = white).\n\n"
           "  --input CUBE     a CAVE folder (31 band PNGs), a .mat (ARAD 'cube', KAUST 'hsi',\n"
           "                   ICVL 'rad', Harvard 'ref', ...) or a spectral OpenEXR (.exr);\n"
           "                   31 bands 400-700 nm or 41 bins 380-780 nm as they are, other\n"
           "                   grids covering 420-680 nm resampled to 400-700 nm (docs/system.md)\n"
           "  --mat-key NAME   the .mat variable holding the cube (default: automatic)\n"
           "  --output PNG     the image to write (.png); written atomically\n"
           "  --exposure X     multiply the cube by X before rendering (0 < X <= 1e6; default 1)\n"
           "  --threads T      OpenMP threads (1..1024; default: all cores)\n"
           "  --help           this text\n");
}

typedef struct render_opts {
    const char *input, *output, *mat_key;
    double exposure;
    lm_cli_common com; /* --threads */
} render_opts;

/* 1: run, 0: help printed, 2: bad usage (printed). */
static int parse(lm_cli *c, render_opts *o)
{
    *o = (render_opts){.exposure = 1.0};
    while (!lm_cli_done(c)) {
        int r;
        if (lm_cli_is_help(c)) {
            help();
            return 0;
        }
        if ((r = lm_cli_value(c, "--input", &o->input)) ||
            (r = lm_cli_value(c, "--mat-key", &o->mat_key)) ||
            (r = lm_cli_value(c, "--output", &o->output)) ||
            (r = lm_cli_real(c, "--exposure", 1e-12, 1e6, &o->exposure)) ||
            (r = lm_cli_common_opt(c, LM_CLI_THREADS, 0, &o->com))) {
            if (r < 0) return 2;
            continue;
        }
        return lm_cli_unknown(c);
    }
    if (!o->input) return lm_cli_error(c, "--input is required (see 'lumosaic render --help')");
    if (!o->output) return lm_cli_error(c, "--output is required (see 'lumosaic render --help')");
    if (!lm_cli_has_ext(o->output, ".png"))
        return lm_cli_error(c, "%s: unknown output format (render writes .png)", o->output);
    return 1;
}

int lm_cmd_render(int argc, char **argv)
{
    lm_cli c;
    render_opts o;
    lm_cli_init(&c, "lumosaic render", argc, argv);
    int r = parse(&c, &o);
    if (r != 1) return r;
    lm_cli_common_apply(&o.com);
    lm_cube cube;
    lm_err e;
    lm_err_clear(&e);
    lm_cube_read_opts ro;
    lm_cube_read_opts_default(&ro);
    ro.mat_key = o.mat_key;
    if (lm_cube_read_with(o.input, &ro, &cube, &e) != LM_OK)
        return lm_cli_error(&c, "%s", e.msg), lm_cli_exit_status(e.status);
    float *rgb = malloc(sizeof(float) * 3 * (size_t)cube.height * cube.width);
    int status = 0;
    if (!rgb) {
        status = 1;
        lm_cli_error(&c, "out of memory (%d x %d image)", cube.width, cube.height);
    } else if (lm_srgb_render_cube(&cube, (float)o.exposure, NULL, rgb, &e) != LM_OK) {
        status = lm_cli_exit_status(e.status);
        lm_cli_error(&c, "%s: %s", o.input, e.msg);
    } else if (lm_image_write_rgb8(o.output, cube.width, cube.height, rgb, &e) != LM_OK) {
        status = LM_EXIT_FAILED;
        lm_cli_error(&c, "%s", e.msg);
    }
    free(rgb);
    lm_cube_free(&cube);
    return status;
}

/* cmd_bound.c — `lumosaic bound`: the spectral bound of the camera (infer/bound.h).
 * What it is: option parsing, the help text, progress lines on stderr and the table on stdout.
 * What it is not: the fit or the scoring (infer/bound.c). */
#include <stdio.h>
#include <stdlib.h>
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "data/util.h"
#include "infer/bound.h"

static void help(void)
{
    printf("usage: lumosaic bound DATA... [--split test|val] [--noise 0,5,10,20]\n"
           "                      [--system FILE] [--ridge R] [--seed S] [--mat-key NAME]\n\n"
           "How well the 31 bands 400-700 nm can be recovered when every pixel's response to\n"
           "every LED is known: no mosaic, so no demosaicing error (an oracle that reads the\n"
           "ground truth). Per-pixel maps from the LEDs' responses to the 31 bands are fitted\n"
           "in closed form (ridge regression) on the training split of DATA and scored on\n"
           "--split, with scenes prepared and scored as 'lumosaic eval' does them (cropped to\n"
           "the tile, divided by their maximum; PSNR, SSIM, SAM on the 31 bands):\n"
           "  linear     the LEDs' responses and a constant (the best linear spectral map)\n"
           "  quadratic  plus their pairwise products (a nonlinear per-pixel prior)\n"
           "A model that reconstructs from the mosaic with a per-pixel spectral map of this\n"
           "form stays below these figures; one that uses neighbouring pixels' spectra\n"
           "(texture, materials) can exceed them. Two buckets carry the same per-pixel light\n"
           "(bucket 0 sums the other LEDs), so the bound holds for both. The means are\n"
           "followed by each scored scene's PSNR, for comparison with 'lumosaic eval\n"
           "--output', which writes each scene's scores too.\n\n"
           "  DATA             scenes or folders of scenes (as for 'lumosaic train'); their\n"
           "                   split is train's: the maps are fitted on the training scenes\n"
           "  --split S        the scored scenes: test (default) or val\n"
           "  --noise LIST     Gaussian noise on every LED's response, %% of the coded frame's\n"
           "                   largest clean value, as eval's levels (default 0); a map is\n"
           "                   fitted per level (at most %d levels)\n"
           "  --system FILE    the imaging system (default: the bundled one)\n"
           "  --ridge R        ridge, relative to the mean diagonal of the normal equations\n"
           "                   (default: each map's best of 1e-9, 1e-8, ..., 1e-3 on the\n"
           "                   validation scenes)\n"
           "  --seed S         noise seed (default 1)\n"
           "  --mat-key NAME   the variable of .mat scenes (default: automatic)\n"
           "  --help           this text\n", LM_BOUND_MAX_NOISE);
}

static const char *const split_names[] = {"test", "val", NULL};

static void log_line(void *user, const char *line)
{
    (void)user;
    fprintf(stderr, "%s\n", line);
}

/* 1: run, 0: help printed, 2: bad usage (printed). */
static int parse(lm_cli *c, lm_bound_run_opts *o, const char **data, int *ndata)
{
    lm_bound_run_opts_default(o);
    const char *noise = NULL;
    int split = 0;
    long long seed = 1;
    while (!lm_cli_done(c)) {
        if (lm_cli_is_help(c)) {
            help();
            return 0;
        }
        int r;
        if ((r = lm_cli_value(c, "--system", &o->system)) ||
            (r = lm_cli_value(c, "--mat-key", &o->mat_key)) ||
            (r = lm_cli_value(c, "--noise", &noise)) ||
            (r = lm_cli_choice(c, "--split", split_names, &split)) ||
            (r = lm_cli_real(c, "--ridge", 0, 1, &o->ridge)) ||
            (r = lm_cli_int(c, "--seed", 0, (long long)1 << 62, &seed))) {
            if (r < 0) return 2;
            continue;
        }
        if (lm_cli_positional(c, data, ndata)) return 2;
    }
    if (!*ndata)
        return lm_cli_error(c, "no DATA given: name scenes or folders of scenes "
                               "(see 'lumosaic bound --help')");
    o->split = split ? LM_SPLIT_VAL : LM_SPLIT_TEST;
    o->seed = seed;
    if (noise) {
        double v[LM_BOUND_MAX_NOISE];
        char why[128];
        int n = lm_parse_list(noise, 0, 100, v, LM_BOUND_MAX_NOISE, why, sizeof why);
        if (n < 0)
            return lm_cli_error(c, "--noise '%s': %s (levels in %% from 0 to 100, e.g. 0,5,10)",
                                noise, why);
        for (int i = 0; i < n; i++) o->k[i] = (float)(v[i] / 100.0);
        o->nnoise = n;
    }
    return 1;
}

int lm_cmd_bound(int argc, char **argv)
{
    lm_cli c;
    lm_cli_init(&c, "lumosaic bound", argc, argv);
    const char **data = calloc((size_t)argc + 1, sizeof *data);
    if (!data) return lm_cli_error(&c, "out of memory"), 1;
    lm_bound_run_opts o;
    int ndata = 0;
    int rc = parse(&c, &o, data, &ndata);
    if (rc == 1) {
        o.data = data, o.ndata = ndata;
        o.log = log_line;
        lm_bound_result res;
        lm_err e;
        lm_err_clear(&e);
        lm_status st = lm_bound_run(&o, &res, &e);
        if (st) {
            lm_cli_error(&c, "%s", e.msg);
            rc = lm_cli_exit_status(st);
        } else {
            printf("%d LEDs; maps fitted on %d training scene(s) (%ld pixels), scored on %d "
                   "%s scene(s)\n", res.nleds, res.ntrain, res.train_pixels, res.nscored,
                   split_names[o.split == LM_SPLIT_VAL]);
            printf("  map        noise %%    PSNR dB     SSIM   SAM deg    ridge\n");
            for (int m = 0; m < LM_BOUND_MAPS; m++)
                for (int l = 0; l < o.nnoise; l++)
                    printf("  %-9s %8g %10.3f %8.4f %9.3f %8.0e\n", lm_bound_map_name(m),
                           100.0 * o.k[l], res.m[m][l].psnr, res.m[m][l].ssim, res.m[m][l].sam,
                           res.ridge[m][l]);
            printf("per scene, PSNR dB (%s / %s):\n  %-28s", lm_bound_map_name(0),
                   lm_bound_map_name(1), "scene");
            for (int l = 0; l < o.nnoise; l++) printf("  %13g %%", 100.0 * o.k[l]);
            printf("\n");
            for (int i = 0; i < res.nscored; i++) {
                printf("  %-28s", res.scene[i].name);
                for (int l = 0; l < o.nnoise; l++)
                    printf("  %7.2f / %5.2f", res.scene[i].m[0][l].psnr,
                           res.scene[i].m[1][l].psnr);
                printf("\n");
            }
            lm_bound_result_free(&res);
            rc = 0;
        }
    }
    free(data);
    return rc;
}

/* cmd_report.c — `lumosaic report`: one self-contained HTML page for an infer or eval output
 * folder (infer/report.h), written atomically.
 * What it is not: the page itself (infer/report.c, infer/report_page.html). */
#include <omp.h>
#include <stdio.h>
#include <stdlib.h>
#include "cli/cli_util.h"
#include "cli/commands.h"
#include "infer/report.h"

static void help(void)
{
    printf("usage: lumosaic report DIR [--output FILE] [--max-side N] [--frame N]\n\n"
           "One self-contained HTML page (works offline: nothing is loaded from a network) for\n"
           "DIR, a folder written by 'lumosaic eval --output' or 'lumosaic infer --output':\n"
           "sRGB previews (D65) of the reconstruction and, for eval, of the truth; a band\n"
           "slider (400-700 nm) over each band, and for eval its error map; the spectrum of\n"
           "any clicked pixel (and the truth's); for eval the scores per noise level and scene,\n"
           "PSNR per band and the rainbow test's recovered peak per row. An eval folder shows\n"
           "its previews, bands and spectra when it was written with 'eval --report' (which\n"
           "also writes DIR/report.html itself); an infer folder shows one frame's cube.\n"
           "A URL ending in #click=X,Y opens the page with pixel (X, Y) clicked.\n\n"
           "  DIR              an eval folder (eval.json) or an infer folder (cube_NNNN.exr)\n"
           "  --output FILE    the page to write (.html; default DIR/report.html); written\n"
           "                   atomically\n"
           "  --max-side N     the cube behind the band images, error maps and spectra is\n"
           "                   box-averaged to at most N pixels on its long side (%d..%d;\n"
           "                   default %d); the sRGB previews keep the full size\n"
           "  --frame N        infer folders: show cube_NNNN.exr with number N (0..99999999;\n"
           "                   default: the lowest number)\n"
           "  --help           this text\n",
           LM_REPORT_MIN_SIDE, LM_REPORT_MAX_SIDE, LM_REPORT_DEFAULT_SIDE);
}

typedef struct report_cli_opts {
    const char *dir, *output;
    long long max_side, frame;
} report_cli_opts;

/* 1: run, 0: help printed, 2: bad usage (printed). */
static int parse(lm_cli *c, report_cli_opts *o, const char **pos)
{
    *o = (report_cli_opts){.max_side = LM_REPORT_DEFAULT_SIDE, .frame = -1};
    int npos = 0;
    while (!lm_cli_done(c)) {
        int r;
        if (lm_cli_is_help(c)) {
            help();
            return 0;
        }
        if ((r = lm_cli_value(c, "--output", &o->output)) ||
            (r = lm_cli_int(c, "--max-side", LM_REPORT_MIN_SIDE, LM_REPORT_MAX_SIDE,
                            &o->max_side)) ||
            (r = lm_cli_int(c, "--frame", 0, 99999999, &o->frame))) {
            if (r < 0) return 2;
            continue;
        }
        if (lm_cli_positional(c, pos, &npos)) return 2;
    }
    if (npos != 1)
        return lm_cli_error(c, "%s (see 'lumosaic report --help')",
                            npos ? "one DIR only" : "no DIR given: name an eval or infer output folder");
    o->dir = pos[0];
    if (o->output && !lm_cli_has_ext(o->output, ".html"))
        return lm_cli_error(c, "%s: the page is written as .html", o->output);
    return 1;
}

int lm_cmd_report(int argc, char **argv)
{
    lm_cli c;
    report_cli_opts o;
    lm_cli_init(&c, "lumosaic report", argc, argv);
    const char **pos = calloc((size_t)argc + 1, sizeof *pos);
    if (!pos) return lm_cli_error(&c, "out of memory"), 1;
    int rc = parse(&c, &o, pos);
    if (rc != 1) return free(pos), rc;
    char out[4200];
    if (!o.output) snprintf(out, sizeof out, "%s/report.html", o.dir);
    else snprintf(out, sizeof out, "%s", o.output);
    lm_report_opts ro = {.max_side = (int)o.max_side, .frame = (int)o.frame};
    lm_report_info info;
    lm_err e;
    lm_err_clear(&e);
    double t0 = omp_get_wtime();
    if (lm_report_write(o.dir, out, &ro, &info, &e)) {
        free(pos);
        lm_cli_error(&c, "%s", e.msg);
        return lm_cli_exit_status(e.status);
    }
    printf("report: %s (%.1f kB, %.2f s): %s", out, info.bytes / 1000.0, omp_get_wtime() - t0,
           info.eval ? "eval scores" : "reconstruction");
    if (info.has_sample)
        printf(", %s %d x %d (cube %d x %d)%s", info.shown, info.width, info.height, info.side_w,
               info.side_h, info.has_truth ? " with truth" : "");
    if (info.rainbow_rows) printf(", rainbow %d rows", info.rainbow_rows);
    printf("\n");
    free(pos);
    return 0;
}

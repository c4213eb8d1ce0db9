/* cmd_calibrate.c — `lumosaic calibrate`: the paper's LED-gain calibration (system.md section
 * 11). Coded frames of a ColorChecker are averaged; each patch region (a JSON of 24 rectangles,
 * or a 6 x 4 grid from the centres of the chart's corner patches) gives each LED's mean; the
 * gains come from NNLS against the simulated patch responses (data/calib.h); a new system file
 * with the calibrated gains and a report (JSON, and a table on stdout) are written.
 * With --write-chart CUBE.exr it instead writes a ColorChecker scene on the system's grid (for
 * trying calibration on frames simulated from it).
 * What it is not: the fit of `infer --model auto` (that command is `lumosaic fit-auto`). */
#include <jansson.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include "cli/cli_util.h"
#include "data/util.h"
#include "cli/commands.h"
#include "data/calib.h"
#include "data/cube_io.h"
#include "data/frames.h"

#define MAX_INPUTS 256

static void help(void)
{
    printf("usage: lumosaic calibrate FRAMES... (--patches RECTS.json | --chart-corners LIST)\n"
           "                          --output SYSTEM.json [--system FILE] [--reflectance CSV]\n"
           "                          [--patch-fraction F] [--offset] [--max-error F]\n"
           "                          [--report FILE]\n"
           "       lumosaic calibrate --write-chart CUBE.exr [--chart-corners LIST]\n"
           "                          [--system FILE] [--reflectance CSV]\n\n"
           "LED gains by non-negative least squares (the paper's calibration): FRAMES (coded\n"
           "frames of a ColorChecker Classic, files, folders or %%04d patterns; all averaged)\n"
           "give, per patch region, the mean of each LED's pixels (the 12 x 24 measured\n"
           "matrix); each LED's response in the system file against each patch's reflectance\n"
           "gives the simulated one; gains alpha >= 0 minimise the squared difference. Writes\n"
           "a copy of the system file with \"gains\" calibrated (relative: one factor common to\n"
           "all LEDs drops out) and a report: per-LED gain, per-patch residual, the fit's\n"
           "relative error.\n\n"
           "  FRAMES              frames of the system's sensor size (16-bit PNG/TIFF, EXR)\n"
           "  --patches FILE      JSON {\"patches\": [[x, y, w, h], ...]}: 24 regions, chart\n"
           "                      order (row by row from dark skin; pixels)\n"
           "  --chart-corners L   X1,Y1,X2,Y2,X3,Y3,X4,Y4: centres of patches 1 (dark skin),\n"
           "                      6 (bluish green), 24 (black) and 19 (white) in the frame;\n"
           "                      the 24 regions are squares on the 6 x 4 grid they span\n"
           "  --patch-fraction F  region side / centre spacing with --chart-corners (0..1;\n"
           "                      default 0.5: away from patch borders)\n"
           "  --system FILE       system description (default: the bundled prototype)\n"
           "  --reflectance CSV   the 24 patch reflectances (first 24 value columns; default:\n"
           "                      the bundled BabelColor table, extended flat past 730 nm)\n"
           "  --offset            also fit a common dark offset >= 0 (a black level)\n"
           "  --max-error F       refuse a fit whose relative error exceeds F (0..10; default\n"
           "                      0.1: frames of another system, or misplaced patches)\n"
           "  --output FILE       the calibrated system file to write\n"
           "  --report FILE       the report (default: the output with .report.json)\n"
           "  --write-chart CUBE  write a chart scene (.exr, the system's grid and sensor size,\n"
           "                      grey 0.2 around the patches; default corners: centred)\n"
           "  --help              this text\n\n"
           "Exit status: 0 done, 1 an output cannot be written, 2 bad usage or input (nothing\n"
           "written).\n");
}

typedef struct cal_args {
    const char *in[MAX_INPUTS];
    int nin;
    const char *patches, *corners, *system, *refl, *output, *report, *chart;
    double frac, max_error;
    int offset;
} cal_args;

static int parse(lm_cli *c, cal_args *a)
{
    while (!lm_cli_done(c)) {
        int r;
        if (lm_cli_is_help(c)) {
            help();
            return 0;
        }
        if (!strcmp(c->argv[c->i], "--models"))
            return lm_cli_error(c, "--models: the fit of 'infer --model auto' is now 'lumosaic "
                                "fit-auto' (calibrate fits LED gains from ColorChecker frames)");
        if ((r = lm_cli_value(c, "--patches", &a->patches)) ||
            (r = lm_cli_value(c, "--chart-corners", &a->corners)) ||
            (r = lm_cli_real(c, "--patch-fraction", 1e-6, 1, &a->frac)) ||
            (r = lm_cli_value(c, "--system", &a->system)) ||
            (r = lm_cli_value(c, "--reflectance", &a->refl)) ||
            (r = lm_cli_flag(c, "--offset", &a->offset)) ||
            (r = lm_cli_real(c, "--max-error", 0, 10, &a->max_error)) ||
            (r = lm_cli_value(c, "--output", &a->output)) ||
            (r = lm_cli_value(c, "--report", &a->report)) ||
            (r = lm_cli_value(c, "--write-chart", &a->chart))) {
            if (r < 0) return 2;
            continue;
        }
        if (a->nin >= MAX_INPUTS) return lm_cli_error(c, "at most %d frame arguments", MAX_INPUTS);
        if (lm_cli_positional(c, a->in, &a->nin)) return 2;
    }
    if (a->chart) {
        if (a->nin || a->output || a->patches)
            return lm_cli_error(c, "--write-chart takes no frames, --output or --patches");
        if (!lm_cli_has_ext(a->chart, ".exr"))
            return lm_cli_error(c, "--write-chart %s: the chart is a spectral OpenEXR cube; name "
                                "it .exr", a->chart);
        return 1;
    }
    if (!a->nin) return lm_cli_error(c, "no frames given (see 'lumosaic calibrate --help')");
    if (!a->output) return lm_cli_error(c, "--output SYSTEM.json is required");
    if (!a->patches == !a->corners)
        return lm_cli_error(c, "give the patch regions with one of --patches or --chart-corners");
    return 1;
}

static int parse_corners(const lm_cli *c, const char *s, double out[8])
{
    char why[128];
    int n = lm_parse_list(s, -1e6, 1e6, out, 8, why, sizeof why);
    if (n != 8)
        return lm_cli_error(c, "--chart-corners: need 8 numbers X1,Y1,X2,Y2,X3,Y3,X4,Y4 (got "
                            "'%s')", s);
    return 0;
}

/* The average of every frame of every input, *out (height x width). */
static lm_status average_frames(const cal_args *a, float **out, int *h, int *w, int *count,
                                lm_err *e)
{
    double *acc = NULL;
    *out = NULL, *count = 0;
    lm_status st = LM_OK;
    for (int i = 0; i < a->nin && !st; i++) {
        lm_frame_seq seq;
        if ((st = lm_frame_seq_open(a->in[i], &seq, e))) break;
        if (!acc) {
            *h = seq.height, *w = seq.width;
            acc = calloc((size_t)*h * *w, sizeof *acc);
            if (!acc) st = lm_err_set(e, LM_ERR_NOMEM, "out of memory");
        } else if (seq.height != *h || seq.width != *w) {
            st = lm_err_set(e, LM_ERR_FORMAT, "%s: %d x %d frames, the first input's are %d x %d",
                            a->in[i], seq.width, seq.height, *w, *h);
        }
        for (int k = 0; k < seq.count && !st; k++) {
            lm_frame f;
            if ((st = lm_frame_seq_read(&seq, k, &f, e))) break;
            for (size_t p = 0; p < (size_t)*h * *w; p++) acc[p] += f.data[p];
            lm_frame_free(&f);
            ++*count;
        }
        lm_frame_seq_free(&seq);
    }
    float *avg = st ? NULL : malloc((size_t)*h * *w * sizeof *avg);
    if (!st && !avg) st = lm_err_set(e, LM_ERR_NOMEM, "out of memory");
    for (size_t p = 0; !st && p < (size_t)*h * *w; p++) avg[p] = (float)(acc[p] / *count);
    free(acc);
    *out = avg;
    return st;
}

static lm_status write_report(const char *path, const lm_system *sys, const lm_calib_fit *f,
                              const double *M, const double *A, int nframes, int offset,
                              lm_err *e)
{
    json_t *leds = json_array(), *patches = json_array();
    for (int l = 0; l < sys->nleds; l++)
        json_array_append_new(leds, json_pack("{s:s, s:f, s:f, s:f, s:f}", "name",
                              sys->leds[l].name, "gain", f->gain[l], "gain_before",
                              sys->leds[l].gain, "alpha", f->alpha[l], "rms_rel", f->led_rms[l]));
    for (int p = 0; p < LM_CALIB_PATCHES; p++) {
        json_t *m = json_array(), *s = json_array();
        for (int l = 0; l < sys->nleds; l++) {
            json_array_append_new(m, json_real(M[l * LM_CALIB_PATCHES + p]));
            json_array_append_new(s, json_real(f->alpha[l] * A[l * LM_CALIB_PATCHES + p] + f->offset));
        }
        json_array_append_new(patches, json_pack("{s:i, s:f, s:o, s:o}", "patch", p + 1,
                              "rms_rel", f->patch_rms[p], "measured", m, "fitted", s));
    }
    json_t *root = json_pack("{s:s, s:i, s:s, s:f, s:f, s:b, s:o, s:o}", "system", sys->path,
                             "frames", nframes, "method", "NNLS (Lawson-Hanson active set)",
                             "relative_error", f->rel_error, "offset", f->offset, "offset_fitted",
                             offset, "leds", leds, "patches", patches);
    char tmp[4200];
    snprintf(tmp, sizeof tmp, "%s.tmp.%d", path, (int)getpid());
    int rc = json_dump_file(root, tmp, JSON_INDENT(2) | JSON_PRESERVE_ORDER | JSON_REAL_PRECISION(8));
    json_decref(root);
    if (rc || rename(tmp, path)) {
        remove(tmp);
        return lm_err_set(e, LM_ERR_WRITE, "%s: cannot write the report", path);
    }
    return LM_OK;
}

static void print_table(const lm_system *sys, const lm_calib_fit *f, int nframes)
{
    printf("calibrated from %d frame(s): relative error %.4f%s\n", nframes, f->rel_error,
           f->offset > 0 ? "" : "");
    if (f->offset > 0) printf("dark offset %.6g\n", f->offset);
    printf("%-12s %12s %12s %10s\n", "LED", "gain before", "gain", "rms rel");
    for (int l = 0; l < sys->nleds; l++)
        printf("%-12s %12.6g %12.6g %10.4f\n", sys->leds[l].name, sys->leds[l].gain, f->gain[l],
               f->led_rms[l]);
    printf("patch rms rel:");
    for (int p = 0; p < LM_CALIB_PATCHES; p++) printf(" %.3f", f->patch_rms[p]);
    printf("\n");
}

static void default_corners(const lm_system *sys, double c[8])
{
    double pitch = 0.6 * (sys->width / 6.0 < sys->height / 4.0 ? sys->width / 6.0 : sys->height / 4.0);
    double cx = 0.5 * sys->width, cy = 0.5 * sys->height, dx = 2.5 * pitch, dy = 1.5 * pitch;
    double v[8] = {cx - dx, cy - dy, cx + dx, cy - dy, cx + dx, cy + dy, cx - dx, cy + dy};
    memcpy(c, v, sizeof v);
}

static int write_chart(lm_cli *c, const cal_args *a, const lm_system *sys)
{
    double corners[8], C[LM_CALIB_PATCHES * 128];
    if (a->corners) {
        if (parse_corners(c, a->corners, corners)) return 2;
    } else {
        default_corners(sys, corners);
    }
    lm_calib_rect r[LM_CALIB_PATCHES];
    lm_cube cube;
    lm_err e = {0};
    if (sys->nbins > 128) return lm_cli_error(c, "the system's grid has over 128 bins");
    lm_status st = lm_calib_grid(corners, 0.85, r, &e);
    if (!st) st = lm_calib_reflectances(sys, a->refl, C, &e);
    if (!st) st = lm_calib_chart_cube(sys, sys->height, sys->width, r, C, 0.2, &cube, &e);
    if (st) return lm_cli_error(c, "%s", e.msg);
    st = lm_cube_write_exr(a->chart, &cube, &e);
    lm_cube_free(&cube);
    if (st) {
        lm_cli_error(c, "%s", e.msg);
        return lm_cli_exit_status(st);
    }
    printf("chart scene: %s (%d x %d, %d bins; corner patch centres", a->chart, sys->width,
           sys->height, sys->nbins);
    for (int i = 0; i < 8; i += 2) printf(" %.1f,%.1f", corners[i], corners[i + 1]);
    printf(")\n");
    return 0;
}

static int calibrate(lm_cli *c, const cal_args *a, const lm_system *sys)
{
    lm_calib_rect r[LM_CALIB_PATCHES];
    lm_err e = {0};
    double corners[8];
    if (a->corners && parse_corners(c, a->corners, corners)) return 2;
    lm_status st = a->patches ? lm_calib_rects_load(a->patches, r, &e)
                              : lm_calib_grid(corners, a->frac > 0 ? a->frac : 0.5, r, &e);
    float *frame = NULL;
    int h = 0, w = 0, nframes = 0;
    if (!st) st = average_frames(a, &frame, &h, &w, &nframes, &e);
    if (!st && (h != sys->height || w != sys->width))
        st = lm_err_set(&e, LM_ERR_FORMAT, "the frames are %d x %d, the system's sensor (%s) is "
                        "%d x %d: frames of another system?", w, h, sys->path, sys->width,
                        sys->height);
    double *C = malloc((size_t)LM_CALIB_PATCHES * sys->nbins * sizeof *C);
    double M[LM_SYSTEM_MAX_LEDS * LM_CALIB_PATCHES], A[LM_SYSTEM_MAX_LEDS * LM_CALIB_PATCHES];
    if (!st && !C) st = lm_err_set(&e, LM_ERR_NOMEM, "out of memory");
    if (!st) st = lm_calib_measure(sys, frame, h, w, r, M, &e);
    if (!st) st = lm_calib_reflectances(sys, a->refl, C, &e);
    if (!st) lm_calib_simulate(sys, C, A);
    lm_calib_fit fit;
    if (!st) st = lm_calib_solve(sys, A, M, a->offset, &fit, &e);
    double maxe = a->max_error >= 0 ? a->max_error : 0.1;
    if (!st && !(fit.rel_error <= maxe))
        st = lm_err_set(&e, LM_ERR_FORMAT, "the fit leaves a relative error of %.3f (over "
                        "--max-error %g): frames of another system, or misplaced patches?",
                        fit.rel_error, maxe);
    free(frame);
    free(C);
    if (st) return lm_cli_error(c, "%s", e.msg);
    char report[4096], note[1024];
    if (a->report) snprintf(report, sizeof report, "%s", a->report);
    else {
        size_t n = strlen(a->output);
        int json = n > 5 && !strcmp(a->output + n - 5, ".json");
        snprintf(report, sizeof report, "%.*s.report.json", (int)(json ? n - 5 : n), a->output);
    }
    snprintf(note, sizeof note, "LED gains calibrated by NNLS from %d ColorChecker frame(s) "
             "(lumosaic calibrate; relative error %.4f) over %s", nframes, fit.rel_error,
             sys->path);
    st = lm_calib_write_system(sys, fit.gain, note, a->output, &e);
    if (!st && (st = write_report(report, sys, &fit, M, A, nframes, a->offset, &e)))
        remove(a->output);
    if (st) {
        lm_cli_error(c, "%s", e.msg);
        return lm_cli_exit_status(st);
    }
    print_table(sys, &fit, nframes);
    printf("system: %s\nreport: %s\n", a->output, report);
    return 0;
}

int lm_cmd_calibrate(int argc, char **argv)
{
    lm_cli c;
    cal_args a = {.frac = -1, .max_error = -1};
    lm_cli_init(&c, "lumosaic calibrate", argc, argv);
    int r = parse(&c, &a);
    if (r != 1) return r;
    lm_system sys;
    lm_err e = {0};
    if (a.system ? lm_system_load(a.system, &sys, &e) : lm_system_default(&sys, &e))
        return lm_cli_error(&c, "%s", e.msg);
    r = a.chart ? write_chart(&c, &a, &sys) : calibrate(&c, &a, &sys);
    lm_system_free(&sys);
    return r;
}

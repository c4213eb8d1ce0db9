/* make_cube.c — writes small spectral cubes for the end-to-end CLI tests (tests/cli/).
 * What it is: `cli_make_cube OUT KIND H W`, KIND one of
 *   good      31 bands 400-700 nm, values in [0.05, 0.95] varying with band and pixel
 *   nan       good with one NaN          negative  good with one value -0.25
 *   bands20   20 bands 400-590 nm        grid41    41 bands 380-780 nm (the system's grid)
 *   fivenm    61 bands 400-700 nm at 5 nm
 * written through lm_image_write_exr (which, unlike lm_cube_write_exr, does not validate), so
 * bad values reach the file; or, OUT a .mat (MATLAB v5, matio):
 *   kaust     `hsi`, 34 bands (400-730 nm) of 12-bit counts
 *   twokeys   `cube` and `alt`, 31 bands each (alt = cube / 2)
 * What it is not: a test by itself. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "data/cube_io.h"
#include "data/image.h"
#include <matio.h>

static float value(int b, int i) { return 0.05f + 0.9f * (float)((b * 7 + i * 13) % 101) / 100.0f; }

/* A v5 .mat: kaust or twokeys (see the top of the file); column-major H x W x B. */
static int write_mat(const char *path, const char *kind, int H, int W)
{
    int kaust = !strcmp(kind, "kaust"), B = kaust ? 34 : 31;
    size_t n = (size_t)H * W * B, dims[3] = {(size_t)H, (size_t)W, (size_t)B};
    double *d = malloc(n * sizeof *d);
    uint16_t *u = malloc(n * sizeof *u);
    mat_t *m = d && u ? Mat_CreateVer(path, NULL, MAT_FT_MAT5) : NULL;
    if (!m) return free(d), free(u), 1;
    for (int b = 0; b < B; b++)
        for (int x = 0; x < W; x++)
            for (int y = 0; y < H; y++) {
                size_t k = (size_t)y + (size_t)H * ((size_t)x + (size_t)W * b);
                d[k] = value(b, y * W + x);
                u[k] = (uint16_t)lround(4095.0 * d[k]);
            }
    matvar_t *v = kaust ? Mat_VarCreate("hsi", MAT_C_UINT16, MAT_T_UINT16, 3, dims, u, 0)
                        : Mat_VarCreate("cube", MAT_C_DOUBLE, MAT_T_DOUBLE, 3, dims, d, 0);
    int rc = Mat_VarWrite(m, v, MAT_COMPRESSION_ZLIB);
    Mat_VarFree(v);
    if (!kaust) {
        for (size_t k = 0; k < n; k++) d[k] *= 0.5;
        v = Mat_VarCreate("alt", MAT_C_DOUBLE, MAT_T_DOUBLE, 3, dims, d, 0);
        rc |= Mat_VarWrite(m, v, MAT_COMPRESSION_ZLIB);
        Mat_VarFree(v);
    }
    Mat_Close(m);
    free(d), free(u);
    return rc ? 1 : 0;
}

int main(int argc, char **argv)
{
    if (argc != 5) {
        fprintf(stderr, "usage: cli_make_cube OUT.exr good|nan|negative|bands20|grid41|fivenm H W\n"
                        "       cli_make_cube OUT.mat kaust|twokeys H W\n");
        return 2;
    }
    const char *kind = argv[2];
    int H = atoi(argv[3]), W = atoi(argv[4]);
    if (H < 1 || W < 1) return 2;
    if (!strcmp(kind, "kaust") || !strcmp(kind, "twokeys")) return write_mat(argv[1], kind, H, W);
    int five = !strcmp(kind, "fivenm");
    int nb = !strcmp(kind, "bands20") ? 20 : (!strcmp(kind, "grid41") ? 41 : five ? 61 : 31);
    float start = !strcmp(kind, "grid41") ? 380.0f : 400.0f, step = five ? 5.0f : 10.0f;
    float *d = malloc(sizeof(float) * nb * H * W);
    char(*names)[32] = malloc(sizeof(*names) * nb);
    const char **np = malloc(sizeof(char *) * nb);
    if (!d || !names || !np) return 1;
    for (int b = 0; b < nb; b++) {
        lm_spectral_channel_name(names[b], sizeof names[b], start + step * b);
        np[b] = names[b];
        for (int i = 0; i < H * W; i++) d[(size_t)b * H * W + i] = value(b, i);
    }
    if (!strcmp(kind, "nan")) d[3 * H * W + 1] = NAN;
    if (!strcmp(kind, "negative")) d[5 * H * W + 2] = -0.25f;
    const char *attrs[] = {"spectralLayoutVersion", "1.0", NULL};
    lm_err e;
    lm_err_clear(&e);
    int rc = lm_image_write_exr(argv[1], W, H, nb, np, d, attrs, &e) == LM_OK ? 0 : 1;
    if (rc) fprintf(stderr, "cli_make_cube: %s\n", e.msg);
    free(d), free(names), free(np);
    return rc;
}

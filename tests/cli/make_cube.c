/* make_cube.c — writes small spectral OpenEXR cubes for the end-to-end CLI tests (tests/cli/).
 * What it is: `cli_make_cube OUT.exr KIND H W`, KIND one of
 *   good      31 bands 400-700 nm, values in [0.05, 0.95] varying with band and pixel
 *   nan       good with one NaN          negative  good with one value -0.25
 *   bands20   20 bands 400-590 nm        grid41    41 bands 380-780 nm (the system's grid)
 * written through lm_image_write_exr (which, unlike lm_cube_write_exr, does not validate), so
 * bad values reach the file. What it is not: a test by itself. */
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "data/cube_io.h"
#include "data/image.h"

int main(int argc, char **argv)
{
    if (argc != 5) {
        fprintf(stderr, "usage: cli_make_cube OUT.exr good|nan|negative|bands20|grid41 H W\n");
        return 2;
    }
    const char *kind = argv[2];
    int H = atoi(argv[3]), W = atoi(argv[4]);
    int nb = !strcmp(kind, "bands20") ? 20 : (!strcmp(kind, "grid41") ? 41 : 31);
    float start = !strcmp(kind, "grid41") ? 380.0f : 400.0f;
    if (H < 1 || W < 1) return 2;
    float *d = malloc(sizeof(float) * nb * H * W);
    char(*names)[32] = malloc(sizeof(*names) * nb);
    const char **np = malloc(sizeof(char *) * nb);
    if (!d || !names || !np) return 1;
    for (int b = 0; b < nb; b++) {
        lm_spectral_channel_name(names[b], sizeof names[b], start + 10.0f * b);
        np[b] = names[b];
        for (int i = 0; i < H * W; i++)
            d[(size_t)b * H * W + i] = 0.05f + 0.9f * (float)((b * 7 + i * 13) % 101) / 100.0f;
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

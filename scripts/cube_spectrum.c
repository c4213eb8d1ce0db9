/* cube_spectrum.c — print the mean spectrum of a small square of a cube, one line per band:
 * "wavelength_nm value". Used by scripts/readme_figure.sh; built on the public API.
 * Usage: cube_spectrum CUBE X Y [HALF]   (the square of side 2 HALF + 1 around column X, row Y) */
#include <stdio.h>
#include <stdlib.h>
#include "lumosaic.h"

int main(int argc, char **argv)
{
    if (argc < 4) {
        fprintf(stderr, "usage: cube_spectrum CUBE X Y [HALF]\n");
        return 2;
    }
    lm_api_error err;
    lm_api_cube *c = NULL;
    if (lm_api_cube_read(argv[1], NULL, &c, &err) != LM_API_OK) {
        fprintf(stderr, "cube_spectrum: %s\n", err.message);
        return 2;
    }
    int b = 0, h = 0, w = 0, x = atoi(argv[2]), y = atoi(argv[3]);
    int r = argc > 4 ? atoi(argv[4]) : 2;
    lm_api_cube_shape(c, &b, &h, &w, &err);
    const float *d = lm_api_cube_data(c), *wl = lm_api_cube_wavelengths(c);
    for (int k = 0; k < b; k++) {
        double s = 0;
        int n = 0;
        for (int yy = y - r; yy <= y + r; yy++)
            for (int xx = x - r; xx <= x + r; xx++)
                if (yy >= 0 && yy < h && xx >= 0 && xx < w) s += d[((size_t)k * h + yy) * w + xx], n++;
        printf("%g %g\n", wl[k], n ? s / n : 0.0);
    }
    lm_api_cube_free(c);
    return 0;
}

/* cube_psnr.c — prints the PSNR (dB) of a predicted cube against a ground-truth cube for the
 * end-to-end CLI tests (tests/cli/infer.sh): `cli_cube_psnr PRED TRUTH`, any format lm_cube_read
 * takes, same size and band count; both divided by the truth's maximum (system.md §10), PSNR
 * with peak 1 over all bands (data/metrics.h). What it is not: a test by itself. */
#include <stdio.h>
#include "data/cube_io.h"
#include "data/metrics.h"

int main(int argc, char **argv)
{
    if (argc != 3) {
        fprintf(stderr, "usage: cli_cube_psnr PRED TRUTH\n");
        return 2;
    }
    lm_cube p, t;
    lm_err e = {0};
    if (lm_cube_read(argv[1], &p, &e) || lm_cube_read(argv[2], &t, &e)) {
        fprintf(stderr, "cli_cube_psnr: %s\n", e.msg);
        return 2;
    }
    int rc = 0;
    if (p.bands != t.bands || p.height != t.height || p.width != t.width) {
        fprintf(stderr, "cli_cube_psnr: %dx%dx%d vs %dx%dx%d\n", p.bands, p.height, p.width,
                t.bands, t.height, t.width);
        rc = 2;
    } else {
        float mx = lm_cube_max(&t);
        long n = (long)t.bands * t.height * t.width;
        for (long i = 0; i < n && mx > 0; i++) {
            p.data[i] /= mx;
            t.data[i] /= mx;
        }
        printf("%.3f\n", lm_metric_psnr(p.data, t.data, t.bands, t.height, t.width, 0, t.bands));
    }
    lm_cube_free(&p);
    lm_cube_free(&t);
    return rc;
}

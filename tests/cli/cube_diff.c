/* cube_diff.c — prints the largest absolute difference between two cubes for the end-to-end
 * CLI tests (tests/cli/infer_opencl.sh): `cli_cube_diff A B`, any format lm_cube_read takes,
 * same size and band count; raw values, no normalisation. Exit 2 on unreadable or mismatched
 * cubes. What it is not: a test by itself. */
#include <math.h>
#include <stdio.h>
#include "data/cube_io.h"

int main(int argc, char **argv)
{
    if (argc != 3) {
        fprintf(stderr, "usage: cli_cube_diff A B\n");
        return 2;
    }
    lm_cube a, b;
    lm_err e = {0};
    if (lm_cube_read(argv[1], &a, &e) || lm_cube_read(argv[2], &b, &e)) {
        fprintf(stderr, "cli_cube_diff: %s\n", e.msg);
        return 2;
    }
    int rc = 0;
    if (a.bands != b.bands || a.height != b.height || a.width != b.width) {
        fprintf(stderr, "cli_cube_diff: %dx%dx%d vs %dx%dx%d\n", a.bands, a.height, a.width,
                b.bands, b.height, b.width);
        rc = 2;
    } else {
        double mx = 0.0;
        long n = (long)a.bands * a.height * a.width;
        for (long i = 0; i < n; i++) {
            double d = fabs((double)a.data[i] - b.data[i]);
            if (!(d <= mx)) mx = d; /* NaN propagates */
        }
        printf("%.9g\n", mx);
    }
    lm_cube_free(&a);
    lm_cube_free(&b);
    return rc;
}

/* fuzz_exr_cube.c — the spectral OpenEXR cube reader (data/io_exr.c, OpenEXR's C API): the
 * input is one .exr file; a failure must be one line naming it, a success a cube within the
 * limits with finite values >= 0. */
#include "tests/fuzz/fuzz_util.h"
#include "data/cube_io.h"
#include "data/limits.h"

/* A cube read successfully: sizes within the limits (its values were checked by the reader;
 * reading them all lets ASan see the buffer). */
static void check_cube(const lm_cube *c)
{
    double n = (double)c->bands * c->height * c->width, sum = 0.0;
    if (c->bands <= 0 || c->height <= 0 || c->width <= 0 || n > (double)LM_MAX_CUBE_VALUES)
        abort();
    for (size_t i = 0; i < (size_t)n; i++) sum += c->data[i];
    if (!(sum >= 0.0)) abort();
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char p[512];
    fz_write(p, "in.exr", data, size);
    lm_cube c;
    lm_err e = {LM_OK, ""};
    lm_status s = lm_cube_read_exr(p, &c, &e);
    fz_check(s, &e, p);
    if (s == LM_OK) {
        check_cube(&c);
        lm_cube_free(&c);
    }
    return 0;
}

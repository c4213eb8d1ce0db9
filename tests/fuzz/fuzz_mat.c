/* fuzz_mat.c — the MATLAB .mat cube reader (data/io_mat.c: the structure checks of
 * data/mat_check.c, then matio in a child process): the input is one .mat file; a failure must
 * be one line naming it, a success a 31-band cube within the limits (read onto the 31-band
 * grid, so the wavelength variable and the resampling are exercised too). Faults of libmatio or
 * libhdf5 happen in the child and come back as errors; libFuzzer sees no coverage from there
 * (it measures this process only), so this harness exercises the checks and the reply. */
#include "tests/fuzz/fuzz_util.h"
#include "data/cube_io.h"
#include "data/limits.h"

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char p[512];
    fz_write(p, "in.mat", data, size);
    lm_cube c;
    lm_err e = {LM_OK, ""};
    lm_cube_read_opts o;
    lm_cube_read_opts_default(&o);
    o.keep.count = 0; /* every success is 31 bands 400-700 nm */
    lm_status s = lm_cube_read_mat_with(p, &o, 1, &c, &e);
    fz_check(s, &e, p);
    if (s == LM_OK) {
        if (c.bands != LM_CAVE_BANDS || c.height <= 0 || c.width <= 0 ||
            (double)c.bands * c.height * c.width > (double)LM_MAX_CUBE_VALUES)
            abort();
        lm_cube_free(&c);
    }
    return 0;
}

/* fuzz_frame.c — the coded-frame reader (data/frames.c over the OpenImageIO shim): the input is
 * one file, named .png, .tif or .exr after its first bytes (else .png). It is read as a frame
 * and opened as a sequence of one; a failure must be one line naming the file, a success a
 * frame of the limits' size with finite values. */
#include "tests/fuzz/fuzz_util.h"
#include "data/frames.h"
#include "data/limits.h"
#include <math.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    char name[16], p[512];
    snprintf(name, sizeof name, "in%s", fz_image_ext(data, size, ".png"));
    fz_write(p, name, data, size);
    lm_frame f;
    lm_err e = {LM_OK, ""};
    lm_status s = lm_frame_read(p, &f, &e);
    fz_check(s, &e, p);
    if (s == LM_OK) {
        if (f.width <= 0 || f.height <= 0 || (long long)f.width * f.height > LM_MAX_FRAME_PIXELS)
            abort();
        for (long i = 0; i < (long)f.width * f.height; i++)
            if (!isfinite(f.data[i])) abort();
        lm_frame_free(&f);
    }
    lm_frame_seq q;
    lm_err_clear(&e);
    s = lm_frame_seq_open(p, &q, &e);
    fz_check(s, &e, p);
    if (s == LM_OK) lm_frame_seq_free(&q);
    return 0;
}

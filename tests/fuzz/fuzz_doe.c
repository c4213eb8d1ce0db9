/* fuzz_doe.c — the DOE description of the QDO baseline (data/doe.c): the input is the JSON text,
 * loaded as a file "fuzz.json" in the harness's folder (so a "height_map" profile's file
 * resolves there: h.png, a valid 3 x 3 16-bit map, is written beside it), and parsed from text.
 * A failure must be one line naming the label; a success must give a height map of the
 * aperture's size with every height finite and in [0, max_height). No PSF is computed (a
 * valid grid of 4096 would make each input cost seconds). */
#include "tests/fuzz/fuzz_util.h"
#include "data/doe.h"
#include "data/image.h"
#include <math.h>

static void check_ok(const lm_doe *d)
{
    if (!d->height || !d->mask || d->m < 1 || d->m > d->grid || !(d->max_height_m > 0)) abort();
    for (long k = 0; k < (long)d->m * d->m; k++)
        if (!(d->height[k] >= 0 && d->height[k] < d->max_height_m * 1.000001)) abort();
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    static int png_done;
    char path[512], png[512];
    if (!png_done) {
        float v[9] = {0, 0.125f, 0.25f, 0.5f, 0.75f, 0.875f, 1, 0.3f, 0.6f};
        lm_err pe = {LM_OK, ""};
        if (lm_image_write_gray16(fz_path(png, "h.png"), 3, 3, v, &pe)) abort();
        png_done = 1;
    }
    fz_write(path, "fuzz.json", data, size);
    lm_doe d;
    lm_err e = {LM_OK, ""};
    lm_status s = lm_doe_load(path, &d, &e);
    fz_check(s, &e, "fuzz.json");
    if (s == LM_OK) check_ok(&d);
    lm_doe_free(&d);
    char *text = malloc(size + 1);
    if (!text) abort();
    memcpy(text, data, size);
    text[size] = 0;
    lm_err e2 = {LM_OK, ""};
    s = lm_doe_parse(text, "fuzz.json", &d, &e2);
    fz_check(s, &e2, "fuzz.json");
    if (s == LM_OK) check_ok(&d);
    lm_doe_free(&d);
    free(text);
    return 0;
}

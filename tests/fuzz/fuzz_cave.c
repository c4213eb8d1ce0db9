/* fuzz_cave.c — the CAVE folder reader (data/io_cave.c over the OpenImageIO shim): a folder of
 * 31 valid 4 x 3 16-bit band PNGs in which the input replaces one band. The input's first byte
 * picks the band (mod 31); the rest is that band's file, named .png, or .tif after its first
 * bytes. A failure must be one line naming the folder, a success a 31-band cube. */
#include "tests/fuzz/fuzz_util.h"
#include "data/cube_io.h"
#include "data/image.h"
#include "data/limits.h"
#include <sys/stat.h>

static char scene[512];

/* The folder of valid bands, made once. */
static void make_scene(void)
{
    float v[12];
    for (int i = 0; i < 12; i++) v[i] = (float)i / 11.0f;
    mkdir(fz_path(scene, "scene"), 0755);
    for (int b = 1; b <= LM_CAVE_BANDS; b++) {
        char p[600];
        lm_err e = {LM_OK, ""};
        snprintf(p, sizeof p, "%s/scene_ms_%02d.png", scene, b);
        if (lm_image_write_gray16(p, 4, 3, v, &e) != LM_OK) {
            fprintf(stderr, "fuzz_cave: %s\n", e.msg);
            abort();
        }
    }
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (!scene[0]) make_scene();
    if (size < 1) return 0;
    int band = 1 + data[0] % LM_CAVE_BANDS;
    const char *ext = fz_image_ext(data + 1, size - 1, ".png");
    char png[600], mine[600], keep[600];
    snprintf(png, sizeof png, "%s/scene_ms_%02d.png", scene, band);
    snprintf(mine, sizeof mine, "%s/scene_ms_%02d%s", scene, band, ext);
    snprintf(keep, sizeof keep, "%s/keep.bin", fz_tmp());
    if (rename(png, keep) != 0) abort();
    FILE *f = fopen(mine, "wb");
    if (!f || (size > 1 && fwrite(data + 1, 1, size - 1, f) != size - 1) || fclose(f) != 0)
        abort();
    lm_cube c;
    lm_err e = {LM_OK, ""};
    lm_status s = lm_cube_read_cave(scene, &c, &e);
    fz_check(s, &e, scene);
    if (s == LM_OK) {
        if (c.bands != LM_CAVE_BANDS || c.height != 3 || c.width != 4) abort();
        lm_cube_free(&c);
    }
    if (remove(mine) != 0 || rename(keep, png) != 0) abort();
    return 0;
}

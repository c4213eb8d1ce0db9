/* test_raw.c — infer/raw.h: the gain remap. A frame simulated with the bundled system's gains
 * perturbed by up to +-30 % (or with another sub-frame allocation), rescaled per tile phase,
 * equals the frame of the bundled system; the given noise level is converted with the noise
 * factor; another tile map, another emission and a dark LED are refused by name. */
#include "tests/check.h"
#include "data/forward.h"
#include "data/spectra.h"
#include "data/synth.h"
#include "data/system.h"
#include "infer/raw.h"
#include "tensor/rng.h"
#include <stdlib.h>

static char *default_text(void)
{
    char path[1024];
    lm_err e = {0};
    if (lm_data_path("systems/default.json", path, sizeof path, &e)) return NULL;
    FILE *f = fopen(path, "rb");
    if (!f) return NULL;
    char *buf = calloc(1, 1 << 16);
    if (buf) buf[fread(buf, 1, (1 << 16) - 1, f)] = 0;
    fclose(f);
    return buf;
}

/* text with its first `from` replaced by `to` (a new string; NULL when absent). */
static char *replace(const char *text, const char *from, const char *to)
{
    const char *hit = text ? strstr(text, from) : NULL;
    CHECK_MSG(hit != NULL, "'%s' not in default.json", from);
    char *out = hit ? malloc(strlen(text) + strlen(to) + 1) : NULL;
    if (out) sprintf(out, "%.*s%s%s", (int)(hit - text), text, to, hit + strlen(from));
    return out;
}

/* The bundled system's text with each edit[2i] replaced by edit[2i + 1] (a NULL-ended
 * list), parsed (its CSV paths resolved). */
static lm_status variantv(const char *const *edit, lm_system *s, lm_err *e)
{
    char *text = default_text(), dir[1024];
    for (int i = 0; edit[i] && text; i += 2) {
        char *next = replace(text, edit[i], edit[i + 1]);
        free(text);
        text = next;
    }
    snprintf(dir, sizeof dir, "%s/systems", lm_data_dir());
    lm_err_clear(e);
    lm_status st = text ? lm_system_parse(text, dir, "variant", s, e) : LM_ERR_ARG;
    CHECK_MSG(st == LM_OK, "%s", e->msg);
    free(text);
    return st;
}

static lm_status variant(const char *from, const char *to, lm_system *s, lm_err *e)
{
    const char *edit[3] = {from, to, NULL};
    return variantv(edit, s, e);
}

/* The bundled gains times 1 + u, u uniform in [-spread, spread] (seeded), as a "gains" field. */
static void perturbed_gains(const lm_system *def, double spread, char *buf, size_t n)
{
    lm_rng r;
    lm_rng_seed(&r, 7);
    int k = snprintf(buf, n, "\"gains\": [");
    for (int l = 0; l < def->nleds; l++)
        k += snprintf(buf + k, n - k, "%s%.17g", l ? ", " : "",
                      def->leds[l].gain * (1.0 + 2.0 * spread * (lm_rng_uniform(&r) - 0.5)));
    snprintf(buf + k, n - k, "]");
}

/* Frames of the rainbow (H x W) through both systems, noise-free: the camera's remapped must
 * equal the model's. */
static void check_frames_map(const lm_system *model, const lm_system *cam, const lm_gain_remap *g)
{
    enum { H = 66, W = 64 };
    lm_cube cube;
    lm_err e = {0};
    if (lm_synth_rainbow(H, W, &cube, &e)) return;
    float *a = malloc(sizeof(float) * H * W), *b = malloc(sizeof(float) * H * W);
    lm_forward_opts fo;
    memset(&fo, 0, sizeof fo);
    fo.nthreads = 1;
    CHECK(lm_forward_simulate31(model, &cube, &fo, NULL, a, NULL, &e) == LM_OK);
    CHECK(lm_forward_simulate31(cam, &cube, &fo, NULL, b, NULL, &e) == LM_OK);
    float diff = 0.0f, amax = 0.0f, bmax = 0.0f;
    for (int i = 0; i < H * W; i++) diff = fmaxf(diff, fabsf(a[i] - b[i]) / (a[i] + 1e-3f));
    CHECK_MSG(diff > 0.05f, "the perturbed frame should differ (%g)", (double)diff);
    for (int i = 0; i < H * W; i++) bmax = fmaxf(bmax, b[i]);
    float k = lm_gain_remap_frame(g, b, 1, H, W, 0.1f, b); /* in place */
    CHECK_ARRAY_CLOSE(b, a, H * W, 1e-6, 1e-4);
    for (int i = 0; i < H * W; i++) amax = fmaxf(amax, b[i]);
    CHECK_CLOSE(k, 0.1 * bmax * g->noise_scale / amax, 0, 1e-5);
    CHECK(lm_gain_remap_frame(g, b, 1, H, W, -1.0f, b) == -1.0f);
    free(a);
    free(b);
    lm_cube_free(&cube);
}

static void test_perturbed_gains_map_back(void)
{
    lm_system def, cam;
    lm_err e = {0};
    if (lm_system_default(&def, &e)) {
        CHECK_MSG(0, "%s", e.msg);
        return;
    }
    char gains[2048];
    perturbed_gains(&def, 0.3, gains, sizeof gains);
    if (variant("\"gains\": \"equal_white\"", gains, &cam, &e)) {
        lm_system_free(&def);
        return;
    }
    lm_gain_remap g;
    CHECK_MSG(lm_gain_remap_init(&def, &cam, &g, &e) == LM_OK, "%s", e.msg);
    CHECK(g.active && g.ty == 3 && g.tx == 4);
    /* the brightest LED is full scale in both systems: the factors are >= 1 */
    CHECK(fabsf(g.min - 1.0f) < 1e-6f && g.max > 1.3f && g.noise_scale > 1.0f);
    double ss = 0.0;
    for (int t = 0; t < 12; t++) ss += (double)g.scale[t] * g.scale[t];
    CHECK_CLOSE(g.noise_scale, sqrt(ss / 12), 0, 1e-6);
    check_frames_map(&def, &cam, &g);
    lm_gain_remap same; /* a system onto itself: nothing to do */
    CHECK(lm_gain_remap_init(&def, &def, &same, &e) == LM_OK && !same.active);
    lm_system_free(&cam);
    lm_system_free(&def);
}

/* UV on for 18 sub-frames instead of 9 with the same gains: twice its light, the same
 * spectrum; UV is then the full-scale LED, every other LED half of it. */
static void test_other_allocation_maps_back(void)
{
    lm_system def, cam;
    lm_err e = {0};
    if (lm_system_default(&def, &e)) {
        CHECK_MSG(0, "%s", e.msg);
        return;
    }
    char gains[2048];
    perturbed_gains(&def, 0.0, gains, sizeof gains);
    const char *edit[] = {"{\"name\": \"UV\", \"subframes\": 9,", "{\"name\": \"UV\", \"subframes\": 18,",
                          "\"subframes_total\": 158", "\"subframes_total\": 167",
                          "\"gains\": \"equal_white\"", gains, NULL};
    if (variantv(edit, &cam, &e)) {
        lm_system_free(&def);
        return;
    }
    lm_gain_remap g;
    CHECK_MSG(lm_gain_remap_init(&def, &cam, &g, &e) == LM_OK, "%s", e.msg);
    int uv = lm_system_led_index(&def, "UV");
    for (int t = 0; t < 12; t++)
        CHECK_CLOSE(g.scale[t], def.tile_led[t] == uv ? 1.0 : 2.0, 1e-5, 0);
    check_frames_map(&def, &cam, &g);
    lm_system_free(&cam);
    lm_system_free(&def);
}

static void test_refusals(void)
{
    lm_system def, cam;
    lm_err e = {0};
    if (lm_system_default(&def, &e)) {
        CHECK_MSG(0, "%s", e.msg);
        return;
    }
    lm_gain_remap g;
    if (!variant("[\"FarRed\", \"Green\",  \"DeepRed\",   \"RoyalBlue\"]",
                 "[\"Green\", \"FarRed\",  \"DeepRed\",   \"RoyalBlue\"]", &cam, &e)) {
        CHECK(lm_gain_remap_init(&def, &cam, &g, &e) == LM_ERR_ARG && !g.active);
        CHECK_MSG(strstr(e.msg, "another tile map: position (0, 0) holds Green"), "%s", e.msg);
        lm_system_free(&cam);
    }
    if (!variant("\"column\": \"Cyan\"}", "\"column\": \"Blue\"}", &cam, &e)) {
        CHECK(lm_gain_remap_init(&def, &cam, &g, &e) == LM_ERR_ARG);
        CHECK_MSG(strstr(e.msg, "LED 'Cyan' has another emission"), "%s", e.msg);
        lm_system_free(&cam);
    }
    if (!variant("\"gains\": \"equal_white\"",
                 "\"gains\": [1, 1, 1, 1, 1, 1, 1, 0, 1, 1, 1, 1]", &cam, &e)) {
        CHECK(lm_gain_remap_init(&def, &cam, &g, &e) == LM_ERR_ARG);
        CHECK_MSG(strstr(e.msg, "LED 'Amber' has no response"), "%s", e.msg);
        lm_system_free(&cam);
    }
    lm_system_free(&def);
}

int main(void)
{
    RUN(test_perturbed_gains_map_back);
    RUN(test_other_allocation_maps_back);
    RUN(test_refusals);
    return check_summary();
}

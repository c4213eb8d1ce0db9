/* test_raw.c — infer/raw.h. The gain remap: a frame simulated with the bundled system's gains
 * perturbed by up to +-30 % (or with another sub-frame allocation), rescaled per tile phase,
 * equals the frame of the bundled system; the given noise level is converted with the noise
 * factor; another tile map, another emission and a dark LED are refused by name. The raw-frame
 * conventions on synthetic 16-bit PNG files: 12-bit data LSB- and MSB-aligned (and the wrong
 * alignment refused), a black level, averaged dark frames, a flat with per-pixel gains (a dead
 * pixel left), saturated pixels counted and masked. */
#include "tests/check.h"
#include "data/forward.h"
#include "data/spectra.h"
#include "data/synth.h"
#include "data/system.h"
#include "infer/raw.h"
#include "tensor/rng.h"
#include <stdlib.h>
#include <sys/stat.h>
#include <unistd.h>

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

/* ---- raw-frame conventions ------------------------------------------------------------ */
enum { RH = 24, RW = 32 };
static char tmpdir[64];

/* A 16-bit PNG holding the codes c[i] (0..65535) at tmpdir/name; its path in path. */
static void write_codes(const char *name, const double *c, char *path, size_t n)
{
    float v[RH * RW];
    for (int i = 0; i < RH * RW; i++) v[i] = (float)(c[i] / 65535.0);
    snprintf(path, n, "%s/%s", tmpdir, name);
    lm_err e = {0};
    CHECK_MSG(lm_frame_write(path, RH, RW, v, &e) == LM_OK, "%s", e.msg);
}

/* The scene: values in [0.05, 0.95], varied per pixel. */
static double scene(int i) { return 0.05 + 0.9 * ((i * 37) % 101) / 100.0; }

/* Read path and convert it with o; out gets the frame (RH x RW). */
static lm_status convert(const lm_raw_opts *o, const char *path, float *out, lm_err *e)
{
    lm_raw r;
    lm_frame f;
    lm_err_clear(e);
    lm_status st = lm_raw_init(&r, o, RH, RW, 3, 4, e);
    if (st) return st;
    st = lm_frame_read(path, &f, e);
    if (!st) {
        st = lm_raw_apply(&r, &f, path, e);
        if (!st) memcpy(out, f.data, sizeof(float) * RH * RW);
        lm_frame_free(&f);
    }
    lm_raw_free(&r);
    return st;
}

static void test_bits_alignment_and_saturation(void)
{
    double lsb[RH * RW], msb[RH * RW];
    float want[RH * RW], got[RH * RW];
    for (int i = 0; i < RH * RW; i++) {
        lsb[i] = floor(scene(i) * 4095 + 0.5);
        if (i % 97 == 5) lsb[i] = 4095; /* saturated */
        msb[i] = lsb[i] * 16;
        want[i] = (float)(lsb[i] / 4095);
    }
    char pl[256], pm[256];
    write_codes("lsb.png", lsb, pl, sizeof pl);
    write_codes("msb.png", msb, pm, sizeof pm);
    lm_err e;
    lm_raw_opts o = {.bits = 12};
    CHECK_MSG(convert(&o, pl, got, &e) == LM_OK, "%s", e.msg);
    CHECK_ARRAY_CLOSE(got, want, RH * RW, 1e-6, 0);
    CHECK(convert(&o, pm, got, &e) == LM_ERR_FORMAT && strstr(e.msg, "add --msb"));
    o.msb = 1;
    CHECK_MSG(convert(&o, pm, got, &e) == LM_OK, "%s", e.msg);
    CHECK_ARRAY_CLOSE(got, want, RH * RW, 1e-6, 0);
    CHECK(convert(&o, pl, got, &e) == LM_ERR_FORMAT && strstr(e.msg, "drop --msb"));
    lm_frame f;
    lm_err_clear(&e);
    if (lm_frame_read(pm, &f, &e) == LM_OK) {
        uint8_t mask[RH * RW];
        int k = 0, ok = 1;
        for (int i = 0; i < RH * RW; i++) k += i % 97 == 5;
        CHECK_CLOSE(lm_raw_saturated(&o, &f, mask), (double)k / (RH * RW), 1e-12, 0);
        for (int i = 0; i < RH * RW; i++) ok &= mask[i] == (i % 97 == 5);
        CHECK(ok);
        lm_raw_opts plain = {0}; /* as 16-bit data nothing reaches 65535 */
        CHECK(lm_raw_saturated(&plain, &f, NULL) == 0.0);
        lm_frame_free(&f);
    }
    lm_raw r;
    lm_raw_opts bad = {.bits = 12, .black = 4095};
    CHECK(lm_raw_init(&r, &bad, RH, RW, 3, 4, &e) == LM_ERR_ARG);
}

static void test_black_dark_flat(void)
{
    double c[RH * RW], d1[RH * RW], d2[RH * RW], fl[RH * RW];
    float want[RH * RW], got[RH * RW];
    double dmean = 0.0;
    for (int i = 0; i < RH * RW; i++) {
        int y = i / RW, x = i % RW;
        double d = 2000.0 + 50.0 * (x % 5) + 30.0 * (y % 7); /* codes of 16 bits */
        d1[i] = d - 100, d2[i] = d + 100;
        dmean += d / 65535.0;
        want[i] = (float)scene(i);
    }
    dmean /= RH * RW;
    char p[256], pd1[256], pd2[256], pf[256], pat[300];
    lm_err e;
    /* black level 256 in 12-bit codes */
    for (int i = 0; i < RH * RW; i++) c[i] = floor(256 + scene(i) * (4095 - 256) + 0.5);
    write_codes("black.png", c, p, sizeof p);
    lm_raw_opts o = {.bits = 12, .black = 256};
    CHECK_MSG(convert(&o, p, got, &e) == LM_OK, "%s", e.msg);
    CHECK_ARRAY_CLOSE(got, want, RH * RW, 0.6 / (4095 - 256), 0);
    /* dark frames: two, averaged */
    for (int i = 0; i < RH * RW; i++)
        c[i] = floor(65535.0 * (0.5 * (d1[i] + d2[i]) / 65535.0 + scene(i) * (1 - dmean)) + 0.5);
    write_codes("dark_frame.png", c, p, sizeof p);
    mkdir(strcat(strcpy(pat, tmpdir), "/dark"), 0700);
    write_codes("dark/d_0001.png", d1, pd1, sizeof pd1);
    write_codes("dark/d_0002.png", d2, pd2, sizeof pd2);
    lm_raw_opts od = {.dark = pat};
    CHECK_MSG(convert(&od, p, got, &e) == LM_OK, "%s", e.msg);
    CHECK_ARRAY_CLOSE(got, want, RH * RW, 1.0 / 65535, 0);
    /* a flat: per-pixel gains 1 +- 0.2 (mean 1 over each tile phase), a white target at 0.8 */
    for (int i = 0; i < RH * RW; i++) {
        int y = i / RW, x = i % RW;
        double g = (x + y) % 2 ? 1.2 : 0.8;
        fl[i] = floor(65535.0 * 0.8 * g + 0.5);
        c[i] = floor(65535.0 * 0.8 * scene(i) * g + 0.5); /* below full scale */
    }
    fl[7 * RW + 9] = 0; /* a dead pixel: left as it is */
    c[7 * RW + 9] = floor(65535.0 * 0.8 * scene(7 * RW + 9) + 0.5);
    write_codes("flat.png", fl, pf, sizeof pf);
    write_codes("flat_frame.png", c, p, sizeof p);
    lm_raw_opts of = {.flat = pf};
    lm_raw r;
    lm_err_clear(&e);
    CHECK_MSG(lm_raw_init(&r, &of, RH, RW, 3, 4, &e) == LM_OK, "%s", e.msg);
    CHECK(r.flat_skipped == 1);
    lm_raw_free(&r);
    CHECK_MSG(convert(&of, p, got, &e) == LM_OK, "%s", e.msg);
    /* the dead pixel (gain 0.8) is missing from its phase's mean, 64 pixels of mean gain 1:
     * that phase's pixels read (1 - 0.8 / 64) of the scene */
    for (int i = 0; i < RH * RW; i++) want[i] = (float)(0.8 * scene(i));
    int bad = 0;
    for (int i = 0; i < RH * RW; i++) {
        int y = i / RW, x = i % RW;
        double k = (y % 3 == 7 % 3 && x % 4 == 9 % 4) ? 1.0 - 0.8 / 64 : 1.0;
        if (i == 7 * RW + 9) k = 1.0;
        if (fabs(got[i] - want[i] * k) > 2e-4 && bad++ < 3)
            fprintf(stderr, "(%d, %d): %g, want %g\n", y, x, got[i], want[i] * k);
    }
    CHECK_MSG(bad == 0, "%d pixels off", bad);
    /* refused: both black and dark; a dark frame of another size; an unlit flat */
    lm_raw_opts both = {.black = 10, .dark = pat};
    CHECK(lm_raw_init(&r, &both, RH, RW, 3, 4, &e) == LM_ERR_ARG);
    CHECK(lm_raw_init(&r, &od, RH, RW + 4, 3, 4, &e) == LM_ERR_SHAPE && strstr(e.msg, "dark"));
    for (int i = 0; i < RH * RW; i++) fl[i] = (i % RW) % 4 == 1 ? 0 : 30000;
    write_codes("unlit.png", fl, pf, sizeof pf);
    lm_raw_opts ou = {.flat = pf};
    lm_err_clear(&e);
    CHECK(lm_raw_init(&r, &ou, RH, RW, 3, 4, &e) == LM_ERR_ARG && strstr(e.msg, "no signal"));
}

int main(void)
{
    snprintf(tmpdir, sizeof tmpdir, "/tmp/lm_test_raw_XXXXXX");
    if (!mkdtemp(tmpdir)) return 1;
    RUN(test_perturbed_gains_map_back);
    RUN(test_other_allocation_maps_back);
    RUN(test_refusals);
    RUN(test_bits_alignment_and_saturation);
    RUN(test_black_dark_flat);
    char cmd[128];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", tmpdir);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", tmpdir);
    return check_summary();
}

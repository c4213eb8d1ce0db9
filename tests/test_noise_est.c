/* test_noise_est.c — the blind noise estimate of a raw coded frame (data/noise_est.h).
 * Bad input (NULL, tile < 1, size not a multiple of the tile, phases under 3 x 3, NaN/inf) fails
 * with the documented status, and the float wrappers return it negated; a constant frame reads
 * sigma 0, an all-zero one has no level; white Gaussian noise on a ramp is read without bias at
 * 66 x 64 .. 480 x 640 for 3 x 4, 4 x 4 and 1 x 1 tiles, the same on a second call; frames
 * simulated from the 3 CAVE scenes of $LM_SHARED_DIR/data/cave (cropped to the tile grid, noise
 * from lm_forward_noise with gauss_k = k, 3 draws) read sigma and the level k within 20 % for
 * every k in {1, 2.5, 5, 10, 15, 20} %, and their clean frames a level under 0.005; every
 * 66 x 64 crop of them gets an estimate, within 25 % from k = 10 % (errors printed). Prints the
 * time per 640 x 480 frame (not asserted).
 * Report mode (not run by CTest): `test_noise_est --report [--seeds N] [dir ...]` prints, for
 * every CAVE scene folder in the dirs (default $LM_SHARED_DIR/data/cave and .../cave-256), the
 * worst signed error of sigma and of the level over N seeds per k, then the worst |error| per k
 * over all scenes. */
#include <dirent.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "tests/check.h"
#include "tests/shared_dir.h"
#include "data/cube_io.h"
#include "data/forward.h"
#include "data/noise_est.h"

#define NK 6
static const float g_ks[NK] = {0.01f, 0.025f, 0.05f, 0.1f, 0.15f, 0.2f};
static lm_system g_sys;
static int g_ok;
#define TH (g_sys.tile_rows) /* the default system's 3 x 4 tile */
#define TW (g_sys.tile_cols)


/* A CAVE scene's noise-free coded frame (default system), cropped at the top-left to the tile
 * grid. Returns NULL (and reports) on failure. */
static float *cave_frame(const char *dir, int *h, int *w)
{
    lm_cube c;
    lm_err e;
    lm_err_clear(&e);
    if (lm_cube_read(dir, &c, &e) != LM_OK) {
        CHECK_MSG(0, "%s", e.msg);
        return NULL;
    }
    float *full = malloc(sizeof(float) * c.height * c.width);
    lm_forward_opts o = {0};
    o.nthreads = 1;
    lm_status s = lm_forward_simulate31(&g_sys, &c, &o, NULL, full, NULL, &e);
    CHECK_MSG(s == LM_OK, "%s", e.msg);
    *h = c.height / TH * TH, *w = c.width / TW * TW;
    for (int y = 0; s == LM_OK && y < *h; y++)
        memmove(full + (long)y * *w, full + (long)y * c.width, sizeof(float) * *w);
    lm_cube_free(&c);
    if (s != LM_OK) free(full);
    return s == LM_OK ? full : NULL;
}

static float frame_max(const float *f, long n)
{
    float m = f[0];
    for (long i = 1; i < n; i++) m = f[i] > m ? f[i] : m;
    return m;
}

/* out = clean + the paper's noise at level k (sigma = k * max clean value). */
static void add_noise(const float *clean, float *out, int h, int w, float k, uint64_t seed)
{
    memcpy(out, clean, sizeof(float) * h * w);
    lm_noise_opts o = {0};
    o.gauss_k = k;
    lm_rng r;
    lm_rng_seed(&r, seed);
    lm_err e;
    CHECK_MSG(lm_forward_noise(out, h, w, &o, &r, 1, &e) == LM_OK, "%s", e.msg);
}

/* ---- input checks ---------------------------------------------------------------------- */

static void test_bad_input(void)
{
    float buf[24 * 24];
    for (int i = 0; i < 24 * 24; i++) buf[i] = (float)(i % 7) * 0.1f;
    lm_noise_info info;
    lm_err e;
    lm_err_clear(&e);
    CHECK(lm_noise_analyze(NULL, 24, 24, 3, 4, &info, &e) == LM_ERR_ARG && strstr(e.msg, "noise:"));
    CHECK(lm_noise_analyze(buf, 24, 24, 3, 4, NULL, NULL) == LM_ERR_ARG);
    CHECK(lm_noise_analyze(buf, 24, 24, 0, 4, &info, NULL) == LM_ERR_ARG);
    lm_err_clear(&e);
    CHECK(lm_noise_analyze(buf, 22, 24, 3, 4, &info, &e) == LM_ERR_SHAPE &&
          strstr(e.msg, "22 x 24") && strstr(e.msg, "multiple"));
    CHECK(lm_noise_analyze(buf, 24, 22, 3, 4, &info, NULL) == LM_ERR_SHAPE);
    CHECK(lm_noise_analyze(buf, -3, 24, 3, 4, &info, NULL) == LM_ERR_SHAPE);
    lm_err_clear(&e);
    CHECK(lm_noise_analyze(buf, 6, 24, 3, 4, &info, &e) == LM_ERR_SHAPE && strstr(e.msg, "small"));
    CHECK(lm_noise_analyze(buf, 9, 12, 3, 4, &info, NULL) == LM_OK); /* the smallest frame */
    CHECK(lm_noise_estimate(NULL, 24, 24, 3, 4) == (float)LM_ERR_ARG);
    CHECK(lm_noise_estimate(buf, 22, 24, 3, 4) == (float)LM_ERR_SHAPE);
    CHECK(lm_noise_level(buf, 24, 24, 3, 0) == (float)LM_ERR_ARG);
    CHECK(lm_noise_level(buf, 6, 8, 3, 4) == (float)LM_ERR_SHAPE);
    buf[2 * 24 + 5] = NAN;
    lm_err_clear(&e);
    CHECK(lm_noise_analyze(buf, 24, 24, 3, 4, &info, &e) == LM_ERR_NUMERIC &&
          strstr(e.msg, "x=5, y=2"));
    buf[2 * 24 + 5] = INFINITY;
    CHECK(lm_noise_estimate(buf, 24, 24, 3, 4) == (float)LM_ERR_NUMERIC);
}

static void test_constant_and_zero(void)
{
    float buf[12 * 16];
    for (int i = 0; i < 12 * 16; i++) buf[i] = 0.25f;
    lm_noise_info info;
    CHECK(lm_noise_analyze(buf, 12, 16, 3, 4, &info, NULL) == LM_OK);
    CHECK(info.sigma == 0 && info.peak == 0.25f && info.level == 0);
    memset(buf, 0, sizeof buf);
    lm_err e;
    lm_err_clear(&e);
    CHECK(lm_noise_analyze(buf, 12, 16, 3, 4, &info, &e) == LM_ERR_NUMERIC &&
          strstr(e.msg, "no positive signal"));
    CHECK(lm_noise_estimate(buf, 12, 16, 3, 4) == 0.0f);
    CHECK(lm_noise_level(buf, 12, 16, 3, 4) == (float)LM_ERR_NUMERIC);
}

/* ---- pure noise ------------------------------------------------------------------------ */

/* sigma 0.02 on a ramp 0.5 .. 0.8 (the mask cancels the ramp exactly): unbiased at every size
 * and tile (200 seeds measured: 66 x 64 reads 0.89 .. 1.07, 480 x 640 0.99 .. 1.01). */
static void test_pure_noise_sizes(void)
{
    const int sizes[4][2] = {{66, 64}, {99, 100}, {240, 320}, {480, 640}};
    const int tiles[3][2] = {{3, 4}, {4, 4}, {1, 1}};
    const double tol[4] = {0.15, 0.15, 0.06, 0.03};
    lm_rng r;
    lm_rng_seed(&r, 11);
    for (int t = 0; t < 3; t++)
        for (int s = 0; s < 4; s++) {
            int th = tiles[t][0], tw = tiles[t][1];
            int h = sizes[s][0] / th * th, w = sizes[s][1] / tw * tw;
            float *a = malloc(sizeof(float) * h * w);
            for (int y = 0; y < h; y++)
                for (int x = 0; x < w; x++)
                    a[y * w + x] = 0.5f + 0.3f * y / h + 0.02f * lm_rng_normal(&r);
            float s1 = lm_noise_estimate(a, h, w, th, tw), s2 = lm_noise_estimate(a, h, w, th, tw);
            CHECK_MSG(fabs(s1 / 0.02 - 1) < tol[s], "tile %dx%d, %dx%d: sigma %g, want 0.02", th,
                      tw, h, w, s1);
            CHECK(s1 == s2);
            /* the caller's scratch, dirty from another frame, gives the same number (and that
             * path runs on one thread, the other on the OpenMP default: the same bits) */
            size_t nb = lm_noise_scratch_bytes(w);
            unsigned char *scr = malloc(nb);
            memset(scr, 0xA5, nb);
            CHECK(lm_noise_estimate_scratch(a, h, w, th, tw, scr) == s1);
            CHECK(lm_noise_estimate_scratch(a, h, w, th, tw, scr) == s1);
            free(scr);
            free(a);
        }
}

/* One uniform patch with noise at k = 10 %: a frame that is all plateau reads the peak high
 * (measured level / k 0.85 .. 0.93 at 240 x 320 over 200 seeds). */
static void test_uniform_level(void)
{
    const int h = 240, w = 320;
    float *a = malloc(sizeof(float) * h * w);
    lm_rng r;
    lm_rng_seed(&r, 5);
    for (int i = 0; i < h * w; i++) a[i] = 0.5f + 0.05f * lm_rng_normal(&r);
    float k = lm_noise_level(a, h, w, 3, 4);
    CHECK_MSG(fabs(k / 0.1 - 1) < 0.2, "uniform patch: level %g, want 0.1", k);
    free(a);
}

/* ---- CAVE scenes ----------------------------------------------------------------------- */

typedef struct scene_frame {
    char name[256];
    float *clean;
    int h, w;
    float max;
} scene_frame;

static int cmp_name(const void *a, const void *b) { return strcmp(a, b); }

/* The scene folders in dir, sorted by name; returns how many were loaded (at most cap). */
static int load_scenes(const char *dir, scene_frame *out, int cap)
{
    DIR *d = opendir(dir);
    CHECK_MSG(d != NULL, "cannot open %s", dir);
    if (!d) return 0;
    char names[64][256];
    int n = 0;
    for (struct dirent *de; (de = readdir(d)) && n < 64;) {
        char p[1024];
        snprintf(p, sizeof p, "%s/%s", dir, de->d_name);
        if (de->d_name[0] != '.' && lm_cube_detect(p) == LM_CUBE_FMT_CAVE)
            snprintf(names[n++], sizeof names[0], "%s", de->d_name);
    }
    closedir(d);
    qsort(names, n, sizeof names[0], cmp_name);
    int got = 0;
    for (int i = 0; i < n && got < cap; i++) {
        char p[1024];
        snprintf(p, sizeof p, "%s/%s", dir, names[i]);
        scene_frame *s = &out[got];
        s->clean = cave_frame(p, &s->h, &s->w);
        if (!s->clean) continue;
        snprintf(s->name, sizeof s->name, "%s", names[i]);
        s->max = frame_max(s->clean, (long)s->h * s->w);
        got++;
    }
    return got;
}

static void free_scenes(scene_frame *s, int n)
{
    for (int i = 0; i < n; i++) free(s[i].clean);
}

/* Worst signed relative errors of sigma and level over `seeds` noise draws at level k. */
static void scene_errors(const scene_frame *s, float k, int seeds, float *buf, double *es,
                         double *el)
{
    *es = *el = 0;
    for (int r = 0; r < seeds; r++) {
        add_noise(s->clean, buf, s->h, s->w, k, 1000 + 17 * r);
        lm_noise_info info;
        lm_err e;
        lm_err_clear(&e);
        lm_status st = lm_noise_analyze(buf, s->h, s->w, TH, TW, &info, &e);
        CHECK_MSG(st == LM_OK, "%s: %s", s->name, e.msg);
        double a = info.sigma / (k * s->max) - 1, b = info.level / k - 1;
        *es = fabs(a) > fabs(*es) ? a : *es;
        *el = fabs(b) > fabs(*el) ? b : *el;
    }
}

static void test_cave_levels(void)
{
    if (!g_ok) return;
    char dir[1024];
    snprintf(dir, sizeof dir, "%s/data/cave", shared_dir());
    scene_frame sc[8];
    int n = load_scenes(dir, sc, 8);
    CHECK_MSG(n == 3, "%d CAVE scenes in %s, expected 3", n, dir);
    printf("     sigma / level relative error (worst of 3 draws) at k = 1 .. 20 %%\n");
    for (int i = 0; i < n; i++) {
        float *buf = malloc(sizeof(float) * sc[i].h * sc[i].w);
        float k0 = lm_noise_level(sc[i].clean, sc[i].h, sc[i].w, TH, TW);
        CHECK_MSG(k0 >= 0 && k0 < 0.005f, "%s clean: level %g", sc[i].name, k0);
        printf("     %-30s clean %.4f", sc[i].name, k0);
        for (int j = 0; j < NK; j++) {
            double es, el;
            scene_errors(&sc[i], g_ks[j], 3, buf, &es, &el);
            CHECK_MSG(fabs(es) < 0.2 && fabs(el) < 0.2, "%s k=%g: sigma %+.3f level %+.3f",
                      sc[i].name, g_ks[j], es, el);
            printf(" %+.2f/%+.2f", es, el);
        }
        printf("\n");
        free(buf);
    }
    free_scenes(sc, n);
}

/* Frames as a 16-bit PNG holds them: noise, then clipped at 0 (and at the full scale 1.0 of
 * the frame's units) and quantised to 16 bits. Near the floor the noise is cut, which the
 * estimator must not read as less noise: within 25 % of the true sigma from k = 2.5 % (measured
 * <= 16 % over all 27 shared scenes, one draw; 23 % at k = 1 %, printed). */
static void test_cave_clipped(void)
{
    if (!g_ok) return;
    char dir[1024];
    snprintf(dir, sizeof dir, "%s/data/cave", shared_dir());
    scene_frame sc[8];
    int n = load_scenes(dir, sc, 8);
    printf("     clipped + 16-bit: sigma relative error at k = 1 .. 20 %%\n");
    for (int i = 0; i < n; i++) {
        float *buf = malloc(sizeof(float) * sc[i].h * sc[i].w);
        printf("     %-30s", sc[i].name);
        for (int j = 0; j < NK; j++) {
            memcpy(buf, sc[i].clean, sizeof(float) * sc[i].h * sc[i].w);
            lm_noise_opts o = {0};
            o.gauss_k = g_ks[j];
            o.clip = 1;
            o.bits = 16;
            o.full_scale = sc[i].max > 1.0f ? sc[i].max : 1.0f;
            lm_rng r;
            lm_rng_seed(&r, 77 + j);
            lm_err e;
            CHECK_MSG(lm_forward_noise(buf, sc[i].h, sc[i].w, &o, &r, 1, &e) == LM_OK, "%s", e.msg);
            double es = lm_noise_estimate(buf, sc[i].h, sc[i].w, TH, TW) / (g_ks[j] * sc[i].max) - 1;
            if (g_ks[j] >= 0.025f)
                CHECK_MSG(fabs(es) < 0.25, "%s clipped k=%g: sigma %+.3f", sc[i].name, g_ks[j], es);
            printf(" %+.2f", es);
        }
        printf("\n");
        free(buf);
    }
    free_scenes(sc, n);
}

/* The smallest frames the brief asks for: 66 x 64 crops (on the tile grid) of the CAVE frames,
 * each with noise at k x its own maximum. Every crop gets a finite positive estimate, within 25 %
 * from k = 10 % (measured <= 16 %); the error is printed per k: small crops with little flat area
 * read high at low k (texture finer than the mosaic looks like noise). */
static void test_cave_small_crops(void)
{
    if (!g_ok) return;
    char dir[1024];
    snprintf(dir, sizeof dir, "%s/data/cave", shared_dir());
    scene_frame sc[8];
    int n = load_scenes(dir, sc, 8), ncrops = 0;
    const int ch = 66, cw = 64;
    float *crop = malloc(sizeof(float) * ch * cw), *buf = malloc(sizeof(float) * ch * cw);
    double worst[NK] = {0};
    for (int i = 0; i < n; i++)
        for (int y0 = 0; y0 + ch <= sc[i].h; y0 += 33)
            for (int x0 = 0; x0 + cw <= sc[i].w; x0 += 64, ncrops++) {
                for (int y = 0; y < ch; y++)
                    memcpy(crop + y * cw, sc[i].clean + (long)(y0 + y) * sc[i].w + x0,
                           sizeof(float) * cw);
                scene_frame s = {.clean = crop, .h = ch, .w = cw, .max = frame_max(crop, ch * cw)};
                snprintf(s.name, sizeof s.name, "%.200s@%d,%d", sc[i].name, y0, x0);
                for (int j = 0; j < NK; j++) {
                    double es, el;
                    scene_errors(&s, g_ks[j], 1, buf, &es, &el);
                    CHECK_MSG(es > -1 && isfinite(es), "%s k=%g: sigma %+.3f", s.name, g_ks[j], es);
                    if (g_ks[j] >= 0.1f)
                        CHECK_MSG(fabs(es) < 0.25, "%s k=%g: sigma %+.3f", s.name, g_ks[j], es);
                    worst[j] = fmax(worst[j], fabs(es));
                }
            }
    printf("     %d crops of 66 x 64, worst |sigma error| at k = 1 .. 20 %%:", ncrops);
    for (int j = 0; j < NK; j++) printf(" %.2f", worst[j]);
    printf("\n");
    free(crop);
    free(buf);
    free_scenes(sc, n);
}

/* Not asserted: the machine is shared. A 640 x 480 frame tiled from a CAVE frame (periods that
 * are multiples of the tile keep the mosaic). */
static double time_frame_ms(const scene_frame *s)
{
    const int h = 480, w = 640;
    float *big = malloc(sizeof(float) * h * w), *buf = malloc(sizeof(float) * h * w);
    int ph = s->h / TH * TH, pw = s->w / TW * TW;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) big[y * w + x] = s->clean[(long)(y % ph) * s->w + x % pw];
    scene_frame t = {.clean = big, .h = h, .w = w, .max = frame_max(big, (long)h * w)};
    add_noise(t.clean, buf, h, w, 0.05f, 3);
    double best = 1e30;
    for (int r = 0; r < 20; r++) {
        struct timespec t0, t1;
        clock_gettime(CLOCK_MONOTONIC, &t0);
        volatile float v = lm_noise_level(buf, h, w, TH, TW);
        (void)v;
        clock_gettime(CLOCK_MONOTONIC, &t1);
        best = fmin(best, (t1.tv_sec - t0.tv_sec) * 1e3 + (t1.tv_nsec - t0.tv_nsec) * 1e-6);
    }
    free(big);
    free(buf);
    return best;
}

static void test_timing(void)
{
    if (!g_ok) return;
    char dir[1024];
    snprintf(dir, sizeof dir, "%s/data/cave", shared_dir());
    scene_frame sc[8];
    int n = load_scenes(dir, sc, 8);
    if (n) printf("     640 x 480 frame: %.2f ms (best of 20)\n", time_frame_ms(&sc[n - 1]));
    free_scenes(sc, n);
}

/* ---- report mode ----------------------------------------------------------------------- */

static void report_dir(const char *dir, int seeds, double *worst_s, double *worst_l, int *count)
{
    static scene_frame sc[64];
    int n = load_scenes(dir, sc, 64);
    for (int i = 0; i < n; i++) {
        float *buf = malloc(sizeof(float) * sc[i].h * sc[i].w);
        printf("%-34s %3dx%-3d %.4f", sc[i].name, sc[i].h, sc[i].w,
               lm_noise_level(sc[i].clean, sc[i].h, sc[i].w, TH, TW));
        for (int j = 0; j < NK; j++) {
            double es, el;
            scene_errors(&sc[i], g_ks[j], seeds, buf, &es, &el);
            printf(" %+.2f/%+.2f", es, el);
            worst_s[j] = fmax(worst_s[j], fabs(es));
            worst_l[j] = fmax(worst_l[j], fabs(el));
        }
        printf("\n");
        free(buf);
    }
    if (n) printf("%-34s 640x480 %.2f ms per frame\n", "(timing)", time_frame_ms(&sc[0]));
    *count += n;
    free_scenes(sc, n);
}

static int report(int argc, char **argv)
{
    int seeds = 3, ndirs = 0;
    const char *dirs[16];
    for (int i = 0; i < argc; i++) {
        if (!strcmp(argv[i], "--seeds") && i + 1 < argc) seeds = atoi(argv[++i]);
        else if (ndirs < 16) dirs[ndirs++] = argv[i];
    }
    static char d0[1024], d1[1024];
    if (!ndirs) {
        snprintf(d0, sizeof d0, "%s/data/cave", shared_dir());
        snprintf(d1, sizeof d1, "%s/data/cave-256", shared_dir());
        dirs[ndirs++] = d0, dirs[ndirs++] = d1;
    }
    double ws[NK] = {0}, wl[NK] = {0};
    int count = 0;
    printf("%-34s %-7s %-6s sigma/level error (worst of %d seeds) at k =", "scene", "size",
           "clean", seeds);
    for (int j = 0; j < NK; j++) printf(" %g", g_ks[j]);
    printf("\n");
    for (int i = 0; i < ndirs; i++) report_dir(dirs[i], seeds, ws, wl, &count);
    printf("worst |error| over %d scenes, k:    ", count);
    for (int j = 0; j < NK; j++) printf(" %9g", g_ks[j]);
    printf("\n%-38s", "  sigma");
    for (int j = 0; j < NK; j++) printf(" %9.3f", ws[j]);
    printf("\n%-38s", "  level");
    for (int j = 0; j < NK; j++) printf(" %9.3f", wl[j]);
    printf("\n");
    return check_summary();
}

int main(int argc, char **argv)
{
    lm_err e;
    lm_err_clear(&e);
    g_ok = lm_system_default(&g_sys, &e) == LM_OK;
    CHECK_MSG(g_ok, "default system: %s", e.msg);
    if (argc > 1 && !strcmp(argv[1], "--report")) {
        int rc = report(argc - 2, argv + 2);
        lm_system_free(&g_sys);
        return rc;
    }
    RUN(test_bad_input);
    RUN(test_constant_and_zero);
    RUN(test_pure_noise_sizes);
    RUN(test_uniform_level);
    RUN(test_cave_levels);
    RUN(test_cave_clipped);
    RUN(test_cave_small_crops);
    RUN(test_timing);
    lm_system_free(&g_sys);
    return check_summary();
}

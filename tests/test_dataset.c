/* test_dataset.c — the sampler (data/dataset.h): split by scene group (group keys, groups
 * never split, exact quotas, determinism, disjoint lists, at most boundary groups move when
 * scenes are added, the real 27-scene split, borrowing below 3 scenes), tile-aligned patches
 * (a fixture whose values encode the position: the target tells where the patch came from and
 * the raw equals lm_forward_clean of that crop), flips applied to the cube before simulation,
 * the 33-channel target written out here, batch determinism across datasets, worker counts
 * and batch sizes, noise level distribution and actual noise, synthetic proportion, the LRU
 * bound (load counts), fixed evaluation samples, and bad input. Fixtures are spectral EXR files
 * written to a mkdtemp folder (removed at the end); the real CAVE samples come from
 * $LM_SHARED_DIR/data/cave (and cave-256 for the real split). */
#define _GNU_SOURCE
#include "tests/check.h"
#include "tests/shared_dir.h"
#include "data/cube_io.h"
#include "data/dataset.h"
#include "data/forward.h"
#include "data/spectra.h"
#include <dirent.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <unistd.h>

static char tmpdir[] = "/tmp/lm_dataset_XXXXXX";
static lm_system g_sys;
static int g_ok;
static lm_err g_err;

#define PH 12
#define PW 16
#define POS_H 30
#define POS_W 40


/* The position fixture: band 0 = (y+1)/1000, band 1 = (x+1)/1000, others vary with b, y, x. */
static float pos_value(int b, int y, int x)
{
    if (b == 0) return (float)(y + 1) / 1000.0f;
    if (b == 1) return (float)(x + 1) / 1000.0f;
    if (b == 30 && y == 0 && x == 0) return 1.0f; /* the peak: normalisation leaves it as is */
    return 0.05f + (float)((b * 7 + y * 3 + x * 5) % 17) / 20.0f;
}

/* Every fixture peaks at exactly 1 (band 30, pixel 0,0), so the dataset's normalisation by the
 * scene maximum (system.md §10) leaves it unchanged; `scale` then multiplies the whole scene
 * (test_scene_normalised: a darker copy must give the same samples). */
static void write_scene_scaled(const char *path, int h, int w, int kind, float scale)
{
    lm_cube c;
    CHECK(lm_cube_alloc(&c, 31, h, w, 400, 10) == LM_OK);
    for (int b = 0; b < 31; b++)
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++)
                lm_cube_band(&c, b)[y * w + x] = kind ? pos_value(b, y, x)
                                                      : 0.1f + 0.02f * (float)((b + y + x) % 9);
    lm_cube_band(&c, 30)[0] = 1.0f;
    for (size_t i = 0; i < (size_t)31 * h * w; i++) c.data[i] *= scale;
    lm_err e;
    lm_err_clear(&e);
    CHECK_MSG(lm_cube_write_exr(path, &c, &e) == LM_OK, "%s", e.msg);
    lm_cube_free(&c);
}

static void write_scene(const char *path, int h, int w, int kind)
{
    write_scene_scaled(path, h, w, kind, 1.0f);
}

static void subdir(char *out, size_t n, const char *name)
{
    snprintf(out, n, "%s/%s", tmpdir, name);
    mkdir(out, 0700);
}

static lm_dataset_cfg base_cfg(const char *const *paths, int npaths)
{
    lm_dataset_cfg c;
    lm_dataset_default_cfg(&c);
    c.paths = paths;
    c.npaths = npaths;
    c.sys = &g_sys;
    c.patch_h = PH;
    c.patch_w = PW;
    c.synth_fraction = 0.0f;
    c.noise_min = c.noise_max = 0.0f;
    c.flips = 0;
    c.workers = 0;
    c.seed = 42;
    c.val_patches = 4;
    return c;
}

static char g_posdir[1024], g_pospath[1100];

/* ---- split ------------------------------------------------------------------------------ */
static void check_key(const char *name, int h, int w, const char *want)
{
    char key[64];
    int n = lm_dataset_group_key(name, h, w, key, sizeof key);
    CHECK_MSG(!strcmp(key, want) && n == (int)strlen(want), "%s (%d x %d) -> '%s', expected '%s'",
              name, h, w, key, want);
}

static void test_group_key(void)
{
    check_key("clay_256", 256, 256, "clay");
    check_key("ARAD_1K_0001", 482, 512, "ARAD_1K_0001");
    check_key("balloons_crop100", 100, 100, "balloons");
    check_key("chart_and_stuffed_toy_crop150", 150, 150, "chart_and_stuffed_toy");
    check_key("chart_and_stuffed_toy_256", 256, 256, "chart_and_stuffed_toy");
    check_key("scene_128", 100, 128, "scene");       /* the width */
    check_key("scene_100", 100, 128, "scene");       /* the height */
    check_key("scene_256", 128, 128, "scene_256");   /* not its size: part of the name */
    check_key("scene_crop7_256", 256, 256, "scene_crop7"); /* one suffix only */
    check_key("a_crop1_crop2", 9, 9, "a_crop1");
    check_key("scene_crop", 9, 9, "scene_crop");     /* no digits */
    check_key("scenecrop12", 12, 12, "scenecrop12"); /* no underscore */
    check_key("_256", 256, 256, "_256");             /* nothing would be left */
    check_key("scene_99999999999", 9, 9, "scene_99999999999");
    char small[4];
    CHECK(lm_dataset_group_key("clay_256", 256, 256, small, sizeof small) == 4 &&
          !strcmp(small, "cla"));
}

static int in_split(const lm_dataset *d, lm_data_split s, const char *name)
{
    for (int i = 0; i < lm_dataset_num_scenes(d, s); i++)
        if (!strcmp(lm_dataset_scene_name(d, s, i), name)) return 1;
    return 0;
}

/* The split fixture: group g is fake_g<NN> (9 x 8) plus one variant of it (_crop5, _8 = the
 * width or _9 = the height); fake_g00_7 is a group of its own (7 is not a size). */
#define SPLIT_MAX_GROUPS 24
#define ODD_GROUP (SPLIT_MAX_GROUPS - 1)
static void split_name(char *out, size_t n, int g, int variant)
{
    static const char *suffix[3] = {"_crop5", "_8", "_9"};
    snprintf(out, n, "fake_g%02d%s", g, variant ? suffix[g % 3] : "");
}

static void add_split_group(const char *dir, int g)
{
    char path[1200], name[64];
    for (int v = 0; v < 2; v++) {
        split_name(name, sizeof name, g, v);
        snprintf(path, sizeof path, "%s/%s.exr", dir, name);
        write_scene(path, 9, 8, 0);
    }
}

static lm_dataset *open_split_dir(const char *dir)
{
    const char *paths[1] = {dir};
    lm_dataset_cfg cfg = base_cfg(paths, 1);
    cfg.patch_h = 6;
    cfg.patch_w = 8;
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *d = lm_dataset_open(&cfg, &e);
    CHECK_MSG(d != NULL, "%s", e.msg);
    return d;
}

/* Groups 0..ng-1 (and fake_g00_7): both scenes of a group in one split, every scene in exactly
 * one list, the quotas exact; split[g] receives group g's split, split[ODD_GROUP] that of
 * fake_g00_7. */
static void check_split_rule(const lm_dataset *d, int ng, int *split)
{
    int groups[3] = {0, 0, 0}, total = 0;
    char name[64];
    for (int g = 0; g < ng; g++) {
        split_name(name, sizeof name, g, 0);
        split[g] = lm_dataset_split_of_scene(d, name);
        CHECK_MSG(split[g] >= 0 && in_split(d, split[g], name), "%s", name);
        split_name(name, sizeof name, g, 1);
        CHECK_MSG(lm_dataset_split_of_scene(d, name) == split[g], "%s", name);
        if (split[g] >= 0) groups[split[g]]++;
    }
    int odd = split[ODD_GROUP] = lm_dataset_split_of_scene(d, "fake_g00_7");
    CHECK(odd >= 0 && in_split(d, odd, "fake_g00_7"));
    if (odd >= 0) groups[odd]++;
    int G = ng + 1, q = (G + 5) / 10; /* floor(0.1 G + 0.5) */
    CHECK_MSG(groups[LM_SPLIT_TEST] == q && groups[LM_SPLIT_VAL] == q &&
              groups[LM_SPLIT_TRAIN] == G - 2 * q, "%d groups: test %d, val %d, train %d", G,
              groups[LM_SPLIT_TEST], groups[LM_SPLIT_VAL], groups[LM_SPLIT_TRAIN]);
    for (int s = 0; s < 3; s++) {
        total += lm_dataset_num_scenes(d, s);
        CHECK(!lm_dataset_split_borrowed(d, s));
        for (int i = 0; i < lm_dataset_num_scenes(d, s); i++) {
            const char *nm = lm_dataset_scene_name(d, s, i);
            CHECK(lm_dataset_split_of_scene(d, nm) == s);
            CHECK(lm_dataset_split_of_scene(d, lm_dataset_scene_path(d, s, i)) == s);
            CHECK(in_split(d, s, nm) + in_split(d, (s + 1) % 3, nm) +
                  in_split(d, (s + 2) % 3, nm) == 1); /* never in two splits */
        }
    }
    CHECK(total == 2 * ng + 1);
    CHECK(lm_dataset_split_of_scene(d, "no_such_scene") == -1);
}

/* Quotas exact, groups never split, the same split on every open; adding one group at a time
 * moves at most one old group across each boundary (test/val, val/train), and one more into
 * val when the quota grows (val then gains a group from train at both ends). */
static void test_split_groups_and_quotas(void)
{
    char dir[1024], path[1200];
    subdir(dir, sizeof dir, "fake");
    int ng = 12;
    for (int g = 0; g < ng; g++) add_split_group(dir, g);
    snprintf(path, sizeof path, "%s/fake_g00_7.exr", dir);
    write_scene(path, 9, 8, 0);
    int prev[SPLIT_MAX_GROUPS] = {0}, cur[SPLIT_MAX_GROUPS] = {0}, again[SPLIT_MAX_GROUPS] = {0};
    lm_dataset *d = open_split_dir(dir), *d2 = open_split_dir(dir);
    if (!d || !d2) goto done;
    check_split_rule(d, ng, prev);
    check_split_rule(d2, ng, again);
    CHECK(memcmp(prev, again, sizeof prev) == 0);
    for (; ng < 16; ng++) { /* 13 .. 17 groups: the quota grows from 1 to 2 at 15 */
        add_split_group(dir, ng);
        lm_dataset_close(d);
        d = open_split_dir(dir);
        if (!d) goto done;
        check_split_rule(d, ng + 1, cur);
        int moved = 0, grew = (ng + 2 + 5) / 10 > (ng + 1 + 5) / 10;
        for (int g = 0; g < SPLIT_MAX_GROUPS; g++) {
            if (g >= ng && g != ODD_GROUP) continue;
            moved += cur[g] != prev[g];
            CHECK(abs(cur[g] - prev[g]) <= 1); /* only to the neighbouring split */
        }
        CHECK_MSG(moved <= 2 + grew, "%d groups: %d old groups moved", ng + 2, moved);
        memcpy(prev, cur, sizeof cur);
    }
done:
    lm_dataset_close(d);
    lm_dataset_close(d2);
}

/* The real data: 27 scenes in 26 groups (cave's two chart_and_stuffed_toy variants are one);
 * 3 test and 3 val groups by hash rank, named in the describe output. Reads band-01 headers. */
static void test_split_real_scenes(void)
{
    char cave[1024], cave256[1100];
    snprintf(cave, sizeof cave, "%s/data/cave", shared_dir());
    snprintf(cave256, sizeof cave256, "%s/data/cave-256", shared_dir());
    struct stat st;
    if (stat(cave, &st) != 0 || stat(cave256, &st) != 0) {
        fprintf(stderr, "test_split_real_scenes: skipped, %s or %s absent\n", cave, cave256);
        return;
    }
    const char *paths[2] = {cave, cave256};
    lm_dataset_cfg cfg;
    lm_dataset_default_cfg(&cfg);
    cfg.paths = paths;
    cfg.npaths = 2;
    cfg.sys = &g_sys;
    cfg.workers = 0;
    cfg.synth_fraction = 0.0f;
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *d = lm_dataset_open(&cfg, &e);
    CHECK_MSG(d != NULL, "%s", e.msg);
    if (!d) return;
    static const char *test[3] = {"cd_256", "fake_and_real_tomatoes_256",
                                  "real_and_fake_apples_256"};
    static const char *val[3] = {"watercolors_256", "glass_tiles_256", "pompoms_256"};
    CHECK(lm_dataset_num_scenes(d, LM_SPLIT_TEST) == 3 && lm_dataset_num_scenes(d, LM_SPLIT_VAL)
          == 3 && lm_dataset_num_scenes(d, LM_SPLIT_TRAIN) == 21);
    char *buf = NULL;
    size_t n = 0;
    FILE *f = open_memstream(&buf, &n);
    lm_dataset_describe(d, f);
    fclose(f);
    for (int i = 0; i < 3; i++) {
        CHECK_MSG(in_split(d, LM_SPLIT_TEST, test[i]), "%s not in test", test[i]);
        CHECK_MSG(in_split(d, LM_SPLIT_VAL, val[i]), "%s not in val", val[i]);
        CHECK_MSG(buf && strstr(buf, test[i]) && strstr(buf, val[i]), "describe: %s", buf);
    }
    CHECK(buf && strstr(buf, "27 scenes in 26 groups"));
    free(buf);
    CHECK(in_split(d, LM_SPLIT_TRAIN, "chart_and_stuffed_toy_256") &&
          in_split(d, LM_SPLIT_TRAIN, "chart_and_stuffed_toy_crop150"));
    lm_dataset_close(d);
}

static void test_borrow_below_three_scenes(void)
{
    const char *paths[1] = {g_pospath};
    lm_dataset_cfg cfg = base_cfg(paths, 1);
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *d = lm_dataset_open(&cfg, &e);
    CHECK_MSG(d != NULL, "%s", e.msg);
    if (!d) return;
    for (int s = 0; s < 3; s++) CHECK(lm_dataset_num_scenes(d, s) == 1);
    CHECK(lm_dataset_split_of_scene(d, "posscene") == LM_SPLIT_TRAIN);
    CHECK(!lm_dataset_split_borrowed(d, LM_SPLIT_TRAIN) && lm_dataset_split_borrowed(d,
          LM_SPLIT_VAL) && lm_dataset_split_borrowed(d, LM_SPLIT_TEST));
    CHECK(lm_dataset_eval_count(d, LM_SPLIT_VAL) == 4 && lm_dataset_eval_count(d, LM_SPLIT_TEST));
    char *buf = NULL;
    size_t n = 0;
    FILE *f = open_memstream(&buf, &n);
    lm_dataset_describe(d, f);
    fclose(f);
    CHECK(buf && strstr(buf, "borrowed"));
    free(buf);
    lm_dataset_close(d);
}

static void ref_raw(const lm_cube *c31, float *raw);
static void crop(lm_cube *out, int y0, int x0, int fh, int fv);

static void test_eval_samples_fixed(void)
{
    const char *paths[1] = {g_pospath};
    lm_dataset_cfg cfg = base_cfg(paths, 1);
    cfg.flips = 1;
    cfg.synth_fraction = 0.5f;
    cfg.noise_max = 0.1f;
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *d = lm_dataset_open(&cfg, &e);
    CHECK_MSG(d != NULL, "%s", e.msg);
    if (!d) return;
    float raw[PH * PW], raw2[PH * PW], t[33 * PH * PW], t2[33 * PH * PW], rr[PH * PW];
    int offsets = 0, last = -1;
    for (int s = LM_SPLIT_VAL; s <= LM_SPLIT_TEST; s++)
        for (int i = 0; i < lm_dataset_eval_count(d, s); i++) {
            lm_dataset_sample_info info;
            CHECK(lm_dataset_sample_info_get(d, s, i, &info, &e) == LM_OK);
            CHECK(info.kind == LM_SAMPLE_SCENE && !info.flip_h && !info.flip_v &&
                  info.noise_k == 0.0f); /* real scenes, no flips, val_noise */
            CHECK(lm_dataset_eval_sample(d, s, i, raw, t, &e) == LM_OK);
            CHECK(lm_dataset_eval_sample(d, s, i, raw2, t2, &e) == LM_OK);
            CHECK(memcmp(raw, raw2, sizeof raw) == 0 && memcmp(t, t2, sizeof t) == 0);
            lm_cube c;
            crop(&c, info.y0, info.x0, 0, 0);
            ref_raw(&c, rr);
            CHECK_ARRAY_CLOSE(raw, rr, PH * PW, 1e-6, 1e-5);
            lm_cube_free(&c);
            offsets += info.y0 * 100 + info.x0 != last;
            last = info.y0 * 100 + info.x0;
        }
    CHECK(offsets > 2);
    lm_dataset_close(d);
}

/* ---- patches ---------------------------------------------------------------------------- */
static void crop(lm_cube *out, int y0, int x0, int fh, int fv)
{
    CHECK(lm_cube_alloc(out, 31, PH, PW, 400, 10) == LM_OK);
    for (int b = 0; b < 31; b++)
        for (int y = 0; y < PH; y++)
            for (int x = 0; x < PW; x++)
                lm_cube_band(out, b)[y * PW + x] =
                    pos_value(b, y0 + (fv ? PH - 1 - y : y), x0 + (fh ? PW - 1 - x : x));
}

/* raw of a 31-band crop through mirror + forward_clean (tile phase 0, 0). */
static void ref_raw(const lm_cube *c31, float *raw)
{
    lm_cube c41;
    lm_err e;
    lm_err_clear(&e);
    CHECK(lm_cube_mirror41(c31, &c41, &e) == LM_OK);
    CHECK_MSG(lm_forward_clean(&g_sys, &c41, 0, 0, raw, NULL, 1, &e) == LM_OK, "%s", e.msg);
    lm_cube_free(&c41);
}

/* The 33-channel target written out: 385 = mean(380 <- 420, 390 <- 410), 400..700, 745 = mean
 * of 710..780 <- 690..620. */
static void ref_target(const lm_cube *c, float *t)
{
    size_t n = (size_t)PH * PW;
    for (size_t i = 0; i < n; i++) {
        t[i] = 0.5f * (lm_cube_band(c, 2)[i] + lm_cube_band(c, 1)[i]);
        for (int b = 0; b < 31; b++) t[(b + 1) * n + i] = lm_cube_band(c, b)[i];
        float acc = 0.0f;
        for (int b = 29; b >= 22; b--) acc += lm_cube_band(c, b)[i];
        t[32 * n + i] = acc / 8.0f;
    }
}

static void test_patches_on_tile_grid(void)
{
    const char *paths[1] = {g_pospath};
    lm_dataset_cfg cfg = base_cfg(paths, 1);
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *d = lm_dataset_open(&cfg, &e);
    CHECK_MSG(d != NULL, "%s", e.msg);
    if (!d) return;
    const int B = 8;
    size_t n = (size_t)PH * PW;
    float raw[B * PH * PW], target[B * 33 * PH * PW], rr[PH * PW], rt[33 * PH * PW];
    int seen_y[POS_H] = {0}, seen_x[POS_W] = {0}, distinct = 0;
    for (long bi = 0; bi < 4; bi++) {
        CHECK_MSG(lm_dataset_batch(d, bi, B, raw, target, &e) == LM_OK, "%s", e.msg);
        for (int j = 0; j < B; j++) {
            const float *t = target + (size_t)j * 33 * n;
            int y0 = (int)lroundf(t[1 * n] * 1000.0f) - 1;
            int x0 = (int)lroundf(t[2 * n] * 1000.0f) - 1;
            CHECK_MSG(y0 % 3 == 0 && x0 % 4 == 0 && y0 >= 0 && x0 >= 0 && y0 + PH <= POS_H &&
                      x0 + PW <= POS_W, "patch at (%d, %d)", y0, x0);
            if (y0 < 0 || x0 < 0 || y0 + PH > POS_H || x0 + PW > POS_W) continue;
            lm_dataset_sample_info info;
            CHECK(lm_dataset_sample_info_get(d, LM_SPLIT_TRAIN, bi * B + j, &info, &e) == LM_OK);
            CHECK(info.kind == LM_SAMPLE_SCENE && info.y0 == y0 && info.x0 == x0);
            distinct += !seen_y[y0] + !seen_x[x0];
            seen_y[y0] = seen_x[x0] = 1;
            lm_cube c;
            crop(&c, y0, x0, 0, 0);
            ref_raw(&c, rr);
            ref_target(&c, rt);
            CHECK_ARRAY_CLOSE(raw + (size_t)j * n, rr, n, 1e-6, 1e-5);
            CHECK_ARRAY_CLOSE(t, rt, 33 * n, 1e-7, 1e-6);
            lm_cube_free(&c);
        }
    }
    CHECK_MSG(distinct >= 6, "only %d distinct offsets", distinct);
    lm_dataset_close(d);
}

static void test_flips_before_simulation(void)
{
    const char *paths[1] = {g_pospath};
    lm_dataset_cfg cfg = base_cfg(paths, 1);
    cfg.flips = 1;
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *d = lm_dataset_open(&cfg, &e);
    CHECK_MSG(d != NULL, "%s", e.msg);
    if (!d) return;
    size_t n = (size_t)PH * PW;
    float raw[PH * PW], target[33 * PH * PW], rr[PH * PW], rt[33 * PH * PW], plain[PH * PW];
    int kinds[4] = {0, 0, 0, 0};
    for (long i = 0; i < 24; i++) {
        lm_dataset_sample_info info;
        CHECK(lm_dataset_sample_info_get(d, LM_SPLIT_TRAIN, i, &info, &e) == LM_OK);
        CHECK(lm_dataset_batch(d, i, 1, raw, target, &e) == LM_OK);
        kinds[info.flip_h + 2 * info.flip_v]++;
        lm_cube c;
        crop(&c, info.y0, info.x0, info.flip_h, info.flip_v);
        ref_raw(&c, rr);
        ref_target(&c, rt);
        CHECK_ARRAY_CLOSE(raw, rr, n, 1e-6, 1e-5);
        CHECK_ARRAY_CLOSE(target, rt, 33 * n, 1e-7, 1e-6);
        lm_cube_free(&c);
        if (!info.flip_h) continue;
        /* flipping the coded raw instead would give other numbers (it breaks the mosaic) */
        crop(&c, info.y0, info.x0, 0, info.flip_v);
        ref_raw(&c, plain);
        double diff = 0;
        for (int y = 0; y < PH; y++)
            for (int x = 0; x < PW; x++) diff += fabs(raw[y * PW + x] - plain[y * PW + PW - 1 - x]);
        CHECK(diff > 1e-2 * (double)n * 0.1);
        lm_cube_free(&c);
    }
    for (int k = 0; k < 4; k++) CHECK_MSG(kinds[k] > 0, "flip combination %d never drawn", k);
    lm_dataset_close(d);
}

/* ---- both buckets ------------------------------------------------------------------------ */
/* Bucket 0 of a 31-band crop, written out: per pixel, (sum over every LED of a_l . r) minus the
 * pixel's own LED's a . r, on the mirrored 41 bins, in double. */
static void ref_bucket0(const lm_cube *c31, double *b0)
{
    lm_cube c41;
    lm_err e;
    lm_err_clear(&e);
    CHECK(lm_cube_mirror41(c31, &c41, &e) == LM_OK);
    const lm_system *s = &g_sys;
    for (int y = 0; y < PH; y++)
        for (int x = 0; x < PW; x++) {
            const int own = s->tile_led[(y % s->tile_rows) * s->tile_cols + x % s->tile_cols];
            double all = 0, mine = 0;
            for (int l = 0; l < s->nleds; l++)
                for (int b = 0; b < s->nbins; b++) {
                    double v = (double)s->leds[l].response[b] * lm_cube_band(&c41, b)[y * PW + x];
                    all += v;
                    if (l == own) mine += v;
                }
            b0[y * PW + x] = all - mine;
        }
    lm_cube_free(&c41);
}

/* buckets 2: plane 0 is bucket 1 as before, plane 1 bucket 0 / (LEDs - 1) of the same (flipped)
 * crop; noise-free. */
static void test_two_buckets_clean(void)
{
    const char *paths[1] = {g_pospath};
    lm_dataset_cfg cfg = base_cfg(paths, 1);
    cfg.flips = 1;
    cfg.buckets = 2;
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *d = lm_dataset_open(&cfg, &e);
    CHECK_MSG(d != NULL, "%s", e.msg);
    if (!d) return;
    CHECK(lm_dataset_buckets(d) == 2);
    const size_t n = (size_t)PH * PW;
    float raw[2 * PH * PW], target[33 * PH * PW], rr[PH * PW], rt[33 * PH * PW];
    double b0[PH * PW];
    const double inv = 1.0 / (g_sys.nleds - 1);
    int flipped = 0;
    for (long i = 0; i < 16; i++) {
        lm_dataset_sample_info info;
        CHECK(lm_dataset_sample_info_get(d, LM_SPLIT_TRAIN, i, &info, &e) == LM_OK);
        CHECK_MSG(lm_dataset_batch(d, i, 1, raw, target, &e) == LM_OK, "%s", e.msg);
        flipped += info.flip_h || info.flip_v;
        lm_cube c;
        crop(&c, info.y0, info.x0, info.flip_h, info.flip_v);
        ref_raw(&c, rr);
        ref_target(&c, rt);
        ref_bucket0(&c, b0);
        CHECK_ARRAY_CLOSE(raw, rr, n, 1e-6, 1e-5);
        CHECK_ARRAY_CLOSE(target, rt, 33 * n, 1e-7, 1e-6);
        double worst = 0, mean = 0;
        for (size_t p = 0; p < n; p++) {
            double want = b0[p] * inv, err = fabs(raw[n + p] - want) / (fabs(want) + 1e-6);
            worst = err > worst ? err : worst;
            mean += raw[n + p] / n;
        }
        CHECK_MSG(worst < 1e-5, "sample %ld: bucket 0 off by %g (relative)", i, worst);
        CHECK(mean > 0.05); /* the fixture is bright: bucket 0 is not empty */
        lm_cube_free(&c);
    }
    CHECK(flipped > 0);
    /* validation samples: two planes too, the same as the training path */
    CHECK(lm_dataset_eval_sample(d, LM_SPLIT_VAL, 0, raw, target, &e) == LM_OK);
    lm_dataset_sample_info info;
    CHECK(lm_dataset_sample_info_get(d, LM_SPLIT_VAL, 0, &info, &e) == LM_OK);
    lm_cube c;
    crop(&c, info.y0, info.x0, 0, 0);
    ref_bucket0(&c, b0);
    for (size_t p = 0; p < n; p++) CHECK_CLOSE(raw[n + p], b0[p] * inv, 1e-6, 1e-5);
    lm_cube_free(&c);
    lm_dataset_close(d);
}

/* FNV-1a over the bytes of n floats. */
static uint64_t hash_floats(const float *v, size_t n)
{
    uint64_t h = 0xcbf29ce484222325ull;
    const unsigned char *p = (const unsigned char *)v;
    for (size_t i = 0; i < n * sizeof(float); i++) h = (h ^ p[i]) * 0x100000001b3ull;
    return h;
}

/* With noise, clipping, quantisation, flips and synthetic shares: bucket 1 of a two-bucket
 * sample is bit for bit the one-bucket sample (and the one-bucket batch is the numbers the
 * loader gave before buckets existed: a fixed hash), bucket 0 gets noise of sd k x its own clean
 * maximum, drawn independently of bucket 1's. */
static void test_two_buckets_noise(void)
{
    const char *paths[1] = {g_pospath};
    lm_dataset_cfg cfg = base_cfg(paths, 1);
    cfg.flips = 1;
    cfg.synth_fraction = 0.3f;
    cfg.procedural_fraction = 0.2f;
    cfg.noise_min = 0.05f;
    cfg.noise_max = 0.15f;
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *one = lm_dataset_open(&cfg, &e);
    cfg.buckets = 2;
    lm_dataset *two = lm_dataset_open(&cfg, &e);
    cfg.noise_min = cfg.noise_max = 0.0f;
    lm_dataset *clean = lm_dataset_open(&cfg, &e);
    cfg.noise_min = 0.05f;
    cfg.noise_max = 0.15f;
    cfg.sensor_clip = 1;
    cfg.sensor_bits = 16;
    cfg.buckets = 1;
    lm_dataset *one_q = lm_dataset_open(&cfg, &e);
    cfg.buckets = 2;
    cfg.workers = 2; /* the pool too */
    lm_dataset *two_q = lm_dataset_open(&cfg, &e);
    CHECK_MSG(one && two && clean && one_q && two_q, "%s", e.msg);
    if (!one || !two || !clean || !one_q || !two_q) goto done;
    enum { B = 8 };
    const size_t n = (size_t)PH * PW;
    static float r1[B * PH * PW], r2[B * 2 * PH * PW], rc[B * 2 * PH * PW];
    static float t1[B * 33 * PH * PW], t2[B * 33 * PH * PW];
    CHECK(lm_dataset_batch(one, 0, B, r1, t1, &e) == LM_OK);
    /* the one-bucket loader's numbers before buckets existed (same seed, fixture and
     * options): the coded frames' bits depend on whether the compiler fuses multiply-adds in
     * the forward model, so one hash for the portable build (no FMA outside the per-level
     * kernels) and one for a build for an FMA machine (-march=native) */
    uint64_t h1 = hash_floats(r1, B * n), ht = hash_floats(t1, B * 33 * n);
    CHECK_MSG(h1 == 0xab01d2af681271ecull || h1 == 0xc9b174cf1e73b7f8ull,
              "one-bucket batch hash %016llx", (unsigned long long)h1);
    CHECK_MSG(ht == 0x48717e10521704a7ull, "one-bucket target hash %016llx", (unsigned long long)ht);
    int kinds[3] = {0, 0, 0};
    double corr_sum = 0;
    for (long bi = 0; bi < 3; bi++) {
        CHECK(lm_dataset_batch(one, bi, B, r1, t1, &e) == LM_OK);
        CHECK(lm_dataset_batch(two, bi, B, r2, t2, &e) == LM_OK);
        CHECK(lm_dataset_batch(clean, bi, B, rc, t2, &e) == LM_OK);
        CHECK(memcmp(t1, t2, sizeof t1) == 0);
        for (int j = 0; j < B; j++) {
            lm_dataset_sample_info info;
            CHECK(lm_dataset_sample_info_get(two, LM_SPLIT_TRAIN, bi * B + j, &info, &e) == LM_OK);
            kinds[info.kind]++;
            CHECK_MSG(memcmp(r1 + j * n, r2 + 2 * j * n, n * sizeof(float)) == 0,
                      "sample %ld: bucket 1 differs from the one-bucket sample", bi * B + j);
            const float *c0 = rc + (2 * j + 1) * n, *v0 = r2 + (2 * j + 1) * n;
            const float *c1 = rc + 2 * j * n, *v1 = r2 + 2 * j * n;
            double mx = 0, s = 0, ss = 0, cross = 0, s1 = 0, ss1 = 0;
            for (size_t p = 0; p < n; p++) {
                double d0 = v0[p] - c0[p], d1 = v1[p] - c1[p];
                mx = c0[p] > mx ? c0[p] : mx;
                s += d0, ss += d0 * d0, s1 += d1, ss1 += d1 * d1, cross += d0 * d1;
            }
            double m = s / n, sd = sqrt(ss / n - m * m), m1 = s1 / n, sd1 = sqrt(ss1 / n - m1 * m1);
            CHECK_MSG(fabs(sd / mx / info.noise_k - 1) < 0.15, "sample %ld: bucket 0 noise sd "
                      "%g x max, k %g", bi * B + j, sd / mx, info.noise_k);
            corr_sum += (cross / n - m * m1) / (sd * sd1);
        }
    }
    CHECK_MSG(fabs(corr_sum / (3 * B)) < 0.05, "bucket noises correlated: %g", corr_sum / (3 * B));
    for (int k = 0; k < 3; k++) CHECK_MSG(kinds[k] > 0, "sample kind %d never drawn", k);
    /* clipped and quantised: each bucket on its own full scale, stored in [0, 1] */
    CHECK(lm_dataset_batch(one_q, 1, B, r1, t1, &e) == LM_OK);
    CHECK(lm_dataset_batch(two_q, 1, B, r2, t2, &e) == LM_OK);
    int top0 = 0;
    for (int j = 0; j < B; j++) {
        CHECK(memcmp(r1 + j * n, r2 + 2 * j * n, n * sizeof(float)) == 0);
        for (size_t p = 0; p < n; p++) {
            float v = r2[(2 * j + 1) * n + p];
            /* 16-bit steps of the stored scale (up to the float rounding of the 1/11) */
            CHECK(v >= 0.0f && v <= 1.0f && fabsf(v * 65535.0f - rintf(v * 65535.0f)) < 1e-2f);
            top0 += v > 0.2f;
        }
    }
    CHECK(top0 > 0); /* not clipped at bucket 1's full scale (1 / 11 once stored) */
done:
    lm_dataset_close(one);
    lm_dataset_close(two);
    lm_dataset_close(clean);
    lm_dataset_close(one_q);
    lm_dataset_close(two_q);
}

/* ---- determinism on the real CAVE scenes ------------------------------------------------- */
static lm_dataset *open_cave(int workers, uint64_t seed, int cache)
{
    static char dir[1024];
    snprintf(dir, sizeof dir, "%s/data/cave", shared_dir());
    static const char *paths[1];
    paths[0] = dir;
    lm_dataset_cfg cfg;
    lm_dataset_default_cfg(&cfg);
    cfg.paths = paths;
    cfg.npaths = 1;
    cfg.sys = &g_sys;
    cfg.workers = workers;
    cfg.seed = seed;
    cfg.cache_scenes = cache;
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *d = lm_dataset_open(&cfg, &e);
    CHECK_MSG(d != NULL, "%s", e.msg);
    return d;
}

static void test_cave_scenes_listed(void)
{
    lm_dataset *d = open_cave(0, 1, 0);
    if (!d) return;
    int total = 0;
    for (int s = 0; s < 3; s++) total += lm_dataset_num_scenes(d, s);
    CHECK(total >= 3);
    /* 2 groups (balloons, chart_and_stuffed_toy): a tenth of 2, rounded, is 0: all train, and
     * with 3 scenes val and test do not borrow */
    CHECK(lm_dataset_num_scenes(d, LM_SPLIT_TRAIN) == 3);
    CHECK(lm_dataset_num_scenes(d, LM_SPLIT_VAL) == 0 && lm_dataset_num_scenes(d, LM_SPLIT_TEST)
          == 0 && !lm_dataset_split_borrowed(d, LM_SPLIT_TEST));
    CHECK(in_split(d, LM_SPLIT_TRAIN, "balloons_crop100"));
    CHECK(lm_dataset_split_of_scene(d, "chart_and_stuffed_toy_256") == LM_SPLIT_TRAIN);
    lm_dataset_close(d);
}

#define CB 4
#define CN (66 * 64)
static void test_batches_deterministic(void)
{
    lm_dataset *a = open_cave(0, 7, 0), *b = open_cave(2, 7, 1), *c = open_cave(0, 8, 0);
    if (!a || !b || !c) goto done;
    static float ra[CB * CN], ta[CB * 33 * CN], rb[CB * CN], tb[CB * 33 * CN];
    static float r2[CB * CN], t2[CB * 33 * CN];
    lm_err e;
    lm_err_clear(&e);
    const long order[5] = {0, 1, 5, 1, 2}; /* includes a stale prefetch and a repeat */
    for (int k = 0; k < 5; k++) {
        CHECK_MSG(lm_dataset_batch(a, order[k], CB, ra, ta, &e) == LM_OK, "%s", e.msg);
        CHECK_MSG(lm_dataset_batch(b, order[k], CB, rb, tb, &e) == LM_OK, "%s", e.msg);
        CHECK(memcmp(ra, rb, sizeof ra) == 0 && memcmp(ta, tb, sizeof ta) == 0);
    }
    /* sample i is item i % B of batch i / B, whatever B */
    CHECK(lm_dataset_batch(a, 1, CB, ra, ta, &e) == LM_OK);
    CHECK(lm_dataset_batch(b, 3, 2, r2, t2, &e) == LM_OK);
    CHECK(memcmp(ra + 2 * CN, r2, 2 * CN * sizeof(float)) == 0);
    CHECK(memcmp(ta + 2 * 33 * CN, t2, 2 * 33 * CN * sizeof(float)) == 0);
    /* different samples differ; another seed gives other samples */
    CHECK(memcmp(ra, ra + CN, CN * sizeof(float)) != 0);
    CHECK(lm_dataset_batch(a, 2, CB, r2, t2, &e) == LM_OK);
    CHECK(memcmp(ra, r2, CN * sizeof(float)) != 0);
    CHECK(lm_dataset_batch(c, 1, CB, r2, t2, &e) == LM_OK);
    CHECK(memcmp(ra, r2, sizeof ra) != 0);
    /* fixed evaluation samples */
    if (lm_dataset_eval_count(a, LM_SPLIT_VAL) > 0) {
        CHECK(lm_dataset_eval_sample(a, LM_SPLIT_VAL, 3, ra, ta, &e) == LM_OK);
        CHECK(lm_dataset_eval_sample(b, LM_SPLIT_VAL, 3, rb, tb, &e) == LM_OK);
        CHECK(memcmp(ra, rb, CN * sizeof(float)) == 0);
    }
done:
    lm_dataset_close(a);
    lm_dataset_close(b);
    lm_dataset_close(c);
}

/* ---- noise and synthetic share ----------------------------------------------------------- */
static void test_noise_levels(void)
{
    const char *paths[1] = {g_pospath};
    lm_dataset_cfg cfg = base_cfg(paths, 1);
    cfg.noise_min = 0.05f;
    cfg.noise_max = 0.15f;
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *d = lm_dataset_open(&cfg, &e);
    cfg.noise_min = cfg.noise_max = 0.0f;
    lm_dataset *clean = lm_dataset_open(&cfg, &e);
    CHECK_MSG(d && clean, "%s", e.msg);
    if (!d || !clean) goto done;
    const int N = 4000;
    int hist[5] = {0}, out = 0;
    double mean = 0;
    for (long i = 0; i < N; i++) {
        lm_dataset_sample_info info;
        CHECK(lm_dataset_sample_info_get(d, LM_SPLIT_TRAIN, i, &info, &e) == LM_OK);
        out += !(info.noise_k >= 0.05f && info.noise_k < 0.15f);
        mean += info.noise_k / N;
        int bin = (int)((info.noise_k - 0.05f) / 0.02f);
        hist[bin < 0 ? 0 : bin > 4 ? 4 : bin]++;
    }
    CHECK(out == 0);
    CHECK_CLOSE(mean, 0.10, 0.002, 0);
    for (int b = 0; b < 5; b++) CHECK_CLOSE(hist[b] / (double)N, 0.2, 0.03, 0);
    /* the raw's noise has sd = k x max clean value */
    float raw[PH * PW], cl[PH * PW], t[33 * PH * PW];
    for (long i = 0; i < 6; i++) {
        lm_dataset_sample_info info;
        CHECK(lm_dataset_sample_info_get(d, LM_SPLIT_TRAIN, i, &info, &e) == LM_OK);
        CHECK(lm_dataset_batch(d, i, 1, raw, t, &e) == LM_OK);
        CHECK(lm_dataset_batch(clean, i, 1, cl, t, &e) == LM_OK);
        double mx = 0, s = 0, ss = 0;
        for (int p = 0; p < PH * PW; p++) {
            mx = cl[p] > mx ? cl[p] : mx;
            s += raw[p] - cl[p];
            ss += (raw[p] - cl[p]) * (raw[p] - cl[p]);
        }
        double m = s / (PH * PW), sd = sqrt(ss / (PH * PW) - m * m);
        CHECK_CLOSE(sd / mx, info.noise_k, 0, 0.15);
    }
done:
    lm_dataset_close(d);
    lm_dataset_close(clean);
}

/* A per-sample share (clip_fraction, clean_fraction) of 0.5 in `half`: about half of the
 * training samples drawn with the flag (flag(info)), each exactly `alt`'s sample (the loader
 * that does it to every sample), the others exactly `plain`'s (which never does); the plan's
 * other draws unchanged; validation samples never. */
static void check_share(lm_dataset *plain, lm_dataset *half, lm_dataset *alt,
                        int (*flag)(const lm_dataset_sample_info *), const char *what)
{
    lm_err e;
    lm_err_clear(&e);
    const int N = 2000;
    int n = 0;
    for (long i = 0; i < N; i++) {
        lm_dataset_sample_info info, p0;
        CHECK(lm_dataset_sample_info_get(half, LM_SPLIT_TRAIN, i, &info, &e) == LM_OK);
        CHECK(lm_dataset_sample_info_get(plain, LM_SPLIT_TRAIN, i, &p0, &e) == LM_OK);
        CHECK(!flag(&p0) && info.kind == p0.kind && info.scene == p0.scene);
        n += flag(&info);
    }
    CHECK_CLOSE(n / (double)N, 0.5, 0.04, 0);
    static float rh[PH * PW], rp[PH * PW], ra[PH * PW], t[33 * PH * PW];
    int seen[2] = {0, 0}, differ = 0;
    for (long i = 0; i < 24; i++) {
        lm_dataset_sample_info info;
        CHECK(lm_dataset_sample_info_get(half, LM_SPLIT_TRAIN, i, &info, &e) == LM_OK);
        CHECK(lm_dataset_batch(half, i, 1, rh, t, &e) == LM_OK);
        CHECK(lm_dataset_batch(plain, i, 1, rp, t, &e) == LM_OK);
        CHECK(lm_dataset_batch(alt, i, 1, ra, t, &e) == LM_OK);
        const int f = flag(&info);
        seen[f]++;
        CHECK_MSG(memcmp(rh, f ? ra : rp, sizeof rh) == 0, "sample %ld (%s %d) is not the %s "
                  "loader's", i, what, f, f ? what : "plain");
        differ += f && memcmp(ra, rp, sizeof ra) != 0;
    }
    CHECK(seen[0] > 0 && seen[1] > 0);
    CHECK(differ > 0); /* the flagged samples are not the plain loader's */
    CHECK(lm_dataset_eval_sample(half, LM_SPLIT_VAL, 0, rh, t, &e) == LM_OK);
    CHECK(lm_dataset_eval_sample(plain, LM_SPLIT_VAL, 0, rp, t, &e) == LM_OK);
    CHECK(memcmp(rh, rp, sizeof rh) == 0);
}

/* A share above 1 is refused with `msg`. */
static void check_share_refused(const lm_dataset_cfg *cfg, const char *msg)
{
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *bad = lm_dataset_open(cfg, &e);
    CHECK_MSG(bad == NULL && strstr(e.msg, msg), "%s 1.5: %s", msg, e.msg);
    lm_dataset_close(bad);
}

static int clip_flag(const lm_dataset_sample_info *i) { return i->clip; }
static int clean_flag(const lm_dataset_sample_info *i) { return i->clean; }

/* clip_fraction: a share of the training samples clipped to [0, 1] as sensor_clip clips them
 * all (the noise level kept); the others exactly the unclipped loader's */
static void test_clip_fraction(void)
{
    const char *paths[1] = {g_pospath};
    lm_dataset_cfg cfg = base_cfg(paths, 1);
    cfg.noise_min = 0.05f;
    cfg.noise_max = 0.15f;
    cfg.val_noise = 0.1f;
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *plain = lm_dataset_open(&cfg, &e);
    cfg.sensor_clip = 1;
    lm_dataset *all = lm_dataset_open(&cfg, &e);
    cfg.sensor_clip = 0;
    cfg.clip_fraction = 0.5f;
    lm_dataset *half = lm_dataset_open(&cfg, &e);
    cfg.clip_fraction = 1.5f;
    check_share_refused(&cfg, "clip share");
    CHECK_MSG(plain && all && half, "%s", e.msg);
    if (plain && all && half) {
        check_share(plain, half, all, clip_flag, "clipping");
        static float rh[PH * PW], t[33 * PH * PW];
        for (long i = 0; i < 24; i++) {
            lm_dataset_sample_info info, p0;
            CHECK(lm_dataset_sample_info_get(half, LM_SPLIT_TRAIN, i, &info, &e) == LM_OK);
            CHECK(lm_dataset_sample_info_get(plain, LM_SPLIT_TRAIN, i, &p0, &e) == LM_OK);
            CHECK(info.noise_k == p0.noise_k);
            CHECK(lm_dataset_batch(half, i, 1, rh, t, &e) == LM_OK);
            for (int q = 0; q < PH * PW && info.clip; q++) CHECK(rh[q] >= 0.0f);
        }
    }
    lm_dataset_close(plain);
    lm_dataset_close(all);
    lm_dataset_close(half);
}

/* clean_fraction: a share of the training samples without noise (Gaussian, shot and read: noise
 * level 0), each the noiseless loader's sample; the others exactly the noisy loader's */
static void test_clean_fraction(void)
{
    const char *paths[1] = {g_pospath};
    lm_dataset_cfg cfg = base_cfg(paths, 1);
    cfg.noise_min = 0.05f;
    cfg.noise_max = 0.15f;
    cfg.val_noise = 0.1f;
    cfg.photons = 500.0;
    cfg.read_noise = 3.0f;
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *plain = lm_dataset_open(&cfg, &e);
    cfg.clean_fraction = 0.5f;
    lm_dataset *half = lm_dataset_open(&cfg, &e);
    cfg.clean_fraction = 1.5f;
    check_share_refused(&cfg, "noiseless share");
    cfg.clean_fraction = 0.0f;
    cfg.noise_min = cfg.noise_max = 0.0f;
    cfg.photons = 0.0, cfg.read_noise = 0.0f;
    lm_dataset *none = lm_dataset_open(&cfg, &e);
    CHECK_MSG(plain && half && none, "%s", e.msg);
    if (plain && half && none) {
        check_share(plain, half, none, clean_flag, "noiseless");
        for (long i = 0; i < 200; i++) {
            lm_dataset_sample_info info, p0;
            CHECK(lm_dataset_sample_info_get(half, LM_SPLIT_TRAIN, i, &info, &e) == LM_OK);
            CHECK(lm_dataset_sample_info_get(plain, LM_SPLIT_TRAIN, i, &p0, &e) == LM_OK);
            CHECK(info.clean ? info.noise_k == 0.0f : info.noise_k == p0.noise_k);
        }
    }
    lm_dataset_close(plain);
    lm_dataset_close(half);
    lm_dataset_close(none);
}

static void test_synthetic_share(void)
{
    const char *paths[1] = {g_pospath};
    lm_dataset_cfg cfg = base_cfg(paths, 1);
    cfg.synth_fraction = 0.33f; /* the paper's share: narrowband patches only */
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *d = lm_dataset_open(&cfg, &e);
    CHECK_MSG(d != NULL, "%s", e.msg);
    if (!d) return;
    const int N = 4000;
    int n[4] = {0, 0, 0, 0};
    for (long i = 0; i < N; i++) {
        lm_dataset_sample_info info;
        CHECK(lm_dataset_sample_info_get(d, LM_SPLIT_TRAIN, i, &info, &e) == LM_OK);
        n[info.kind]++;
    }
    CHECK_CLOSE(n[LM_SAMPLE_NARROWBAND] / (double)N, 0.33, 0.025, 0);
    CHECK(n[LM_SAMPLE_PROCEDURAL] == 0);
    lm_dataset_close(d);
    cfg.synth_fraction = 0.2f; /* and procedural scenes as their own share */
    cfg.procedural_fraction = 0.3f;
    d = lm_dataset_open(&cfg, &e);
    CHECK_MSG(d != NULL, "%s", e.msg);
    if (!d) return;
    memset(n, 0, sizeof n);
    for (long i = 0; i < N; i++) {
        lm_dataset_sample_info info;
        CHECK(lm_dataset_sample_info_get(d, LM_SPLIT_TRAIN, i, &info, &e) == LM_OK);
        n[info.kind]++;
    }
    CHECK_CLOSE(n[LM_SAMPLE_NARROWBAND] / (double)N, 0.2, 0.025, 0);
    CHECK_CLOSE(n[LM_SAMPLE_PROCEDURAL] / (double)N, 0.3, 0.025, 0);
    /* the samples are what the info says: narrowband = uniform target, procedural = not */
    size_t np = (size_t)PH * PW;
    float raw[PH * PW], t[33 * PH * PW];
    int checked[3] = {0, 0, 0};
    for (long i = 0; i < 60; i++) {
        lm_dataset_sample_info info;
        CHECK(lm_dataset_sample_info_get(d, LM_SPLIT_TRAIN, i, &info, &e) == LM_OK);
        if (info.kind == LM_SAMPLE_SCENE || checked[info.kind] >= 3) continue;
        CHECK(lm_dataset_batch(d, i, 1, raw, t, &e) == LM_OK);
        int varies = 0;
        for (int ch = 0; ch < 33; ch++)
            for (size_t p = 1; p < np; p++) varies += t[ch * np + p] != t[ch * np];
        CHECK(info.kind == LM_SAMPLE_NARROWBAND ? varies == 0 : varies > 0);
        float mx = 0;
        for (size_t p = 0; p < 33 * np; p++) mx = t[p] > mx ? t[p] : mx;
        CHECK(mx <= 1.0f && mx > 0.0f);
        checked[info.kind]++;
    }
    CHECK(checked[1] > 0 && checked[2] > 0);
    lm_dataset_close(d);
    /* fine narrowband detail as a third share, drawn after the other two: those keep their
     * samples */
    lm_dataset_cfg cf = cfg;
    cf.fine_fraction = 0.25f;
    lm_dataset *f = lm_dataset_open(&cf, &e), *g = lm_dataset_open(&cfg, &e);
    CHECK_MSG(f && g, "%s", e.msg);
    memset(n, 0, sizeof n);
    int same_kind = 0, fine_checked = 0;
    for (long i = 0; f && g && i < N; i++) {
        lm_dataset_sample_info info, ref;
        CHECK(lm_dataset_sample_info_get(f, LM_SPLIT_TRAIN, i, &info, &e) == LM_OK);
        CHECK(lm_dataset_sample_info_get(g, LM_SPLIT_TRAIN, i, &ref, &e) == LM_OK);
        n[info.kind]++;
        same_kind += info.kind == ref.kind || (info.kind == LM_SAMPLE_FINE &&
                                               ref.kind == LM_SAMPLE_SCENE);
        if (info.kind == LM_SAMPLE_FINE && fine_checked < 2) {
            CHECK(lm_dataset_batch(f, i, 1, raw, t, &e) == LM_OK);
            float mx = 0;
            for (size_t q = 0; q < 33 * np; q++) mx = t[q] > mx ? t[q] : mx;
            CHECK(mx <= 1.0f && mx > 0.0f);
            fine_checked++;
        }
    }
    CHECK_CLOSE(n[LM_SAMPLE_NARROWBAND] / (double)N, 0.2, 0.025, 0);
    CHECK_CLOSE(n[LM_SAMPLE_PROCEDURAL] / (double)N, 0.3, 0.025, 0);
    CHECK_CLOSE(n[LM_SAMPLE_FINE] / (double)N, 0.25, 0.025, 0);
    CHECK(same_kind == N && fine_checked == 2);
    lm_dataset_close(f), lm_dataset_close(g);
    cf.fine_fraction = 0.6f; /* over 1 in all */
    lm_err_clear(&e);
    CHECK(lm_dataset_open(&cf, &e) == NULL && e.status == LM_ERR_ARG &&
          strstr(e.msg, "fine_fraction"));
    cfg.synth_fraction = 0.5f; /* fully synthetic: no scene needed */
    cfg.procedural_fraction = 0.5f;
    cfg.npaths = 0;
    d = lm_dataset_open(&cfg, &e);
    CHECK_MSG(d != NULL, "%s", e.msg);
    if (d) CHECK(lm_dataset_batch(d, 3, 1, raw, t, &e) == LM_OK);
    lm_dataset_close(d);
    cfg.procedural_fraction = 0.6f; /* over 1 in all */
    lm_err_clear(&e);
    CHECK(lm_dataset_open(&cfg, &e) == NULL && e.status == LM_ERR_ARG);
    CHECK(strstr(e.msg, "procedural_fraction") != NULL);
}

/* ---- cache ------------------------------------------------------------------------------ */
static void test_lru_bound(void)
{
    char dir[1024], path[1100];
    subdir(dir, sizeof dir, "lru");
    for (int i = 0; i < 4; i++) { /* 4 groups: all train */
        snprintf(path, sizeof path, "%s/lru_%d.exr", dir, i);
        write_scene(path, 15, 16, i == 2);
    }
    const char *paths[1] = {dir};
    lm_dataset_cfg cfg = base_cfg(paths, 1);
    cfg.cache_scenes = 2;
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *small = lm_dataset_open(&cfg, &e);
    cfg.cache_scenes = 0;
    lm_dataset *all = lm_dataset_open(&cfg, &e);
    cfg.cache_scenes = 1;
    cfg.workers = 2;
    lm_dataset *one = lm_dataset_open(&cfg, &e);
    CHECK_MSG(small && all && one, "%s", e.msg);
    if (!small || !all || !one) goto done;
    CHECK(lm_dataset_num_scenes(small, LM_SPLIT_TRAIN) == 4);
    float ra[3 * PH * PW], ta[3 * 33 * PH * PW], rb[3 * PH * PW], tb[3 * 33 * PH * PW];
    for (long bi = 0; bi < 20; bi++) {
        CHECK(lm_dataset_batch(small, bi, 3, ra, ta, &e) == LM_OK);
        CHECK(lm_dataset_batch(all, bi, 3, rb, tb, &e) == LM_OK);
        CHECK(memcmp(ra, rb, sizeof ra) == 0 && memcmp(ta, tb, sizeof ta) == 0);
        CHECK(lm_dataset_batch(one, bi, 3, rb, tb, &e) == LM_OK);
        CHECK(memcmp(ra, rb, sizeof ra) == 0 && memcmp(ta, tb, sizeof ta) == 0);
    }
    lm_dataset_stats s1, s2, s3;
    lm_dataset_get_stats(small, &s1);
    lm_dataset_get_stats(all, &s2);
    lm_dataset_get_stats(one, &s3);
    CHECK_MSG(s1.max_cached <= 2 && s1.cached <= 2 && s1.loads > 4, "cache 2: max %d, loads %ld",
              s1.max_cached, s1.loads);
    CHECK_MSG(s2.loads == 4 && s2.max_cached == 4, "cache all: max %d, loads %ld",
              s2.max_cached, s2.loads);
    CHECK_MSG(s3.max_cached <= 1 && s3.loads > 4, "cache 1: max %d, loads %ld", s3.max_cached,
              s3.loads);
done:
    lm_dataset_close(small);
    lm_dataset_close(all);
    lm_dataset_close(one);
}

/* ---- bad input -------------------------------------------------------------------------- */
static void expect_open_fails(const lm_dataset_cfg *cfg, lm_status st, const char *needle)
{
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *d = lm_dataset_open(cfg, &e);
    CHECK_MSG(d == NULL && e.status == st && strstr(e.msg, needle), "status %d, message '%s', "
              "expected %d and '%s'", (int)e.status, e.msg, (int)st, needle);
    lm_dataset_close(d);
}

static void test_bad_input(void)
{
    char empty[1024], bad[1024], badfile[1100], missing[1100];
    subdir(empty, sizeof empty, "empty");
    subdir(bad, sizeof bad, "bad");
    snprintf(badfile, sizeof badfile, "%s/broken.exr", bad);
    FILE *f = fopen(badfile, "wb");
    if (f) {
        fputs("this is not an EXR file", f);
        fclose(f);
    }
    const char *p_empty[1] = {empty}, *p_bad[1] = {bad}, *p_pos[1] = {g_pospath};
    lm_dataset_cfg cfg = base_cfg(p_empty, 1);
    expect_open_fails(&cfg, LM_ERR_FORMAT, empty);
    cfg.paths = p_bad;
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *d = lm_dataset_open(&cfg, &e);
    CHECK_MSG(d == NULL && strstr(e.msg, "broken.exr"), "'%s'", e.msg);
    lm_dataset_close(d);
    snprintf(missing, sizeof missing, "%s/nope.exr", tmpdir);
    const char *p_missing[1] = {missing};
    cfg.paths = p_missing;
    expect_open_fails(&cfg, LM_ERR_IO, "nope.exr");
    cfg.paths = p_pos;
    cfg.patch_h = 13;
    expect_open_fails(&cfg, LM_ERR_SHAPE, "multiple of the 3 x 4 tile");
    cfg.patch_h = 33;
    expect_open_fails(&cfg, LM_ERR_SHAPE, "larger than every scene");
    cfg.patch_h = PH;
    cfg.noise_min = 0.2f;
    cfg.noise_max = 0.1f;
    expect_open_fails(&cfg, LM_ERR_ARG, "noise");
    cfg.noise_min = cfg.noise_max = 0.0f;
    cfg.buckets = 3;
    expect_open_fails(&cfg, LM_ERR_ARG, "buckets 3");
    cfg.buckets = 1;
    /* a scene that becomes unreadable after open: the batch error names it */
    char gone[1100];
    snprintf(gone, sizeof gone, "%s/gone.exr", tmpdir);
    write_scene(gone, 15, 16, 0);
    const char *p_gone[1] = {gone};
    cfg = base_cfg(p_gone, 1);
    d = lm_dataset_open(&cfg, &e);
    CHECK_MSG(d != NULL, "%s", e.msg);
    if (!d) return;
    unlink(gone);
    float raw[PH * PW], t[33 * PH * PW];
    lm_err_clear(&e);
    CHECK(lm_dataset_batch(d, 0, 1, raw, t, &e) != LM_OK && strstr(e.msg, "gone.exr"));
    lm_err_clear(&e);
    CHECK(lm_dataset_eval_sample(d, LM_SPLIT_VAL, 99, raw, t, &e) == LM_ERR_ARG);
    lm_dataset_close(d);
}

static void rm_tree(const char *dir)
{
    DIR *d = opendir(dir);
    if (!d) return;
    struct dirent *de;
    while ((de = readdir(d)) != NULL) {
        if (!strcmp(de->d_name, ".") || !strcmp(de->d_name, "..")) continue;
        char p[2048];
        snprintf(p, sizeof p, "%s/%s", dir, de->d_name);
        struct stat st;
        if (lstat(p, &st) == 0 && S_ISDIR(st.st_mode)) rm_tree(p);
        else unlink(p);
    }
    closedir(d);
    rmdir(dir);
}

/* system.md §10: scenes are divided by their own maximum when read, so a copy of the position
 * scene at a quarter of its brightness yields the same targets and raw frames. */
/* Shot and read noise in the loader (cfg.photons, cfg.read_noise): the added variance is
 * mean / photons (Poisson) and read_noise^2 (a fraction of full scale without photons). */
static void test_shot_and_read_noise(void)
{
    const char *pa[1] = {g_pospath};
    lm_dataset_cfg c0 = base_cfg(pa, 1), c1 = c0, c2 = c0;
    c1.photons = 200.0;
    c2.read_noise = 0.02f;
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *a = lm_dataset_open(&c0, &e), *b = lm_dataset_open(&c1, &e);
    lm_dataset *r = lm_dataset_open(&c2, &e);
    CHECK_MSG(a && b && r, "%s", e.msg);
    enum { NB = 16 };
    static float ra[NB * PH * PW], rb[NB * PH * PW], rr[NB * PH * PW], t[NB * 33 * PH * PW];
    if (a && b && r) {
        double sum = 0, d2 = 0, r2 = 0;
        for (int k = 0; k < 8; k++) {
            CHECK(lm_dataset_batch(a, k, NB, ra, t, &e) == LM_OK);
            CHECK(lm_dataset_batch(b, k, NB, rb, t, &e) == LM_OK);
            CHECK(lm_dataset_batch(r, k, NB, rr, t, &e) == LM_OK);
            for (int i = 0; i < NB * PH * PW; i++) {
                sum += ra[i];
                d2 += (double)(rb[i] - ra[i]) * (rb[i] - ra[i]);
                r2 += (double)(rr[i] - ra[i]) * (rr[i] - ra[i]);
            }
        }
        double shot = d2 / sum * 200.0, rd = sqrt(r2 / (8.0 * NB * PH * PW)) / 0.02;
        CHECK_MSG(fabs(shot - 1) < 0.1, "shot noise variance / (mean / photons) = %g", shot);
        CHECK_MSG(fabs(rd - 1) < 0.05, "read noise sd / 0.02 = %g", rd);
    }
    lm_dataset_close(a), lm_dataset_close(b), lm_dataset_close(r);
    lm_dataset_cfg bad = base_cfg(pa, 1);
    bad.photons = -1;
    CHECK(lm_dataset_open(&bad, &e) == NULL && e.status == LM_ERR_ARG);
}

/* Shot noise with both buckets (cfg.buckets 2): bucket 0 collects the other LEDs' light with
 * the same signal per photo-electron, so in its stored units (/ (LEDs - 1)) the added variance
 * is mean / (photons x (LEDs - 1)), and its noise relative to its signal is several times
 * lower than bucket 1's (about eleven times more electrons). */
static void test_shot_noise_two_buckets(void)
{
    const char *pa[1] = {g_pospath};
    lm_dataset_cfg c0 = base_cfg(pa, 1), c1;
    c0.buckets = 2;
    c1 = c0;
    c1.photons = 200.0;
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *a = lm_dataset_open(&c0, &e), *b = lm_dataset_open(&c1, &e);
    CHECK_MSG(a && b, "%s", e.msg);
    enum { NB = 16 };
    static float ra[NB * 2 * PH * PW], rb[NB * 2 * PH * PW], t[NB * 33 * PH * PW];
    if (a && b) {
        double sum[2] = {0, 0}, sq[2] = {0, 0}, d2[2] = {0, 0};
        for (int k = 0; k < 8; k++) {
            CHECK(lm_dataset_batch(a, k, NB, ra, t, &e) == LM_OK);
            CHECK(lm_dataset_batch(b, k, NB, rb, t, &e) == LM_OK);
            for (int i = 0; i < NB * 2 * PH * PW; i++) {
                const int q = (i / (PH * PW)) % 2; /* plane: 0 bucket 1, 1 bucket 0 */
                sum[q] += ra[i];
                sq[q] += (double)ra[i] * ra[i];
                d2[q] += (double)(rb[i] - ra[i]) * (rb[i] - ra[i]);
            }
        }
        const int L = g_sys.nleds;
        double shot1 = d2[0] / sum[0] * 200.0, shot0 = d2[1] / sum[1] * 200.0 * (L - 1);
        CHECK_MSG(fabs(shot1 - 1) < 0.1, "bucket 1: variance / (mean / photons) = %g", shot1);
        CHECK_MSG(fabs(shot0 - 1) < 0.1, "bucket 0: variance / (mean / (photons (LEDs - 1))) "
                  "= %g", shot0);
        /* noise power over signal power, per bucket */
        double rel1 = d2[0] / sq[0], rel0 = d2[1] / sq[1];
        printf("     relative noise power: bucket 1 %.3g, bucket 0 %.3g (%.1fx lower)\n", rel1,
               rel0, rel1 / rel0);
        CHECK_MSG(rel0 < rel1 / 4, "bucket 0's relative noise %g is not well below bucket 1's %g",
                  rel0, rel1);
    }
    lm_dataset_close(a), lm_dataset_close(b);
}

/* photons_min: each training sample's photon count log-uniform in [photons_min, photons]
 * (measured per sample from its shot-noise variance), validation samples at photons. */
static void test_photon_range(void)
{
    const char *pa[1] = {g_pospath};
    lm_dataset_cfg c0 = base_cfg(pa, 1), c1, c2;
    c1 = c0;
    c1.photons = 5000.0;
    c2 = c1;
    c2.photons_min = 50.0;
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *a = lm_dataset_open(&c0, &e), *b = lm_dataset_open(&c1, &e),
               *r = lm_dataset_open(&c2, &e);
    CHECK_MSG(a && b && r, "%s", e.msg);
    enum { NB = 16 };
    static float ra[NB * PH * PW], rb[NB * PH * PW], rr[NB * PH * PW], t[NB * 33 * PH * PW];
    if (a && b && r) {
        double lo = 1e30, hi = 0, fixed_lo = 1e30, fixed_hi = 0;
        for (int k = 0; k < 4; k++) {
            CHECK(lm_dataset_batch(a, k, NB, ra, t, &e) == LM_OK);
            CHECK(lm_dataset_batch(b, k, NB, rb, t, &e) == LM_OK);
            CHECK(lm_dataset_batch(r, k, NB, rr, t, &e) == LM_OK);
            for (int s = 0; s < NB; s++) {
                double sum = 0, d2b = 0, d2r = 0;
                for (int i = s * PH * PW; i < (s + 1) * PH * PW; i++) {
                    sum += ra[i];
                    d2b += (double)(rb[i] - ra[i]) * (rb[i] - ra[i]);
                    d2r += (double)(rr[i] - ra[i]) * (rr[i] - ra[i]);
                }
                const double pb = sum / d2b, pr = sum / d2r; /* variance = mean / photons */
                fixed_lo = fmin(fixed_lo, pb), fixed_hi = fmax(fixed_hi, pb);
                lo = fmin(lo, pr), hi = fmax(hi, pr);
            }
        }
        printf("     photons per sample: fixed %.0f..%.0f, range 50..5000: %.0f..%.0f\n",
               fixed_lo, fixed_hi, lo, hi);
        CHECK_MSG(fixed_lo > 5000 / 1.6 && fixed_hi < 5000 * 1.6, "fixed photons %g..%g",
                  fixed_lo, fixed_hi);
        CHECK_MSG(lo > 50 / 1.6 && hi < 5000 * 1.6 && hi / lo > 10, "photons drawn %g..%g",
                  lo, hi);
        /* validation samples keep the fixed count: the same numbers */
        CHECK(lm_dataset_eval_sample(b, LM_SPLIT_VAL, 0, rb, t, &e) == LM_OK);
        CHECK(lm_dataset_eval_sample(r, LM_SPLIT_VAL, 0, rr, t, &e) == LM_OK);
        CHECK(memcmp(rb, rr, sizeof(float) * PH * PW) == 0);
    }
    lm_dataset_close(a), lm_dataset_close(b), lm_dataset_close(r);
    c2.photons_min = 6000.0; /* above photons */
    CHECK(lm_dataset_open(&c2, &e) == NULL && e.status == LM_ERR_ARG);
}

/* Spectral augmentation: with illum_jitter each training sample's target is the plain
 * sample's times the tilt exp(t (lambda - 550) / 150) / its maximum, band by band (t from the
 * sample's info, within [-A, A]); with gain_jitter the target is the plain one and each
 * bucket-1 pixel is the plain one times its LED's gain factor (factors spread with sd ~ S);
 * validation samples are unchanged; out-of-range settings are refused. */
static void test_spectral_augmentation(void)
{
    const char *pa[1] = {g_pospath};
    lm_dataset_cfg c0 = base_cfg(pa, 1), ci = c0, cg = c0;
    ci.illum_jitter = 0.5f;
    cg.gain_jitter = 0.1f;
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *a = lm_dataset_open(&c0, &e), *di = lm_dataset_open(&ci, &e),
               *dg = lm_dataset_open(&cg, &e);
    CHECK_MSG(a && di && dg, "%s", e.msg);
    enum { NB = 8 };
    const size_t np = (size_t)PH * PW;
    static float r0[NB * PH * PW], ri[NB * PH * PW], rg[NB * PH * PW];
    static float t0[NB * 33 * PH * PW], ti[NB * 33 * PH * PW], tg[NB * 33 * PH * PW];
    if (a && di && dg) {
        CHECK(lm_dataset_batch(a, 0, NB, r0, t0, &e) == LM_OK);
        CHECK(lm_dataset_batch(di, 0, NB, ri, ti, &e) == LM_OK);
        CHECK(lm_dataset_batch(dg, 0, NB, rg, tg, &e) == LM_OK);
        double worst_t = 0, worst_g = 0, tmax = 0, gsum = 0, gsq = 0;
        int ng = 0;
        for (int s = 0; s < NB; s++) {
            lm_dataset_sample_info in, ig;
            CHECK(lm_dataset_sample_info_get(di, LM_SPLIT_TRAIN, s, &in, &e) == LM_OK);
            CHECK(lm_dataset_sample_info_get(dg, LM_SPLIT_TRAIN, s, &ig, &e) == LM_OK);
            const double t = in.illum_tilt;
            CHECK_MSG(fabs(t) <= 0.5, "tilt %g outside [-0.5, 0.5]", t);
            tmax = fmax(tmax, fabs(t));
            double f[31], fm = 0;
            for (int b = 0; b < 31; b++) f[b] = exp(t * (400.0 + 10 * b - 550.0) / 150.0);
            for (int b = 0; b < 31; b++) fm = fmax(fm, f[b]);
            for (int b = 0; b < 31; b++)
                for (size_t i = 0; i < np; i += 5) {
                    const size_t k = ((size_t)s * 33 + b + 1) * np + i;
                    worst_t = fmax(worst_t, fabs(ti[k] - t0[k] * f[b] / fm));
                }
            for (size_t k = (size_t)s * 33 * np; k < (size_t)(s + 1) * 33 * np; k++)
                CHECK(tg[k] == t0[k]);
            for (int l = 0; l < g_sys.nleds; l++) {
                gsum += ig.led_gain[l], gsq += (double)ig.led_gain[l] * ig.led_gain[l];
                ng++;
            }
            for (int y = 0; y < PH; y++)
                for (int x = 0; x < PW; x++) {
                    const size_t k = (size_t)s * np + (size_t)y * PW + x;
                    const double want = r0[k] * ig.led_gain[lm_system_pixel_led(&g_sys, y, x)];
                    worst_g = fmax(worst_g, fabs(rg[k] - want));
                }
        }
        const double gm = gsum / ng, gsd = sqrt(fmax(gsq / ng - gm * gm, 0));
        printf("     tilt |t| up to %.3f; target error %.2g; gain factors mean %.3f sd %.3f; "
               "frame error %.2g\n", tmax, worst_t, gm, gsd, worst_g);
        CHECK_MSG(tmax > 0.1, "tilts too small (%g): not drawn?", tmax);
        CHECK_MSG(worst_t < 1e-5, "tilted target off by %g", worst_t);
        CHECK_MSG(worst_g < 1e-5, "gain-jittered frame off by %g", worst_g);
        CHECK_MSG(fabs(gm - 1) < 0.05 && gsd > 0.06 && gsd < 0.14, "gains mean %g sd %g", gm,
                  gsd);
        /* validation samples: no augmentation */
        CHECK(lm_dataset_eval_sample(a, LM_SPLIT_VAL, 0, r0, t0, &e) == LM_OK);
        CHECK(lm_dataset_eval_sample(di, LM_SPLIT_VAL, 0, ri, ti, &e) == LM_OK);
        CHECK(lm_dataset_eval_sample(dg, LM_SPLIT_VAL, 0, rg, tg, &e) == LM_OK);
        CHECK(memcmp(r0, ri, sizeof(float) * np) == 0 && memcmp(r0, rg, sizeof(float) * np) == 0);
        CHECK(memcmp(t0, ti, sizeof(float) * 33 * np) == 0);
    }
    lm_dataset_close(a), lm_dataset_close(di), lm_dataset_close(dg);
    ci.illum_jitter = 3.0f;
    CHECK(lm_dataset_open(&ci, &e) == NULL && e.status == LM_ERR_ARG);
    cg.gain_jitter = -0.1f;
    CHECK(lm_dataset_open(&cg, &e) == NULL && e.status == LM_ERR_ARG);
}

/* The patch of a zoomed / transposed sample written out from the fixture, independently of the
 * dataset's taps: z >= 1 integrates the piecewise-constant scene exactly over each patch
 * pixel's box (a summed-area table, bilinear between its corners); z < 1 interpolates
 * bilinearly at the pixel's centre (clamped to the scene). */
static double sat_at(const double *S, double y, double x)
{
    y = fmin(fmax(y, 0.0), (double)POS_H), x = fmin(fmax(x, 0.0), (double)POS_W);
    int i = (int)floor(y), j = (int)floor(x);
    if (i >= POS_H) i = POS_H - 1;
    if (j >= POS_W) j = POS_W - 1;
    const double fy = y - i, fx = x - j, W1 = POS_W + 1;
    return (1 - fy) * ((1 - fx) * S[i * (int)W1 + j] + fx * S[i * (int)W1 + j + 1]) +
           fy * ((1 - fx) * S[(i + 1) * (int)W1 + j] + fx * S[(i + 1) * (int)W1 + j + 1]);
}

static void resampled_crop(lm_cube *out, const lm_dataset_sample_info *in)
{
    CHECK(lm_cube_alloc(out, 31, PH, PW, 400, 10) == LM_OK);
    static double S[(POS_H + 1) * (POS_W + 1)];
    const double z = in->zoom;
    for (int b = 0; b < 31; b++) {
        for (int y = 0; y <= POS_H; y++)
            for (int x = 0; x <= POS_W; x++)
                S[y * (POS_W + 1) + x] = y == 0 || x == 0 ? 0.0
                    : pos_value(b, y - 1, x - 1) + S[(y - 1) * (POS_W + 1) + x] +
                      S[y * (POS_W + 1) + x - 1] - S[(y - 1) * (POS_W + 1) + x - 1];
        for (int y = 0; y < PH; y++)
            for (int x = 0; x < PW; x++) {
                const int yy = in->flip_v ? PH - 1 - y : y, xx = in->flip_h ? PW - 1 - x : x;
                const int a = in->transpose ? xx : yy, c = in->transpose ? yy : xx;
                double v;
                if (z >= 1.0) {
                    const double y0 = in->sy0 + a * z, y1 = y0 + z, x0 = in->sx0 + c * z,
                                 x1 = x0 + z;
                    CHECK_MSG(y1 <= POS_H + 1e-3 && x1 <= POS_W + 1e-3, "region (%g, %g) past "
                              "the scene", y1, x1);
                    v = (sat_at(S, y1, x1) - sat_at(S, y0, x1) - sat_at(S, y1, x0) +
                         sat_at(S, y0, x0)) / (z * z);
                } else {
                    double cy = in->sy0 + (a + 0.5) * z - 0.5, cx = in->sx0 + (c + 0.5) * z - 0.5;
                    cy = fmin(fmax(cy, 0.0), POS_H - 1.0), cx = fmin(fmax(cx, 0.0), POS_W - 1.0);
                    const int i = (int)fmin(floor(cy), POS_H - 2.0),
                              j = (int)fmin(floor(cx), POS_W - 2.0);
                    const double fy = cy - i, fx = cx - j;
                    v = (1 - fy) * ((1 - fx) * pos_value(b, i, j) + fx * pos_value(b, i, j + 1)) +
                        fy * ((1 - fx) * pos_value(b, i + 1, j) + fx * pos_value(b, i + 1, j + 1));
                }
                lm_cube_band(out, b)[y * PW + x] = (float)v;
            }
    }
}

/* The largest errors of a sample's target and frame against the reference simulation of the
 * patch c (freed here). */
static void worst_against(lm_cube *c, const float *raw, const float *tgt, double *wt, double *wr)
{
    const size_t np = (size_t)PH * PW;
    static float rr[PH * PW], rt[33 * PH * PW];
    ref_raw(c, rr);
    ref_target(c, rt);
    for (size_t q = 0; q < 33 * np; q++) *wt = fmax(*wt, fabs(tgt[q] - rt[q]));
    for (size_t q = 0; q < np; q++) *wr = fmax(*wr, fabs(raw[q] - rr[q]));
    lm_cube_free(c);
}

/* Geometric augmentation: with scale_jitter and transpose each training sample's target is the
 * scene resampled over its region (zoom within [1 / (1 + S), 1 + S], both sides drawn;
 * transposed about half of the time) and its frame is that patch through the forward model;
 * with both off the samples are the plain ones, bit for bit; validation samples are unchanged;
 * out-of-range settings are refused. */
static void test_geometric_augmentation(void)
{
    const char *pa[1] = {g_pospath};
    lm_dataset_cfg c0 = base_cfg(pa, 1), cz = c0, c1 = c0;
    c0.flips = cz.flips = c1.flips = 1;
    cz.scale_jitter = 0.5f, cz.transpose = 1;
    c1.transpose = 1; /* whole pixels */
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *a = lm_dataset_open(&c0, &e), *dz = lm_dataset_open(&cz, &e),
               *d1 = lm_dataset_open(&c1, &e);
    CHECK_MSG(a && dz && d1, "%s", e.msg);
    static float raw[PH * PW], tgt[33 * PH * PW];
    if (a && dz && d1) {
        int up = 0, down = 0, turned = 0, n = 40;
        double zmin = 9, zmax = 0, worst_t = 0, worst_r = 0;
        for (long i = 0; i < n; i++) {
            for (int k = 0; k < 2; k++) {
                lm_dataset *d = k ? d1 : dz;
                lm_dataset_sample_info in;
                CHECK(lm_dataset_sample_info_get(d, LM_SPLIT_TRAIN, i, &in, &e) == LM_OK);
                CHECK(lm_dataset_batch(d, i, 1, raw, tgt, &e) == LM_OK);
                if (k) CHECK(in.zoom == 1.0f && in.sy0 == floorf(in.sy0) &&
                             in.sx0 == floorf(in.sx0));
                if (!k) {
                    zmin = fmin(zmin, in.zoom), zmax = fmax(zmax, in.zoom);
                    up += in.zoom < 0.95f, down += in.zoom > 1.05f, turned += in.transpose;
                }
                lm_cube c;
                resampled_crop(&c, &in);
                worst_against(&c, raw, tgt, &worst_t, &worst_r);
            }
        }
        printf("     zoom %.3f..%.3f (%d below 0.95, %d above 1.05), %d of %d transposed; "
               "target error %.2g, frame error %.2g\n", zmin, zmax, up, down, turned, n, worst_t,
               worst_r);
        CHECK_MSG(zmin >= 1 / 1.5 - 1e-6 && zmax <= 1.5 + 1e-6, "zoom %g..%g", zmin, zmax);
        CHECK_MSG(up >= 5 && down >= 5, "zoom not drawn on both sides (%d, %d)", up, down);
        CHECK_MSG(turned >= 8 && turned <= 32, "%d of %d transposed", turned, n);
        CHECK_MSG(worst_t < 2e-5, "resampled target off by %g", worst_t);
        CHECK_MSG(worst_r < 2e-5, "frame of the resampled patch off by %g", worst_r);
        /* off: the plain samples, bit for bit; validation: never augmented */
        lm_dataset_cfg cf = c0;
        cf.scale_jitter = 0.0f, cf.transpose = 0;
        lm_dataset *f = lm_dataset_open(&cf, &e);
        CHECK(f != NULL);
        static float r2[PH * PW], t2[33 * PH * PW];
        for (long i = 0; f && i < 6; i++) {
            CHECK(lm_dataset_batch(a, i, 1, raw, tgt, &e) == LM_OK);
            CHECK(lm_dataset_batch(f, i, 1, r2, t2, &e) == LM_OK);
            CHECK(memcmp(raw, r2, sizeof raw) == 0 && memcmp(tgt, t2, sizeof tgt) == 0);
        }
        lm_dataset_close(f);
        CHECK(lm_dataset_eval_sample(a, LM_SPLIT_VAL, 1, raw, tgt, &e) == LM_OK);
        CHECK(lm_dataset_eval_sample(dz, LM_SPLIT_VAL, 1, r2, t2, &e) == LM_OK);
        CHECK(memcmp(raw, r2, sizeof raw) == 0 && memcmp(tgt, t2, sizeof tgt) == 0);
    }
    lm_dataset_close(a), lm_dataset_close(dz), lm_dataset_close(d1);
    cz.scale_jitter = 1.5f;
    CHECK(lm_dataset_open(&cz, &e) == NULL && e.status == LM_ERR_ARG);
    cz.scale_jitter = 0.5f, cz.transpose = 2;
    CHECK(lm_dataset_open(&cz, &e) == NULL && e.status == LM_ERR_ARG);
}

/* Collage: a share of the training samples blends a second patch of a training scene (here
 * the fixture's own, elsewhere) across an edge; the target is that blend, pixel by pixel from the
 * scene, and the frame is the blend through the forward model; samples left alone are the plain
 * ones bit for bit (the collage draws come from a stream of their own); validation is never
 * pasted into; an out-of-range share is refused. */
static void test_collage(void)
{
    const char *pa[1] = {g_pospath};
    lm_dataset_cfg c0 = base_cfg(pa, 1), cc = c0;
    c0.flips = cc.flips = 1;
    cc.collage = 0.5f;
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *a = lm_dataset_open(&c0, &e), *d = lm_dataset_open(&cc, &e);
    CHECK_MSG(a && d, "%s", e.msg);
    static float raw[PH * PW], tgt[33 * PH * PW], r2[PH * PW], t2[33 * PH * PW];
    if (a && d) {
        int mixed = 0, split_ok = 0, n = 40;
        double worst_t = 0, worst_r = 0;
        for (long i = 0; i < n; i++) {
            lm_dataset_sample_info in;
            CHECK(lm_dataset_sample_info_get(d, LM_SPLIT_TRAIN, i, &in, &e) == LM_OK);
            CHECK(lm_dataset_batch(d, i, 1, raw, tgt, &e) == LM_OK);
            if (!in.collage) {
                CHECK(lm_dataset_batch(a, i, 1, r2, t2, &e) == LM_OK);
                CHECK(memcmp(raw, r2, sizeof raw) == 0 && memcmp(tgt, t2, sizeof tgt) == 0);
                continue;
            }
            mixed++;
            lm_cube c;
            CHECK(lm_cube_alloc(&c, 31, PH, PW, 400, 10) == LM_OK);
            int first = 0, second = 0;
            for (int b = 0; b < 31; b++)
                for (int y = 0; y < PH; y++)
                    for (int x = 0; x < PW; x++) {
                        double w = 0.5 + in.edge_nx * (x + 0.5) + in.edge_ny * (y + 0.5) -
                                   in.edge_c;
                        w = fmin(fmax(w, 0.0), 1.0);
                        first += b == 0 && w == 0.0, second += b == 0 && w == 1.0;
                        const double v1 = pos_value(b, in.y0 + (in.flip_v ? PH - 1 - y : y),
                                                    in.x0 + (in.flip_h ? PW - 1 - x : x));
                        const double v2 = pos_value(b, in.mix_y0 + (in.mix_flip_v ? PH - 1 - y : y),
                                                    in.mix_x0 + (in.mix_flip_h ? PW - 1 - x : x));
                        lm_cube_band(&c, b)[y * PW + x] = (float)((1 - w) * v1 + w * v2);
                    }
            split_ok += first > 0 && second > 0; /* the edge runs through the patch */
            CHECK(in.mix_y0 >= 0 && in.mix_y0 + PH <= POS_H && in.mix_x0 >= 0 &&
                  in.mix_x0 + PW <= POS_W);
            worst_against(&c, raw, tgt, &worst_t, &worst_r);
        }
        printf("     %d of %d samples pasted (%d with both patches visible); target error %.2g, "
               "frame error %.2g\n", mixed, n, split_ok, worst_t, worst_r);
        CHECK_MSG(mixed >= 10 && mixed <= 30, "%d of %d pasted at a share of 0.5", mixed, n);
        CHECK_MSG(split_ok == mixed, "an edge outside the patch (%d of %d)", split_ok, mixed);
        CHECK_MSG(worst_t < 2e-5, "collage target off by %g", worst_t);
        CHECK_MSG(worst_r < 2e-5, "frame of the collage off by %g", worst_r);
        CHECK(lm_dataset_eval_sample(a, LM_SPLIT_VAL, 1, raw, tgt, &e) == LM_OK);
        CHECK(lm_dataset_eval_sample(d, LM_SPLIT_VAL, 1, r2, t2, &e) == LM_OK);
        CHECK(memcmp(raw, r2, sizeof raw) == 0 && memcmp(tgt, t2, sizeof tgt) == 0);
    }
    lm_dataset_close(a), lm_dataset_close(d);
    cc.collage = 1.5f;
    CHECK(lm_dataset_open(&cc, &e) == NULL && e.status == LM_ERR_ARG);
}

static void test_scene_normalised(void)
{
    char dark[1200];
    snprintf(dark, sizeof dark, "%s/dark_pos.exr", tmpdir);
    write_scene_scaled(dark, POS_H, POS_W, 1, 0.25f);
    const char *pa[1] = {g_pospath}, *pb[1] = {dark};
    lm_dataset_cfg ca = base_cfg(pa, 1), cb = base_cfg(pb, 1);
    lm_err e;
    lm_err_clear(&e);
    lm_dataset *a = lm_dataset_open(&ca, &e), *b = lm_dataset_open(&cb, &e);
    CHECK_MSG(a && b, "%s", e.msg);
    enum { NB = 2 };
    static float ra[NB * PH * PW], ta[NB * 33 * PH * PW], rb[NB * PH * PW], tb[NB * 33 * PH * PW];
    if (a && b) {
        CHECK(lm_dataset_batch(a, 3, NB, ra, ta, &e) == LM_OK);
        CHECK(lm_dataset_batch(b, 3, NB, rb, tb, &e) == LM_OK);
        float mx = 0.0f;
        for (size_t i = 0; i < sizeof ta / sizeof *ta; i++) mx = fmaxf(mx, ta[i]);
        CHECK(mx > 0.3f);
        CHECK_ARRAY_CLOSE(tb, ta, sizeof ta / sizeof *ta, 1e-6, 1e-5);
        CHECK_ARRAY_CLOSE(rb, ra, sizeof ra / sizeof *ra, 1e-6, 1e-5);
    }
    lm_dataset_close(a);
    lm_dataset_close(b);
    remove(dark);
}

int main(void)
{
    g_ok = lm_system_default(&g_sys, &g_err) == LM_OK;
    if (!g_ok) {
        fprintf(stderr, "default system: %s\n", g_err.msg);
        return 1;
    }
    if (!mkdtemp(tmpdir)) {
        perror("mkdtemp");
        return 1;
    }
    subdir(g_posdir, sizeof g_posdir, "pos");
    snprintf(g_pospath, sizeof g_pospath, "%s/posscene.exr", g_posdir);
    write_scene(g_pospath, POS_H, POS_W, 1);
    RUN(test_group_key);
    RUN(test_split_groups_and_quotas);
    RUN(test_split_real_scenes);
    RUN(test_borrow_below_three_scenes);
    RUN(test_eval_samples_fixed);
    RUN(test_patches_on_tile_grid);
    RUN(test_flips_before_simulation);
    RUN(test_two_buckets_clean);
    RUN(test_two_buckets_noise);
    RUN(test_cave_scenes_listed);
    RUN(test_batches_deterministic);
    RUN(test_noise_levels);
    RUN(test_synthetic_share);
    RUN(test_clip_fraction);
    RUN(test_clean_fraction);
    RUN(test_lru_bound);
    RUN(test_scene_normalised);
    RUN(test_shot_and_read_noise);
    RUN(test_shot_noise_two_buckets);
    RUN(test_photon_range);
    RUN(test_spectral_augmentation);
    RUN(test_geometric_augmentation);
    RUN(test_collage);
    RUN(test_bad_input);
    rm_tree(tmpdir);
    lm_system_free(&g_sys);
    return check_summary();
}

/* test_simrun.c — a simulation run written into a folder (data/simrun.h), called as a library:
 * a 31-band cube whose size is off the tile is refused without crop (LM_ERR_SHAPE naming the
 * input) and cropped top-left with it; a static run with bucket 0 in float EXR writes bucket 1
 * equal to lm_forward_simulate31's frame and bucket 0 equal to its bucket 0 divided by
 * (LEDs - 1), the ground truth and simulate.json; a 3-frame video run calls the progress
 * callback once per frame (1/3, 2/3, 3/3) and writes every frame's files; a cube of neither 31
 * bands nor the system's grid is refused. */
#define _XOPEN_SOURCE 700 /* mkdtemp */
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>
#include "tests/check.h"
#include "data/forward.h"
#include "data/frames.h"
#include "data/simrun.h"

static lm_system g_sys;

/* 31 bands 400..700 nm, H x W, smooth positive values. */
static void make_cube(lm_cube *c, int h, int w)
{
    CHECK(lm_cube_alloc(c, 31, h, w, 400, 10) == LM_OK);
    for (int b = 0; b < 31; b++)
        for (int i = 0; i < h * w; i++)
            lm_cube_band(c, b)[i] = 0.2f + 0.5f * (float)((i * 7 + b * 3) % 17) / 17.0f;
}

static int exists(const char *dir, const char *rel)
{
    char p[512];
    struct stat st;
    snprintf(p, sizeof p, "%s/%s", dir, rel);
    return stat(p, &st) == 0;
}

static void remove_tree(const char *dir)
{
    char cmd[600];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", dir);
    CHECK(system(cmd) == 0);
}

static void test_crop(void)
{
    lm_cube in;
    make_cube(&in, 13, 18); /* tile 3 x 4: 12 x 16 */
    lm_simrun_opts o;
    lm_simrun_opts_default(&o);
    o.input = "cube13x18";
    lm_simrun r;
    lm_err e;
    lm_err_clear(&e);
    CHECK(lm_simrun_init(&r, &o, &g_sys, &in, &e) == LM_ERR_SHAPE);
    CHECK_MSG(strstr(e.msg, "cube13x18: size 13 x 18") && strstr(e.msg, "--crop"), "%s", e.msg);
    lm_simrun_free(&r);
    o.crop = 1;
    lm_err_clear(&e);
    CHECK_MSG(lm_simrun_init(&r, &o, &g_sys, &in, &e) == LM_OK, "%s", e.msg);
    CHECK(r.gt0.height == 12 && r.gt0.width == 16 && r.gt0.bands == 31);
    CHECK(r.in_height == 13 && r.in_width == 18);
    CHECK(r.gt0.data[0] == in.data[0] && lm_cube_band(&r.gt0, 30)[16 + 1] ==
                                             lm_cube_band(&in, 30)[18 + 1]);
    lm_simrun_free(&r);
    lm_cube few;
    CHECK(lm_cube_alloc(&few, 20, 6, 8, 400, 10) == LM_OK); /* neither 31 bands nor the grid */
    memset(few.data, 0, sizeof(float) * 20 * 6 * 8);
    lm_err_clear(&e);
    CHECK(lm_simrun_init(&r, &o, &g_sys, &few, &e) == LM_ERR_SHAPE);
    CHECK_MSG(strstr(e.msg, "cube13x18: 20 bands") && strstr(e.msg, "31 bands"), "%s", e.msg);
    lm_simrun_free(&r);
    lm_cube_free(&few);
    lm_cube_free(&in);
}

static void read_check(const char *dir, const char *rel, const float *want, int n, float scale)
{
    char p[512];
    lm_frame f;
    lm_err e;
    lm_err_clear(&e);
    snprintf(p, sizeof p, "%s/%s", dir, rel);
    CHECK_MSG(lm_frame_read(p, &f, &e) == LM_OK, "%s", e.msg);
    if (f.data) {
        float *w = malloc(sizeof(float) * n);
        for (int i = 0; i < n; i++) w[i] = want[i] * scale;
        CHECK_ARRAY_CLOSE(f.data, w, n, 0, 0);
        free(w);
    }
    lm_frame_free(&f);
}

static void test_static_buckets(void)
{
    lm_cube in;
    make_cube(&in, 12, 16);
    lm_simrun_opts o;
    lm_simrun_opts_default(&o);
    o.input = "cube";
    o.bucket0 = 1;
    o.format = LM_SIMRUN_EXR;
    lm_simrun r;
    lm_err e;
    lm_err_clear(&e);
    char dir[] = "/tmp/test_simrun_XXXXXX";
    CHECK(mkdtemp(dir) != NULL);
    CHECK_MSG(lm_simrun_init(&r, &o, &g_sys, &in, &e) == LM_OK, "%s", e.msg);
    CHECK_MSG(lm_simrun_write(&r, dir, &e) == LM_OK, "%s", e.msg);
    float b1[12 * 16], b0[12 * 16];
    lm_forward_opts fo = {.nthreads = 1};
    lm_rng rng;
    lm_rng_seed(&rng, 1);
    CHECK(lm_forward_simulate31(&g_sys, &in, &fo, &rng, b1, b0, &e) == LM_OK);
    read_check(dir, "frames/frame_0000.exr", b1, 12 * 16, 1.0f);
    read_check(dir, "bucket0/frame_0000.exr", b0, 12 * 16, (float)(1.0 / (g_sys.nleds - 1)));
    CHECK(exists(dir, "gt/gt_0000.exr") && exists(dir, "gt/gt_0000.png"));
    CHECK(exists(dir, "simulate.json") && !exists(dir, "frames/frame_0001.exr"));
    lm_simrun_free(&r);
    remove_tree(dir);
    lm_cube_free(&in);
}

typedef struct progress_log {
    int calls, done[8], total[8];
} progress_log;

static void progress(void *user, int done, int total)
{
    progress_log *p = user;
    if (p->calls < 8) p->done[p->calls] = done, p->total[p->calls] = total;
    p->calls++;
}

static void test_video_progress(void)
{
    lm_cube in;
    make_cube(&in, 12, 16);
    lm_simrun_opts o;
    lm_simrun_opts_default(&o);
    progress_log log = {0};
    o.input = "cube";
    o.video = 1;
    o.frames = 3;
    o.samples = 1;
    o.motion.vx = 30.0;
    o.progress = progress;
    o.user = &log;
    lm_simrun r;
    lm_err e;
    lm_err_clear(&e);
    char dir[] = "/tmp/test_simrun_XXXXXX";
    CHECK(mkdtemp(dir) != NULL);
    CHECK_MSG(lm_simrun_init(&r, &o, &g_sys, &in, &e) == LM_OK, "%s", e.msg);
    CHECK_MSG(lm_simrun_write(&r, dir, &e) == LM_OK, "%s", e.msg);
    CHECK(log.calls == 3);
    for (int i = 0; i < 3 && i < log.calls; i++) CHECK(log.done[i] == i + 1 && log.total[i] == 3);
    CHECK(exists(dir, "frames/frame_0002.png") && exists(dir, "gt/gt_0002.exr"));
    CHECK(!exists(dir, "bucket0") && !exists(dir, "frames/frame_0003.png"));
    lm_simrun_free(&r);
    remove_tree(dir);
    lm_cube_free(&in);
}

int main(void)
{
    lm_err e;
    lm_err_clear(&e);
    int ok = lm_system_default(&g_sys, &e) == LM_OK;
    CHECK_MSG(ok, "%s", e.msg);
    if (!ok) return check_summary();
    RUN(test_crop);
    RUN(test_static_buckets);
    RUN(test_video_progress);
    lm_system_free(&g_sys);
    return check_summary();
}

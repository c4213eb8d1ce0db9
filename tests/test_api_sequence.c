/* test_api_sequence.c — sequences and model choice of the public C API (include/lumosaic.h)
 * against the program: a 3-frame video of a translating CAVE scene (`lumosaic simulate --video
 * --motion`, LM_CLI: the program CTest built) reconstructed by lm_api_reconstruct_sequence with
 * alignment on equals, bit for bit, the cubes `lumosaic infer --threads 2` writes for the same
 * frames (and with alignment off, those of --no-align; the two differ); a calibrated choice
 * (lm_api_model_load_auto, a hand-written calibration of two models with a choice per bin)
 * equals `infer --model auto --auto FILE`; the bundled two-bucket model on a video with
 * bucket 0 equals `infer --model auto` (bucket 0 found beside frames/, no alignment); errors:
 * NULL arguments, zero frames, frames of different sizes, a small buffer, a bad calibration,
 * bad bucket counts (a status and a one-line message, no crash).
 * What it is not: the single-frame API (test_api.c) or alignment's accuracy
 * (test_align_infer.c). */
#include <stdint.h>
#include <stdlib.h>
#include <unistd.h>
#include "include/lumosaic.h"
#include "check.h"
#include "shared_dir.h"
#include "data/frames.h"

#define MODEL_REL "models/demo/rt16nc-lmmse.safetensors"
#define NF 3

static char tmpdir[] = "/tmp/lm_test_api_seq_XXXXXX";
static const char *cli;
static char model[1200]; /* MODEL_REL from the source folder, absolute */
static lm_frame frames[NF];

/* `lumosaic ARGS` in the test's folder (relative paths), stderr to `err` (a file there). */
static int lm(const char *args, const char *err)
{
    char cmd[4096];
    snprintf(cmd, sizeof cmd, "cd '%s' && '%s' %s > /dev/null 2> '%s'", tmpdir, cli, args, err);
    return system(cmd);
}

/* The cube `lumosaic infer` wrote as DIR/cube_000i.exr equals cube (31 x H x W). */
static int same_as_written(const char *dir, int i, const float *cube)
{
    char path[1200];
    snprintf(path, sizeof path, "%s/%s/cube_%04d.exr", tmpdir, dir, i);
    lm_api_cube *c = NULL;
    lm_api_error err;
    if (lm_api_cube_read(path, NULL, &c, &err) != LM_API_OK) {
        CHECK_MSG(0, "%s", err.message);
        return 0;
    }
    int bands = 0, h = 0, w = 0;
    lm_api_cube_shape(c, &bands, &h, &w, NULL);
    int same = bands == 31 && h == frames[0].height && w == frames[0].width &&
               !memcmp(lm_api_cube_data(c), cube, sizeof(float) * 31 * h * w);
    lm_api_cube_free(c);
    return same;
}

static void api_frames(lm_api_frame *f)
{
    for (int i = 0; i < NF; i++)
        f[i] = (lm_api_frame){frames[i].height, frames[i].width, LM_API_PIXEL_F32,
                              frames[i].data, NULL};
}

static void test_sequence_as_infer(void)
{
    char args[1400], cmd[1200];
    snprintf(args, sizeof args, "infer --model '%s' --input mv/frames --output al --threads 2",
             model);
    CHECK(lm(args, "al.err") == 0);
    snprintf(cmd, sizeof cmd, "grep -q 'alignment [0-9]' '%s/al.err'", tmpdir);
    CHECK(system(cmd) == 0); /* aligned */
    snprintf(args, sizeof args, "infer --model '%s' --input mv/frames --output na --threads 2 "
             "--no-align", model);
    CHECK(lm(args, "na.err") == 0);
    lm_api_error err;
    lm_api_model *m = NULL;
    CHECK_MSG(lm_api_model_load(model, NULL, &m, &err) == LM_API_OK, "%s", err.message);
    if (!m) return;
    CHECK(lm_api_model_set_threads(m, 2, &err) == LM_API_OK);
    const size_t nc = (size_t)31 * frames[0].height * frames[0].width;
    float *a = malloc(sizeof(float) * NF * nc), *b = malloc(sizeof(float) * NF * nc);
    float wl[31] = {0};
    lm_api_frame f[NF];
    api_frames(f);
    CHECK_MSG(lm_api_reconstruct_sequence(m, f, NF, 1, a, NF * nc, wl, &err) == LM_API_OK,
              "%s", err.message);
    CHECK_MSG(lm_api_reconstruct_sequence(m, f, NF, 0, b, NF * nc, NULL, &err) == LM_API_OK,
              "%s", err.message);
    CHECK(wl[0] == 400.0f && wl[30] == 700.0f);
    for (int i = 0; i < NF; i++) {
        CHECK_MSG(same_as_written("al", i, a + i * nc), "aligned frame %d", i);
        CHECK_MSG(same_as_written("na", i, b + i * nc), "unaligned frame %d", i);
    }
    CHECK(memcmp(a + nc, b + nc, sizeof(float) * nc) != 0); /* alignment moved frame 1 */
    /* again on the same model: the same cubes (no state left from the first sequence) */
    CHECK(lm_api_reconstruct_sequence(m, f, NF, 1, b, NF * nc, NULL, &err) == LM_API_OK);
    CHECK(!memcmp(a, b, sizeof(float) * NF * nc));
    /* errors */
    CHECK(lm_api_reconstruct_sequence(NULL, f, NF, 1, a, NF * nc, NULL, &err) == LM_API_ERR_ARG);
    CHECK(strstr(err.message, "model") != NULL);
    CHECK(lm_api_reconstruct_sequence(m, f, 0, 1, a, NF * nc, NULL, &err) == LM_API_ERR_ARG);
    CHECK(lm_api_reconstruct_sequence(m, f, NF, 1, a, NF * nc - 1, NULL, &err) ==
          LM_API_ERR_SHAPE && strstr(err.message, "buffer") != NULL);
    int tr = 0;
    lm_api_model_info(m, NULL, NULL, &tr, NULL, &err);
    f[2].height -= tr; /* still a multiple of the tile */
    CHECK(lm_api_reconstruct_sequence(m, f, NF, 1, a, NF * nc, NULL, &err) == LM_API_ERR_SHAPE);
    CHECK_MSG(strstr(err.message, "frame 2") != NULL, "%s", err.message);
    f[2].height += tr;
    f[1].bucket1 = NULL;
    CHECK(lm_api_reconstruct_sequence(m, f, NF, 1, a, NF * nc, NULL, &err) == LM_API_ERR_ARG);
    CHECK_MSG(strstr(err.message, "frame 1") != NULL, "%s", err.message);
    free(a), free(b);
    lm_api_model_free(m);
}

/* Two models (the same weights twice) and two bins: the cheap one where it is as good. */
static void write_calibration(const char *path)
{
    FILE *f = fopen(path, "w");
    if (!f) return;
    fprintf(f, "{\"version\": 1, \"measure\": \"grad\", \"window\": [66, 64], \"stride\": [30, "
            "32], \"edges\": [0.02], \"windows\": [10, 10], \"models\": ["
            "{\"model\": \"%s\", \"preset\": \"rt-16-nc+lmmse\", \"cost_s_per_window\": 1, "
            "\"macs_per_window\": 1, \"psnr\": [30, 40]},"
            "{\"model\": \"%s\", \"preset\": \"rt-16-nc+lmmse\", \"cost_s_per_window\": 2, "
            "\"macs_per_window\": 2, \"psnr\": [40, 40]}]}\n", model, model);
    fclose(f);
}

static void test_auto_as_infer(void)
{
    char calib[1100];
    snprintf(calib, sizeof calib, "%s/auto.json", tmpdir);
    write_calibration(calib);
    CHECK(lm("infer --model auto --auto auto.json --input mv/frames/frame_0000.png --output auto "
             "--threads 2", "auto.err") == 0);
    lm_api_error err;
    lm_api_model *m = NULL;
    CHECK_MSG(lm_api_model_load_auto(calib, 0.5, NULL, &m, &err) == LM_API_OK, "%s",
              err.message);
    if (!m) return;
    const char *preset = NULL;
    CHECK(lm_api_model_info(m, &preset, NULL, NULL, NULL, &err) == LM_API_OK);
    CHECK(preset && !strcmp(preset, "auto"));
    CHECK(lm_api_model_set_threads(m, 2, &err) == LM_API_OK);
    const size_t nc = (size_t)31 * frames[0].height * frames[0].width;
    float *a = malloc(sizeof(float) * nc);
    lm_api_frame f[NF];
    api_frames(f);
    CHECK_MSG(lm_api_reconstruct(m, &f[0], a, nc, NULL, &err) == LM_API_OK, "%s", err.message);
    CHECK(same_as_written("auto", 0, a));
    CHECK(lm_api_reconstruct_sequence(m, f, 1, 1, a, nc, NULL, &err) == LM_API_OK);
    CHECK(same_as_written("auto", 0, a));
    free(a);
    lm_api_model_free(m);
    m = (lm_api_model *)1;
    CHECK(lm_api_model_load_auto(calib, -1.0, NULL, &m, &err) == LM_API_ERR_ARG && !m);
    CHECK(lm_api_model_load_auto(NULL, 0.5, NULL, &m, &err) == LM_API_ERR_ARG);
    CHECK(lm_api_model_load_auto("/nonexistent/auto.json", 0.5, NULL, &m, &err) ==
          LM_API_ERR_IO && strstr(err.message, "/nonexistent/auto.json") != NULL);
}

/* The bundled two-bucket model on a 2-frame video with bucket 0: infer --model auto's cubes
 * (unaligned: bucket 0 is not aligned in time). */
static void test_bundled(void)
{
    lm_api_error err;
    lm_api_model *m = (lm_api_model *)1;
    CHECK(lm_api_model_load_bundled(3, NULL, &m, &err) == LM_API_ERR_ARG && !m);
    CHECK(lm_api_model_load_bundled(1, NULL, NULL, &err) == LM_API_ERR_ARG);
    CHECK(lm_api_model_load("auto", NULL, &m, &err) == LM_API_ERR_ARG && !m);
    int buckets = 0;
    CHECK_MSG(lm_api_model_load_bundled(2, NULL, &m, &err) == LM_API_OK, "%s", err.message);
    if (!m) return;
    CHECK(lm_api_model_info(m, NULL, &buckets, NULL, NULL, &err) == LM_API_OK && buckets == 2);
    CHECK(lm_api_model_set_threads(m, 2, &err) == LM_API_OK);
    lm_api_frame f[2];
    lm_frame b1[2] = {{0}}, b0[2] = {{0}};
    lm_err e;
    lm_err_clear(&e);
    for (int i = 0; i < 2; i++) {
        char path[1200];
        snprintf(path, sizeof path, "%s/b2/frames/frame_%04d.png", tmpdir, i);
        CHECK_MSG(lm_frame_read(path, &b1[i], &e) == LM_OK, "%s", e.msg);
        snprintf(path, sizeof path, "%s/b2/bucket0/frame_%04d.png", tmpdir, i);
        CHECK_MSG(lm_frame_read(path, &b0[i], &e) == LM_OK, "%s", e.msg);
        f[i] = (lm_api_frame){b1[i].height, b1[i].width, LM_API_PIXEL_F32, b1[i].data,
                              b0[i].data};
    }
    const size_t nc = (size_t)31 * b1[0].height * b1[0].width;
    float *a = malloc(sizeof(float) * 2 * nc);
    if (b1[1].data && b0[1].data) {
        CHECK_MSG(lm_api_reconstruct_sequence(m, f, 2, 1, a, 2 * nc, NULL, &err) == LM_API_OK,
                  "%s", err.message);
        for (int i = 0; i < 2; i++) CHECK_MSG(same_as_written("b2o", i, a + i * nc), "%d", i);
        f[1].bucket0 = NULL;
        CHECK(lm_api_reconstruct_sequence(m, f, 2, 1, a, 2 * nc, NULL, &err) == LM_API_ERR_ARG);
        CHECK_MSG(strstr(err.message, "frame 1") && strstr(err.message, "bucket0"), "%s",
                  err.message);
    }
    free(a);
    for (int i = 0; i < 2; i++) lm_frame_free(&b1[i]), lm_frame_free(&b0[i]);
    lm_api_model_free(m);
}

int main(void)
{
    char cave[1024];
    snprintf(cave, sizeof cave, "%s/data/cave/balloons_crop100", shared_dir());
    cli = getenv("LM_CLI");
    if (!cli || access(cave, R_OK) != 0) {
        fprintf(stderr, "skipped: %s\n", cli ? "no CAVE scene" : "LM_CLI is not set");
        return 77;
    }
    char cwd[1024];
    if (!getcwd(cwd, sizeof cwd) || !mkdtemp(tmpdir)) return 1;
    snprintf(model, sizeof model, "%s/%s", cwd, MODEL_REL);
    char args[1200];
    snprintf(args, sizeof args, "simulate --input '%s' --output mv --crop --video --frames 3 "
             "--motion translate:150,-60", cave);
    CHECK(lm(args, "sim.err") == 0);
    snprintf(args, sizeof args, "simulate --input '%s' --output b2 --crop --video --frames 2 "
             "--bucket0", cave);
    CHECK(lm(args, "sim2.err") == 0);
    CHECK(lm("infer --model auto --input b2/frames --output b2o --threads 2", "b2o.err") == 0);
    lm_err e;
    for (int i = 0; i < NF; i++) {
        char path[1200];
        lm_err_clear(&e);
        snprintf(path, sizeof path, "%s/mv/frames/frame_%04d.png", tmpdir, i);
        CHECK_MSG(lm_frame_read(path, &frames[i], &e) == LM_OK, "%s", e.msg);
    }
    if (frames[NF - 1].data) {
        RUN(test_sequence_as_infer);
        RUN(test_auto_as_infer);
        RUN(test_bundled);
    }
    for (int i = 0; i < NF; i++) lm_frame_free(&frames[i]);
    char cmd[1200];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", tmpdir);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", tmpdir);
    return check_summary();
}

/* test_tile.c — patch-wise inference (infer/tile.h) and model loading (infer/model_io.h):
 * window grid on 480 x 640 (count, grid alignment, flush edges, coverage), the weighting kernel,
 * exact folds of constant and identity "networks", patch-wise = whole-image for the linear model
 * away from interior window borders, determinism across batch sizes, errors; load of a saved
 * linear model (weights round trip, missing / foreign / mismatched files). */
#include "data/spectra.h"
#include "infer/model_io.h"
#include "infer/tile.h"
#include "tests/check.h"
#include "tests/model_fixture.h"
#include "train/train.h"
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

static void test_positions_480x640(void)
{
    int ys[64], xs[64];
    int ny = lm_tile_positions(480, 66, 30, ys, 64), nx = lm_tile_positions(640, 64, 32, xs, 64);
    /* regular rows 0..390 (14), then 414 flush with the bottom; columns 0..576 (19) end at 640 */
    CHECK(ny == 15);
    CHECK(nx == 19);
    CHECK(ys[13] == 390 && ys[14] == 414);
    CHECK(xs[18] == 576);
    for (int i = 0; i < ny; i++) CHECK(ys[i] % 3 == 0);
    for (int i = 0; i < nx; i++) CHECK(xs[i] % 4 == 0);
    for (int i = 1; i < ny; i++) CHECK(ys[i] > ys[i - 1]);
    static unsigned char cov[480][640];
    memset(cov, 0, sizeof cov);
    for (int a = 0; a < ny; a++)
        for (int b = 0; b < nx; b++)
            for (int i = 0; i < 66; i++)
                for (int j = 0; j < 64; j++) cov[ys[a] + i][xs[b] + j] = 1;
    long covered = 0;
    for (int y = 0; y < 480; y++)
        for (int x = 0; x < 640; x++) covered += cov[y][x];
    CHECK(covered == 480L * 640);
    /* the cropped CAVE size 99 x 100: rows 0, 30 then 33 flush; columns 0, 32 then 36 flush */
    CHECK(lm_tile_positions(99, 66, 30, ys, 64) == 3 && ys[2] == 33);
    CHECK(lm_tile_positions(100, 64, 32, xs, 64) == 3 && xs[1] == 32 && xs[2] == 36);
    CHECK(lm_tile_positions(66, 66, 30, ys, 64) == 1 && ys[0] == 0);
}

static void test_kernel(void)
{
    float k[66];
    lm_tile_kernel_1d(66, k);
    CHECK_CLOSE(k[32], k[33], 1e-7, 0);
    CHECK(k[32] > 0.99f);
    CHECK(k[0] > 0.0f && k[0] < 0.06f);
    for (int i = 0; i < 33; i++) CHECK(k[i] == k[65 - i]);
    for (int i = 1; i < 33; i++) CHECK(k[i] > k[i - 1]);
}

/* "Networks" for the fold. */
static lm_tensor *const_fn(lm_ctx *c, lm_tensor *raw, void *user)
{
    (void)user;
    int s[4] = {raw->shape[0], 2, raw->shape[2], raw->shape[3]};
    lm_tensor *y = lm_tensor_new(c, 4, s);
    long plane = (long)s[2] * s[3];
    for (int b = 0; b < s[0]; b++)
        for (long p = 0; p < plane; p++) {
            y->data[(b * 2 + 0) * plane + p] = 1.0f;
            y->data[(b * 2 + 1) * plane + p] = 0.25f;
        }
    return y;
}

static lm_tensor *identity_fn(lm_ctx *c, lm_tensor *raw, void *user)
{
    (void)c;
    (void)user;
    return raw;
}

static lm_tensor *bad_shape_fn(lm_ctx *c, lm_tensor *raw, void *user)
{
    (void)user;
    return lm_tensor_new4(c, raw->shape[0], 1, raw->shape[2] - 3, raw->shape[3]);
}

static lm_tensor *failing_fn(lm_ctx *c, lm_tensor *raw, void *user)
{
    (void)raw;
    (void)user;
    lm_ctx_fail(c, LM_ERR_NUMERIC, "fakenet: exploded");
    return NULL;
}

static float *random_frame(int H, int W, uint64_t seed)
{
    lm_rng r;
    lm_rng_seed(&r, seed);
    float *f = malloc(sizeof(float) * H * W);
    for (int i = 0; i < H * W; i++) f[i] = lm_rng_uniform(&r);
    return f;
}

static void test_fold_constant_and_identity(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_tile_opts o;
    lm_tile_default_opts(&o);
    o.batch = 5;
    const int H = 159, W = 200;
    float *frame = random_frame(H, W, 3), *out = malloc(sizeof(float) * 2 * H * W);
    lm_err e = {0};
    CHECK(lm_tile_fold(&c, frame, H, W, 3, 4, &o, const_fn, NULL, 2, out, &e) == LM_OK);
    long bad = 0;
    for (int p = 0; p < H * W; p++) bad += out[p] != 1.0f || out[H * W + p] != 0.25f;
    CHECK_MSG(bad == 0, "%ld pixels of the constant fold differ", bad);
    CHECK(lm_tile_fold(&c, frame, H, W, 3, 4, &o, identity_fn, NULL, 1, out, &e) == LM_OK);
    CHECK_ARRAY_CLOSE(out, frame, H * W, 1e-6, 1e-6);
    CHECK(c.grad_enabled == 1);
    free(frame);
    free(out);
    lm_ctx_free(&c);
}

/* Distance from (y, x) to the nearest border of window (y0, x0) that is not on the frame edge. */
static int interior_dist(int y, int x, int y0, int x0, int wh, int ww, int H, int W)
{
    int d = 1 << 20;
    if (y0 > 0 && y - y0 < d) d = y - y0;
    if (y0 + wh < H && y0 + wh - 1 - y < d) d = y0 + wh - 1 - y;
    if (x0 > 0 && x - x0 < d) d = x - x0;
    if (x0 + ww < W && x0 + ww - 1 - x < d) d = x0 + ww - 1 - x;
    return d;
}

/* Pixels whose distance to every covering window's interior border is > 4 px. */
static unsigned char *safe_mask(int H, int W, const lm_tile_opts *o, long *count)
{
    int ys[64], xs[64];
    int ny = lm_tile_positions(H, o->win_h, o->stride_y, ys, 64);
    int nx = lm_tile_positions(W, o->win_w, o->stride_x, xs, 64);
    unsigned char *m = malloc((size_t)H * W);
    *count = 0;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            int ok = 1;
            for (int a = 0; a < ny; a++)
                for (int b = 0; b < nx; b++)
                    if (y >= ys[a] && y < ys[a] + o->win_h && x >= xs[b] && x < xs[b] + o->win_w &&
                        interior_dist(y, x, ys[a], xs[b], o->win_h, o->win_w, H, W) <= 4)
                        ok = 0;
            m[y * W + x] = (unsigned char)ok;
            *count += ok;
        }
    return m;
}

static void test_linear_patchwise_equals_whole(void)
{
    lm_err e = {0};
    lm_model *m = lm_model_create("linear", NULL, 5, &e);
    CHECK_MSG(m != NULL, "%s", e.msg);
    if (!m) return;
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_tile_opts o;
    lm_tile_default_opts(&o);
    const int H = 159, W = 200;
    float *frame = random_frame(H, W, 9);
    lm_cube cube;
    CHECK(lm_tile_infer(&c, m, frame, H, W, &o, &cube, &e) == LM_OK);
    CHECK(cube.bands == 31 && cube.height == H && cube.width == W);
    CHECK(cube.wavelength[0] == 400.0f && cube.wavelength[30] == 700.0f);
    lm_ctx_set_grad(&c, 0);
    lm_tensor *whole = lm_model_forward(&c, m, lm_tensor_from(&c, 4, (int[]){1, 1, H, W}, frame));
    CHECK_CTX_OK(&c);
    long n_safe = 0, n_bad = 0, n_edge_diff = 0;
    unsigned char *safe = safe_mask(H, W, &o, &n_safe);
    CHECK(n_safe > H * W / 3);
    for (int b = 0; b < 31 && whole; b++)
        for (int p = 0; p < H * W; p++) {
            float d = fabsf(cube.data[(size_t)b * H * W + p] - whole->data[(size_t)(b + 1) * H * W + p]);
            if (safe[p]) n_bad += d > 1e-5f;
            else n_edge_diff += d > 1e-5f;
        }
    CHECK_MSG(n_bad == 0, "%ld safe pixel values differ from the whole-image forward", n_bad);
    /* near interior window borders the demosaic does differ: the comparison is not vacuous */
    CHECK(n_edge_diff > 0);
    free(safe);
    free(frame);
    lm_cube_free(&cube);
    lm_ctx_free(&c);
    lm_model_free(m);
}

/* Infer with each batch size; bitwise equal to the first when tol == 0, else within tol. */
static void run_batches(const char *preset, int nthreads, double tol, int H, int W, int nb,
                        const int *batches)
{
    lm_err e = {0};
    lm_model *m = lm_model_create(preset, NULL, 11, &e);
    CHECK_MSG(m != NULL, "%s: %s", preset, e.msg);
    if (!m) return;
    lm_ctx c;
    lm_ctx_init(&c, nthreads);
    lm_tile_opts o;
    lm_tile_default_opts(&o);
    float *frame = random_frame(H, W, 13);
    lm_cube ref = {0}, got;
    for (int i = 0; i < nb; i++) {
        o.batch = batches[i];
        CHECK(lm_tile_infer(&c, m, frame, H, W, &o, i ? &got : &ref, &e) == LM_OK);
        if (!i) continue;
        double md = 0;
        for (long p = 0; got.data && p < 31L * H * W; p++)
            md = fmax(md, fabs(got.data[p] - ref.data[p]));
        int same = got.data && !memcmp(got.data, ref.data, sizeof(float) * 31 * H * W);
        CHECK_MSG(tol > 0 ? got.data && md <= tol : same, "%s, %d threads: batch %d differs "
                  "from batch %d (max %g)", preset, nthreads, batches[i], batches[0], md);
        lm_cube_free(&got);
    }
    lm_cube_free(&ref);
    free(frame);
    lm_ctx_free(&c);
    lm_model_free(m);
}

static void test_determinism_across_batches(void)
{
    run_batches("linear", 2, 0, 159, 200, 4, (int[]){1, 2, 7, 64});
    /* mcan-tiny's kernels round differently for different batch sizes (a few 1e-7: the fold is
     * not the cause — linear is bitwise above): bitwise per batch size, close across them */
    run_batches("mcan-tiny", 2, 0, 99, 100, 2, (int[]){4, 4});
    run_batches("mcan-tiny", 1, 1e-5, 99, 100, 3, (int[]){1, 4, 9});
    run_batches("mcan-tiny", 2, 1e-5, 99, 100, 3, (int[]){1, 4, 9});
}

/* Frames smaller than the 66 x 64 window (down to 3 x 3 tiles): every coded-frame family
 * reconstructs them (the window cut to the frame), finite; the per-phase linear model equals
 * its whole-frame result there too. */
static void test_small_frames(void)
{
    static const char *presets[] = {"linear",      "lmmse",     "lmmse-rf",   "han-tiny-nc",
                                    "mcan-tiny",   "srnet-tiny", "rt-16-nc",  "tn-96-nc",
                                    "lmmse-b2",    "lmmse-gri-b2", "rt-16-b2", "tn-96-nc-b2",
                                    "tn-160-nc-b2", "rt-8-mf3"};
    static const int sizes[][2] = {{9, 12}, {30, 32}, {63, 64}, {66, 40}, {21, 200}};
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_mosaic mo;
    test_mosaic(&mo); /* srnet reads the LED responses */
    for (size_t i = 0; i < sizeof presets / sizeof *presets; i++) {
        lm_err e = {0};
        lm_model *m = lm_model_create(presets[i], &mo, 7, &e);
        CHECK_MSG(m != NULL, "%s: %s", presets[i], e.msg);
        if (!m) continue;
        const int planes = lm_model_coded_planes(m);
        for (size_t s = 0; s < sizeof sizes / sizeof *sizes; s++) {
            const int H = sizes[s][0], W = sizes[s][1];
            float *frame = random_frame(planes * H, W, 5 + s);
            lm_tile_opts o;
            lm_tile_default_opts(&o);
            lm_cube cube = {0};
            lm_err_clear(&e);
            lm_status st = lm_tile_infer(&c, m, frame, H, W, &o, &cube, &e);
            CHECK_MSG(st == LM_OK, "%s on a %d x %d frame: %s", presets[i], H, W, e.msg);
            size_t bad = 0;
            for (long p = 0; cube.data && p < 31L * H * W; p++) bad += !isfinite(cube.data[p]);
            CHECK_MSG(st || (cube.height == H && cube.width == W && bad == 0),
                      "%s on a %d x %d frame: %zu values not finite", presets[i], H, W, bad);
            if (!st && !strcmp(presets[i], "linear") && H <= o.win_h && W <= o.win_w) {
                lm_cube whole = {0};
                lm_tile_opts big = o;
                big.win_h = H, big.win_w = W;
                CHECK(lm_tile_infer(&c, m, frame, H, W, &big, &whole, &e) == LM_OK);
                CHECK(whole.data && !memcmp(whole.data, cube.data, sizeof(float) * 31 * H * W));
                lm_cube_free(&whole);
            }
            lm_cube_free(&cube);
            free(frame);
        }
        lm_model_free(m);
    }
    lm_ctx_free(&c);
}

static void test_errors(void)
{
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tile_opts o;
    lm_tile_default_opts(&o);
    float *frame = random_frame(99, 100, 1), out[99 * 100];
    lm_err e = {0};
    CHECK(lm_tile_fold(&c, frame, 98, 100, 3, 4, &o, identity_fn, NULL, 1, out, &e) == LM_ERR_SHAPE);
    CHECK(strstr(e.msg, "tile:") && strstr(e.msg, "multiple"));
    lm_err_clear(&e);
    CHECK(lm_tile_fold(&c, frame, 6, 100, 3, 4, &o, identity_fn, NULL, 1, out, &e) == LM_ERR_SHAPE);
    CHECK_MSG(strstr(e.msg, "smaller than 3 x 3 mosaic tiles (9x12)"), "%s", e.msg);
    lm_err_clear(&e);
    CHECK(lm_tile_fold(&c, frame, 99, 8, 3, 4, &o, identity_fn, NULL, 1, out, &e) == LM_ERR_SHAPE);
    lm_err_clear(&e);
    /* a frame smaller than the window: one window covers it there */
    CHECK_MSG(lm_tile_fold(&c, frame, 63, 100, 3, 4, &o, identity_fn, NULL, 1, out, &e) == LM_OK,
              "%s", e.msg);
    CHECK_ARRAY_CLOSE(out, frame, 63 * 100, 1e-6, 1e-6);
    lm_err_clear(&e);
    o.stride_y = 31;
    CHECK(lm_tile_fold(&c, frame, 99, 100, 3, 4, &o, identity_fn, NULL, 1, out, &e) == LM_ERR_ARG);
    CHECK(strstr(e.msg, "multiples of the 3x4"));
    lm_err_clear(&e);
    lm_tile_default_opts(&o);
    o.batch = 0;
    CHECK(lm_tile_fold(&c, frame, 99, 100, 3, 4, &o, identity_fn, NULL, 1, out, &e) == LM_ERR_ARG);
    lm_err_clear(&e);
    o.batch = 2;
    CHECK(lm_tile_fold(&c, frame, 99, 100, 3, 4, &o, bad_shape_fn, NULL, 1, out, &e) == LM_ERR_SHAPE);
    CHECK(strstr(e.msg, "network returned"));
    lm_err_clear(&e);
    CHECK(lm_tile_fold(&c, frame, 99, 100, 3, 4, &o, failing_fn, NULL, 1, out, &e) == LM_ERR_NUMERIC);
    CHECK(strstr(e.msg, "fakenet: exploded"));
    CHECK(lm_ctx_status(&c) == LM_OK);
    free(frame);
    lm_ctx_free(&c);
}

/* Save a linear model as the trainer does (preset, system, system_hash metadata). */
static int save_model(const char *path, const char *preset, const char *sys, const char *hash,
                      lm_model **out)
{
    lm_err e = {0};
    lm_model *m = lm_model_create("linear", NULL, 21, &e);
    if (!m) return -1;
    const char *meta[] = {"format", "lumosaic-checkpoint-1", "preset", preset, "system", sys,
                          "system_hash", hash};
    int st = lm_params_save(&m->params, path, meta, 4, &e);
    if (out) *out = m;
    else lm_model_free(m);
    return st;
}

static void test_model_io(void)
{
    char dir[] = "/tmp/lm_test_tile_XXXXXX", path[256], hash[32], def[1024];
    CHECK(mkdtemp(dir) != NULL);
    lm_err e = {0};
    CHECK(lm_data_path("systems/default.json", def, sizeof def, &e) == LM_OK);
    snprintf(hash, sizeof hash, "%016llx", (unsigned long long)lm_file_hash(def));
    snprintf(path, sizeof path, "%s/model.safetensors", dir);
    lm_model *ref = NULL;
    CHECK(save_model(path, "linear", "", hash, &ref) == 0);
    lm_infer_model im;
    CHECK_MSG(lm_infer_model_load(dir, NULL, &im, &e) == LM_OK, "%s", e.msg);
    if (im.model && ref) {
        CHECK(!strcmp(im.model->preset, "linear"));
        CHECK(im.model->params.total == ref->params.total);
        CHECK(!memcmp(im.model->params.data, ref->params.data,
                      sizeof(float) * ref->params.total));
        CHECK(im.sys.tile_rows == 3 && im.sys.tile_cols == 4);
    }
    lm_infer_model_free(&im);
    CHECK(lm_infer_model_load(path, def, &im, &e) == LM_OK);
    lm_infer_model_free(&im);
    lm_err_clear(&e);
    CHECK(lm_infer_model_load("/nonexistent/run", NULL, &im, &e) == LM_ERR_IO);
    CHECK(strstr(e.msg, "no such model") != NULL);
    lm_err_clear(&e);
    CHECK(save_model(path, "linear", "", "0123456789abcdef", NULL) == 0);
    CHECK(lm_infer_model_load(path, NULL, &im, &e) == LM_ERR_ARG);
    CHECK(strstr(e.msg, "model/system mismatch") != NULL);
    lm_err_clear(&e);
    CHECK(save_model(path, "mcan-tiny", "", hash, NULL) == 0);
    CHECK(lm_infer_model_load(path, NULL, &im, &e) != LM_OK);
    CHECK(strstr(e.msg, "mismatch or bad weights") != NULL);
    lm_err_clear(&e);
    lm_params_save(&ref->params, path, NULL, 0, &e);
    CHECK(lm_infer_model_load(path, NULL, &im, &e) == LM_ERR_FORMAT);
    CHECK(strstr(e.msg, "no 'preset'") != NULL);
    lm_model_free(ref);
    unlink(path);
    rmdir(dir);
}

int main(void)
{
    RUN(test_positions_480x640);
    RUN(test_kernel);
    RUN(test_fold_constant_and_identity);
    RUN(test_linear_patchwise_equals_whole);
    RUN(test_determinism_across_batches);
    RUN(test_small_frames);
    RUN(test_errors);
    RUN(test_model_io);
    return check_summary();
}

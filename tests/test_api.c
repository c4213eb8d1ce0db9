/* test_api.c — the public C API (include/lumosaic.h) against the library paths the commands
 * take: the bundled demo model on the CAVE scene cd_256 (LM_SHARED_DIR), a frame simulated by
 * lm_api_simulate equal to eval's (lm_eval_simulate), the reconstruction's PSNR within 0.01 dB
 * of eval's (lm_eval_reconstruct on the whole frame, as `lumosaic infer` runs this model;
 * unclamped as eval scores it, and clamped at 0 bit for bit equal to eval's cube clamped), a
 * 16-bit frame equal bit for bit to what `lumosaic infer` computes from that frame written as
 * a PNG (lm_frame_write, lm_frame_read, lm_recon_frame, clamp), caller-owned and library-owned
 * cubes, threads, bf16 precision, the sRGB preview, a cube round trip through EXR, and errors:
 * missing and corrupt files, NULL arguments, wrong buffers and frames (a status and a message,
 * no crash). */
#include <math.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include "include/lumosaic.h"
#include "check.h"
#include "shared_dir.h"
#include "data/cube_io.h"
#include "data/frames.h"
#include "data/srgb.h"
#include "infer/eval.h"
#include "infer/recon.h"

#define MODEL "models/demo/rt16nc-lmmse.safetensors"

static char tmpdir[] = "/tmp/lm_test_api_XXXXXX";
static char scene[1024];

static void test_version(void)
{
    int a = -1, b = -1, c = -1;
    const char *s = lm_api_version(&a, &b, &c);
    CHECK(a == LM_API_VERSION_MAJOR && b == LM_API_VERSION_MINOR && c == LM_API_VERSION_PATCH);
    char want[32];
    snprintf(want, sizeof want, "%d.%d.%d", a, b, c);
    CHECK(s && !strcmp(s, want));
    CHECK(!strcmp(lm_api_status_str(LM_API_OK), "ok"));
    CHECK(lm_api_status_str(LM_API_ERR_IO)[0] != 0);
}

static void test_null_arguments(void)
{
    lm_api_error err;
    lm_api_model *m = (lm_api_model *)1;
    lm_api_cube *c = (lm_api_cube *)1;
    lm_api_system *s = (lm_api_system *)1;
    CHECK(lm_api_model_load(NULL, NULL, &m, &err) == LM_API_ERR_ARG && m == NULL);
    CHECK(strstr(err.message, "path") != NULL);
    CHECK(lm_api_model_load(MODEL, NULL, NULL, &err) == LM_API_ERR_ARG);
    CHECK(lm_api_cube_read(NULL, NULL, &c, &err) == LM_API_ERR_ARG && c == NULL);
    CHECK(lm_api_cube_read(scene, NULL, NULL, NULL) == LM_API_ERR_ARG); /* err NULL too */
    CHECK(lm_api_system_load(NULL, NULL, &err) == LM_API_ERR_ARG);
    CHECK(lm_api_system_info(NULL, NULL, NULL, NULL, &err) == LM_API_ERR_ARG);
    CHECK(lm_api_cube_write(NULL, NULL, &err) == LM_API_ERR_ARG);
    CHECK(lm_api_cube_shape(NULL, NULL, NULL, NULL, &err) == LM_API_ERR_ARG);
    CHECK(lm_api_cube_data(NULL) == NULL && lm_api_cube_wavelengths(NULL) == NULL);
    CHECK(lm_api_cube_crop(NULL, 0, 0, 1, 1, &c, &err) == LM_API_ERR_ARG && c == NULL);
    float buf[16];
    CHECK(lm_api_simulate(NULL, NULL, NULL, 0, 0, buf, NULL, 16, &err) == LM_API_ERR_ARG);
    CHECK(lm_api_reconstruct(NULL, NULL, buf, 16, NULL, &err) == LM_API_ERR_ARG);
    CHECK(strstr(err.message, "model") != NULL);
    CHECK(lm_api_reconstruct_cube(NULL, NULL, &c, &err) == LM_API_ERR_ARG && c == NULL);
    CHECK(lm_api_model_info(NULL, NULL, NULL, NULL, NULL, &err) == LM_API_ERR_ARG);
    CHECK(lm_api_model_set_threads(NULL, 1, &err) == LM_API_ERR_ARG);
    CHECK(lm_api_model_set_noise_level(NULL, 0.1, &err) == LM_API_ERR_ARG);
    CHECK(lm_api_model_set_patchwise(NULL, 1, &err) == LM_API_ERR_ARG);
    lm_api_metrics mt;
    CHECK(lm_api_metrics_compute(NULL, buf, 1, 4, 4, &mt, &err) == LM_API_ERR_ARG);
    lm_api_model_free(NULL), lm_api_cube_free(NULL), lm_api_system_free(NULL);
    (void)s;
}

static void test_bad_files(void)
{
    lm_api_error err;
    lm_api_model *m = NULL;
    CHECK(lm_api_model_load("/nonexistent/model.safetensors", NULL, &m, &err) != LM_API_OK);
    CHECK(m == NULL && err.status != LM_API_OK && strstr(err.message, "/nonexistent") != NULL);
    char bad[1100];
    snprintf(bad, sizeof bad, "%s/bad.safetensors", tmpdir);
    FILE *f = fopen(bad, "wb");
    CHECK(f != NULL);
    if (f) fputs("\x10\x00\x00\x00\x00\x00\x00\x00{not json at all", f), fclose(f);
    CHECK(lm_api_model_load(bad, NULL, &m, &err) == LM_API_ERR_FORMAT && m == NULL);
    CHECK(strstr(err.message, "bad.safetensors") != NULL);
    lm_api_cube *c = NULL;
    CHECK(lm_api_cube_read("/nonexistent/cube.exr", NULL, &c, &err) == LM_API_ERR_IO);
    CHECK(c == NULL && strstr(err.message, "cube.exr") != NULL);
    CHECK(lm_api_cube_read(bad, NULL, &c, &err) == LM_API_ERR_UNSUPPORTED && c == NULL);
    lm_api_system *s = NULL;
    CHECK(lm_api_system_load(bad, &s, &err) != LM_API_OK && s == NULL && err.message[0]);
}

/* The scene as eval prepares it (cropped to the tile, divided by its maximum) through the API,
 * checked against lm_eval_prepare. */
static lm_api_cube *prepared_scene(lm_cube *ref)
{
    lm_api_error err;
    lm_api_cube *raw = NULL, *c = NULL;
    lm_api_system *s = NULL;
    int tr, tc, bands, h, w;
    if (lm_api_cube_read(scene, NULL, &raw, &err) || lm_api_system_load(NULL, &s, &err) ||
        lm_api_system_info(s, NULL, &tr, &tc, &err) ||
        lm_api_cube_shape(raw, &bands, &h, &w, &err) ||
        lm_api_cube_crop(raw, 0, 0, h - h % tr, w - w % tc, &c, &err)) {
        CHECK_MSG(0, "%s", err.message);
        lm_api_cube_free(raw), lm_api_system_free(s);
        return NULL;
    }
    lm_api_cube_free(raw);
    lm_api_system_free(s);
    lm_api_cube_shape(c, &bands, &h, &w, NULL);
    float *d = lm_api_cube_data(c), mx = 0.0f;
    const size_t n = (size_t)bands * h * w;
    for (size_t i = 0; i < n; i++) mx = d[i] > mx ? d[i] : mx;
    const float inv = 1.0f / mx; /* as lm_eval_prepare */
    for (size_t i = 0; i < n; i++) d[i] *= inv;
    lm_err e;
    lm_err_clear(&e);
    CHECK(lm_cube_read(scene, ref, &e) == LM_OK && lm_eval_prepare(ref, 3, 4, &e) == LM_OK);
    CHECK(ref->bands == bands && ref->height == h && ref->width == w);
    CHECK(ref->data && !memcmp(ref->data, d, sizeof(float) * n));
    return c;
}

static void test_against_eval(void)
{
    lm_api_error err;
    lm_api_model *m = NULL;
    CHECK(lm_api_model_load(MODEL, NULL, &m, &err) == LM_API_OK);
    lm_cube truth = {0};
    lm_api_cube *c = m ? prepared_scene(&truth) : NULL;
    if (!c) {
        lm_api_model_free(m), lm_cube_free(&truth);
        return;
    }
    const int H = truth.height, W = truth.width;
    const size_t n = (size_t)H * W;
    const float k = 0.05f;
    const uint64_t seed = 7;
    /* the frame: the API's and eval's */
    float *frame = malloc(sizeof(float) * n), *ref = NULL;
    lm_api_noise nz = {.gauss_k = k};
    lm_api_system *s = NULL;
    CHECK(lm_api_system_load(NULL, &s, &err) == LM_API_OK);
    CHECK(lm_api_simulate(s, c, &nz, seed, 0, frame, NULL, n - 1, &err) == LM_API_ERR_SHAPE);
    CHECK(lm_api_simulate(s, c, &nz, seed, 0, frame, NULL, n, &err) == LM_API_OK);
    lm_infer_model im;
    lm_err e;
    lm_err_clear(&e);
    CHECK(lm_infer_model_load(MODEL, NULL, &im, &e) == LM_OK);
    lm_noise_opts no = {.gauss_k = k};
    lm_rng rng;
    lm_rng_seed(&rng, seed);
    size_t nref = 0;
    CHECK(lm_eval_simulate(&im, &truth, &no, &rng, &ref, &nref, &e) == LM_OK && nref == n);
    CHECK(ref && !memcmp(ref, frame, sizeof(float) * n));
    /* eval's reconstruction on the whole frame, its PSNR */
    lm_ctx ctx;
    lm_ctx_init(&ctx, 2);
    lm_tile_opts to;
    lm_tile_default_opts(&to);
    lm_cube er = {0};
    lm_metrics me = {0};
    CHECK(lm_eval_reconstruct(&ctx, &im, ref, H, W, &to, 1, &er, &e) == LM_OK);
    CHECK(lm_metrics_compute(er.data, truth.data, 31, H, W, 0, 31, &me, &e) == LM_OK);
    /* the API's */
    lm_api_frame f = {H, W, LM_API_PIXEL_F32, frame, NULL};
    lm_api_cube *rc = NULL;
    lm_api_metrics ma = {0};
    CHECK(lm_api_model_set_threads(m, 2, &err) == LM_API_OK);
    CHECK(lm_api_reconstruct_cube(m, &f, &rc, &err) == LM_API_OK);
    CHECK(rc && lm_api_metrics_compute(lm_api_cube_data(rc), truth.data, 31, H, W, &ma,
                                       &err) == LM_API_OK);
    /* as infer writes it: eval's cube clamped at 0, bit for bit */
    lm_metrics mc = {0};
    lm_recon_clamp(&er);
    CHECK(rc && er.data && !memcmp(lm_api_cube_data(rc), er.data, sizeof(float) * 31 * n));
    CHECK(lm_metrics_compute(er.data, truth.data, 31, H, W, 0, 31, &mc, &e) == LM_OK);
    CHECK_CLOSE(ma.psnr, mc.psnr, 0.01, 0.0);
    /* as eval scores it: not clamped */
    lm_api_metrics mu = {0};
    lm_api_cube *ru = NULL;
    CHECK(lm_api_model_set_clamp(m, 0, &err) == LM_API_OK);
    CHECK(lm_api_reconstruct_cube(m, &f, &ru, &err) == LM_API_OK);
    CHECK(ru && lm_api_metrics_compute(lm_api_cube_data(ru), truth.data, 31, H, W, &mu,
                                       &err) == LM_API_OK);
    CHECK(lm_api_model_set_clamp(m, 1, &err) == LM_API_OK);
    lm_api_cube_free(ru);
    printf("cd_256 at %.0f %% noise: eval %.4f dB, API %.4f dB (SSIM %.4f / %.4f); clamped at "
           "0 as infer writes it: %.4f / %.4f dB\n", 100 * k, me.psnr, mu.psnr, me.ssim, mu.ssim,
           mc.psnr, ma.psnr);
    CHECK(me.psnr > 25.0);
    CHECK_CLOSE(mu.psnr, me.psnr, 0.01, 0.0);
    CHECK_CLOSE(mu.ssim, me.ssim, 1e-4, 0.0);
    /* a caller-owned buffer: the same values, the wavelengths; too small a buffer refused */
    const size_t nc = 31 * n;
    float *buf = malloc(sizeof(float) * nc), wl[31];
    CHECK(lm_api_reconstruct(m, &f, buf, nc - 1, wl, &err) == LM_API_ERR_SHAPE);
    CHECK(lm_api_reconstruct(m, &f, buf, nc, wl, &err) == LM_API_OK);
    CHECK(rc && !memcmp(buf, lm_api_cube_data(rc), sizeof(float) * nc));
    CHECK(wl[0] == 400.0f && wl[30] == 700.0f);
    /* one thread: the same cube */
    CHECK(lm_api_model_set_threads(m, 1, &err) == LM_API_OK);
    CHECK(lm_api_model_set_threads(m, -1, &err) == LM_API_ERR_ARG);
    CHECK(lm_api_reconstruct(m, &f, buf, nc, NULL, &err) == LM_API_OK);
    CHECK(rc && !memcmp(buf, lm_api_cube_data(rc), sizeof(float) * nc));
    /* bf16 products: a cube that differs a little, as good; fp32 again: the same cube */
    CHECK(lm_api_model_set_precision(m, (lm_api_precision)5, &err) == LM_API_ERR_ARG);
    CHECK(lm_api_model_set_precision(NULL, LM_API_PRECISION_BF16, &err) == LM_API_ERR_ARG);
    CHECK(lm_api_model_set_precision(m, LM_API_PRECISION_BF16, &err) == LM_API_OK);
    CHECK(lm_api_reconstruct(m, &f, buf, nc, NULL, &err) == LM_API_OK);
    CHECK(rc && memcmp(buf, lm_api_cube_data(rc), sizeof(float) * nc) != 0);
    CHECK(lm_api_metrics_compute(buf, truth.data, 31, H, W, &ma, &err) == LM_API_OK);
    printf("bf16: %.4f dB\n", ma.psnr);
    CHECK(ma.psnr > mc.psnr - 0.5);
    CHECK(lm_api_model_set_precision(m, LM_API_PRECISION_FP32, &err) == LM_API_OK);
    CHECK(lm_api_reconstruct(m, &f, buf, nc, NULL, &err) == LM_API_OK);
    CHECK(rc && !memcmp(buf, lm_api_cube_data(rc), sizeof(float) * nc));
    /* the noise level given instead of estimated: another cube, as good */
    CHECK(lm_api_model_set_noise_level(m, 2.0, &err) == LM_API_ERR_ARG);
    CHECK(lm_api_model_set_noise_level(m, k, &err) == LM_API_OK);
    CHECK(lm_api_reconstruct(m, &f, buf, nc, NULL, &err) == LM_API_OK);
    CHECK(lm_api_metrics_compute(buf, truth.data, 31, H, W, &ma, &err) == LM_API_OK);
    printf("noise level given: %.4f dB\n", ma.psnr);
    CHECK(ma.psnr > me.psnr - 0.5);
    CHECK(lm_api_model_set_noise_level(m, -1.0, &err) == LM_API_OK);
    /* a round trip of the cube through a spectral EXR */
    char path[1100];
    snprintf(path, sizeof path, "%s/recon.exr", tmpdir);
    lm_api_cube *back = NULL;
    CHECK(lm_api_cube_write(path, rc, &err) == LM_API_OK);
    CHECK(lm_api_cube_read(path, NULL, &back, &err) == LM_API_OK);
    CHECK(back && rc && !memcmp(lm_api_cube_data(back), lm_api_cube_data(rc), sizeof(float) * nc));
    CHECK(back && lm_api_cube_wavelengths(back)[30] == 700.0f);
    CHECK(lm_api_cube_write("/nonexistent/dir/x.exr", rc, &err) != LM_API_OK && err.message[0]);
    lm_api_cube_free(back);
    /* the sRGB preview: infer's (lm_srgb_render_cube at exposure 1); errors */
    float *rgb = malloc(sizeof(float) * 3 * n), *want = malloc(sizeof(float) * 3 * n);
    CHECK(rc && lm_api_cube_srgb(rc, 1.0f, rgb, 3 * n, &err) == LM_API_OK);
    CHECK(lm_srgb_render_cube(&er, 1.0f, NULL, want, &e) == LM_OK); /* er: rc's values */
    CHECK(!memcmp(rgb, want, sizeof(float) * 3 * n));
    CHECK(lm_api_cube_srgb(rc, 1.0f, rgb, 3 * n - 1, &err) == LM_API_ERR_SHAPE);
    CHECK(lm_api_cube_srgb(rc, -1.0f, rgb, 3 * n, &err) == LM_API_ERR_ARG && err.message[0]);
    CHECK(lm_api_cube_srgb(NULL, 1.0f, rgb, 3 * n, &err) == LM_API_ERR_ARG);
    free(rgb);
    free(want);
    /* frames the model cannot take */
    lm_api_frame g = f;
    g.bucket0 = frame;
    CHECK(lm_api_reconstruct(m, &g, buf, nc, NULL, &err) == LM_API_ERR_ARG);
    CHECK(strstr(err.message, "bucket") != NULL);
    g = f;
    g.height = H - 1;
    CHECK(lm_api_reconstruct(m, &g, buf, nc, NULL, &err) == LM_API_ERR_SHAPE);
    g = f;
    g.type = (lm_api_pixel)7;
    CHECK(lm_api_reconstruct(m, &g, buf, nc, NULL, &err) == LM_API_ERR_ARG);
    g = f;
    g.bucket1 = NULL;
    CHECK(lm_api_reconstruct(m, &g, buf, nc, NULL, &err) == LM_API_ERR_ARG);
    /* NaN in a frame, in a cube to score: refused with the place */
    const float keep = frame[W + 2];
    frame[W + 2] = NAN;
    CHECK(lm_api_reconstruct(m, &f, buf, nc, NULL, &err) == LM_API_ERR_NUMERIC);
    CHECK(strstr(err.message, "row 1, column 2") != NULL);
    frame[W + 2] = keep;
    buf[5] = INFINITY;
    CHECK(lm_api_metrics_compute(buf, truth.data, 31, H, W, &ma, &err) == LM_API_ERR_NUMERIC);
    CHECK(strstr(err.message, "pred") != NULL);
    /* still working after the errors */
    CHECK(lm_api_reconstruct(m, &f, buf, nc, NULL, &err) == LM_API_OK && err.status == LM_API_OK);
    CHECK(rc && !memcmp(buf, lm_api_cube_data(rc), sizeof(float) * nc));
    free(buf);
    lm_api_cube_free(rc);
    lm_cube_free(&er);
    lm_ctx_free(&ctx);
    lm_infer_model_free(&im);
    lm_api_system_free(s);
    free(ref);
    free(frame);
    lm_api_cube_free(c);
    lm_cube_free(&truth);
    lm_api_model_free(m);
}

/* A 16-bit frame in memory gives the cube `lumosaic infer` computes from the same frame in a
 * 16-bit PNG: the frame reader, lm_recon_frame on the whole frame, the clamp at 0. */
static void test_u16_as_infer(void)
{
    lm_api_error err;
    lm_api_model *m = NULL;
    lm_api_system *s = NULL;
    lm_cube truth = {0};
    lm_api_cube *c = NULL;
    CHECK(lm_api_model_load(MODEL, NULL, &m, &err) == LM_API_OK);
    CHECK(lm_api_system_load(NULL, &s, &err) == LM_API_OK);
    if (m && s) c = prepared_scene(&truth);
    if (!c) {
        lm_api_model_free(m), lm_api_system_free(s), lm_cube_free(&truth);
        return;
    }
    const int H = truth.height, W = truth.width;
    const size_t n = (size_t)H * W, nc = 31 * n;
    float *frame = malloc(sizeof(float) * n), *b0 = malloc(sizeof(float) * n);
    float *a = malloc(sizeof(float) * nc);
    uint16_t *u = malloc(sizeof(uint16_t) * n);
    lm_api_noise nz = {.gauss_k = 0.02};
    CHECK(lm_api_simulate(s, c, &nz, 3, 0, frame, b0, n, &err) == LM_API_OK);
    for (size_t i = 0; i < n; i++) { /* as lm_frame_write quantises */
        float v = frame[i] < 0.0f ? 0.0f : frame[i] > 1.0f ? 1.0f : frame[i];
        u[i] = (uint16_t)lroundf(v * 65535.0f);
    }
    char path[1100];
    snprintf(path, sizeof path, "%s/frame.png", tmpdir);
    lm_err e;
    lm_err_clear(&e);
    lm_frame fr = {0};
    CHECK(lm_frame_write(path, H, W, frame, &e) == LM_OK);
    CHECK(lm_frame_read(path, &fr, &e) == LM_OK && fr.height == H && fr.width == W);
    for (size_t i = 0; i < n && fr.data; i++)
        if (fr.data[i] != (float)u[i] / 65535.0f) {
            CHECK_MSG(0, "PNG sample %zu: %g, the 16-bit value %u", i, fr.data[i], u[i]);
            break;
        }
    lm_api_frame f = {H, W, LM_API_PIXEL_U16, u, NULL};
    CHECK(lm_api_reconstruct(m, &f, a, nc, NULL, &err) == LM_API_OK);
    lm_infer_model im;
    CHECK(lm_infer_model_load(MODEL, NULL, &im, &e) == LM_OK);
    lm_ctx ctx;
    lm_ctx_init(&ctx, 2);
    lm_recon_opts ro;
    lm_recon_default_opts(&ro);
    lm_cube ref = {0};
    CHECK(fr.data && lm_recon_frame(&ctx, im.model, fr.data, H, W, &ro, &ref, &e) == LM_OK);
    lm_recon_clamp(&ref);
    CHECK(ref.data && !memcmp(ref.data, a, sizeof(float) * nc));
    /* patch-wise: as `lumosaic infer --tiles` */
    CHECK(lm_api_model_set_patchwise(m, 1, &err) == LM_API_OK);
    CHECK(lm_api_reconstruct(m, &f, a, nc, NULL, &err) == LM_API_OK);
    lm_cube_free(&ref);
    ro.tiles = 1;
    CHECK(fr.data && lm_recon_frame(&ctx, im.model, fr.data, H, W, &ro, &ref, &e) == LM_OK);
    lm_recon_clamp(&ref);
    CHECK(ref.data && !memcmp(ref.data, a, sizeof(float) * nc));
    /* bucket 0: stored / (LEDs - 1), white at most 1 */
    int leds = 0;
    lm_api_system_info(s, &leds, NULL, NULL, &err);
    float mx = 0.0f;
    for (size_t i = 0; i < n; i++) mx = b0[i] > mx ? b0[i] : mx;
    CHECK(leds > 1 && mx > 0.05f && mx < 1.2f);
    lm_cube_free(&ref);
    lm_ctx_free(&ctx);
    lm_infer_model_free(&im);
    lm_frame_free(&fr);
    free(frame), free(b0), free(a), free(u);
    lm_api_cube_free(c);
    lm_cube_free(&truth);
    lm_api_system_free(s);
    lm_api_model_free(m);
}

/* Reconstruct one 66 x 64 frame with the models at paths pa and pb: the largest absolute
 * difference of the two cubes (*bitwise: 1 when they are identical byte for byte); -1 when a
 * model does not load or reconstruct (checked here). */
static double model_diff(const char *pa, const char *pb, int *bitwise)
{
    lm_api_error err;
    lm_api_model *a = NULL, *b = NULL;
    CHECK_MSG(lm_api_model_load(pa, NULL, &a, &err) == LM_API_OK, "%s", err.message);
    CHECK_MSG(lm_api_model_load(pb, NULL, &b, &err) == LM_API_OK, "%s", err.message);
    enum { H = 66, W = 64 };
    static float frame[H * W], ca[31 * H * W], cb[31 * H * W];
    for (int i = 0; i < H * W; i++) frame[i] = 0.3f + 0.2f * sinf(0.37f * (float)i);
    lm_api_frame f = {H, W, LM_API_PIXEL_F32, frame, NULL};
    double d = -1;
    *bitwise = 0;
    if (a && b && lm_api_reconstruct(a, &f, ca, sizeof ca / sizeof *ca, NULL, &err) == LM_API_OK &&
        lm_api_reconstruct(b, &f, cb, sizeof cb / sizeof *cb, NULL, &err) == LM_API_OK) {
        d = 0;
        for (size_t i = 0; i < sizeof ca / sizeof *ca; i++) d = fmax(d, fabs(ca[i] - cb[i]));
        *bitwise = !memcmp(ca, cb, sizeof ca);
    }
    CHECK(d >= 0);
    lm_api_model_free(a), lm_api_model_free(b);
    return d;
}

/* lm_api_model_average: a model averaged with itself reconstructs as the model does, bit for
 * bit; models of other presets and NULL arguments are refused. */
static void test_average(void)
{
    char dir[] = "/tmp/lm_test_api_avg_XXXXXX", out[300];
    CHECK(mkdtemp(dir) != NULL);
    snprintf(out, sizeof out, "%s/self.safetensors", dir);
    lm_api_error err;
    const char *same[2] = {MODEL, MODEL},
               *other[2] = {MODEL, "models/demo/tn160nc-lmmse.safetensors"};
    CHECK_MSG(lm_api_model_average(same, 2, out, &err) == LM_API_OK, "%s", err.message);
    CHECK(lm_api_model_average(other, 2, out, &err) == LM_API_ERR_ARG &&
          strstr(err.message, "one preset"));
    CHECK(lm_api_model_average(NULL, 2, out, &err) == LM_API_ERR_ARG);
    CHECK(lm_api_model_average(same, 1, out, &err) == LM_API_ERR_ARG);
    int bitwise = 0;
    CHECK(model_diff(MODEL, out, &bitwise) == 0 && bitwise);
    unlink(out);
    rmdir(dir);
}

/* lm_api_model_convert: the fp16 file is half the size and reconstructs within fp16's rounding
 * of the model (not bit for bit); fp16 -> fp32 -> fp16 gives the same file; the model's own
 * file and NULL arguments are refused. */
static long file_size(const char *path)
{
    FILE *f = fopen(path, "rb");
    long n = f && fseek(f, 0, SEEK_END) == 0 ? ftell(f) : -1;
    if (f) fclose(f);
    return n;
}

static void test_convert(void)
{
    char dir[] = "/tmp/lm_test_api_conv_XXXXXX", h[300], back[300], again[300];
    CHECK(mkdtemp(dir) != NULL);
    snprintf(h, sizeof h, "%s/h.safetensors", dir);
    snprintf(back, sizeof back, "%s/back.safetensors", dir);
    snprintf(again, sizeof again, "%s/again.safetensors", dir);
    lm_api_error err;
    CHECK_MSG(lm_api_model_convert(MODEL, h, 1, &err) == LM_API_OK, "%s", err.message);
    CHECK_MSG(lm_api_model_convert(h, back, 0, &err) == LM_API_OK, "%s", err.message);
    CHECK_MSG(lm_api_model_convert(back, again, 1, &err) == LM_API_OK, "%s", err.message);
    long s32 = file_size(MODEL), s16 = file_size(h);
    CHECK(s16 > 0 && 2 * s16 > s32 && 2 * s16 < s32 + 8192 && file_size(back) == s32);
    FILE *f = fopen(h, "rb"), *g = fopen(again, "rb");
    int same = f && g;
    for (int a = 0, b = 0; same && (a != EOF || b != EOF);) {
        a = fgetc(f), b = fgetc(g);
        same = a == b;
    }
    if (f) fclose(f);
    if (g) fclose(g);
    CHECK(same);
    CHECK(lm_api_model_convert(NULL, h, 1, &err) == LM_API_ERR_ARG);
    CHECK(lm_api_model_convert(h, h, 1, &err) == LM_API_ERR_ARG &&
          strstr(err.message, "being converted"));
    int bitwise = 1;
    double d = model_diff(MODEL, h, &bitwise);
    CHECK_MSG(d > 0 && d < 2e-3 && !bitwise, "largest difference %g", d);
    unlink(h), unlink(back), unlink(again);
    rmdir(dir);
}

int main(void)
{
    snprintf(scene, sizeof scene, "%s/data/cave-256/cd_256", shared_dir());
    if (access(scene, R_OK) != 0) {
        fprintf(stderr, "skipped: %s not found\n", scene);
        return 77;
    }
    if (!mkdtemp(tmpdir)) return 1;
    RUN(test_version);
    RUN(test_null_arguments);
    RUN(test_bad_files);
    RUN(test_against_eval);
    RUN(test_u16_as_infer);
    RUN(test_average);
    RUN(test_convert);
    char cmd[1200];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", tmpdir);
    if (system(cmd) != 0) fprintf(stderr, "could not remove %s\n", tmpdir);
    return check_summary();
}

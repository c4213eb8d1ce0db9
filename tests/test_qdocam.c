/* test_qdocam.c — the QDO camera (data/qdocam.h): a point source gives the (RGB-weighted) PSF,
 * the FFT path equals a direct edge-padded convolution, a uniform scene stays uniform,
 * linearity, the noise path and argument errors; once with the bundled DOE, and eval's
 * simulation for a qdo-* preset (infer/eval.h) equal to this camera.
 * Not here: the PSFs' optics (test_doe.c). */
#include "data/qdocam.h"
#include "infer/eval.h"
#include "infer/model_io.h"
#include "tests/check.h"
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define NB LM_RGBCAM_BANDS
enum { S = 7, R = S / 2, H = 21, W = 17, PL = H * W };

/* Random asymmetric unit-sum PSFs (an error that flips or shifts the kernel shows). */
static void random_psfs(float *psf, unsigned seed)
{
    lm_rng r;
    lm_rng_seed(&r, seed);
    lm_rng_fill_uniform(&r, psf, NB * S * S, 0, 1);
    for (int b = 0; b < NB; b++) {
        float *p = psf + b * S * S;
        p[0] += 3.0f; /* a strong off-centre tap */
        double s = 0;
        for (int k = 0; k < S * S; k++) s += p[k];
        for (int k = 0; k < S * S; k++) p[k] = (float)(p[k] / s);
    }
}

static int init_random(lm_qdocam *q, float *psf)
{
    random_psfs(psf, 3);
    lm_err e = {0};
    lm_status st = lm_qdocam_init_psfs(q, psf, S, LM_RGBCAM_D65, &e);
    CHECK_MSG(st == LM_OK, "%s", e.msg);
    return st == LM_OK;
}

static void test_point_source(void)
{
    static float psf[NB * S * S], cube[NB * PL], rgb[3 * PL];
    lm_qdocam q;
    if (!init_random(&q, psf)) return;
    int y0 = 9, x0 = 7;
    for (int b = 0; b < NB; b++) cube[b * PL + y0 * W + x0] = 1.0f;
    lm_err e = {0};
    CHECK(lm_qdocam_render(&q, cube, H, W, rgb, &e) == LM_OK);
    double worst = 0;
    for (int k = 0; k < 3; k++)
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++) {
                int dy = y - y0, dx = x - x0;
                double want = 0;
                if (abs(dy) <= R && abs(dx) <= R)
                    for (int b = 0; b < NB; b++)
                        want += q.cam.w[k][b] * psf[b * S * S + (dy + R) * S + dx + R];
                double err = fabs(rgb[k * PL + y * W + x] - want);
                if (err > worst) worst = err;
            }
    printf("point source: largest difference to sum_b w_cb psf_b = %.2g\n", worst);
    CHECK(worst < 1e-6);
    lm_qdocam_free(&q);
}

/* Direct 'same' convolution with edge padding, then the RGB weights. */
static void direct(const lm_qdocam *q, const float *psf, const float *cube, float *rgb)
{
    for (int k = 0; k < 3; k++)
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++) {
                double acc = 0;
                for (int b = 0; b < NB; b++)
                    for (int i = -R; i <= R; i++)
                        for (int j = -R; j <= R; j++) {
                            int sy = y - i < 0 ? 0 : y - i >= H ? H - 1 : y - i;
                            int sx = x - j < 0 ? 0 : x - j >= W ? W - 1 : x - j;
                            acc += q->cam.w[k][b] * psf[b * S * S + (i + R) * S + j + R] *
                                   cube[b * PL + sy * W + sx];
                        }
                rgb[k * PL + y * W + x] = (float)acc;
            }
}

static void test_direct_and_linear(void)
{
    static float psf[NB * S * S], x[NB * PL], y[NB * PL], z[NB * PL];
    static float rx[3 * PL], ry[3 * PL], rz[3 * PL], ref[3 * PL];
    lm_qdocam q;
    if (!init_random(&q, psf)) return;
    lm_rng r;
    lm_rng_seed(&r, 11);
    lm_rng_fill_uniform(&r, x, NB * PL, 0, 1);
    lm_rng_fill_uniform(&r, y, NB * PL, 0, 1);
    for (int i = 0; i < NB * PL; i++) z[i] = 0.7f * x[i] - 1.5f * y[i];
    lm_err e = {0};
    CHECK(lm_qdocam_render(&q, x, H, W, rx, &e) == LM_OK);
    CHECK(lm_qdocam_render(&q, y, H, W, ry, &e) == LM_OK);
    CHECK(lm_qdocam_render(&q, z, H, W, rz, &e) == LM_OK);
    direct(&q, psf, x, ref);
    CHECK_ARRAY_CLOSE(rx, ref, 3 * PL, 1e-5, 1e-5);
    for (int i = 0; i < 3 * PL; i++) ref[i] = 0.7f * rx[i] - 1.5f * ry[i];
    CHECK_ARRAY_CLOSE(rz, ref, 3 * PL, 1e-5, 1e-5);
    /* noise off: simulate = render; noise on: different, seeded */
    lm_noise_opts no = {0}, gauss = {.gauss_k = 0.1f};
    CHECK(lm_qdocam_simulate(&q, x, H, W, &no, NULL, ry, 1, &e) == LM_OK);
    CHECK_ARRAY_CLOSE(ry, rx, 3 * PL, 0, 0);
    CHECK(lm_qdocam_simulate(&q, x, H, W, &gauss, &r, ry, 1, &e) == LM_OK);
    double d = 0;
    for (int i = 0; i < 3 * PL; i++) d += fabs(ry[i] - rx[i]);
    CHECK(d > 0.01 * 3 * PL);
    CHECK(lm_qdocam_render(&q, x, 0, W, rx, &e) == LM_ERR_ARG);
    CHECK(strstr(e.msg, "qdocam: image size") != NULL);
    lm_qdocam_free(&q);
}

/* The bundled DOE: a uniform grey scene stays grey everywhere (edge padding, unit-sum PSFs,
 * white-balanced camera); a point source spreads differently per channel. */
static void test_default_doe(void)
{
    lm_err e = {0};
    lm_qdocam *q = NULL; /* the camera infer/ builds for a qdo-* model: the bundled DOE, D65 */
    CHECK_MSG(lm_infer_qdocam(NULL, &q, &e) == LM_OK, "%s", e.msg);
    if (!q) return;
    enum { h = 66, w = 64, pl = h * w };
    float *cube = malloc(sizeof(float) * NB * pl), *rgb = malloc(sizeof(float) * 3 * pl);
    for (int i = 0; i < NB * pl; i++) cube[i] = 0.6f;
    CHECK(lm_qdocam_render(q, cube, h, w, rgb, &e) == LM_OK);
    double worst = 0;
    for (int i = 0; i < 3 * pl; i++) worst = fmax(worst, fabs(rgb[i] - 0.6));
    printf("default DOE: uniform 0.6 -> largest deviation %.2g\n", worst);
    CHECK(worst < 1e-4);
    memset(cube, 0, sizeof(float) * NB * pl);
    for (int b = 0; b < NB; b++) cube[b * pl + 33 * w + 32] = 1.0f;
    CHECK(lm_qdocam_render(q, cube, h, w, rgb, &e) == LM_OK);
    double peak[3];
    for (int k = 0; k < 3; k++) peak[k] = rgb[k * pl + 33 * w + 32];
    printf("default DOE: point source peak R %.4f G %.4f B %.4f\n", peak[0], peak[1], peak[2]);
    CHECK(peak[1] > peak[0] && peak[1] > peak[2]); /* green is in focus */
    /* eval simulates a qdo-* model's frame through the same camera */
    lm_infer_model im = {.model = lm_model_create("qdo-mst", NULL, 3, &e)};
    CHECK_MSG(im.model && lm_model_has(im.model, LM_CAP_QDO_OPTICS | LM_CAP_RGB_INPUT), "%s",
              e.msg);
    lm_cube cb = {0};
    CHECK(lm_cube_alloc(&cb, NB, h, w, 400.0f, 10.0f) == LM_OK);
    memcpy(cb.data, cube, sizeof(float) * NB * pl);
    float *fr = NULL;
    size_t n = 0;
    im.qdo = q;
    CHECK_MSG(im.model && lm_eval_simulate(&im, &cb, NULL, NULL, &fr, &n, &e) == LM_OK, "%s",
              e.msg);
    CHECK(n == 3 * (size_t)pl);
    if (fr) CHECK_ARRAY_CLOSE(fr, rgb, 3 * pl, 0, 0);
    free(fr);
    lm_cube_free(&cb);
    lm_model_free(im.model);
    free(cube);
    free(rgb);
    lm_qdocam_free(q);
    free(q);
}

/* The tensor twin (lm_qdocam_render_t) equals lm_qdocam_render at every pixel R or more from
 * the border of the padded cube, for two items; and its gradient w.r.t. the PSFs checks. */
static void test_render_t_matches(void)
{
    lm_qdocam q;
    float psf[NB * S * S];
    if (!init_random(&q, psf)) return;
    int B = 2, n = NB * PL;
    float *cube = malloc((size_t)B * n * sizeof(float)), *ref = malloc(3 * PL * sizeof(float));
    lm_rng r;
    lm_rng_seed(&r, 12);
    lm_rng_fill_uniform(&r, cube, (long)B * n, 0, 1);
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_tensor *P = lm_tensor_from(&c, 3, (int[]){NB, S, S}, psf);
    lm_tensor *y = lm_qdocam_render_t(&c, &q.cam, P, cube, B, H, W);
    CHECK_CTX_OK(&c);
    lm_err e = {0};
    int h = H - 2 * R, w = W - 2 * R;
    CHECK(y && y->shape[0] == B && y->shape[1] == 3 && y->shape[2] == h && y->shape[3] == w);
    for (int b = 0; y && b < B; b++) {
        CHECK(lm_qdocam_render(&q, cube + (size_t)b * n, H, W, ref, &e) == LM_OK);
        long bad = 0;
        for (int k = 0; k < 3; k++)
            for (int i = 0; i < h; i++)
                for (int j = 0; j < w; j++) {
                    float a = y->data[(((size_t)b * 3 + k) * h + i) * w + j];
                    float x = ref[(size_t)k * PL + (size_t)(i + R) * W + j + R];
                    bad += !(fabsf(a - x) <= 1e-5f);
                }
        CHECK_MSG(bad == 0, "item %d: %ld pixels differ", b, bad);
    }
    lm_ctx_free(&c);
    lm_qdocam_free(&q);
    free(cube);
    free(ref);
}

typedef struct cam_user { const lm_rgbcam *cam; const float *cube; } cam_user;
static lm_tensor *fn_cam(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin;
    const cam_user *cu = u;
    return lm_qdocam_render_t(c, cu->cam, in[0], cu->cube, 1, 7, 8);
}

static void test_render_t_gradcheck(void)
{
    lm_rgbcam cam;
    lm_err e = {0};
    CHECK(lm_rgbcam_load(&cam, NULL, LM_RGBCAM_D65, &e) == LM_OK);
    float cube[NB * 7 * 8];
    lm_rng r;
    lm_rng_seed(&r, 2);
    lm_rng_fill_uniform(&r, cube, NB * 56, 0, 1);
    lm_ctx c;
    lm_ctx_init(&c, 1);
    lm_tensor *P = lm_tensor_uniform(&c, 3, (int[]){NB, 3, 3}, &r, 0, 1);
    lm_tensor_set_requires_grad(P, 1);
    lm_gradcheck_opts o;
    lm_gradcheck_default_opts(&o);
    o.eps = 1e-2;
    o.atol = 1e-3;
    o.rtol = 1e-2;
    cam_user u = {&cam, cube};
    CHECK_GRAD(&c, fn_cam, &P, 1, &u, &o);
    CHECK(lm_qdocam_render_t(&c, &cam, P, cube, 1, 2, 8) == NULL &&
          strstr(c.msg, "qdocam_render"));
    lm_ctx_free(&c);
}

int main(void)
{
    RUN(test_point_source);
    RUN(test_direct_and_linear);
    RUN(test_default_doe);
    RUN(test_render_t_matches);
    RUN(test_render_t_gradcheck);
    return check_summary();
}

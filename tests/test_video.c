/* test_video.c — the video forward model: a still scene gives exactly the static model (noise
 * included); integer translations move each LED's sub-image by its own window's displacement
 * (one instant, and the average of four for motion blur; both buckets; frame timing); the
 * ground truth sits at the Lime window's centre (a moving edge); rotation, zoom and regions
 * against hand-derived pixel maps; determinism per seed and thread count; errors. */
#include "tests/check.h"
#include "data/video.h"
#include <stdlib.h>

static lm_system g_sys;
static int g_ok;
static lm_err g_err;

static void test_default_system_loads(void) { CHECK_MSG(g_ok, "default system: %s", g_err.msg); }

static void random_cube(lm_cube *c, int bands, int h, int w, float start, float step,
                        uint64_t seed)
{
    lm_rng r;
    lm_rng_seed(&r, seed);
    CHECK(lm_cube_alloc(c, bands, h, w, start, step) == LM_OK);
    lm_rng_fill_uniform(&r, c->data, (long)bands * h * w, 0, 1);
}

static void test_still_scene_equals_static(void)
{
    if (!g_ok) return;
    const int H = 6, W = 8, N = H * W;
    lm_cube c, gt;
    random_cube(&c, 41, H, W, 380, 10, 11);
    lm_video_opts vo = {0};
    vo.noise.gauss_k = 0.05f;
    vo.noise.photons = 1000;
    vo.y0 = 1; /* an off-grid sensor position */
    vo.x0 = 3;
    lm_forward_opts fo = {.y0 = 1, .x0 = 3, .noise = vo.noise};
    float v1[N], v0[N], s1[N], s0[N];
    lm_rng r1, r2;
    lm_rng_seed(&r1, 5);
    lm_rng_seed(&r2, 5);
    lm_err e;
    lm_err_clear(&e);
    CHECK_MSG(lm_video_frame(&g_sys, &c, &vo, 3, &r1, v1, v0, &gt, &e) == LM_OK, "%s", e.msg);
    CHECK(lm_forward_simulate(&g_sys, &c, &fo, &r2, s1, s0, NULL) == LM_OK);
    CHECK(memcmp(v1, s1, sizeof v1) == 0); /* bucket 1: bit for bit */
    CHECK_ARRAY_CLOSE(v0, s0, N, 1e-5, 1e-5);
    CHECK(gt.data && gt.bands == 41 && memcmp(gt.data, c.data, sizeof(float) * 41 * N) == 0);
    CHECK(gt.wavelength[40] == 780.0f);
    /* the generators advanced alike */
    CHECK(lm_rng_u64(&r1) == lm_rng_u64(&r2));
    lm_cube_free(&gt);
    lm_cube_free(&c);
}

/* Two LEDs on a 1 x 2 tile, 3 bins: A fires 0-2000 us, B 2000-4000 us; frames every 5000 us. */
static const char *TWO =
    "{\"version\": 1, \"grid\": {\"start_nm\": 500, \"step_nm\": 10, \"count\": 3},"
    "\"sensor\": {\"width\": 64, \"height\": 16, \"qe\": [1, 1, 1]},"
    "\"subframe_us\": 1000, \"readout_us\": 1000, \"frame_period_us\": 5000,"
    "\"leds\": [{\"name\": \"A\", \"subframes\": 2, \"emission\": [1, 0.5, 0.2]},"
    "           {\"name\": \"B\", \"subframes\": 2, \"emission\": [0.1, 0.5, 1]}],"
    "\"tile_map\": [[\"A\", \"B\"]]}";

static int clampi(int v, int n) { return v < 0 ? 0 : (v >= n ? n - 1 : v); }

/* a_l . r(p - d), clamped at the border, in double. */
static double shifted_dot(const lm_system *s, const lm_cube *c, int l, int y, int x, int dy,
                          int dx)
{
    int H = c->height, W = c->width;
    int sy = clampi(y - dy, H), sx = clampi(x - dx, W);
    double v = 0;
    for (int b = 0; b < c->bands; b++)
        v += (double)lm_system_response(s, l)[b] * c->data[((size_t)b * H + sy) * W + sx];
    return v;
}

/* Each pixel's expected value: mean over its LED's instants of a_l . r(p - v t). */
static void expected(const lm_system *s, const lm_cube *c, double vx, double vy, int frame,
                     int K, int bucket, double *out)
{
    int H = c->height, W = c->width;
    for (int y = 0; y < H; y++)
        for (int x = 0; x < W; x++) {
            int lp = x % 2; /* A at even columns */
            double acc = 0;
            for (int l = 0; l < 2; l++) {
                if ((l == lp) != (bucket == 1)) continue;
                double start = l == 0 ? 0 : 2000, sum = 0;
                for (int k = 0; k < K; k++) {
                    double t = 1e-6 * (frame * 5000 + start + (k + 0.5) * 2000 / K);
                    sum += shifted_dot(s, c, l, y, x, (int)lround(vy * t), (int)lround(vx * t));
                }
                acc += sum / K;
            }
            out[y * W + x] = acc;
        }
}

static void check_translation(const lm_system *s, const lm_cube *c, double vx, double vy,
                              int frame, int K)
{
    int N = c->height * c->width;
    float *b1 = malloc(sizeof(float) * N), *b0 = malloc(sizeof(float) * N);
    double *w1 = malloc(sizeof(double) * N), *w0 = malloc(sizeof(double) * N);
    lm_video_opts o = {.motion = {.vx = vx, .vy = vy}, .samples = K, .nthreads = 2};
    lm_err e;
    lm_err_clear(&e);
    CHECK_MSG(lm_video_frame(s, c, &o, frame, NULL, b1, b0, NULL, &e) == LM_OK, "%s", e.msg);
    expected(s, c, vx, vy, frame, K, 1, w1);
    expected(s, c, vx, vy, frame, K, 0, w0);
    int bad = 0;
    for (int i = 0; i < N; i++)
        bad += fabs(b1[i] - w1[i]) > 1e-6 + 1e-5 * fabs(w1[i]) ||
               fabs(b0[i] - w0[i]) > 1e-6 + 1e-5 * fabs(w0[i]);
    CHECK_MSG(bad == 0, "v = (%g, %g) px/s, frame %d, %d samples: %d pixels differ", vx, vy,
              frame, K, bad);
    free(b1), free(b0), free(w1), free(w0);
}

static void test_integer_translation(void)
{
    lm_system s;
    lm_err e;
    lm_err_clear(&e);
    CHECK_MSG(lm_system_parse(TWO, ".", "two.json", &s, &e) == LM_OK, "%s", e.msg);
    if (e.status) return;
    lm_cube c;
    random_cube(&c, 3, 12, 40, 500, 10, 21);
    /* one instant at each window's centre: A moves 1 px, B 3 px (and -2 / -6 px in y) */
    check_translation(&s, &c, 1000, -2000, 0, 1);
    /* frame 1 starts at 5000 us: A at 6000 us (6 px), B at 8000 us (8 px) */
    check_translation(&s, &c, 1000, 0, 1, 1);
    /* motion blur: four instants per window, 4000 px/s -> A 1, 3, 5, 7 px; B 9 .. 15 px */
    check_translation(&s, &c, 4000, 0, 0, 4);
    check_translation(&s, &c, 0, 4000, 0, 4);
    /* bit-exact: with one instant, A's pixels equal the static model of the shifted cube */
    int H = c.height, W = c.width;
    lm_cube sh;
    CHECK(lm_cube_alloc(&sh, 3, H, W, 500, 10) == LM_OK);
    for (int b = 0; b < 3; b++)
        for (int y = 0; y < H; y++)
            for (int x = 0; x < W; x++)
                sh.data[(b * H + y) * W + x] = c.data[(b * H + y) * W + clampi(x - 1, W)];
    float v[12 * 40], st[12 * 40];
    lm_video_opts o = {.motion = {.vx = 1000}, .samples = 1};
    CHECK(lm_video_frame(&s, &c, &o, 0, NULL, v, NULL, NULL, NULL) == LM_OK);
    CHECK(lm_forward_clean(&s, &sh, 0, 0, st, NULL, 1, NULL) == LM_OK);
    int same = 1;
    for (int i = 0; i < H * W; i += 2) same &= v[i] == st[i];
    CHECK(same);
    lm_cube_free(&sh);
    lm_cube_free(&c);
    lm_system_free(&s);
}

/* A vertical edge (0 left of x = 20, 1 from it on) moving right: the ground truth's row sum is
 * W - 20 - d, d the displacement at the ground-truth instant. */
static void test_ground_truth_at_lime_centre(void)
{
    if (!g_ok) return;
    CHECK_CLOSE(lm_video_gt_time_us(&g_sys), 11700.0, 1e-9, 0); /* Lime: 11100-12300 us */
    const int H = 3, W = 64;
    lm_cube c, gt;
    CHECK(lm_cube_alloc(&c, 41, H, W, 380, 10) == LM_OK);
    for (long i = 0; i < 41L * H * W; i++) c.data[i] = (i % W) >= 20 ? 1.0f : 0.0f;
    double vx = 10.0 / 0.0117; /* 10 px at 11.7 ms */
    lm_video_opts o = {.motion = {.vx = vx}};
    float b1[H * W];
    for (int frame = 0; frame < 2; frame++) {
        CHECK(lm_video_frame(&g_sys, &c, &o, frame, NULL, b1, NULL, &gt, NULL) == LM_OK);
        double t = frame * (1e6 / 30) + 11700.0, d = vx * t * 1e-6;
        for (int b = 0; b < 41; b += 20)
            for (int y = 0; y < H; y++) {
                double sum = 0;
                for (int x = 0; x < W; x++) sum += lm_cube_band(&gt, b)[y * W + x];
                CHECK_CLOSE(sum, W - 20 - d, 1e-4, 0);
            }
        lm_cube_free(&gt);
    }
    lm_cube_free(&c);
}

/* rotation by 90 degrees (clockwise as displayed), zoom x2, a moving rectangle and ellipse */
static void test_warp_geometry(void)
{
    const int n = 9, c0 = 4;
    lm_cube src, out;
    random_cube(&src, 2, n, n, 500, 10, 31);
    lm_motion m = {.rot_deg_s = 90};
    CHECK(lm_video_warp(&src, &m, 1.0, &out, 2, NULL) == LM_OK);
    int bad = 0; /* a point right of the centre lands below it */
    for (int b = 0; b < 2; b++)
        for (int v = -c0; v <= c0; v++)
            for (int u = -c0; u <= c0; u++)
                bad += lm_cube_band(&out, b)[(c0 + v) * n + c0 + u] !=
                       lm_cube_band(&src, b)[(c0 - u) * n + c0 + v];
    CHECK_MSG(bad == 0, "rotation: %d pixels differ", bad);
    lm_cube_free(&out);
    lm_motion z = {.zoom_pct_s = 100, .has_centre = 1, .cx = 2, .cy = 3};
    CHECK(lm_video_warp(&src, &z, 1.0, &out, 1, NULL) == LM_OK);
    const float *o0 = lm_cube_band(&out, 0), *s0 = lm_cube_band(&src, 0);
    CHECK(o0[(3 + 2) * n + 2 + 4] == s0[(3 + 1) * n + 2 + 2]); /* c + 2d <- c + d */
    CHECK(o0[3 * n + 2] == s0[3 * n + 2]);
    CHECK_CLOSE(o0[3 * n + 3], 0.5 * (s0[3 * n + 2] + s0[3 * n + 3]), 1e-6, 0);
    lm_cube_free(&out);
    lm_motion r = {.nregions = 2};
    r.regions[0] = (lm_motion_region){LM_REGION_RECT, 2, 2, 3, 3, 2, 0};
    r.regions[1] = (lm_motion_region){LM_REGION_ELLIPSE, 4, 2, 4, 2, 0, 1}; /* on top */
    CHECK(lm_video_warp(&src, &r, 1.0, &out, 2, NULL) == LM_OK);
    bad = 0;
    for (int y = 0; y < n; y++)
        for (int x = 0; x < n; x++) {
            int in_rect = abs(x - 4) <= 1 && abs(y - 2) <= 1; /* centre (4, 2) at t = 1 */
            double ex = (x - 4) / 2.0, ey = (y - 3) / 1.0;  /* centre (4, 3) at t = 1 */
            int in_ell = ex * ex + ey * ey <= 1.0;
            int sx = in_ell ? x : (in_rect ? x - 2 : x), sy = in_ell ? y - 1 : y;
            bad += lm_cube_band(&out, 1)[y * n + x] != lm_cube_band(&src, 1)[sy * n + sx];
        }
    CHECK_MSG(bad == 0, "regions: %d pixels differ", bad);
    double sx, sy; /* the background does not move */
    lm_motion_source(&r, n, n, 1.0, 0, 8, &sx, &sy);
    CHECK(sx == 0 && sy == 8);
    lm_cube_free(&out);
    lm_cube_free(&src);
}

static void run_noisy(const lm_cube *c, uint64_t seed, int nthreads, float *b1, float *b0)
{
    lm_video_opts o = {.motion = {.vx = 300, .rot_deg_s = 40, .zoom_pct_s = 20, .nregions = 1},
                       .samples = 3, .nthreads = nthreads};
    o.motion.regions[0] = (lm_motion_region){LM_REGION_ELLIPSE, 4, 3, 5, 3, -200, 100};
    o.noise.gauss_k = 0.1f;
    o.noise.photons = 500;
    o.noise.read_noise = 2;
    lm_rng r;
    lm_rng_seed(&r, seed);
    lm_err e;
    lm_err_clear(&e);
    CHECK_MSG(lm_video_frame(&g_sys, c, &o, 2, &r, b1, b0, NULL, &e) == LM_OK, "%s", e.msg);
}

static void test_determinism(void)
{
    if (!g_ok) return;
    enum { H = 9, W = 12, N = H * W };
    lm_cube c;
    random_cube(&c, 41, H, W, 380, 10, 41);
    float a1[N], a0[N], b1[N], b0[N], d1[N], d0[N];
    run_noisy(&c, 7, 1, a1, a0);
    run_noisy(&c, 7, 2, b1, b0);
    run_noisy(&c, 8, 2, d1, d0);
    CHECK(memcmp(a1, b1, sizeof a1) == 0 && memcmp(a0, b0, sizeof a0) == 0);
    CHECK(memcmp(a1, d1, sizeof a1) != 0 && memcmp(a0, d0, sizeof a0) != 0);
    lm_cube_free(&c);
}

static void test_errors(void)
{
    if (!g_ok) return;
    lm_cube c, gt;
    random_cube(&c, 41, 3, 4, 380, 10, 51);
    float out[12];
    lm_err e;
    lm_video_opts o = {.motion = {.zoom_pct_s = -100}};
    lm_err_clear(&e);
    CHECK(lm_video_frame(&g_sys, &c, &o, 0, NULL, out, NULL, &gt, &e) == LM_ERR_ARG);
    CHECK_MSG(strstr(e.msg, "video: motion: zoom"), "%s", e.msg);
    CHECK(gt.data == NULL);
    o.motion = (lm_motion){.nregions = 1};
    lm_err_clear(&e);
    CHECK(lm_video_frame(&g_sys, &c, &o, 0, NULL, out, NULL, NULL, &e) == LM_ERR_ARG);
    CHECK_MSG(strstr(e.msg, "region 0: size"), "%s", e.msg);
    o.motion = (lm_motion){.vx = NAN};
    lm_err_clear(&e);
    CHECK(lm_video_warp(&c, &o.motion, 0.0, &gt, 1, &e) == LM_ERR_ARG && !gt.data);
    o = (lm_video_opts){.samples = LM_VIDEO_MAX_SAMPLES + 1};
    lm_err_clear(&e);
    CHECK(lm_video_frame(&g_sys, &c, &o, 0, NULL, out, NULL, NULL, &e) == LM_ERR_ARG);
    CHECK_MSG(strstr(e.msg, "video: 65 samples"), "%s", e.msg);
    o.samples = 0;
    lm_err_clear(&e);
    CHECK(lm_video_frame(&g_sys, &c, &o, -1, NULL, out, NULL, NULL, &e) == LM_ERR_ARG);
    c.data[5] = NAN;
    lm_err_clear(&e);
    CHECK(lm_video_frame(&g_sys, &c, &o, 0, NULL, out, NULL, NULL, &e) == LM_ERR_NUMERIC);
    CHECK_MSG(strstr(e.msg, "forward:"), "%s", e.msg);
    lm_cube_free(&c);
    random_cube(&c, 31, 3, 4, 400, 10, 52);
    lm_err_clear(&e);
    CHECK(lm_video_frame(&g_sys, &c, &o, 0, NULL, out, NULL, NULL, &e) == LM_ERR_SHAPE);
    CHECK_MSG(strstr(e.msg, "cube has 31 bands"), "%s", e.msg);
    lm_cube_free(&c);
}

int main(void)
{
    lm_err_clear(&g_err);
    g_ok = lm_system_default(&g_sys, &g_err) == LM_OK;
    RUN(test_default_system_loads);
    RUN(test_still_scene_equals_static);
    RUN(test_integer_translation);
    RUN(test_ground_truth_at_lime_centre);
    RUN(test_warp_geometry);
    RUN(test_determinism);
    RUN(test_errors);
    lm_system_free(&g_sys);
    return check_summary();
}

/* test_flow.c — DIS-style optical flow (data/flow.h) and temporal alignment (data/align.h).
 * Synthetic motion of textured images with a known transform T (translation d, small rotation,
 * zoom about the centre): I0(p) = S(p), I1(q) = S(T^-1(q)), so the true F_{0->1}(p) = T(p) - p.
 * Sources: a procedural texture (sum of random sinusoids, evaluated exactly at any point) and a
 * CAVE band (bilinear samples of a 256 x 256 band, 160 x 160 crop around its centre).
 * EPE is measured over the pixels whose true destination lies inside I1 (at least 1 px from the
 * border): pixels that leave the frame carry no information. Timings are printed, not asserted. */
#include <math.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <time.h>
#include "check.h"
#include "data/cube_io.h"
#include "data/system.h"
#include "data/video.h"
#include "data/align.h"
#include "data/flow.h"

#define N 160

typedef struct {
    uint64_t s;
} rng;
static double rnd(rng *r) /* splitmix64 -> [0, 1) */
{
    uint64_t z = (r->s += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return (double)((z ^ (z >> 31)) >> 11) / 9007199254740992.0;
}
static double gauss(rng *r)
{
    double u = rnd(r) + 1e-12, v = rnd(r);
    return sqrt(-2.0 * log(u)) * cos(2.0 * M_PI * v);
}

/* A source image: procedural (band == NULL) or bilinear samples of a band, offset so that the
 * crop's (0, 0) is at (ox, oy) of the band. */
typedef struct {
    double kx[40], ky[40], ph[40], amp[40];
    const float *band;
    int bh, bw;
    double ox, oy;
} source;

static void source_texture(source *s, uint64_t seed)
{
    rng r = {seed};
    memset(s, 0, sizeof *s);
    for (int k = 0; k < 40; k++) {
        double lam = 5.0 + 35.0 * rnd(&r), th = 2.0 * M_PI * rnd(&r);
        s->kx[k] = 2.0 * M_PI / lam * cos(th);
        s->ky[k] = 2.0 * M_PI / lam * sin(th);
        s->ph[k] = 2.0 * M_PI * rnd(&r);
        s->amp[k] = 0.5 + rnd(&r);
    }
}

static double source_at(const source *s, double x, double y)
{
    if (s->band)
        return lm_flow_sample(s->band, s->bh, s->bw, (float)(x + s->ox), (float)(y + s->oy));
    double v = 0.0;
    for (int k = 0; k < 40; k++) v += s->amp[k] * sin(s->kx[k] * x + s->ky[k] * y + s->ph[k]);
    return 0.5 + v / 40.0;
}

/* T(p) = c + z R(th) (p - c) + d, c the image centre. */
typedef struct {
    double dx, dy, th, z;
} motion;

static void motion_apply(const motion *m, double x, double y, double *tx, double *ty)
{
    double c = 0.5 * (N - 1), ct = cos(m->th), st = sin(m->th);
    *tx = c + m->z * (ct * (x - c) - st * (y - c)) + m->dx;
    *ty = c + m->z * (st * (x - c) + ct * (y - c)) + m->dy;
}

static void motion_inverse(const motion *m, double x, double y, double *tx, double *ty)
{
    double c = 0.5 * (N - 1), ct = cos(m->th), st = sin(m->th);
    double ux = (x - m->dx - c) / m->z, uy = (y - m->dy - c) / m->z;
    *tx = c + ct * ux + st * uy;
    *ty = c - st * ux + ct * uy;
}

/* I0, I1 and the true flow; noise sigma relative to the texture range. */
static void make_pair(const source *s, const motion *m, double sigma, uint64_t seed, float *i0,
                      float *i1, float *truth)
{
    rng r = {seed};
    for (int y = 0; y < N; y++)
        for (int x = 0; x < N; x++) {
            double ax, ay, bx, by;
            motion_inverse(m, x, y, &ax, &ay);
            motion_apply(m, x, y, &bx, &by);
            i0[y * N + x] = (float)(source_at(s, x, y) + sigma * gauss(&r));
            i1[y * N + x] = (float)(source_at(s, ax, ay) + sigma * gauss(&r));
            truth[y * N + x] = (float)(bx - x);
            truth[N * N + y * N + x] = (float)(by - y);
        }
}

/* Mean EPE over pixels whose true destination is inside the image (1 px margin). */
static double mean_epe(const float *f, const float *truth)
{
    double sum = 0.0;
    long cnt = 0;
    for (int y = 0; y < N; y++)
        for (int x = 0; x < N; x++) {
            long i = (long)y * N + x;
            double tx = x + truth[i], ty = y + truth[N * N + i];
            if (tx < 1 || ty < 1 || tx > N - 2 || ty > N - 2) continue;
            sum += hypot(f[i] - truth[i], f[N * N + i] - truth[N * N + i]);
            cnt++;
        }
    return cnt ? sum / cnt : 1e9;
}

static double now_ms(void)
{
    struct timespec ts;
    clock_gettime(CLOCK_MONOTONIC, &ts);
    return ts.tv_sec * 1e3 + ts.tv_nsec * 1e-6;
}

/* EPE of one preset on one source and motion. */
static double run_epe(const source *s, const motion *m, lm_flow_preset p, double *ms)
{
    float *i0 = malloc(sizeof(float) * N * N * 6), *i1 = i0 + N * N, *truth = i1 + N * N;
    float *f = truth + 2 * N * N;
    make_pair(s, m, 0.01, 7, i0, i1, truth);
    lm_flow_opts o;
    lm_flow_default_opts(&o, p);
    o.nthreads = 1; /* timings: one thread (the caller may run planes in parallel) */
    lm_err e = {0};
    double t0 = now_ms();
    lm_status st = lm_flow_compute(i0, i1, N, N, &o, f, &e);
    if (ms) *ms = now_ms() - t0;
    CHECK_MSG(st == LM_OK, "%s", e.msg);
    double epe = st == LM_OK ? mean_epe(f, truth) : 1e9;
    free(i0);
    return epe;
}

static const double MAGS[] = {0.4, 1.0, 3.0, 6.0, 12.0};

/* Translation of magnitude d at an odd angle, + 0.57 deg rotation + 0.5 % zoom (models.md). */
static motion motion_of(double d, int affine)
{
    motion m = {d * cos(0.6), d * sin(0.6), affine ? 0.01 : 0.0, affine ? 1.005 : 1.0};
    return m;
}

/* Bounds (px) asserted: medium preset for |d| <= 6 px and for 12 px; fast preset (all). */
static void epe_table(const char *name, const source *s, int shifts, double bound6,
                      double bound12, double bound_fast)
{
    double ms[2] = {0.0, 0.0};
    for (int affine = shifts ? 0 : 1; affine < 2; affine++) {
        printf("  %-8s %-7s", name, affine ? "affine" : "shift");
        for (int k = 0; k < 5; k++) {
            motion m = motion_of(MAGS[k], affine);
            double tm, tf, em = run_epe(s, &m, LM_FLOW_MEDIUM, &tm);
            double ef = run_epe(s, &m, LM_FLOW_FAST, &tf);
            ms[0] += tm / (shifts ? 10.0 : 5.0);
            ms[1] += tf / (shifts ? 10.0 : 5.0);
            printf(" |%4.1f| %.3f %.3f", MAGS[k], em, ef);
            double bound = MAGS[k] <= 6.0 ? bound6 : bound12;
            CHECK_MSG(em < bound, "%s %s |d| %.1f: medium EPE %.3f >= %.2f", name,
                      affine ? "affine" : "shift", MAGS[k], em, bound);
            CHECK_MSG(ef < bound_fast, "%s %s |d| %.1f: fast EPE %.3f >= %.2f", name,
                      affine ? "affine" : "shift", MAGS[k], ef, bound_fast);
        }
        printf("\n");
    }
    printf("  %s: mean time per 160x160 pair, 1 thread: medium %.1f ms, fast %.1f ms\n", name,
           ms[0], ms[1]);
}

static void test_epe_texture(void)
{
    source s;
    source_texture(&s, 42);
    epe_table("texture", &s, 1, 0.08, 0.10, 0.20);
}

static void test_epe_cave(void)
{
    const char *dir = getenv("LM_SHARED_DIR");
    char path[1024];
    snprintf(path, sizeof path, "%s/data/cave/chart_and_stuffed_toy_256", dir ? dir : "../shared");
    lm_cube cube;
    lm_err e = {0};
    if (lm_cube_read(path, &cube, &e) != LM_OK) {
        printf("  (CAVE band not available: %s; skipped)\n", e.msg);
        return;
    }
    source s;
    memset(&s, 0, sizeof s);
    s.band = lm_cube_band(&cube, 15); /* 550 nm */
    s.bh = cube.height;
    s.bw = cube.width;
    s.ox = 0.5 * (cube.width - N);
    s.oy = 0.5 * (cube.height - N);
    float mx = 0.0f, *band = lm_cube_band(&cube, 15);
    for (long i = 0; i < (long)cube.height * cube.width; i++) mx = fmaxf(mx, band[i]);
    for (long i = 0; i < (long)cube.height * cube.width; i++) band[i] /= mx;
    epe_table("cave550", &s, 0, 0.25, 0.30, 0.45);
    lm_cube_free(&cube);
}

/* Identical images: the flow must be ~0 everywhere. */
static void test_zero_motion(void)
{
    source s;
    source_texture(&s, 3);
    motion m = {0.0, 0.0, 0.0, 1.0};
    float *i0 = malloc(sizeof(float) * N * N * 6), *i1 = i0 + N * N, *truth = i1 + N * N;
    float *f = truth + 2 * N * N;
    make_pair(&s, &m, 0.0, 1, i0, i1, truth);
    lm_err e = {0};
    CHECK(lm_flow_compute(i0, i1, N, N, NULL, f, &e) == LM_OK);
    float mx = 0.0f;
    for (int i = 0; i < 2 * N * N; i++) mx = fmaxf(mx, fabsf(f[i]));
    printf("  zero motion: max |F| = %.2g px\n", mx);
    CHECK(mx < 1e-3f);
    free(i0);
}

/* Odd, non-square and minimal sizes (pyramid floors, patch grids flush with the border);
 * constant images give a zero flow (no NaN from the flat Hessians). */
static void test_odd_sizes(void)
{
    source s;
    source_texture(&s, 13);
    const int hs[3] = {53, 24, 31}, ws[3] = {71, 24, 97};
    for (int k = 0; k < 3; k++) {
        int h = hs[k], w = ws[k];
        float *i0 = malloc(sizeof(float) * (size_t)(h * w * 4)), *i1 = i0 + h * w;
        float *f = i1 + h * w;
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) {
                i0[y * w + x] = (float)source_at(&s, x, y);
                i1[y * w + x] = (float)source_at(&s, x - 1.5, y + 0.5); /* F = (1.5, -0.5) */
            }
        lm_err e = {0};
        for (int p = 0; p < 2; p++) {
            lm_flow_opts o;
            lm_flow_default_opts(&o, (lm_flow_preset)p);
            CHECK_MSG(lm_flow_compute(i0, i1, h, w, &o, f, &e) == LM_OK, "%s", e.msg);
            double epe = 0.0;
            int cnt = 0;
            for (int y = 2; y < h - 2; y++)
                for (int x = 2; x < w - 3; x++, cnt++)
                    epe += hypot(f[y * w + x] - 1.5, f[h * w + y * w + x] + 0.5);
            printf("  %dx%d %s: mean EPE %.3f\n", h, w, p ? "fast" : "medium", epe / cnt);
            CHECK_MSG(epe / cnt < 0.2, "%dx%d preset %d: EPE %.3f", h, w, p, epe / cnt);
        }
        for (int i = 0; i < h * w; i++) i0[i] = i1[i] = 0.25f;
        CHECK(lm_flow_compute(i0, i1, h, w, NULL, f, &e) == LM_OK);
        float mx = 0.0f;
        for (int i = 0; i < 2 * h * w; i++) mx = fmaxf(mx, fabsf(f[i]));
        CHECK(mx == 0.0f); /* also false for NaN */
        free(i0);
    }
}

/* Hand values of the sampler and the warp (clamped borders, bilinear). */
static void test_warp_hand(void)
{
    const float img[6] = {0, 1, 2, 10, 11, 12}; /* 2 x 3 */
    CHECK_CLOSE(lm_flow_sample(img, 2, 3, 0.5f, 0.5f), 5.5, 1e-6, 0);
    CHECK_CLOSE(lm_flow_sample(img, 2, 3, 1.25f, 0.0f), 1.25, 1e-6, 0);
    CHECK_CLOSE(lm_flow_sample(img, 2, 3, -3.0f, 7.0f), 10.0, 1e-6, 0);
    CHECK_CLOSE(lm_flow_sample(img, 2, 3, 9.0f, 0.25f), 4.5, 1e-6, 0);
    float flow[12] = {1, 1, 1, 1, 1, 1, 0, 0, 0, -1, -1, -1}, out[6];
    lm_flow_warp(img, 2, 3, flow, 1.0f, out, 1);
    const float want[6] = {1, 2, 2, 1, 2, 2};
    CHECK_ARRAY_CLOSE(out, want, 6, 1e-6, 0);
    lm_flow_warp(img, 2, 3, flow, -0.5f, out, 2);
    const float want2[6] = {0, 0.5f, 1.5f, 10, 10.5f, 11.5f};
    CHECK_ARRAY_CLOSE(out, want2, 6, 1e-6, 0); /* row 1 samples y = 1.5, clamped to 1 */
}

/* Warping I1 with the true flow reproduces I0 (where the destination is inside); warping with
 * the estimated flow does almost as well; an integer shift is reproduced exactly. */
static void test_warp_reproduces(void)
{
    source s;
    source_texture(&s, 5);
    motion m = motion_of(3.0, 1);
    float *i0 = malloc(sizeof(float) * N * N * 7), *i1 = i0 + N * N, *truth = i1 + N * N;
    float *f = truth + 2 * N * N, *w = f + 2 * N * N;
    make_pair(&s, &m, 0.0, 1, i0, i1, truth);
    double e_true = 0.0, e_est = 0.0, e_none = 0.0;
    long cnt = 0;
    lm_err e = {0};
    CHECK(lm_flow_compute(i0, i1, N, N, NULL, f, &e) == LM_OK);
    float *w2 = malloc(sizeof(float) * N * N);
    lm_flow_warp(i1, N, N, truth, 1.0f, w, 2);
    lm_flow_warp(i1, N, N, f, 1.0f, w2, 2);
    for (int y = 8; y < N - 8; y++)
        for (int x = 8; x < N - 8; x++) {
            long i = (long)y * N + x;
            e_true += (w[i] - i0[i]) * (w[i] - i0[i]);
            e_est += (w2[i] - i0[i]) * (w2[i] - i0[i]);
            e_none += (i1[i] - i0[i]) * (i1[i] - i0[i]);
            cnt++;
        }
    e_true = sqrt(e_true / cnt), e_est = sqrt(e_est / cnt), e_none = sqrt(e_none / cnt);
    printf("  warp RMS: true flow %.4f, estimated %.4f, no warp %.4f\n", e_true, e_est, e_none);
    /* what remains with the true flow is the bilinear interpolation error of the texture */
    CHECK(e_true < 0.08 * e_none);
    CHECK(e_est < 1.5 * e_true);
    motion sh = {5.0, -2.0, 0.0, 1.0};
    make_pair(&s, &sh, 0.0, 1, i0, i1, truth);
    lm_flow_warp(i1, N, N, truth, 1.0f, w, 1);
    for (int y = 4; y < N - 8; y++) CHECK_ARRAY_CLOSE(w + y * N, i0 + y * N, N - 8, 1e-6, 0);
    free(w2);
    free(i0);
}

static void test_intermediate_hand(void)
{
    float f01[4] = {2, 2, 0, 1}, f10[4] = {-2, -2, 0, -1}, ft0[4], ft1[4];
    lm_flow_intermediate(f01, f10, 2, 0.5f, ft0, ft1);
    const float w0[4] = {-1, -1, 0, -0.5f}, w1[4] = {1, 1, 0, 0.5f};
    CHECK_ARRAY_CLOSE(ft0, w0, 4, 1e-6, 0);
    CHECK_ARRAY_CLOSE(ft1, w1, 4, 1e-6, 0);
    lm_flow_intermediate(f01, f10, 2, 0.25f, ft0, ft1); /* -(3/16) 2 + (1/16)(-2) = -0.5 */
    CHECK_CLOSE(ft0[0], -0.5, 1e-6, 0);
    CHECK_CLOSE(ft1[0], 0.5625 * 2 + 0.1875 * 2, 1e-6, 0);
}

/* Frame between two frames of a translating texture vs the true intermediate frame. */
static void test_interpolate(void)
{
    source s;
    source_texture(&s, 9);
    float *i0 = malloc(sizeof(float) * N * N * 7), *i1 = i0 + N * N, *truth = i1 + N * N;
    float *mid = truth + 2 * N * N, *out = mid + N * N, *junk = out + N * N;
    motion m = {4.0, -3.0, 0.0, 1.0}, h = {1.0, -0.75, 0.0, 1.0}; /* h: the t = 0.25 frame */
    make_pair(&s, &m, 0.0, 1, i0, i1, truth);
    make_pair(&s, &h, 0.0, 1, junk, mid, truth);
    lm_err e = {0};
    CHECK(lm_flow_interpolate(i0, i1, N, N, 0.25f, NULL, out, &e) == LM_OK);
    double err = 0.0, base = 0.0;
    long cnt = 0;
    for (int y = 10; y < N - 10; y++)
        for (int x = 10; x < N - 10; x++) {
            long i = (long)y * N + x;
            err += (out[i] - mid[i]) * (out[i] - mid[i]);
            base += (i0[i] - mid[i]) * (i0[i] - mid[i]);
            cnt++;
        }
    printf("  interpolation t=0.25 RMS %.4f (nearest frame %.4f)\n", sqrt(err / cnt),
           sqrt(base / cnt));
    CHECK(sqrt(err / cnt) < 0.05 * sqrt(base / cnt));
    free(i0);
}

/* Same inputs -> bitwise the same flow, for 1 and 2 threads. */
static void test_determinism(void)
{
    source s;
    source_texture(&s, 11);
    motion m = motion_of(6.0, 1);
    float *i0 = malloc(sizeof(float) * N * N * 8), *i1 = i0 + N * N, *truth = i1 + N * N;
    float *a = truth + 2 * N * N, *b = a + 2 * N * N;
    make_pair(&s, &m, 0.01, 2, i0, i1, truth);
    lm_flow_opts o;
    lm_err e = {0};
    for (int p = 0; p < 2; p++) {
        lm_flow_default_opts(&o, (lm_flow_preset)p);
        o.nthreads = 2;
        CHECK(lm_flow_compute(i0, i1, N, N, &o, a, &e) == LM_OK);
        CHECK(lm_flow_compute(i0, i1, N, N, &o, b, &e) == LM_OK);
        CHECK(memcmp(a, b, sizeof(float) * 2 * N * N) == 0);
        o.nthreads = 1;
        CHECK(lm_flow_compute(i0, i1, N, N, &o, b, &e) == LM_OK);
        CHECK(memcmp(a, b, sizeof(float) * 2 * N * N) == 0);
    }
    free(i0);
}

static void test_flow_errors(void)
{
    float img[40 * 40] = {0}, img2[40 * 40] = {0}, f[2 * 40 * 40];
    lm_flow_opts o;
    lm_flow_default_opts(&o, LM_FLOW_MEDIUM);
    lm_err e = {0};
    CHECK(lm_flow_compute(img, img2, 20, 40, &o, f, &e) == LM_ERR_SHAPE); /* < 2 x 12 */
    CHECK(strstr(e.msg, "flow:") != NULL);
    lm_err_clear(&e);
    CHECK(lm_flow_compute(img, img2, 40, 0, &o, f, &e) == LM_ERR_SHAPE);
    lm_err_clear(&e);
    CHECK(lm_flow_compute(img, NULL, 40, 40, &o, f, &e) == LM_ERR_ARG);
    lm_err_clear(&e);
    o.patch = 0;
    CHECK(lm_flow_compute(img, img2, 40, 40, &o, f, &e) == LM_ERR_ARG);
    CHECK(strstr(e.msg, "flow:") != NULL);
    lm_err_clear(&e);
    lm_flow_default_opts(&o, LM_FLOW_FAST);
    img2[5 * 40 + 7] = NAN;
    CHECK(lm_flow_compute(img, img2, 40, 40, &o, f, &e) == LM_ERR_NUMERIC);
    CHECK(strstr(e.msg, "x=7, y=5") != NULL);
    lm_err_clear(&e);
    CHECK(lm_flow_interpolate(img, img2, 40, 40, 0.5f, &o, NULL, &e) == LM_ERR_ARG);
}

/* Unshuffle by hand on a 6 x 8 frame (two 3 x 4 tiles each way), and the round trip. */
static void test_unshuffle_remosaic(void)
{
    float raw[48], planes[48], back[48];
    for (int i = 0; i < 48; i++) raw[i] = (float)i;
    lm_err e = {0};
    CHECK(lm_align_unshuffle(raw, 6, 8, 3, 4, planes, &e) == LM_OK);
    /* plane t = 6 (row 1, col 2) holds pixels (1, 2), (1, 6), (4, 2), (4, 6) */
    const float want6[4] = {1 * 8 + 2, 1 * 8 + 6, 4 * 8 + 2, 4 * 8 + 6};
    CHECK_ARRAY_CLOSE(planes + 6 * 4, want6, 4, 0, 0);
    CHECK_CLOSE(planes[0], 0, 0, 0);
    CHECK_CLOSE(planes[11 * 4 + 3], 5 * 8 + 7, 0, 0);
    CHECK(lm_align_remosaic(planes, 2, 2, 3, 4, back, &e) == LM_OK);
    CHECK_ARRAY_CLOSE(back, raw, 48, 0, 0);
    CHECK(lm_align_unshuffle(raw, 7, 8, 3, 4, planes, &e) == LM_ERR_SHAPE);
    CHECK(strstr(e.msg, "align:") != NULL);
    lm_err_clear(&e);
    CHECK(lm_align_remosaic(planes, 0, 2, 3, 4, back, &e) == LM_ERR_SHAPE);
}

/* Times of the default system, by hand from system.md §1-2: window centres in us over the
 * frame period (1e6 / 30 us: frames start 33.3 ms apart), not exposure + readout (29.7 ms). */
static void test_phase_times(void)
{
    lm_system sys;
    lm_err e = {0};
    if (lm_system_default(&sys, &e) != LM_OK) {
        fprintf(stderr, "default system: %s\n", e.msg);
        CHECK(0);
        return;
    }
    float t[12];
    int ref = -1;
    const double T = 1e6 / 30.0;
    CHECK(lm_align_phase_times(&sys, t, &ref, &e) == LM_OK);
    CHECK(ref == 6);                            /* row 1, col 2: Lime */
    CHECK_CLOSE(t[6], 11700.0 / T, 1e-6, 0);  /* Lime 11100-12300 */
    CHECK_CLOSE(t[0], 2250.0 / T, 1e-6, 0);   /* FarRed 0-4500 */
    CHECK_CLOSE(t[8], 16650.0 / T, 1e-6, 0);  /* Amber 13650-19650 */
    CHECK_CLOSE(t[11], 23025.0 / T, 1e-6, 0); /* Cyan 22350-23700 */
    lm_system_free(&sys);
}

/* A 2 x 2 tile, 1000-us sub-frames: A 0-2000, lime 2000-3000, B 3000-6000, C 6000-8000;
 * readout 1000 us but frames every 10000 us (exposure + readout would be 9000). */
static const char *SYS4 =
    "{\"version\": 1, \"grid\": {\"start_nm\": 500, \"step_nm\": 10, \"count\": 2},"
    "\"sensor\": {\"width\": 64, \"height\": 64, \"qe\": [1, 1]},"
    "\"subframe_us\": 1000, \"readout_us\": 1000, \"frame_period_us\": 10000,"
    "\"leds\": [{\"name\": \"A\", \"subframes\": 2, \"emission\": [1, 0.5]},"
    "           {\"name\": \"%s\", \"subframes\": 1, \"emission\": [0.5, 1]},"
    "           {\"name\": \"B\", \"subframes\": 3, \"emission\": [0.2, 1]},"
    "           {\"name\": \"C\", \"subframes\": 2, \"emission\": [1, 0.2]}],"
    "\"tile_map\": [[\"A\", \"%s\"], [\"B\", \"C\"]]}";

/* The time base is the system's frame period, and the reference phase is the LED whose window
 * centre the video simulator uses as ground-truth instant (with and without a Lime LED). */
static void test_phase_times_frame_period(void)
{
    const char *names[2] = {"lime", "D"};
    const int want_ref[2] = {1, 2}; /* no Lime: B, on at the exposure midpoint (4000 us) */
    for (int k = 0; k < 2; k++) {
        char json[1024];
        snprintf(json, sizeof json, SYS4, names[k], names[k]);
        lm_system sys;
        lm_err e = {0};
        CHECK_MSG(lm_system_parse(json, ".", "sys4", &sys, &e) == LM_OK, "%s", e.msg);
        float t[4];
        int ref = -1;
        CHECK_MSG(lm_align_phase_times(&sys, t, &ref, &e) == LM_OK, "%s", e.msg);
        const float want[4] = {0.1f, 0.25f, 0.45f, 0.7f};
        CHECK_ARRAY_CLOSE(t, want, 4, 1e-6, 0);
        CHECK(ref == want_ref[k]);
        CHECK_CLOSE(lm_video_gt_time_us(&sys), t[ref] * 10000.0, 1e-3, 0);
        CHECK_CLOSE(lm_video_frame_start_us(&sys, 2) - lm_video_frame_start_us(&sys, 1), 10000.0,
                    1e-9, 0);
        lm_system_free(&sys);
    }
}

#define AH 64
#define NP 12
/* Plane p of frame i of a texture translating by v px per frame: S(x - v (i + t_p)). */
static void make_video_frame(const source *s, const float *t, int i, double vx, double vy,
                             float *planes)
{
    for (int p = 0; p < NP; p++)
        for (int y = 0; y < AH; y++)
            for (int x = 0; x < AH; x++)
                planes[(p * AH + y) * AH + x] =
                    (float)source_at(s, x - vx * (i + t[p]), y - vy * (i + t[p]));
}

/* RMS over the interior (8 px margin) of plane p against the reference-time truth. */
static double plane_rms(const float *a, const float *b)
{
    double e = 0.0;
    int cnt = 0;
    for (int y = 8; y < AH - 8; y++)
        for (int x = 8; x < AH - 8; x++, cnt++)
            e += (a[y * AH + x] - b[y * AH + x]) * (a[y * AH + x] - b[y * AH + x]);
    return sqrt(e / cnt);
}

/* Aligned planes vs the planes rendered at the reference time: much closer than unaligned,
 * for the normal case and both edge fallbacks; no neighbour copies; ref plane is copied. */
static void test_align_video(void)
{
    const float t[NP] = {0.076f, 0.179f, 0.234f, 0.275f, 0.318f, 0.361f,
                         0.394f, 0.437f, 0.561f, 0.674f, 0.720f, 0.776f};
    const int ref = 6;
    source s;
    source_texture(&s, 21);
    size_t n = (size_t)NP * AH * AH;
    float *fr = malloc(sizeof(float) * n * 5), *truth = fr + 3 * n, *out = fr + 4 * n;
    for (int i = 0; i < 3; i++) make_video_frame(&s, t, i, 6.0, -4.0, fr + i * n);
    float tref[NP];
    for (int p = 0; p < NP; p++) tref[p] = t[ref];
    make_video_frame(&s, tref, 1, 6.0, -4.0, truth);
    const float *cases[3][2] = {{fr, fr + 2 * n}, {fr, NULL}, {NULL, fr + 2 * n}};
    const char *names[3] = {"both neighbours", "no next", "no previous"};
    lm_flow_opts o;
    lm_flow_default_opts(&o, LM_FLOW_MEDIUM);
    for (int c = 0; c < 3; c++) {
        lm_err e = {0};
        CHECK(lm_align_frame(cases[c][0], fr + n, cases[c][1], NP, AH, AH, t, ref, &o, NULL, out,
                             &e) == LM_OK);
        double worst = 0.0, before = 0.0;
        for (int p = 0; p < NP; p++) {
            size_t off = (size_t)p * AH * AH;
            double ra = plane_rms(out + off, truth + off);
            double rb = plane_rms(fr + n + off, truth + off);
            if (getenv("LM_FLOW_VERBOSE"))
                printf("    plane %d: %.4f (unaligned %.4f)\n", p, ra, rb);
            /* 0.006: bilinear-resampling floor of this texture (see test_warp_reproduces) */
            if (p != ref)
                CHECK_MSG(ra < 0.15 * rb || ra < 0.006, "%s plane %d: %.4f vs %.4f", names[c], p,
                          ra, rb);
            worst = ra > worst ? ra : worst;
            before = rb > before ? rb : before;
        }
        CHECK_ARRAY_CLOSE(out + ref * AH * AH, fr + n + ref * AH * AH, AH * AH, 0, 0);
        printf("  align (%s): worst plane RMS %.4f (unaligned %.4f)\n", names[c], worst, before);
    }
    lm_err e = {0};
    CHECK(lm_align_frame(NULL, fr + n, NULL, NP, AH, AH, t, ref, &o, NULL, out, &e) == LM_OK);
    CHECK_ARRAY_CLOSE(out, fr + n, (long)n, 0, 0);
    CHECK(lm_align_frame(fr, fr + n, NULL, NP, AH, AH, t, NP, &o, NULL, out, &e) == LM_ERR_ARG);
    CHECK(strstr(e.msg, "align:") != NULL);
    lm_err_clear(&e);
    CHECK(lm_align_frame(fr, fr + n, NULL, NP, 16, 16 * 16, t, ref, &o, NULL, out, &e) == LM_ERR_SHAPE);
    CHECK(strstr(e.msg, "plane 0") != NULL && strstr(e.msg, "flow:") != NULL);
    free(fr);
}

int main(void)
{
    printf("mean EPE (px) on 160x160, noise sigma 0.01, (medium, fast) at |d|:\n");
    RUN(test_epe_texture);
    RUN(test_epe_cave);
    RUN(test_zero_motion);
    RUN(test_odd_sizes);
    RUN(test_warp_hand);
    RUN(test_warp_reproduces);
    RUN(test_intermediate_hand);
    RUN(test_interpolate);
    RUN(test_determinism);
    RUN(test_flow_errors);
    RUN(test_unshuffle_remosaic);
    RUN(test_phase_times);
    RUN(test_phase_times_frame_period);
    RUN(test_align_video);
    return check_summary();
}

/* test_opencl_move.c — CPU vs OpenCL agreement, forward and input gradients, of the data
 * movement ops: permute/transpose, pixel (un)shuffle, concat/split, pad2d (zero, reflect),
 * bilinear resize (both align_corners, up and down), phase-aware mosaic upsampling, and the
 * per-phase mean and scale of mosaic attention (sums in another order: atol 1e-5).
 * These only move values or take fixed weighted sums in the CPU's order, so tolerances are
 * tight (exact for pure moves; atol 1e-6, rtol 1e-5 for resize; atol 1e-5 for the long
 * weighted sums of the mosaic backward, where fused multiply-adds may differ). Exit 77 only when no OpenCL platform exists. */
#include "tests/test_opencl_util.h"

#define SHAPE(...) {__VA_ARGS__}

typedef struct perm_sel { int perm[5]; int d0, d1; } perm_sel;
static lm_tensor *f_permute(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n;
    const perm_sel *p = u;
    return p->d0 != p->d1 ? lm_transpose(c, in[0], p->d0, p->d1) : lm_permute(c, in[0], p->perm);
}

typedef struct shuf_sel { int fy, fx, inverse; } shuf_sel;
static lm_tensor *f_shuffle(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n;
    const shuf_sel *s = u;
    return s->inverse ? lm_pixel_shuffle(c, in[0], s->fy, s->fx)
                      : lm_pixel_unshuffle(c, in[0], s->fy, s->fx);
}

/* phase_scale(x, s) * (1 + phase_mean(x) broadcast): both ops and both of phase_scale's inputs. */
static lm_tensor *f_phase(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n;
    const shuf_sel *s = u;
    lm_tensor *m = lm_phase_mean(c, in[0], s->fy, s->fx);
    lm_tensor *y = lm_phase_scale(c, in[0], in[1], s->fy, s->fx);
    return lm_phase_scale(c, y, lm_add_scalar(c, m, 1.0f), s->fy, s->fx);
}

typedef struct cat_sel { int dim; } cat_sel;
static lm_tensor *f_concat(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    return lm_concat(c, in, n, ((cat_sel *)u)->dim);
}

/* split x along dim 1 into {2, 3, 2} and join the parts back in reverse order */
static lm_tensor *f_split(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n, (void)u;
    lm_tensor *parts[3];
    if (lm_split(c, in[0], 1, 3, (int[]){2, 3, 2}, parts)) return NULL;
    lm_tensor *rev[3] = {parts[2], parts[1], parts[0]};
    return lm_concat(c, rev, 3, 1);
}

typedef struct pad_sel { int t, b, l, r; lm_pad_mode mode; } pad_sel;
static lm_tensor *f_pad(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n;
    const pad_sel *p = u;
    return lm_pad2d(c, in[0], p->t, p->b, p->l, p->r, p->mode);
}

typedef struct resize_sel { int oh, ow, ac; } resize_sel;
static lm_tensor *f_resize(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n;
    const resize_sel *r = u;
    return lm_resize_bilinear(c, in[0], r->oh, r->ow, r->ac);
}

typedef struct mosaic_sel { int ty, tx, nch; int py[16], px[16]; } mosaic_sel;
static lm_tensor *f_mosaic(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n;
    const mosaic_sel *m = u;
    return lm_mosaic_upsample(c, in[0], m->ty, m->tx, m->nch, m->py, m->px);
}

static void test_permute(void)
{
    perm_sel a = {{2, 0, 3, 1, 0}, 0, 0}, b = {{0}, -1, 1}, d = {{4, 2, 0, 1, 3}, 0, 0};
    agree_case k1 = {"permute 2031", f_permute, &a, 1, {4}, {SHAPE(2, 3, 4, 5)}, .atol = 0,
                     .rtol = 0};
    agree_case k2 = {"transpose -1,1", f_permute, &b, 1, {4}, {SHAPE(2, 3, 4, 5)}, .atol = 0,
                     .rtol = 0};
    agree_case k3 = {"permute 5-d", f_permute, &d, 1, {5}, {SHAPE(2, 3, 2, 4, 3)}, .atol = 0,
                     .rtol = 0};
    check_agree(&k1, 1);
    check_agree(&k2, 2);
    check_agree(&k3, 3);
}

static void test_shuffle(void)
{
    shuf_sel u23 = {2, 3, 0}, s22 = {2, 2, 1}, s42 = {4, 2, 1};
    agree_case k1 = {"pixel_unshuffle 2x3", f_shuffle, &u23, 1, {4}, {SHAPE(2, 3, 8, 12)},
                     .atol = 0, .rtol = 0};
    agree_case k2 = {"pixel_shuffle 2x2", f_shuffle, &s22, 1, {4}, {SHAPE(2, 12, 4, 5)},
                     .atol = 0, .rtol = 0};
    agree_case k3 = {"pixel_shuffle 4x2", f_shuffle, &s42, 1, {4}, {SHAPE(1, 16, 3, 4)},
                     .atol = 0, .rtol = 0};
    check_agree(&k1, 10);
    check_agree(&k2, 11);
    check_agree(&k3, 12);
    shuf_sel p34 = {3, 4, 0}, p21 = {2, 1, 0};
    agree_case k4 = {"phase mean + scale 3x4", f_phase, &p34, 2, {4, 4},
                     {SHAPE(2, 3, 9, 16), SHAPE(2, 36, 1, 1)}, .atol = 1e-5, .rtol = 1e-5};
    agree_case k5 = {"phase mean + scale 2x1", f_phase, &p21, 2, {4, 2},
                     {SHAPE(1, 5, 4, 7), SHAPE(1, 10)}, .atol = 1e-5, .rtol = 1e-5};
    check_agree(&k4, 13);
    check_agree(&k5, 14);
}

static void test_concat_split(void)
{
    cat_sel d1 = {1}, dl = {-1};
    agree_case k1 = {"concat dim 1", f_concat, &d1, 3, {4, 4, 4},
                     {SHAPE(2, 2, 3, 4), SHAPE(2, 5, 3, 4), SHAPE(2, 1, 3, 4)}, .no_grad = {0, 1, 0},
                     .atol = 0, .rtol = 0};
    agree_case k2 = {"concat last dim", f_concat, &dl, 2, {3, 3}, {SHAPE(3, 4, 2), SHAPE(3, 4, 5)},
                     .atol = 0, .rtol = 0};
    check_agree(&k1, 20);
    check_agree(&k2, 21);
    /* more inputs than a tape node holds: several nodes share the output */
    agree_case k3 = {"concat 6 (dim 0)", f_concat, &(cat_sel){0}, 6, {2, 2, 2, 2, 2, 2},
                     {SHAPE(1, 3), SHAPE(2, 3), SHAPE(1, 3), SHAPE(3, 3), SHAPE(1, 3), SHAPE(2, 3)},
                     .atol = 0, .rtol = 0};
    check_agree(&k3, 22);
    agree_case k4 = {"split + concat", f_split, NULL, 1, {4}, {SHAPE(2, 7, 3, 3)}, .atol = 0,
                     .rtol = 0};
    check_agree(&k4, 23);
}

static void test_pad(void)
{
    pad_sel z = {1, 2, 3, 1, LM_PAD_ZERO}, r = {2, 1, 3, 2, LM_PAD_REFLECT},
            r2 = {3, 3, 2, 2, LM_PAD_REFLECT};
    agree_case k1 = {"pad zero", f_pad, &z, 1, {4}, {SHAPE(2, 3, 4, 5)}, .atol = 0, .rtol = 0};
    agree_case k2 = {"pad reflect", f_pad, &r, 1, {4}, {SHAPE(2, 3, 4, 5)}, .atol = 1e-7,
                     .rtol = 1e-6};
    agree_case k3 = {"pad reflect 4x3 by 3,2", f_pad, &r2, 1, {4}, {SHAPE(1, 2, 4, 3)},
                     .atol = 1e-7, .rtol = 1e-6};
    check_agree(&k1, 30);
    check_agree(&k2, 31);
    check_agree(&k3, 32);
}

static void test_resize(void)
{
    resize_sel up0 = {11, 13, 0}, up1 = {11, 13, 1}, dn0 = {5, 7, 0}, dn1 = {5, 7, 1},
               one = {1, 1, 1}, x4 = {24, 20, 0};
    resize_sel *sels[6] = {&up0, &up1, &dn0, &dn1, &one, &x4};
    const char *names[6] = {"resize up ac0", "resize up ac1", "resize down ac0",
                            "resize down ac1", "resize to 1x1 ac1", "resize x4 ac0"};
    int shapes[6][4] = {{2, 3, 5, 7}, {2, 3, 5, 7}, {1, 2, 16, 12},
                        {1, 2, 16, 12}, {1, 2, 4, 5}, {1, 2, 6, 5}};
    for (int i = 0; i < 6; i++) {
        agree_case k = {names[i], f_resize, sels[i], 1, {4}, .atol = 1e-6, .rtol = 1e-5};
        memcpy(k.shape[0], shapes[i], sizeof shapes[i]);
        check_agree(&k, 40 + (uint64_t)i);
    }
}

static void test_mosaic(void)
{
    mosaic_sel m6 = {2, 3, 6, {0, 0, 0, 1, 1, 1}, {0, 1, 2, 0, 1, 2}};
    mosaic_sel m4 = {2, 2, 4, {1, 0, 1, 1}, {0, 1, 1, 0}}; /* repeated phase */
    mosaic_sel m16 = {4, 4, 16, {0}, {0}};
    for (int k = 0; k < 16; k++) m16.py[k] = k / 4, m16.px[k] = k % 4;
    mosaic_sel one = {4, 2, 2, {3, 1}, {1, 0}}; /* a single tile row: ns == 1 */
    agree_case k1 = {"mosaic 2x3 all phases", f_mosaic, &m6, 1, {4}, {SHAPE(2, 1, 8, 12)},
                     .atol = 1e-5, .rtol = 1e-5};
    agree_case k2 = {"mosaic 2x2 repeated", f_mosaic, &m4, 1, {4}, {SHAPE(1, 1, 6, 8)},
                     .atol = 1e-5, .rtol = 1e-5};
    agree_case k3 = {"mosaic 4x4 16 channels", f_mosaic, &m16, 1, {4}, {SHAPE(1, 1, 16, 20)},
                     .atol = 1e-5, .rtol = 1e-5};
    agree_case k4 = {"mosaic single tile row", f_mosaic, &one, 1, {4}, {SHAPE(2, 1, 4, 6)},
                     .atol = 1e-5, .rtol = 1e-5};
    check_agree(&k1, 50);
    check_agree(&k2, 51);
    check_agree(&k3, 52);
    check_agree(&k4, 53);
}

int main(void)
{
    int s = opencl_setup();
    if (s) return s;
    RUN(test_permute);
    RUN(test_shuffle);
    RUN(test_concat_split);
    RUN(test_pad);
    RUN(test_resize);
    RUN(test_mosaic);
    lm_cl_backend_free(clb_);
    return check_summary();
}

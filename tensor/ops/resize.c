/* resize.c — bilinear resize of B x C x H x W to B x C x oh x ow, as PyTorch
 * F.interpolate(mode='bilinear', align_corners=0/1) computes it (float arithmetic):
 *   align_corners = 0: src = max(0, (dst + 0.5) * in/out - 0.5)
 *   align_corners = 1: src = dst * (in - 1)/(out - 1)  (0 when out == 1)
 *   i0 = min(floor(src), in - 1), i1 = min(i0 + 1, in - 1), lambda = src - i0.
 * Per-axis index/weight tables live in the ctx arena. The backward is separable and
 * deterministic for any thread count: (1) scatter each gradient row along x into a row of
 * in-width (one row per job), (2) scatter those rows along y into the input gradient, one
 * fixed band of columns per job, rows in order.
 * What it is not: antialiased downsampling, nearest/bicubic modes, scale-factor arguments. */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"

typedef struct axis_tab { int *i0, *i1; float *l; } axis_tab;

/* Table for an axis of `in` source and `out` destination positions (arena). */
static int axis_table(lm_ctx *c, int in, int out, int ac, axis_tab *t)
{
    t->i0 = lm_ctx_alloc(c, (size_t)out * 2 * sizeof(int));
    t->l = t->i0 ? lm_ctx_alloc(c, (size_t)out * sizeof(float)) : NULL;
    if (!t->l) return -1;
    t->i1 = t->i0 + out;
    float scale = lm_resize_scale(in, out, ac);
    for (int o = 0; o < out; o++) {
        float s = ac ? scale * (float)o : scale * ((float)o + 0.5f) - 0.5f;
        if (s < 0.0f) s = 0.0f;
        int i = (int)s;
        if (i > in - 1) i = in - 1;
        float l = s - (float)i;
        t->i0[o] = i;
        t->i1[o] = i < in - 1 ? i + 1 : i;
        t->l[o] = l < 0.0f ? 0.0f : (l > 1.0f ? 1.0f : l);
    }
    return 0;
}

/* forward: t[0] = x (B x C x H x W), t[1] = y (B x C x oh x ow); y = */
static int resize_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_resize_params *p = params;
    const lm_tensor *x = t[0], *y = t[1];
    const int H = x->shape[2], W = x->shape[3], oh = y->shape[2], ow = y->shape[3];
    axis_tab ty, tx;
    if (axis_table(c, H, oh, p->align_corners, &ty) || axis_table(c, W, ow, p->align_corners, &tx))
        return c->status;
    const long rows = (long)y->shape[0] * y->shape[1] * oh;
    const float *xd = x->data;
    float *yd = y->data;
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c))
    for (long r = 0; r < rows; r++) {
        const int Y = (int)(r % oh);
        const float *plane = xd + (r / oh) * H * (long)W;
        const float *r0 = plane + (long)ty.i0[Y] * W, *r1 = plane + (long)ty.i1[Y] * W;
        const float ly = ty.l[Y], hy = 1.0f - ly;
        float *yr = yd + r * ow;
        for (int X = 0; X < ow; X++) {
            const int a = tx.i0[X], b = tx.i1[X];
            const float lx = tx.l[X], hx = 1.0f - lx;
            yr[X] = hy * (hx * r0[a] + lx * r0[b]) + ly * (hx * r1[a] + lx * r1[b]);
        }
    }
    return 0;
}

/* backward: t[0] = gx (B x C x H x W), t[1] = gy (B x C x oh x ow); gx += */
static int resize_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    enum { BAND = 64 };
    const lm_resize_params *p = params;
    const lm_tensor *gx = t[0], *gy = t[1];
    const int H = gx->shape[2], W = gx->shape[3], oh = gy->shape[2], ow = gy->shape[3];
    const long planes = (long)gx->shape[0] * gx->shape[1], rows = planes * oh;
    axis_tab ty, tx;
    if (axis_table(c, H, oh, p->align_corners, &ty) || axis_table(c, W, ow, p->align_corners, &tx))
        return c->status;
    float *tmp = lm_ctx_alloc(c, (size_t)rows * W * sizeof(float)); /* rows x W */
    if (!tmp) return c->status;
    const float *gyd = gy->data;
    float *gxd = gx->data;
    const int nt_ = lm_nthreads(c);
#pragma omp parallel for schedule(static) num_threads(nt_)
    for (long r = 0; r < rows; r++) {
        float *tr = tmp + r * W;
        const float *gr = gyd + r * ow;
        for (int i = 0; i < W; i++) tr[i] = 0.0f;
        for (int X = 0; X < ow; X++) {
            tr[tx.i0[X]] += (1.0f - tx.l[X]) * gr[X];
            tr[tx.i1[X]] += tx.l[X] * gr[X];
        }
    }
    const long nband = (W + BAND - 1) / BAND, jobs = planes * nband;
#pragma omp parallel for schedule(static) num_threads(nt_)
    for (long j = 0; j < jobs; j++) {
        const long pl = j / nband;
        const int x0 = (int)(j % nband) * BAND, x1 = x0 + BAND < W ? x0 + BAND : W;
        float *g = gxd + pl * H * (long)W;
        for (int Y = 0; Y < oh; Y++) {
            const float *tr = tmp + (pl * oh + Y) * W;
            float *g0 = g + (long)ty.i0[Y] * W, *g1 = g + (long)ty.i1[Y] * W;
            const float ly = ty.l[Y], hy = 1.0f - ly;
            for (int i = x0; i < x1; i++) g0[i] += hy * tr[i];
            for (int i = x0; i < x1; i++) g1[i] += ly * tr[i];
        }
    }
    return 0;
}
LM_KERNEL(resize_bilinear_fwd, resize_fwd_cpu);
LM_KERNEL(resize_bilinear_bwd, resize_bwd_cpu);

static void resize_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *t[2] = {lm_grad(c, x), n->out->grad};
    if (t[0]) lm_kernel_run(c, &lm_kernel_resize_bilinear_bwd, t, 2, n->params);
}

lm_tensor *lm_resize_bilinear(lm_ctx *c, lm_tensor *x, int oh, int ow, int align_corners)
{
    if (!lm_check_inputs(c, "resize_bilinear", 1, x)) return NULL;
    char sb[64];
    if (x->ndim != 4) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "resize_bilinear: input %s is not B x C x H x W",
                    lm_shape_str(x, sb, sizeof sb));
        return NULL;
    }
    if (oh < 1 || ow < 1) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "resize_bilinear: output size %d x %d for input %s", oh, ow,
                    lm_shape_str(x, sb, sizeof sb));
        return NULL;
    }
    x = lm_contiguous(c, x);
    if (!x) return NULL;
    int s[4] = {x->shape[0], x->shape[1], oh, ow};
    lm_tensor *y = lm_tensor_new(c, 4, s);
    if (!y) return NULL;
    lm_resize_params p = {align_corners ? 1 : 0};
    lm_tensor *t[2] = {x, y};
    if (lm_kernel_run(c, &lm_kernel_resize_bilinear_fwd, t, 2, &p)) return NULL;
    lm_record(c, "resize_bilinear", resize_backward, y, &x, 1, &p, sizeof p);
    return y;
}

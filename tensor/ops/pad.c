/* pad.c — pad2d: zero or reflect padding of the last two dims of a B x C x H x W tensor.
 * What it is: output (H + top + bottom) x (W + left + right); each output row/column reads one
 * source row/column given by a table (-1 = zero padding). Reflect is PyTorch 'reflect': the
 * edge is not repeated (row -1 reads row 1), so each pad must be smaller than the size.
 * Backward scatters through the same tables (+=); with reflect several outputs land on one
 * input, so the backward runs one plane per job, each in a fixed order.
 * What it is not: replicate/circular padding, negative (cropping) pads. */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"

/* Source index of each of the n + lo + hi output positions (-1 = zero). */
static void pad_table(int *tab, int n, int lo, int hi, int mode)
{
    for (int o = 0; o < n + lo + hi; o++) {
        int i = o - lo;
        if (mode == LM_PAD_REFLECT) {
            if (i < 0) i = -i;
            if (i >= n) i = 2 * (n - 1) - i;
        } else if (i < 0 || i >= n)
            i = -1;
        tab[o] = i;
    }
}

/* Row and column tables in the ctx arena; NULL on allocation failure. */
static int *pad_tables(lm_ctx *c, const lm_pad_params *p, int H, int W)
{
    const int Ho = H + p->top + p->bottom, Wo = W + p->left + p->right;
    int *tab = lm_ctx_alloc(c, (size_t)(Ho + Wo) * sizeof *tab);
    if (!tab) return NULL;
    pad_table(tab, H, p->top, p->bottom, p->mode);
    pad_table(tab + Ho, W, p->left, p->right, p->mode);
    return tab;
}

/* forward: t[0] = x (B x C x H x W), t[1] = y (B x C x Ho x Wo); y = */
static int pad_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_tensor *x = t[0], *y = t[1];
    const int H = x->shape[2], W = x->shape[3], Ho = y->shape[2], Wo = y->shape[3];
    const int *rt = pad_tables(c, params, H, W);
    if (!rt) return c->status;
    const int *ct = rt + Ho;
    const long rows = (long)y->shape[0] * y->shape[1] * Ho;
    const float *xd = x->data;
    float *yd = y->data;
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c))
    for (long r = 0; r < rows; r++) {
        const int iy = rt[r % Ho];
        float *yr = yd + r * Wo;
        if (iy < 0) {
            for (int X = 0; X < Wo; X++) yr[X] = 0.0f;
            continue;
        }
        const float *xr = xd + ((r / Ho) * H + iy) * (long)W;
        for (int X = 0; X < Wo; X++) yr[X] = ct[X] < 0 ? 0.0f : xr[ct[X]];
    }
    return 0;
}

/* backward: t[0] = gx (B x C x H x W), t[1] = gy (B x C x Ho x Wo); gx += */
static int pad_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_tensor *gx = t[0], *gy = t[1];
    const int H = gx->shape[2], W = gx->shape[3], Ho = gy->shape[2], Wo = gy->shape[3];
    const int *rt = pad_tables(c, params, H, W);
    if (!rt) return c->status;
    const int *ct = rt + Ho;
    const long planes = (long)gx->shape[0] * gx->shape[1];
    float *xd = gx->data;
    const float *yd = gy->data;
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c))
    for (long pl = 0; pl < planes; pl++) {
        for (int Y = 0; Y < Ho; Y++) {
            if (rt[Y] < 0) continue;
            float *xr = xd + (pl * H + rt[Y]) * W;
            const float *yr = yd + (pl * Ho + Y) * Wo;
            for (int X = 0; X < Wo; X++)
                if (ct[X] >= 0) xr[ct[X]] += yr[X];
        }
    }
    return 0;
}
LM_KERNEL(pad2d_fwd, pad_fwd_cpu);
LM_KERNEL(pad2d_bwd, pad_bwd_cpu);

static void pad_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *t[2] = {lm_grad(c, x), n->out->grad};
    if (t[0]) lm_kernel_run(c, &lm_kernel_pad2d_bwd, t, 2, n->params);
}

/* Returns nonzero when the arguments are valid for x. */
static int pad_check(lm_ctx *c, const lm_tensor *x, const lm_pad_params *p)
{
    char sb[64];
    if (x->ndim != 4) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "pad2d: input %s is not B x C x H x W",
                    lm_shape_str(x, sb, sizeof sb));
        return 0;
    }
    if (p->mode != LM_PAD_ZERO && p->mode != LM_PAD_REFLECT) {
        lm_ctx_fail(c, LM_ERR_ARG, "pad2d: unknown mode %d", p->mode);
        return 0;
    }
    if (p->top < 0 || p->bottom < 0 || p->left < 0 || p->right < 0) {
        lm_ctx_fail(c, LM_ERR_ARG, "pad2d: negative pad (%d, %d, %d, %d)", p->top, p->bottom,
                    p->left, p->right);
        return 0;
    }
    const int H = x->shape[2], W = x->shape[3];
    if (p->mode == LM_PAD_REFLECT &&
        (p->top >= H || p->bottom >= H || p->left >= W || p->right >= W)) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "pad2d: reflect pads (top %d, bottom %d, left %d, right %d)"
                    " must be smaller than the input %s", p->top, p->bottom, p->left, p->right,
                    lm_shape_str(x, sb, sizeof sb));
        return 0;
    }
    return 1;
}

lm_tensor *lm_pad2d(lm_ctx *c, lm_tensor *x, int top, int bottom, int left, int right,
                    lm_pad_mode mode)
{
    if (!lm_check_inputs(c, "pad2d", 1, x)) return NULL;
    lm_pad_params p = {top, bottom, left, right, (int)mode};
    if (!pad_check(c, x, &p)) return NULL;
    x = lm_contiguous(c, x);
    if (!x) return NULL;
    int s[4] = {x->shape[0], x->shape[1], x->shape[2] + top + bottom, x->shape[3] + left + right};
    lm_tensor *y = lm_tensor_new(c, 4, s);
    if (!y) return NULL;
    lm_tensor *t[2] = {x, y};
    if (lm_kernel_run(c, &lm_kernel_pad2d_fwd, t, 2, &p)) return NULL;
    lm_record(c, "pad2d", pad_backward, y, &x, 1, &p, sizeof p);
    return y;
}

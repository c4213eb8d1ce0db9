/* shuffle.c — pixel_unshuffle / pixel_shuffle with rectangular factors (fy, fx).
 * What it is: a pure rearrangement between a "big" B x C x H x W tensor and a "small"
 * B x (C fy fx) x H/fy x W/fx tensor; small channel c*fy*fx + i*fx + j, pixel (y, x) holds
 * big[c, fy*y + i, fx*x + j] (PyTorch order). One helper moves values either way with = or +=,
 * so the forward and backward of both ops are the same loop.
 * What it is not: a resampling (values are only moved), nor a view (the output is a copy). */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"

/* big: B x C x H x W, small: B x C*fy*fx x H/fy x W/fx, both contiguous.
 * to_small: small (= or += when add) big; else big (= or +=) small. The map is a bijection,
 * so rows of big are independent jobs (no races, no reductions). */
static void shuffle_move(lm_ctx *c, const lm_tensor *big, const lm_tensor *small, int fy, int fx,
                         int to_small, int add)
{
    const int H = big->shape[2], W = big->shape[3];
    const int hs = H / fy, ws = W / fx;
    const long rows = (long)big->shape[0] * big->shape[1] * H;
    float *bd = big->data, *sd = small->data;
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c))
    for (long r = 0; r < rows; r++) { /* row r = (b*C + ch)*H + y of big */
        const long bc = r / H;
        const int y = (int)(r % H), i = y % fy, ys = y / fy;
        float *brow = bd + r * W;
        for (int j = 0; j < fx; j++) {
            float *srow = sd + ((bc * fy + i) * fx + j) * (long)hs * ws + (long)ys * ws;
            const float *bj = brow + j;
            if (to_small && add)
                for (int u = 0; u < ws; u++) srow[u] += bj[(long)u * fx];
            else if (to_small)
                for (int u = 0; u < ws; u++) srow[u] = bj[(long)u * fx];
            else if (add)
                for (int u = 0; u < ws; u++) brow[j + (long)u * fx] += srow[u];
            else
                for (int u = 0; u < ws; u++) brow[j + (long)u * fx] = srow[u];
        }
    }
}

/* unshuffle forward: t[0] = x (big), t[1] = y (small); y = */
static int unshuffle_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_shuffle_params *p = params;
    shuffle_move(c, t[0], t[1], p->fy, p->fx, 1, 0);
    return 0;
}
/* unshuffle backward: t[0] = gx (big), t[1] = gy (small); gx += */
static int unshuffle_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_shuffle_params *p = params;
    shuffle_move(c, t[0], t[1], p->fy, p->fx, 0, 1);
    return 0;
}
/* shuffle forward: t[0] = x (small), t[1] = y (big); y = */
static int shuffle_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_shuffle_params *p = params;
    shuffle_move(c, t[1], t[0], p->fy, p->fx, 0, 0);
    return 0;
}
/* shuffle backward: t[0] = gx (small), t[1] = gy (big); gx += */
static int shuffle_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_shuffle_params *p = params;
    shuffle_move(c, t[1], t[0], p->fy, p->fx, 1, 1);
    return 0;
}
LM_KERNEL(pixel_unshuffle_fwd, unshuffle_fwd_cpu);
LM_KERNEL(pixel_unshuffle_bwd, unshuffle_bwd_cpu);
LM_KERNEL(pixel_shuffle_fwd, shuffle_fwd_cpu);
LM_KERNEL(pixel_shuffle_bwd, shuffle_bwd_cpu);

static void unshuffle_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *t[2] = {lm_grad(c, x), n->out->grad};
    if (t[0]) lm_kernel_run(c, &lm_kernel_pixel_unshuffle_bwd, t, 2, n->params);
}

static void shuffle_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *t[2] = {lm_grad(c, x), n->out->grad};
    if (t[0]) lm_kernel_run(c, &lm_kernel_pixel_shuffle_bwd, t, 2, n->params);
}

/* Common argument checks; returns 0 after setting the ctx error. */
static int shuffle_args_ok(lm_ctx *c, const char *op, const lm_tensor *x, int fy, int fx)
{
    char sb[64];
    if (fy < 1 || fx < 1) {
        lm_ctx_fail(c, LM_ERR_ARG, "%s: factors %d x %d must be >= 1", op, fy, fx);
        return 0;
    }
    if (x->ndim != 4) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "%s: input %s is not B x C x H x W", op,
                    lm_shape_str(x, sb, sizeof sb));
        return 0;
    }
    return 1;
}

lm_tensor *lm_pixel_unshuffle(lm_ctx *c, lm_tensor *x, int fy, int fx)
{
    if (!lm_check_inputs(c, "pixel_unshuffle", 1, x)) return NULL;
    if (!shuffle_args_ok(c, "pixel_unshuffle", x, fy, fx)) return NULL;
    char sb[64];
    if (x->shape[2] % fy || x->shape[3] % fx) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "pixel_unshuffle: %s: H and W must be multiples of the "
                    "factors %d x %d", lm_shape_str(x, sb, sizeof sb), fy, fx);
        return NULL;
    }
    x = lm_contiguous(c, x);
    if (!x) return NULL;
    int s[4] = {x->shape[0], x->shape[1] * fy * fx, x->shape[2] / fy, x->shape[3] / fx};
    lm_tensor *y = lm_tensor_new(c, 4, s);
    if (!y) return NULL;
    lm_shuffle_params p = {fy, fx};
    lm_tensor *t[2] = {x, y};
    if (lm_kernel_run(c, &lm_kernel_pixel_unshuffle_fwd, t, 2, &p)) return NULL;
    lm_record(c, "pixel_unshuffle", unshuffle_backward, y, &x, 1, &p, sizeof p);
    return y;
}

lm_tensor *lm_pixel_shuffle(lm_ctx *c, lm_tensor *x, int fy, int fx)
{
    if (!lm_check_inputs(c, "pixel_shuffle", 1, x)) return NULL;
    if (!shuffle_args_ok(c, "pixel_shuffle", x, fy, fx)) return NULL;
    char sb[64];
    if (x->shape[1] % (fy * fx)) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "pixel_shuffle: %s: channels must be a multiple of "
                    "%d x %d", lm_shape_str(x, sb, sizeof sb), fy, fx);
        return NULL;
    }
    x = lm_contiguous(c, x);
    if (!x) return NULL;
    int s[4] = {x->shape[0], x->shape[1] / (fy * fx), x->shape[2] * fy, x->shape[3] * fx};
    lm_tensor *y = lm_tensor_new(c, 4, s);
    if (!y) return NULL;
    lm_shuffle_params p = {fy, fx};
    lm_tensor *t[2] = {x, y};
    if (lm_kernel_run(c, &lm_kernel_pixel_shuffle_fwd, t, 2, &p)) return NULL;
    lm_record(c, "pixel_shuffle", shuffle_backward, y, &x, 1, &p, sizeof p);
    return y;
}

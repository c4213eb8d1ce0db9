/* cl_ops_move.c — typed launchers of move.cl for tensor/ops/permute.c ("permute_fwd/bwd"),
 * shuffle.c ("pixel_unshuffle_fwd/bwd", "pixel_shuffle_fwd/bwd"), concat.c ("concat_fwd/bwd",
 * "split_fwd/bwd"), pad.c ("pad2d_fwd/bwd"), resize.c ("resize_bilinear_fwd/bwd") and
 * mosaic_upsample.c ("mosaic_upsample_fwd/bwd"). Permute, shuffle, concat and split are all
 * one kernel (view_copy) over views built here: same shape, source and destination strides. */
#include "kernels-opencl/cl_impl.h"
#include "tensor/op_params.h"

int lm_cl_view_copy(lm_cl *b, lm_ctx *c, const lm_tensor *src, const lm_tensor *dst, int add)
{
    cl_int8 shp, sst, dshp, dst8;
    lm_cl_shape8(src, &shp, &sst);
    lm_cl_shape8(dst, &dshp, &dst8);
    int n = (int)lm_tensor_numel(src);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "view_copy")) return c->status;
    lm_cl_arg_tensor(&a, src);
    lm_cl_arg_raw(&a, sizeof sst, &sst);
    lm_cl_arg_tensor(&a, dst);
    lm_cl_arg_raw(&a, sizeof dst8, &dst8);
    lm_cl_arg_raw(&a, sizeof shp, &shp);
    lm_cl_arg_int(&a, n);
    lm_cl_arg_int(&a, add);
    return lm_cl_run_chunks(&a, (size_t)n);
}

/* t with a new 5-d shape and strides (a view of the same buffer). */
static lm_tensor view5(const lm_tensor *t, const int *shape, const ptrdiff_t *stride)
{
    lm_tensor v = *t;
    v.ndim = 5;
    for (int i = 0; i < 5; i++) {
        v.shape[i] = shape[i];
        v.stride[i] = stride[i];
    }
    return v;
}

/* ---- permute ------------------------------------------------------------------------------ */
/* x viewed in y's order: shape of y, strides x.stride[perm[d]]. */
static lm_tensor permuted(const lm_tensor *x, const lm_tensor *y, const lm_permute_params *p)
{
    lm_tensor v = *x;
    for (int d = 0; d < y->ndim; d++) {
        v.shape[d] = y->shape[d];
        v.stride[d] = x->stride[p->perm[d]];
    }
    return v;
}

/* t = {x, y}: y = x permuted. */
int lm_cl_launch_permute_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    lm_tensor v = permuted(t[0], t[1], pp);
    return lm_cl_view_copy(b, c, &v, t[1], 0);
}

/* t = {gx, gy}: gx += gy moved back. */
int lm_cl_launch_permute_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    lm_tensor v = permuted(t[0], t[1], pp);
    return lm_cl_view_copy(b, c, t[1], &v, 1);
}

/* ---- pixel (un)shuffle -------------------------------------------------------------------- */
/* big B x C x H x W and small B x C fy fx x H/fy x W/fx as two views of one 5-d index space.
 * order 0 (small's order): (bc, i, j, ys, u); order 1 (big's order): (bc, ys, i, u, j). */
static void shuffle_views(const lm_tensor *big, const lm_tensor *small, int fy, int fx,
                          int order, lm_tensor *vb, lm_tensor *vs)
{
    const int H = big->shape[2], W = big->shape[3], hs = H / fy, ws = W / fx;
    const int bc = big->shape[0] * big->shape[1];
    const ptrdiff_t HW = (ptrdiff_t)H * W, sc = (ptrdiff_t)fy * fx * hs * ws;
    if (order == 0) {
        int sh[5] = {bc, fy, fx, hs, ws};
        ptrdiff_t bs[5] = {HW, W, 1, (ptrdiff_t)fy * W, fx}, ss[5] = {sc, fx * hs * ws, hs * ws,
                                                                        ws, 1};
        *vb = view5(big, sh, bs);
        *vs = view5(small, sh, ss);
    } else {
        int sh[5] = {bc, hs, fy, ws, fx};
        ptrdiff_t bs[5] = {HW, (ptrdiff_t)fy * W, W, fx, 1}, ss[5] = {sc, ws, fx * hs * ws, 1,
                                                                        hs * ws};
        *vb = view5(big, sh, bs);
        *vs = view5(small, sh, ss);
    }
}

/* t = {x big, y small}: y = unshuffle(x) */
int lm_cl_launch_pixel_unshuffle_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt,
                                     const void *pp)
{
    (void)nt;
    const lm_shuffle_params *p = pp;
    lm_tensor vb, vs;
    shuffle_views(t[0], t[1], p->fy, p->fx, 0, &vb, &vs);
    return lm_cl_view_copy(b, c, &vb, &vs, 0);
}

/* t = {gx big, gy small}: gx += */
int lm_cl_launch_pixel_unshuffle_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt,
                                     const void *pp)
{
    (void)nt;
    const lm_shuffle_params *p = pp;
    lm_tensor vb, vs;
    shuffle_views(t[0], t[1], p->fy, p->fx, 0, &vb, &vs);
    return lm_cl_view_copy(b, c, &vs, &vb, 1);
}

/* t = {x small, y big}: y = shuffle(x) */
int lm_cl_launch_pixel_shuffle_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_shuffle_params *p = pp;
    lm_tensor vb, vs;
    shuffle_views(t[1], t[0], p->fy, p->fx, 1, &vb, &vs);
    return lm_cl_view_copy(b, c, &vs, &vb, 0);
}

/* t = {gx small, gy big}: gx += */
int lm_cl_launch_pixel_shuffle_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_shuffle_params *p = pp;
    lm_tensor vb, vs;
    shuffle_views(t[1], t[0], p->fy, p->fx, 1, &vb, &vs);
    return lm_cl_view_copy(b, c, &vb, &vs, 1);
}

/* ---- concat / split ----------------------------------------------------------------------- */
/* The band of `whole` that `part` occupies from `start` along dim. */
static lm_tensor band_of(const lm_tensor *whole, const lm_tensor *part, int dim, int start)
{
    lm_tensor v = *whole;
    for (int d = 0; d < whole->ndim; d++) v.shape[d] = part->shape[d];
    v.dev_off += (size_t)start * (size_t)whole->stride[dim];
    return v;
}

/* t = {x_0 .. x_{nt-2}, y}: y = concat along dim. */
int lm_cl_launch_concat_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    const lm_band_params *p = pp;
    int start = p->start;
    for (int i = 0; i < nt - 1; i++) {
        lm_tensor v = band_of(t[nt - 1], t[i], p->dim, start);
        if (lm_cl_view_copy(b, c, t[i], &v, 0)) return c->status;
        start += t[i]->shape[p->dim];
    }
    return 0;
}

/* t = {gx_i, gy}: gx_i += its band of gy */
int lm_cl_launch_concat_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_band_params *p = pp;
    lm_tensor v = band_of(t[1], t[0], p->dim, p->start);
    return lm_cl_view_copy(b, c, &v, t[0], 1);
}

/* t = {x, part}: part = band */
int lm_cl_launch_split_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_band_params *p = pp;
    lm_tensor v = band_of(t[0], t[1], p->dim, p->start);
    return lm_cl_view_copy(b, c, &v, t[1], 0);
}

/* t = {gx, gpart}: band of gx += gpart */
int lm_cl_launch_split_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_band_params *p = pp;
    lm_tensor v = band_of(t[0], t[1], p->dim, p->start);
    return lm_cl_view_copy(b, c, t[1], &v, 1);
}

/* ---- pad ---------------------------------------------------------------------------------- */
/* fwd t = {x, y}; bwd t = {gx, gy}: (small, big) either way. */
static int run_pad(lm_cl *b, lm_ctx *c, lm_tensor *const *t, const lm_pad_params *p, int bwd)
{
    const lm_tensor *x = t[0], *y = t[1];
    int n = (int)lm_tensor_numel(bwd ? x : y);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, bwd ? "pad_bwd" : "pad_fwd")) return c->status;
    lm_cl_arg_tensor(&a, x);
    lm_cl_arg_tensor(&a, y);
    lm_cl_arg_int(&a, x->shape[2]);
    lm_cl_arg_int(&a, x->shape[3]);
    lm_cl_arg_int(&a, y->shape[2]);
    lm_cl_arg_int(&a, y->shape[3]);
    lm_cl_arg_int(&a, p->top);
    if (bwd) lm_cl_arg_int(&a, p->bottom);
    lm_cl_arg_int(&a, p->left);
    if (bwd) lm_cl_arg_int(&a, p->right);
    lm_cl_arg_int(&a, p->mode);
    lm_cl_arg_int(&a, n);
    return lm_cl_run_1d(&a, (size_t)n);
}

int lm_cl_launch_pad2d_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    return run_pad(b, c, t, pp, 0);
}

int lm_cl_launch_pad2d_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    return run_pad(b, c, t, pp, 1);
}

/* ---- resize ------------------------------------------------------------------------------- */
/* t = {x, y} */
int lm_cl_launch_resize_bilinear_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt,
                                     const void *pp)
{
    (void)nt;
    int ac = ((const lm_resize_params *)pp)->align_corners;
    const lm_tensor *x = t[0], *y = t[1];
    int H = x->shape[2], W = x->shape[3], oh = y->shape[2], ow = y->shape[3];
    int n = (int)lm_tensor_numel(y);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "resize_fwd")) return c->status;
    lm_cl_arg_tensor(&a, x);
    lm_cl_arg_tensor(&a, y);
    lm_cl_arg_int(&a, H);
    lm_cl_arg_int(&a, W);
    lm_cl_arg_int(&a, oh);
    lm_cl_arg_int(&a, ow);
    lm_cl_arg_float(&a, lm_resize_scale(H, oh, ac));
    lm_cl_arg_float(&a, lm_resize_scale(W, ow, ac));
    lm_cl_arg_int(&a, ac);
    lm_cl_arg_int(&a, n);
    return lm_cl_run_1d(&a, (size_t)n);
}

/* t = {gx, gy}: rows gathered along x into a device scratch, then along y into gx. */
int lm_cl_launch_resize_bilinear_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt,
                                     const void *pp)
{
    (void)nt;
    int ac = ((const lm_resize_params *)pp)->align_corners;
    const lm_tensor *gx = t[0], *gy = t[1];
    int H = gx->shape[2], W = gx->shape[3], oh = gy->shape[2], ow = gy->shape[3];
    int rows = gx->shape[0] * gx->shape[1] * oh;
    lm_tensor *tmp = lm_tensor_new_on(c, LM_DEVICE_OPENCL, 2, (int[]){rows, W});
    if (!tmp) return c->status;
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "resize_bwd_rows")) return c->status;
    lm_cl_arg_tensor(&a, gy);
    lm_cl_arg_tensor(&a, tmp);
    lm_cl_arg_int(&a, W);
    lm_cl_arg_int(&a, ow);
    lm_cl_arg_float(&a, lm_resize_scale(W, ow, ac));
    lm_cl_arg_int(&a, ac);
    lm_cl_arg_int(&a, rows * W);
    if (lm_cl_run_1d(&a, (size_t)rows * W)) return c->status;
    int n = (int)lm_tensor_numel(gx);
    if (lm_cl_begin(&a, b, c, "resize_bwd_cols")) return c->status;
    lm_cl_arg_tensor(&a, gx);
    lm_cl_arg_tensor(&a, tmp);
    lm_cl_arg_int(&a, H);
    lm_cl_arg_int(&a, W);
    lm_cl_arg_int(&a, oh);
    lm_cl_arg_float(&a, lm_resize_scale(H, oh, ac));
    lm_cl_arg_int(&a, ac);
    lm_cl_arg_int(&a, n);
    return lm_cl_run_1d(&a, (size_t)n);
}

/* ---- mosaic upsampling -------------------------------------------------------------------- */
/* fwd t = {raw, y}; bwd t = {graw, gy}. The per-channel phases (up to 2 x 64 ints, too many
 * for kernel arguments) go to the device in one small blocking write per launch. */
static int run_mosaic(lm_cl *b, lm_ctx *c, lm_tensor *const *t, const lm_mosaic_params *p,
                      int bwd)
{
    int nch = p->nch, H = t[0]->shape[2], W = t[0]->shape[3];
    int ph[2 * LM_MOSAIC_UPSAMPLE_MAX_CH];
    for (int k = 0; k < nch; k++) {
        ph[k] = p->py[k];
        ph[nch + k] = p->px[k];
    }
    lm_tensor *dph = lm_tensor_new_on(c, LM_DEVICE_OPENCL, 1, (int[]){2 * nch});
    if (!dph || lm_tensor_write(c, dph, (const float *)(const void *)ph)) return c->status;
    int n = (int)lm_tensor_numel(bwd ? t[0] : t[1]);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, bwd ? "mosaic_bwd" : "mosaic_fwd")) return c->status;
    lm_cl_arg_tensor(&a, t[0]);
    lm_cl_arg_tensor(&a, t[1]);
    lm_cl_arg_tensor(&a, dph);
    lm_cl_arg_int(&a, nch);
    lm_cl_arg_int(&a, H);
    lm_cl_arg_int(&a, W);
    lm_cl_arg_int(&a, p->ty);
    lm_cl_arg_int(&a, p->tx);
    lm_cl_arg_int(&a, n);
    return lm_cl_run_1d(&a, (size_t)n);
}

int lm_cl_launch_mosaic_upsample_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt,
                                     const void *pp)
{
    (void)nt;
    return run_mosaic(b, c, t, pp, 0);
}

int lm_cl_launch_mosaic_upsample_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt,
                                     const void *pp)
{
    (void)nt;
    return run_mosaic(b, c, t, pp, 1);
}

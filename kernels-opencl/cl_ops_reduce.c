/* cl_ops_reduce.c — typed launchers of reduce.cl for tensor/ops/reduce.c ("reduce_sum_fwd",
 * "reduce_sum_bwd", "global_avg_pool_fwd", "global_avg_pool_bwd") and loss.c
 * ("l1_mse_loss_fwd", "l1_mse_loss_bwd"). Backward broadcasts use eltwise.cl's bcast_add. */
#include "kernels-opencl/cl_impl.h"
#include "tensor/op_params.h"

#define LONG_SUM 65536  /* a single long sum is split into chunks first */
#define CHUNK_MIN 4096
#define MAX_CHUNKS 256

typedef lm_cl_reduction red_space;

static void space_init(red_space *s)
{
    for (int i = 0; i < 8; i++) {
        s->kshp.s[i] = s->rshp.s[i] = 1;
        s->kst.s[i] = s->rst.s[i] = 0;
    }
    s->ny = s->nr = 1;
}

void lm_cl_reduction_init(lm_cl_reduction *r) { space_init(r); }

int lm_cl_reduce(lm_cl *b, lm_ctx *c, const lm_tensor *x, const lm_cl_reduction *s,
                 lm_tensor *y, float k, int acc)
{
    int serial = s->nr <= 256 || s->ny >= 2048;
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, serial ? "reduce_rows_serial" : "reduce_rows_wg")) return c->status;
    lm_cl_arg_tensor(&a, x);
    lm_cl_arg_raw(&a, sizeof s->kshp, &s->kshp);
    lm_cl_arg_raw(&a, sizeof s->kst, &s->kst);
    lm_cl_arg_raw(&a, sizeof s->rshp, &s->rshp);
    lm_cl_arg_raw(&a, sizeof s->rst, &s->rst);
    lm_cl_arg_int(&a, (int)s->nr);
    lm_cl_arg_tensor(&a, y);
    if (serial) lm_cl_arg_int(&a, (int)s->ny);
    lm_cl_arg_float(&a, k);
    lm_cl_arg_int(&a, acc);
    return serial ? lm_cl_run_1d(&a, (size_t)s->ny) : lm_cl_run_groups(&a, (size_t)s->ny);
}

static int run_rows(lm_cl *b, lm_ctx *c, const lm_tensor *x, const red_space *s, lm_tensor *y,
                    float k)
{
    return lm_cl_reduce(b, c, x, s, y, k, 0);
}

/* y[0] = k * sum of f(p, q) over n contiguous elements (kind LM_CL_SUM_PLAIN: p, LM_LOSS_L1:
 * |p-q|, LM_LOSS_MSE: (p-q)^2):
 * chunk sums in a device scratch, then one work-group adds them. */
static int run_long_sum(lm_cl *b, lm_ctx *c, const lm_tensor *p, const lm_tensor *q, long n,
                        int kind, lm_tensor *y, float k)
{
    long nch = (n + CHUNK_MIN - 1) / CHUNK_MIN;
    if (nch > MAX_CHUNKS) nch = MAX_CHUNKS;
    long chunk = (n + nch - 1) / nch;
    lm_tensor *part = lm_tensor_new_on(c, LM_DEVICE_OPENCL, 1, (int[]){(int)nch});
    if (!part) return c->status;
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "chunk_sums")) return c->status;
    lm_cl_arg_tensor(&a, p);
    lm_cl_arg_tensor(&a, q);
    lm_cl_arg_int(&a, (int)n);
    lm_cl_arg_int(&a, (int)chunk);
    lm_cl_arg_int(&a, kind);
    lm_cl_arg_tensor(&a, part);
    if (lm_cl_run_groups(&a, (size_t)nch)) return c->status;
    red_space s;
    space_init(&s);
    s.rshp.s[4] = (cl_int)nch;
    s.rst.s[4] = 1;
    s.nr = nch;
    return run_rows(b, c, part, &s, y, k);
}

/* d += k * s broadcast over d's shape (s strides st in d's 5-d index space). */
static int run_bcast_add(lm_cl *b, lm_ctx *c, lm_tensor *d, const lm_tensor *s, cl_int8 shp,
                         cl_int8 st, float k)
{
    int n = (int)lm_tensor_numel(d);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "bcast_add")) return c->status;
    lm_cl_arg_tensor(&a, d);
    lm_cl_arg_tensor(&a, s);
    lm_cl_arg_raw(&a, sizeof shp, &shp);
    lm_cl_arg_raw(&a, sizeof st, &st);
    lm_cl_arg_int(&a, n);
    lm_cl_arg_float(&a, k);
    return lm_cl_run_chunks(&a, (size_t)n);
}

/* ---- sum / mean --------------------------------------------------------------------------- */
static void sum_space(const lm_tensor *x, unsigned mask, red_space *s)
{
    space_init(s);
    cl_int st = 1;
    for (int i = x->ndim - 1; i >= 0; i--) {
        int pos = LM_MAX_DIMS - x->ndim + i;
        if ((mask >> i) & 1u) {
            s->rshp.s[pos] = x->shape[i];
            s->rst.s[pos] = st;
            s->nr *= x->shape[i];
        } else {
            s->kshp.s[pos] = x->shape[i];
            s->kst.s[pos] = st;
            s->ny *= x->shape[i];
        }
        st *= x->shape[i];
    }
}

/* t = {x, y}: y = scale * sum over the masked dims. */
int lm_cl_launch_reduce_sum_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_reduce_params *p = pp;
    red_space s;
    sum_space(t[0], p->mask, &s);
    if (s.ny == 1 && s.nr >= LONG_SUM)
        return run_long_sum(b, c, t[0], t[0], s.nr, LM_CL_SUM_PLAIN, t[1], p->scale);
    return run_rows(b, c, t[0], &s, t[1], p->scale);
}

/* t = {gy, gx}: gx += scale * gy broadcast over the reduced dims. */
int lm_cl_launch_reduce_sum_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_reduce_params *p = pp;
    const lm_tensor *gx = t[1];
    cl_int8 shp, st, unused;
    lm_cl_shape8(gx, &shp, &unused);
    for (int i = 0; i < 8; i++) st.s[i] = 0;
    cl_int sy = 1;
    for (int i = gx->ndim - 1; i >= 0; i--) {
        if ((p->mask >> i) & 1u) continue;
        st.s[LM_MAX_DIMS - gx->ndim + i] = sy;
        sy *= gx->shape[i];
    }
    return run_bcast_add(b, c, t[1], t[0], shp, st, p->scale);
}

/* ---- global average pooling --------------------------------------------------------------- */
/* t = {x (B x C x H x W), y (B x C x 1 x 1)}: y = mean over H W. */
int lm_cl_launch_global_avg_pool_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt,
                                     const void *pp)
{
    (void)nt, (void)pp;
    const lm_tensor *x = t[0];
    int bc = x->shape[0] * x->shape[1], hw = x->shape[2] * x->shape[3];
    red_space s;
    space_init(&s);
    s.kshp.s[3] = bc;
    s.kst.s[3] = hw;
    s.rshp.s[4] = hw;
    s.rst.s[4] = 1;
    s.ny = bc;
    s.nr = hw;
    return run_rows(b, c, x, &s, t[1], (float)(1.0 / (double)hw));
}

/* t = {gy, gx}: gx += gy / (H W). */
int lm_cl_launch_global_avg_pool_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt,
                                     const void *pp)
{
    (void)nt, (void)pp;
    const lm_tensor *gx = t[1];
    int bc = gx->shape[0] * gx->shape[1], hw = gx->shape[2] * gx->shape[3];
    cl_int8 shp = {{1, 1, 1, bc, hw, 1, 1, 1}}, st = {{0, 0, 0, 1, 0, 0, 0, 0}};
    return run_bcast_add(b, c, t[1], t[0], shp, st, (float)(1.0 / (double)hw));
}

/* ---- losses ------------------------------------------------------------------------------- */
/* t = {pred, target, y {1}}: y = mean |p - t| (L1) or (p - t)^2 (MSE). */
int lm_cl_launch_l1_mse_loss_fwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_loss_params *p = pp;
    long n = lm_tensor_numel(t[0]);
    return run_long_sum(b, c, t[0], t[1], n, p->kind, t[2], (float)(1.0 / (double)n));
}

/* t = {pred, target, gy {1}, gd}: gd += sign dloss/dpred. */
int lm_cl_launch_l1_mse_loss_bwd(lm_cl *b, lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_loss_bwd_params *p = pp;
    int n = (int)lm_tensor_numel(t[0]);
    lm_cl_args a;
    if (lm_cl_begin(&a, b, c, "loss_bwd")) return c->status;
    for (int i = 0; i < 4; i++) lm_cl_arg_tensor(&a, t[i]);
    lm_cl_arg_int(&a, n);
    lm_cl_arg_int(&a, p->kind);
    lm_cl_arg_float(&a, p->sign);
    return lm_cl_run_1d(&a, (size_t)n);
}

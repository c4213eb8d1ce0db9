/* mosaic_upsample.c — phase-aware demosaic upsampling (system.md section 6).
 * What it is: raw B x 1 x H x W with a ty x tx tile -> B x nch x H x W. Channel k takes the
 * samples of tile phase (py, px) = (phase_y[k], phase_x[k]): s[v][u] = raw[ty v + py][tx u + px],
 * v < H/ty, u < W/tx, and interpolates them bilinearly at their true positions: for output row
 * Y, sy = clamp((Y - py) / ty, 0, H/ty - 1), v0 = floor(sy), v1 = min(v0 + 1, H/ty - 1),
 * ly = sy - v0 (same for columns). A pixel holding a sample of the phase reproduces it exactly;
 * beyond the first/last sample row or column the nearest sample is used; nothing outside the
 * frame is read. Per-channel row/column tables live in the ctx arena.
 * Backward, as two gathers (deterministic for any thread count, no atomics): the positions
 * that read sample v as their first (second) neighbour form one range, since the tables are
 * monotone; (1) per output row, each sub-image column u sums the gradient over its two column
 * ranges; (2) per raw row R, for each channel whose phase owns R (in channel order), each
 * sample sums step (1)'s rows over its two row ranges and adds into raw column tx u + px.
 * At most 64 channels: the phases travel in the kernel's plain params struct.
 * What it is not: the pixel-unshuffle (see shuffle.c), nor any learned demosaic. */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"

/* Per position: sample index pair and weight of the second sample. Per sample v: the position
 * ranges [lo0, hi0) reading v as first and [lo1, hi1) as second sample (empty: lo = n, hi = 0). */
typedef struct mosaic_tab { int *i0, *i1; float *l; int *lo0, *hi0, *lo1, *hi1; } mosaic_tab;

/* Integer arithmetic (exact for any frame size): d = clamp(Y - phase, 0, t (ns - 1)),
 * v0 = d / t, ly = (d mod t) / t. */
static void axis_fill(int n, int t, int phase, int *i0, int *i1, float *l)
{
    const int ns = n / t, last = t * (ns - 1);
    for (int Y = 0; Y < n; Y++) {
        int d = Y - phase;
        d = d < 0 ? 0 : (d > last ? last : d);
        const int v = d / t;
        i0[Y] = v;
        i1[Y] = v + 1 < ns ? v + 1 : ns - 1;
        l[Y] = (float)(d - v * t) / (float)t;
    }
}

/* Ranges of the monotone tables i0, i1 (n positions, ns samples). */
static void axis_ranges(const int *i0, const int *i1, int n, int ns, int *lo0, int *hi0, int *lo1,
                        int *hi1)
{
    for (int v = 0; v < ns; v++) {
        lo0[v] = lo1[v] = n;
        hi0[v] = hi1[v] = 0;
    }
    for (int Y = 0; Y < n; Y++) {
        if (Y < lo0[i0[Y]]) lo0[i0[Y]] = Y;
        if (Y < lo1[i1[Y]]) lo1[i1[Y]] = Y;
        hi0[i0[Y]] = Y + 1;
        hi1[i1[Y]] = Y + 1;
    }
}

/* One table per channel over n positions with period t (arena); phase[k] per channel. */
static int mosaic_table(lm_ctx *c, int nch, int n, int t, const int *phase, mosaic_tab *m)
{
    const size_t np = (size_t)nch * n, ns = (size_t)nch * (n / t);
    int *ip = lm_ctx_alloc(c, (2 * np + 4 * ns) * sizeof(int));
    float *fp = ip ? lm_ctx_alloc(c, np * sizeof(float)) : NULL;
    if (!fp) return -1;
    *m = (mosaic_tab){ip, ip + np, fp, ip + 2 * np, ip + 2 * np + ns, ip + 2 * np + 2 * ns,
                      ip + 2 * np + 3 * ns};
    for (int k = 0; k < nch; k++) {
        const long o = (long)k * n, q = (long)k * (n / t);
        axis_fill(n, t, phase[k], m->i0 + o, m->i1 + o, m->l + o);
        axis_ranges(m->i0 + o, m->i1 + o, n, n / t, m->lo0 + q, m->hi0 + q, m->lo1 + q,
                    m->hi1 + q);
    }
    return 0;
}

/* Row tables (nch x H) and column tables (nch x W) of every channel. */
static int mosaic_tables(lm_ctx *c, const lm_mosaic_params *p, int H, int W, mosaic_tab *rt,
                         mosaic_tab *ct)
{
    if (mosaic_table(c, p->nch, H, p->ty, p->py, rt)) return -1;
    return mosaic_table(c, p->nch, W, p->tx, p->px, ct);
}

/* forward: t[0] = raw (B x 1 x H x W), t[1] = y (B x nch x H x W); y = */
static int mosaic_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_mosaic_params *p = params;
    const int H = t[0]->shape[2], W = t[0]->shape[3], nch = p->nch, tx = p->tx;
    mosaic_tab rt, ct;
    if (mosaic_tables(c, p, H, W, &rt, &ct)) return c->status;
    const long rows = (long)t[0]->shape[0] * nch * H;
    const float *rd = t[0]->data;
    float *yd = t[1]->data;
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c))
    for (long r = 0; r < rows; r++) { /* r = (b * nch + k) * H + Y */
        const int Y = (int)(r % H), k = (int)((r / H) % nch);
        const long b = r / ((long)H * nch);
        const int kY = k * H + Y;
        const float *raw = rd + b * H * (long)W + p->px[k];
        const float *s0 = raw + (long)(p->ty * rt.i0[kY] + p->py[k]) * W;
        const float *s1 = raw + (long)(p->ty * rt.i1[kY] + p->py[k]) * W;
        const float ly = rt.l[kY], hy = 1.0f - ly;
        const int *u0 = ct.i0 + k * W, *u1 = ct.i1 + k * W;
        const float *lx = ct.l + k * W;
        float *yr = yd + r * W;
        for (int X = 0; X < W; X++) {
            const long a = (long)tx * u0[X], e = (long)tx * u1[X];
            const float hx = 1.0f - lx[X];
            yr[X] = hy * (hx * s0[a] + lx[X] * s0[e]) + ly * (hx * s1[a] + lx[X] * s1[e]);
        }
    }
    return 0;
}

/* Backward step 1, one output-gradient row g (W) of channel k: tr[u] (W/tx) =
 * sum over u's column ranges of the column weight times g. */
static void mosaic_bwd_row(const mosaic_tab *ct, int k, int W, int ws, const float *g, float *tr)
{
    const float *lx = ct->l + (long)k * W;
    const long q = (long)k * ws;
    for (int u = 0; u < ws; u++) {
        float s = 0.0f;
        for (int X = ct->lo0[q + u]; X < ct->hi0[q + u]; X++) s += (1.0f - lx[X]) * g[X];
        for (int X = ct->lo1[q + u]; X < ct->hi1[q + u]; X++) s += lx[X] * g[X];
        tr[u] = s;
    }
}

/* Backward step 2, raw-gradient row R of one batch item (+=): every channel whose row phase
 * owns R adds its sample row v = (R - py) / ty, gathered from tmp (H x W/tx per channel). */
static void mosaic_bwd_raw_row(const lm_mosaic_params *p, const mosaic_tab *rt, const float *tmp,
                               float *grow, int H, int W, int R)
{
    const int ws = W / p->tx, hs = H / p->ty;
    for (int k = 0; k < p->nch; k++) {
        if (R % p->ty != p->py[k]) continue;
        const long q = (long)k * hs + (R - p->py[k]) / p->ty;
        const float *tk = tmp + (long)k * H * ws, *ly = rt->l + (long)k * H;
        float *g = grow + p->px[k];
        for (int Y = rt->lo0[q]; Y < rt->hi0[q]; Y++) {
            const float w = 1.0f - ly[Y], *tr = tk + (long)Y * ws;
            for (int u = 0; u < ws; u++) g[(long)p->tx * u] += w * tr[u];
        }
        for (int Y = rt->lo1[q]; Y < rt->hi1[q]; Y++) {
            const float w = ly[Y], *tr = tk + (long)Y * ws;
            for (int u = 0; u < ws; u++) g[(long)p->tx * u] += w * tr[u];
        }
    }
}

/* backward: t[0] = graw (B x 1 x H x W), t[1] = gy (B x nch x H x W); graw += */
static int mosaic_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    const lm_mosaic_params *p = params;
    const int B = t[0]->shape[0], H = t[0]->shape[2], W = t[0]->shape[3], ws = W / p->tx;
    mosaic_tab rt, ct;
    if (mosaic_tables(c, p, H, W, &rt, &ct)) return c->status;
    const long rows = (long)B * p->nch * H;
    float *tmp = lm_ctx_alloc(c, (size_t)rows * ws * sizeof(float)); /* rows x W/tx */
    if (!tmp) return c->status;
    const float *gyd = t[1]->data;
    float *gr = t[0]->data;
    const int nth = lm_nthreads(c);
#pragma omp parallel for schedule(static) num_threads(nth)
    for (long r = 0; r < rows; r++)
        mosaic_bwd_row(&ct, (int)((r / H) % p->nch), W, ws, gyd + r * W, tmp + r * ws);
#pragma omp parallel for schedule(static) num_threads(nth)
    for (long j = 0; j < (long)B * H; j++) {
        const long b = j / H;
        mosaic_bwd_raw_row(p, &rt, tmp + b * p->nch * H * (long)ws, gr + j * W, H, W,
                           (int)(j % H));
    }
    return 0;
}
LM_KERNEL(mosaic_upsample_fwd, mosaic_fwd_cpu);
LM_KERNEL(mosaic_upsample_bwd, mosaic_bwd_cpu);

static void mosaic_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *t[2] = {lm_grad(c, x), n->out->grad};
    if (t[0]) lm_kernel_run(c, &lm_kernel_mosaic_upsample_bwd, t, 2, n->params);
}

/* Validates the arguments and fills p; returns nonzero when valid. */
static int mosaic_check(lm_ctx *c, const lm_tensor *raw, int ty, int tx, int nch,
                        const int *phase_y, const int *phase_x, lm_mosaic_params *p)
{
    char sb[64];
    if (raw->ndim != 4 || raw->shape[1] != 1) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "mosaic_upsample: raw %s is not B x 1 x H x W",
                    lm_shape_str(raw, sb, sizeof sb));
        return 0;
    }
    if (ty < 1 || tx < 1 || raw->shape[2] % ty || raw->shape[3] % tx) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "mosaic_upsample: raw %s is not a whole number of %d x %d "
                    "tiles", lm_shape_str(raw, sb, sizeof sb), ty, tx);
        return 0;
    }
    if (nch < 1 || nch > LM_MOSAIC_UPSAMPLE_MAX_CH || !phase_y || !phase_x) {
        lm_ctx_fail(c, LM_ERR_ARG, "mosaic_upsample: %d channels (need 1..%d and both phase "
                    "arrays)", nch, LM_MOSAIC_UPSAMPLE_MAX_CH);
        return 0;
    }
    *p = (lm_mosaic_params){.ty = ty, .tx = tx, .nch = nch};
    for (int k = 0; k < nch; k++) {
        if (phase_y[k] < 0 || phase_y[k] >= ty || phase_x[k] < 0 || phase_x[k] >= tx) {
            lm_ctx_fail(c, LM_ERR_ARG, "mosaic_upsample: channel %d phase (%d, %d) is outside "
                        "the %d x %d tile", k, phase_y[k], phase_x[k], ty, tx);
            return 0;
        }
        p->py[k] = phase_y[k];
        p->px[k] = phase_x[k];
    }
    return 1;
}

lm_tensor *lm_mosaic_upsample(lm_ctx *c, lm_tensor *raw, int ty, int tx, int nch,
                              const int *phase_y, const int *phase_x)
{
    if (!lm_check_inputs(c, "mosaic_upsample", 1, raw)) return NULL;
    lm_mosaic_params p;
    if (!mosaic_check(c, raw, ty, tx, nch, phase_y, phase_x, &p)) return NULL;
    raw = lm_contiguous(c, raw);
    if (!raw) return NULL;
    int s[4] = {raw->shape[0], nch, raw->shape[2], raw->shape[3]};
    lm_tensor *y = lm_tensor_new(c, 4, s);
    if (!y) return NULL;
    lm_tensor *t[2] = {raw, y};
    if (lm_kernel_run(c, &lm_kernel_mosaic_upsample_fwd, t, 2, &p)) return NULL;
    lm_record(c, "mosaic_upsample", mosaic_backward, y, &raw, 1, &p, sizeof p);
    return y;
}

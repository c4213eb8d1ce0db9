/* conv3d.c — 3-D convolution with stride 1 and zero padding, forward and backward for the
 * input, the weight and the bias.
 *
 * What it is: PyTorch Conv3d cross-correlation, x: B x Cin x D x H x W, w: Cout x Cin x kd x
 * kh x kw, any kernel size and padding. The hot case is CSAM (1 -> 1 channel, 3x3x3, pad 1 on
 * a B x 1 x C x H x W volume), so the CPU kernels are direct loops over output rows whose
 * inner loop is a contiguous, vectorised sweep along W over a zero-padded copy of the input
 * rows (so no bounds checks along W); the taps of one output row are summed in one pass:
 *   forward   each output plane (b, co, z) is computed by one thread;
 *   d/dx      the same loops on dy with the kernel flipped, Cin/Cout swapped and padding
 *             k - 1 - p (each dx plane by one thread);
 *   d/dw      per-thread partial sums over a fixed static split of the (b, z) planes,
 *             combined in thread order (float sums per block of columns, then double);
 *   d/dbias   the same split for the sum of dy.
 * Deterministic for a given thread count (forward and d/dx for any thread count).
 * What it is not: a strided or dilated 3-D conv, nor an im2col/GEMM conv (the channel counts
 * this project uses are tiny; a many-channel 3-D conv would want GEMM). */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"
#include <omp.h>
#include <string.h>

/* Work (multiply-adds) below which a kernel runs on one thread: a parallel region costs more. */
#define CONV3D_PAR_MIN 65536L

/* Multiply-adds of one pass (forward, d/dx or d/dw). */
static long conv3d_macs(const lm_conv3d_params *p)
{
    return (long)p->B * p->Cout * p->Do * p->Ho * p->Wo * p->Cin * p->kd * p->kh * p->kw;
}

/* Width of a W-padded input row: output column ox, tap kx reads padded column ox + kx. */
static int padded_width(const lm_conv3d_params *p) { return p->Wo + p->kw - 1; }

/* dst (nrows x Wp) = rows of src (nrows x W) shifted right by pw (negative: cropped), zeros
 * elsewhere. Returns the arena buffer or NULL (ctx error set). */
static float *pad_rows(lm_ctx *c, const float *src, long nrows, int W, int pw, int Wp)
{
    float *dst = lm_ctx_alloc(c, (size_t)nrows * (size_t)Wp * sizeof(float));
    if (!dst) return NULL;
    int lo = pw > 0 ? pw : 0, hi = W + pw < Wp ? W + pw : Wp; /* [lo, hi) comes from src */
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c)) \
    if (nrows * Wp >= CONV3D_PAR_MIN)
    for (long r = 0; r < nrows; r++) {
        float *d = dst + r * Wp;
        const float *sr = src + r * W - pw;
        for (int j = 0; j < lo && j < Wp; j++) d[j] = 0.0f;
        for (int j = lo; j < hi; j++) d[j] = sr[j];
        for (int j = hi > lo ? hi : lo; j < Wp; j++) d[j] = 0.0f;
    }
    return dst;
}

/* Taps gathered for one output row and summed in one pass, so the output row is read and
 * written once per batch instead of once per tap: tap t adds k[t] * x[t][ox] to column ox. */
#define CONV3D_TAPS 64
typedef struct tap_batch {
    const float *x[CONV3D_TAPS];
    float k[CONV3D_TAPS];
    int n;
} tap_batch;

/* yr[ox0 .. ox0 + BW) += sum_t k[t] x[t][ox]. Called with constant widths so the block stays
 * in vector registers (several independent FMA chains). */
static inline __attribute__((always_inline)) void tap_block(const tap_batch *tb,
                                                            float *restrict yr, int ox0,
                                                            const int BW)
{
    float acc[64];
    for (int i = 0; i < BW; i++) acc[i] = yr[ox0 + i];
    for (int t = 0; t < tb->n; t++) {
        const float kv = tb->k[t], *xs = tb->x[t] + ox0;
#pragma GCC unroll 64
        for (int i = 0; i < BW; i++) acc[i] += kv * xs[i];
    }
    for (int i = 0; i < BW; i++) yr[ox0 + i] = acc[i];
}

/* yr[0 .. Wo) += sum_t k[t] x[t][ox]; every element sums its terms in tap order. */
static void tap_batch_flush(tap_batch *tb, float *restrict yr, int Wo)
{
    int ox = 0;
    for (; ox + 64 <= Wo; ox += 64) tap_block(tb, yr, ox, 64);
    for (; ox + 16 <= Wo; ox += 16) tap_block(tb, yr, ox, 16);
    for (; ox < Wo; ox++) {
        float s = yr[ox];
        for (int t = 0; t < tb->n; t++) s += tb->k[t] * tb->x[t][ox];
        yr[ox] = s;
    }
    tb->n = 0;
}

/* One output plane y[b, co, oz] (Ho x Wo) = bias (or += when accumulate) + taps over xb, the
 * W-padded input of batch item b (Cin x D x H rows of padded_width). */
static void conv3d_plane(const lm_conv3d_params *p, const float *xb, const float *w, float bias,
                         int accumulate, int co, int oz, float *yp)
{
    int Wp = padded_width(p);
    long kvol = (long)p->kd * p->kh * p->kw;
    tap_batch tb;
    tb.n = 0;
    for (int oy = 0; oy < p->Ho; oy++) {
        float *yr = yp + (long)oy * p->Wo;
        if (!accumulate)
            for (int i = 0; i < p->Wo; i++) yr[i] = bias;
        for (int ci = 0; ci < p->Cin; ci++)
            for (int kz = 0; kz < p->kd; kz++) {
                int iz = oz + kz - p->pd;
                if (iz < 0 || iz >= p->D) continue;
                const float *xp = xb + ((long)ci * p->D + iz) * p->H * Wp;
                const float *kp = w + ((long)co * p->Cin + ci) * kvol + (long)kz * p->kh * p->kw;
                for (int ky = 0; ky < p->kh; ky++) {
                    int iy = oy + ky - p->ph;
                    if (iy < 0 || iy >= p->H) continue;
                    if (tb.n + p->kw > CONV3D_TAPS) tap_batch_flush(&tb, yr, p->Wo);
                    for (int kx = 0; kx < p->kw; kx++) {
                        tb.x[tb.n] = xp + (long)iy * Wp + kx;
                        tb.k[tb.n++] = kp[ky * p->kw + kx];
                    }
                }
            }
        if (tb.n) tap_batch_flush(&tb, yr, p->Wo);
    }
}

/* y = (bias) + conv, or y += conv when accumulate; x unpadded. Each plane by one thread. */
static int conv3d_direct(lm_ctx *c, const lm_conv3d_params *p, const float *x, const float *w,
                         const float *bias, int accumulate, float *y)
{
    int Wp = padded_width(p);
    long in_b = (long)p->Cin * p->D * p->H * Wp, plane = (long)p->Ho * p->Wo;
    long nplanes = (long)p->B * p->Cout * p->Do;
    lm_arena_mark mark = lm_arena_get_mark(&c->arena);
    float *xp = pad_rows(c, x, (long)p->B * p->Cin * p->D * p->H, p->W, p->pw, Wp);
    if (!xp) return c->status;
#pragma omp parallel for schedule(static) num_threads(lm_nthreads(c)) \
    if (conv3d_macs(p) >= CONV3D_PAR_MIN)
    for (long i = 0; i < nplanes; i++) {
        int oz = (int)(i % p->Do), co = (int)(i / p->Do % p->Cout), b = (int)(i / p->Do / p->Cout);
        conv3d_plane(p, xp + b * in_b, w, bias ? bias[co] : 0.0f, accumulate, co, oz,
                     y + i * plane);
    }
    lm_arena_rewind(&c->arena, mark);
    return 0;
}

/* t = {x, w, y [, bias]}. Writes y = (bias) + conv3d(x, w). */
static int conv3d_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    return conv3d_direct(c, pp, t[0]->data, t[1]->data, nt > 3 ? t[3]->data : NULL, 0,
                         t[2]->data);
}

/* t = {dy, w, dx}. dx += conv3d(dy, flip(w)^T) with padding k - 1 - p. */
static int conv3d_bwd_x_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_conv3d_params *p = pp;
    lm_conv3d_params q = *p; /* dy -> dx geometry */
    q.Cin = p->Cout, q.D = p->Do, q.H = p->Ho, q.W = p->Wo;
    q.Cout = p->Cin, q.Do = p->D, q.Ho = p->H, q.Wo = p->W;
    q.pd = p->kd - 1 - p->pd, q.ph = p->kh - 1 - p->ph, q.pw = p->kw - 1 - p->pw;
    q.has_bias = 0;
    long kvol = (long)p->kd * p->kh * p->kw, nw = (long)p->Cout * p->Cin * kvol;
    lm_arena_mark mark = lm_arena_get_mark(&c->arena);
    float *wf = lm_ctx_alloc(c, (size_t)nw * sizeof(float));
    if (!wf) return c->status;
    const float *w = t[1]->data;
    for (long i = 0; i < nw; i++) { /* wf[ci][co][r] = w[co][ci][kvol - 1 - r] */
        long r = i % kvol, co = i / kvol % p->Cout, ci = i / kvol / p->Cout;
        wf[i] = w[(co * p->Cin + ci) * kvol + kvol - 1 - r];
    }
    int rc = conv3d_direct(c, &q, t[0]->data, wf, NULL, 1, t[2]->data);
    lm_arena_rewind(&c->arena, mark);
    return rc;
}

/* sum over n rows r and columns [0, W) of a[r * sa + i] * b[r * sb + i], blocked so that the
 * column sums stay in vector registers; each block's float sums are added in double. */
static inline __attribute__((always_inline)) double dot_block(const float *a, long sa,
                                                              const float *b, long sb, int n,
                                                              const int BW)
{
    float acc[64];
    for (int i = 0; i < BW; i++) acc[i] = 0.0f;
    for (int r = 0; r < n; r++) {
        const float *ar = a + r * sa, *br = b + r * sb;
#pragma GCC unroll 64
        for (int i = 0; i < BW; i++) acc[i] += ar[i] * br[i];
    }
    double s = 0.0;
    for (int i = 0; i < BW; i++) s += acc[i];
    return s;
}

static double dot_rows(const float *a, long sa, const float *b, long sb, int n, int W)
{
    double s = 0.0;
    int i = 0;
    for (; i + 64 <= W; i += 64) s += dot_block(a + i, sa, b + i, sb, n, 64);
    for (; i + 16 <= W; i += 16) s += dot_block(a + i, sa, b + i, sb, n, 16);
    for (; i < W; i++)
        for (int r = 0; r < n; r++) s += (double)a[r * sa + i] * b[r * sb + i];
    return s;
}

/* part[co][ci][kz][ky][kx] += sum over the output planes q in [q0, q1) (q = b Do + oz) of
 * dy * shifted x; xp is the W-padded input. */
static void wgrad_planes(const lm_conv3d_params *p, const float *xp, const float *dy, long q0,
                         long q1, double *part)
{
    int Wp = padded_width(p);
    long plane = (long)p->Ho * p->Wo, k2 = (long)p->kh * p->kw;
    for (long q = q0; q < q1; q++) {
        int b = (int)(q / p->Do), oz = (int)(q % p->Do);
        for (int co = 0; co < p->Cout; co++) {
            const float *dyp = dy + (((long)b * p->Cout + co) * p->Do + oz) * plane;
            for (int ci = 0; ci < p->Cin; ci++)
                for (int kz = 0; kz < p->kd; kz++) {
                    int iz = oz + kz - p->pd;
                    if (iz < 0 || iz >= p->D) continue;
                    const float *xpl = xp + (((long)b * p->Cin + ci) * p->D + iz) * p->H * Wp;
                    double *pk = part + (((long)co * p->Cin + ci) * p->kd + kz) * k2;
                    for (int ky = 0; ky < p->kh; ky++) {
                        int oy0 = p->ph - ky > 0 ? p->ph - ky : 0; /* 0 <= oy + ky - ph < H */
                        int oy1 = p->H + p->ph - ky < p->Ho ? p->H + p->ph - ky : p->Ho;
                        if (oy1 <= oy0) continue;
                        const float *xr = xpl + (long)(oy0 + ky - p->ph) * Wp;
                        for (int kx = 0; kx < p->kw; kx++)
                            pk[ky * p->kw + kx] += dot_rows(dyp + (long)oy0 * p->Wo, p->Wo,
                                                            xr + kx, Wp, oy1 - oy0, p->Wo);
                    }
                }
        }
    }
}

/* t = {x, dy, dw}. dw += sum over batch and planes; per-thread partials in fixed order. */
static int conv3d_bwd_w_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_conv3d_params *p = pp;
    int T = lm_nthreads(c);
    long nw = (long)p->Cout * p->Cin * p->kd * p->kh * p->kw, nq = (long)p->B * p->Do;
    lm_arena_mark mark = lm_arena_get_mark(&c->arena);
    double *part = lm_ctx_alloc(c, (size_t)(T * nw) * sizeof(double));
    float *xp = part ? pad_rows(c, t[0]->data, (long)p->B * p->Cin * p->D * p->H, p->W, p->pw,
                                padded_width(p))
                     : NULL;
    if (!xp) return c->status;
    memset(part, 0, (size_t)(T * nw) * sizeof(double));
#pragma omp parallel num_threads(T) if (conv3d_macs(p) >= CONV3D_PAR_MIN)
    {
        int id = omp_get_thread_num(), n = omp_get_num_threads();
        wgrad_planes(p, xp, t[1]->data, nq * id / n, nq * (id + 1) / n, part + id * nw);
    }
    float *dw = t[2]->data;
    for (long i = 0; i < nw; i++) {
        double s = 0.0;
        for (int id = 0; id < T; id++) s += part[id * nw + i];
        dw[i] += (float)s;
    }
    lm_arena_rewind(&c->arena, mark);
    return 0;
}

/* Sum of n floats: float partial sums in 16 lanes over blocks of 1024, added in double. */
static double sum_floats(const float *r, long n)
{
    double s = 0.0;
    for (long i0 = 0; i0 < n; i0 += 1024) {
        long m = n - i0 < 1024 ? n - i0 : 1024, i = 0;
        float acc[16] = {0};
        for (; i + 16 <= m; i += 16)
            for (int l = 0; l < 16; l++) acc[l] += r[i0 + i + l];
        for (; i < m; i++) acc[0] += r[i0 + i];
        for (int l = 0; l < 16; l++) s += acc[l];
    }
    return s;
}

/* t = {dy, db}. db += sum of dy over batch and voxels; per-thread partials in fixed order. */
static int conv3d_bwd_b_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *pp)
{
    (void)nt;
    const lm_conv3d_params *p = pp;
    int T = lm_nthreads(c);
    long plane = (long)p->Ho * p->Wo, nq = (long)p->B * p->Cout * p->Do;
    lm_arena_mark mark = lm_arena_get_mark(&c->arena);
    double *part = lm_ctx_alloc(c, (size_t)(T * p->Cout) * sizeof(double));
    if (!part) return c->status;
    memset(part, 0, (size_t)(T * p->Cout) * sizeof(double));
    const float *dy = t[0]->data;
#pragma omp parallel num_threads(T) if (nq * plane >= CONV3D_PAR_MIN)
    {
        int id = omp_get_thread_num(), n = omp_get_num_threads();
        for (long q = nq * id / n; q < nq * (id + 1) / n; q++) {
            part[(long)id * p->Cout + q / p->Do % p->Cout] +=
                sum_floats(dy + q * plane, plane);
        }
    }
    float *db = t[1]->data;
    for (int co = 0; co < p->Cout; co++) {
        double s = 0.0;
        for (int id = 0; id < T; id++) s += part[(long)id * p->Cout + co];
        db[co] += (float)s;
    }
    lm_arena_rewind(&c->arena, mark);
    return 0;
}

LM_KERNEL(conv3d_fwd, conv3d_fwd_cpu);
LM_KERNEL(conv3d_bwd_x, conv3d_bwd_x_cpu);
LM_KERNEL(conv3d_bwd_w, conv3d_bwd_w_cpu);
LM_KERNEL(conv3d_bwd_b, conv3d_bwd_b_cpu);

/* in = {x, w [, bias]} */
static void conv3d_backward(lm_ctx *c, lm_node *n)
{
    const lm_conv3d_params *p = n->params;
    lm_tensor *x = n->in[0], *w = n->in[1], *bias = n->nin > 2 ? n->in[2] : NULL;
    lm_tensor *dy = n->out->grad;
    if (lm_requires_grad(x)) {
        lm_tensor *t[3] = {dy, w, lm_grad(c, x)};
        if (t[2]) lm_kernel_run(c, &lm_kernel_conv3d_bwd_x, t, 3, p);
    }
    if (lm_requires_grad(w)) {
        lm_tensor *t[3] = {x, dy, lm_grad(c, w)};
        if (t[2]) lm_kernel_run(c, &lm_kernel_conv3d_bwd_w, t, 3, p);
    }
    if (lm_requires_grad(bias)) {
        lm_tensor *t[2] = {dy, lm_grad(c, bias)};
        if (t[1]) lm_kernel_run(c, &lm_kernel_conv3d_bwd_b, t, 2, p);
    }
}

/* Shape checks and output size. Returns 0 on success (params filled), else sets the error. */
static int conv3d_shapes(lm_ctx *c, const lm_tensor *x, const lm_tensor *w, const lm_tensor *bias,
                         int pd, int ph, int pw, lm_conv3d_params *p)
{
    char sx[64], sw[64], sb[64];
    lm_shape_str(x, sx, sizeof sx);
    lm_shape_str(w, sw, sizeof sw);
    if (pd < 0 || ph < 0 || pw < 0) {
        lm_ctx_fail(c, LM_ERR_ARG, "conv3d: negative padding %dx%dx%d", pd, ph, pw);
        return -1;
    }
    if (x->ndim != 5 || w->ndim != 5 || w->shape[1] != x->shape[1]) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "conv3d: x %s and weight %s do not match (need x B x Cin "
                    "x D x H x W, weight Cout x Cin x kd x kh x kw)", sx, sw);
        return -1;
    }
    *p = (lm_conv3d_params){x->shape[0], x->shape[1], x->shape[2], x->shape[3], x->shape[4],
                         w->shape[0], 0, 0, 0, w->shape[2], w->shape[3], w->shape[4],
                         pd, ph, pw, bias != NULL};
    if (bias && (bias->ndim != 1 || bias->shape[0] != p->Cout)) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "conv3d: bias %s, expected %d (Cout) for weight %s",
                    lm_shape_str(bias, sb, sizeof sb), p->Cout, sw);
        return -1;
    }
    p->Do = p->D + 2 * pd - p->kd + 1;
    p->Ho = p->H + 2 * ph - p->kh + 1;
    p->Wo = p->W + 2 * pw - p->kw + 1;
    if (p->Do < 1 || p->Ho < 1 || p->Wo < 1) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "conv3d: kernel of weight %s is larger than x %s padded "
                    "by %dx%dx%d", sw, sx, pd, ph, pw);
        return -1;
    }
    return 0;
}

lm_tensor *lm_conv3d(lm_ctx *c, lm_tensor *x, lm_tensor *w, lm_tensor *bias, int pad_d,
                     int pad_h, int pad_w)
{
    if (!lm_check_inputs(c, "conv3d", 2, x, w)) return NULL;
    lm_conv3d_params p;
    if (conv3d_shapes(c, x, w, bias, pad_d, pad_h, pad_w, &p)) return NULL;
    x = lm_contiguous(c, x);
    w = lm_contiguous(c, w);
    if (bias) bias = lm_contiguous(c, bias);
    int s[5] = {p.B, p.Cout, p.Do, p.Ho, p.Wo};
    lm_tensor *y = lm_tensor_new(c, 5, s);
    if (!y) return NULL;
    lm_tensor *t[4] = {x, w, y, bias};
    if (lm_kernel_run(c, &lm_kernel_conv3d_fwd, t, bias ? 4 : 3, &p)) return NULL;
    lm_tensor *in[3] = {x, w, bias};
    lm_record(c, "conv3d", conv3d_backward, y, in, bias ? 3 : 2, &p, sizeof p);
    return y;
}

/* phase.c — pooling and scaling per mosaic phase, in place of the image: MCAN's mosaic attention
 * without moving the image to channels and back.
 *   lm_phase_mean(x, fy, fx)     y[b, c P + i fx + j] = mean of x[b, c, i::fy, j::fx]
 *                                (= global_avg_pool(pixel_unshuffle(x, fy, fx)))
 *   lm_phase_scale(x, s, fy, fx) y[b, c, y, x] = x[b, c, y, x] s[b, c P + (y % fy) fx + x % fx]
 *                                (= pixel_shuffle(pixel_unshuffle(x) * s))
 * with P = fy fx, x B x C x H x W (H, W multiples of fy, fx) and s B x C P (x 1 x 1).
 * What it is: two loops, a per-phase sum (of x, or of gy x) and a per-phase broadcast (of a
 * scale, times x or gy), over the B C planes of the image, one plane per thread at a time (static
 * schedule), so every output element is computed by one thread in a fixed order whatever the
 * thread count. A plane's rows are added into W-wide float column sums per row phase
 * (vectorised), and those folded into the P phase sums in double. The scale is applied through a
 * row pattern (the phase scales of row phase i repeated along W), so the inner loops are plain
 * multiplies of contiguous rows.
 * What it is not: a general broadcast (binary.c), or a shuffle (shuffle.c). */
#include "tensor/ops.h"
#include "tensor/op_list.h"
#include "tensor/op_params.h"
#include <omp.h>
#include <stdlib.h>

#define PAR_MIN 32768L /* below this many elements, one thread */

/* A kernel's view of the image: P phases, planes of H x W, threads, and per-thread scratch of
 * fy W floats (freed by the kernel). */
typedef struct pgeom {
    int fy, fx, P, H, W, nth;
    long planes, hw;
    float *buf;
} pgeom;

static int pgeom_init(lm_ctx *c, const lm_tensor *img, const void *params, const char *op,
                      pgeom *g)
{
    const lm_shuffle_params *p = params;
    g->fy = p->fy, g->fx = p->fx, g->P = p->fy * p->fx;
    g->H = img->shape[2], g->W = img->shape[3];
    g->planes = (long)img->shape[0] * img->shape[1], g->hw = (long)g->H * g->W;
    g->nth = g->planes * g->hw >= PAR_MIN ? lm_nthreads(c) : 1;
    g->buf = malloc(sizeof(float) * (size_t)g->fy * g->W * g->nth);
    return g->buf ? 0 : lm_ctx_fail(c, LM_ERR_NOMEM, "%s: out of memory", op);
}

/* y[k P + q] (= or +=, add) k_ * sum over phase q of plane k of a, or of a b when b != NULL.
 * A plane's rows are added into W-wide column sums per row phase, folded in double. */
static int phase_sums(lm_ctx *c, const lm_tensor *a, const lm_tensor *b, float *y, double k_,
                      int add, const void *params, const char *op)
{
    pgeom g;
    if (pgeom_init(c, a, params, op, &g)) return c->status;
    const int fy = g.fy, fx = g.fx, W = g.W, H = g.H;
#pragma omp parallel for num_threads(g.nth) schedule(static)
    for (long k = 0; k < g.planes; k++) {
        float *cs = g.buf + (size_t)omp_get_thread_num() * fy * W;
        const float *ap = a->data + k * g.hw, *bp = b ? b->data + k * g.hw : NULL;
        for (int i = 0; i < fy; i++) {
            float *d = cs + i * W;
            for (int u = 0; u < W; u++) d[u] = 0.0f;
            for (int yy = i; yy < H; yy += fy) {
                const float *r = ap + (long)yy * W;
                if (bp)
                    for (int u = 0; u < W; u++) d[u] += r[u] * bp[(long)yy * W + u];
                else
                    for (int u = 0; u < W; u++) d[u] += r[u];
            }
        }
        for (int i = 0; i < fy; i++)
            for (int j = 0; j < fx; j++) {
                double s = 0.0;
                for (int u = j; u < W; u += fx) s += cs[i * W + u];
                float v = (float)(s * k_), *o = y + k * g.P + i * fx + j;
                *o = add ? *o + v : v;
            }
    }
    free(g.buf);
    return 0;
}

/* d (= or +=, add) k_ s[plane P + phase] times a (or 1 when a == NULL), through row patterns
 * (the phase scales of row phase i repeated along W). */
static int phase_apply(lm_ctx *c, const lm_tensor *a, const float *s, lm_tensor *d, float k_,
                       int add, const void *params, const char *op)
{
    pgeom g;
    if (pgeom_init(c, d, params, op, &g)) return c->status;
    const int fy = g.fy, fx = g.fx, W = g.W, H = g.H;
#pragma omp parallel for num_threads(g.nth) schedule(static)
    for (long k = 0; k < g.planes; k++) {
        float *pat = g.buf + (size_t)omp_get_thread_num() * fy * W;
        for (int i = 0; i < fy; i++)
            for (int u = 0; u < W; u++) pat[i * W + u] = k_ * s[k * g.P + i * fx + u % fx];
        float *dp = d->data + k * g.hw;
        const float *ap = a ? a->data + k * g.hw : NULL;
        for (int yy = 0; yy < H; yy++) {
            const float *q = pat + (yy % fy) * W;
            float *r = dp + (long)yy * W;
            if (ap && add)
                for (int u = 0; u < W; u++) r[u] += ap[(long)yy * W + u] * q[u];
            else if (ap)
                for (int u = 0; u < W; u++) r[u] = ap[(long)yy * W + u] * q[u];
            else
                for (int u = 0; u < W; u++) r[u] += q[u];
        }
    }
    free(g.buf);
    return 0;
}

static double per_pixel(const lm_tensor *img, const lm_shuffle_params *p)
{
    return (double)(p->fy * p->fx) / ((double)img->shape[2] * img->shape[3]);
}

/* t = {x, y (B x C P)}: y = per-phase means. */
static int phase_mean_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    return phase_sums(c, t[0], NULL, t[1]->data, per_pixel(t[0], params), 0, params,
                      "phase_mean");
}

/* t = {gy (B x C P), gx}: gx += gy / (H W / P) at each phase's pixels. */
static int phase_mean_bwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    return phase_apply(c, NULL, t[0]->data, t[1], (float)per_pixel(t[1], params), 1, params,
                       "phase_mean");
}

/* t = {x, s, y}: y = x s. */
static int phase_scale_fwd_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    return phase_apply(c, t[0], t[1]->data, t[2], 1.0f, 0, params, "phase_scale");
}

/* t = {gy, s, gx}: gx += gy s. */
static int phase_scale_bwd_x_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    return phase_apply(c, t[0], t[1]->data, t[2], 1.0f, 1, params, "phase_scale");
}

/* t = {gy, x, gs}: gs[b, c P + q] += sum over phase q's pixels of gy x. */
static int phase_scale_bwd_s_cpu(lm_ctx *c, lm_tensor *const *t, int nt, const void *params)
{
    (void)nt;
    return phase_sums(c, t[0], t[1], t[2]->data, 1.0, 1, params, "phase_scale");
}

LM_KERNEL(phase_mean_fwd, phase_mean_fwd_cpu);
LM_KERNEL(phase_mean_bwd, phase_mean_bwd_cpu);
LM_KERNEL(phase_scale_fwd, phase_scale_fwd_cpu);
LM_KERNEL(phase_scale_bwd_x, phase_scale_bwd_x_cpu);
LM_KERNEL(phase_scale_bwd_s, phase_scale_bwd_s_cpu);

static void phase_mean_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *t[2] = {n->out->grad, lm_grad(c, x)};
    if (t[1]) lm_kernel_run(c, &lm_kernel_phase_mean_bwd, t, 2, n->params);
}

static void phase_scale_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0], *s = n->in[1], *gy = n->out->grad;
    if (lm_requires_grad(x)) {
        lm_tensor *t[3] = {gy, s, lm_grad(c, x)};
        if (t[2]) lm_kernel_run(c, &lm_kernel_phase_scale_bwd_x, t, 3, n->params);
    }
    if (lm_requires_grad(s)) {
        lm_tensor *t[3] = {gy, x, lm_grad(c, s)};
        if (t[2]) lm_kernel_run(c, &lm_kernel_phase_scale_bwd_s, t, 3, n->params);
    }
}

/* x must be B x C x H x W with H, W multiples of fy, fx >= 1. */
static int phase_args_ok(lm_ctx *c, const char *op, const lm_tensor *x, int fy, int fx)
{
    char sb[64];
    if (fy < 1 || fx < 1 || fy > 64 || fx > 64) {
        lm_ctx_fail(c, LM_ERR_ARG, "%s: factors %d x %d must be in 1..64", op, fy, fx);
        return 0;
    }
    if (x->ndim != 4 || x->shape[2] % fy || x->shape[3] % fx) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "%s: input %s must be B x C x H x W with H, W multiples of "
                    "%d x %d", op, lm_shape_str(x, sb, sizeof sb), fy, fx);
        return 0;
    }
    return 1;
}

lm_tensor *lm_phase_mean(lm_ctx *c, lm_tensor *x, int fy, int fx)
{
    if (!lm_check_inputs(c, "phase_mean", 1, x)) return NULL;
    if (!phase_args_ok(c, "phase_mean", x, fy, fx)) return NULL;
    x = lm_contiguous(c, x);
    lm_tensor *y = x ? lm_tensor_new4(c, x->shape[0], x->shape[1] * fy * fx, 1, 1) : NULL;
    if (!y) return NULL;
    lm_shuffle_params p = {fy, fx};
    lm_tensor *t[2] = {x, y};
    if (lm_kernel_run(c, &lm_kernel_phase_mean_fwd, t, 2, &p)) return NULL;
    lm_record(c, "phase_mean", phase_mean_backward, y, &x, 1, &p, sizeof p);
    return y;
}

lm_tensor *lm_phase_scale(lm_ctx *c, lm_tensor *x, lm_tensor *s, int fy, int fx)
{
    if (!lm_check_inputs(c, "phase_scale", 2, x, s)) return NULL;
    if (!phase_args_ok(c, "phase_scale", x, fy, fx)) return NULL;
    long want = (long)x->shape[0] * x->shape[1] * fy * fx;
    if (lm_tensor_numel(s) != want || s->shape[0] != x->shape[0]) {
        char sx[64], ss[64];
        lm_ctx_fail(c, LM_ERR_SHAPE, "phase_scale: scales %s do not match %s: want %d x %ld",
                    lm_shape_str(s, ss, sizeof ss), lm_shape_str(x, sx, sizeof sx),
                    x->shape[0], want / x->shape[0]);
        return NULL;
    }
    x = lm_contiguous(c, x);
    s = x ? lm_contiguous(c, s) : NULL;
    lm_tensor *y = s ? lm_tensor_new(c, 4, x->shape) : NULL;
    if (!y) return NULL;
    lm_shuffle_params p = {fy, fx};
    lm_tensor *t[3] = {x, s, y};
    if (lm_kernel_run(c, &lm_kernel_phase_scale_fwd, t, 3, &p)) return NULL;
    lm_tensor *in[2] = {x, s};
    lm_record(c, "phase_scale", phase_scale_backward, y, in, 2, &p, sizeof p);
    return y;
}

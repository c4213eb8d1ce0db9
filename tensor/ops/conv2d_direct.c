/* conv2d_direct.c — direct forward CPU path of conv2d for few output channels (stride 1,
 * dilation 1, one group, Cout <= LM_CONV_DIRECT_MAX_COUT), the shapes of the real-time models
 * (3x3 at 8-32 channels, 1x1 12 -> 33) where im2col + GEMM spends its time copying columns.
 * What it is: per output row, the kh input rows of every input channel are copied into a
 * zero-padded per-thread buffer (padding and frame edges handled there, once); then for each
 * block of LM_VLN output pixels and each block of up to 16 output channels, the accumulators
 * (one vector per output channel) stay in registers while the loop runs over input channels
 * and taps: one vector load of input, one broadcast multiply-add per output channel.
 * Weights are first reordered to [ci][i][j][co]. Writes y = conv(x, w) + bias. Parallel over
 * output rows (fixed static partition); every output element is summed by one thread in the
 * fixed order (bias, then ci, i, j), so the result does not depend on the thread count.
 * What it is not: a backward (the tiled path does it) or strided / dilated / grouped conv. */
#include "tensor/ops/gemm_internal.h"
#include "tensor/ops/simd.h"
#include <omp.h>
#include <string.h>

/* Built with -DLM_CONV_DIRECT_OFF, never (to benchmark the tiled path against this one). */
int lm_conv2d_direct_applies(const lm_conv_geom *g)
{
#ifdef LM_CONV_DIRECT_OFF
    (void)g;
    return 0;
#endif
    return g->sh == 1 && g->sw == 1 && g->dh == 1 && g->dw == 1 && g->groups == 1 &&
           g->Cout <= LM_CONV_DIRECT_MAX_COUT && g->Cin * g->kh * g->kw <= 1024 &&
           g->Wo >= LM_VLN / 2;
}

typedef struct direct_row {
    const float *buf;   /* (Cin * kh) rows of Wp floats: input row oy - ph + i, col x - pw */
    const float *wt;    /* [Cin * kh][kw][Cout] */
    const float *bias;  /* Cout or NULL */
    float *y;           /* output row oy of channel 0; channel stride ys */
    long ys;
    int rows, kw, Wp, Wo, Cout;
} direct_row;

/* One output row, channels [co0, co0 + CB): the accumulators live in registers. */
#define DIRECT_ROW(CB)                                                                        \
    static void direct_row_##CB(const direct_row *r, int co0)                                 \
    {                                                                                         \
        const float *buf = r->buf, *wt = r->wt + co0;                                         \
        const int rows = r->rows, kw = r->kw, Wp = r->Wp, Wo = r->Wo, Cout = r->Cout;         \
        float b[CB];                                                                          \
        for (int q = 0; q < CB; q++) b[q] = r->bias ? r->bias[co0 + q] : 0.0f;                \
        for (int x0 = 0; x0 < Wo; x0 += LM_VLN) {                                                 \
            lm_vfn acc[CB];                                                                       \
            _Pragma("GCC unroll 16") for (int q = 0; q < CB; q++) acc[q] = (lm_vfn){0} + b[q];    \
            for (int k = 0; k < rows; k++)                                                    \
                for (int j = 0; j < kw; j++) {                                                \
                    const lm_vfn xv = lm_loadn(buf + (long)k * Wp + x0 + j);                         \
                    const float *wp = wt + ((long)k * kw + j) * Cout;                         \
                    _Pragma("GCC unroll 16") for (int q = 0; q < CB; q++)                     \
                        acc[q] += wp[q] * xv;                                                 \
                }                                                                             \
            const int n = Wo - x0 < LM_VLN ? Wo - x0 : LM_VLN;                                        \
            _Pragma("GCC unroll 16") for (int q = 0; q < CB; q++)                             \
                lm_storen(r->y + (co0 + q) * r->ys + x0, acc[q], n);                             \
        }                                                                                     \
    }
DIRECT_ROW(16)
DIRECT_ROW(8)
DIRECT_ROW(4)
DIRECT_ROW(2)
DIRECT_ROW(1)

static void direct_row_all(const direct_row *r)
{
    int co = 0;
    for (; co + 16 <= r->Cout; co += 16) direct_row_16(r, co);
    if (r->Cout - co >= 8) direct_row_8(r, co), co += 8;
    if (r->Cout - co >= 4) direct_row_4(r, co), co += 4;
    if (r->Cout - co >= 2) direct_row_2(r, co), co += 2;
    if (r->Cout - co >= 1) direct_row_1(r, co);
}

/* buf (Cin * kh rows of Wp) = input rows oy - ph + i of image xb, shifted by pw, zero outside
 * the image and in the slack columns. */
static void fill_rows(const lm_conv_geom *g, const float *xb, int oy, int Wp, float *buf)
{
    for (int ci = 0; ci < g->Cin; ci++)
        for (int i = 0; i < g->kh; i++) {
            float *d = buf + ((long)ci * g->kh + i) * Wp;
            int iy = oy - g->ph + i;
            memset(d, 0, sizeof(float) * (size_t)Wp);
            if (iy >= 0 && iy < g->H)
                memcpy(d + g->pw, xb + ((long)ci * g->H + iy) * g->W, sizeof(float) * (size_t)g->W);
        }
}

int lm_conv2d_direct_fwd(lm_ctx *c, const lm_conv_geom *g, const float *x, const float *w,
                         const float *bias, float *y)
{
    const int rows = g->Cin * g->kh, taps = g->kh * g->kw, nt = lm_nthreads(c);
    /* the padded row must hold the input (W + 2 pw) and every vector load of the last block */
    int Wp = (g->Wo + LM_VLN - 1) / LM_VLN * LM_VLN + g->kw - 1;
    if (Wp < g->W + 2 * g->pw) Wp = g->W + 2 * g->pw;
    lm_arena_mark m = lm_arena_get_mark(&c->arena);
    float *wt = lm_ctx_alloc(c, sizeof(float) * (size_t)g->Cout * rows * g->kw);
    float *bufs = wt ? lm_ctx_alloc(c, sizeof(float) * (size_t)nt * rows * Wp) : NULL;
    if (!bufs) return c->status;
    for (int co = 0; co < g->Cout; co++)
        for (int ci = 0; ci < g->Cin; ci++)
            for (int t = 0; t < taps; t++)
                wt[((long)ci * taps + t) * g->Cout + co] = w[((long)co * g->Cin + ci) * taps + t];
    const long nrows = (long)g->B * g->Ho, plane = (long)g->Ho * g->Wo;
#pragma omp parallel num_threads(nt)
    {
        float *buf = bufs + (long)omp_get_thread_num() * rows * Wp;
#pragma omp for schedule(static)
        for (long r = 0; r < nrows; r++) {
            const int b = (int)(r / g->Ho), oy = (int)(r % g->Ho);
            fill_rows(g, x + (long)b * g->Cin * g->H * g->W, oy, Wp, buf);
            direct_row dr = {buf, wt, bias, y + (long)b * g->Cout * plane + (long)oy * g->Wo,
                             plane, rows, g->kw, Wp, g->Wo, g->Cout};
            direct_row_all(&dr);
        }
    }
    lm_arena_rewind(&c->arena, m);
    return 0;
}

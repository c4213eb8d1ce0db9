/* lmmse_direct.c — the inner loops of the closed-form floor's direct path (models/lmmse.c):
 * every output pixel of a frame = bias + the K x K window of each input plane times its
 * phase's filters, over up to 40 output channels held in 8-lane vector registers.
 * Compiled once per instruction set (cmake/isa.cmake) and called through
 * lm_lmmse_direct_rows (lmmse.c picks the variant of the active level).
 * What it is not: the packing of the filters or the padding of the frame (lmmse.c). */
#include "models/lmmse_direct.h"
#include <string.h>

typedef float v8 __attribute__((vector_size(32)));
#define NP32 3 /* pixels per step: up to 32 channels */
#define NP40 2 /* up to 40 */

static inline v8 v8_load(const float *p) { v8 v; memcpy(&v, p, sizeof v); return v; }

/* Row y, phase column j: pixels x = j, j + tx, ... of the phase, NP at a time (the last step
 * repeats its last pixel to fill the registers, stored once), NV 8-lane vectors of channels
 * (NV x 8 = the packing's lanes). NV and NP are constants at each call (always inlined), so
 * the accumulators stay in registers. C padded planes of PH rows lie one below the other in
 * pad; the taps run over their windows in turn (plane q's row u is tap row q K + u). */
static inline __attribute__((always_inline)) void
row_phase(const float *T, const float *pad, int PW, int PH, int C, int K, int y, int j, int W,
          int tx, float *out, size_t plane, int nch, const int NV, const int NP)
{
    const int L = NV * 8;
    const float *B = T + (size_t)C * K * K * L;
    for (int x = j; x < W; x += NP * tx) {
        int np = (W - x + tx - 1) / tx;
        np = np < NP ? np : NP;
        int off[8];
#pragma GCC unroll 8
        for (int q = 0; q < NP; q++) off[q] = (q < np ? q : np - 1) * tx;
        v8 a[8][5];
#pragma GCC unroll 8
        for (int q = 0; q < NP; q++)
#pragma GCC unroll 5
            for (int g = 0; g < NV; g++) a[q][g] = v8_load(B + 8 * g);
        for (int qu = 0; qu < C * K; qu++) {
            const float *row = pad + ((size_t)(qu / K) * PH + y + qu % K) * PW + x;
            const float *Tu = T + (size_t)qu * K * L;
            for (int v = 0; v < K; v++, Tu += L) {
                v8 t[5];
#pragma GCC unroll 5
                for (int g = 0; g < NV; g++) t[g] = v8_load(Tu + 8 * g);
#pragma GCC unroll 8
                for (int q = 0; q < NP; q++) {
                    const float sv = row[v + off[q]];
#pragma GCC unroll 5
                    for (int g = 0; g < NV; g++) a[q][g] += sv * t[g];
                }
            }
        }
        for (int q = 0; q < np; q++) {
            float o[40];
            for (int g = 0; g < NV; g++) memcpy(o + 8 * g, &a[q][g], sizeof(v8));
            float *d = out + (size_t)y * W + x + (size_t)q * tx;
            for (int c = 0; c < nch; c++) d[c * plane] = o[c];
        }
    }
}

/* up to 32 channels (the 31 bands of a whole frame) and up to 40 (a tensor forward's 33) */
static void row_phase32(const float *T, const float *pad, int PW, int PH, int C, int K, int y,
                        int j, int W, int tx, float *out, size_t plane, int nch)
{
    row_phase(T, pad, PW, PH, C, K, y, j, W, tx, out, plane, nch, 4, NP32);
}

static void row_phase40(const float *T, const float *pad, int PW, int PH, int C, int K, int y,
                        int j, int W, int tx, float *out, size_t plane, int nch)
{
    row_phase(T, pad, PW, PH, C, K, y, j, W, tx, out, plane, nch, 5, NP40);
}

void lm_lmmse_direct_rows(const float *wt, size_t packed, const float *pad, int PW, int PH, int C,
                          int K, int ty, int tx, int H, int W, float *out, int nch, int lanes,
                          int nthreads)
{
    const size_t plane = (size_t)H * W;
    #pragma omp parallel for schedule(static) num_threads(nthreads)
    for (int y = 0; y < H; y++) {
        const int i = y % ty;
        for (int j = 0; j < tx; j++) {
            const float *T = wt + (size_t)(i * tx + j) * packed;
            if (lanes == 32) row_phase32(T, pad, PW, PH, C, K, y, j, W, tx, out, plane, nch);
            else row_phase40(T, pad, PW, PH, C, K, y, j, W, tx, out, plane, nch);
        }
    }
}

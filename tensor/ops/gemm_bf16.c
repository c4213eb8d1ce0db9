/* gemm_bf16.c — the bf16 panel product (gemm_bf16.h): packing, an AMX tile kernel and an
 * AVX-512-BF16 kernel (each compiled with a target attribute and chosen at run time), and
 * their fp32 twin.
 *
 * Layouts (K2 = ceil(K / 2) pairs, NP = n rounded up to 16):
 *   AVX-512-BF16 and the fp32 twin:
 *     Ap[((p K2 + q) MR + r) 2 + t] = A[p MR + r][2 q + t]   (panel p, pair q, row r)
 *     Bp[(q NP + j) 2 + t]          = B[2 q + t][j]
 *   so one 64-byte load of Bp holds 16 columns x one pair of k, and one 32-bit broadcast of Ap
 *   one row's pair: vdpbf16ps adds a0 b0 + a1 b1 into each column's fp32 accumulator. The
 *   micro-tile is MR = 6 rows x 32 columns (12 accumulators), as the fp32 panel kernel's.
 *   AMX: K is cut into S = ceil(K2 / 16) steps of kb = ceil(K2 / S) pairs (K2P = S kb, zero
 *   padded), M into blocks of 16 rows (zero padded), n into blocks of 16 columns:
 *     Ap[((mb S + s) 16 + r) 2 kb + 2 c + t]  = A[16 mb + r][2 (s kb + c) + t]
 *     Bp[((jb BS + q) 16 + jj) 2 + t]         = B[2 q + t][16 jb + jj]
 *   with BS = K2P + 1 pair-rows per column block of B, the last one zero (so the blocks are not
 *   a multiple of 1 KiB apart: packing's writes, one row of B at a time, would crowd a few
 *   cache sets). Every tile is one contiguous block: A's 16 rows x 2 kb bf16 (row stride
 *   4 kb bytes), B's kb pair-rows x 16 columns x 2 (row stride 64 bytes, the pairs tdpbf16ps
 *   wants). Tiles
 *   0-3 hold a 32 x 32 block of C, 4-5 two A tiles, 6-7 two B tiles; a pass over the S steps
 *   does 4 tdpbf16ps per 4 tile loads. C tiles wholly inside M x n are loaded from and stored
 *   to C directly; edge tiles go through a 16 x 16 scratch and masked AVX-512 stores. */
#include "tensor/ops/gemm_bf16.h"
#include "tensor/isa.h"
#include "tensor/tensor.h"
#include <pthread.h>
#include <string.h>

#if defined(__x86_64__) && defined(__GNUC__)
#define LM_HAVE_BF16_KERNEL 1
#include <immintrin.h>
#else
#define LM_HAVE_BF16_KERNEL 0
#endif
/* the tile intrinsics: GCC 11 and clang 12 on */
#if LM_HAVE_BF16_KERNEL && ((defined(__clang__) && __clang_major__ >= 12) ||                  \
                            (!defined(__clang__) && __GNUC__ >= 11))
#define LM_HAVE_AMX_KERNEL 1
#else
#define LM_HAVE_AMX_KERNEL 0
#endif

#define MR LM_BF16_MR

void lm_bf16_from_f32(const float *x, lm_bf16 *y, long n)
{
    for (long i = 0; i < n; i++) y[i] = lm_bf16_round(x[i]);
}

static int pad16(int n) { return (n + 15) / 16 * 16; }

/* The AMX cut of K (see the layouts above). */
typedef struct amx_geom {
    int K2, S, kb, K2P;
    int BS; /* pair-rows from one column block of B to the next: K2P + 1 */
} amx_geom;

static amx_geom amx_cut(int K)
{
    amx_geom g;
    g.K2 = (K + 1) / 2;
    g.S = g.K2 > 0 ? (g.K2 + 15) / 16 : 1;
    g.kb = g.K2 > 0 ? (g.K2 + g.S - 1) / g.S : 1;
    g.K2P = g.S * g.kb;
    g.BS = g.K2P + 1;
    return g;
}

size_t lm_bf16_pack_a_size_for(lm_bf16_kernel k, int M, int K)
{
    if (k == LM_BF16_AMX) return (size_t)pad16(M) * (size_t)amx_cut(K).K2P * 2;
    return (size_t)((M + MR - 1) / MR) * MR * (size_t)((K + 1) / 2) * 2;
}

size_t lm_bf16_pack_b_size_for(lm_bf16_kernel k, int K, int n)
{
    if (k == LM_BF16_AMX) return (size_t)amx_cut(K).BS * pad16(n) * 2;
    return (size_t)((K + 1) / 2) * pad16(n) * 2;
}

#if LM_HAVE_BF16_KERNEL
/* lm_bf16_round of 16 floats (mask: which are read; the others 0), each in the low half of
 * its 32-bit lane. */
__attribute__((target("avx512f"))) static inline __m512i round16(const float *p, __mmask16 mask)
{
    const __m512i u = _mm512_castps_si512(_mm512_maskz_loadu_ps(mask, p));
    const __m512i one = _mm512_set1_epi32(1);
    __m512i r = _mm512_add_epi32(u, _mm512_set1_epi32(0x7fff));
    r = _mm512_srli_epi32(_mm512_add_epi32(r, _mm512_and_si512(_mm512_srli_epi32(u, 16), one)), 16);
    const __mmask16 nan = _mm512_cmpgt_epu32_mask(_mm512_and_si512(u, _mm512_set1_epi32(0x7fffffff)),
                                                  _mm512_set1_epi32(0x7f800000));
    const __m512i quiet = _mm512_or_si512(_mm512_srli_epi32(u, 16), _mm512_set1_epi32(0x40));
    return _mm512_mask_mov_epi32(r, nan, quiet);
}

/* 16 columns of one pair of rows (b1 may be NULL: zeros), rounded and interleaved: 32 bf16. */
__attribute__((target("avx512f"))) static void pack_pair16(const float *b0, const float *b1,
                                                           lm_bf16 *d)
{
    __m512i r = round16(b0, 0xffff);
    if (b1) r = _mm512_or_si512(r, _mm512_slli_epi32(round16(b1, 0xffff), 16));
    _mm512_storeu_si512(d, r);
}
#endif

#if LM_HAVE_BF16_KERNEL
/* 16 floats (mask: which) rounded to bf16 into d (the masked lanes only). */
__attribute__((target("avx512f,avx512vl,avx512bw"))) static void round_store16(const float *p,
                                                                              __mmask16 mask,
                                                                              lm_bf16 *d)
{
    _mm256_mask_storeu_epi16(d, mask, _mm512_cvtepi32_epi16(round16(p, mask)));
}
#endif

/* d[i] = bf16(x[i]), i < cnt (vec: AVX-512 at this level). */
static void round_row(const float *x, int cnt, int vec, lm_bf16 *d)
{
    int i = 0;
#if LM_HAVE_BF16_KERNEL
    if (vec)
        for (; i < cnt; i += 16) {
            const int w = cnt - i < 16 ? cnt - i : 16;
            round_store16(x + i, (__mmask16)((1u << w) - 1u), d + i);
        }
#else
    (void)vec;
#endif
    for (; i < cnt; i++) d[i] = lm_bf16_round(x[i]);
}

void lm_bf16_pack_a_for(lm_bf16_kernel kern, int M, int K, const float *A, long lda,
                        lm_bf16 *Ap)
{
    if (kern == LM_BF16_AMX) {
        const amx_geom g = amx_cut(K);
        const int MB = pad16(M) / 16, vec = LM_HAVE_BF16_KERNEL && lm_isa_active() >= LM_ISA_AVX512;
        for (int mb = 0; mb < MB; mb++)
            for (int s = 0; s < g.S; s++)
                for (int r = 0; r < 16; r++) {
                    lm_bf16 *d = Ap + (((size_t)mb * g.S + s) * 16 + r) * 2 * g.kb;
                    const int m = 16 * mb + r, k0 = 2 * s * g.kb;
                    const int cnt = m >= M ? 0 : K - k0 < 2 * g.kb ? K - k0 : 2 * g.kb;
                    round_row(A + (long)m * lda + k0, cnt, vec, d);
                    memset(d + cnt, 0, sizeof(lm_bf16) * (size_t)(2 * g.kb - cnt));
                }
        return;
    }
    const int K2 = (K + 1) / 2, P = (M + MR - 1) / MR;
    for (int p = 0; p < P; p++)
        for (int q = 0; q < K2; q++)
            for (int r = 0; r < MR; r++)
                for (int t = 0; t < 2; t++) {
                    const int m = p * MR + r, k = 2 * q + t;
                    Ap[(((size_t)p * K2 + q) * MR + r) * 2 + t] =
                        m < M && k < K ? lm_bf16_round(A[(long)m * lda + k]) : 0;
                }
}

/* Pair-row q of B (rows 2q, 2q + 1; q past K2: zeros), columns [0, n) rounded and interleaved
 * into d, column j at d + 2 (j / 16) gap + 2 (j % 16), gap the bf16 between column blocks
 * divided by 2 (16 for the vdpbf16ps layout, whose blocks are contiguous; 16 BS for AMX);
 * the columns up to the next multiple of 16 are zero. (Row by row: B is read in order, which
 * measured faster than writing the AMX blocks in order.) */
static void pack_b_row(int K, int n, const float *B, long ldb, int q, int vec, size_t gap,
                       lm_bf16 *d)
{
    const int K2 = (K + 1) / 2;
    int j = 0;
    if (q >= K2) {
        for (; j < n; j += 16) memset(d + 2 * (size_t)(j / 16) * gap, 0, sizeof(lm_bf16) * 32);
        return;
    }
    const float *b0 = B + (long)(2 * q) * ldb, *b1 = 2 * q + 1 < K ? b0 + ldb : NULL;
#if LM_HAVE_BF16_KERNEL
    if (vec)
        for (; j + 16 <= n; j += 16)
            pack_pair16(b0 + j, b1 ? b1 + j : NULL, d + 2 * (size_t)(j / 16) * gap);
#else
    (void)vec;
#endif
    for (; j < n; j++) {
        lm_bf16 *e = d + 2 * ((size_t)(j / 16) * gap + j % 16);
        e[0] = lm_bf16_round(b0[j]);
        e[1] = b1 ? lm_bf16_round(b1[j]) : 0;
    }
    if (n % 16) {
        lm_bf16 *e = d + 2 * ((size_t)(n / 16) * gap + n % 16);
        memset(e, 0, sizeof(lm_bf16) * 2 * (size_t)(16 - n % 16));
    }
}

void lm_bf16_pack_b_for(lm_bf16_kernel kern, int K, int n, const float *B, long ldb,
                        lm_bf16 *Bp)
{
    const int vec = LM_HAVE_BF16_KERNEL && lm_isa_active() >= LM_ISA_AVX512;
    if (kern == LM_BF16_AMX) { /* strips of 8 column blocks, each row by row */
        const amx_geom g = amx_cut(K);
        for (int j0 = 0; j0 < n; j0 += 128) {
            const int w = n - j0 < 128 ? n - j0 : 128;
            lm_bf16 *d = Bp + (size_t)j0 * 2 * g.BS;
            for (int q = 0; q < g.BS; q++) /* (the last pair-row of each block: zero padding) */
                pack_b_row(q < g.K2P ? K : 0, w, B + j0, ldb, q, vec, (size_t)16 * g.BS,
                           d + (size_t)q * 32);
        }
        return;
    }
    const int K2 = (K + 1) / 2, NP = pad16(n);
    for (int q = 0; q < K2; q++) pack_b_row(K, n, B, ldb, q, vec, 16, Bp + (size_t)q * NP * 2);
}

/* ---- fp32 twin: the same sums, pair by pair (a1 b1 first, then a0 b0, as vdpbf16ps) -----
 * It reads either layout: pair q of row m of A at Ap + arow(m) + (q / kb) sa + (q % kb) ca, of
 * column j of B at Bp + bcol(j) + (q / kb) sb + (q % kb) cb. */
static void panel_fp32(lm_bf16_kernel kern, int M, int n, int K, const lm_bf16 *Ap,
                       const lm_bf16 *Bp, const float *bias, int accumulate, float *C, long ldc)
{
    const int K2 = (K + 1) / 2, NP = pad16(n);
    const int amx = kern == LM_BF16_AMX;
    const amx_geom g = amx_cut(K);
    const int kb = amx ? g.kb : K2 > 0 ? K2 : 1;
    const size_t sa = amx ? (size_t)32 * kb : 0, ca = amx ? 2 : 2 * MR;
    const size_t sb = amx ? (size_t)32 * kb : 0, cb = amx ? 32 : (size_t)NP * 2;
    for (int m = 0; m < M; m++) {
        const lm_bf16 *a = amx ? Ap + (((size_t)(m / 16) * g.S) * 16 + m % 16) * 2 * kb
                               : Ap + ((size_t)(m / MR) * K2 * MR + m % MR) * 2;
        float *c = C + (long)m * ldc;
        for (int j = 0; j < n; j++) {
            const lm_bf16 *b = amx ? Bp + ((size_t)(j / 16) * g.BS * 16 + j % 16) * 2
                                   : Bp + (size_t)j * 2;
            float s = accumulate ? c[j] : bias ? bias[m] : 0.0f;
            for (int q0 = 0; q0 < K2; q0 += kb) {
                const lm_bf16 *as = a + (size_t)(q0 / kb) * sa, *bs = b + (size_t)(q0 / kb) * sb;
                const int e = K2 - q0 < kb ? K2 - q0 : kb;
                for (int q = 0; q < e; q++) {
                    const lm_bf16 *aq = as + q * ca, *bq = bs + q * cb;
                    s += lm_bf16_to_f32(aq[1]) * lm_bf16_to_f32(bq[1]);
                    s += lm_bf16_to_f32(aq[0]) * lm_bf16_to_f32(bq[0]);
                }
            }
            c[j] = s;
        }
    }
}

#if LM_HAVE_BF16_KERNEL
#define BF16 __attribute__((target("avx512f,avx512vl,avx512bw,avx512dq,avx512bf16")))

/* Rows [p MR, p MR + rows) x columns [j, j + 16 nv) (nv 1 or 2; the last block masked). */
BF16 static void tile(int K2, int NP, const lm_bf16 *a, const lm_bf16 *Bp, int j, int nv,
                      int rows, int n, const float *bias, int accumulate, float *C, long ldc)
{
    __m512 acc[MR][2];
    __mmask16 mk[2];
    for (int v = 0; v < 2; v++) {
        int left = n - j - 16 * v;
        mk[v] = left >= 16 ? (__mmask16)0xffff : left > 0 ? (__mmask16)((1u << left) - 1u) : 0;
    }
#pragma GCC unroll 6
    for (int r = 0; r < MR; r++) {
        const float b0 = bias && r < rows ? bias[r] : 0.0f;
        acc[r][0] = _mm512_set1_ps(b0), acc[r][1] = acc[r][0];
        if (accumulate && r < rows) {
            acc[r][0] = _mm512_maskz_loadu_ps(mk[0], C + (long)r * ldc + j);
            if (nv == 2) acc[r][1] = _mm512_maskz_loadu_ps(mk[1], C + (long)r * ldc + j + 16);
        }
    }
    const lm_bf16 *b = Bp + (size_t)j * 2;
    if (nv == 2) {
        for (int q = 0; q < K2; q++, a += MR * 2, b += (size_t)NP * 2) {
            __m512bh b0 = (__m512bh)_mm512_loadu_si512(b), b1 = (__m512bh)_mm512_loadu_si512(b + 32);
#pragma GCC unroll 6
            for (int r = 0; r < MR; r++) {
                int32_t pr;
                memcpy(&pr, a + 2 * r, 4);
                __m512bh av = (__m512bh)_mm512_set1_epi32(pr);
                acc[r][0] = _mm512_dpbf16_ps(acc[r][0], av, b0);
                acc[r][1] = _mm512_dpbf16_ps(acc[r][1], av, b1);
            }
        }
    } else {
        for (int q = 0; q < K2; q++, a += MR * 2, b += (size_t)NP * 2) {
            __m512bh b0 = (__m512bh)_mm512_loadu_si512(b);
#pragma GCC unroll 6
            for (int r = 0; r < MR; r++) {
                int32_t pr;
                memcpy(&pr, a + 2 * r, 4);
                acc[r][0] = _mm512_dpbf16_ps(acc[r][0], (__m512bh)_mm512_set1_epi32(pr), b0);
            }
        }
    }
    for (int r = 0; r < rows; r++) {
        _mm512_mask_storeu_ps(C + (long)r * ldc + j, mk[0], acc[r][0]);
        if (nv == 2) _mm512_mask_storeu_ps(C + (long)r * ldc + j + 16, mk[1], acc[r][1]);
    }
}

BF16 static void panel_avx512bf16(int M, int n, int K, const lm_bf16 *Ap, const lm_bf16 *Bp,
                                  const float *bias, int accumulate, float *C, long ldc)
{
    const int K2 = (K + 1) / 2, NP = pad16(n);
    for (int j = 0; j < n; j += 32) {
        const int nv = n - j > 16 ? 2 : 1;
        for (int p = 0; p < M; p += MR) {
            const int rows = M - p < MR ? M - p : MR;
            tile(K2, NP, Ap + (size_t)p * K2 * 2, Bp, j, nv, rows, n, bias ? bias + p : NULL,
                 accumulate, C + (long)p * ldc, ldc);
        }
    }
}
#endif

#if LM_HAVE_AMX_KERNEL
#define AMX                                                                                   \
    __attribute__((target("amx-tile,amx-bf16,avx512f,avx512vl,avx512bw,avx512dq,prfchw")))
/* The tile instructions' memory operands are invisible to the compiler (GCC's intrinsics are
 * asm statements without memory inputs): a barrier keeps the stores a tile load reads before it. */
#define MEMORY_BARRIER() __asm__ volatile("" ::: "memory")

/* ldtilecfg's operand: palette 1, bytes per row and rows of each tile. */
typedef struct tile_config {
    uint8_t palette, start_row, reserved[14];
    uint16_t colsb[16];
    uint8_t rows[16];
} tile_config;

/* Where one C tile goes: rows x cols of C (1..16 each) at c; full when 16 x 16. */
typedef struct ctile {
    float *c;
    int rows, cols;
    __mmask16 mask;
} ctile;

/* Where a C tile's starting value is: C itself for a whole tile accumulated; scr (16 x 16,
 * filled here, zero past the edges) for an edge tile accumulated or a bias; NULL for zero. */
AMX static const float *c_start(const ctile *t, const float *bias, int accumulate, long ldc,
                                float *scr)
{
    if (!accumulate && !bias) return NULL;
    if (accumulate && t->rows == 16 && t->cols == 16) return t->c;
    for (int r = 0; r < 16; r++) {
        __m512 v = _mm512_setzero_ps();
        if (r < t->rows)
            v = accumulate ? _mm512_maskz_loadu_ps(t->mask, t->c + (long)r * ldc)
                           : _mm512_maskz_mov_ps(t->mask, _mm512_set1_ps(bias[r]));
        _mm512_store_ps(scr + 16 * r, v);
    }
    MEMORY_BARRIER();
    return scr;
}

/* The rows x cols of a tile stored in scr, into C. */
AMX static void c_finish(const ctile *t, long ldc, const float *scr)
{
    MEMORY_BARRIER();
    for (int r = 0; r < t->rows; r++)
        _mm512_mask_storeu_ps(t->c + (long)r * ldc, t->mask, _mm512_load_ps(scr + 16 * r));
}

/* Tile numbers are immediates: one statement per tile. */
#define TILE_START(T, init, ld)                                                               \
    do {                                                                                      \
        if (!(init)) _tile_zero(T);                                                           \
        else _tile_loadd(T, init, ld);                                                        \
    } while (0)
#define TILE_END(T, ct, ldc, scr)                                                             \
    do {                                                                                      \
        if ((ct).rows == 16 && (ct).cols == 16) {                                             \
            _tile_stored(T, (ct).c, (ldc) * 4);                                               \
        } else {                                                                              \
            _tile_stored(T, scr, 64);                                                         \
            c_finish(&(ct), ldc, scr);                                                        \
        }                                                                                     \
    } while (0)

/* A tile load; with stream 1 a hint that the data will not be used again soon (tileloaddt1),
 * so it does not push the reused operand out of the first-level cache. */
#define TILE_LOAD(T, p, ld, stream)                                                           \
    do {                                                                                      \
        if (stream) _tile_stream_loadd(T, p, ld);                                             \
        else _tile_loadd(T, p, ld);                                                           \
    } while (0)

/* One block of mt x nt C tiles (mt, nt in 1..2: constants after inlining) at row block mb,
 * column block jb, over all K; hint (a constant) 1 streams A's tiles, 2 B's. */
AMX static inline __attribute__((always_inline)) void
amx_block(const int mt, const int nt, const int hint, const amx_geom *g, int M, int n, int mb,
          int jb,
          const lm_bf16 *Ap, const lm_bf16 *Bp, const float *bias, int accumulate, float *C,
          long ldc, float (*scr)[256])
{
    ctile ct[2][2];
    const float *init[2][2];
    for (int i = 0; i < mt; i++)
        for (int j = 0; j < nt; j++) {
            const int m0 = 16 * (mb + i), j0 = 16 * (jb + j);
            ct[i][j].c = C + (long)m0 * ldc + j0;
            ct[i][j].rows = M - m0 < 16 ? M - m0 : 16;
            ct[i][j].cols = n - j0 < 16 ? n - j0 : 16;
            ct[i][j].mask = (__mmask16)((1u << ct[i][j].cols) - 1u);
            init[i][j] = c_start(&ct[i][j], bias ? bias + m0 : NULL, accumulate, ldc,
                                 scr[2 * i + j]);
        }
    TILE_START(0, init[0][0], init[0][0] == scr[0] ? 64 : ldc * 4);
    if (nt == 2) TILE_START(1, init[0][1], init[0][1] == scr[1] ? 64 : ldc * 4);
    if (mt == 2) TILE_START(2, init[1][0], init[1][0] == scr[2] ? 64 : ldc * 4);
    if (mt == 2 && nt == 2) TILE_START(3, init[1][1], init[1][1] == scr[3] ? 64 : ldc * 4);
    /* one step: an A tile (16 rows x kb pairs) or a B tile (kb pair-rows x 16 columns) */
    const size_t step = (size_t)32 * g->kb, bblk = (size_t)32 * g->BS;
    const lm_bf16 *a0 = Ap + (size_t)mb * g->S * step, *a1 = a0 + (size_t)g->S * step;
    const lm_bf16 *b0 = Bp + (size_t)jb * bblk, *b1 = b0 + bblk;
    const long lda = 4L * g->kb;
    if (ldc % 256 == 0) /* C's rows a multiple of 1 KiB apart share few cache sets: fetched
                         * for writing now, while the tiles multiply, not at the store */
        for (int i = 0; i < mt; i++)
            for (int j = 0; j < nt; j++)
                if (ct[i][j].rows == 16 && ct[i][j].cols == 16 && !init[i][j])
                    for (int r = 0; r < 16; r++) __builtin_prefetch(ct[i][j].c + (long)r * ldc, 1, 3);
    for (int s = 0; s < g->S; s++) {
        TILE_LOAD(4, a0 + s * step, lda, hint == 1);
        if (mt == 2) TILE_LOAD(5, a1 + s * step, lda, hint == 1);
        TILE_LOAD(6, b0 + s * step, 64, hint == 2);
        if (nt == 2) TILE_LOAD(7, b1 + s * step, 64, hint == 2);
        _tile_dpbf16ps(0, 4, 6);
        if (nt == 2) _tile_dpbf16ps(1, 4, 7);
        if (mt == 2) _tile_dpbf16ps(2, 5, 6);
        if (mt == 2 && nt == 2) _tile_dpbf16ps(3, 5, 7);
    }
    TILE_END(0, ct[0][0], ldc, scr[0]);
    if (nt == 2) TILE_END(1, ct[0][1], ldc, scr[1]);
    if (mt == 2) TILE_END(2, ct[1][0], ldc, scr[2]);
    if (mt == 2 && nt == 2) TILE_END(3, ct[1][1], ldc, scr[3]);
}

/* Every block: with rows_outer 0, column pairs outer and row pairs inner (a B column block is
 * reused across the rows; A, when small, across the columns); with 1 the other way round (a
 * pair of A's row blocks reused across the columns). */
AMX static inline __attribute__((always_inline)) void
amx_sweep(const int hint, const int rows_outer, const amx_geom *g, int M, int n,
          const lm_bf16 *Ap, const lm_bf16 *Bp, const float *bias, int accumulate, float *C,
          long ldc, float (*scr)[256])
{
    const int MB = (M + 15) / 16, NB = (n + 15) / 16;
    const int outer = rows_outer ? MB : NB, inner = rows_outer ? NB : MB;
    for (int o = 0; o < outer; o += 2)
        for (int i = 0; i < inner; i += 2) {
            const int mb = rows_outer ? o : i, jb = rows_outer ? i : o;
            const int mt = MB - mb >= 2 ? 2 : 1, nt = NB - jb >= 2 ? 2 : 1;
            if (mt == 2 && nt == 2)
                amx_block(2, 2, hint, g, M, n, mb, jb, Ap, Bp, bias, accumulate, C, ldc, scr);
            else if (mt == 2)
                amx_block(2, 1, hint, g, M, n, mb, jb, Ap, Bp, bias, accumulate, C, ldc, scr);
            else if (nt == 2)
                amx_block(1, 2, hint, g, M, n, mb, jb, Ap, Bp, bias, accumulate, C, ldc, scr);
            else
                amx_block(1, 1, hint, g, M, n, mb, jb, Ap, Bp, bias, accumulate, C, ldc, scr);
        }
}

AMX static void panel_amx(int M, int n, int K, const lm_bf16 *Ap, const lm_bf16 *Bp,
                          const float *bias, int accumulate, float *C, long ldc)
{
    const amx_geom g = amx_cut(K);
    tile_config cfg;
    memset(&cfg, 0, sizeof cfg);
    cfg.palette = 1;
    for (int t = 0; t < 4; t++) cfg.rows[t] = 16, cfg.colsb[t] = 64;     /* C: 16 x 16 fp32 */
    for (int t = 4; t < 6; t++) cfg.rows[t] = 16, cfg.colsb[t] = (uint16_t)(4 * g.kb); /* A */
    for (int t = 6; t < 8; t++) cfg.rows[t] = (uint8_t)g.kb, cfg.colsb[t] = 64;          /* B */
    float scr[4][256] __attribute__((aligned(64)));
    MEMORY_BARRIER(); /* the packed operands and C, written before the call */
    _tile_loadconfig(&cfg);
    /* A whole in the first-level cache (up to 32 KiB): kept there across the columns, and B
     * streamed when each column block serves one pass of rows; else row pairs outer, each
     * pair of A's row blocks kept and B streamed (measured: 512^3 10 % faster than keeping B
     * column blocks and streaming A; the smaller products slightly slower that way) */
    const size_t abytes = lm_bf16_pack_a_size_for(LM_BF16_AMX, M, K) * sizeof(lm_bf16);
    if (abytes > 32768)
        amx_sweep(2, 1, &g, M, n, Ap, Bp, bias, accumulate, C, ldc, scr);
    else if (M <= 32)
        amx_sweep(2, 0, &g, M, n, Ap, Bp, bias, accumulate, C, ldc, scr);
    else
        amx_sweep(0, 0, &g, M, n, Ap, Bp, bias, accumulate, C, ldc, scr);
    _tile_release();
    MEMORY_BARRIER();
}
#endif

int lm_bf16_kernel_runs(lm_bf16_kernel k)
{
    const lm_cpu_features *f = lm_cpu_features_get();
    const lm_isa level = lm_isa_active();
    switch (k) {
    case LM_BF16_FP32: return 1;
    case LM_BF16_DPBF16:
        return LM_HAVE_BF16_KERNEL && level >= LM_ISA_AVX512 && f->avx512_bf16;
    case LM_BF16_AMX:
        return LM_HAVE_AMX_KERNEL && level >= LM_ISA_AMX && f->amx_bf16 && lm_amx_tile_granted();
    }
    return 0;
}

static pthread_once_t kernel_once = PTHREAD_ONCE_INIT;
static lm_bf16_kernel kernel_chosen = LM_BF16_FP32;

static void choose_kernel(void)
{
    kernel_chosen = lm_bf16_kernel_runs(LM_BF16_AMX)      ? LM_BF16_AMX
                    : lm_bf16_kernel_runs(LM_BF16_DPBF16) ? LM_BF16_DPBF16
                                                          : LM_BF16_FP32;
}

lm_bf16_kernel lm_bf16_kernel_active(void)
{
    pthread_once(&kernel_once, choose_kernel);
    return kernel_chosen;
}

const char *lm_bf16_kernel_name(lm_bf16_kernel k)
{
    switch (k) {
    case LM_BF16_FP32: return "fp32 twin";
    case LM_BF16_DPBF16: return "AVX-512-BF16 (vdpbf16ps)";
    case LM_BF16_AMX: return "AMX tiles";
    }
    return "?";
}

int lm_gemm_bf16_native(void) { return lm_bf16_kernel_active() != LM_BF16_FP32; }

const char *lm_precision_describe(int precision)
{
    if (precision != LM_PRECISION_BF16) return "fp32";
    const lm_cpu_features *f = lm_cpu_features_get();
    switch (lm_bf16_kernel_active()) {
    case LM_BF16_AMX: return "bf16 (AMX tiles, fp32 sums)";
    case LM_BF16_DPBF16:
        if (f->amx_bf16 && lm_isa_active() >= LM_ISA_AMX)
            return "bf16 (AVX-512-BF16 products, fp32 sums: the kernel refuses the AMX tile state)";
        return "bf16 (AVX-512-BF16 products, fp32 sums)";
    case LM_BF16_FP32: break;
    }
    return f->avx512_bf16
               ? "bf16 (operands rounded to bf16, products in fp32: LM_ISA is below avx512)"
               : "bf16 (operands rounded to bf16, products in fp32: this CPU has no AVX-512-BF16)";
}

size_t lm_bf16_pack_a_size(int M, int K)
{
    return lm_bf16_pack_a_size_for(lm_bf16_kernel_active(), M, K);
}

size_t lm_bf16_pack_b_size(int K, int n)
{
    return lm_bf16_pack_b_size_for(lm_bf16_kernel_active(), K, n);
}

void lm_bf16_pack_a(int M, int K, const float *A, long lda, lm_bf16 *Ap)
{
    lm_bf16_pack_a_for(lm_bf16_kernel_active(), M, K, A, lda, Ap);
}

void lm_bf16_pack_b(int K, int n, const float *B, long ldb, lm_bf16 *Bp)
{
    lm_bf16_pack_b_for(lm_bf16_kernel_active(), K, n, B, ldb, Bp);
}

/* The product with kernel k, which the caller knows runs here (lm_bf16_kernel_runs). */
static void run_kernel(lm_bf16_kernel k, int M, int n, int K, const lm_bf16 *Ap,
                       const lm_bf16 *Bp, const float *bias, int accumulate, float *C, long ldc)
{
    if (M <= 0 || n <= 0) return;
#if LM_HAVE_AMX_KERNEL
    if (k == LM_BF16_AMX) {
        panel_amx(M, n, K, Ap, Bp, bias, accumulate, C, ldc);
        return;
    }
#endif
#if LM_HAVE_BF16_KERNEL
    if (k == LM_BF16_DPBF16) {
        panel_avx512bf16(M, n, K, Ap, Bp, bias, accumulate, C, ldc);
        return;
    }
#endif
    panel_fp32(k, M, n, K, Ap, Bp, bias, accumulate, C, ldc);
}

void lm_gemm_bf16_panel_for(lm_bf16_kernel k, int M, int n, int K, const lm_bf16 *Ap,
                            const lm_bf16 *Bp, const float *bias, int accumulate, float *C,
                            long ldc)
{
    if (k != LM_BF16_FP32 && !lm_bf16_kernel_runs(k)) { /* its layout, multiplied in fp32 */
        panel_fp32(k, M, n, K, Ap, Bp, bias, accumulate, C, ldc);
        return;
    }
    run_kernel(k, M, n, K, Ap, Bp, bias, accumulate, C, ldc);
}

/* The process's kernel was checked once when it was chosen: no check per call. */
void lm_gemm_bf16_panel(int M, int n, int K, const lm_bf16 *Ap, const lm_bf16 *Bp,
                        const float *bias, int accumulate, float *C, long ldc)
{
    run_kernel(lm_bf16_kernel_active(), M, n, K, Ap, Bp, bias, accumulate, C, ldc);
}

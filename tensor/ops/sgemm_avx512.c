/* sgemm_avx512.c — the project's single-threaded SGEMM: lm_sgemm_st.
 * What it is: row-major C = alpha op(A) op(B) + beta C with CBLAS semantics (4 transpose
 * combinations, any leading dimensions, beta == 0 never reads C, K == 0 scales C), computed
 * by Goto/BLIS blocking: for each NC-column block of C and KC-deep slice of K, op(B) is
 * packed into KC x NR micro-panels, then for each MC-row block op(A) into MR x KC
 * micro-panels (both zero-padded at the edges), and an MR x NR register-blocked AVX-512 FMA
 * micro-kernel updates each tile of C (edge tiles through masked loads/stores). When M fits
 * one A block and B is not transposed, B's full-width panels are read in place, unpacked
 * (the conv shapes: M = output channels <= 128). The K order
 * of every element is fixed (slices in order, k ascending inside), so results never depend
 * on threads. Packing buffers are per thread (malloc'ed once, grown, freed at thread exit).
 * The AVX-512 code is compiled with a target attribute and chosen at run time
 * (the level of tensor/isa.h: CPU, operating system and LM_ISA); otherwise, or with LM_SGEMM=blas in the environment, or after
 * lm_sgemm_set_impl(LM_SGEMM_BLAS), OpenBLAS cblas_sgemm does the work.
 * What it is not: multi-threaded (see gemm_parallel.c), an op, or a checker of arguments. */
#include "tensor/ops/gemm_internal.h"
#include "tensor/isa.h"
#include <cblas.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

#if defined(__x86_64__) && defined(__GNUC__)
#define LM_HAVE_AVX512_KERNEL 1
#include <immintrin.h>
#else
#define LM_HAVE_AVX512_KERNEL 0
#endif

/* ---- implementation choice ------------------------------------------------------------- */
static int impl_default = LM_SGEMM_BLAS; /* resolved once */
static int impl_forced = -1;             /* lm_sgemm_set_impl; -1 = use the default */
static pthread_once_t impl_once = PTHREAD_ONCE_INIT;

/* The AVX-512 kernel runs when the chosen level (tensor/isa.h: CPU, OS, LM_ISA) has it. */
static int cpu_has_avx512(void)
{
#if LM_HAVE_AVX512_KERNEL
    return lm_isa_active() >= LM_ISA_AVX512;
#else
    return 0;
#endif
}

static void impl_resolve(void)
{
    const char *e = getenv("LM_SGEMM");
    int blas = e && strcmp(e, "blas") == 0;
    impl_default = !blas && cpu_has_avx512() ? LM_SGEMM_AVX512 : LM_SGEMM_BLAS;
}

int lm_sgemm_impl(void)
{
    pthread_once(&impl_once, impl_resolve);
    int f = __atomic_load_n(&impl_forced, __ATOMIC_RELAXED);
    return f >= 0 ? f : impl_default;
}

int lm_sgemm_set_impl(int impl)
{
    int prev = lm_sgemm_impl();
    if (impl == LM_SGEMM_AVX512 && !cpu_has_avx512()) impl = LM_SGEMM_BLAS;
    __atomic_store_n(&impl_forced, impl < 0 ? -1 : impl, __ATOMIC_RELAXED);
    return prev;
}

/* C = beta C over M x N (beta == 0 writes zeros, whatever C held). */
static void scale_c(int M, int N, float beta, float *C, int ldc)
{
    for (int i = 0; i < M; i++) {
        float *p = C + (long)i * ldc;
        if (beta == 0.0f)
            memset(p, 0, sizeof(float) * (size_t)N);
        else if (beta != 1.0f)
            for (int j = 0; j < N; j++) p[j] *= beta;
    }
}

#if LM_HAVE_AVX512_KERNEL
/* ---- the AVX-512 path ------------------------------------------------------------------ */
#define AVX512 __attribute__((target("avx512f,avx512vl,avx512bw,avx512dq,fma")))
#define MR 8              /* rows of a micro-tile */
#define NV 3              /* 16-float vectors per micro-tile row */
#define NR (16 * NV)      /* columns of a micro-tile */
#define KC 256            /* depth of a packed slice */
#define MC 128            /* rows of a packed A block (multiple of MR) */
#define NC 3072           /* columns of a packed B block (multiple of NR) */
#define DIRECT_MAX_M MC  /* up to this many rows (one A block), op(B) = B is not packed */

typedef struct pack_buf {
    float *a, *b; /* MC x KC and KC x NC, 64-byte aligned */
} pack_buf;

static pthread_key_t buf_key;
static pthread_once_t buf_once = PTHREAD_ONCE_INIT;

static void buf_free(void *p)
{
    pack_buf *pb = p;
    free(pb->a);
    free(pb->b);
    free(pb);
}

static void buf_key_init(void) { (void)pthread_key_create(&buf_key, buf_free); }

/* This thread's packing buffers (NULL when out of memory). */
static pack_buf *thread_buf(void)
{
    pthread_once(&buf_once, buf_key_init);
    pack_buf *pb = pthread_getspecific(buf_key);
    if (pb) return pb;
    pb = calloc(1, sizeof *pb);
    if (!pb) return NULL;
    if (posix_memalign((void **)&pb->a, 64, sizeof(float) * MC * KC) ||
        posix_memalign((void **)&pb->b, 64, sizeof(float) * KC * NC) ||
        pthread_setspecific(buf_key, pb)) {
        free(pb->a), free(pb->b), free(pb);
        return NULL;
    }
    return pb;
}

/* Mask of the first n (clamped to 0..16) lanes. */
static inline __mmask16 lanes(int n)
{
    return n >= 16 ? (__mmask16)0xFFFF : n <= 0 ? (__mmask16)0 : (__mmask16)((1u << n) - 1);
}

/* dst (kc x W, W = MR or NR) = src rows k (stride ld) of w <= W contiguous floats, zero-padded:
 * op(A) with A transposed, op(B) with B not transposed. */
AVX512 static void pack_contig(float *dst, const float *src, long ld, int kc, int w, int W)
{
    for (int k = 0; k < kc; k++, dst += W) {
        const float *s = src + (long)k * ld;
        for (int v = 0; v < W; v += 16)
            _mm512_mask_storeu_ps(dst + v, lanes(W - v),
                                  _mm512_maskz_loadu_ps(lanes(w - v), s + v));
    }
}

/* dst[k*W + j] = src[j*ld + k] for a 16 x 16 block: in-register transpose (unpack within
 * 128-bit lanes, then shuffle lanes twice). Rows j >= w of src are not read (zeros); with
 * W < 16 each output row stores its first W lanes only (a packed micro-panel of MR rows). */
AVX512 static inline void transpose16_part(float *dst, long W, const float *src, long ld, int w)
{
    __m512 r[16], t[16];
#pragma GCC unroll 16
    for (int j = 0; j < 16; j++) r[j] = j < w ? _mm512_loadu_ps(src + j * ld) : _mm512_setzero_ps();
#pragma GCC unroll 8
    for (int j = 0; j < 16; j += 2) {
        t[j] = _mm512_unpacklo_ps(r[j], r[j + 1]);
        t[j + 1] = _mm512_unpackhi_ps(r[j], r[j + 1]);
    }
#pragma GCC unroll 4
    for (int q = 0; q < 16; q += 4) { /* r[q + c]: column c (+4 per lane) of rows q..q+3 */
        r[q] = _mm512_shuffle_ps(t[q], t[q + 2], 0x44);
        r[q + 1] = _mm512_shuffle_ps(t[q], t[q + 2], 0xEE);
        r[q + 2] = _mm512_shuffle_ps(t[q + 1], t[q + 3], 0x44);
        r[q + 3] = _mm512_shuffle_ps(t[q + 1], t[q + 3], 0xEE);
    }
#pragma GCC unroll 4
    for (int c = 0; c < 4; c++) {
        t[c] = _mm512_shuffle_f32x4(r[c], r[c + 4], 0x88);
        t[c + 4] = _mm512_shuffle_f32x4(r[c], r[c + 4], 0xDD);
        t[c + 8] = _mm512_shuffle_f32x4(r[c + 8], r[c + 12], 0x88);
        t[c + 12] = _mm512_shuffle_f32x4(r[c + 8], r[c + 12], 0xDD);
    }
    const __mmask16 mk = W < 16 ? lanes((int)W) : (__mmask16)0xFFFF;
#pragma GCC unroll 8
    for (int c = 0; c < 8; c++) {
        _mm512_mask_storeu_ps(dst + c * W, mk, _mm512_shuffle_f32x4(t[c], t[c + 8], 0x88));
        _mm512_mask_storeu_ps(dst + (c + 8) * W, mk, _mm512_shuffle_f32x4(t[c], t[c + 8], 0xDD));
    }
}


/* dst (kc x W) with dst[k][j] = src[j*ld + k] for j < w, zeros beyond: op(A) with A not
 * transposed, op(B) with B transposed. 16 x 16 blocks (rows beyond w read as zeros) go through
 * transpose16_part: for the MR-row micro-panels and for partial NR panels too (a strided scalar
 * copy and zero fill of those took 14-18 % of a han-tiny training step). */
AVX512 static void pack_strided(float *dst, const float *src, long ld, int kc, int w, int W)
{
    int k16 = kc / 16 * 16;
    if (W <= 16) { /* one micro-panel (W = MR): w rows, zero-padded, 16 k at a time */
        for (int k = 0; k < k16; k += 16) transpose16_part(dst + (long)k * W, W, src + k, ld, w);
        for (int j = 0; j < W; j++) {
            const float *s = src + (long)j * ld;
            for (int k = k16; k < kc; k++) dst[(long)k * W + j] = j < w ? s[k] : 0.0f;
        }
        return;
    }
    if (W % 16 == 0) { /* NR-wide panels: 16 x 16 blocks, rows j >= w zero (no strided
                        * zeroing: a partial panel, e.g. 33 of 48 columns, is one pass) */
        for (int j = 0; j < W; j += 16) {
            int jw = w - j < 0 ? 0 : w - j > 16 ? 16 : w - j;
            for (int k = 0; k < k16; k += 16)
                transpose16_part(dst + (long)k * W + j, W, src + (long)j * ld + k, ld, jw);
        }
        for (int k = k16; k < kc; k++)
            for (int j = 0; j < W; j++) dst[(long)k * W + j] = j < w ? src[(long)j * ld + k] : 0.0f;
        return;
    }
    for (int j = 0; j < w; j++) {
        const float *s = src + (long)j * ld;
        for (int k = 0; k < kc; k++) dst[(long)k * W + j] = s[k];
    }
    for (int j = w; j < W; j++)
        for (int k = 0; k < kc; k++) dst[(long)k * W + j] = 0.0f;
}

/* One m x n (<= MR x NR) tile: C = alpha ap bp + beta C over depth kc, where ap is MR x kc
 * (k-major), bp kc x NR with rows ldk apart (NR when packed). beta == 0: C is written,
 * never read. */
AVX512 static void micro_kernel(int kc, const float *ap, const float *bp, long ldk, float *C,
                                int ldc, int m, int n, float alpha, float beta)
{
    __m512 acc[MR][NV];
#pragma GCC unroll 16
    for (int i = 0; i < MR; i++)
#pragma GCC unroll 4
        for (int v = 0; v < NV; v++) acc[i][v] = _mm512_setzero_ps();
    for (int k = 0; k < kc; k++, ap += MR, bp += ldk) {
        __m512 b[NV];
#pragma GCC unroll 4
        for (int v = 0; v < NV; v++) b[v] = _mm512_loadu_ps(bp + 16 * v);
#pragma GCC unroll 16
        for (int i = 0; i < MR; i++) {
            __m512 a = _mm512_set1_ps(ap[i]);
#pragma GCC unroll 4
            for (int v = 0; v < NV; v++) acc[i][v] = _mm512_fmadd_ps(a, b[v], acc[i][v]);
        }
    }
    __m512 va = _mm512_set1_ps(alpha), vb = _mm512_set1_ps(beta);
    __mmask16 mk[NV];
    for (int v = 0; v < NV; v++) mk[v] = lanes(n - 16 * v);
#pragma GCC unroll 16
    for (int i = 0; i < MR; i++) {
        if (i >= m) break;
        float *c = C + (long)i * ldc;
#pragma GCC unroll 4
        for (int v = 0; v < NV; v++) {
            __m512 r = _mm512_mul_ps(va, acc[i][v]);
            if (beta != 0.0f)
                r = _mm512_fmadd_ps(vb, _mm512_maskz_loadu_ps(mk[v], c + 16 * v), r);
            _mm512_mask_storeu_ps(c + 16 * v, mk[v], r);
        }
    }
}

/* C (M x nc) = alpha op(A)[:, pc:pc+kc] Bk + beta C, Bk = the kc x nc slice of op(B): packed
 * panels bp, or (when Bd is not NULL) its full-width panels read in place from Bd (rows ldbd
 * apart) and only the last, narrower panel packed. ap: room for MC x KC. */
AVX512 static void block_rows(int ta, int M, int nc, int kc, int pc, float alpha,
                              const float *A, int lda, const float *bp, const float *Bd,
                              int ldbd, float beta, float *C, int ldc, float *ap)
{
    for (int ic = 0; ic < M; ic += MC) {
        int mc = M - ic < MC ? M - ic : MC;
        for (int ir = 0; ir < mc; ir += MR) {
            int m = mc - ir < MR ? mc - ir : MR;
            float *dst = ap + (long)ir * kc;
            if (ta)
                pack_contig(dst, A + (long)pc * lda + ic + ir, lda, kc, m, MR);
            else
                pack_strided(dst, A + (long)(ic + ir) * lda + pc, lda, kc, m, MR);
        }
        for (int jr = 0; jr < nc; jr += NR) {
            int n = nc - jr < NR ? nc - jr : NR, in_place = Bd && n == NR;
            const float *b = in_place ? Bd + jr : bp + (long)jr * kc;
            for (int ir = 0; ir < mc; ir += MR) {
                int m = mc - ir < MR ? mc - ir : MR;
                micro_kernel(kc, ap + (long)ir * kc, b, in_place ? ldbd : NR,
                             C + (long)(ic + ir) * ldc + jr, ldc, m, n, alpha, beta);
            }
        }
    }
}

/* Returns 0, or -1 when the packing buffers cannot be allocated (caller falls back). */
AVX512 static int sgemm_avx512(int ta, int tb, int M, int N, int K, float alpha,
                               const float *A, int lda, const float *B, int ldb, float beta,
                               float *C, int ldc)
{
    pack_buf *pb = thread_buf();
    if (!pb) return -1;
    /* at most one A block: each B panel is read once, so packing it costs more than
     * reading it in place (measured: M = 16..128 gain 10-60%; larger M lose) */
    int direct = !tb && M <= DIRECT_MAX_M;
    for (int jc = 0; jc < N; jc += NC) {
        int nc = N - jc < NC ? N - jc : NC;
        for (int pc = 0; pc < K; pc += KC) {
            int kc = K - pc < KC ? K - pc : KC;
            const float *Bd = direct ? B + (long)pc * ldb + jc : NULL;
            for (int jr = 0; jr < nc; jr += NR) {
                int n = nc - jr < NR ? nc - jr : NR;
                float *dst = pb->b + (long)jr * kc;
                if (direct && n == NR) continue; /* read in place */
                if (tb)
                    pack_strided(dst, B + (long)(jc + jr) * ldb + pc, ldb, kc, n, NR);
                else
                    pack_contig(dst, B + (long)pc * ldb + jc + jr, ldb, kc, n, NR);
            }
            block_rows(ta, M, nc, kc, pc, alpha, A, lda, pb->b, Bd, ldb,
                       pc == 0 ? beta : 1.0f, C + jc, ldc, pb->a);
        }
    }
    return 0;
}
#endif

void lm_sgemm_st(int ta, int tb, int M, int N, int K, float alpha, const float *A, int lda,
                 const float *B, int ldb, float beta, float *C, int ldc)
{
    if (M <= 0 || N <= 0) return;
    if (K <= 0 || alpha == 0.0f) { /* CBLAS leaves C unscaled for K == 0 in some builds */
        scale_c(M, N, beta, C, ldc);
        return;
    }
#if LM_HAVE_AVX512_KERNEL
    if (lm_sgemm_impl() == LM_SGEMM_AVX512 &&
        sgemm_avx512(ta, tb, M, N, K, alpha, A, lda, B, ldb, beta, C, ldc) == 0)
        return;
#endif
    cblas_sgemm(CblasRowMajor, ta ? CblasTrans : CblasNoTrans, tb ? CblasTrans : CblasNoTrans, M,
                N, K, alpha, A, lda, B, ldb, beta, C, ldc);
}

/* gemm.cl - batched single-precision GEMM, row-major, CBLAS semantics:
 * C = alpha op(A) op(B) + beta C, op(A) M x K, op(B) K x N (ta, tb: transposed storage).
 * Three kernels with the same arguments, chosen by the launcher (cl_gemm.c) from ta, tb:
 *   gemm_vn   (tb == 0): each work-item computes an 8 x 16 block of C as eight float16 rows:
 *             per k one 16-wide load of B's row and 8 broadcasts of A (any ta), 8 FMAs.
 *   gemm_dot  (ta == 0, tb == 1): both operands contiguous along k; each work-item computes a
 *             4 x 4 block of C as 16 float16 dot-product accumulators over k, summed at the end
 *             (pairwise across the 16 lanes), then the k % 16 tail in order.
 *   gemm      (ta == 1, tb == 1 only): the local-memory tiled kernel below.
 * The explicit vectors suit PoCL's CPU device (one work-item is one SIMD loop, small
 * work-groups); measured on PoCL 3.1 / AVX-512 they run 5-30x faster than the tiled kernel
 * and 2-6x faster than CLBlast 1.5 (see bench/bench_opencl.c and the report in cl_gemm.c).
 * Batch: global dimension 2 is item z = (z1, z2) = (z / n2, z % n2); each operand starts at
 * off + z1 s1 + z2 s2. sum1: dimension 2 holds z2 only and the n1 products of each z2 are
 * accumulated into one C (a sum over the batch, in z1 order, into the same accumulators).
 * Accumulation in float; beta == 0 never reads C. Writes =, or += via beta = 1. */

#define GEMM_ARGS                                                                          \
    __global const float *A, int ao, int lda, int ta, int as1, int as2,                    \
    __global const float *B, int bo, int ldb, int tb, int bs1, int bs2,                    \
    __global float *C, int co, int ldc, int cs1, int cs2,                                  \
    int M, int N, int K, int n1, int n2, int sum1, float alpha, float beta

/* C[m, n0 .. n0 + len) = alpha r + beta C (beta 0: C not read). */
static void gemm_store(__global float *c, const float *r, int len, float alpha, float beta)
{
    for (int j = 0; j < len; j++) c[j] = beta == 0.0f ? alpha * r[j] : alpha * r[j] + beta * c[j];
}

#define VN_RM 8 /* rows of C per work-item in gemm_vn */

__kernel void gemm_vn(GEMM_ARGS)
{
    int n0 = get_global_id(0) * 16, m0 = get_global_id(1) * VN_RM, z = get_global_id(2);
    if (n0 >= N || m0 >= M) return;
    int z1 = sum1 ? 0 : z / n2, z2 = sum1 ? z : z % n2, zend = sum1 ? n1 : z1 + 1;
    int sam = ta ? 1 : lda, sak = ta ? lda : 1, full = n0 + 16 <= N;
    int mr[VN_RM];
    for (int i = 0; i < VN_RM; i++) mr[i] = min(m0 + i, M - 1) * sam; /* clamped rows */
    float16 acc[VN_RM];
    for (int i = 0; i < VN_RM; i++) acc[i] = (float16)0.0f;
    for (; z1 < zend; z1++) {
        __global const float *Ab = A + ao + z1 * as1 + z2 * as2;
        __global const float *Bb = B + bo + z1 * bs1 + z2 * bs2 + n0;
        for (int k = 0; k < K; k++) {
            float16 b;
            if (full) {
                b = vload16(0, Bb + k * ldb);
            } else {
                float t[16];
                for (int j = 0; j < 16; j++) t[j] = n0 + j < N ? Bb[k * ldb + j] : 0.0f;
                b = vload16(0, t);
            }
            int ko = k * sak;
            for (int i = 0; i < VN_RM; i++) acc[i] = fma((float16)Ab[mr[i] + ko], b, acc[i]);
        }
    }
    __global float *Cb = C + co + (sum1 ? 0 : (z / n2) * cs1) + z2 * cs2 + n0;
    for (int i = 0; i < VN_RM && m0 + i < M; i++) {
        float r[16];
        vstore16(acc[i], 0, r);
        gemm_store(Cb + (m0 + i) * ldc, r, min(16, N - n0), alpha, beta);
    }
}

static float hsum16(float16 v)
{
    float8 h = v.lo + v.hi;
    float4 q = h.lo + h.hi;
    float2 d = q.lo + q.hi;
    return d.x + d.y;
}

__kernel void gemm_dot(GEMM_ARGS)
{
    int n0 = get_global_id(0) * 4, m0 = get_global_id(1) * 4, z = get_global_id(2);
    if (n0 >= N || m0 >= M) return;
    int z1 = sum1 ? 0 : z / n2, z2 = sum1 ? z : z % n2, zend = sum1 ? n1 : z1 + 1;
    int K16 = K / 16 * 16;
    float s[4][4];
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++) s[i][j] = 0.0f;
    for (; z1 < zend; z1++) {
        __global const float *a[4], *b[4];
        for (int i = 0; i < 4; i++)
            a[i] = A + ao + z1 * as1 + z2 * as2 + min(m0 + i, M - 1) * lda;
        for (int j = 0; j < 4; j++)
            b[j] = B + bo + z1 * bs1 + z2 * bs2 + min(n0 + j, N - 1) * ldb;
        float16 acc[4][4];
        for (int i = 0; i < 4; i++)
            for (int j = 0; j < 4; j++) acc[i][j] = (float16)0.0f;
        for (int k = 0; k < K16; k += 16) {
            float16 av[4], bv[4];
            for (int i = 0; i < 4; i++) av[i] = vload16(0, a[i] + k);
            for (int j = 0; j < 4; j++) bv[j] = vload16(0, b[j] + k);
            for (int i = 0; i < 4; i++)
                for (int j = 0; j < 4; j++) acc[i][j] = fma(av[i], bv[j], acc[i][j]);
        }
        for (int i = 0; i < 4; i++)
            for (int j = 0; j < 4; j++) {
                float t = hsum16(acc[i][j]);
                for (int k = K16; k < K; k++) t += a[i][k] * b[j][k];
                s[i][j] += t;
            }
    }
    __global float *Cb = C + co + (sum1 ? 0 : (z / n2) * cs1) + z2 * cs2 + n0;
    for (int i = 0; i < 4 && m0 + i < M; i++)
        gemm_store(Cb + (m0 + i) * ldc, s[i], min(4, N - n0), alpha, beta);
}

/* ---- the tiled kernel (ta and tb both set) ----------------------------------------------
 * A 16 x 16 work-group computes a 64 x 64 tile of C, each work-item a 4 x 4 block (rows
 * ty + 16 i, columns tx + 16 j); A and B go through local memory in K-slices of 16. */
#define GT 64  /* C tile edge */
#define GK 16  /* K slice */

__kernel __attribute__((reqd_work_group_size(16, 16, 1)))
void gemm(GEMM_ARGS)
{
    __local float As[GK][GT + 1];
    __local float Bs[GK][GT + 1];
    int tx = get_local_id(0), ty = get_local_id(1), lid = ty * 16 + tx;
    int n0 = get_group_id(0) * GT, m0 = get_group_id(1) * GT, z = get_group_id(2);
    int z1 = sum1 ? 0 : z / n2, z2 = sum1 ? z : z % n2, zend = sum1 ? n1 : z1 + 1;
    float acc[4][4];
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 4; j++) acc[i][j] = 0.0f;
    for (; z1 < zend; z1++) {
        __global const float *Ab = A + ao + z1 * as1 + z2 * as2;
        __global const float *Bb = B + bo + z1 * bs1 + z2 * bs2;
        for (int k0 = 0; k0 < K; k0 += GK) {
            for (int e = lid; e < GT * GK; e += 256) {
                int mm = ta ? e % GT : e / GK, kk = ta ? e / GT : e % GK;
                int m = m0 + mm, k = k0 + kk;
                As[kk][mm] = m < M && k < K ? Ab[ta ? k * lda + m : m * lda + k] : 0.0f;
                int nn = tb ? e / GK : e % GT, kb = tb ? e % GK : e / GT;
                int n = n0 + nn, kq = k0 + kb;
                Bs[kb][nn] = n < N && kq < K ? Bb[tb ? n * ldb + kq : kq * ldb + n] : 0.0f;
            }
            barrier(CLK_LOCAL_MEM_FENCE);
            for (int kk = 0; kk < GK; kk++) {
                float a[4], b[4];
                for (int i = 0; i < 4; i++) a[i] = As[kk][ty + 16 * i];
                for (int j = 0; j < 4; j++) b[j] = Bs[kk][tx + 16 * j];
                for (int i = 0; i < 4; i++)
                    for (int j = 0; j < 4; j++) acc[i][j] += a[i] * b[j];
            }
            barrier(CLK_LOCAL_MEM_FENCE);
        }
    }
    __global float *Cb = C + co + (sum1 ? 0 : (z / n2) * cs1) + z2 * cs2;
    for (int i = 0; i < 4; i++) {
        int m = m0 + ty + 16 * i;
        if (m >= M) continue;
        for (int j = 0; j < 4; j++) {
            int n = n0 + tx + 16 * j;
            if (n >= N) continue;
            float v = alpha * acc[i][j];
            Cb[m * ldc + n] = beta == 0.0f ? v : v + beta * Cb[m * ldc + n];
        }
    }
}

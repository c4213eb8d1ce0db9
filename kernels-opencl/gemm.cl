/* gemm.cl - batched single-precision GEMM, row-major, CBLAS semantics:
 * C = alpha op(A) op(B) + beta C, op(A) M x K, op(B) K x N (ta, tb: transposed storage).
 * Tiling: a 16 x 16 work-group computes a 64 x 64 tile of C, each work-item a 4 x 4 block
 * (rows ty + 16 i, columns tx + 16 j, so neighbouring items touch neighbouring columns);
 * A and B go through local memory in K-slices of 16, loaded along their contiguous dimension.
 * Batch: group z of dimension 2 is item (z1, z2) = (z / n2, z % n2); each operand starts at
 * off + z1 s1 + z2 s2. sum1: dimension 2 holds z2 only and the n1 products of each z2 are
 * accumulated into one C (a sum over the batch, in z1 order, one accumulator per element).
 * Accumulation in float along k; beta == 0 never reads C. Writes =, or += via beta = 1. */

#define GT 64  /* C tile edge */
#define GK 16  /* K slice */

__kernel __attribute__((reqd_work_group_size(16, 16, 1)))
void gemm(__global const float *A, int ao, int lda, int ta, int as1, int as2,
          __global const float *B, int bo, int ldb, int tb, int bs1, int bs2,
          __global float *C, int co, int ldc, int cs1, int cs2,
          int M, int N, int K, int n1, int n2, int sum1, float alpha, float beta)
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

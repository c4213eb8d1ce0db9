/* phase.cl — per mosaic phase pooling and scaling (tensor/ops/phase.c): x is k = B C planes of
 * H x W, P = fy fx phases, phase q = i fx + j holds rows i::fy and columns j::fx; s and the
 * means are k x P. Elementwise kernels take CHUNK elements per work-item; the reductions one
 * output per element of their chunk, summed in row-major order (float). */

/* y[o] = inv * sum of plane o / P at phase o % P. Writes = (add 0) or += (add 1); with b (the
 * other factor, may alias nothing) the sum is of a b instead of a. */
__kernel void phase_sum(__global const float *a, int ao, __global const float *b, int bo,
                        int has_b, __global float *y, int yo, int fy, int fx, int H, int W, int n,
                        float inv, int add)
{
    CHUNK_RANGE(o0, o1, n);
    const int P = fy * fx;
    for (int o = o0; o < o1; o++) {
        const int k = o / P, q = o % P, i = q / fx, j = q % fx;
        const long base = (long)k * H * W;
        float s = 0.0f;
        for (int yy = i; yy < H; yy += fy)
            for (int u = j; u < W; u += fx) {
                const long e = base + (long)yy * W + u;
                s += has_b ? a[ao + e] * b[bo + e] : a[ao + e];
            }
        y[yo + o] = add ? y[yo + o] + inv * s : inv * s;
    }
}

/* d[e] (=, add 0, or +=, add 1) k * (a[e] if has_a else 1) * s[plane P + phase of e]. */
__kernel void phase_apply(__global const float *a, int ao, int has_a, __global const float *s,
                          int so, __global float *d, int dof, int fy, int fx, int H, int W, int n,
                          float k, int add)
{
    CHUNK_RANGE(e0, e1, n);
    const int P = fy * fx, hw = H * W;
    for (int e = e0; e < e1; e++) {
        const int plane = e / hw, r = e % hw, yy = r / W, u = r % W;
        const float v = k * s[so + plane * P + (yy % fy) * fx + u % fx] * (has_a ? a[ao + e] : 1.0f);
        d[dof + e] = add ? d[dof + e] + v : v;
    }
}

/* reduce.cl - sums: the reduction of tensor/ops/reduce.c (sum, mean, global average pooling)
 * and the chunked first pass of loss.c's mean. CPU twins accumulate in double; here each
 * work-item accumulates with Kahan compensation and work-groups add up in a fixed tree, so a
 * given device always gives the same result.
 * A reduction is described by two 5-d index spaces over the same input: "kept" (kshp, kst)
 * enumerates the output elements, "reduced" (rshp, rst) the elements summed into each. */

/* y[j] = k * sum_q x[view(j, kept) + view(q, reduced)], q < nr (acc: y[j] += instead); one
 * work-group per output j (global = ny * WG), item l summing the l-th of WG contiguous ranges
 * of q (offsets stepped without divisions, vc_step). Writes = or +=. */
__kernel __attribute__((reqd_work_group_size(WG, 1, 1)))
void reduce_rows_wg(__global const float *x, int xo, int8 kshp, int8 kst, int8 rshp, int8 rst,
                    int nr, __global float *y, int yo, float k, int acc)
{
    __local float scratch[WG];
    int j = get_group_id(0), l = get_local_id(0);
    int base = xo + view_offset(j, kshp, kst);
    float s = 0.0f, c = 0.0f;
    int per = (nr + WG - 1) / WG, q0 = min(nr, l * per), q1 = min(nr, q0 + per);
    if (q0 < q1) {
        int jr, o = vc_start(q0, rshp, rst, &jr);
        for (int q = q0; q < q1; q++, o = vc_step(o, &jr, q, rshp, rst))
            kahan_add(&s, &c, x[base + o]);
    }
    float tot = wg_sum(scratch, s - c);
    if (l == 0) y[yo + j] = acc ? y[yo + j] + k * tot : k * tot;
}

/* Same with one work-item per output (many outputs, short sums). Writes = or +=. */
__kernel void reduce_rows_serial(__global const float *x, int xo, int8 kshp, int8 kst,
                                 int8 rshp, int8 rst, int nr, __global float *y, int yo, int ny,
                                 float k, int acc)
{
    int j = get_global_id(0);
    if (j >= ny) return;
    int base = xo + view_offset(j, kshp, kst);
    float s = 0.0f, c = 0.0f;
    int jr, o = vc_start(0, rshp, rst, &jr);
    for (int q = 0; q < nr; q++, o = vc_step(o, &jr, q, rshp, rst)) kahan_add(&s, &c, x[base + o]);
    y[yo + j] = acc ? y[yo + j] + k * (s - c) : k * (s - c);
}

/* First pass of a long sum over contiguous data: part[g] = sum of f over elements
 * [g chunk, min(n, (g + 1) chunk)); one work-group per chunk. f: kind LM_CL_SUM_PLAIN = p,
 * LM_LOSS_L1 = |p - q|, LM_LOSS_MSE = (p - q)^2. Writes =. */
__kernel __attribute__((reqd_work_group_size(WG, 1, 1)))
void chunk_sums(__global const float *p, int po, __global const float *q, int qo, int n,
                int chunk, int kind, __global float *part, int pto)
{
    __local float scratch[WG];
    int g = get_group_id(0), l = get_local_id(0);
    int e = min(n, (g + 1) * chunk);
    float s = 0.0f, c = 0.0f;
    for (int i = g * chunk + l; i < e; i += WG) {
        float v = p[po + i];
        if (kind == LM_LOSS_L1) v = fabs(v - q[qo + i]);
        else if (kind == LM_LOSS_MSE) {
            float d = v - q[qo + i];
            v = d * d;
        }
        kahan_add(&s, &c, v);
    }
    float tot = wg_sum(scratch, s - c);
    if (l == 0) part[pto + g] = tot;
}

/* Loss backward (loss.c): gd += sign g / n * (L1: sign(p - q); MSE: 2 (p - q)), g = gy[0].
 * Writes +=. */
__kernel void loss_bwd(__global const float *p, int po, __global const float *q, int qo,
                       __global const float *gy, int gyo, __global float *gd, int gdo, int n,
                       int kind, float sign)
{
    int i = get_global_id(0);
    if (i >= n) return;
    float k = sign * gy[gyo] / (float)n;
    float d = p[po + i] - q[qo + i];
    gd[gdo + i] += kind == LM_LOSS_L1 ? k * (float)((d > 0.0f) - (d < 0.0f)) : 2.0f * k * d;
}

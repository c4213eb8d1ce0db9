/* view.cl - fill, flat add and strided copies: the device twins of fill_cpu (tensor/tensor.c)
 * and of contig_fwd_cpu / strided_add_cpu / flat_add_cpu (tensor/ops/view.c).
 * Every tensor argument is a (buffer, element offset) pair; one work-item per CHUNK elements.
 * Strided views are described by shape and strides as in common.cl (view_offset). */

/* y[i] = v, i < n. Writes =. */
__kernel void fill(__global float *y, int yo, int n, float v)
{
    CHUNK_RANGE(i0, i1, n);
    for (int i = i0; i < i1; i++) y[yo + i] = v;
}

/* a[i] += b[i], i < n (both contiguous). Writes +=. */
__kernel void flat_add(__global float *a, int ao, __global const float *b, int bo, int n)
{
    CHUNK_RANGE(i0, i1, n);
    for (int i = i0; i < i1; i++) a[ao + i] += b[bo + i];
}

/* y (contiguous, n elements) = x (strided view shp/st). Writes =. */
__kernel void strided_copy(__global const float *x, int xo, int8 shp, int8 st,
                           __global float *y, int yo, int n)
{
    CHUNK_RANGE(i0, i1, n);
    if (i0 >= n) return;
    int j, o = vc_start(i0, shp, st, &j);
    for (int i = i0; i < i1; i++, o = vc_step(o, &j, i, shp, st)) y[yo + i] = x[xo + o];
}

/* x (strided view shp/st, distinct elements) += g (contiguous, n elements). Writes +=. */
__kernel void strided_add(__global float *x, int xo, int8 shp, int8 st,
                          __global const float *g, int go, int n)
{
    CHUNK_RANGE(i0, i1, n);
    if (i0 >= n) return;
    int j, o = vc_start(i0, shp, st, &j);
    for (int i = i0; i < i1; i++, o = vc_step(o, &j, i, shp, st)) x[xo + o] += g[go + i];
}

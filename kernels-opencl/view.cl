/* view.cl - fill, flat add and strided copies: the device twins of fill_cpu (tensor/tensor.c)
 * and of contig_fwd_cpu / strided_add_cpu / flat_add_cpu (tensor/ops/view.c).
 * Every tensor argument is a (buffer, element offset) pair; one work-item per element.
 * Strided views are described by shape and strides as in common.cl (view_offset). */

/* y[i] = v, i < n. Writes =. */
__kernel void fill(__global float *y, int yo, int n, float v)
{
    int i = get_global_id(0);
    if (i < n) y[yo + i] = v;
}

/* a[i] += b[i], i < n (both contiguous). Writes +=. */
__kernel void flat_add(__global float *a, int ao, __global const float *b, int bo, int n)
{
    int i = get_global_id(0);
    if (i < n) a[ao + i] += b[bo + i];
}

/* y (contiguous, n elements) = x (strided view shp/st). Writes =. */
__kernel void strided_copy(__global const float *x, int xo, int8 shp, int8 st,
                           __global float *y, int yo, int n)
{
    int i = get_global_id(0);
    if (i < n) y[yo + i] = x[xo + view_offset(i, shp, st)];
}

/* x (strided view shp/st, distinct elements) += g (contiguous, n elements). Writes +=. */
__kernel void strided_add(__global float *x, int xo, int8 shp, int8 st,
                          __global const float *g, int go, int n)
{
    int i = get_global_id(0);
    if (i < n) x[xo + view_offset(i, shp, st)] += g[go + i];
}

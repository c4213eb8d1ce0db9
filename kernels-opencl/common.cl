/* common.cl - helpers shared by every kernel file (embedded first, before the other .cl files).
 * Conventions of all kernels: every tensor is a (__global float *, int element offset) pair;
 * 1-d launches are rounded up to the work-group size, so kernels guard their index; sizes
 * and indices are int (the backend refuses tensors beyond 2^31 elements). */

/* Work-group size of the kernels that reduce in local memory (a power of two; the launchers
 * use LM_CL_WG, the same value). */
#define WG 64

/* Element offset of the i-th element (row-major order) of a 5-d view: shape and strides
 * right-aligned into int8 (s0..s4 used; leading dims of shape 1, stride 0). A stride of 0
 * broadcasts that dim. */
int view_offset(int i, int8 shp, int8 st)
{
    int off = 0;
    int r = i % shp.s4;
    off += r * st.s4;
    i /= shp.s4;
    r = i % shp.s3;
    off += r * st.s3;
    i /= shp.s3;
    r = i % shp.s2;
    off += r * st.s2;
    i /= shp.s2;
    r = i % shp.s1;
    off += r * st.s1;
    i /= shp.s1;
    return off + i * st.s0;
}

/* Compensated (Kahan) accumulation: *s + *c holds the running sum. Float-only devices have no
 * double; this keeps long sums close to the CPU's double accumulation. */
void kahan_add(float *s, float *c, float v)
{
    float y = v - *c;
    float t = *s + y;
    *c = (t - *s) - y;
    *s = t;
}

/* Sum of v over the work-group (WG items, local size WG); every item gets the result. */
float wg_sum(__local float *scratch, float v)
{
    int l = get_local_id(0);
    scratch[l] = v;
    barrier(CLK_LOCAL_MEM_FENCE);
    for (int h = WG / 2; h > 0; h >>= 1) {
        if (l < h) scratch[l] += scratch[l + h];
        barrier(CLK_LOCAL_MEM_FENCE);
    }
    float r = scratch[0];
    barrier(CLK_LOCAL_MEM_FENCE);
    return r;
}

/* common.cl - helpers shared by every kernel file (embedded first, before the other .cl files).
 * Conventions of all kernels: every tensor is a (__global float *, int element offset) pair;
 * 1-d launches are rounded up to the work-group size, so kernels guard their index; sizes
 * and indices are int (the backend refuses tensors beyond 2^31 elements). */

/* Defined by the build options (kernels-opencl/cl_backend.c), from the C definitions:
 * WG, the work-group size of the kernels that reduce in local memory (LM_CL_WG, a power of
 * two); CHUNK, the elements per work-item of CHUNK_RANGE (LM_CL_CHUNK); and every enum value
 * a kernel names (LM_OP_ENUMS of tensor/op_params.h, LM_CL_SUM_PLAIN of cl_impl.h). */

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

/* The chunked 1-d kernels: work-item g handles elements [CHUNK g, CHUNK g + CHUNK) of n in
 * one plain loop (PoCL's CPU device pays per work-item; a loop per item runs 10-25x faster than
 * one item per element). Launched with lm_cl_run_chunks; CHUNK is LM_CL_CHUNK (build option). */
#define CHUNK_RANGE(i0, i1, n) int i0 = get_global_id(0) * CHUNK, i1 = min((n), i0 + CHUNK)

/* Offsets of a 5-d view at consecutive indices without divisions: vc_step from the offset
 * of index i - 1 (j: position along the last dim, from vc_start) to index i. */
int vc_start(int i, int8 shp, int8 st, int *j)
{
    *j = i % shp.s4;
    return view_offset(i, shp, st);
}
int vc_step(int off, int *j, int i, int8 shp, int8 st)
{
    if (++*j < shp.s4) return off + st.s4;
    *j = 0;
    return view_offset(i, shp, st);
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

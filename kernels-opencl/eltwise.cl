/* eltwise.cl - elementwise ops: binary with broadcasting (tensor/ops/binary.c), affine
 * (scalar.c), activations (activation.c). One work-item per CHUNK output elements.
 * Broadcast operands: the output's 5-d shape shp and the operand's strides (0 along broadcast
 * dims); flat = 1 when the operand has the output's size (offset = i, no index arithmetic). */

float binary_apply(int op, float a, float b)
{
    switch (op) {
    case LM_BIN_ADD: return a + b;
    case LM_BIN_SUB: return a - b;
    case LM_BIN_MUL: return a * b;
    default: return a / b;
    }
}

/* y (n, contiguous) = a op b. Writes =. */
__kernel void binary_fwd(__global const float *a, int ao, int8 sa, int fa,
                         __global const float *b, int bo, int8 sb, int fb,
                         __global float *y, int yo, int8 shp, int n, int op)
{
    CHUNK_RANGE(i0, i1, n);
    if (i0 >= n) return;
    int ja = 0, jb = 0, oa = fa ? i0 : vc_start(i0, shp, sa, &ja);
    int ob = fb ? i0 : vc_start(i0, shp, sb, &jb);
    for (int i = i0; i < i1; i++) {
        y[yo + i] = binary_apply(op, a[ao + oa], b[bo + ob]);
        oa = fa ? i + 1 : vc_step(oa, &ja, i + 1, shp, sa);
        ob = fb ? i + 1 : vc_step(ob, &jb, i + 1, shp, sb);
    }
}

/* d (n, the output's size) += (or = when !accumulate) d(a op b)/d(operand `which`) * g. */
__kernel void binary_bwd(__global const float *g, int go,
                         __global const float *a, int ao, int8 sa, int fa,
                         __global const float *b, int bo, int8 sb, int fb,
                         __global float *d, int dof, int8 shp, int n, int op, int which,
                         int accumulate)
{
    CHUNK_RANGE(i0, i1, n);
    if (i0 >= n) return;
    int ja = 0, jb = 0, oa = fa ? i0 : vc_start(i0, shp, sa, &ja);
    int ob = fb ? i0 : vc_start(i0, shp, sb, &jb);
    for (int i = i0; i < i1; i++) {
        float gv = g[go + i], av = a[ao + oa], bv = b[bo + ob], r;
        switch (op * 2 + which) {
        case LM_BIN_ADD * 2 + 0: case LM_BIN_ADD * 2 + 1: case LM_BIN_SUB * 2 + 0: r = gv; break;
        case LM_BIN_SUB * 2 + 1: r = -gv; break;
        case LM_BIN_MUL * 2 + 0: r = gv * bv; break;
        case LM_BIN_MUL * 2 + 1: r = gv * av; break;
        case LM_BIN_DIV * 2 + 0: r = gv / bv; break;
        default: r = -gv * av / (bv * bv); break;
        }
        d[dof + i] = accumulate ? d[dof + i] + r : r;
        oa = fa ? i + 1 : vc_step(oa, &ja, i + 1, shp, sa);
        ob = fb ? i + 1 : vc_step(ob, &jb, i + 1, shp, sb);
    }
}

/* d[i] += k * s[i], i < n (contiguous). Writes +=. */
__kernel void scaled_add(__global float *d, int dof, __global const float *s, int so, int n,
                         float k)
{
    CHUNK_RANGE(i0, i1, n);
    for (int i = i0; i < i1; i++) d[dof + i] += k * s[so + i];
}

/* d (n, contiguous, 5-d shape shp) += k * s broadcast (strides st, 0 along broadcast dims).
 * Writes +=. */
__kernel void bcast_add(__global float *d, int dof, __global const float *s, int so, int8 shp,
                        int8 st, int n, float k)
{
    CHUNK_RANGE(i0, i1, n);
    if (i0 >= n) return;
    int j, o = vc_start(i0, shp, st, &j);
    for (int i = i0; i < i1; i++, o = vc_step(o, &j, i, shp, st)) d[dof + i] += k * s[so + o];
}

/* y = s x + t. Writes =. */
__kernel void affine_fwd(__global const float *x, int xo, __global float *y, int yo, int n,
                         float s, float t)
{
    CHUNK_RANGE(i0, i1, n);
    for (int i = i0; i < i1; i++) y[yo + i] = s * x[xo + i] + t;
}

/* Activations; kind: LM_ACT_* (lm_act_kind, tensor/op_params.h); GELU is the exact one. */
float sigmoid_stable(float x)
{
    if (x >= 0.0f) return 1.0f / (1.0f + exp(-x));
    float e = exp(x);
    return e / (1.0f + e);
}

/* y = f(x). Writes =. */
__kernel void activation_fwd(__global const float *x, int xo, __global float *y, int yo, int n,
                             int kind, float slope)
{
    CHUNK_RANGE(i0, i1, n);
    for (int i = i0; i < i1; i++) {
        float v = x[xo + i], r;
        switch (kind) {
        case LM_ACT_RELU: r = v > 0.0f ? v : 0.0f; break;
        case LM_ACT_LEAKY: r = v > 0.0f ? v : slope * v; break;
        case LM_ACT_SIGMOID: r = sigmoid_stable(v); break;
        case LM_ACT_TANH: r = tanh(v); break;
        default: r = 0.5f * v * (1.0f + erf(v * 0.70710678118654752440f)); break;
        }
        y[yo + i] = r;
    }
}

/* gx += f'(x) gy (f' from x, or from y for sigmoid and tanh). Writes +=. */
__kernel void activation_bwd(__global const float *x, int xo, __global const float *y, int yo,
                             __global const float *gy, int gyo, __global float *gx, int gxo,
                             int n, int kind, float slope)
{
    CHUNK_RANGE(i0, i1, n);
    for (int i = i0; i < i1; i++) {
        float v = x[xo + i], yv = y[yo + i], g = gy[gyo + i], r;
        switch (kind) {
        case LM_ACT_RELU: r = v > 0.0f ? g : 0.0f; break;
        case LM_ACT_LEAKY: r = v > 0.0f ? g : slope * g; break;
        case LM_ACT_SIGMOID: r = g * yv * (1.0f - yv); break;
        case LM_ACT_TANH: r = g * (1.0f - yv * yv); break;
        default: {
            float cdf = 0.5f * (1.0f + erf(v * 0.70710678118654752440f));
            r = g * (cdf + v * 0.39894228040143267794f * exp(-0.5f * v * v)); /* 1/sqrt(2 pi) */
        }
        }
        gx[gxo + i] += r;
    }
}

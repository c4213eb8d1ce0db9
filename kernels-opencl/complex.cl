/* complex.cl - complex tensors (last dim 2: re, im): the 2-D DFT (tensor/ops/fft2.c) as a direct
 * sum, polar / abs2 / cmul (complex.c) and the PSF cell sampling (area_sample.c).
 * The DFT is O((H W)^2): exact for the small transforms the device runs here; phases are
 * reduced modulo the size in integers before the float angle, so they stay accurate. */

/* y (B x H x W x 2) = or += scale sum_{n,m} x[n,m] exp(sign 2 pi i (k n / H + l m / W)).
 * One work-item per output element (b, k, l). */
__kernel void fft2_dft(__global const float *x, int xo, __global float *y, int yo, int B, int H,
                       int W, int sign, float scale, int acc)
{
    int g = get_global_id(0);
    if (g >= B * H * W) return;
    int l = g % W, k = (g / W) % H, b = g / (H * W);
    __global const float *xb = x + xo + 2 * (long)b * H * W;
    float sr = 0.0f, si = 0.0f;
    for (int n = 0; n < H; n++) {
        int kn = (k * n) % H;
        for (int m = 0; m < W; m++) {
            int lm = (l * m) % W;
            float ang = (float)sign * 6.283185307179586f * ((float)kn / H + (float)lm / W);
            float c = cos(ang), s = sin(ang);
            float xr = xb[2 * (n * W + m)], xi = xb[2 * (n * W + m) + 1];
            sr += xr * c - xi * s;
            si += xr * s + xi * c;
        }
    }
    __global float *o = y + yo + 2 * g;
    if (acc) {
        o[0] += scale * sr;
        o[1] += scale * si;
    } else {
        o[0] = scale * sr;
        o[1] = scale * si;
    }
}

/* y[2i], y[2i+1] = a[i] (cos p[i], sin p[i]). Writes =. */
__kernel void polar_fwd(__global const float *a, int ao, __global const float *p, int po,
                        __global float *y, int yo, int n)
{
    CHUNK_RANGE(i0, i1, n);
    for (int i = i0; i < i1; i++) {
        float c = cos(p[po + i]), s = sin(p[po + i]);
        y[yo + 2 * i] = a[ao + i] * c;
        y[yo + 2 * i + 1] = a[ao + i] * s;
    }
}

/* ga += gr cos p + gi sin p; gp += a (gi cos p - gr sin p) (has_a / has_p: that gradient). */
__kernel void polar_bwd(__global const float *a, int ao, __global const float *p, int po,
                        __global const float *g, int go, __global float *ga, int gao,
                        __global float *gp, int gpo, int n, int has_a, int has_p)
{
    CHUNK_RANGE(i0, i1, n);
    for (int i = i0; i < i1; i++) {
        float c = cos(p[po + i]), s = sin(p[po + i]);
        float gr = g[go + 2 * i], gi = g[go + 2 * i + 1];
        if (has_a) ga[gao + i] += gr * c + gi * s;
        if (has_p) gp[gpo + i] += a[ao + i] * (gi * c - gr * s);
    }
}

/* y[i] = z[2i]^2 + z[2i+1]^2. Writes =. */
__kernel void abs2_fwd(__global const float *z, int zo, __global float *y, int yo, int n)
{
    CHUNK_RANGE(i0, i1, n);
    for (int i = i0; i < i1; i++) {
        float r = z[zo + 2 * i], m = z[zo + 2 * i + 1];
        y[yo + i] = r * r + m * m;
    }
}

/* gz += 2 z gy. */
__kernel void abs2_bwd(__global const float *z, int zo, __global const float *g, int go,
                       __global float *gz, int gzo, int n)
{
    CHUNK_RANGE(i0, i1, n);
    for (int i = i0; i < i1; i++) {
        gz[gzo + 2 * i] += 2.0f * z[zo + 2 * i] * g[go + i];
        gz[gzo + 2 * i + 1] += 2.0f * z[zo + 2 * i + 1] * g[go + i];
    }
}

/* y[i] = a[i] b[i % nb] (complex, na elements). Writes =. */
__kernel void cmul_fwd(__global const float *a, int ao, __global const float *b, int bo,
                       __global float *y, int yo, int na, int nb)
{
    CHUNK_RANGE(i0, i1, na);
    for (int i = i0; i < i1; i++) {
        int j = i % nb;
        float ar = a[ao + 2 * i], ai = a[ao + 2 * i + 1], br = b[bo + 2 * j], bi = b[bo + 2 * j + 1];
        y[yo + 2 * i] = ar * br - ai * bi;
        y[yo + 2 * i + 1] = ar * bi + ai * br;
    }
}

/* ga[i] += g[i] conj(b[i % nb]) (na elements). */
__kernel void cmul_bwd_a(__global const float *b, int bo, __global const float *g, int go,
                         __global float *d, int dof, int na, int nb)
{
    CHUNK_RANGE(i0, i1, na);
    for (int i = i0; i < i1; i++) {
        int j = i % nb;
        float gr = g[go + 2 * i], gi = g[go + 2 * i + 1], br = b[bo + 2 * j], bi = b[bo + 2 * j + 1];
        d[dof + 2 * i] += gr * br + gi * bi;
        d[dof + 2 * i + 1] += gi * br - gr * bi;
    }
}

/* gb[j] += sum_r g[j + r nb] conj(a[j + r nb]) (one work-item per j of nb). */
__kernel void cmul_bwd_b(__global const float *a, int ao, __global const float *g, int go,
                         __global float *d, int dof, int na, int nb)
{
    int j = get_global_id(0);
    if (j >= nb) return;
    float sr = 0.0f, si = 0.0f;
    for (int i = j; i < na; i += nb) {
        float gr = g[go + 2 * i], gi = g[go + 2 * i + 1], ar = a[ao + 2 * i], ai = a[ao + 2 * i + 1];
        sr += gr * ar + gi * ai;
        si += gi * ar - gr * ai;
    }
    d[dof + 2 * j] += sr;
    d[dof + 2 * j + 1] += si;
}

/* The taps of cell (i, j) of image b (see area_sample.c): index and weight into idx / wt. */
#define AREA_LOOP(BODY)                                                                       \
    int lo = -(N / 2), hi = N - N / 2 - 1;                                                    \
    for (int a = 0; a < K; a++) {                                                             \
        float u = r * ((float)(i - S / 2) + ((float)a + 0.5f) / K - 0.5f);                    \
        int y0 = (int)floor(u);                                                               \
        if (y0 < lo || y0 + 1 > hi) continue;                                                 \
        float ty = u - (float)y0;                                                             \
        int ya = (y0 + N) % N, yb = (y0 + 1 + N) % N;                                         \
        for (int bb = 0; bb < K; bb++) {                                                      \
            float v = r * ((float)(j - S / 2) + ((float)bb + 0.5f) / K - 0.5f);               \
            int x0 = (int)floor(v);                                                           \
            if (x0 < lo || x0 + 1 > hi) continue;                                             \
            float tx = v - (float)x0;                                                         \
            int xa = (x0 + N) % N, xb = (x0 + 1 + N) % N;                                     \
            BODY(ya * N + xa, (1.0f - ty) * (1.0f - tx));                                     \
            BODY(ya * N + xb, (1.0f - ty) * tx);                                              \
            BODY(yb * N + xa, ty * (1.0f - tx));                                              \
            BODY(yb * N + xb, ty * tx);                                                       \
        }                                                                                     \
    }

/* y (B x S x S) = cell sums of x (B x N x N); ratio[b] per image. One work-item per cell. */
__kernel void area_sample_fwd(__global const float *x, int xo, __global float *y, int yo,
                              __global const float *ratio, int ro, int B, int N, int S, int K)
{
    int g = get_global_id(0);
    if (g >= B * S * S) return;
    int j = g % S, i = (g / S) % S, b = g / (S * S);
    float r = ratio[ro + b], acc = 0.0f;
    __global const float *src = x + xo + (long)b * N * N;
#define AREA_ACC(k, w) acc += (w) * src[k]
    AREA_LOOP(AREA_ACC)
#undef AREA_ACC
    y[yo + g] = acc;
}

/* gx (B x N x N) += the transpose applied to gy: one work-item per image (cells share taps). */
__kernel void area_sample_bwd(__global const float *gy, int gyo, __global float *gx, int gxo,
                              __global const float *ratio, int ro, int B, int N, int S, int K)
{
    int b = get_global_id(0);
    if (b >= B) return;
    float r = ratio[ro + b];
    __global float *gb = gx + gxo + (long)b * N * N;
    for (int i = 0; i < S; i++)
        for (int j = 0; j < S; j++) {
            float g = gy[gyo + (b * S + i) * S + j];
#define AREA_SCATTER(k, w) gb[k] += (w) * g
            AREA_LOOP(AREA_SCATTER)
#undef AREA_SCATTER
        }
}

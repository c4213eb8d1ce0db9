/* move.cl - data movement: the general two-view copy used by permute, pixel (un)shuffle,
 * concat and split (tensor/ops/permute.c, shuffle.c, concat.c), zero/reflect padding (pad.c),
 * bilinear resize (resize.c) and the phase-aware mosaic upsampling (mosaic_upsample.c).
 * Backward passes that the CPU writes as scatters with collisions (pad reflect, resize, mosaic)
 * are gathers here: one work-item per input-gradient element walks, in the CPU's order, the
 * output positions that read it, so no atomics are needed and each element is written once. */

/* d[view(i, shp, dst)] = (or += when add) s[view(i, shp, sst)], i < n: both sides strided views
 * of one 5-d shape. Writes = or +=. */
__kernel void view_copy(__global const float *s, int so, int8 sst, __global float *d, int dof,
                        int8 dst, int8 shp, int n, int add)
{
    CHUNK_RANGE(i0, i1, n);
    if (i0 >= n) return;
    int js, jd, os = vc_start(i0, shp, sst, &js), od = vc_start(i0, shp, dst, &jd);
    for (int i = i0; i < i1; i++) {
        float v = s[so + os];
        d[dof + od] = add ? d[dof + od] + v : v;
        os = vc_step(os, &js, i + 1, shp, sst);
        od = vc_step(od, &jd, i + 1, shp, dst);
    }
}

/* ---- pad ----------------------------------------------------------------------------------- */
/* Source index of output position o (n inputs, lo before); -1 = zero. mode: lm_pad_mode. */
int pad_src(int o, int n, int lo, int mode)
{
    int i = o - lo;
    if (mode == LM_PAD_REFLECT) {
        if (i < 0) i = -i;
        if (i >= n) i = 2 * (n - 1) - i;
        return i;
    }
    return i < 0 || i >= n ? -1 : i;
}

/* y (planes x Ho x Wo) = padded x (planes x H x W); one item per output. Writes =. */
__kernel void pad_fwd(__global const float *x, int xo, __global float *y, int yo, int H, int W,
                      int Ho, int Wo, int top, int left, int mode, int n)
{
    int i = get_global_id(0);
    if (i >= n) return;
    int X = i % Wo, Y = (i / Wo) % Ho, pl = i / (Wo * Ho);
    int iy = pad_src(Y, H, top, mode), ix = pad_src(X, W, left, mode);
    y[yo + i] = iy < 0 || ix < 0 ? 0.0f : x[xo + (pl * H + iy) * W + ix];
}

/* Output positions (ascending, at most 3) whose source is input position i. */
int pad_readers(int i, int n, int lo, int hi, int mode, int *o)
{
    int k = 0;
    if (mode == LM_PAD_REFLECT && i > 0 && i <= lo) o[k++] = lo - i; /* reflected before the start */
    o[k++] = lo + i;                                         /* itself */
    int r = 2 * (n - 1) - i;                                 /* reflected after the end */
    if (mode == LM_PAD_REFLECT && r >= n && r < n + hi) o[k++] = lo + r;
    return k;
}

/* gx (planes x H x W) += gy gathered through the pad tables, in the CPU's (Y, X) order.
 * One item per input. Writes +=. */
__kernel void pad_bwd(__global float *gx, int gxo, __global const float *gy, int gyo, int H,
                      int W, int Ho, int Wo, int top, int bottom, int left, int right, int mode,
                      int n)
{
    int i = get_global_id(0);
    if (i >= n) return;
    int ix = i % W, iy = (i / W) % H, pl = i / (W * H);
    int ys[3], xs[3];
    int ny = pad_readers(iy, H, top, bottom, mode, ys);
    int nx = pad_readers(ix, W, left, right, mode, xs);
    float v = gx[gxo + i];
    for (int a = 0; a < ny; a++)
        for (int b = 0; b < nx; b++) v += gy[gyo + (pl * Ho + ys[a]) * Wo + xs[b]];
    gx[gxo + i] = v;
}

/* ---- bilinear resize ----------------------------------------------------------------------- */
/* First source index of output position o (as resize.c's axis_table: same float steps) and
 * the weight *l of the second; scale is computed by the host exactly as the CPU does. */
int resize_src(int o, int in, float scale, int ac, float *l)
{
    float s = ac ? scale * (float)o : scale * ((float)o + 0.5f) - 0.5f;
    if (s < 0.0f) s = 0.0f;
    int i = (int)s;
    if (i > in - 1) i = in - 1;
    float w = s - (float)i;
    *l = w < 0.0f ? 0.0f : (w > 1.0f ? 1.0f : w);
    return i;
}

/* First output position o in [0, out) with resize_src(o) >= target (out if none); the
 * table is monotone in o. */
int resize_lower_bound(int target, int in, int out, float scale, int ac)
{
    int lo = 0, hi = out;
    float l;
    while (lo < hi) {
        int mid = (lo + hi) / 2;
        if (resize_src(mid, in, scale, ac, &l) < target) lo = mid + 1;
        else hi = mid;
    }
    return lo;
}

/* y (planes x oh x ow) = bilinear x (planes x H x W). Writes =. */
__kernel void resize_fwd(__global const float *x, int xo, __global float *y, int yo, int H,
                         int W, int oh, int ow, float sy, float sx, int ac, int n)
{
    int i = get_global_id(0);
    if (i >= n) return;
    int X = i % ow, Y = (i / ow) % oh, pl = i / (ow * oh);
    float ly, lx;
    int y0 = resize_src(Y, H, sy, ac, &ly), x0 = resize_src(X, W, sx, ac, &lx);
    int y1 = y0 < H - 1 ? y0 + 1 : y0, x1 = x0 < W - 1 ? x0 + 1 : x0;
    __global const float *p = x + xo + pl * H * W;
    float hy = 1.0f - ly, hx = 1.0f - lx;
    y[yo + i] = hy * (hx * p[y0 * W + x0] + lx * p[y0 * W + x1]) +
                ly * (hx * p[y1 * W + x0] + lx * p[y1 * W + x1]);
}

/* Backward step 1: tmp (rows x W, rows = planes oh) = each gradient row scattered along x,
 * gathered per input column i over the outputs that read it. Writes =. */
__kernel void resize_bwd_rows(__global const float *gy, int gyo, __global float *tmp, int to,
                              int W, int ow, float sx, int ac, int n)
{
    int k = get_global_id(0);
    if (k >= n) return;
    int i = k % W, r = k / W;
    int X0 = resize_lower_bound(i - 1, W, ow, sx, ac), X1 = resize_lower_bound(i + 1, W, ow, sx, ac);
    __global const float *g = gy + gyo + r * ow;
    float s = 0.0f, l;
    for (int X = X0; X < X1; X++) {
        int a = resize_src(X, W, sx, ac, &l), b = a < W - 1 ? a + 1 : a;
        if (a == i) s += (1.0f - l) * g[X];
        if (b == i) s += l * g[X];
    }
    tmp[to + k] = s;
}

/* Backward step 2: gx (planes x H x W) += tmp rows gathered along y. Writes +=. */
__kernel void resize_bwd_cols(__global float *gx, int gxo, __global const float *tmp, int to,
                              int H, int W, int oh, float sy, int ac, int n)
{
    int k = get_global_id(0);
    if (k >= n) return;
    int xx = k % W, i = (k / W) % H, pl = k / (W * H);
    int Y0 = resize_lower_bound(i - 1, H, oh, sy, ac), Y1 = resize_lower_bound(i + 1, H, oh, sy, ac);
    float v = gx[gxo + k], l;
    for (int Y = Y0; Y < Y1; Y++) {
        int a = resize_src(Y, H, sy, ac, &l), b = a < H - 1 ? a + 1 : a;
        float t = tmp[to + (pl * oh + Y) * W + xx];
        if (a == i) v += (1.0f - l) * t;
        if (b == i) v += l * t;
    }
    gx[gxo + k] = v;
}

/* ---- mosaic upsampling --------------------------------------------------------------------- */
/* Sample pair and weight of position Y (n positions, period t, phase p): integer steps as
 * mosaic_upsample.c's axis_fill. Returns v0; *v1, *l. */
int mosaic_src(int Y, int n, int t, int p, int *v1, float *l)
{
    int ns = n / t, last = t * (ns - 1);
    int d = clamp(Y - p, 0, last);
    int v = d / t;
    *v1 = v + 1 < ns ? v + 1 : ns - 1;
    *l = (float)(d - v * t) / (float)t;
    return v;
}

/* Positions [*lo, *hi) reading sample v as first (which = 0) or second (which = 1) sample. */
void mosaic_range(int v, int n, int t, int p, int which, int *lo, int *hi)
{
    int ns = n / t;
    if (which == 1) {
        if (v == 0) {
            *lo = 0;
            *hi = ns == 1 ? n : 0;
            return;
        }
        *lo = v - 1 == 0 ? 0 : p + (v - 1) * t;
        *hi = v == ns - 1 ? n : p + v * t;
        return;
    }
    *lo = v == 0 ? 0 : p + v * t;
    *hi = v == ns - 1 ? n : p + v * t + t;
}

/* y (B x nch x H x W) = per channel k, bilinear samples of phase (py[k], px[k]) of raw
 * (B x 1 x H x W); ph = py[0..nch) then px[0..nch) (ints). Writes =. */
__kernel void mosaic_fwd(__global const float *raw, int ro, __global float *y, int yo,
                         __global const int *ph, int pho, int nch, int H, int W, int ty, int tx,
                         int n)
{
    int i = get_global_id(0);
    if (i >= n) return;
    int X = i % W, Y = (i / W) % H, k = (i / (W * H)) % nch, b = i / (W * H * nch);
    int py = ph[pho + k], px = ph[pho + nch + k], v1, u1;
    float ly, lx;
    int v0 = mosaic_src(Y, H, ty, py, &v1, &ly), u0 = mosaic_src(X, W, tx, px, &u1, &lx);
    __global const float *r = raw + ro + b * H * W + px;
    __global const float *s0 = r + (ty * v0 + py) * W, *s1 = r + (ty * v1 + py) * W;
    int a = tx * u0, e = tx * u1;
    float hy = 1.0f - ly, hx = 1.0f - lx;
    y[yo + i] = hy * (hx * s0[a] + lx * s0[e]) + ly * (hx * s1[a] + lx * s1[e]);
}

/* Column step of the backward for one gradient row g: sum over the positions reading sample
 * u of the column weight times g (as mosaic_bwd_row). */
float mosaic_row_sum(__global const float *g, int u, int W, int tx, int px)
{
    int lo, hi, v1;
    float s = 0.0f, l;
    mosaic_range(u, W, tx, px, 0, &lo, &hi);
    for (int X = lo; X < hi; X++) {
        mosaic_src(X, W, tx, px, &v1, &l);
        s += (1.0f - l) * g[X];
    }
    mosaic_range(u, W, tx, px, 1, &lo, &hi);
    for (int X = lo; X < hi; X++) {
        mosaic_src(X, W, tx, px, &v1, &l);
        s += l * g[X];
    }
    return s;
}

/* graw (B x 1 x H x W) += gradient of every channel whose phase owns the pixel, gathered in
 * the CPU's order (channels ascending; rows reading the sample as first, then as second).
 * One item per raw pixel. Writes +=. */
__kernel void mosaic_bwd(__global float *graw, int go, __global const float *gy, int gyo,
                         __global const int *ph, int pho, int nch, int H, int W, int ty, int tx,
                         int n)
{
    int i = get_global_id(0);
    if (i >= n) return;
    int C = i % W, R = (i / W) % H, b = i / (W * H);
    float v = graw[go + i];
    for (int k = 0; k < nch; k++) {
        int py = ph[pho + k], px = ph[pho + nch + k];
        if (R % ty != py || C % tx != px) continue;
        int sv = (R - py) / ty, su = (C - px) / tx;
        __global const float *gk = gy + gyo + (b * nch + k) * H * W;
        for (int which = 0; which < 2; which++) {
            int lo, hi, v1;
            float l;
            mosaic_range(sv, H, ty, py, which, &lo, &hi);
            for (int Y = lo; Y < hi; Y++) {
                mosaic_src(Y, H, ty, py, &v1, &l);
                float wy = which ? l : 1.0f - l;
                v += wy * mosaic_row_sum(gk + Y * W, su, W, tx, px);
            }
        }
    }
    graw[go + i] = v;
}

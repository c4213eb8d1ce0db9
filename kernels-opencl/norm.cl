/* norm.cl - softmax (tensor/ops/softmax.c), layer norm over channels (layer_norm.c) and L2
 * normalisation (l2_normalize.c). The tensor is seen as outer x len x inner around the axis;
 * one work-item per column (outer, inner) walks the len entries (stride inner), so
 * neighbouring work-items read neighbouring memory. */

/* y = softmax over len, max-subtracted. ncols = outer * inner. Writes =. */
__kernel void softmax_fwd(__global const float *x, int xo, __global float *y, int yo, int len,
                          int inner, int ncols)
{
    int col = get_global_id(0);
    if (col >= ncols) return;
    int base = (col / inner) * len * inner + col % inner;
    __global const float *xp = x + xo + base;
    __global float *yp = y + yo + base;
    float m = xp[0];
    for (int l = 1; l < len; l++) m = fmax(m, xp[l * inner]);
    float s = 0.0f, c = 0.0f;
    for (int l = 0; l < len; l++) {
        float e = exp(xp[l * inner] - m);
        yp[l * inner] = e;
        kahan_add(&s, &c, e);
    }
    float inv = 1.0f / (s - c);
    for (int l = 0; l < len; l++) yp[l * inner] *= inv;
}

/* gx += y (gy - sum_len(gy y)). Writes +=. */
__kernel void softmax_bwd(__global const float *y, int yo, __global const float *gy, int gyo,
                          __global float *gx, int gxo, int len, int inner, int ncols)
{
    int col = get_global_id(0);
    if (col >= ncols) return;
    int base = (col / inner) * len * inner + col % inner;
    __global const float *yp = y + yo + base, *gp = gy + gyo + base;
    __global float *gxp = gx + gxo + base;
    float s = 0.0f, c = 0.0f;
    for (int l = 0; l < len; l++) kahan_add(&s, &c, gp[l * inner] * yp[l * inner]);
    float dot = s - c;
    for (int l = 0; l < len; l++) gxp[l * inner] += yp[l * inner] * (gp[l * inner] - dot);
}

/* Layer norm over the C channels of each pixel of B x C x HW; one work-item per pixel
 * (npix = B HW). y = (x - mean) rstd w + b; st (B x 2 x HW) = mean plane, rstd plane.
 * Float accumulation in channel order, as the CPU twin. Writes =. */
__kernel void ln_fwd(__global const float *x, int xo, __global float *y, int yo,
                     __global float *st, int sto, __global const float *w, int wo,
                     __global const float *b, int bo, int C, int HW, int npix, float eps,
                     int has_w, int has_b)
{
    int pix = get_global_id(0);
    if (pix >= npix) return;
    int bi = pix / HW, q = pix % HW, base = bi * C * HW + q;
    float mean = 0.0f, var = 0.0f;
    for (int ch = 0; ch < C; ch++) mean += x[xo + base + ch * HW];
    mean /= (float)C;
    for (int ch = 0; ch < C; ch++) {
        float d = x[xo + base + ch * HW] - mean;
        var += d * d;
    }
    float rstd = 1.0f / sqrt(var / (float)C + eps);
    st[sto + bi * 2 * HW + q] = mean;
    st[sto + bi * 2 * HW + HW + q] = rstd;
    for (int ch = 0; ch < C; ch++) {
        float wc = has_w ? w[wo + ch] : 1.0f, bc = has_b ? b[bo + ch] : 0.0f;
        y[yo + base + ch * HW] = (x[xo + base + ch * HW] - mean) * rstd * wc + bc;
    }
}

/* gx += rstd (d - mean_c(d) - xhat mean_c(d xhat)), d = gy w. Writes +=. */
__kernel void ln_bwd_x(__global float *gx, int gxo, __global const float *gy, int gyo,
                       __global const float *x, int xo, __global const float *st, int sto,
                       __global const float *w, int wo, int C, int HW, int npix, int has_w)
{
    int pix = get_global_id(0);
    if (pix >= npix) return;
    int bi = pix / HW, q = pix % HW, base = bi * C * HW + q;
    float mean = st[sto + bi * 2 * HW + q], rstd = st[sto + bi * 2 * HW + HW + q];
    float sd = 0.0f, sdx = 0.0f;
    for (int ch = 0; ch < C; ch++) {
        float d = gy[gyo + base + ch * HW] * (has_w ? w[wo + ch] : 1.0f);
        sd += d;
        sdx += d * (x[xo + base + ch * HW] - mean) * rstd;
    }
    sd /= (float)C;
    sdx /= (float)C;
    for (int ch = 0; ch < C; ch++) {
        float xh = (x[xo + base + ch * HW] - mean) * rstd;
        float d = gy[gyo + base + ch * HW] * (has_w ? w[wo + ch] : 1.0f);
        gx[gxo + base + ch * HW] += rstd * (d - sd - xh * sdx);
    }
}

/* gw[ch] += sum gy xhat, gb[ch] += sum gy over B x HW; one work-group per channel.
 * Writes +=. */
__kernel __attribute__((reqd_work_group_size(WG, 1, 1)))
void ln_bwd_wb(__global float *gw, int gwo, __global float *gb, int gbo,
               __global const float *gy, int gyo, __global const float *x, int xo,
               __global const float *st, int sto, int B, int C, int HW, int has_gw, int has_gb)
{
    __local float scratch[WG];
    int ch = get_group_id(0), l = get_local_id(0);
    float sw = 0.0f, cw = 0.0f, sb = 0.0f, cb = 0.0f;
    for (int e = l; e < B * HW; e += WG) {
        int bi = e / HW, q = e % HW, k = (bi * C + ch) * HW + q;
        float mean = st[sto + bi * 2 * HW + q], rstd = st[sto + bi * 2 * HW + HW + q];
        float g = gy[gyo + k];
        kahan_add(&sw, &cw, g * ((x[xo + k] - mean) * rstd));
        kahan_add(&sb, &cb, g);
    }
    float tw = wg_sum(scratch, sw - cw);
    float tb = wg_sum(scratch, sb - cb);
    if (l == 0 && has_gw) gw[gwo + ch] += tw;
    if (l == 0 && has_gb) gb[gbo + ch] += tb;
}

/* y = x / max(||x||, eps) over len. Writes =. */
__kernel void l2_fwd(__global const float *x, int xo, __global float *y, int yo, int len,
                     int inner, int ncols, float eps)
{
    int col = get_global_id(0);
    if (col >= ncols) return;
    int base = (col / inner) * len * inner + col % inner;
    float s = 0.0f, c = 0.0f;
    for (int l = 0; l < len; l++) {
        float v = x[xo + base + l * inner];
        kahan_add(&s, &c, v * v);
    }
    float n = sqrt(s - c);
    float den = n > eps ? n : eps;
    for (int l = 0; l < len; l++) y[yo + base + l * inner] = x[xo + base + l * inner] / den;
}

/* n >= eps: gx += g / n - x (x.g) / n^3; else gx += g / eps. Writes +=. */
__kernel void l2_bwd(__global float *gx, int gxo, __global const float *gy, int gyo,
                     __global const float *x, int xo, int len, int inner, int ncols, float eps)
{
    int col = get_global_id(0);
    if (col >= ncols) return;
    int base = (col / inner) * len * inner + col % inner;
    float s = 0.0f, c = 0.0f, d = 0.0f, cd = 0.0f;
    for (int l = 0; l < len; l++) {
        float v = x[xo + base + l * inner];
        kahan_add(&s, &c, v * v);
        kahan_add(&d, &cd, v * gy[gyo + base + l * inner]);
    }
    float n = sqrt(s - c), dot = d - cd;
    int pass = n >= eps && n > 0.0f;
    float a1 = 1.0f / (pass ? n : eps), a3 = pass ? dot / (n * n * n) : 0.0f;
    for (int l = 0; l < len; l++) {
        int k = base + l * inner;
        gx[gxo + k] += a1 * gy[gyo + k] - a3 * x[xo + k];
    }
}

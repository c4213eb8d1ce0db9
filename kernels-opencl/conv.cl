/* conv.cl - convolution helpers: im2col and a gathering col2im for conv2d /
 * conv_transpose2d (tensor/ops/conv2d.c, conv_transpose2d.c; the products run in gemm.cl),
 * and direct conv3d kernels (conv3d.c: stride 1, tiny channel counts).
 * conv2d geometry: int16 in lm_conv_geom order (tensor/ops/gemm_internal.h):
 *   B Cin H W Cout Ho Wo kh kw sh sw ph pw dh dw groups. */
#define CG_B g.s0
#define CG_CIN g.s1
#define CG_H g.s2
#define CG_W g.s3
#define CG_COUT g.s4
#define CG_HO g.s5
#define CG_WO g.s6
#define CG_KH g.s7
#define CG_KW g.s8
#define CG_SH g.s9
#define CG_SW g.sa
#define CG_PH g.sb
#define CG_PW g.sc
#define CG_DH g.sd
#define CG_DW g.se
#define CG_G g.sf

/* col ([img][group][K][P], K = Cin/groups kh kw) = patches of images b0.. for output
 * columns p0 .. p0 + P (zero outside the input). Work-item (s, r): row r of the nimg groups K
 * rows, columns [64 s, 64 s + 64) of the chunk, walked with an incremental (oy, ox) so the
 * loop has no divisions (PoCL runs one simple loop per work-item well). Writes =. */
#define IM2COL_SEG 64
__kernel void im2col(__global const float *x, int xo, __global float *col, int co, int16 g,
                     int b0, int p0, int P, int n)
{
    int s = get_global_id(0), r = get_global_id(1);
    int cig = CG_CIN / CG_G, kk = CG_KH * CG_KW, K = cig * kk;
    if (r >= n / P || s * IM2COL_SEG >= P) return;
    int k = r % K, q = (r / K) % CG_G, im = r / (K * CG_G);
    int ci = k / kk, ki = (k % kk) / CG_KW, kj = k % CG_KW;
    __global const float *xc = x + xo + ((b0 + im) * CG_CIN + q * cig + ci) * CG_H * CG_W;
    __global float *out = col + co + (long)r * P;
    int pp = s * IM2COL_SEG, pend = min(P, pp + IM2COL_SEG);
    int oy = (p0 + pp) / CG_WO, ox = (p0 + pp) % CG_WO;
    int iy = oy * CG_SH - CG_PH + ki * CG_DH, dx = kj * CG_DW - CG_PW;
    for (; pp < pend; pp++) {
        int ix = ox * CG_SW + dx;
        out[pp] = iy >= 0 && iy < CG_H && ix >= 0 && ix < CG_W ? xc[iy * CG_W + ix] : 0.0f;
        if (++ox == CG_WO) {
            ox = 0;
            iy += CG_SH;
        }
    }
}

/* dx (images b0 .. b0 + nimg) += col2im(dcol) for output columns [p0, p0 + P): each input
 * pixel gathers the patch entries that read it, taps in (ki, kj) order. Work-item (s, r):
 * input row r = (img, c, iy), pixels [64 s, 64 s + 64) of it, accumulated in a private
 * array tap by tap (the tap tests hoisted out of the pixel loop). Writes +=. */
__kernel void col2im_gather(__global const float *dcol, int dco, __global float *dx, int dxo,
                            int16 g, int b0, int p0, int P, int n)
{
    int s = get_global_id(0), r = get_global_id(1);
    if (r >= n / CG_W || s * IM2COL_SEG >= CG_W) return;
    int cig = CG_CIN / CG_G, kk = CG_KH * CG_KW, K = cig * kk;
    int iy = r % CG_H, c = (r / CG_H) % CG_CIN, im = r / (CG_H * CG_CIN);
    int q = c / cig, ci = c % cig, x0 = s * IM2COL_SEG, len = min(CG_W - x0, IM2COL_SEG);
    __global float *d = dx + dxo + ((b0 + im) * CG_CIN + c) * CG_H * CG_W + iy * CG_W + x0;
    float v[IM2COL_SEG];
    for (int j = 0; j < len; j++) v[j] = d[j];
    for (int ki = 0; ki < CG_KH; ki++) {
        int ty = iy + CG_PH - ki * CG_DH;
        if (ty < 0 || ty % CG_SH || ty / CG_SH >= CG_HO) continue;
        int prow = (ty / CG_SH) * CG_WO - p0;
        for (int kj = 0; kj < CG_KW; kj++) {
            __global const float *src =
                dcol + dco + (long)((im * CG_G + q) * K + ci * kk + ki * CG_KW + kj) * P;
            for (int j = 0; j < len; j++) {
                int tx = x0 + j + CG_PW - kj * CG_DW;
                if (tx < 0 || tx % CG_SW) continue;
                int ox = tx / CG_SW, p = prow + ox;
                if (ox < CG_WO && p >= 0 && p < P) v[j] += src[p];
            }
        }
    }
    for (int j = 0; j < len; j++) d[j] = v[j];
}

/* ---- conv3d (stride 1); geometry int16 in conv3d_params order:
 * B Cin D H W Cout Do Ho Wo kd kh kw pd ph pw has_bias ---------------------------------- */
#define C3_B g.s0
#define C3_CIN g.s1
#define C3_D g.s2
#define C3_H g.s3
#define C3_W g.s4
#define C3_COUT g.s5
#define C3_DO g.s6
#define C3_HO g.s7
#define C3_WO g.s8
#define C3_KD g.s9
#define C3_KH g.sa
#define C3_KW g.sb
#define C3_PD g.sc
#define C3_PH g.sd
#define C3_PW g.se
#define C3_HAS_BIAS g.sf

/* y = bias + conv3d(x, w); taps in (ci, kz, ky, kx) order. One item per output. Writes =. */
__kernel void conv3d_fwd(__global const float *x, int xo, __global const float *w, int wo,
                         __global float *y, int yo, __global const float *bias, int bo,
                         int16 g, int n)
{
    int i = get_global_id(0);
    if (i >= n) return;
    int ox = i % C3_WO, oy = (i / C3_WO) % C3_HO, oz = (i / (C3_WO * C3_HO)) % C3_DO;
    int co = (i / (C3_WO * C3_HO * C3_DO)) % C3_COUT, b = i / (C3_WO * C3_HO * C3_DO * C3_COUT);
    float s = C3_HAS_BIAS ? bias[bo + co] : 0.0f;
    for (int ci = 0; ci < C3_CIN; ci++)
        for (int kz = 0; kz < C3_KD; kz++) {
            int iz = oz + kz - C3_PD;
            if (iz < 0 || iz >= C3_D) continue;
            for (int ky = 0; ky < C3_KH; ky++) {
                int iy = oy + ky - C3_PH;
                if (iy < 0 || iy >= C3_H) continue;
                __global const float *xr = x + xo + (((b * C3_CIN + ci) * C3_D + iz) * C3_H + iy) * C3_W;
                __global const float *wr = w + wo + (((co * C3_CIN + ci) * C3_KD + kz) * C3_KH + ky) * C3_KW;
                for (int kx = 0; kx < C3_KW; kx++) {
                    int ix = ox + kx - C3_PW;
                    if (ix >= 0 && ix < C3_W) s += wr[kx] * xr[ix];
                }
            }
        }
    y[yo + i] = s;
}

/* dx += sum over (co, taps) of w * dy at the output reading this input; taps in the CPU's
 * flipped order. One item per input. Writes +=. */
__kernel void conv3d_bwd_x(__global const float *dy, int dyo, __global const float *w, int wo,
                           __global float *dx, int dxo, int16 g, int n)
{
    int i = get_global_id(0);
    if (i >= n) return;
    int ix = i % C3_W, iy = (i / C3_W) % C3_H, iz = (i / (C3_W * C3_H)) % C3_D;
    int ci = (i / (C3_W * C3_H * C3_D)) % C3_CIN, b = i / (C3_W * C3_H * C3_D * C3_CIN);
    float v = dx[dxo + i];
    for (int co = 0; co < C3_COUT; co++)
        for (int kz = C3_KD - 1; kz >= 0; kz--) {
            int oz = iz - kz + C3_PD;
            if (oz < 0 || oz >= C3_DO) continue;
            for (int ky = C3_KH - 1; ky >= 0; ky--) {
                int oy = iy - ky + C3_PH;
                if (oy < 0 || oy >= C3_HO) continue;
                __global const float *dr = dy + dyo + (((b * C3_COUT + co) * C3_DO + oz) * C3_HO + oy) * C3_WO;
                __global const float *wr = w + wo + (((co * C3_CIN + ci) * C3_KD + kz) * C3_KH + ky) * C3_KW;
                for (int kx = C3_KW - 1; kx >= 0; kx--) {
                    int ox = ix - kx + C3_PW;
                    if (ox >= 0 && ox < C3_WO) v += wr[kx] * dr[ox];
                }
            }
        }
    dx[dxo + i] = v;
}

/* dw[co, ci, kz, ky, kx] += sum over (b, oz, oy, ox) of dy * x at the tap; one work-group per
 * weight element, each item summing whole output rows (b, oz, oy) with ox innermost (the tap's
 * valid ox range hoisted out of the loop). Writes +=. */
__kernel __attribute__((reqd_work_group_size(WG, 1, 1)))
void conv3d_bwd_w(__global const float *x, int xo, __global const float *dy, int dyo,
                  __global float *dw, int dwo, int16 g)
{
    __local float scratch[WG];
    int e = get_group_id(0), l = get_local_id(0);
    int kx = e % C3_KW, ky = (e / C3_KW) % C3_KH, kz = (e / (C3_KW * C3_KH)) % C3_KD;
    int ci = (e / (C3_KW * C3_KH * C3_KD)) % C3_CIN, co = e / (C3_KW * C3_KH * C3_KD * C3_CIN);
    int rows = C3_B * C3_DO * C3_HO;
    int ox0 = max(0, C3_PW - kx), ox1 = min(C3_WO, C3_W + C3_PW - kx);
    float s = 0.0f, c = 0.0f;
    for (int q = l; q < rows; q += WG) {
        int oy = q % C3_HO, oz = (q / C3_HO) % C3_DO, b = q / (C3_HO * C3_DO);
        int iz = oz + kz - C3_PD, iy = oy + ky - C3_PH;
        if (iz < 0 || iz >= C3_D || iy < 0 || iy >= C3_H) continue;
        __global const float *dr =
            dy + dyo + (((b * C3_COUT + co) * C3_DO + oz) * C3_HO + oy) * C3_WO;
        __global const float *xr =
            x + xo + (((b * C3_CIN + ci) * C3_D + iz) * C3_H + iy) * C3_W + kx - C3_PW;
        float r = 0.0f;
        for (int ox = ox0; ox < ox1; ox++) r += dr[ox] * xr[ox];
        kahan_add(&s, &c, r);
    }
    float tot = wg_sum(scratch, s - c);
    if (l == 0) dw[dwo + e] += tot;
}

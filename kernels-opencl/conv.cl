/* conv.cl - convolution kernels: for stride-1 conv2d / conv_transpose2d (tensor/ops/conv2d.c,
 * conv_transpose2d.c) direct "implicit GEMM" kernels over a zero-padded input, a per-channel
 * bias gradient; for other strides im2col and a gathering col2im (the products run in
 * gemm.cl); direct conv3d kernels (conv3d.c: stride 1, tiny channel counts).
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

/* ---- stride-1 conv2d without im2col ("implicit GEMM") ------------------------------------
 * The input is first copied into a zero-padded buffer xp (B x C x Hp x Wp, Hp = H + 2 ph,
 * Wp = 32 nbx + (kw - 1) dw, nbx = ceil(Wo / 32)), so every tap of every 32-pixel block of an
 * output row is two unmasked vload16 of xp; out-of-range outputs (ox >= Wo) are computed on
 * zeros and not stored. The weights go to wt ([group][k][cogp], k = (ci, ki, kj), output
 * channels padded with zeros to cogp, a multiple of 8) so the 8 weights of a tap are one
 * vload8. */

/* xp = x placed at (ph, pw), zero elsewhere; one work-item per row of xp (nrows = B C Hp),
 * plain copy and zero loops. Writes =. */
__kernel void conv_pad(__global const float *x, int xo, __global float *xp, int xpo, int H,
                       int W, int Hp, int Wp, int ph, int pw, int nrows)
{
    int r = get_global_id(0);
    if (r >= nrows) return;
    int iy = r % Hp - ph, bc = r / Hp;
    __global float *d = xp + xpo + (long)r * Wp;
    if (iy < 0 || iy >= H) {
        for (int j = 0; j < Wp; j++) d[j] = 0.0f;
        return;
    }
    __global const float *s = x + xo + (bc * H + iy) * W;
    int w = min(W, Wp - pw);
    for (int j = 0; j < pw; j++) d[j] = 0.0f;
    for (int j = 0; j < w; j++) d[pw + j] = s[j];
    for (int j = pw + w; j < Wp; j++) d[j] = 0.0f;
}

/* wt[q][k][co] (co < cogp, zero from cog) = weight of output channel co, tap k = (ci, ki, kj)
 * of the convolution computed (cog outputs, cig inputs per group): w[q][co][k] as stored, or
 * with flip (the stride-1 input gradient as a convolution of dy) the conv2d weight
 * w[q][ci][co][kh-1-ki][kw-1-kj] of the forward conv whose Cout/groups is cig. One item per
 * element of wt (n = groups K cogp). Writes =. */
__kernel void conv_wprep(__global const float *w, int wo, __global float *wt, int wto, int cog,
                         int cig, int kh, int kw, int cogp, int flip, int n)
{
    int i = get_global_id(0);
    if (i >= n) return;
    int kk = kh * kw, K = cig * kk, co = i % cogp, k = (i / cogp) % K, q = i / (cogp * K);
    int ci = k / kk, ki = (k % kk) / kw, kj = k % kw;
    float v = 0.0f;
    if (co < cog)
        v = flip ? w[wo + ((q * cig + ci) * cog + co) * kk + (kh - 1 - ki) * kw + kw - 1 - kj]
                 : w[wo + (q * cog + co) * K + k];
    wt[wto + i] = v;
}

#define IC_RM 8 /* output channels per work-item */

/* y (B x Cout x Ho x Wo) = conv(xp, wt) [+ bias] [+ beta y], stride 1, xp and wt as above.
 * Work-item (block of 8 output channels of a group, pixel block: output row oy, columns
 * 32 bx.., image x group; the channel blocks of one pixel block run together and share its
 * input rows in cache); taps in (ci, ki, kj) order, 8 x 2 float16 accumulators. beta 0: y
 * not read. Writes = (beta 0) or += (beta 1). */
__kernel void conv_fwd_implicit(__global const float *xp, int xpo, __global const float *wt,
                                int wto, __global float *y, int yo, __global const float *bias,
                                int bo, int16 g, int Hp, int Wp, int cogp, int has_bias,
                                float beta)
{
    int nbx = (CG_WO + 31) / 32, cog = CG_COUT / CG_G, cig = CG_CIN / CG_G;
    int m0 = get_global_id(0) * IC_RM, blk = get_global_id(1), z = get_global_id(2);
    if (blk >= nbx * CG_HO || m0 >= cog) return;
    int oy = blk / nbx, ox0 = (blk % nbx) * 32, im = z / CG_G, q = z % CG_G;
    int K = cig * CG_KH * CG_KW;
    __global const float *xb = xp + xpo + ((im * CG_CIN + q * cig) * Hp + oy) * Wp + ox0;
    __global const float *wb = wt + wto + q * K * cogp + m0;
    /* named accumulators (arrays indexed in loops stayed in memory in PoCL's build) */
    float16 a0 = 0.0f, a1 = 0.0f, a2 = 0.0f, a3 = 0.0f, a4 = 0.0f, a5 = 0.0f, a6 = 0.0f,
            a7 = 0.0f, b0 = 0.0f, b1 = 0.0f, b2 = 0.0f, b3 = 0.0f, b4 = 0.0f, b5 = 0.0f,
            b6 = 0.0f, b7 = 0.0f;
    for (int ci = 0; ci < cig; ci++)
        for (int ki = 0; ki < CG_KH; ki++) {
            __global const float *xr = xb + (ci * Hp + ki * CG_DH) * Wp;
            __global const float *wr = wb + (ci * CG_KH + ki) * CG_KW * cogp;
            for (int kj = 0; kj < CG_KW; kj++) {
                float16 x0 = vload16(0, xr + kj * CG_DW), x1 = vload16(0, xr + kj * CG_DW + 16);
                float8 w = vload8(0, wr + kj * cogp);
#define IC_TAP(r, s) a##r = fma((float16)w.s, x0, a##r); b##r = fma((float16)w.s, x1, b##r);
                IC_TAP(0, s0) IC_TAP(1, s1) IC_TAP(2, s2) IC_TAP(3, s3)
                IC_TAP(4, s4) IC_TAP(5, s5) IC_TAP(6, s6) IC_TAP(7, s7)
#undef IC_TAP
            }
        }
    float16 acc0[IC_RM] = {a0, a1, a2, a3, a4, a5, a6, a7};
    float16 acc1[IC_RM] = {b0, b1, b2, b3, b4, b5, b6, b7};
    for (int i = 0; i < IC_RM && m0 + i < cog; i++) {
        int co = q * cog + m0 + i;
        float16 bv = (float16)(has_bias ? bias[bo + co] : 0.0f);
        __global float *out = y + yo + ((im * CG_COUT + co) * CG_HO + oy) * CG_WO + ox0;
        float t[32];
        vstore16(acc0[i] + bv, 0, t);
        vstore16(acc1[i] + bv, 0, t + 16);
        int len = min(32, CG_WO - ox0);
        if (len == 32 && beta == 0.0f) {
            vstore16(acc0[i] + bv, 0, out);
            vstore16(acc1[i] + bv, 0, out + 16);
        } else {
            for (int j = 0; j < len; j++) out[j] = beta == 0.0f ? t[j] : t[j] + beta * out[j];
        }
    }
}

static float hsum16c(float16 v)
{
    float8 h = v.lo + v.hi;
    float4 q = h.lo + h.hi;
    float2 d = q.lo + q.hi;
    return d.x + d.y;
}

/* dw (Cout x Cin/groups x kh x kw) += sum over (image, oy, ox) of dy * xp at the tap, stride 1.
 * Work-item (4 weight columns k = (ci, ki, kj), 4 output channels, group): float16
 * accumulators over 16-pixel blocks of each output row, images and rows in order, summed
 * across lanes at the end. Writes +=. */
__kernel void conv_bwd_w_implicit(__global const float *xp, int xpo, __global const float *dy,
                                  int dyo, __global float *dw, int dwo, int16 g, int Hp, int Wp)
{
    int cog = CG_COUT / CG_G, cig = CG_CIN / CG_G, kk = CG_KH * CG_KW, K = cig * kk;
    int k0 = get_global_id(0) * 4, m0 = get_global_id(1) * 4, q = get_global_id(2);
    if (k0 >= K || m0 >= cog) return;
    int nbx = (CG_WO + 15) / 16, tail = CG_WO - (nbx - 1) * 16;
    int xoff[4], dyc[4];
    for (int j = 0; j < 4; j++) {
        int k = min(k0 + j, K - 1), ci = k / kk, ki = (k % kk) / CG_KW, kj = k % CG_KW;
        xoff[j] = ((q * cig + ci) * Hp + ki * CG_DH) * Wp + kj * CG_DW;
    }
    for (int i = 0; i < 4; i++) dyc[i] = q * cog + min(m0 + i, cog - 1); /* channel */
    /* named accumulators (arrays indexed in loops stayed in memory in PoCL's build) */
    float16 a00 = 0.0f, a01 = 0.0f, a02 = 0.0f, a03 = 0.0f, a10 = 0.0f, a11 = 0.0f, a12 = 0.0f,
            a13 = 0.0f, a20 = 0.0f, a21 = 0.0f, a22 = 0.0f, a23 = 0.0f, a30 = 0.0f, a31 = 0.0f,
            a32 = 0.0f, a33 = 0.0f;
    int nfull = tail == 16 ? nbx : nbx - 1, plane = CG_HO * CG_WO;
    for (int im = 0; im < CG_B; im++)
        for (int oy = 0; oy < CG_HO; oy++) {
            __global const float *xr = xp + xpo + (im * CG_CIN * Hp + oy) * Wp;
            __global const float *dr = dy + dyo + im * CG_COUT * plane + oy * CG_WO;
            for (int bx = 0; bx < nbx; bx++) {
                float16 d0, d1, d2, d3;
                if (bx < nfull) {
                    d0 = vload16(bx, dr + dyc[0] * plane);
                    d1 = vload16(bx, dr + dyc[1] * plane);
                    d2 = vload16(bx, dr + dyc[2] * plane);
                    d3 = vload16(bx, dr + dyc[3] * plane);
                } else {
                    float t[4][16];
                    for (int i = 0; i < 4; i++)
                        for (int j = 0; j < 16; j++)
                            t[i][j] = j < tail ? dr[dyc[i] * plane + bx * 16 + j] : 0.0f;
                    d0 = vload16(0, t[0]), d1 = vload16(0, t[1]);
                    d2 = vload16(0, t[2]), d3 = vload16(0, t[3]);
                }
                float16 x0 = vload16(bx, xr + xoff[0]), x1 = vload16(bx, xr + xoff[1]);
                float16 x2 = vload16(bx, xr + xoff[2]), x3 = vload16(bx, xr + xoff[3]);
#define BW_ROW(i) a##i##0 = fma(d##i, x0, a##i##0); a##i##1 = fma(d##i, x1, a##i##1); \
                  a##i##2 = fma(d##i, x2, a##i##2); a##i##3 = fma(d##i, x3, a##i##3);
                BW_ROW(0) BW_ROW(1) BW_ROW(2) BW_ROW(3)
#undef BW_ROW
            }
        }
    float16 acc[4][4] = {{a00, a01, a02, a03}, {a10, a11, a12, a13}, {a20, a21, a22, a23},
                         {a30, a31, a32, a33}};
    for (int i = 0; i < 4 && m0 + i < cog; i++)
        for (int j = 0; j < 4 && k0 + j < K; j++)
            dw[dwo + (q * cog + m0 + i) * K + k0 + j] += hsum16c(acc[i][j]);
}

/* db[c] += sum over (b, the vol positions) of dy[b, c, ..]: one work-group of WG items per
 * channel, item l summing positions l, l + WG, .. of each image (images in order, Kahan
 * across images), then the fixed-order tree of wg_sum. Writes +=. */
__kernel __attribute__((reqd_work_group_size(WG, 1, 1)))
void bias_grad_wg(__global const float *dy, int dyo, __global float *db, int dbo, int B, int C,
                  int vol)
{
    __local float scratch[WG];
    int co = get_group_id(0), l = get_local_id(0);
    float s = 0.0f, c = 0.0f;
    for (int b = 0; b < B; b++) {
        __global const float *p = dy + dyo + (b * C + co) * vol;
        float r = 0.0f;
        for (int i = l; i < vol; i += WG) r += p[i];
        kahan_add(&s, &c, r);
    }
    float tot = wg_sum(scratch, s - c);
    if (l == 0) db[dbo + co] += tot;
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

/* y = bias + conv3d(x, w); taps in (ci, kz, ky, kx) order. Work-item (s, r): output row
 * r = (b, co, oz, oy) of nrows, outputs ox in [16 s, 16 s + 16) (a fixed-size private
 * array: PoCL keeps it in registers). Writes =. */
__kernel void conv3d_fwd(__global const float *x, int xo, __global const float *w, int wo,
                         __global float *y, int yo, __global const float *bias, int bo,
                         int16 g, int nrows)
{
    int s = get_global_id(0), r = get_global_id(1), ox0 = s * 16;
    if (r >= nrows || ox0 >= C3_WO) return;
    int oy = r % C3_HO, oz = (r / C3_HO) % C3_DO, co = (r / (C3_HO * C3_DO)) % C3_COUT;
    int b = r / (C3_HO * C3_DO * C3_COUT);
    float acc[16];
    for (int j = 0; j < 16; j++) acc[j] = C3_HAS_BIAS ? bias[bo + co] : 0.0f;
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
                    float wv = wr[kx];
                    int d = ox0 + kx - C3_PW;
                    for (int j = 0; j < 16; j++)
                        if (d + j >= 0 && d + j < C3_W) acc[j] += wv * xr[d + j];
                }
            }
        }
    int len = min(16, C3_WO - ox0);
    for (int j = 0; j < len; j++) y[yo + r * C3_WO + ox0 + j] = acc[j];
}

/* dx += sum over (co, taps) of w * dy at the output reading this input; taps in the CPU's
 * flipped order. Work-item (s, r): input row r = (b, ci, iz, iy) of nrows, inputs ix in
 * [16 s, 16 s + 16). Writes +=. */
__kernel void conv3d_bwd_x(__global const float *dy, int dyo, __global const float *w, int wo,
                           __global float *dx, int dxo, int16 g, int nrows)
{
    int s = get_global_id(0), r = get_global_id(1), ix0 = s * 16;
    if (r >= nrows || ix0 >= C3_W) return;
    int iy = r % C3_H, iz = (r / C3_H) % C3_D, ci = (r / (C3_H * C3_D)) % C3_CIN;
    int b = r / (C3_H * C3_D * C3_CIN), len = min(16, C3_W - ix0);
    __global float *d = dx + dxo + r * C3_W + ix0;
    float acc[16];
    for (int j = 0; j < 16; j++) acc[j] = j < len ? d[j] : 0.0f;
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
                    float wv = wr[kx];
                    int o = ix0 - kx + C3_PW;
                    for (int j = 0; j < 16; j++)
                        if (o + j >= 0 && o + j < C3_WO) acc[j] += wv * dr[o + j];
                }
            }
        }
    for (int j = 0; j < len; j++) d[j] = acc[j];
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

/* flow.c — DIS-style dense optical flow (see flow.h for the method and the conventions).
 * What it is: pyramid, patch inverse search, densification, variational refinement, warping.
 * What it is not: a copy of any public implementation; no occlusion handling, no spatial
 * propagation between patches (the pyramid initialisation replaces it for our small images).
 * Every parallel loop partitions rows (or patches) statically and writes each output value
 * from one thread with the same arithmetic, so results do not depend on the thread count. */
#include "data/flow.h"
#include <float.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>

#define MAX_LEVELS 8
#define MAX_PATCH 32
#define VAR_EPS 0.001f
#define SOR_OMEGA 1.6f
#define VAR_ZETA 0.1f

typedef struct level {
    int h, w;
    float *i0, *i1;   /* images (scaled to 0..255) */
    float *gx, *gy;   /* gradients of i0 */
} level;

void lm_flow_default_opts(lm_flow_opts *o, lm_flow_preset preset)
{
    memset(o, 0, sizeof *o);
    o->patch = 12;
    o->alpha = 20.0f;
    o->gamma = 1.0f;
    o->delta = 5.0f;
    o->sor_iters = 5;
    o->nthreads = 1;
    if (preset == LM_FLOW_FAST) {
        o->stride = 6;
        o->gn_iters = 12;
        o->finest = 1;
        o->var_iters = 3;
    } else {
        o->stride = 4;
        o->gn_iters = 16;
        o->finest = 0;
        o->var_iters = 8;
    }
}

int lm_flow_min_size(const lm_flow_opts *o) { return 2 * o->patch; }

static inline int clampi(int v, int lo, int hi) { return v < lo ? lo : v > hi ? hi : v; }

float lm_flow_sample(const float *img, int h, int w, float x, float y)
{
    x = x < 0.0f ? 0.0f : x > (float)(w - 1) ? (float)(w - 1) : x;
    y = y < 0.0f ? 0.0f : y > (float)(h - 1) ? (float)(h - 1) : y;
    int x0 = (int)x, y0 = (int)y;
    int x1 = x0 + 1 < w ? x0 + 1 : x0, y1 = y0 + 1 < h ? y0 + 1 : y0;
    float ax = x - (float)x0, ay = y - (float)y0;
    const float *r0 = img + (long)y0 * w, *r1 = img + (long)y1 * w;
    float top = r0[x0] + ax * (r0[x1] - r0[x0]);
    float bot = r1[x0] + ax * (r1[x1] - r1[x0]);
    return top + ay * (bot - top);
}

typedef float (*sampler)(const float *img, int h, int w, float x, float y);

/* out(p) = sample(src, p + s F(p)), rows split statically over the threads. */
static void warp_with(sampler sample, const float *src, int h, int w, const float *flow,
                      float s, float *out, int nthreads)
{
    long n = (long)h * w;
#pragma omp parallel for schedule(static) num_threads(nthreads > 0 ? nthreads : 1)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            long i = (long)y * w + x;
            out[i] = sample(src, h, w, (float)x + s * flow[i], (float)y + s * flow[n + i]);
        }
}

void lm_flow_warp(const float *src, int h, int w, const float *flow, float s, float *out,
                  int nthreads)
{
    warp_with(lm_flow_sample, src, h, w, flow, s, out, nthreads);
}

/* Catmull-Rom weights of the 4 taps around a sample at fraction f of the way from tap 1 to 2. */
static void cubic_weights(float f, float *wt)
{
    float f2 = f * f, f3 = f2 * f;
    wt[0] = 0.5f * (-f3 + 2.0f * f2 - f);
    wt[1] = 0.5f * (3.0f * f3 - 5.0f * f2 + 2.0f);
    wt[2] = 0.5f * (-3.0f * f3 + 4.0f * f2 + f);
    wt[3] = 0.5f * (f3 - f2);
}

float lm_flow_sample_cubic(const float *img, int h, int w, float x, float y)
{
    x = x < 0.0f ? 0.0f : x > (float)(w - 1) ? (float)(w - 1) : x;
    y = y < 0.0f ? 0.0f : y > (float)(h - 1) ? (float)(h - 1) : y;
    int x0 = (int)x, y0 = (int)y;
    float wx[4], wy[4], acc = 0.0f;
    cubic_weights(x - (float)x0, wx);
    cubic_weights(y - (float)y0, wy);
    for (int j = 0; j < 4; j++) {
        const float *r = img + (long)clampi(y0 - 1 + j, 0, h - 1) * w;
        float row = 0.0f;
        for (int i = 0; i < 4; i++) row += wx[i] * r[clampi(x0 - 1 + i, 0, w - 1)];
        acc += wy[j] * row;
    }
    return acc;
}

void lm_flow_warp_cubic(const float *src, int h, int w, const float *flow, float s, float *out,
                        int nthreads)
{
    warp_with(lm_flow_sample_cubic, src, h, w, flow, s, out, nthreads);
}

/* Central differences with border clamping: gx = (I(x+1) - I(x-1)) / 2. */
static void gradients(const float *img, int h, int w, float *gx, float *gy, int nt)
{
#pragma omp parallel for schedule(static) num_threads(nt)
    for (int y = 0; y < h; y++) {
        const float *up = img + (long)clampi(y - 1, 0, h - 1) * w;
        const float *dn = img + (long)clampi(y + 1, 0, h - 1) * w;
        const float *r = img + (long)y * w;
        for (int x = 0; x < w; x++) {
            gx[(long)y * w + x] = 0.5f * (r[clampi(x + 1, 0, w - 1)] - r[clampi(x - 1, 0, w - 1)]);
            gy[(long)y * w + x] = 0.5f * (dn[x] - up[x]);
        }
    }
}

/* 2 x 2 box average to floor(h/2) x floor(w/2). */
static void downsample(const float *src, int h, int w, float *dst, int nt)
{
    int h2 = h / 2, w2 = w / 2;
#pragma omp parallel for schedule(static) num_threads(nt)
    for (int y = 0; y < h2; y++)
        for (int x = 0; x < w2; x++) {
            const float *a = src + (long)(2 * y) * w + 2 * x, *b = a + w;
            dst[(long)y * w2 + x] = 0.25f * (a[0] + a[1] + b[0] + b[1]);
        }
}

/* Flow of level l+1 (hc x wc) to level l (h x w): bilinear, displacements doubled. */
static void upsample_flow(const float *fc, int hc, int wc, float *f, int h, int w, int nt)
{
    long nc = (long)hc * wc, n = (long)h * w;
#pragma omp parallel for schedule(static) num_threads(nt)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            float cx = 0.5f * ((float)x - 0.5f), cy = 0.5f * ((float)y - 0.5f);
            f[(long)y * w + x] = 2.0f * lm_flow_sample(fc, hc, wc, cx, cy);
            f[n + (long)y * w + x] = 2.0f * lm_flow_sample(fc + nc, hc, wc, cx, cy);
        }
}

/* Patch origins along an axis of length n: 0, s, 2s, ... while the patch fits, then n - p. */
static int patch_positions(int n, int p, int s, int *pos)
{
    int k = 0;
    for (int q = 0; q + p <= n; q += s) pos[k++] = q;
    if (pos[k - 1] + p < n) pos[k++] = n - p;
    return k;
}

/* Sum of squares of the mean-normalised residual r = (I1(x+u) - T) - mean, over one patch. */
static float patch_residual(const level *L, int px, int py, int p, float u, float v, float *r)
{
    double mean = 0.0;
    for (int j = 0; j < p; j++)
        for (int i = 0; i < p; i++) {
            float t = L->i0[(long)(py + j) * L->w + px + i];
            float s = lm_flow_sample(L->i1, L->h, L->w, (float)(px + i) + u, (float)(py + j) + v);
            r[j * p + i] = s - t;
            mean += s - t;
        }
    float m = (float)(mean / (p * p)), ssd = 0.0f;
    for (int k = 0; k < p * p; k++) {
        r[k] -= m;
        ssd += r[k] * r[k];
    }
    return ssd;
}

/* Inverse-compositional Gauss-Newton on one patch, mean-normalised. (u, v) in: initial
 * displacement; out: the best displacement seen (the initial one if search diverges). */
static void patch_search(const level *L, int px, int py, const lm_flow_opts *o, float *u,
                         float *v)
{
    int p = o->patch;
    float gx[MAX_PATCH * MAX_PATCH], gy[MAX_PATCH * MAX_PATCH], r[MAX_PATCH * MAX_PATCH];
    double mx = 0.0, my = 0.0;
    for (int j = 0; j < p; j++)
        for (int i = 0; i < p; i++) {
            long q = (long)(py + j) * L->w + px + i;
            gx[j * p + i] = L->gx[q];
            gy[j * p + i] = L->gy[q];
            mx += L->gx[q];
            my += L->gy[q];
        }
    double hxx = 0.0, hxy = 0.0, hyy = 0.0;
    for (int k = 0; k < p * p; k++) {
        gx[k] -= (float)(mx / (p * p));
        gy[k] -= (float)(my / (p * p));
        hxx += gx[k] * gx[k];
        hxy += gx[k] * gy[k];
        hyy += gy[k] * gy[k];
    }
    double det = hxx * hyy - hxy * hxy;
    if (det < 1e-6 * (hxx + hyy) * (hxx + hyy) || det <= 0.0) return; /* flat / edge patch */
    float u0 = *u, v0 = *v, cu = u0, cv = v0, best = FLT_MAX, bu = u0, bv = v0;
    for (int it = 0; it <= o->gn_iters; it++) {
        float ssd = patch_residual(L, px, py, p, cu, cv, r);
        if (ssd < best) { best = ssd; bu = cu; bv = cv; }
        if (it == o->gn_iters) break;
        double bx = 0.0, by = 0.0;
        for (int k = 0; k < p * p; k++) {
            bx += gx[k] * r[k];
            by += gy[k] * r[k];
        }
        float du = (float)((hyy * bx - hxy * by) / det), dv = (float)((hxx * by - hxy * bx) / det);
        cu -= du;
        cv -= dv;
        if (du * du + dv * dv < 1e-4f) { /* converged: score the final step and stop */
            ssd = patch_residual(L, px, py, p, cu, cv, r);
            if (ssd < best) { best = ssd; bu = cu; bv = cv; }
            break;
        }
    }
    if ((bu - u0) * (bu - u0) + (bv - v0) * (bv - v0) > (float)(p * p)) return;
    *u = bu;
    *v = bv;
}

/* Range [lo[x], hi[x]) of patch indices whose span contains x, for every x < n. */
static void patch_cover(const int *pos, int np, int p, int n, int *lo, int *hi)
{
    for (int x = 0; x < n; x++) {
        int a = 0;
        while (a < np && pos[a] + p <= x) a++;
        int b = a;
        while (b < np && pos[b] <= x) b++;
        lo[x] = a;
        hi[x] = b;
    }
}

/* Dense flow (2 planes) from patch displacements pu/pv (npy x npx), each pixel the average of
 * the covering patches weighted by 1 / max(1, |I1(x + u) - I0(x)|). */
static void densify(const level *L, const int *xs, int npx, const int *ys, int npy, int p,
                    const float *pu, const float *pv, int *lo, int *hi, float *flow, int nt)
{
    int h = L->h, w = L->w;
    long n = (long)h * w;
    int *xlo = lo, *xhi = hi, *ylo = lo + w, *yhi = hi + w;
    patch_cover(xs, npx, p, w, xlo, xhi);
    patch_cover(ys, npy, p, h, ylo, yhi);
#pragma omp parallel for schedule(static) num_threads(nt)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            float su = 0.0f, sv = 0.0f, sw = 0.0f, i0 = L->i0[(long)y * w + x];
            for (int j = ylo[y]; j < yhi[y]; j++)
                for (int i = xlo[x]; i < xhi[x]; i++) {
                    float u = pu[j * npx + i], v = pv[j * npx + i];
                    float d = fabsf(lm_flow_sample(L->i1, h, w, (float)x + u, (float)y + v) - i0);
                    float wt = 1.0f / (d > 1.0f ? d : 1.0f);
                    su += wt * u;
                    sv += wt * v;
                    sw += wt;
                }
            flow[(long)y * w + x] = sw > 0.0f ? su / sw : 0.0f;
            flow[n + (long)y * w + x] = sw > 0.0f ? sv / sw : 0.0f;
        }
}

/* Linearised data terms of the variational energy, per pixel: three rows (c1 du + c2 dv + c3)
 * for brightness constancy (b*) and gradient constancy in x (x*) and y (y*), each divided by
 * sqrt(|its spatial derivatives|^2 + zeta^2) so that every row measures a displacement-like
 * residual whatever the local contrast (the normalisation of Zimmer et al.). */
typedef struct var_terms {
    float *b1, *b2, *b3, *x1, *x2, *x3, *y1, *y2, *y3;
} var_terms;

static void var_derivatives(const level *L, const float *warped, var_terms *t, float *s0,
                            float *s1, float *s2, float *s3, int nt)
{
    int h = L->h, w = L->w;
    long n = (long)h * w;
    float *ix = s2, *iy = s3;
    gradients(warped, h, w, s0, s1, nt);
    for (long i = 0; i < n; i++) {
        ix[i] = 0.5f * (s0[i] + L->gx[i]);
        iy[i] = 0.5f * (s1[i] + L->gy[i]);
        t->b3[i] = warped[i] - L->i0[i];
        t->x3[i] = s0[i] - L->gx[i];
        t->y3[i] = s1[i] - L->gy[i];
    }
    gradients(ix, h, w, t->x1, t->x2, nt); /* Ixx, Ixy */
    gradients(iy, h, w, t->y1, t->y2, nt); /* Iyx, Iyy */
    const float z2 = VAR_ZETA * VAR_ZETA;
    for (long i = 0; i < n; i++) {
        float ixy = 0.5f * (t->x2[i] + t->y1[i]);
        t->x2[i] = ixy;
        t->y1[i] = ixy;
        float nb = 1.0f / sqrtf(ix[i] * ix[i] + iy[i] * iy[i] + z2);
        float nx = 1.0f / sqrtf(t->x1[i] * t->x1[i] + ixy * ixy + z2);
        float ny = 1.0f / sqrtf(ixy * ixy + t->y2[i] * t->y2[i] + z2);
        t->b1[i] = nb * ix[i];
        t->b2[i] = nb * iy[i];
        t->b3[i] *= nb;
        t->x1[i] *= nx;
        t->x2[i] *= nx;
        t->x3[i] *= nx;
        t->y1[i] *= ny;
        t->y2[i] *= ny;
        t->y3[i] *= ny;
    }
}

/* The per-pixel 2 x 2 system of the data terms at the current increment (du, dv), with robust
 * (Charbonnier) weights: co = {a11, a12, a22, b1, b2}; and the smoothness weight ws of the total
 * flow. Recomputed once per fixed-point iteration. */
static void var_coeffs(const var_terms *t, const float *f, const float *du, const float *dv,
                       int h, int w, const lm_flow_opts *o, float *const co[5], float *ws, int nt)
{
    long n = (long)h * w;
#pragma omp parallel for schedule(static) num_threads(nt)
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            long i = (long)y * w + x;
            float c1 = t->b1[i], c2 = t->b2[i], c3 = t->b3[i], x1 = t->x1[i], x2 = t->x2[i];
            float x3 = t->x3[i], y1 = t->y1[i], y2 = t->y2[i], y3 = t->y3[i];
            float a = c3 + c1 * du[i] + c2 * dv[i];
            float gxr = x3 + x1 * du[i] + x2 * dv[i], gyr = y3 + y1 * du[i] + y2 * dv[i];
            float bd = o->delta / sqrtf(a * a + VAR_EPS * VAR_EPS);
            float bg = o->gamma / sqrtf(gxr * gxr + gyr * gyr + VAR_EPS * VAR_EPS);
            co[0][i] = bd * c1 * c1 + bg * (x1 * x1 + y1 * y1);
            co[1][i] = bd * c1 * c2 + bg * (x1 * x2 + y1 * y2);
            co[2][i] = bd * c2 * c2 + bg * (x2 * x2 + y2 * y2);
            co[3][i] = bd * c1 * c3 + bg * (x1 * x3 + y1 * y3);
            co[4][i] = bd * c2 * c3 + bg * (x2 * x3 + y2 * y3);
            long r = x + 1 < w ? i + 1 : i, d = y + 1 < h ? i + w : i;
            float ux = f[r] + du[r] - f[i] - du[i], uy = f[d] + du[d] - f[i] - du[i];
            float vx = f[n + r] + dv[r] - f[n + i] - dv[i];
            float vy = f[n + d] + dv[d] - f[n + i] - dv[i];
            ws[i] = 1.0f / sqrtf(ux * ux + uy * uy + vx * vx + vy * vy + VAR_EPS * VAR_EPS);
        }
}

/* One red-black SOR half-sweep (pixels with (x + y) % 2 == color) of the Euler-Lagrange
 * equations for the increment (du, dv): (A + alpha W) d = -b + alpha sum_q w_pq (f_q + d_q - f_p),
 * w_pq = (ws_p + ws_q) / 2 over the 4-neighbours inside the image. */
static void var_sor(const float *const co[5], const float *f, float *du, float *dv,
                    const float *ws, int h, int w, float al, int color, int nt)
{
    long n = (long)h * w;
#pragma omp parallel for schedule(static) num_threads(nt)
    for (int y = 0; y < h; y++)
        for (int x = (y + color) & 1; x < w; x += 2) {
            long i = (long)y * w + x;
            long nb[4] = {i - 1, i + 1, i - w, i + w};
            int ok[4] = {x > 0, x + 1 < w, y > 0, y + 1 < h};
            float W = 0.0f, su = 0.0f, sv = 0.0f;
            for (int k = 0; k < 4; k++) {
                if (!ok[k]) continue;
                long q = nb[k];
                float wq = 0.5f * (ws[i] + ws[q]);
                W += wq;
                su += wq * (f[q] + du[q] - f[i]);
                sv += wq * (f[n + q] + dv[q] - f[n + i]);
            }
            float d1 = co[0][i] + al * W, d2 = co[2][i] + al * W;
            if (d1 > 0.0f) {
                float nu = (-co[3][i] + al * su - co[1][i] * dv[i]) / d1;
                du[i] += SOR_OMEGA * (nu - du[i]);
            }
            if (d2 > 0.0f) {
                float nv = (-co[4][i] + al * sv - co[1][i] * du[i]) / d2;
                dv[i] += SOR_OMEGA * (nv - dv[i]);
            }
        }
}

/* Variational refinement of flow f (2 planes) at one level; scratch holds 18 planes. */
static void var_refine(const level *L, float *f, const lm_flow_opts *o, float *scratch, int nt)
{
    int h = L->h, w = L->w;
    long n = (long)h * w;
    float *s = scratch;
    float *warped = s, *du = s + n, *dv = s + 2 * n, *ws = s + 3 * n;
    float *const co[5] = {s + 4 * n, s + 5 * n, s + 6 * n, s + 7 * n, s + 8 * n};
    var_terms t = {s + 9 * n,  s + 10 * n, s + 11 * n, s + 12 * n, s + 13 * n,
                   s + 14 * n, s + 15 * n, s + 16 * n, s + 17 * n};
    lm_flow_warp(L->i1, h, w, f, 1.0f, warped, nt);
    var_derivatives(L, warped, &t, co[0], co[1], co[2], co[3], nt); /* co: scratch here */
    memset(du, 0, (size_t)n * sizeof *du);
    memset(dv, 0, (size_t)n * sizeof *dv);
    for (int k = 0; k < o->var_iters; k++) {
        var_coeffs(&t, f, du, dv, h, w, o, co, ws, nt);
        for (int it = 0; it < o->sor_iters; it++) {
            var_sor((const float *const *)co, f, du, dv, ws, h, w, o->alpha, 0, nt);
            var_sor((const float *const *)co, f, du, dv, ws, h, w, o->alpha, 1, nt);
        }
    }
    for (long i = 0; i < n; i++) {
        f[i] += du[i];
        f[n + i] += dv[i];
    }
}

/* One pyramid level: patch search initialised from init (the coarser level's flow, upsampled;
 * NULL at the coarsest level), densification into f, variational refinement. */
static lm_status flow_level(const level *L, const float *init, const lm_flow_opts *o, float *f,
                            float *scratch, int nt)
{
    int h = L->h, w = L->w, p = o->patch;
    long n = (long)h * w;
    int *xs = malloc(sizeof(int) * (size_t)(w + h + 2));
    if (!xs) return LM_ERR_NOMEM;
    int *ys = xs + w + 1;
    int npx = patch_positions(w, p, o->stride, xs), npy = patch_positions(h, p, o->stride, ys);
    float *pu = scratch, *pv = scratch + (long)npx * npy;
    int np = npx * npy;
#pragma omp parallel for schedule(static) num_threads(nt)
    for (int k = 0; k < np; k++) {
        int px = xs[k % npx], py = ys[k / npx];
        float u = 0.0f, v = 0.0f;
        if (init) {
            float cx = (float)px + 0.5f * (float)(p - 1), cy = (float)py + 0.5f * (float)(p - 1);
            u = lm_flow_sample(init, h, w, cx, cy);
            v = lm_flow_sample(init + n, h, w, cx, cy);
        }
        patch_search(L, px, py, o, &u, &v);
        pu[k] = u;
        pv[k] = v;
    }
    int *cover = malloc(sizeof(int) * (size_t)(2 * (w + h)));
    if (!cover) {
        free(xs);
        return LM_ERR_NOMEM;
    }
    densify(L, xs, npx, ys, npy, p, pu, pv, cover, cover + w + h, f, nt);
    free(cover);
    free(xs);
    if (o->var_iters > 0) var_refine(L, f, o, scratch, nt);
    return LM_OK;
}

static lm_status check_args(const float *i0, const float *i1, int h, int w,
                            const lm_flow_opts *o, const float *flow, lm_err *e)
{
    if (!i0 || !i1 || !flow) return lm_err_set(e, LM_ERR_ARG, "flow: NULL image or flow buffer");
    if (o->patch < 2 || o->patch > MAX_PATCH || o->stride < 1 || o->stride > o->patch ||
        o->gn_iters < 0 || o->finest < 0 || o->var_iters < 0 || o->sor_iters < 0)
        return lm_err_set(e, LM_ERR_ARG,
                          "flow: bad options (patch %d must be 2..%d, stride %d must be 1..patch, "
                          "iteration counts >= 0)", o->patch, MAX_PATCH, o->stride);
    int m = lm_flow_min_size(o);
    if (h < m || w < m)
        return lm_err_set(e, LM_ERR_SHAPE, "flow: image %dx%d (h x w) is smaller than %dx%d",
                          h, w, m, m);
    long n = (long)h * w;
    for (long i = 0; i < n; i++)
        if (!isfinite(i0[i]) || !isfinite(i1[i]))
            return lm_err_set(e, LM_ERR_NUMERIC, "flow: non-finite pixel at (x=%ld, y=%ld)",
                              i % w, i / w);
    return LM_OK;
}

/* Levels 0..coarsest of both images (scaled so the maximum is 255) with i0's gradients; all
 * planes in one block *mem. Returns the number of levels, 0 on allocation failure. */
static int build_pyramid(const float *i0, const float *i1, int h, int w, int minside, level *L,
                         float **mem, int nt)
{
    int nl = 1;
    while (nl < MAX_LEVELS && (h >> nl) >= minside && (w >> nl) >= minside) nl++;
    long total = 0;
    for (int l = 0; l < nl; l++) total += 4L * (h >> l) * (w >> l);
    float *m = malloc(sizeof(float) * (size_t)total);
    if (!(*mem = m)) return 0;
    float mx = 0.0f;
    for (long i = 0; i < (long)h * w; i++) {
        mx = i0[i] > mx ? i0[i] : mx;
        mx = i1[i] > mx ? i1[i] : mx;
    }
    float sc = mx > 0.0f ? 255.0f / mx : 1.0f;
    for (int l = 0; l < nl; l++) {
        long n = (long)(h >> l) * (w >> l);
        L[l] = (level){h >> l, w >> l, m, m + n, m + 2 * n, m + 3 * n};
        m += 4 * n;
        if (l == 0) {
            for (long i = 0; i < n; i++) {
                L[0].i0[i] = sc * i0[i];
                L[0].i1[i] = sc * i1[i];
            }
        } else {
            downsample(L[l - 1].i0, L[l - 1].h, L[l - 1].w, L[l].i0, nt);
            downsample(L[l - 1].i1, L[l - 1].h, L[l - 1].w, L[l].i1, nt);
        }
        gradients(L[l].i0, L[l].h, L[l].w, L[l].gx, L[l].gy, nt);
    }
    return nl;
}

lm_status lm_flow_compute(const float *i0, const float *i1, int h, int w,
                          const lm_flow_opts *opts, float *flow, lm_err *e)
{
    lm_flow_opts def;
    if (!opts) lm_flow_default_opts(&def, LM_FLOW_MEDIUM);
    const lm_flow_opts *o = opts ? opts : &def;
    lm_status s = check_args(i0, i1, h, w, o, flow, e);
    if (s) return s;
    int nt = o->nthreads > 0 ? o->nthreads : 1;
    level L[MAX_LEVELS];
    float *pyr = NULL;
    int nl = build_pyramid(i0, i1, h, w, lm_flow_min_size(o), L, &pyr, nt);
    long n = (long)h * w;
    float *fa = malloc(sizeof(float) * (size_t)(22 * n)); /* 2 flows + 18 scratch planes */
    if (!nl || !fa) {
        free(pyr);
        free(fa);
        return lm_err_set(e, LM_ERR_NOMEM, "flow: out of memory for %dx%d images", h, w);
    }
    float *cur = fa, *up = fa + 2 * n, *scratch = fa + 4 * n; /* up: coarser flow, upsampled */
    int finest = o->finest < nl - 1 ? o->finest : nl - 1;
    for (int l = nl - 1; l >= 0 && s == LM_OK; l--) {
        if (l >= finest) {
            s = flow_level(&L[l], l == nl - 1 ? NULL : up, o, cur, scratch, nt);
        } else {
            float *tmp = cur;
            cur = up;
            up = tmp;
        }
        if (l > 0) upsample_flow(cur, L[l].h, L[l].w, up, L[l - 1].h, L[l - 1].w, nt);
    }
    if (s == LM_OK) memcpy(flow, cur, sizeof(float) * (size_t)(2 * n));
    free(pyr);
    free(fa);
    return s ? lm_err_set(e, s, "flow: out of memory for %dx%d images", h, w) : LM_OK;
}

void lm_flow_intermediate(const float *f01, const float *f10, long n, float t, float *ft0,
                          float *ft1)
{
    float a0 = -(1.0f - t) * t, b0 = t * t, a1 = (1.0f - t) * (1.0f - t), b1 = -t * (1.0f - t);
    for (long i = 0; i < 2 * n; i++) {
        ft0[i] = a0 * f01[i] + b0 * f10[i];
        ft1[i] = a1 * f01[i] + b1 * f10[i];
    }
}

lm_status lm_flow_interpolate_flows(const float *i0, const float *i1, int h, int w, float t,
                                    const float *f01, const float *f10, int nthreads,
                                    float *out, lm_err *e)
{
    if (!i0 || !i1 || !f01 || !f10 || !out)
        return lm_err_set(e, LM_ERR_ARG, "flow: NULL image, flow or output buffer");
    long n = (long)h * w;
    float *b = malloc(sizeof(float) * (size_t)(6 * n));
    if (!b) return lm_err_set(e, LM_ERR_NOMEM, "flow: out of memory for %dx%d images", h, w);
    float *ft0 = b, *ft1 = b + 2 * n, *w0 = b + 4 * n, *w1 = b + 5 * n;
    int nt = nthreads > 0 ? nthreads : 1;
    lm_flow_intermediate(f01, f10, n, t, ft0, ft1);
    lm_flow_warp_cubic(i0, h, w, ft0, 1.0f, w0, nt);
    lm_flow_warp_cubic(i1, h, w, ft1, 1.0f, w1, nt);
    for (long i = 0; i < n; i++) out[i] = (1.0f - t) * w0[i] + t * w1[i];
    free(b);
    return LM_OK;
}

lm_status lm_flow_interpolate(const float *i0, const float *i1, int h, int w, float t,
                              const lm_flow_opts *opts, float *out, lm_err *e)
{
    if (!out) return lm_err_set(e, LM_ERR_ARG, "flow: NULL output buffer");
    long n = (long)h * w;
    if (h <= 0 || w <= 0)
        return lm_err_set(e, LM_ERR_SHAPE, "flow: image %dx%d (h x w) is empty", h, w);
    float *b = malloc(sizeof(float) * (size_t)(4 * n));
    if (!b) return lm_err_set(e, LM_ERR_NOMEM, "flow: out of memory for %dx%d images", h, w);
    float *f01 = b, *f10 = b + 2 * n;
    lm_status s = lm_flow_compute(i0, i1, h, w, opts, f01, e);
    if (!s) s = lm_flow_compute(i1, i0, h, w, opts, f10, e);
    if (!s) s = lm_flow_interpolate_flows(i0, i1, h, w, t, f01, f10,
                                          opts && opts->nthreads > 0 ? opts->nthreads : 1, out, e);
    free(b);
    return s;
}

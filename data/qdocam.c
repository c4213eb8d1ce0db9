/* qdocam.c — the QDO camera (qdocam.h): edge-padded FFT convolution of each band with its PSF,
 * accumulated per RGB channel in the Fourier domain, 3 inverse FFTs, crop, noise.
 * What it is not: the PSF computation (doe.c) or the colour weights (rgbcam.c). */
#include "data/qdocam.h"
#include "data/spectra.h"
#include <fftw3.h>
#include <stdlib.h>
#include <string.h>

#define NB LM_RGBCAM_BANDS

lm_status lm_qdocam_init_psfs(lm_qdocam *q, const float *psfs, int S, lm_rgbcam_illum illum,
                              lm_err *err)
{
    memset(q, 0, sizeof *q);
    if (S < 1 || S % 2 == 0 || S > 1023)
        return lm_err_set(err, LM_ERR_ARG, "qdocam: PSF size %d (must be odd, 1..1023)", S);
    size_t n = (size_t)NB * S * S;
    q->psf = malloc(n * sizeof(float));
    if (!q->psf) return lm_err_set(err, LM_ERR_NOMEM, "qdocam: out of memory");
    memcpy(q->psf, psfs, n * sizeof(float));
    q->psf_size = S;
    lm_status st = lm_rgbcam_load(&q->cam, NULL, illum, err);
    if (st) lm_qdocam_free(q);
    return st;
}

lm_status lm_qdocam_init(lm_qdocam *q, const lm_doe *doe, lm_rgbcam_illum illum, lm_err *err)
{
    memset(q, 0, sizeof *q);
    int S = doe->psf_size;
    float *psfs = malloc((size_t)NB * S * S * sizeof(float));
    if (!psfs) return lm_err_set(err, LM_ERR_NOMEM, "qdocam: out of memory");
    lm_status st = lm_doe_psfs(doe, LM_GRID31_START, LM_GRID41_STEP, NB, psfs, err);
    if (!st) st = lm_qdocam_init_psfs(q, psfs, S, illum, err);
    free(psfs);
    return st;
}

void lm_qdocam_free(lm_qdocam *q)
{
    free(q->psf);
    memset(q, 0, sizeof *q);
}

/* Work buffers and plans for one padded size Hp x Wp (Wc = Wp / 2 + 1 complex columns). */
typedef struct conv {
    int H, W, r, Hp, Wp, Wc;
    float *buf;
    fftwf_complex *spec, *kspec, *acc[3];
    fftwf_plan fwd, inv;
} conv;

static void conv_free(conv *c)
{
    lm_fftw_lock();
    if (c->fwd) fftwf_destroy_plan(c->fwd);
    if (c->inv) fftwf_destroy_plan(c->inv);
    lm_fftw_unlock();
    fftwf_free(c->buf);
    fftwf_free(c->spec);
    fftwf_free(c->kspec);
    for (int k = 0; k < 3; k++) fftwf_free(c->acc[k]);
}

static lm_status conv_init(conv *c, int H, int W, int r, lm_err *err)
{
    memset(c, 0, sizeof *c);
    c->H = H, c->W = W, c->r = r, c->Hp = H + 2 * r, c->Wp = W + 2 * r, c->Wc = c->Wp / 2 + 1;
    size_t nc = (size_t)c->Hp * c->Wc;
    c->buf = fftwf_malloc((size_t)c->Hp * c->Wp * sizeof(float));
    c->spec = fftwf_malloc(nc * sizeof(fftwf_complex));
    c->kspec = fftwf_malloc(nc * sizeof(fftwf_complex));
    int ok = c->buf && c->spec && c->kspec;
    for (int k = 0; k < 3; k++) {
        c->acc[k] = fftwf_malloc(nc * sizeof(fftwf_complex));
        ok = ok && c->acc[k];
        if (c->acc[k]) memset(c->acc[k], 0, nc * sizeof(fftwf_complex));
    }
    if (ok) {
        lm_fftw_lock();
        c->fwd = fftwf_plan_dft_r2c_2d(c->Hp, c->Wp, c->buf, c->spec, FFTW_ESTIMATE);
        c->inv = fftwf_plan_dft_c2r_2d(c->Hp, c->Wp, c->acc[0], c->buf, FFTW_ESTIMATE);
        lm_fftw_unlock();
        ok = c->fwd && c->inv;
    }
    if (ok) return LM_OK;
    conv_free(c);
    return lm_err_set(err, LM_ERR_NOMEM, "qdocam: out of memory (%d x %d image)", H, W);
}

/* buf = the band, edge-padded by r on every side. */
static void pad_edge(conv *c, const float *band)
{
    for (int y = 0; y < c->Hp; y++) {
        int sy = y - c->r < 0 ? 0 : y - c->r >= c->H ? c->H - 1 : y - c->r;
        const float *src = band + (size_t)sy * c->W;
        float *dst = c->buf + (size_t)y * c->Wp;
        for (int x = 0; x < c->Wp; x++) {
            int sx = x - c->r < 0 ? 0 : x - c->r >= c->W ? c->W - 1 : x - c->r;
            dst[x] = src[sx];
        }
    }
}

/* buf = the PSF with its centre at (0, 0), wrapped (a circular convolution kernel). */
static void place_kernel(conv *c, const float *psf, int S)
{
    memset(c->buf, 0, (size_t)c->Hp * c->Wp * sizeof(float));
    for (int i = 0; i < S; i++)
        for (int j = 0; j < S; j++) {
            int y = (i - S / 2 + c->Hp) % c->Hp, x = (j - S / 2 + c->Wp) % c->Wp;
            c->buf[(size_t)y * c->Wp + x] = psf[(size_t)i * S + j];
        }
}

/* acc[k] += w[k][b] * FFT(band) * FFT(psf_b), over all bands. */
static void accumulate(conv *c, const lm_qdocam *q, const float *cube)
{
    int S = q->psf_size;
    size_t nc = (size_t)c->Hp * c->Wc, plane = (size_t)c->H * c->W;
    for (int b = 0; b < NB; b++) {
        pad_edge(c, cube + b * plane);
        fftwf_execute_dft_r2c(c->fwd, c->buf, c->spec);
        place_kernel(c, q->psf + (size_t)b * S * S, S);
        fftwf_execute_dft_r2c(c->fwd, c->buf, c->kspec);
        for (size_t i = 0; i < nc; i++) {
            float re = c->spec[i][0] * c->kspec[i][0] - c->spec[i][1] * c->kspec[i][1];
            float im = c->spec[i][0] * c->kspec[i][1] + c->spec[i][1] * c->kspec[i][0];
            for (int k = 0; k < 3; k++) {
                c->acc[k][i][0] += q->cam.w[k][b] * re;
                c->acc[k][i][1] += q->cam.w[k][b] * im;
            }
        }
    }
}

lm_status lm_qdocam_render(const lm_qdocam *q, const float *cube, int H, int W, float *rgb,
                           lm_err *err)
{
    if (H < 1 || W < 1) return lm_err_set(err, LM_ERR_ARG, "qdocam: image size %d x %d", H, W);
    if (!q->psf) return lm_err_set(err, LM_ERR_ARG, "qdocam: not initialised");
    conv c;
    lm_status st = conv_init(&c, H, W, q->psf_size / 2, err);
    if (st) return st;
    accumulate(&c, q, cube);
    float scale = 1.0f / ((float)c.Hp * c.Wp);
    for (int k = 0; k < 3; k++) {
        fftwf_execute_dft_c2r(c.inv, c.acc[k], c.buf);
        for (int y = 0; y < H; y++) {
            const float *src = c.buf + (size_t)(y + c.r) * c.Wp + c.r;
            float *dst = rgb + (size_t)k * H * W + (size_t)y * W;
            for (int x = 0; x < W; x++) dst[x] = src[x] * scale;
        }
    }
    conv_free(&c);
    return LM_OK;
}

lm_status lm_qdocam_simulate(const lm_qdocam *q, const float *cube, int H, int W,
                             const lm_noise_opts *noise, lm_rng *rng, float *rgb, int nthreads,
                             lm_err *err)
{
    lm_status st = lm_qdocam_render(q, cube, H, W, rgb, err);
    if (st || !noise) return st;
    return lm_forward_noise(rgb, 3 * H, W, noise, rng, nthreads, err);
}

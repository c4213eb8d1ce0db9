/* qdocam.h — the QDO baseline's camera: a 31-band reflectance cube (400..700 nm, 10 nm) seen
 * through a DOE (data/doe.h) by an RGB sensor.
 * What it is: per band, 2-D convolution of the band with that wavelength's PSF ('same' size,
 * by FFT: FFTW real-to-complex), then RGB integration with the RGB baseline's camera
 * (data/rgbcam.h: the same sensitivities, illuminant and white balance, so a uniform white
 * scene gives (1, 1, 1)), then the same noise options (lm_forward_noise on the 3 planes as one
 * image, as lm_rgbcam_simulate does). The RGB integration is done in the Fourier domain (it is
 * linear): 31 forward transforms of the bands and 3 inverse ones per image.
 * Borders: edge padding (the border pixels are replicated PSF-radius pixels outwards). A patch
 * is a window of a larger scene, and a real camera sees light from outside the window; zero
 * padding would darken every patch's rim, an artefact full frames do not have. Replication
 * keeps a uniform scene uniform up to the border.
 * Only the 400..700 nm bands enter (as in rgbcam.h): the datasets have no data outside them.
 * What it is not: the optics (doe.h), differentiable, or multi-threaded (one FFT pipeline per
 * call; the dataset's workers run calls in parallel). */
#ifndef LM_QDOCAM_H
#define LM_QDOCAM_H
#include "data/doe.h"
#include "data/rgbcam.h"
#include "tensor/ops.h"

typedef struct lm_qdocam {
    lm_rgbcam cam;
    int psf_size;  /* S, odd */
    float *psf;    /* 31 x S x S, each unit sum, centre pixel on axis */
} lm_qdocam;

/* PSFs of the DOE on the 31-band grid, and the RGB camera (bundled Nikon D5100 curves). */
lm_status lm_qdocam_init(lm_qdocam *q, const lm_doe *doe, lm_rgbcam_illum illum, lm_err *err);
/* The same from given PSFs (31 x S x S, copied; S odd), e.g. for tests or a loaded design. */
lm_status lm_qdocam_init_psfs(lm_qdocam *q, const float *psfs, int S, lm_rgbcam_illum illum,
                              lm_err *err);
void lm_qdocam_free(lm_qdocam *q);

/* Noise-free: cube = 31 planes of H x W (band-major), rgb = 3 planes of H x W. */
lm_status lm_qdocam_render(const lm_qdocam *q, const float *cube, int H, int W, float *rgb,
                           lm_err *err);
/* Render, then lm_forward_noise on the 3 planes as one 3H x W image (as lm_rgbcam_simulate).
 * rng may be NULL when no noise is on; noise NULL = none. */
lm_status lm_qdocam_simulate(const lm_qdocam *q, const float *cube, int H, int W,
                             const lm_noise_opts *noise, lm_rng *rng, float *rgb, int nthreads,
                             lm_err *err);

/* The differentiable twin of lm_qdocam_render (data/qdocam_t.c): cube = B x 31 x Hp x Wp host
 * floats (band-major per item), padded by r = S/2 pixels of real scene on every side; psf = a
 * 31 x S x S tensor (e.g. lm_doe_psf_t, with gradients). Returns the clean RGB B x 3 x
 * (Hp - 2r) x (Wp - 2r), equal to lm_qdocam_render's pixels at least r from the border of
 * the same padded cube. CPU contexts. */
lm_tensor *lm_qdocam_render_t(lm_ctx *c, const lm_rgbcam *cam, lm_tensor *psf,
                              const float *cube, int B, int Hp, int Wp);

#endif

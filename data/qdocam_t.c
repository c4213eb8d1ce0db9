/* qdocam_t.c — the QDO camera as tensor ops (lm_qdocam_render_t): the differentiable twin of
 * lm_qdocam_render for end-to-end DOE optimisation, gradients flowing to the PSFs (and from
 * them, through lm_doe_psf_t, to the height map).
 * Per band: circular convolution by FFT on the padded patch (lm_fft2, lm_cmul), the RGB
 * integration with the camera weights in the Fourier domain (a 3 x 31 lm_matmul: 3 inverse
 * transforms instead of 31), then the real part cropped to the patch. The cube comes padded by
 * the PSF radius r on every side with real scene context (not edge replication): the cropped
 * outputs then see only real pixels and equal lm_qdocam_render's interior, and a circular
 * convolution on the padded size is exact there (wrap-around reaches only the dropped rim).
 * The PSF sits at the top-left of its padded plane, so output (y + 2r, x + 2r) is the pixel
 * (y, x) of the patch.
 * What it is not: noise (the caller adds it) or a device path (CPU tensors: the cube is filled
 * on the host). */
#include "data/qdocam.h"
#include <string.h>

lm_tensor *lm_qdocam_render_t(lm_ctx *c, const lm_rgbcam *cam, lm_tensor *psf,
                              const float *cube, int B, int Hp, int Wp)
{
    if (!lm_check_inputs(c, "qdocam_render", 1, psf)) return NULL;
    char s[64];
    int S = psf->ndim == 3 ? psf->shape[1] : 0, r = S / 2;
    if (psf->ndim != 3 || psf->shape[0] != LM_RGBCAM_BANDS || psf->shape[2] != S || S % 2 == 0 ||
        Hp <= 2 * r || Wp <= 2 * r || B < 1 || !cube) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "qdocam_render: psf %s (31 x S x S, S odd), cube %d x 31 x "
                    "%d x %d (more than the PSF's width)", lm_shape_str(psf, s, sizeof s), B, Hp,
                    Wp);
        return NULL;
    }
    const int NB = LM_RGBCAM_BANDS, H = Hp - 2 * r, W = Wp - 2 * r;
    lm_tensor *cc = lm_tensor_new_on(c, LM_DEVICE_CPU, 5, (int[]){B, NB, Hp, Wp, 2});
    lm_tensor *w = lm_tensor_new_on(c, LM_DEVICE_CPU, 2, (int[]){3, NB});
    lm_tensor *zero = lm_tensor_zeros(c, 3, (int[]){NB, Hp, Wp});
    if (!cc || !w || !zero) return NULL;
    size_t n = (size_t)B * NB * Hp * Wp;
    for (size_t i = 0; i < n; i++) cc->data[2 * i] = cube[i], cc->data[2 * i + 1] = 0.0f;
    for (int k = 0; k < 3; k++)
        for (int b = 0; b < NB; b++) w->data[k * NB + b] = cam->w[k][b];
    lm_tensor *kp = lm_pad2d(c, lm_reshape(c, psf, 4, (int[]){NB, 1, S, S}), 0, Hp - S, 0,
                             Wp - S, LM_PAD_ZERO);
    lm_tensor *K = lm_fft2(c, lm_polar(c, lm_reshape(c, kp, 3, (int[]){NB, Hp, Wp}), zero), 0);
    lm_tensor *P = lm_cmul(c, lm_fft2(c, cc, 0), K);                   /* B x 31 x Hp x Wp x 2 */
    lm_tensor *R = lm_matmul(c, w, lm_reshape(c, P, 3, (int[]){B, NB, Hp * Wp * 2}), 0, 0);
    lm_tensor *img = lm_fft2(c, lm_reshape(c, R, 5, (int[]){B, 3, Hp, Wp, 2}), 1);
    img = lm_slice(c, lm_slice(c, lm_slice(c, img, 4, 0, 1), 2, 2 * r, H), 3, 2 * r, W);
    img = lm_contiguous(c, img);
    return img ? lm_reshape(c, img, 4, (int[]){B, 3, H, W}) : NULL;
}

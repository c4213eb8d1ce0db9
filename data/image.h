/* image.h — the C-callable shim around OpenImageIO (implemented in image_oiio.cpp).
 * What it is: read one image file (PNG through libpng, so that its messages end up in the
 * lm_err and nothing is printed; TIFF or EXR through OpenImageIO; chosen by the extension; no other
 * OpenImageIO reader is ever tried) as float samples with its bit depth and channel names,
 * its header checked first (see lm_image_want, data/limits.h); write 8-bit RGB, 16-bit
 * single-channel and
 * float EXR images. Every writer is atomic: it writes `<path>.tmp.<pid>` and renames it onto
 * `path`; on failure the temporary file is removed and `path` is left untouched.
 * What it is not: colour management (no gamma, no sRGB transfer, no alpha premultiplication is
 * applied in either direction) or the spectral EXR layout (see io_exr.c, OpenEXR's C API). */
#ifndef LM_IMAGE_H
#define LM_IMAGE_H
#include <stdio.h>
#include <unistd.h>

#ifdef __cplusplus
extern "C" {
#endif
#include "tensor/status.h" /* it has no C++ guard of its own */

#define LM_IMAGE_NAME_LEN 64

typedef struct lm_image {
    int width, height, channels;
    int bits;       /* bits per sample in the file: 8 (or fewer, packed), 16 (uint16 or half), 32 */
    int is_float;   /* 1 if the file stores floating-point samples */
    float *data;    /* height * width * channels, interleaved: data[(y*W + x)*C + c]; NULL
                     * after lm_image_info. Unsigned integers are scaled to [0, 1] exactly as
                     * v / (2^bits - 1) (8-bit: /255, 16-bit: /65535); floats are copied. */
    char (*names)[LM_IMAGE_NAME_LEN]; /* channel names as the file gives them (may be "") */
} lm_image;

/* What a caller accepts, checked against the header before anything is allocated for pixels
 * (0: no limit beyond the generic ones). */
typedef struct lm_image_want {
    int max_channels;
    long long max_pixels; /* width x height */
} lm_image_want;

/* Header only: sizes, channels, bits and names; img->data stays NULL. Free with lm_image_free.
 * Every header is checked (want may be NULL): width and height 1..LM_MAX_IMAGE_SIDE, width x
 * height x channels <= LM_MAX_IMAGE_SAMPLES, samples 8/16-bit unsigned, half or float, the
 * wishes of want, and no more samples than the file can hold (its size x the maximum ratio of
 * its compression, data/limits.h). Errors: LM_ERR_IO (missing file, a directory, unreadable),
 * LM_ERR_UNSUPPORTED (not .png/.tif/.tiff/.exr) or LM_ERR_FORMAT (not an image OpenImageIO can
 * read, or a header failing a check), message "<path>: <problem>". img is zeroed on failure. */
lm_status lm_image_info(const char *path, const lm_image_want *want, lm_image *img, lm_err *e);

/* Read the first subimage entirely (see lm_image.data for the scaling), after the checks of
 * lm_image_info. Truncated or corrupt files give LM_ERR_FORMAT. img is zeroed on failure. */
lm_status lm_image_read(const char *path, const lm_image_want *want, lm_image *img, lm_err *e);
void lm_image_free(lm_image *img);

/* 8-bit RGB (format from path's extension, normally .png): rgb is H*W*3 interleaved in [0, 1],
 * written as round(clamp(v, 0, 1) * 255). No transfer function is applied.
 * NaN -> LM_ERR_NUMERIC. */
lm_status lm_image_write_rgb8(const char *path, int width, int height, const float *rgb,
                              lm_err *e);

/* 16-bit single channel (.png, .tif, .tiff): v is H*W in [0, 1], written as
 * round(clamp(v, 0, 1) * 65535). NaN -> LM_ERR_NUMERIC. */
lm_status lm_image_write_gray16(const char *path, int width, int height, const float *v,
                                lm_err *e);

/* 32-bit float OpenEXR (ZIP compressed), channels planar: data[c*H*W + y*W + x].
 * names: nch channel names (NULL: a single channel is named "Y"). attrs: NULL or a
 * NULL-terminated list of key, value string pairs stored as string attributes. */
lm_status lm_image_write_exr(const char *path, int width, int height, int nch,
                             const char *const *names, const float *data,
                             const char *const *attrs, lm_err *e);

/* The temporary name every atomic writer uses for path: "<path>.tmp.<pid>". Returns 0, or -1
 * if it does not fit in n bytes. */
static inline int lm_tmp_path(char *buf, size_t n, const char *path)
{
    int k = snprintf(buf, n, "%s.tmp.%ld", path, (long)getpid());
    return (k < 0 || (size_t)k >= n) ? -1 : 0;
}

#ifdef __cplusplus
}
#endif
#endif

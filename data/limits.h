/* limits.h — the largest inputs the file readers accept, in one place (listed in
 * docs/guide/troubleshooting.md).
 * What it is: a maximum image side, frame size and cube size, and the most each compression a
 * reader meets can expand (decoded bytes per byte on disk), so that a file of n bytes can only
 * make a reader allocate what n bytes can really decode to. Every reader checks a file's header
 * against these before it allocates anything for the pixels; a file over a limit is
 * LM_ERR_FORMAT with a one-line message naming the file.
 * What it is not: a memory budget for processing (a model's activations, the dataset cache) or
 * a limit on what the writers produce. */
#ifndef LM_LIMITS_H
#define LM_LIMITS_H
#include "tensor/status.h"

#ifdef __cplusplus
extern "C" {
#endif

/* Width or height of any image, frame or cube. */
#define LM_MAX_IMAGE_SIDE 65536
/* Pixels of a coded frame: 2^26 (e.g. 8192 x 8192; 256 MiB as float). */
#define LM_MAX_FRAME_PIXELS (1LL << 26)
/* Values (bands x height x width) of a cube as read: 2^28 (1 GiB as float; e.g. 31 x 2944 x 2944,
 * 30x the largest dataset cube, KAUST's 34 x 512 x 512). */
#define LM_MAX_CUBE_VALUES (1LL << 28)
/* Samples (width x height x channels) of any image read through the OpenImageIO shim. */
#define LM_MAX_IMAGE_SAMPLES (1LL << 28)

/* The most a compressed stream can expand, decoded bytes per stored byte (with LM_DECODE_SLACK
 * on top, so tiny files are never refused). */
#define LM_RATIO_NONE 1       /* uncompressed: the samples are in the file */
#define LM_RATIO_B44 11       /* OpenEXR B44/B44A: a 4 x 4 block of halves (32 bytes) in >= 3 */
#define LM_RATIO_RLE 64       /* TIFF PackBits, OpenEXR RLE: a run of 128 bytes in 2 */
#define LM_RATIO_DEFLATE 1032 /* zlib/deflate (PNG, TIFF and OpenEXR zip, MAT v5 and v7.3): a
                               * 258-byte match per 2 bits; also bounds OpenEXR PIZ (Huffman
                               * with 8-bit run lengths: ~410) and baseline JPEG */
#define LM_RATIO_LZW 1400     /* TIFF LZW (12-bit codes, strings growing by one byte: ~1365);
                               * OpenEXR PXR24 (deflate of 24 of every 32 bits: 1032 x 4/3) */
#define LM_RATIO_OTHER 4096   /* codecs without a tighter bound here (OpenEXR DWAA/DWAB, TIFF
                               * CCITT fax, ...): generous, but still bounded */
#define LM_DECODE_SLACK 65536 /* bytes any file may decode to regardless of its size */

/* The ratio of a codec by name, as OpenImageIO and OpenEXR name them ("none", "zip", "zips",
 * "deflate", "lzw", "packbits", "rle", "piz", "pxr24", "b44", "b44a", "jpeg", ...); NULL or ""
 * is "none"; a name not listed gets LM_RATIO_OTHER. */
int lm_codec_ratio(const char *codec);

/* LM_OK if decoded_bytes <= file_bytes * ratio + LM_DECODE_SLACK, else LM_ERR_FORMAT
 * "<path>: <what> needs N MB of samples, more than a file of B bytes can hold (<codec>
 * expands at most R:1); the file is corrupt or truncated". what describes the claim
 * ("a 3584 x 61452 x 1 image"). */
lm_status lm_limit_decoded(const char *path, const char *what, double decoded_bytes,
                           long long file_bytes, const char *codec, int ratio, lm_err *e);

/* The size of a regular file in bytes, or -1 (missing, not a regular file). */
long long lm_file_bytes(const char *path);

#ifdef __cplusplus
}
#endif
#endif

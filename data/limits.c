/* limits.c — the compression bounds of limits.h and the check every reader makes with them.
 * What it is: codec name -> maximum expansion ratio, the "can this file hold what its header
 * claims" test, the size of a file.
 * What it is not: the per-format header parsing (each reader asks its library). */
#include "data/limits.h"
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

typedef struct codec_bound {
    const char *name;
    int ratio;
} codec_bound;

static const codec_bound codecs[] = {
    {"none", LM_RATIO_NONE},       {"packbits", LM_RATIO_RLE},     {"rle", LM_RATIO_RLE},
    {"b44", LM_RATIO_B44},         {"b44a", LM_RATIO_B44},         {"zip", LM_RATIO_DEFLATE},
    {"zips", LM_RATIO_DEFLATE},    {"deflate", LM_RATIO_DEFLATE},  {"piz", LM_RATIO_DEFLATE},
    {"jpeg", LM_RATIO_DEFLATE},    {"lzw", LM_RATIO_LZW},          {"pxr24", LM_RATIO_LZW},
};

int lm_codec_ratio(const char *codec)
{
    if (!codec || !codec[0]) return LM_RATIO_NONE;
    for (size_t i = 0; i < sizeof codecs / sizeof codecs[0]; i++)
        if (strcasecmp(codec, codecs[i].name) == 0) return codecs[i].ratio;
    return LM_RATIO_OTHER;
}

lm_status lm_limit_decoded(const char *path, const char *what, double decoded_bytes,
                           long long file_bytes, const char *codec, int ratio, lm_err *e)
{
    double can_hold = (double)file_bytes * ratio + LM_DECODE_SLACK;
    if (decoded_bytes <= can_hold) return LM_OK;
    return lm_err_set(e, LM_ERR_FORMAT, "%s: %s needs %.1f MB of samples, more than a file of "
                      "%lld bytes can hold (%s expands at most %d:1): corrupt or truncated",
                      path, what, decoded_bytes / 1e6, file_bytes,
                      codec && codec[0] ? codec : "none", ratio);
}

long long lm_file_bytes(const char *path)
{
    struct stat st;
    if (stat(path, &st) != 0 || !S_ISREG(st.st_mode)) return -1;
    return (long long)st.st_size;
}

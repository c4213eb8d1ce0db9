/* io_exr.c — spectral OpenEXR (Fichet, Pacanowski, Wilkie, JCGT 2021) through OpenEXR's C API.
 * What it is: the reader (channels `T.<nm>nm`, else `S0.<nm>nm`, sorted by wavelength; HALF or
 * FLOAT scanline images) and the atomic writer (FLOAT `T.<nm>nm` channels with a comma and six
 * decimals, attribute spectralLayoutVersion = "1.0", ZIP level 1 scanline chunks), plus the
 * channel name helpers. The reader checks the claimed cube against data/limits.h (size, and
 * what the file can hold under its compression) before allocating it. OpenEXR messages are captured (nothing is printed) and quoted in errors.
 * What it is not: RGB EXR (that is OpenImageIO, image.h), polarised (S1..S3) or tiled/deep
 * spectral images, or units other than nm. */
#include "data/cube_io.h"
#include "data/image.h"
#include "data/limits.h"
#include <errno.h>
#include <math.h>
#include <openexr.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>

#define CHAN_NAME_LEN 48
/* zlib level 1: a 31 x 512 x 512 cube writes in ~1.3 s instead of ~5 s at the default level,
 * for a file ~5 % larger (measured on this machine). */
#define EXR_ZIP_LEVEL 1

/* ---- channel names ------------------------------------------------------------------- */

int lm_spectral_channel_name(char *buf, size_t n, float wavelength_nm)
{
    int k = snprintf(buf, n, "T.%.6fnm", (double)wavelength_nm);
    if (k < 0 || (size_t)k >= n) return -1;
    for (char *p = buf + 2; *p; p++)
        if (*p == '.') *p = ','; /* the layout's decimal separator, whatever the locale */
    return 0;
}

/* Digits at *s into *v (scaled by 10 per digit); returns how many were read. */
static int read_digits(const char **s, double *v)
{
    int n = 0;
    while (**s >= '0' && **s <= '9') {
        *v = *v * 10.0 + (double)(**s - '0');
        (*s)++;
        n++;
    }
    return n;
}

int lm_spectral_channel_parse(const char *name, const char *prefix, double *nm)
{
    size_t lp = strlen(prefix);
    if (strncmp(name, prefix, lp) != 0) return 0;
    const char *s = name + lp;
    double ip = 0.0, fp = 0.0;
    int nd = read_digits(&s, &ip), nf = 0;
    if (*s == ',' || *s == '.') {
        s++;
        const char *f0 = s;
        nf = read_digits(&s, &fp);
        fp /= pow(10.0, (double)(s - f0));
    }
    if (nd + nf == 0) return 0;
    double v = ip + fp, ex = 0.0;
    if (*s == 'e' || *s == 'E') {
        s++;
        int neg = *s == '-';
        if (*s == '+' || *s == '-') s++;
        if (!read_digits(&s, &ex)) return 0;
        v *= pow(10.0, neg ? -ex : ex);
    }
    if (strcmp(s, "nm") != 0 || !(v > 0.0) || !isfinite(v)) return 0;
    *nm = v;
    return 1;
}

/* ---- error capture ------------------------------------------------------------------- */

static _Thread_local char exr_last_msg[256];

static void exr_quiet_handler(exr_const_context_t c, exr_result_t code, const char *msg)
{
    (void)c;
    (void)code;
    if (!exr_last_msg[0]) snprintf(exr_last_msg, sizeof exr_last_msg, "%s", msg ? msg : "");
}

static exr_context_initializer_t exr_init(int reading)
{
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = exr_quiet_handler;
    if (reading) init.flags = EXR_CONTEXT_FLAG_DISABLE_CHUNK_RECONSTRUCTION;
    exr_last_msg[0] = 0;
    return init;
}

static lm_status exr_fail(lm_err *e, lm_status s, const char *path, const char *what,
                          exr_result_t rv)
{
    const char *why = exr_last_msg[0] ? exr_last_msg : exr_get_default_error_message(rv);
    return lm_err_set(e, s, "%s: %s: %s", path, what, why);
}

/* ---- reader -------------------------------------------------------------------------- */

typedef struct spectral_chan {
    const char *name; /* points into the context's channel list */
    double nm;
} spectral_chan;

static int cmp_nm(const void *a, const void *b)
{
    double x = ((const spectral_chan *)a)->nm, y = ((const spectral_chan *)b)->nm;
    return (x > y) - (x < y);
}

/* The spectral channels of part 0: `T.` ones, else `S0.` ones, sorted by wavelength. */
static lm_status find_channels(exr_context_t ctx, const char *path, spectral_chan *sc, int *n,
                               lm_err *e)
{
    const exr_attr_chlist_t *cl;
    exr_result_t rv = exr_get_channels(ctx, 0, &cl);
    if (rv != EXR_ERR_SUCCESS) return exr_fail(e, LM_ERR_FORMAT, path, "no channel list", rv);
    const char *prefixes[2] = {"T.", "S0."};
    *n = 0;
    for (int p = 0; p < 2 && *n == 0; p++) {
        for (int i = 0; i < cl->num_channels; i++) {
            const exr_attr_chlist_entry_t *ch = &cl->entries[i];
            double nm;
            if (!lm_spectral_channel_parse(ch->name.str, prefixes[p], &nm)) continue;
            if (*n == LM_CUBE_MAX_BANDS)
                return lm_err_set(e, LM_ERR_FORMAT, "%s: more than %d spectral channels", path,
                                  LM_CUBE_MAX_BANDS);
            if (ch->pixel_type == EXR_PIXEL_UINT || ch->x_sampling != 1 || ch->y_sampling != 1)
                return lm_err_set(e, LM_ERR_FORMAT, "%s: channel %s must be HALF or FLOAT and "
                                  "not subsampled", path, ch->name.str);
            sc[*n].name = ch->name.str;
            sc[(*n)++].nm = nm;
        }
    }
    if (*n == 0)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: no spectral channels (expected names like "
                          "T.550,000000nm)", path);
    qsort(sc, (size_t)*n, sizeof *sc, cmp_nm);
    for (int i = 1; i < *n; i++)
        if (sc[i].nm == sc[i - 1].nm)
            return lm_err_set(e, LM_ERR_FORMAT, "%s: channels %s and %s have the same wavelength",
                              path, sc[i - 1].name, sc[i].name);
    return LM_OK;
}

static int band_of(const spectral_chan *sc, int n, const char *name)
{
    for (int b = 0; b < n; b++)
        if (strcmp(sc[b].name, name) == 0) return b;
    return -1;
}

/* Point the pipeline's channels at rows [start_y - y0, +height) of their band; others skipped. */
static void point_decoder(exr_decode_pipeline_t *d, const spectral_chan *sc, lm_cube *cube,
                          int y0)
{
    size_t W = (size_t)cube->width;
    for (int c = 0; c < d->channel_count; c++) {
        exr_coding_channel_info_t *ch = &d->channels[c];
        int b = band_of(sc, cube->bands, ch->channel_name);
        ch->decode_to_ptr = b < 0 ? NULL
                                  : (uint8_t *)(lm_cube_band(cube, b) +
                                                (size_t)(d->chunk.start_y - y0) * W);
        ch->user_data_type = EXR_PIXEL_FLOAT;
        ch->user_bytes_per_element = 4;
        ch->user_pixel_stride = 4;
        ch->user_line_stride = (int32_t)(4 * W);
    }
}

static lm_status decode_all(exr_context_t ctx, const char *path, const spectral_chan *sc,
                            lm_cube *cube, int y0, lm_err *e)
{
    int32_t lpc = 0;
    exr_result_t rv = exr_get_scanlines_per_chunk(ctx, 0, &lpc);
    if (rv != EXR_ERR_SUCCESS || lpc <= 0)
        return exr_fail(e, LM_ERR_FORMAT, path, "bad chunk layout", rv);
    exr_decode_pipeline_t dec = EXR_DECODE_PIPELINE_INITIALIZER;
    int started = 0;
    for (int y = y0; rv == EXR_ERR_SUCCESS && y < y0 + cube->height; y += lpc) {
        exr_chunk_info_t ci;
        rv = exr_read_scanline_chunk_info(ctx, 0, y, &ci);
        if (rv == EXR_ERR_SUCCESS)
            rv = started ? exr_decoding_update(ctx, 0, &ci, &dec)
                         : exr_decoding_initialize(ctx, 0, &ci, &dec);
        if (rv != EXR_ERR_SUCCESS) break;
        point_decoder(&dec, sc, cube, y0);
        if (!started && (rv = exr_decoding_choose_default_routines(ctx, 0, &dec)) != 0) break;
        started = 1;
        rv = exr_decoding_run(ctx, 0, &dec);
    }
    if (started) exr_decoding_destroy(ctx, &dec);
    if (rv != EXR_ERR_SUCCESS)
        return exr_fail(e, LM_ERR_FORMAT, path, "truncated or corrupt pixel data", rv);
    return LM_OK;
}

/* The cube the header claims must be within the limits and fit in the file (data/limits.h),
 * checked before it is allocated. */
static lm_status check_claim(exr_context_t ctx, const char *path, const spectral_chan *sc, int n,
                             int64_t W, int64_t H, lm_err *e)
{
    if (W <= 0 || H <= 0 || W > LM_MAX_IMAGE_SIDE || H > LM_MAX_IMAGE_SIDE)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: invalid data window %lld x %lld (at most %d "
                          "per side)", path, (long long)W, (long long)H, LM_MAX_IMAGE_SIDE);
    if ((double)n * W * H > (double)LM_MAX_CUBE_VALUES)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: a %d x %lld x %lld cube is over the limit of "
                          "%lld values", path, n, (long long)H, (long long)W, LM_MAX_CUBE_VALUES);
    static const char *names[] = {"none", "rle", "zips", "zip", "piz", "pxr24", "b44", "b44a",
                                  "dwaa", "dwab"};
    exr_compression_t comp = EXR_COMPRESSION_NONE;
    exr_result_t rv = exr_get_compression(ctx, 0, &comp);
    if (rv != EXR_ERR_SUCCESS || (int)comp < 0 || comp >= EXR_COMPRESSION_LAST_TYPE)
        return exr_fail(e, LM_ERR_FORMAT, path, "bad compression", rv);
    const exr_attr_chlist_t *cl;
    if ((rv = exr_get_channels(ctx, 0, &cl)) != EXR_ERR_SUCCESS)
        return exr_fail(e, LM_ERR_FORMAT, path, "no channel list", rv);
    double bytes = 0.0;
    for (int i = 0; i < cl->num_channels; i++)
        if (band_of(sc, n, cl->entries[i].name.str) >= 0)
            bytes += cl->entries[i].pixel_type == EXR_PIXEL_HALF ? 2.0 : 4.0;
    char what[96];
    snprintf(what, sizeof what, "a %d x %lld x %lld cube", n, (long long)H, (long long)W);
    return lm_limit_decoded(path, what, bytes * (double)W * (double)H, lm_file_bytes(path),
                            names[comp], lm_codec_ratio(names[comp]), e);
}

static lm_status read_part0(exr_context_t ctx, const char *path, lm_cube *cube, lm_err *e)
{
    exr_storage_t storage;
    exr_attr_box2i_t dw;
    exr_result_t rv = exr_get_storage(ctx, 0, &storage);
    if (rv == EXR_ERR_SUCCESS) rv = exr_get_data_window(ctx, 0, &dw);
    if (rv != EXR_ERR_SUCCESS) return exr_fail(e, LM_ERR_FORMAT, path, "bad header", rv);
    if (storage != EXR_STORAGE_SCANLINE)
        return lm_err_set(e, LM_ERR_UNSUPPORTED, "%s: only scanline EXR images are supported "
                          "(this one is tiled or deep)", path);
    spectral_chan sc[LM_CUBE_MAX_BANDS];
    int n = 0;
    lm_status s = find_channels(ctx, path, sc, &n, e);
    if (s != LM_OK) return s;
    int64_t W = (int64_t)dw.max.x - dw.min.x + 1, H = (int64_t)dw.max.y - dw.min.y + 1;
    if ((s = check_claim(ctx, path, sc, n, W, H, e)) != LM_OK) return s;
    s = lm_cube_alloc(cube, n, (int)H, (int)W, 0.0f, 0.0f);
    if (s != LM_OK)
        return lm_err_set(e, s, "%s: cannot allocate a %d x %lld x %lld cube", path, n,
                          (long long)H, (long long)W);
    for (int b = 0; b < n; b++) cube->wavelength[b] = (float)sc[b].nm;
    return decode_all(ctx, path, sc, cube, dw.min.y, e);
}

lm_status lm_cube_read_exr(const char *path, lm_cube *cube, lm_err *e)
{
    memset(cube, 0, sizeof *cube);
    struct stat st;
    if (stat(path, &st) != 0) return lm_err_set(e, LM_ERR_IO, "%s: no such file", path);
    if (S_ISDIR(st.st_mode))
        return lm_err_set(e, LM_ERR_IO, "%s: is a directory, expected an .exr file", path);
    lm_status fchk = lm_file_check(path, "an .exr file", e);
    if (fchk) return fchk;
    exr_context_initializer_t init = exr_init(1);
    exr_context_t ctx = NULL;
    exr_result_t rv = exr_start_read(&ctx, path, &init);
    lm_status s;
    if (rv != EXR_ERR_SUCCESS)
        s = exr_fail(e, LM_ERR_FORMAT, path, "not a readable OpenEXR file", rv);
    else
        s = read_part0(ctx, path, cube, e);
    if (ctx) exr_finish(&ctx);
    if (s == LM_OK) s = lm_cube_apply_sidecar(path, cube, e);
    if (s == LM_OK) s = lm_cube_check_values(cube, path, e);
    if (s != LM_OK) lm_cube_free(cube);
    return s;
}

/* ---- writer -------------------------------------------------------------------------- */

typedef char chan_name[CHAN_NAME_LEN];

static lm_status check_cube_for_write(const char *path, const lm_cube *cube, chan_name *names,
                                      lm_err *e)
{
    if (!cube || !cube->data || cube->bands <= 0 || cube->bands > LM_CUBE_MAX_BANDS ||
        cube->height <= 0 || cube->width <= 0)
        return lm_err_set(e, LM_ERR_ARG, "%s: empty or invalid cube", path);
    for (int b = 0; b < cube->bands; b++) {
        if (!(cube->wavelength[b] > 0.0f) || !isfinite(cube->wavelength[b]) ||
            lm_spectral_channel_name(names[b], CHAN_NAME_LEN, cube->wavelength[b]) != 0)
            return lm_err_set(e, LM_ERR_ARG, "%s: band %d has an invalid wavelength %g", path,
                              b + 1, cube->wavelength[b]);
        for (int a = 0; a < b; a++)
            if (strcmp(names[a], names[b]) == 0)
                return lm_err_set(e, LM_ERR_ARG, "%s: bands %d and %d have the same wavelength "
                                  "(%s)", path, a + 1, b + 1, names[b]);
    }
    return lm_cube_check_values(cube, path, e);
}

static lm_status write_header(exr_context_t ctx, const lm_cube *cube, chan_name *names,
                              const char *path, lm_err *e)
{
    int part = 0;
    exr_result_t rv = exr_add_part(ctx, NULL, EXR_STORAGE_SCANLINE, &part);
    if (rv == EXR_ERR_SUCCESS)
        rv = exr_initialize_required_attr_simple(ctx, part, cube->width, cube->height,
                                                 EXR_COMPRESSION_ZIP);
    if (rv == EXR_ERR_SUCCESS) rv = exr_set_zip_compression_level(ctx, part, EXR_ZIP_LEVEL);
    for (int b = 0; rv == EXR_ERR_SUCCESS && b < cube->bands; b++)
        rv = exr_add_channel(ctx, part, names[b], EXR_PIXEL_FLOAT, EXR_PERCEPTUALLY_LINEAR, 1, 1);
    if (rv == EXR_ERR_SUCCESS) rv = exr_attr_set_string(ctx, part, "spectralLayoutVersion", "1.0");
    if (rv == EXR_ERR_SUCCESS) rv = exr_write_header(ctx);
    return rv == EXR_ERR_SUCCESS ? LM_OK : exr_fail(e, LM_ERR_WRITE, path, "cannot write header", rv);
}

static void point_encoder(exr_encode_pipeline_t *p, const lm_cube *cube, chan_name *names)
{
    size_t W = (size_t)cube->width;
    for (int c = 0; c < p->channel_count; c++) {
        exr_coding_channel_info_t *ch = &p->channels[c];
        int b = 0;
        while (b < cube->bands - 1 && strcmp(names[b], ch->channel_name) != 0) b++;
        ch->encode_from_ptr = (const uint8_t *)(lm_cube_band(cube, b) +
                                                (size_t)p->chunk.start_y * W);
        ch->user_data_type = EXR_PIXEL_FLOAT;
        ch->user_bytes_per_element = 4;
        ch->user_pixel_stride = 4;
        ch->user_line_stride = (int32_t)(4 * W);
    }
}

static lm_status write_pixels(exr_context_t ctx, const lm_cube *cube, chan_name *names,
                              const char *path, lm_err *e)
{
    int32_t lpc = 0;
    exr_result_t rv = exr_get_scanlines_per_chunk(ctx, 0, &lpc);
    if (rv == EXR_ERR_SUCCESS && lpc <= 0) rv = EXR_ERR_UNKNOWN;
    exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
    int started = 0;
    for (int y = 0; rv == EXR_ERR_SUCCESS && y < cube->height; y += lpc) {
        exr_chunk_info_t ci;
        rv = exr_write_scanline_chunk_info(ctx, 0, y, &ci);
        if (rv == EXR_ERR_SUCCESS)
            rv = started ? exr_encoding_update(ctx, 0, &ci, &enc)
                         : exr_encoding_initialize(ctx, 0, &ci, &enc);
        if (rv != EXR_ERR_SUCCESS) break;
        point_encoder(&enc, cube, names);
        if (!started && (rv = exr_encoding_choose_default_routines(ctx, 0, &enc)) != 0) break;
        started = 1;
        rv = exr_encoding_run(ctx, 0, &enc);
    }
    if (started) exr_encoding_destroy(ctx, &enc);
    return rv == EXR_ERR_SUCCESS ? LM_OK : exr_fail(e, LM_ERR_WRITE, path, "cannot write pixels", rv);
}

lm_status lm_cube_write_exr(const char *path, const lm_cube *cube, lm_err *e)
{
    chan_name names[LM_CUBE_MAX_BANDS];
    char tmp[4096];
    if (!path || lm_tmp_path(tmp, sizeof tmp, path) != 0)
        return lm_err_set(e, LM_ERR_ARG, "%s: invalid or too long path", path ? path : "(null)");
    lm_status s = check_cube_for_write(path, cube, names, e);
    if (s != LM_OK) return s;
    exr_context_initializer_t init = exr_init(0);
    exr_context_t ctx = NULL;
    exr_result_t rv = exr_start_write(&ctx, tmp, EXR_WRITE_FILE_DIRECTLY, &init);
    if (rv != EXR_ERR_SUCCESS) s = exr_fail(e, LM_ERR_WRITE, path, "cannot create file", rv);
    if (s == LM_OK) s = write_header(ctx, cube, names, path, e);
    if (s == LM_OK) s = write_pixels(ctx, cube, names, path, e);
    if (ctx) {
        rv = exr_finish(&ctx);
        if (s == LM_OK && rv != EXR_ERR_SUCCESS)
            s = exr_fail(e, LM_ERR_WRITE, path, "cannot finish file", rv);
    }
    if (s == LM_OK && rename(tmp, path) != 0)
        s = lm_err_set(e, LM_ERR_WRITE, "%s: cannot rename the temporary file into place: %s", path,
                       strerror(errno));
    if (s != LM_OK) remove(tmp);
    return s;
}

/* image_oiio.cpp — the one C++ file: a C-callable shim around OpenImageIO (see image.h).
 * What it is: open/read a PNG, TIFF or EXR image as float with its bit depth, after checking its
 * header against the caller's wishes and data/limits.h (nothing is allocated for pixels before;
 * an EXR header is parsed by OpenEXR's C API first, see exr_header_ok),
 * and atomic writers for 8-bit RGB, 16-bit grey and float EXR. No exception crosses the C
 * boundary. PNG files are read with libpng directly (read_png), its errors and warnings caught:
 * OpenImageIO's PNG reader installs no libpng handlers, so libpng printed its own line on stderr
 * before our error for a corrupt PNG.
 * What it is not: a place for format logic (CAVE folders, frame sequences, spectral layouts
 * live in C files that call this). */
#include "data/image.h"
#include "data/limits.h"

#include <OpenImageIO/imageio.h>
#include <openexr.h>
#include <png.h>

#include <cctype>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <string>
#include <strings.h>
#include <sys/stat.h>
#include <vector>
#include <zlib.h>

using OIIO::ImageInput;
using OIIO::ImageOutput;
using OIIO::ImageSpec;
using OIIO::TypeDesc;

/* The file must exist and be a regular file; the message names it. */
static lm_status check_regular_file(const char *path, lm_err *e)
{
    struct stat st;
    if (stat(path, &st) != 0) return lm_err_set(e, LM_ERR_IO, "%s: no such file", path);
    if (S_ISDIR(st.st_mode))
        return lm_err_set(e, LM_ERR_IO, "%s: is a directory, expected an image file", path);
    return lm_file_check(path, "an image file", e);
}

/* OpenImageIO messages can span lines; keep the first line only. */
static std::string first_line(std::string s)
{
    size_t p = s.find('\n');
    if (p != std::string::npos) s.resize(p);
    if (s.empty()) s = "unknown error";
    return s;
}

/* A PNG must hold whole chunks up to IEND, each with a correct CRC. Checked before
 * OpenImageIO sees the file: its PNG reader leaks when libpng hits the end of a truncated
 * file, libpng prints its own complaint about a corrupt chunk on stderr (a second line), and
 * the message is clearer. A .png without the PNG signature is refused here too (libpng would
 * print "PNG file corrupted by ASCII conversion" and the like); another file passes. */
static lm_status png_check(const char *path, bool is_png, lm_err *e)
{
    FILE *f = fopen(path, "rb");
    if (!f) return LM_OK;
    unsigned char b[8], block[65536];
    lm_status s = LM_OK;
    bool sig = fread(b, 1, 8, f) == 8 && std::memcmp(b, "\x89PNG\r\n\x1a\n", 8) == 0;
    if (!sig && is_png)
        s = lm_err_set(e, LM_ERR_FORMAT, "%s: cannot read image: not a PNG file (no PNG "
                       "signature)", path);
    if (sig) {
        fseek(f, 0, SEEK_END);
        long size = ftell(f), pos = 8;
        int ended = 0;
        while (s == LM_OK && !ended && pos + 12 <= size && fseek(f, pos, SEEK_SET) == 0 &&
               fread(b, 1, 8, f) == 8) {
            unsigned long len = (unsigned long)b[0] << 24 | b[1] << 16 | b[2] << 8 | b[3];
            if (len > (unsigned long)(size - pos - 12)) break;
            uLong crc = crc32(0L, b + 4, 4);
            for (unsigned long done = 0; done < len;) {
                size_t k = len - done < sizeof block ? len - done : sizeof block;
                if (fread(block, 1, k, f) != k) break;
                crc = crc32(crc, block, (uInt)k);
                done += k;
            }
            unsigned char c[4];
            if (fread(c, 1, 4, f) != 4 ||
                crc != ((uLong)c[0] << 24 | (uLong)c[1] << 16 | (uLong)c[2] << 8 | c[3])) {
                char type[5];
                for (int i = 0; i < 4; i++) type[i] = std::isalpha(b[4 + i]) ? (char)b[4 + i] : '?';
                type[4] = 0;
                s = lm_err_set(e, LM_ERR_FORMAT, "%s: corrupt PNG: chunk %s at byte %ld fails "
                               "its CRC", path, type, pos);
            }
            ended = std::memcmp(b + 4, "IEND", 4) == 0;
            pos += 12 + (long)len;
        }
        if (s == LM_OK && !ended)
            s = lm_err_set(e, LM_ERR_FORMAT, "%s: truncated PNG (file ends before IEND)", path);
    }
    fclose(f);
    return s;
}

/* OpenEXR's C API (Core) checks every attribute's size against the file while parsing a
 * header; the C++ library behind OpenImageIO's reader allocates what a header claims first
 * (1.76 GB for a 66-byte file with an attribute of that declared size). So an .exr header is
 * parsed by the C API before OpenImageIO sees the file. */
static thread_local char exr_msg[256];

static void exr_quiet(exr_const_context_t, exr_result_t, const char *msg)
{
    if (!exr_msg[0]) snprintf(exr_msg, sizeof exr_msg, "%s", msg ? msg : "");
}

static lm_status exr_header_ok(const char *path, lm_err *e)
{
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    init.error_handler_fn = exr_quiet;
    init.flags = EXR_CONTEXT_FLAG_DISABLE_CHUNK_RECONSTRUCTION;
    exr_msg[0] = 0;
    exr_context_t ctx = NULL;
    exr_result_t rv = exr_start_read(&ctx, path, &init);
    if (ctx) exr_finish(&ctx);
    if (rv == EXR_ERR_SUCCESS) return LM_OK;
    return lm_err_set(e, LM_ERR_FORMAT, "%s: not a readable OpenEXR file: %s", path,
                      first_line(exr_msg[0] ? exr_msg : exr_get_default_error_message(rv)).c_str());
}

static lm_status png_header_ok(const char *path, int w, int h, int ch, int bits,
                               const lm_image_want *want, lm_err *e);

/* ---- PNG through libpng ------------------------------------------------------------------ */
/* libpng reports through these: errors are kept for the lm_err and jump back to read_png;
 * warnings (a damaged ancillary chunk: the image itself is whole) are dropped. */
static void png_on_error(png_structp p, png_const_charp msg)
{
    char *keep = (char *)png_get_error_ptr(p);
    snprintf(keep, 200, "%s", msg ? msg : "libpng error");
    png_longjmp(p, 1);
}
static void png_on_warning(png_structp, png_const_charp) {}

/* Channel names as OpenImageIO gives them: Y; Y A; R G B; R G B A. */
static void png_names(lm_image *img)
{
    static const char *const n[4][4] = {{"Y"}, {"Y", "A"}, {"R", "G", "B"}, {"R", "G", "B", "A"}};
    for (int c = 0; c < img->channels && c < 4; c++)
        snprintf(img->names[c], LM_IMAGE_NAME_LEN, "%s", n[img->channels - 1][c]);
}

/* The samples OpenImageIO's reader gives: palette and grey < 8 bits expanded to 8 bits, tRNS as
 * an alpha channel, 16-bit samples in host order; no gamma. Plain C in here: the longjmp of an
 * error must not skip C++ destructors. */
static lm_status read_png(const char *path, const lm_image_want *want, lm_image *img, int pixels,
                          lm_err *e)
{
    FILE *f = fopen(path, "rb");
    if (!f) return lm_err_set(e, LM_ERR_IO, "%s: cannot open: %s", path, strerror(errno));
    char msg[200] = "";
    png_structp p = png_create_read_struct(PNG_LIBPNG_VER_STRING, msg, png_on_error,
                                           png_on_warning);
    png_infop info = p ? png_create_info_struct(p) : NULL;
    unsigned char *volatile buf = NULL;
    png_bytep *volatile rows = NULL;
    volatile lm_status st = LM_OK;
    if (!info) {
        st = lm_err_set(e, LM_ERR_NOMEM, "%s: out of memory", path);
    } else if (setjmp(png_jmpbuf(p))) {
        st = lm_err_set(e, LM_ERR_FORMAT, "%s: truncated or corrupt image: %s", path, msg);
    } else {
        png_init_io(p, f);
        png_read_info(p, info);
        const int file_bits = png_get_bit_depth(p, info); /* 1, 2, 4 are expanded to 8 */
        png_set_expand(p);
        if (png_get_bit_depth(p, info) == 16) png_set_swap(p); /* little-endian host */
        png_set_interlace_handling(p);
        png_read_update_info(p, info);
        img->width = (int)png_get_image_width(p, info);
        img->height = (int)png_get_image_height(p, info);
        img->channels = png_get_channels(p, info);
        img->bits = file_bits < 8 ? file_bits : png_get_bit_depth(p, info);
        size_t n = (size_t)img->width * img->height * img->channels, rb = png_get_rowbytes(p, info);
        img->names = img->channels >= 1 && img->channels <= 4
                         ? (char(*)[LM_IMAGE_NAME_LEN])calloc((size_t)img->channels,
                                                             LM_IMAGE_NAME_LEN)
                         : NULL;
        if (img->channels < 1 || img->channels > 4)
            st = lm_err_set(e, LM_ERR_FORMAT, "%s: unsupported PNG with %d channels", path,
                            img->channels);
        else st = png_header_ok(path, img->width, img->height, img->channels, img->bits, want, e);
        if (!st && !img->names) st = lm_err_set(e, LM_ERR_NOMEM, "%s: out of memory", path);
        else png_names(img);
        if (!st && pixels) {
            buf = (unsigned char *)malloc(rb * img->height);
            rows = (png_bytep *)malloc(sizeof(png_bytep) * img->height);
            img->data = (float *)malloc(n * sizeof(float));
            if (!buf || !rows || !img->data)
                st = lm_err_set(e, LM_ERR_NOMEM, "%s: out of memory", path);
        }
        if (!st && pixels) {
            for (int y = 0; y < img->height; y++) rows[y] = buf + rb * y;
            png_read_image(p, rows);
            png_read_end(p, NULL);
            const unsigned short *u = (const unsigned short *)(const void *)buf;
            for (size_t i = 0; i < n; i++) /* rows are packed: rb = width * channels * size */
                img->data[i] = img->bits == 16 ? (float)u[i] / 65535.0f : (float)buf[i] / 255.0f;
        }
    }
    png_destroy_read_struct(&p, &info, NULL);
    fclose(f);
    free(buf);
    free(rows);
    return st;
}

static void fill_header(const ImageSpec &sp, lm_image *img)
{
    img->width = sp.width;
    img->height = sp.height;
    img->channels = sp.nchannels;
    int storage = (int)sp.format.size() * 8;
    img->bits = sp.get_int_attribute("oiio:BitsPerSample", storage);
    img->is_float = sp.format.is_floating_point();
    for (int c = 0; c < sp.nchannels; c++) {
        std::string n = c < (int)sp.channelnames.size() ? sp.channelnames[c] : std::string();
        snprintf(img->names[c], LM_IMAGE_NAME_LEN, "%s", n.c_str());
    }
}

/* The OpenImageIO plugin for a path's extension (case-insensitive), or NULL: only these three
 * are ever handed a file, so a file is never tried against OpenImageIO's other readers. */
static const char *plugin_of(const char *path)
{
    const char *slash = std::strrchr(path, '/'), *dot = std::strrchr(path, '.');
    if (!dot || (slash && dot < slash)) return NULL;
    if (!strcasecmp(dot, ".png")) return "png";
    if (!strcasecmp(dot, ".tif") || !strcasecmp(dot, ".tiff")) return "tiff";
    return strcasecmp(dot, ".exr") == 0 ? "openexr" : NULL;
}

static bool sample_type_ok(TypeDesc t)
{
    return t.basetype == TypeDesc::UINT8 || t.basetype == TypeDesc::UINT16 ||
           t.basetype == TypeDesc::HALF || t.basetype == TypeDesc::FLOAT;
}

/* Bytes the samples take in the file's own types (bits per sample for packed integers). */
static double decoded_bytes(const ImageSpec &sp)
{
    double bits = 0.0;
    int packed = sp.get_int_attribute("oiio:BitsPerSample", 0);
    for (int c = 0; c < sp.nchannels; c++) {
        TypeDesc t = sp.channelformat(c);
        bits += packed > 0 && !t.is_floating_point() ? packed : 8.0 * (double)t.size();
    }
    return (double)sp.width * sp.height * bits / 8.0;
}

/* Everything the header says, checked before any pixel is allocated: size, channels, sample
 * types, what the caller accepts, and that the file can hold that many samples. */
static lm_status check_header(const char *path, const char *plugin, const ImageSpec &sp,
                              const lm_image_want *want, lm_err *e)
{
    double pixels = (double)sp.width * sp.height;
    long long max_pixels = want && want->max_pixels > 0 ? want->max_pixels : LM_MAX_IMAGE_SAMPLES;
    if (sp.depth > 1)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: a volume image (depth %d) is not supported",
                          path, sp.depth);
    if (sp.width <= 0 || sp.height <= 0 || sp.nchannels <= 0 || sp.width > LM_MAX_IMAGE_SIDE ||
        sp.height > LM_MAX_IMAGE_SIDE)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: invalid image size %d x %d x %d (at most %d "
                          "per side)", path, sp.width, sp.height, sp.nchannels, LM_MAX_IMAGE_SIDE);
    if (pixels > (double)max_pixels || pixels * sp.nchannels > (double)LM_MAX_IMAGE_SAMPLES)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: image size %d x %d x %d is over the limit of "
                          "%lld pixels (%lld samples)", path, sp.width, sp.height, sp.nchannels,
                          max_pixels, LM_MAX_IMAGE_SAMPLES);
    if (want && want->max_channels == 1 && sp.nchannels > 1)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: has %d channels, expected a single-channel "
                          "image", path, sp.nchannels);
    if (want && want->max_channels > 0 && sp.nchannels > want->max_channels)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: has %d channels, expected at most %d", path,
                          sp.nchannels, want->max_channels);
    for (int c = 0; c < sp.nchannels; c++)
        if (!sample_type_ok(sp.channelformat(c)))
            return lm_err_set(e, LM_ERR_FORMAT, "%s: channel %d has samples of type %s "
                              "(expected 8/16-bit unsigned, half or float)", path, c,
                              sp.channelformat(c).c_str());
    std::string codec = std::strcmp(plugin, "png") == 0
                            ? std::string("deflate")
                            : std::string(sp.get_string_attribute("compression", "none"));
    char what[96];
    snprintf(what, sizeof what, "a %d x %d x %d image", sp.width, sp.height, sp.nchannels);
    return lm_limit_decoded(path, what, decoded_bytes(sp), lm_file_bytes(path), codec.c_str(),
                            lm_codec_ratio(codec.c_str()), e);
}

/* The PNG header (after libpng's expansion: channels, bits) against the caller's wishes and the
 * limits, as check_header does for OpenImageIO's readers. Its own function: the ImageSpec (a C++
 * object) lives and dies here, never across a libpng call that may longjmp. */
static lm_status png_header_ok(const char *path, int w, int h, int ch, int bits,
                               const lm_image_want *want, lm_err *e)
{
    try {
        ImageSpec sp(w, h, ch, bits == 16 ? TypeDesc::UINT16 : TypeDesc::UINT8);
        return check_header(path, "png", sp, want, e);
    } catch (...) {
        return lm_err_set(e, LM_ERR_FORMAT, "%s: cannot read image (exception)", path);
    }
}

/* A .png goes to libpng (after the chunk and CRC check): 1 and *st, or 0 for other files. */
static int png_route(const char *path, const lm_image_want *want, lm_image *img, int pixels,
                     lm_err *e, lm_status *st)
{
    std::memset(img, 0, sizeof *img);
    const char *plugin = plugin_of(path);
    if (!plugin || std::strcmp(plugin, "png")) return 0;
    if ((*st = check_regular_file(path, e)) == LM_OK && (*st = png_check(path, true, e)) == LM_OK)
        *st = read_png(path, want, img, pixels, e);
    if (*st != LM_OK) lm_image_free(img);
    return 1;
}

static lm_status open_input(const char *path, const lm_image_want *want,
                            std::unique_ptr<ImageInput> &in, lm_image *img, lm_err *e)
{
    std::memset(img, 0, sizeof *img);
    lm_status s = check_regular_file(path, e);
    if (s != LM_OK) return s;
    const char *plugin = plugin_of(path);
    if (!plugin)
        return lm_err_set(e, LM_ERR_UNSUPPORTED, "%s: unknown image format (expected .png, "
                          ".tif, .tiff or .exr)", path);
    if ((s = png_check(path, !std::strcmp(plugin, "png"), e)) != LM_OK) return s;
    if (!std::strcmp(plugin, "openexr") && (s = exr_header_ok(path, e)) != LM_OK) return s;
    ImageSpec config, spec;
    config.attribute("oiio:UnassociatedAlpha", 1); /* never premultiply PNG/TIFF alpha */
    in = ImageInput::create(plugin);
    if (!in || !in->open(path, spec, config))
        return lm_err_set(e, LM_ERR_FORMAT, "%s: cannot read image: %s", path,
                          first_line(in ? in->geterror() : OIIO::geterror()).c_str());
    const ImageSpec &sp = in->spec();
    if ((s = check_header(path, plugin, sp, want, e)) != LM_OK) return s;
    img->names = (char(*)[LM_IMAGE_NAME_LEN])calloc((size_t)sp.nchannels, LM_IMAGE_NAME_LEN);
    if (!img->names) return lm_err_set(e, LM_ERR_NOMEM, "%s: out of memory", path);
    fill_header(sp, img);
    return LM_OK;
}

extern "C" lm_status lm_image_info(const char *path, const lm_image_want *want, lm_image *img,
                                   lm_err *e)
{
    lm_status ps;
    if (png_route(path, want, img, 0, e, &ps)) return ps;
    try {
        std::unique_ptr<ImageInput> in;
        lm_status s = open_input(path, want, in, img, e);
        if (s != LM_OK) lm_image_free(img);
        return s;
    } catch (...) {
        lm_image_free(img);
        return lm_err_set(e, LM_ERR_FORMAT, "%s: cannot read image (exception)", path);
    }
}

/* Read all pixels; 8/16-bit unsigned samples are read natively and divided by 255/65535 so the
 * scaling is exactly v / (2^n - 1); everything else is converted to float by OpenImageIO. */
static lm_status read_pixels(const char *path, ImageInput &in, lm_image *img, lm_err *e)
{
    const ImageSpec &sp = in.spec();
    size_t n = (size_t)sp.width * sp.height * sp.nchannels;
    img->data = (float *)malloc(n * sizeof(float));
    if (!img->data) return lm_err_set(e, LM_ERR_NOMEM, "%s: out of memory", path);
    TypeDesc::BASETYPE bt = (TypeDesc::BASETYPE)sp.format.basetype;
    bool native = sp.channelformats.empty() && (bt == TypeDesc::UINT8 || bt == TypeDesc::UINT16);
    bool ok;
    if (native) {
        std::vector<unsigned char> raw(n * sp.format.size());
        ok = in.read_image(0, 0, 0, sp.nchannels, sp.format, raw.data());
        if (ok && bt == TypeDesc::UINT8)
            for (size_t i = 0; i < n; i++) img->data[i] = (float)raw[i] / 255.0f;
        else if (ok) {
            const unsigned short *u = (const unsigned short *)(const void *)raw.data();
            for (size_t i = 0; i < n; i++) img->data[i] = (float)u[i] / 65535.0f;
        }
    } else {
        ok = in.read_image(0, 0, 0, sp.nchannels, TypeDesc::FLOAT, img->data);
    }
    if (!ok)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: truncated or corrupt image: %s", path,
                          first_line(in.geterror()).c_str());
    return LM_OK;
}

extern "C" lm_status lm_image_read(const char *path, const lm_image_want *want, lm_image *img,
                                   lm_err *e)
{
    lm_status s;
    if (png_route(path, want, img, 1, e, &s)) return s;
    try {
        std::unique_ptr<ImageInput> in;
        s = open_input(path, want, in, img, e);
        if (s == LM_OK) s = read_pixels(path, *in, img, e);
    } catch (...) {
        s = lm_err_set(e, LM_ERR_FORMAT, "%s: cannot read image (exception)", path);
    }
    if (s != LM_OK) lm_image_free(img);
    return s;
}

extern "C" void lm_image_free(lm_image *img)
{
    if (!img) return;
    free(img->data);
    free(img->names);
    std::memset(img, 0, sizeof *img);
}

/* ---- writers ------------------------------------------------------------------------- */

/* Write pixels (interleaved, type `fmt`) to a temporary file, then rename it onto path. The
 * format is chosen from path's extension (the temporary name has none that OIIO knows). */
static lm_status write_atomic(const char *path, ImageSpec &spec, const void *pixels, lm_err *e)
{
    char tmp[4096];
    if (lm_tmp_path(tmp, sizeof tmp, path) != 0)
        return lm_err_set(e, LM_ERR_ARG, "%s: path too long", path);
    std::unique_ptr<ImageOutput> out = ImageOutput::create(path);
    if (!out)
        return lm_err_set(e, LM_ERR_UNSUPPORTED, "%s: cannot write this format: %s", path,
                          first_line(OIIO::geterror()).c_str());
    bool ok = out->open(tmp, spec);
    if (ok) ok = out->write_image(spec.format, pixels);
    if (ok) ok = out->close();
    if (!ok) {
        std::string msg = first_line(out->geterror());
        out.reset();
        remove(tmp);
        return lm_err_set(e, LM_ERR_WRITE, "%s: write failed: %s", path, msg.c_str());
    }
    out.reset();
    if (rename(tmp, path) != 0) {
        remove(tmp);
        return lm_err_set(e, LM_ERR_WRITE, "%s: cannot rename the temporary file into place: %s",
                          path, strerror(errno));
    }
    return LM_OK;
}

/* Arguments of the integer writers; v holds w * h pixels of nch samples. */
static lm_status check_args(const char *path, int w, int h, int nch, const float *v, lm_err *e)
{
    if (!path || w <= 0 || h <= 0 || !v)
        return lm_err_set(e, LM_ERR_ARG, "%s: invalid image arguments (%d x %d)",
                          path ? path : "(null)", w, h);
    size_t n = (size_t)w * h * nch;
    for (size_t i = 0; i < n; i++)
        if (std::isnan(v[i])) {
            size_t px = i / (size_t)nch;
            return lm_err_set(e, LM_ERR_NUMERIC, "%s: NaN at (x=%d, y=%d), refusing to write",
                              path, (int)(px % (size_t)w), (int)(px / (size_t)w));
        }
    return LM_OK;
}

template <typename T>
static void quantise(const float *v, size_t n, float maxv, std::vector<T> &q)
{
    q.resize(n);
    for (size_t i = 0; i < n; i++) {
        float x = v[i] < 0.0f ? 0.0f : (v[i] > 1.0f ? 1.0f : v[i]);
        q[i] = (T)std::lround(x * maxv);
    }
}

extern "C" lm_status lm_image_write_rgb8(const char *path, int width, int height,
                                         const float *rgb, lm_err *e)
{
    lm_status s = check_args(path, width, height, 3, rgb, e);
    if (s != LM_OK) return s;
    size_t n = (size_t)width * height * 3;
    try {
        std::vector<unsigned char> q;
        quantise(rgb, n, 255.0f, q);
        ImageSpec spec(width, height, 3, TypeDesc::UINT8);
        return write_atomic(path, spec, q.data(), e);
    } catch (...) {
        return lm_err_set(e, LM_ERR_WRITE, "%s: write failed (exception)", path);
    }
}

extern "C" lm_status lm_image_write_gray16(const char *path, int width, int height,
                                           const float *v, lm_err *e)
{
    lm_status s = check_args(path, width, height, 1, v, e);
    if (s != LM_OK) return s;
    size_t n = (size_t)width * height;
    try {
        std::vector<unsigned short> q;
        quantise(v, n, 65535.0f, q);
        ImageSpec spec(width, height, 1, TypeDesc::UINT16);
        spec.channelnames.assign(1, "Y");
        return write_atomic(path, spec, q.data(), e);
    } catch (...) {
        return lm_err_set(e, LM_ERR_WRITE, "%s: write failed (exception)", path);
    }
}

extern "C" lm_status lm_image_write_exr(const char *path, int width, int height, int nch,
                                        const char *const *names, const float *data,
                                        const char *const *attrs, lm_err *e)
{
    if (!path || width <= 0 || height <= 0 || nch <= 0 || !data || (nch > 1 && !names))
        return lm_err_set(e, LM_ERR_ARG, "%s: invalid EXR arguments (%d x %d x %d)",
                          path ? path : "(null)", width, height, nch);
    try {
        size_t plane = (size_t)width * height;
        std::vector<float> inter(plane * nch);
        for (int c = 0; c < nch; c++)
            for (size_t i = 0; i < plane; i++) inter[i * nch + c] = data[c * plane + i];
        ImageSpec spec(width, height, nch, TypeDesc::FLOAT);
        spec.channelnames.clear();
        for (int c = 0; c < nch; c++) spec.channelnames.push_back(names ? names[c] : "Y");
        spec.alpha_channel = -1;
        spec.attribute("compression", "zip");
        for (int i = 0; attrs && attrs[i] && attrs[i + 1]; i += 2)
            spec.attribute(attrs[i], attrs[i + 1]);
        return write_atomic(path, spec, inter.data(), e);
    } catch (...) {
        return lm_err_set(e, LM_ERR_WRITE, "%s: write failed (exception)", path);
    }
}

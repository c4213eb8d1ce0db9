/* test_cube_io.c — cube readers/writers: CAVE folders, ARAD/KAUST .mat, spectral EXR.
 * Fixtures are generated here in a mkdtemp folder (removed at the end): PNG bands with a
 * minimal encoder of this file (zlib, independent of OpenImageIO), .mat files with matio,
 * EXR files with our C-API writer and, independently, with OpenImageIO (C++ OpenEXR). The real
 * CAVE samples are checked against a minimal PNG decoder of this file. */
#define _GNU_SOURCE
#include "tests/check.h"
#include "tests/shared_dir.h"
#include "tests/fixture.h"
#include "data/cube_io.h"
#include "data/image.h"
#include <dirent.h>
#include <ftw.h>
#include <hdf5.h>
#include <matio.h>
#include <openexr.h>
#include <pthread.h>
#include <stdint.h>
#include <stdlib.h>
#include <sys/stat.h>
#include <unistd.h>
#include <zlib.h>

static int exists(const char *p) { return file_size(p) >= 0; }

static void truncate_copy(const char *src, const char *dst, long keep)
{
    FILE *f = fopen(src, "rb"), *g = fopen(dst, "wb");
    for (long i = 0; f && g && i < keep; i++) {
        int c = fgetc(f);
        if (c == EOF) break;
        fputc(c, g);
    }
    if (f) fclose(f);
    if (g) fclose(g);
}

static void write_bytes(const char *p, const char *bytes, size_t n)
{
    FILE *f = fopen(p, "wb");
    if (f) {
        fwrite(bytes, 1, n, f);
        fclose(f);
    }
}

/* Some "<name>.tmp.<pid>" left in the temporary folder? */
static int tmp_leftovers(void)
{
    DIR *d = opendir(tmpdir);
    struct dirent *de;
    int found = 0;
    while (d && (de = readdir(d)) != NULL) found |= strstr(de->d_name, ".tmp.") != NULL;
    if (d) closedir(d);
    return found;
}

/* ---- a minimal PNG writer / reader (greyscale, 8 or 16 bit), for independent fixtures ---- */

static void put32(unsigned char *p, uint32_t v)
{
    p[0] = (unsigned char)(v >> 24), p[1] = (unsigned char)(v >> 16);
    p[2] = (unsigned char)(v >> 8), p[3] = (unsigned char)v;
}

static uint32_t get32(const unsigned char *p)
{
    return (uint32_t)p[0] << 24 | (uint32_t)p[1] << 16 | (uint32_t)p[2] << 8 | p[3];
}

static void png_chunk(FILE *f, const char *type, const unsigned char *d, uint32_t n)
{
    unsigned char b[4];
    put32(b, n);
    fwrite(b, 1, 4, f);
    fwrite(type, 1, 4, f);
    if (n) fwrite(d, 1, n, f);
    uLong crc = crc32(0, (const Bytef *)type, 4);
    if (n) crc = crc32(crc, d, n);
    put32(b, (uint32_t)crc);
    fwrite(b, 1, 4, f);
}

/* Greyscale PNG (colour type 0), filter 0 on every row; v holds w*h samples. */
static void png_write_grey(const char *path, int w, int h, int depth, const uint16_t *v)
{
    size_t bps = (size_t)depth / 8, row = 1 + (size_t)w * bps, n = row * h;
    unsigned char *raw = calloc(n, 1), ihdr[13] = {0};
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            unsigned char *p = raw + y * row + 1 + x * bps;
            uint16_t s = v[y * w + x];
            if (depth == 16) p[0] = (unsigned char)(s >> 8), p[1] = (unsigned char)s;
            else p[0] = (unsigned char)s;
        }
    uLongf clen = compressBound(n);
    unsigned char *comp = malloc(clen);
    compress2(comp, &clen, raw, n, 6);
    put32(ihdr, (uint32_t)w);
    put32(ihdr + 4, (uint32_t)h);
    ihdr[8] = (unsigned char)depth;
    FILE *f = fopen(path, "wb");
    fwrite("\x89PNG\r\n\x1a\n", 1, 8, f);
    png_chunk(f, "IHDR", ihdr, 13);
    png_chunk(f, "IDAT", comp, (uint32_t)clen);
    png_chunk(f, "IEND", NULL, 0);
    fclose(f);
    free(raw);
    free(comp);
}

/* A 16-bit greyscale PNG header claiming w x h, with one zero row of pixel data: a tiny file
 * whose header asks for a large image. */
static void png_write_claim(const char *path, int w, int h)
{
    size_t row = 1 + 2 * (size_t)w;
    unsigned char *raw = calloc(row, 1), ihdr[13] = {0};
    uLongf clen = compressBound(row);
    unsigned char *comp = malloc(clen);
    compress2(comp, &clen, raw, row, 9);
    put32(ihdr, (uint32_t)w);
    put32(ihdr + 4, (uint32_t)h);
    ihdr[8] = 16;
    FILE *f = fopen(path, "wb");
    fwrite("\x89PNG\r\n\x1a\n", 1, 8, f);
    png_chunk(f, "IHDR", ihdr, 13);
    png_chunk(f, "IDAT", comp, (uint32_t)clen);
    png_chunk(f, "IEND", NULL, 0);
    fclose(f);
    free(raw);
    free(comp);
}

static int paeth(int a, int b, int c)
{
    int p = a + b - c, pa = abs(p - a), pb = abs(p - b), pc = abs(p - c);
    return (pa <= pb && pa <= pc) ? a : (pb <= pc ? b : c);
}

/* Decode a 16-bit greyscale non-interlaced PNG into out (w*h). Returns 0 on success. */
static int png_read_grey16(const char *path, int *w, int *h, uint16_t **out)
{
    FILE *f = fopen(path, "rb");
    if (!f) return -1;
    static unsigned char file[1 << 22];
    size_t n = fread(file, 1, sizeof file, f), idn = 0;
    fclose(f);
    unsigned char *idat = malloc(n);
    for (size_t i = 8; i + 12 <= n;) {
        uint32_t len = get32(file + i);
        if (!memcmp(file + i + 4, "IHDR", 4)) {
            *w = (int)get32(file + i + 8), *h = (int)get32(file + i + 12);
            if (file[i + 16] != 16 || file[i + 17] != 0 || file[i + 20] != 0) return -1;
        }
        if (!memcmp(file + i + 4, "IDAT", 4)) memcpy(idat + idn, file + i + 8, len), idn += len;
        i += 12 + len;
    }
    size_t row = 1 + 2 * (size_t)*w;
    uLongf rawn = row * *h;
    unsigned char *raw = malloc(rawn);
    int bad = uncompress(raw, &rawn, idat, idn) != Z_OK || rawn != row * *h;
    for (int y = 0; !bad && y < *h; y++) {
        unsigned char *r = raw + y * row + 1, *u = y ? raw + (y - 1) * row + 1 : NULL;
        for (size_t i = 0; i < row - 1; i++) {
            int a = i >= 2 ? r[i - 2] : 0, b = u ? u[i] : 0, c = (u && i >= 2) ? u[i - 2] : 0;
            int pred[5] = {0, a, b, (a + b) / 2, paeth(a, b, c)};
            if (r[-1] > 4) bad = 1;
            else r[i] = (unsigned char)(r[i] + pred[r[-1]]);
        }
    }
    *out = malloc(sizeof(uint16_t) * (size_t)*w * *h);
    for (int i = 0; !bad && i < *w * *h; i++) {
        int y = i / *w, x = i % *w;
        const unsigned char *p = raw + y * row + 1 + 2 * x;
        (*out)[i] = (uint16_t)(p[0] << 8 | p[1]);
    }
    free(idat);
    free(raw);
    return bad ? -1 : 0;
}

/* ---- CAVE ------------------------------------------------------------------------------ */


static void test_cave_real_scene(void)
{
    char dir[1024], band[1200];
    snprintf(dir, sizeof dir, "%s/data/cave/balloons_crop100", shared_dir());
    lm_cube c;
    lm_err e = {0};
    CHECK_MSG(lm_cube_read(dir, &c, &e) == LM_OK, "%s", e.msg);
    CHECK(c.bands == 31 && c.height == 100 && c.width == 100);
    if (c.bands != 31 || c.height != 100 || c.width != 100) return;
    CHECK(c.wavelength[0] == 400.0f && c.wavelength[15] == 550.0f && c.wavelength[30] == 700.0f);
    float mx = lm_cube_max(&c), mn = 1.0f;
    for (size_t i = 0; i < (size_t)31 * 100 * 100; i++) mn = c.data[i] < mn ? c.data[i] : mn;
    CHECK(mx > 0.0f && mx <= 1.0f && mn >= 0.0f);
    /* band 17 against an independent decode of the file */
    snprintf(band, sizeof band, "%s/balloons_crop100_ms_17.png", dir);
    int w = 0, h = 0;
    uint16_t *ref = NULL;
    CHECK(png_read_grey16(band, &w, &h, &ref) == 0 && w == 100 && h == 100);
    float expect[100 * 100];
    for (int i = 0; i < 100 * 100; i++) expect[i] = (float)ref[i] / 65535.0f;
    CHECK_ARRAY_CLOSE(lm_cube_band(&c, 16), expect, 100 * 100, 0.0, 0.0);
    free(ref);
    lm_cube_free(&c);
    snprintf(dir, sizeof dir, "%s/data/cave/chart_and_stuffed_toy_crop150", shared_dir());
    CHECK_MSG(lm_cube_read(dir, &c, &e) == LM_OK, "%s", e.msg);
    CHECK(c.bands == 31 && c.height == 150 && c.width == 150 && lm_cube_max(&c) > 0.0f);
    lm_cube_free(&c);
}

/* A scene of 31 w x h bands: sample (b, y, x) = (b*97 + y*13 + x*7 + 1) % (max+1). */
static uint16_t cave_sample(int b, int y, int x, int depth)
{
    int m = depth == 16 ? 65536 : 256;
    return (uint16_t)((b * 9973 + y * 1031 + x * 71 + 1) % m);
}

static void make_scene(const char *dir, const char *scene, int w, int h, int depth)
{
    mkdir(dir, 0755);
    uint16_t *v = malloc(sizeof(uint16_t) * (size_t)w * h);
    for (int b = 0; b < 31; b++) {
        char p[1200];
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++) v[y * w + x] = cave_sample(b, y, x, depth);
        snprintf(p, sizeof p, "%s/%s_ms_%02d.png", dir, scene, b + 1);
        png_write_grey(p, w, h, depth, v);
    }
    free(v);
}

static void check_scene(const lm_cube *c, int w, int h, int depth)
{
    CHECK(c->bands == 31 && c->width == w && c->height == h);
    if (c->bands != 31 || c->width != w || c->height != h) return;
    float *expect = malloc(sizeof(float) * 31 * w * h);
    for (int b = 0; b < 31; b++)
        for (int y = 0; y < h; y++)
            for (int x = 0; x < w; x++)
                expect[(b * h + y) * w + x] =
                    (float)cave_sample(b, y, x, depth) / (depth == 16 ? 65535.0f : 255.0f);
    CHECK_ARRAY_CLOSE(c->data, expect, 31 * w * h, 0.0, 0.0);
    free(expect);
}

static void test_cave_fixtures_8_and_16_bit(void)
{
    char d16[1024], d8[1024], nest[1024], inner[1200];
    lm_cube c;
    lm_err e = {0};
    make_scene(tpath(d16, "s16"), "s16", 7, 5, 16);
    CHECK_MSG(lm_cube_read(d16, &c, &e) == LM_OK, "%s", e.msg);
    check_scene(&c, 7, 5, 16);
    lm_cube_free(&c);
    make_scene(tpath(d8, "s8"), "s8", 4, 6, 8);
    CHECK_MSG(lm_cube_read(d8, &c, &e) == LM_OK, "%s", e.msg);
    check_scene(&c, 4, 6, 8);
    lm_cube_free(&c);
    /* CAVE zips unpack as scene/scene/ */
    mkdir(tpath(nest, "nest"), 0755);
    snprintf(inner, sizeof inner, "%s/nest", nest);
    make_scene(inner, "nest", 3, 2, 16);
    write_bytes(tpath(d8, "nest/readme.txt"), "x", 1);
    CHECK_MSG(lm_cube_read(nest, &c, &e) == LM_OK, "%s", e.msg);
    check_scene(&c, 3, 2, 16);
    lm_cube_free(&c);
}

static void test_cave_rgb_bands(void)
{
    char d[1024], p[1200];
    lm_cube c;
    lm_err e = {0};
    make_scene(tpath(d, "rgb"), "rgb", 3, 2, 8);
    float rgb[3 * 2 * 3];
    for (int i = 0; i < 6; i++)
        rgb[3 * i] = rgb[3 * i + 1] = rgb[3 * i + 2] =
            (float)cave_sample(4, i / 3, i % 3, 8) / 255.0f;
    snprintf(p, sizeof p, "%s/rgb_ms_05.png", d);
    CHECK(lm_image_write_rgb8(p, 3, 2, rgb, &e) == LM_OK);
    CHECK_MSG(lm_cube_read(d, &c, &e) == LM_OK, "equal channels must be accepted: %s", e.msg);
    check_scene(&c, 3, 2, 8);
    lm_cube_free(&c);
    rgb[4] = 0.5f; /* pixel (1, 0): G differs from R */
    CHECK(lm_image_write_rgb8(p, 3, 2, rgb, &e) == LM_OK);
    CHECK(lm_cube_read(d, &c, &e) == LM_ERR_FORMAT && c.data == NULL);
    CHECK_ERR(e, LM_ERR_FORMAT, "rgb_ms_05.png", "greyscale");
}

static void test_cave_errors(void)
{
    char d[1024], p[1200], q[1200];
    lm_cube c;
    lm_err e = {0};
    make_scene(tpath(d, "bad"), "bad", 4, 3, 16);
    snprintf(p, sizeof p, "%s/bad_ms_17.png", d);
    snprintf(q, sizeof q, "%s/keep17.bin", tmpdir);
    rename(p, q);
    CHECK(lm_cube_read(d, &c, &e) == LM_ERR_FORMAT && c.data == NULL);
    CHECK_ERR(e, LM_ERR_FORMAT, "band 17 missing", "bad_ms_17.png");
    lm_err_clear(&e);
    uint16_t small[2 * 2] = {1, 2, 3, 4};
    png_write_grey(p, 2, 2, 16, small); /* band 17 of another size */
    CHECK(lm_cube_read(d, &c, &e) == LM_ERR_FORMAT);
    CHECK_ERR(e, LM_ERR_FORMAT, "bad_ms_17.png", "2 x 2");
    lm_err_clear(&e);
    truncate_copy(q, p, file_size(q) / 2); /* a truncated band */
    CHECK(lm_cube_read(d, &c, &e) == LM_ERR_FORMAT);
    CHECK_ERR(e, LM_ERR_FORMAT, "bad_ms_17.png", "truncated");
    lm_err_clear(&e);
    write_bytes(p, "this is not a png file at all", 29); /* garbage */
    CHECK(lm_cube_read(d, &c, &e) == LM_ERR_FORMAT);
    CHECK_ERR(e, LM_ERR_FORMAT, "bad_ms_17.png", NULL);
    lm_err_clear(&e);
    rename(q, p);
    CHECK(lm_cube_read(d, &c, &e) == LM_OK);
    lm_cube_free(&c);
    snprintf(q, sizeof q, "%s/bad_ms_32.png", d); /* a 32nd band */
    png_write_grey(q, 4, 3, 16, (uint16_t[12]){0});
    CHECK(lm_cube_read(d, &c, &e) == LM_ERR_FORMAT);
    CHECK_ERR(e, LM_ERR_FORMAT, "bad_ms_32.png", "31 bands");
    lm_err_clear(&e);
    remove(q);
    CHECK(lm_cube_read(tpath(q, "no_such_scene"), &c, &e) == LM_ERR_IO);
    CHECK_ERR(e, LM_ERR_IO, "no_such_scene", "no such");
    lm_err_clear(&e);
    mkdir(tpath(q, "empty"), 0755);
    CHECK(lm_cube_read(q, &c, &e) == LM_ERR_FORMAT);
    CHECK_ERR(e, LM_ERR_FORMAT, "empty", "no CAVE band");
    lm_err_clear(&e);
    CHECK(lm_cube_read_cave(p, &c, &e) == LM_ERR_IO); /* a file where a folder is expected */
    CHECK_ERR(e, LM_ERR_IO, "bad_ms_17.png", "folder");
    lm_err_clear(&e);
    /* band headers claiming large images, refused before their pixels are allocated: over the
     * size of band 01, over a cube's size, more than the file holds */
    png_write_claim(p, 8000, 8000);
    CHECK(lm_cube_read(d, &c, &e) == LM_ERR_FORMAT && c.data == NULL);
    CHECK_ERR(e, LM_ERR_FORMAT, "bad_ms_17.png", "limit of 12 pixels");
    lm_err_clear(&e);
    snprintf(q, sizeof q, "%s/bad_ms_01.png", d);
    png_write_claim(q, 8000, 8000);
    CHECK(lm_cube_read(d, &c, &e) == LM_ERR_FORMAT && c.data == NULL);
    CHECK_ERR(e, LM_ERR_FORMAT, "bad_ms_01.png", "8000 x 8000");
    lm_err_clear(&e);
    png_write_claim(q, 2900, 2900);
    CHECK(lm_cube_read(d, &c, &e) == LM_ERR_FORMAT && c.data == NULL);
    CHECK_ERR(e, LM_ERR_FORMAT, "bad_ms_01.png", "can hold");
    lm_err_clear(&e);
    mkdir(tpath(q, "two"), 0755); /* two scenes one level down: ambiguous */
    make_scene(tpath(q, "two/a"), "a", 2, 2, 8);
    make_scene(tpath(q, "two/b"), "b", 2, 2, 8);
    CHECK(lm_cube_read(tpath(q, "two"), &c, &e) == LM_ERR_FORMAT);
    CHECK_ERR(e, LM_ERR_FORMAT, "two", "several sub-folders");
}

/* ---- MAT ------------------------------------------------------------------------------- */

static float arad_value(int b, int y, int x) { return (float)(b * 1000 + y * 31 + x) / 65536.0f; }

/* ARAD-like file: `cube` H x W x B single in MATLAB order, optional `bands`. */
static void write_arad(const char *path, int H, int W, int B, int with_bands, float poison)
{
    float *d = malloc(sizeof(float) * H * W * B);
    for (int b = 0; b < B; b++)
        for (int x = 0; x < W; x++)
            for (int y = 0; y < H; y++) d[y + H * (x + W * b)] = arad_value(b, y, x);
    d[1 + H * (2 + W * 3)] = poison < 0.0f || poison != poison ? poison : d[1 + H * (2 + W * 3)];
    mat_t *m = Mat_CreateVer(path, NULL, MAT_FT_MAT73);
    size_t dims[3] = {(size_t)H, (size_t)W, (size_t)B};
    matvar_t *v = Mat_VarCreate("cube", MAT_C_SINGLE, MAT_T_SINGLE, 3, dims, d, 0);
    Mat_VarWrite(m, v, MAT_COMPRESSION_NONE);
    Mat_VarFree(v);
    if (with_bands) {
        double wl[31];
        for (int i = 0; i < 31; i++) wl[i] = 401.0 + 10.0 * i;
        size_t bd[2] = {1, 31};
        v = Mat_VarCreate("bands", MAT_C_DOUBLE, MAT_T_DOUBLE, 2, bd, wl, 0);
        Mat_VarWrite(m, v, MAT_COMPRESSION_NONE);
        Mat_VarFree(v);
    }
    Mat_Close(m);
    free(d);
}

/* What an HDF5 reader sees: the dataset `cube` as B x W x H. */
static void check_hdf5_view(const char *path, int H, int W, int B)
{
    hid_t f = H5Fopen(path, H5F_ACC_RDONLY, H5P_DEFAULT);
    hid_t ds = H5Dopen2(f, "cube", H5P_DEFAULT);
    hid_t sp = H5Dget_space(ds);
    hsize_t dims[3] = {0};
    CHECK(H5Sget_simple_extent_ndims(sp) == 3);
    H5Sget_simple_extent_dims(sp, dims, NULL);
    CHECK(dims[0] == (hsize_t)B && dims[1] == (hsize_t)W && dims[2] == (hsize_t)H);
    H5Sclose(sp);
    H5Dclose(ds);
    H5Fclose(f);
}

static void test_mat_arad_v73(void)
{
    char p[1024];
    lm_cube c;
    lm_err e = {0};
    const int H = 5, W = 4;
    write_arad(tpath(p, "arad.mat"), H, W, 31, 1, 0.0f);
    check_hdf5_view(p, H, W, 31);
    /* the native reader: bands 401..701 kept as the file gives them (lm_cube_read resamples) */
    CHECK_MSG(lm_cube_read_mat(p, &c, &e) == LM_OK, "%s", e.msg);
    CHECK(c.bands == 31 && c.height == H && c.width == W);
    if (c.bands == 31 && c.height == H && c.width == W) {
        int bad = 0;
        for (int b = 0; b < 31; b++)
            for (int y = 0; y < H; y++)
                for (int x = 0; x < W; x++)
                    bad += lm_cube_band(&c, b)[y * W + x] != arad_value(b, y, x);
        CHECK_MSG(bad == 0, "%d values differ (transposed?)", bad);
        CHECK(c.wavelength[0] == 401.0f && c.wavelength[30] == 701.0f);
    }
    lm_cube_free(&c);
    write_arad(tpath(p, "arad_nobands.mat"), H, W, 31, 0, 0.0f);
    CHECK(lm_cube_read(p, &c, &e) == LM_OK && c.wavelength[1] == 410.0f);
    lm_cube_free(&c);
}

/* Other threads allocate without pause while .mat files are read: a reader started by fork
 * alone inherited whatever lock another thread held at that instant (ASan's allocator, seen as
 * a reader that never finished in CI); the reader must run in a fresh process image. */
typedef struct churn_state {
    volatile int stop;
    unsigned long rounds;
} churn_state;

static void *churn(void *arg)
{
    churn_state *st = arg;
    void *keep[64] = {0};
    unsigned r = 12345u;
    while (!st->stop) {
        r = r * 1103515245u + 12345u;
        int k = (int)(r >> 16) % 64;
        free(keep[k]);
        keep[k] = malloc(16 + (r >> 8) % 8192);
        if (keep[k]) ((char *)keep[k])[0] = 1;
        st->rounds++;
    }
    for (int k = 0; k < 64; k++) free(keep[k]);
    return NULL;
}

static void test_mat_while_threads_allocate(void)
{
    char p[1024];
    write_arad(tpath(p, "busy.mat"), 5, 4, 31, 1, 0.0f);
    churn_state st[2] = {{0, 0}, {0, 0}};
    pthread_t t[2];
    for (int i = 0; i < 2; i++) CHECK(pthread_create(&t[i], NULL, churn, &st[i]) == 0);
    int ok = 0;
    for (int i = 0; i < 40; i++) {
        lm_cube c;
        lm_err e = {0};
        if (lm_cube_read_mat(p, &c, &e) == LM_OK && c.bands == 31) ok++;
        else fprintf(stderr, "  read %d: %s\n", i, e.msg);
        lm_cube_free(&c);
    }
    for (int i = 0; i < 2; i++) st[i].stop = 1;
    for (int i = 0; i < 2; i++) pthread_join(t[i], NULL);
    CHECK_MSG(ok == 40, "%d of 40 reads succeeded", ok);
    CHECK(st[0].rounds > 0 && st[1].rounds > 0);
}

static uint16_t kaust_count(int b, int y, int x)
{
    return (uint16_t)((b * 113 + y * 17 + x * 5) % 4096);
}

static void test_mat_kaust_v5(void)
{
    char p[1024];
    lm_cube c;
    lm_err e = {0};
    const int H = 3, W = 6, B = 34;
    uint16_t d[3 * 6 * 34];
    for (int b = 0; b < B; b++)
        for (int x = 0; x < W; x++)
            for (int y = 0; y < H; y++) d[y + H * (x + W * b)] = kaust_count(b, y, x);
    mat_t *m = Mat_CreateVer(tpath(p, "kaust.mat"), NULL, MAT_FT_MAT5);
    size_t dims[3] = {H, W, B};
    matvar_t *v = Mat_VarCreate("hsi", MAT_C_UINT16, MAT_T_UINT16, 3, dims, d, 0);
    Mat_VarWrite(m, v, MAT_COMPRESSION_ZLIB);
    Mat_VarFree(v);
    Mat_Close(m);
    CHECK_MSG(lm_cube_read(p, &c, &e) == LM_OK, "%s", e.msg);
    CHECK(c.bands == 31 && c.height == H && c.width == W);
    if (c.bands == 31 && c.height == H && c.width == W) {
        float expect[31 * 3 * 6];
        for (int b = 0; b < 31; b++)
            for (int y = 0; y < H; y++)
                for (int x = 0; x < W; x++)
                    expect[(b * H + y) * W + x] = (float)kaust_count(b, y, x) / 4095.0f;
        CHECK_ARRAY_CLOSE(c.data, expect, 31 * H * W, 0.0, 1e-7);
        CHECK(c.wavelength[0] == 400.0f && c.wavelength[30] == 700.0f);
    }
    lm_cube_free(&c);
}

/* KAUST-like v5 file: `hsi` H x W x B uint16, plain or zlib-compressed. */
static void write_kaust(const char *path, int H, int W, int B, int zip)
{
    uint16_t *d = malloc(sizeof(uint16_t) * H * W * B);
    for (int i = 0; i < H * W * B; i++) d[i] = (uint16_t)((i * 2654435761u) >> 20);
    mat_t *m = Mat_CreateVer(path, NULL, MAT_FT_MAT5);
    size_t dims[3] = {(size_t)H, (size_t)W, (size_t)B};
    matvar_t *v = Mat_VarCreate("hsi", MAT_C_UINT16, MAT_T_UINT16, 3, dims, d, 0);
    Mat_VarWrite(m, v, zip ? MAT_COMPRESSION_ZLIB : MAT_COMPRESSION_NONE);
    Mat_VarFree(v);
    Mat_Close(m);
    free(d);
}

/* A v5 file cut short (plain or compressed) used to read its missing bands as zeros. */
static void test_mat_truncated_v5(void)
{
    char p[1024], q[1024];
    lm_cube c;
    lm_err e = {0};
    for (int zip = 0; zip < 2; zip++) {
        write_kaust(tpath(q, zip ? "kz.mat" : "kp.mat"), 20, 16, 34, zip);
        CHECK_MSG(lm_cube_read(q, &c, &e) == LM_OK, "%s", e.msg);
        lm_cube_free(&c);
        long n = file_size(q), keep[5] = {n - 1, n - 8, n * 2 / 3, n / 2, 140};
        for (int i = 0; i < 5; i++) {
            truncate_copy(q, tpath(p, "cut5.mat"), keep[i]);
            CHECK_MSG(lm_cube_read(p, &c, &e) == LM_ERR_FORMAT && c.data == NULL,
                      "zip %d, kept %ld of %ld: %s", zip, keep[i], n, e.msg);
            CHECK_ERR(e, LM_ERR_FORMAT, "cut5.mat", "truncated");
            lm_err_clear(&e);
        }
    }
    /* dimensions patched to claim more values than the data holds (plain file: the dims
     * element's first value is at byte 128 + 8 + 16 + 8) */
    write_kaust(tpath(p, "dims.mat"), 3, 6, 34, 0);
    FILE *f = fopen(p, "r+b");
    CHECK(f && fseek(f, 160, SEEK_SET) == 0 && fputc(4, f) == 4);
    if (f) fclose(f);
    CHECK(lm_cube_read(p, &c, &e) == LM_ERR_FORMAT && c.data == NULL);
    CHECK_ERR(e, LM_ERR_FORMAT, "dims.mat", "holds 1224 bytes of data for 816 values");
    lm_err_clear(&e);
    /* a compressed stream damaged in its middle, the file's size unchanged */
    write_kaust(tpath(p, "zbad.mat"), 20, 16, 34, 1);
    f = fopen(p, "r+b");
    long mid = file_size(p) / 2;
    CHECK(f && fseek(f, mid, SEEK_SET) == 0);
    for (int i = 0; f && i < 16; i++) fputc(0xA5 ^ i, f);
    if (f) fclose(f);
    CHECK(lm_cube_read(p, &c, &e) == LM_ERR_FORMAT && c.data == NULL);
    CHECK_ERR(e, LM_ERR_FORMAT, "zbad.mat", "hsi");
    lm_err_clear(&e);
}

/* Regression inputs of tests/fuzz/regress/mat: the reliability file whose corrupt attribute
 * makes libhdf5 read out of bounds (SEGV, depending on the heap: see cli_hostile, which runs
 * it with glibc.malloc.top_pad=0 where it always faulted), and a 200-byte v5 struct whose
 * field-name tag claims 3.4 GB (matio tried malloc(3.4 GB) and calloc(27 GB)). */
static void test_mat_hostile(void)
{
    const char *files[2] = {"tests/fuzz/regress/mat/mat-hdf5-corrupt-byte.mat",
                            "tests/fuzz/regress/mat/mat5-struct-huge-fields.mat"};
    for (int i = 0; i < 2; i++) {
        lm_cube c;
        lm_err e = {0};
        CHECK_MSG(lm_cube_read(files[i], &c, &e) == LM_ERR_FORMAT && c.data == NULL, "%s: %s",
                  files[i], e.msg);
        CHECK_ERR(e, LM_ERR_FORMAT, files[i], NULL);
    }
}

static void test_mat_errors(void)
{
    char p[1024], q[1024];
    lm_cube c;
    lm_err e = {0};
    write_arad(tpath(p, "b30.mat"), 3, 2, 30, 0, 0.0f); /* 30 bands, no wavelengths */
    CHECK(lm_cube_read(p, &c, &e) == LM_ERR_FORMAT && c.data == NULL);
    CHECK_ERR(e, LM_ERR_FORMAT, "b30.mat", "30 bands and no wavelength list");
    lm_err_clear(&e);
    write_arad(tpath(p, "nan.mat"), 3, 4, 31, 0, NAN);
    CHECK(lm_cube_read(p, &c, &e) == LM_ERR_NUMERIC && c.data == NULL);
    CHECK_ERR(e, LM_ERR_NUMERIC, "nan.mat", "band 4 (430.0 nm) has NaN");
    lm_err_clear(&e);
    write_arad(tpath(p, "neg.mat"), 3, 4, 31, 0, -0.25f);
    CHECK(lm_cube_read(p, &c, &e) == LM_ERR_NUMERIC);
    CHECK_ERR(e, LM_ERR_NUMERIC, "neg.mat", "x=2, y=1");
    lm_err_clear(&e);
    mat_t *m = Mat_CreateVer(tpath(p, "nokey.mat"), NULL, MAT_FT_MAT5);
    size_t dims[2] = {1, 1};
    double one = 1.0;
    matvar_t *v = Mat_VarCreate("other", MAT_C_DOUBLE, MAT_T_DOUBLE, 2, dims, &one, 0);
    Mat_VarWrite(m, v, MAT_COMPRESSION_NONE);
    Mat_VarFree(v);
    Mat_Close(m);
    CHECK(lm_cube_read(p, &c, &e) == LM_ERR_FORMAT);
    CHECK_ERR(e, LM_ERR_FORMAT, "nokey.mat", "holds: other");
    lm_err_clear(&e);
    write_arad(tpath(q, "full.mat"), 40, 30, 31, 1, 0.0f);
    long sizes[3] = {file_size(q) / 2, file_size(q) - 3000, 600};
    for (int i = 0; i < 3; i++) {
        truncate_copy(q, tpath(p, "trunc.mat"), sizes[i]);
        CHECK_MSG(lm_cube_read(p, &c, &e) != LM_OK && c.data == NULL, "kept %ld", sizes[i]);
        CHECK_ERR(e, LM_ERR_FORMAT, "trunc.mat", "truncated");
        lm_err_clear(&e);
    }
    write_bytes(tpath(p, "garbage.mat"), "MATLAB 5.0 MAT-file, garbage follows \x01\x02", 40);
    CHECK(lm_cube_read(p, &c, &e) == LM_ERR_FORMAT);
    CHECK_ERR(e, LM_ERR_FORMAT, "garbage.mat", NULL);
    lm_err_clear(&e);
    mkdir(tpath(p, "dir.mat"), 0755); /* a folder named .mat is read as a CAVE folder */
    CHECK(lm_cube_read_mat(p, &c, &e) == LM_ERR_IO);
    CHECK_ERR(e, LM_ERR_IO, "dir.mat", "directory");
    lm_err_clear(&e);
    CHECK(lm_cube_read(tpath(p, "missing.mat"), &c, &e) == LM_ERR_IO);
    CHECK_ERR(e, LM_ERR_IO, "missing.mat", "no such");
}

/* ---- spectral EXR ------------------------------------------------------------------------ */

static float fill_value(size_t i) { return (float)(i % 977) * 0.0137f + 1e-3f; }

static void fill_cube(lm_cube *c, int bands, int h, int w)
{
    lm_cube_alloc(c, bands, h, w, 400.0f, 10.0f);
    for (size_t i = 0; i < (size_t)bands * h * w; i++) c->data[i] = fill_value(i);
}

static int file_contains(const char *path, const char *needle, size_t n)
{
    static char buf[1 << 16];
    FILE *f = fopen(path, "rb");
    if (!f) return 0;
    size_t k = fread(buf, 1, sizeof buf, f);
    fclose(f);
    return memmem(buf, k, needle, n) != NULL;
}

static void test_channel_names(void)
{
    char b[64];
    double nm;
    CHECK(lm_spectral_channel_name(b, sizeof b, 550.0f) == 0 && !strcmp(b, "T.550,000000nm"));
    CHECK(lm_spectral_channel_name(b, sizeof b, 412.5f) == 0 && !strcmp(b, "T.412,500000nm"));
    CHECK(lm_spectral_channel_name(b, 8, 412.5f) == -1);
    CHECK(lm_spectral_channel_parse("T.550,000000nm", "T.", &nm) && nm == 550.0);
    CHECK(lm_spectral_channel_parse("T.412.25nm", "T.", &nm) && nm == 412.25);
    CHECK(lm_spectral_channel_parse("S0.700nm", "S0.", &nm) && nm == 700.0);
    CHECK(lm_spectral_channel_parse("T.5,5e2nm", "T.", &nm) && nm == 550.0);
    CHECK(!lm_spectral_channel_parse("T.550,0Hz", "T.", &nm));
    CHECK(!lm_spectral_channel_parse("T.nm", "T.", &nm));
    CHECK(!lm_spectral_channel_parse("S0.550nm", "T.", &nm));
    CHECK(!lm_spectral_channel_parse("T.550nmx", "T.", &nm));
    CHECK(!lm_spectral_channel_parse("T.-550nm", "T.", &nm));
}

static void test_exr_round_trip(void)
{
    char p[1024];
    lm_cube c, r;
    lm_err e = {0};
    fill_cube(&c, 31, 37, 23); /* 37 rows: two full 16-line ZIP chunks and a partial one */
    c.wavelength[5] = 450.5f;
    c.wavelength[30] = 1000.0f; /* "T.1000,..." sorts first as text: the reader must sort by nm */
    CHECK_MSG(lm_cube_write_exr(tpath(p, "rt.exr"), &c, &e) == LM_OK, "%s", e.msg);
    CHECK(!tmp_leftovers());
    CHECK(file_contains(p, "spectralLayoutVersion\0string", 29));
    CHECK(file_contains(p, "T.450,500000nm", 14) && file_contains(p, "T.1000,000000nm", 15));
    CHECK_MSG(lm_cube_read_exr(p, &r, &e) == LM_OK, "%s", e.msg);
    CHECK(r.bands == 31 && r.height == 37 && r.width == 23);
    if (r.bands == 31 && r.height == 37 && r.width == 23) {
        CHECK_ARRAY_CLOSE(r.data, c.data, 31 * 37 * 23, 0.0, 0.0);
        CHECK_ARRAY_CLOSE(r.wavelength, c.wavelength, 31, 0.0, 0.0);
    }
    lm_cube_free(&r);
    /* an independent reader (OpenImageIO / C++ OpenEXR) sees the same values per channel */
    lm_image im;
    CHECK_MSG(lm_image_read(p, NULL, &im, &e) == LM_OK, "%s", e.msg);
    CHECK(im.channels == 31 && im.width == 23 && im.height == 37 && im.is_float);
    for (int ch = 0; ch < im.channels && im.channels == 31; ch++) {
        double nm = 0;
        CHECK(lm_spectral_channel_parse(im.names[ch], "T.", &nm));
        int b = 0;
        while (b < 30 && c.wavelength[b] != (float)nm) b++;
        int bad = 0;
        for (int i = 0; i < 37 * 23; i++) bad += im.data[i * 31 + ch] != lm_cube_band(&c, b)[i];
        CHECK_MSG(bad == 0, "channel %s: %d values differ", im.names[ch], bad);
    }
    lm_image_free(&im);
    lm_cube_free(&c);
}

static void test_exr_written_by_another_library(void)
{
    char p[1024];
    lm_cube r;
    lm_err e = {0};
    /* channels out of order, with others mixed in; 1000 nm sorts before 400 nm as text */
    const char *names[5] = {"T.650,5nm", "R", "T.1000,000000nm", "S0.500,000000nm",
                            "T.400,000000nm"};
    const char *attrs[] = {"spectralLayoutVersion", "1.0", NULL};
    float d[5 * 3 * 2];
    for (int i = 0; i < 30; i++) d[i] = (float)i / 8.0f;
    CHECK(lm_image_write_exr(tpath(p, "oiio.exr"), 2, 3, 5, names, d, attrs, &e) == LM_OK);
    CHECK_MSG(lm_cube_read_exr(p, &r, &e) == LM_OK, "%s", e.msg);
    CHECK(r.bands == 3 && r.height == 3 && r.width == 2);
    if (r.bands == 3) {
        CHECK(r.wavelength[0] == 400.0f && r.wavelength[1] == 650.5f &&
              r.wavelength[2] == 1000.0f);
        CHECK_ARRAY_CLOSE(lm_cube_band(&r, 0), d + 24, 6, 0.0, 0.0);
        CHECK_ARRAY_CLOSE(lm_cube_band(&r, 1), d + 0, 6, 0.0, 0.0);
        CHECK_ARRAY_CLOSE(lm_cube_band(&r, 2), d + 12, 6, 0.0, 0.0);
    }
    lm_cube_free(&r);
    const char *emissive[2] = {"S0.600nm", "S0.500nm"};
    CHECK(lm_image_write_exr(tpath(p, "s0.exr"), 2, 3, 2, emissive, d, NULL, &e) == LM_OK);
    CHECK_MSG(lm_cube_read_exr(p, &r, &e) == LM_OK, "%s", e.msg);
    CHECK(r.bands == 2 && r.wavelength[0] == 500.0f && r.data && r.data[0] == d[6]);
    lm_cube_free(&r);
    const char *rgb[3] = {"R", "G", "B"};
    CHECK(lm_image_write_exr(tpath(p, "rgb.exr"), 2, 3, 3, rgb, d, NULL, &e) == LM_OK);
    CHECK(lm_cube_read_exr(p, &r, &e) == LM_ERR_FORMAT && r.data == NULL);
    CHECK_ERR(e, LM_ERR_FORMAT, "rgb.exr", "no spectral channels");
    lm_err_clear(&e);
    d[3 * 2 + 5] = NAN; /* band 2 of the S0 file, pixel (1, 2) */
    CHECK(lm_image_write_exr(tpath(p, "nan.exr"), 2, 3, 2, emissive, d, NULL, &e) == LM_OK);
    CHECK(lm_cube_read_exr(p, &r, &e) == LM_ERR_NUMERIC && r.data == NULL);
    CHECK_ERR(e, LM_ERR_NUMERIC, "nan.exr", "band 1 (500.0 nm) has NaN");
}

/* A scanline EXR with HALF channels, written with OpenEXR's C API directly (no compression);
 * data is planar, one w*h plane per channel. Returns 0 on success. */
static int write_half_exr(const char *path, int w, int h, int nch, const char *const *names,
                          const uint16_t *data)
{
    exr_context_t ctx;
    exr_context_initializer_t init = EXR_DEFAULT_CONTEXT_INITIALIZER;
    int part, rv = exr_start_write(&ctx, path, EXR_WRITE_FILE_DIRECTLY, &init);
    if (rv) return rv;
    rv = exr_add_part(ctx, NULL, EXR_STORAGE_SCANLINE, &part);
    if (!rv) rv = exr_initialize_required_attr_simple(ctx, part, w, h, EXR_COMPRESSION_NONE);
    for (int c = 0; !rv && c < nch; c++)
        rv = exr_add_channel(ctx, part, names[c], EXR_PIXEL_HALF, EXR_PERCEPTUALLY_LINEAR, 1, 1);
    if (!rv) rv = exr_write_header(ctx);
    exr_encode_pipeline_t enc = EXR_ENCODE_PIPELINE_INITIALIZER;
    for (int y = 0; !rv && y < h; y++) { /* NONE: one scanline per chunk */
        exr_chunk_info_t ci;
        rv = exr_write_scanline_chunk_info(ctx, part, y, &ci);
        if (!rv) rv = y ? exr_encoding_update(ctx, part, &ci, &enc)
                        : exr_encoding_initialize(ctx, part, &ci, &enc);
        for (int c = 0; !rv && c < enc.channel_count; c++) {
            int k = 0;
            while (k < nch - 1 && strcmp(names[k], enc.channels[c].channel_name)) k++;
            enc.channels[c].encode_from_ptr = (const uint8_t *)(data + (size_t)k * w * h + y * w);
            enc.channels[c].user_pixel_stride = 2;
            enc.channels[c].user_line_stride = 2 * w;
        }
        if (!rv && y == 0) rv = exr_encoding_choose_default_routines(ctx, part, &enc);
        if (!rv) rv = exr_encoding_run(ctx, part, &enc);
    }
    exr_encoding_destroy(ctx, &enc);
    int rf = exr_finish(&ctx);
    return rv ? rv : rf;
}

static void test_exr_half_channels(void)
{
    char p[1024];
    lm_cube r;
    lm_err e = {0};
    /* half bit patterns: 0x3C00 = 1, 0x3800 = 0.5, 0x3555 = 0.333251953125, 0x0001 = 2^-24 */
    const uint16_t bits[4] = {0x3C00, 0x3800, 0x3555, 0x0001};
    const float vals[4] = {1.0f, 0.5f, 0.333251953125f, 5.9604644775390625e-8f};
    uint16_t d[2 * 3 * 2];
    float expect[2 * 3 * 2];
    for (int i = 0; i < 12; i++) d[i] = bits[(i * 3) % 4], expect[i] = vals[(i * 3) % 4];
    const char *names[2] = {"T.600nm", "T.500nm"};
    CHECK(write_half_exr(tpath(p, "half.exr"), 3, 2, 2, names, d) == 0);
    CHECK_MSG(lm_cube_read_exr(p, &r, &e) == LM_OK, "%s", e.msg);
    CHECK(r.bands == 2 && r.width == 3 && r.height == 2);
    if (r.bands == 2 && r.width == 3 && r.height == 2) {
        CHECK(r.wavelength[0] == 500.0f && r.wavelength[1] == 600.0f);
        CHECK_ARRAY_CLOSE(lm_cube_band(&r, 0), expect + 6, 6, 0.0, 0.0);
        CHECK_ARRAY_CLOSE(lm_cube_band(&r, 1), expect, 6, 0.0, 0.0);
    }
    lm_cube_free(&r);
}

/* Copy an EXR with its dataWindow attribute changed to (0, 0) .. (w - 1, h - 1). 0 on success. */
static int claim_window(const char *src, const char *dst, int w, int h)
{
    static unsigned char buf[1 << 20];
    FILE *f = fopen(src, "rb");
    size_t n = f ? fread(buf, 1, sizeof buf, f) : 0;
    if (f) fclose(f);
    const char key[] = "dataWindow\0box2i\0";
    unsigned char *at = memmem(buf, n, key, sizeof key - 1);
    if (!at || at + sizeof key - 1 + 4 + 16 > buf + n) return -1;
    int32_t box[4] = {0, 0, w - 1, h - 1}; /* little-endian host, as the file */
    memcpy(at + sizeof key - 1 + 4, box, sizeof box);
    write_bytes(dst, (const char *)buf, n);
    return 0;
}

static void test_exr_bad_files(void)
{
    char p[1024], q[1024];
    lm_cube c;
    lm_err e = {0};
    fill_cube(&c, 31, 40, 30);
    CHECK(lm_cube_write_exr(tpath(q, "good.exr"), &c, &e) == LM_OK);
    long n = file_size(q), keep[4] = {n - 1, n / 2, 400, 10};
    for (int i = 0; i < 4; i++) {
        lm_cube r;
        truncate_copy(q, tpath(p, "cut.exr"), keep[i]);
        CHECK_MSG(lm_cube_read(p, &r, &e) == LM_ERR_FORMAT && r.data == NULL, "kept %ld: %s",
                  keep[i], e.msg);
        CHECK_ERR(e, LM_ERR_FORMAT, "cut.exr", NULL);
        lm_err_clear(&e);
    }
    write_bytes(tpath(p, "junk.exr"), "\x76\x2f\x31\x01 garbage garbage garbage", 28);
    CHECK(lm_cube_read(p, &(lm_cube){0}, &e) == LM_ERR_FORMAT);
    CHECK_ERR(e, LM_ERR_FORMAT, "junk.exr", NULL);
    lm_err_clear(&e);
    write_bytes(tpath(p, "text.exr"), "hello", 5);
    CHECK(lm_cube_read_exr(p, &(lm_cube){0}, &e) == LM_ERR_FORMAT);
    CHECK_ERR(e, LM_ERR_FORMAT, "text.exr", "OpenEXR");
    lm_err_clear(&e);
    mkdir(tpath(p, "folder.exr"), 0755);
    CHECK(lm_cube_read_exr(p, &(lm_cube){0}, &e) == LM_ERR_IO);
    CHECK_ERR(e, LM_ERR_IO, "folder.exr", "directory");
    lm_err_clear(&e);
    CHECK(lm_cube_read(tpath(p, "cube.txt"), &(lm_cube){0}, &e) == LM_ERR_IO);
    write_bytes(p, "1 2 3", 5);
    lm_err_clear(&e);
    CHECK(lm_cube_read(p, &(lm_cube){0}, &e) == LM_ERR_UNSUPPORTED);
    CHECK_ERR(e, LM_ERR_UNSUPPORTED, "cube.txt", "unknown cube format");
    lm_err_clear(&e);
    /* a data window claiming a large cube: refused from the header, before the allocation */
    int wins[3][2] = {{2900, 2900}, {8000, 8000}, {70000, 3}};
    const char *why[3] = {"can hold", "31 x 8000 x 8000 cube is over the limit", "70000 x 3"};
    for (int i = 0; i < 3; i++) {
        lm_cube r;
        CHECK(claim_window(q, tpath(p, "claim.exr"), wins[i][0], wins[i][1]) == 0);
        CHECK(lm_cube_read(p, &r, &e) == LM_ERR_FORMAT && r.data == NULL);
        CHECK_ERR(e, LM_ERR_FORMAT, "claim.exr", why[i]);
        lm_err_clear(&e);
    }
    lm_cube_free(&c);
}

static void test_exr_write_is_atomic(void)
{
    char p[1024];
    lm_cube c, r;
    lm_err e = {0};
    fill_cube(&c, 3, 4, 5);
    CHECK(lm_cube_write_exr(tpath(p, "atomic.exr"), &c, &e) == LM_OK);
    long before = file_size(p);
    c.data[7] = NAN; /* band 1, (x=2, y=1) */
    CHECK(lm_cube_write_exr(p, &c, &e) == LM_ERR_NUMERIC);
    CHECK_ERR(e, LM_ERR_NUMERIC, "atomic.exr", "band 1 (400.0 nm) has NaN (nan) at (x=2, y=1)");
    lm_err_clear(&e);
    c.data[7] = -1.0f;
    CHECK(lm_cube_write_exr(p, &c, &e) == LM_ERR_NUMERIC);
    lm_err_clear(&e);
    c.data[7] = 0.5f;
    c.wavelength[2] = c.wavelength[1];
    CHECK(lm_cube_write_exr(p, &c, &e) == LM_ERR_ARG);
    CHECK_ERR(e, LM_ERR_ARG, "atomic.exr", "same wavelength");
    lm_err_clear(&e);
    CHECK(file_size(p) == before && !tmp_leftovers());
    CHECK(lm_cube_read_exr(p, &r, &e) == LM_OK && r.bands == 3 && r.data[7] == fill_value(7));
    lm_cube_free(&r);
    c.wavelength[2] = 420.0f;
    CHECK(lm_cube_write_exr(tpath(p, "no_dir/x.exr"), &c, &e) == LM_ERR_WRITE);
    CHECK_ERR(e, LM_ERR_WRITE, "no_dir/x.exr", NULL);
    CHECK(!exists(p) && !tmp_leftovers());
    lm_cube_free(&c);
}

int main(void)
{
    snprintf(tmpdir, sizeof tmpdir, "/tmp/lm_cube_io_XXXXXX");
    if (!mkdtemp(tmpdir)) {
        perror("mkdtemp");
        return 1;
    }
    RUN(test_cave_real_scene);
    RUN(test_cave_fixtures_8_and_16_bit);
    RUN(test_cave_rgb_bands);
    RUN(test_cave_errors);
    RUN(test_mat_arad_v73);
    RUN(test_mat_kaust_v5);
    RUN(test_mat_errors);
    RUN(test_mat_truncated_v5);
    RUN(test_mat_hostile);
    RUN(test_mat_while_threads_allocate);
    RUN(test_channel_names);
    RUN(test_exr_round_trip);
    RUN(test_exr_written_by_another_library);
    RUN(test_exr_half_channels);
    RUN(test_exr_bad_files);
    RUN(test_exr_write_is_atomic);
    fixture_cleanup();
    return check_summary();
}

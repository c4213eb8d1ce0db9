/* doe.c — DOE description (JSON, doe.h), its quantised height map, and height map -> PSF by a
 * single-FFT Fresnel transform (FFTW, single precision) resampled to the sensor pixels.
 * What it is not: the camera convolution (qdocam.c) or any gradient of the PSF. */
#include "data/doe.h"
#include "data/spectra.h"
#include "data/image.h"
#include "data/util.h"
#include <fftw3.h>
#include <jansson.h>
#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>

/* ---- parsing ----------------------------------------------------------------------------- */
typedef struct parser {
    const char *label;
    lm_err *err;
    int dir; /* 1: label is a file path (a height map's file is relative to its folder) */
} parser;

/* "doe file <label>: <field>: <message>" */
#define bad(p, field, ...) lm_err_field((p)->err, LM_ERR_FORMAT, "doe file", (p)->label, field, \
                                        __VA_ARGS__)

/* A positive number field of obj (named `name` in messages), scaled by `unit`. */
static lm_status positive(parser *p, json_t *obj, const char *key, const char *name, double unit,
                          double *out)
{
    json_t *v = json_object_get(obj, key);
    if (!v) return bad(p, name, "missing (required)");
    double x = json_number_value(v);
    if (!json_is_number(v) || !(x > 0 && x < 1e9))
        return bad(p, name, "must be a positive number");
    *out = x * unit;
    return LM_OK;
}

static lm_status integer(parser *p, json_t *obj, const char *key, int lo, int hi, int *out)
{
    json_t *v = json_object_get(obj, key);
    if (!v) return bad(p, key, "missing (required)");
    if (!json_is_integer(v) || json_integer_value(v) < lo || json_integer_value(v) > hi)
        return bad(p, key, "must be an integer in %d..%d", lo, hi);
    *out = (int)json_integer_value(v);
    return LM_OK;
}

/* Every key of obj must be in the NULL-terminated list. */
static lm_status known_keys(parser *p, json_t *obj, const char *prefix, const char *const *keys)
{
    const char *key;
    json_t *v;
    json_object_foreach(obj, key, v) {
        int i = 0;
        while (keys[i] && strcmp(keys[i], key) != 0) i++;
        if (!keys[i]) {
            char f[96];
            snprintf(f, sizeof f, "%s%s", prefix, key);
            return bad(p, f, "unknown field");
        }
    }
    return LM_OK;
}

static lm_status parse_array3(parser *p, json_t *m, const char *key, double *out)
{
    char f[64];
    snprintf(f, sizeof f, "material.%s", key);
    json_t *a = json_object_get(m, key);
    if (!json_is_array(a) || json_array_size(a) != 3)
        return bad(p, f, "must be an array of 3 numbers");
    for (int i = 0; i < 3; i++) {
        json_t *e = json_array_get(a, (size_t)i);
        if (!json_is_number(e) || !(fabs(json_number_value(e)) < 1e6))
            return bad(p, f, "must be an array of 3 numbers");
        out[i] = json_number_value(e);
    }
    return LM_OK;
}

static lm_status parse_material(parser *p, json_t *root, lm_doe *d)
{
    static const double silica[6] = {0.6961663, 0.4079426, 0.8974794, 0.0684043 * 0.0684043,
                                     0.1162414 * 0.1162414, 9.896161 * 9.896161};
    json_t *m = json_object_get(root, "material");
    const char *model = json_is_object(m) ? json_string_value(json_object_get(m, "model")) : NULL;
    if (json_is_string(m) && strcmp(json_string_value(m), "fused_silica") == 0) {
        d->material = LM_DOE_SELLMEIER;
        memcpy(d->coef, silica, sizeof silica);
        return LM_OK;
    }
    if (!m) return bad(p, "material", "missing (required)");
    if (!model)
        return bad(p, "material", "must be \"fused_silica\" or an object with \"model\": "
                   "\"sellmeier\" | \"cauchy\"");
    if (strcmp(model, "sellmeier") == 0) {
        static const char *const keys[] = {"model", "B", "C_um2", NULL};
        d->material = LM_DOE_SELLMEIER;
        lm_status st = known_keys(p, m, "material.", keys);
        if (!st) st = parse_array3(p, m, "B", d->coef);
        return st ? st : parse_array3(p, m, "C_um2", d->coef + 3);
    }
    if (strcmp(model, "cauchy") == 0) {
        static const char *const keys[] = {"model", "A", "B_um2", NULL};
        d->material = LM_DOE_CAUCHY;
        lm_status st = known_keys(p, m, "material.", keys);
        if (!st) st = positive(p, m, "A", "material.A", 1.0, &d->coef[0]);
        json_t *b = json_object_get(m, "B_um2");
        if (!st && (!json_is_number(b) || !(fabs(json_number_value(b)) < 10)))
            st = bad(p, "material.B_um2", "must be a number (um^2)");
        if (!st) d->coef[1] = json_number_value(b);
        return st;
    }
    return bad(p, "material.model", "unknown model '%s' (sellmeier, cauchy)", model);
}

static lm_status parse_profile(parser *p, json_t *root, lm_doe *d)
{
    static const char *const keys[] = {"type", "focal_mm", "design_nm", NULL};
    static const char *const hkeys[] = {"type", "file", NULL};
    json_t *pr = json_object_get(root, "profile");
    if (!json_is_object(pr))
        return bad(p, "profile", "must be {\"type\": \"fresnel_lens\", \"focal_mm\", "
                   "\"design_nm\"} or {\"type\": \"height_map\", \"file\"}");
    const char *type = json_string_value(json_object_get(pr, "type"));
    if (type && strcmp(type, "height_map") == 0) {
        lm_status st = known_keys(p, pr, "profile.", hkeys);
        const char *f = json_string_value(json_object_get(pr, "file"));
        if (!st && (!f || !f[0]))
            st = bad(p, "profile.file", "must be the name of a 16-bit PNG");
        if (st) return st;
        const char *slash = strrchr(p->label, '/');
        int n = f[0] == '/' || !p->dir || !slash
                    ? snprintf(d->height_file, sizeof d->height_file, "%s", f)
                    : snprintf(d->height_file, sizeof d->height_file, "%.*s/%s",
                               (int)(slash - p->label), p->label, f);
        if (n < 0 || (size_t)n >= sizeof d->height_file)
            return bad(p, "profile.file", "path too long");
        d->height_map = 1;
        d->design_m = 550e-9; /* the wavelength of the default max_height */
        return LM_OK;
    }
    lm_status st = known_keys(p, pr, "profile.", keys);
    if (!st && (!type || strcmp(type, "fresnel_lens") != 0))
        st = bad(p, "profile.type", "must be \"fresnel_lens\" or \"height_map\"");
    if (!st) st = positive(p, pr, "focal_mm", "profile.focal_mm", 1e-3, &d->focal_m);
    if (!st) st = positive(p, pr, "design_nm", "profile.design_nm", 1e-9, &d->design_m);
    if (!st && !(d->design_m >= 200e-9 && d->design_m <= 2000e-9))
        st = bad(p, "profile.design_nm", "must be in 200..2000 nm");
    return st;
}

static lm_status parse_scalars(parser *p, json_t *root, lm_doe *d)
{
    lm_status st = positive(p, root, "aperture_mm", "aperture_mm", 1e-3, &d->aperture_m);
    if (!st) st = positive(p, root, "doe_pitch_um", "doe_pitch_um", 1e-6, &d->pitch_m);
    /* the FFT size bounds the cost: simulate on one thread ~6 s at 1536, ~34 s and 330 MB at
     * 4096 (8192 takes minutes and ~1 GB); training's tape holds ~12 x bands x grid^2 floats */
    if (!st) st = integer(p, root, "grid", 16, LM_DOE_MAX_GRID, &d->grid);
    if (!st) st = integer(p, root, "levels", 0, 1024, &d->levels);
    if (!st && d->levels == 1) st = bad(p, "levels", "must be 0 (continuous) or 2..1024");
    if (!st) st = positive(p, root, "sensor_distance_mm", "sensor_distance_mm", 1e-3,
                           &d->distance_m);
    if (!st) st = positive(p, root, "sensor_pitch_um", "sensor_pitch_um", 1e-6,
                           &d->sensor_pitch_m);
    if (!st) st = integer(p, root, "psf_size", 3, 255, &d->psf_size);
    if (!st && d->psf_size % 2 == 0) st = bad(p, "psf_size", "must be odd (a centre pixel)");
    d->max_height_m = 0;
    if (!st && json_object_get(root, "max_height_um"))
        st = positive(p, root, "max_height_um", "max_height_um", 1e-6, &d->max_height_m);
    return st;
}

/* The sampling rules of doe.h, on the 400..700 nm range. */
static lm_status check_sampling(parser *p, const lm_doe *d)
{
    double lo = LM_GRID31_START * 1e-9, hi = (LM_GRID31_START + 300.0) * 1e-9;
    double du_hi = hi * d->distance_m / (d->grid * d->pitch_m);
    if (du_hi > d->sensor_pitch_m / 2)
        return bad(p, "grid", "too small: the Fresnel-plane spacing at 700 nm is %.3g um, more "
                   "than half the sensor pitch; use a grid of at least %d", du_hi * 1e6,
                   (int)ceil(2 * hi * d->distance_m / (d->pitch_m * d->sensor_pitch_m)));
    double field = lo * d->distance_m / d->pitch_m, need = (d->psf_size + 2) * d->sensor_pitch_m;
    if (field < need)
        return bad(p, "psf_size", "the PSF window (%.3g mm) exceeds the Fresnel field at 400 nm "
                   "(%.3g mm = lambda z / doe_pitch)", need * 1e3, field * 1e3);
    double across = 2 * ceil(d->aperture_m / (2 * d->pitch_m)) + 1;
    if (across > d->grid)
        return bad(p, "aperture_mm", "the aperture spans %.0f DOE pixels, more than the grid "
                   "(%d)", across, d->grid);
    return LM_OK;
}

static lm_status parse_root(parser *p, json_t *root, lm_doe *d)
{
    static const char *const keys[] = {
        "version", "name", "description", "aperture_mm", "doe_pitch_um", "grid", "levels",
        "max_height_um", "material", "profile", "sensor_distance_mm", "sensor_pitch_um",
        "psf_size", NULL};
    if (!json_is_object(root)) return bad(p, "(top level)", "must be a JSON object");
    json_t *v = json_object_get(root, "version");
    if (!json_is_integer(v) || json_integer_value(v) != LM_DOE_VERSION)
        return bad(p, "version", "%s (this build reads version %d)",
                   v ? "unsupported" : "missing", LM_DOE_VERSION);
    d->version = LM_DOE_VERSION;
    lm_status st = known_keys(p, root, "", keys);
    json_t *name = json_object_get(root, "name");
    if (!st && name && !json_is_string(name)) st = bad(p, "name", "must be a string");
    if (!st && name) snprintf(d->name, sizeof d->name, "%s", json_string_value(name));
    if (!st) st = parse_scalars(p, root, d);
    if (!st) st = parse_material(p, root, d);
    if (!st) st = parse_profile(p, root, d);
    double n0 = st ? 0 : lm_doe_index(d, d->design_m);
    if (!st && !(n0 > 1.0 && n0 < 5.0))
        st = bad(p, "material", "refractive index %g at %g nm (must be in 1..5)", n0,
                 d->design_m * 1e9);
    if (!st && d->max_height_m == 0) d->max_height_m = d->design_m / (n0 - 1.0);
    if (!st) st = check_sampling(p, d);
    return st;
}

static lm_status finish(parser *p, json_t *root, lm_doe *d)
{
    lm_status st = parse_root(p, root, d);
    json_decref(root);
    if (!st && d->height_map) { /* the map's errors name the description too */
        lm_err he = {0};
        st = lm_doe_build_height(d, &he);
        if (st) lm_err_set(p->err, st, "doe file %s: profile.file: %s", p->label, he.msg);
    } else if (!st) {
        st = lm_doe_build_height(d, p->err);
    }
    if (st) lm_doe_free(d);
    return st;
}

lm_status lm_doe_parse(const char *json_text, const char *label, lm_doe *doe, lm_err *err)
{
    memset(doe, 0, sizeof *doe);
    parser p = {label ? label : "(text)", err, 0};
    json_error_t je;
    json_t *root = json_loads(json_text, JSON_REJECT_DUPLICATES, &je);
    if (!root)
        return lm_err_set(err, LM_ERR_FORMAT, "doe file %s: line %d, column %d: %s", p.label,
                          je.line, je.column, je.text);
    return finish(&p, root, doe);
}

lm_status lm_doe_load(const char *path, lm_doe *doe, lm_err *err)
{
    memset(doe, 0, sizeof *doe);
    parser p = {path, err, 1};
    lm_status fchk = lm_file_check(path, "a DOE description (.json)", err);
    if (fchk) return fchk;
    json_error_t je;
    json_t *root = json_load_file(path, JSON_REJECT_DUPLICATES, &je);
    if (!root && json_error_code(&je) == json_error_cannot_open_file)
        return lm_err_set(err, LM_ERR_IO, "doe file %s: cannot open (%s)", path, je.text);
    if (!root)
        return lm_err_set(err, LM_ERR_FORMAT, "doe file %s: line %d, column %d: %s", path,
                          je.line, je.column, je.text);
    return finish(&p, root, doe);
}

lm_status lm_doe_default(lm_doe *doe, lm_err *err)
{
    char path[1024];
    memset(doe, 0, sizeof *doe);
    lm_status st = lm_data_path(LM_DOE_DEFAULT_FILE, path, sizeof path, err);
    return st ? st : lm_doe_load(path, doe, err);
}

void lm_doe_free(lm_doe *doe)
{
    free(doe->height);
    free(doe->mask);
    doe->height = NULL;
    doe->mask = NULL;
}

/* ---- optics ------------------------------------------------------------------------------ */
double lm_doe_index(const lm_doe *d, double lambda_m)
{
    double l2 = (lambda_m * 1e6) * (lambda_m * 1e6); /* um^2 */
    if (d->material == LM_DOE_CAUCHY) return d->coef[0] + d->coef[1] / l2;
    double n2 = 1.0;
    for (int i = 0; i < 3; i++) n2 += d->coef[i] * l2 / (l2 - d->coef[3 + i]);
    return n2 > 0 ? sqrt(n2) : NAN;
}

double lm_doe_quantise(double frac, int levels)
{
    double f = frac - floor(frac);
    if (levels > 0) f = fmod(floor(f * levels + 0.5), levels) / levels;
    return f >= 1.0 || !(f >= 0.0) ? 0.0 : f;
}

/* The height_map profile: the PNG read, checked (one channel, m x m, finite values in [0, 1]),
 * quantised to the levels and masked. */
static lm_status load_height_map(lm_doe *d, double r2max, lm_err *err)
{
    int m = d->m;
    lm_image img;
    lm_image_want want = {1, 8192LL * 8192};
    lm_err ie = {0};
    if (lm_image_read(d->height_file, &want, &img, &ie))
        return lm_err_set(err, ie.status, "doe height map %s", ie.msg);
    lm_status st = LM_OK;
    if (img.width != m || img.height != m || img.channels != 1)
        st = lm_err_set(err, LM_ERR_FORMAT, "doe height map %s: %d x %d x %d; this DOE needs "
                        "%d x %d x 1 (samples across the aperture)", d->height_file, img.width,
                        img.height, img.channels, m, m);
    for (int i = 0; !st && i < m; i++)
        for (int j = 0; j < m; j++) {
            size_t k = (size_t)i * m + j;
            double frac = img.data[k];
            if (!(frac >= 0 && frac <= 1)) {
                st = lm_err_set(err, LM_ERR_FORMAT, "doe height map %s: value %g at (%d, %d) "
                                "outside [0, 1]", d->height_file, frac, i, j);
                break;
            }
            frac = lm_doe_quantise(frac, d->levels);
            double y = (i - m / 2) * d->pitch_m, x = (j - m / 2) * d->pitch_m;
            d->mask[k] = x * x + y * y <= r2max;
            d->height[k] = d->mask[k] ? (float)(frac * d->max_height_m) : 0.0f;
        }
    lm_image_free(&img);
    return st;
}

lm_status lm_doe_save(const lm_doe *d, const char *json_path, const char *png_name, lm_err *err)
{
    int m = d->m;
    char png[1200];
    const char *slash = strrchr(json_path, '/');
    if (strchr(png_name, '/'))
        return lm_err_set(err, LM_ERR_ARG, "doe: height map name %s must be a file name",
                          png_name);
    snprintf(png, sizeof png, "%.*s%s%s", slash ? (int)(slash - json_path) : 0, json_path,
             slash ? "/" : "", png_name);
    float *v = malloc((size_t)m * m * sizeof(float));
    if (!v) return lm_err_set(err, LM_ERR_NOMEM, "doe: out of memory");
    for (size_t k = 0; k < (size_t)m * m; k++) v[k] = (float)(d->height[k] / d->max_height_m);
    lm_status st = lm_image_write_gray16(png, m, m, v, err);
    free(v);
    if (st) return st;
    json_t *root = json_object(), *mat = json_object(), *prof = json_object();
    json_object_set_new(root, "version", json_integer(LM_DOE_VERSION));
    if (d->name[0]) json_object_set_new(root, "name", json_string(d->name));
    json_object_set_new(root, "aperture_mm", json_real(d->aperture_m * 1e3));
    json_object_set_new(root, "doe_pitch_um", json_real(d->pitch_m * 1e6));
    json_object_set_new(root, "grid", json_integer(d->grid));
    json_object_set_new(root, "levels", json_integer(d->levels));
    json_object_set_new(root, "max_height_um", json_real(d->max_height_m * 1e6));
    if (d->material == LM_DOE_CAUCHY) {
        json_object_set_new(mat, "model", json_string("cauchy"));
        json_object_set_new(mat, "A", json_real(d->coef[0]));
        json_object_set_new(mat, "B_um2", json_real(d->coef[1]));
    } else {
        json_t *b = json_array(), *c = json_array();
        for (int i = 0; i < 3; i++) {
            json_array_append_new(b, json_real(d->coef[i]));
            json_array_append_new(c, json_real(d->coef[3 + i]));
        }
        json_object_set_new(mat, "model", json_string("sellmeier"));
        json_object_set_new(mat, "B", b);
        json_object_set_new(mat, "C_um2", c);
    }
    json_object_set_new(root, "material", mat);
    json_object_set_new(prof, "type", json_string("height_map"));
    json_object_set_new(prof, "file", json_string(png_name));
    json_object_set_new(root, "profile", prof);
    json_object_set_new(root, "sensor_distance_mm", json_real(d->distance_m * 1e3));
    json_object_set_new(root, "sensor_pitch_um", json_real(d->sensor_pitch_m * 1e6));
    json_object_set_new(root, "psf_size", json_integer(d->psf_size));
    char tmp[1200];
    snprintf(tmp, sizeof tmp, "%s.tmp.%ld", json_path, (long)getpid());
    int bad_write = json_dump_file(root, tmp, JSON_INDENT(2) | JSON_REAL_PRECISION(17)) != 0;
    json_decref(root);
    if (bad_write || rename(tmp, json_path) != 0) {
        remove(tmp);
        return lm_err_set(err, LM_ERR_WRITE, "doe file %s: cannot write", json_path);
    }
    return LM_OK;
}

lm_status lm_doe_build_height(lm_doe *d, lm_err *err)
{
    double across = 2 * ceil(d->aperture_m / (2 * d->pitch_m)) + 1;
    if (!(across >= 1 && across <= d->grid))
        return lm_err_set(err, LM_ERR_ARG, "doe: the aperture spans %g DOE pixels; the grid "
                          "has %d", across, d->grid);
    int m = d->m = (int)across;
    free(d->height);
    free(d->mask);
    d->height = malloc((size_t)m * m * sizeof(float));
    d->mask = malloc((size_t)m * m);
    if (!d->height || !d->mask) return lm_err_set(err, LM_ERR_NOMEM, "doe: out of memory");
    double r2max = 0.25 * d->aperture_m * d->aperture_m;
    if (d->height_map) return load_height_map(d, r2max, err);
    for (int i = 0; i < m; i++)
        for (int j = 0; j < m; j++) {
            double y = (i - m / 2) * d->pitch_m, x = (j - m / 2) * d->pitch_m, r2 = x * x + y * y;
            /* lens phase -pi r^2 / (lambda0 f), wrapped to one period, as a fraction */
            double frac = lm_doe_quantise(-r2 / (2.0 * d->design_m * d->focal_m), d->levels);
            size_t k = (size_t)i * m + j;
            d->mask[k] = r2 <= r2max;
            d->height[k] = d->mask[k] ? (float)(frac * d->max_height_m) : 0.0f;
        }
    return LM_OK;
}

/* pupil x Fresnel chirp, placed with the optical axis at index 0 (wrapped). */
static void fill_pupil(const lm_doe *d, double lambda, fftwf_complex *a, double *energy)
{
    int N = d->grid, m = d->m;
    double dn = lm_doe_index(d, lambda) - 1.0, e = 0;
    memset(a, 0, (size_t)N * N * sizeof(fftwf_complex));
    for (int i = 0; i < m; i++)
        for (int j = 0; j < m; j++) {
            size_t k = (size_t)i * m + j;
            if (!d->mask[k]) continue;
            int yi = i - m / 2, xi = j - m / 2;
            double y = yi * d->pitch_m, x = xi * d->pitch_m;
            double ph = 2 * M_PI * dn * d->height[k] / lambda +
                        M_PI * (x * x + y * y) / (lambda * d->distance_m);
            size_t o = (size_t)((yi + N) % N) * N + (size_t)((xi + N) % N);
            a[o][0] = (float)cos(ph);
            a[o][1] = (float)sin(ph);
            e += 1.0;
        }
    *energy = e;
}

lm_status lm_doe_fresnel(const lm_doe *d, double lambda_m, float *out, double *du,
                         double *pupil_energy, lm_err *err)
{
    int N = d->grid;
    if (!d->height || !(lambda_m > 0))
        return lm_err_set(err, LM_ERR_ARG, "doe: no height map, or wavelength %g", lambda_m);
    fftwf_complex *a = fftwf_malloc((size_t)N * N * sizeof(fftwf_complex));
    if (!a) return lm_err_set(err, LM_ERR_NOMEM, "doe: out of memory (grid %d)", N);
    lm_fftw_lock();
    fftwf_plan plan = fftwf_plan_dft_2d(N, N, a, a, FFTW_FORWARD, FFTW_ESTIMATE);
    lm_fftw_unlock();
    double e;
    fill_pupil(d, lambda_m, a, &e);
    fftwf_execute(plan);
    double scale = 1.0 / ((double)N * N);
    for (int i = 0; out && i < N; i++)
        for (int j = 0; j < N; j++) {
            const float *c = a[(size_t)((i + N / 2) % N) * N + (size_t)((j + N / 2) % N)];
            out[(size_t)i * N + j] = (float)(((double)c[0] * c[0] + (double)c[1] * c[1]) * scale);
        }
    lm_fftw_lock();
    fftwf_destroy_plan(plan);
    lm_fftw_unlock();
    fftwf_free(a);
    if (du) *du = lambda_m * d->distance_m / (N * d->pitch_m);
    if (pupil_energy) *pupil_energy = e;
    return LM_OK;
}

/* Bilinear value of the N x N image at fractional index (fy, fx); 0 outside. */
static double bilinear(const float *img, int N, double fy, double fx)
{
    int y0 = (int)floor(fy), x0 = (int)floor(fx);
    if (y0 < 0 || x0 < 0 || y0 + 1 >= N || x0 + 1 >= N) return 0.0;
    double ty = fy - y0, tx = fx - x0;
    const float *r0 = img + (size_t)y0 * N + x0, *r1 = r0 + N;
    return (1 - ty) * ((1 - tx) * r0[0] + tx * r0[1]) + ty * ((1 - tx) * r1[0] + tx * r1[1]);
}

/* Sensor pixels: the mean of K x K bilinear samples over each pixel's area, unit sum. */
static lm_status resample(const lm_doe *d, const float *I, double du, double lambda, float *psf,
                          lm_err *err)
{
    int S = d->psf_size, N = d->grid, K = LM_DOE_SUPERSAMPLE;
    double p = d->sensor_pitch_m, total = 0;
    for (int i = 0; i < S; i++)
        for (int j = 0; j < S; j++) {
            double acc = 0;
            for (int a = 0; a < K; a++)
                for (int b = 0; b < K; b++) {
                    double y = (i - S / 2 + (a + 0.5) / K - 0.5) * p;
                    double x = (j - S / 2 + (b + 0.5) / K - 0.5) * p;
                    acc += bilinear(I, N, y / du + N / 2, x / du + N / 2);
                }
            psf[(size_t)i * S + j] = (float)acc;
            total += acc;
        }
    if (!(total > 0))
        return lm_err_set(err, LM_ERR_NUMERIC, "doe: no light in the PSF window at %g nm",
                          lambda * 1e9);
    for (int k = 0; k < S * S; k++) psf[k] = (float)(psf[k] / total);
    return LM_OK;
}

lm_status lm_doe_psf(const lm_doe *d, double lambda_m, float *psf, lm_err *err)
{
    size_t N = (size_t)d->grid;
    float *I = malloc(N * N * sizeof(float));
    if (!I) return lm_err_set(err, LM_ERR_NOMEM, "doe: out of memory (grid %zu)", N);
    double du;
    lm_status st = lm_doe_fresnel(d, lambda_m, I, &du, NULL, err);
    if (!st) st = resample(d, I, du, lambda_m, psf, err);
    free(I);
    return st;
}

lm_status lm_doe_psfs(const lm_doe *d, double start_nm, double step_nm, int nb, float *psfs,
                      lm_err *err)
{
    size_t S2 = (size_t)d->psf_size * d->psf_size;
    for (int b = 0; b < nb; b++) {
        lm_status st = lm_doe_psf(d, (start_nm + step_nm * b) * 1e-9, psfs + b * S2, err);
        if (st) return st;
    }
    return LM_OK;
}

/* Centroid (px from the centre) and the radius holding half the energy of a unit-sum PSF. */
static void psf_stats(const float *psf, int S, double *cy, double *cx, double *r50)
{
    double y = 0, x = 0;
    for (int k = 0; k < S * S; k++) y += psf[k] * (k / S - S / 2), x += psf[k] * (k % S - S / 2);
    *cy = y, *cx = x, *r50 = S;
    for (double r = 0.5; r < S; r += 0.5) {
        double e = 0;
        for (int k = 0; k < S * S; k++) {
            double dy = k / S - S / 2, dx = k % S - S / 2;
            if (dy * dy + dx * dx <= r * r) e += psf[k];
        }
        if (e >= 0.5) {
            *r50 = r;
            return;
        }
    }
}

lm_status lm_doe_describe(const lm_doe *d, FILE *f, lm_err *err)
{
    char lv[32];
    if (d->levels) snprintf(lv, sizeof lv, "%d levels", d->levels);
    else snprintf(lv, sizeof lv, "continuous");
    char prof[1100];
    if (d->height_map) snprintf(prof, sizeof prof, "height map %s", d->height_file);
    else snprintf(prof, sizeof prof, "Fresnel lens f = %g mm at %g nm", d->focal_m * 1e3,
                  d->design_m * 1e9);
    fprintf(f, "doe %s: %s, aperture %g mm, DOE pitch %g um, grid "
            "%d (%d samples across), %s, max height %.4g um, %s n(%g nm) = %.5f\n", d->name,
            prof, d->aperture_m * 1e3, d->pitch_m * 1e6, d->grid,
            d->m, lv, d->max_height_m * 1e6,
            d->material == LM_DOE_CAUCHY ? "Cauchy" : "Sellmeier", d->design_m * 1e9,
            lm_doe_index(d, d->design_m));
    fprintf(f, "  sensor at %g mm, pixel %g um, PSF %d x %d px\n  %6s %8s %10s %9s\n",
            d->distance_m * 1e3, d->sensor_pitch_m * 1e6, d->psf_size, d->psf_size, "nm",
            "peak", "centroid", "r50 px");
    int S = d->psf_size;
    float *psf = malloc((size_t)S * S * sizeof(float));
    if (!psf) return lm_err_set(err, LM_ERR_NOMEM, "doe: out of memory");
    lm_status st = LM_OK;
    for (int l = 400; l <= 700 && !st; l += 50) {
        double cy, cx, r50, peak = 0;
        st = lm_doe_psf(d, l * 1e-9, psf, err);
        if (st) break;
        for (int k = 0; k < S * S; k++) peak = psf[k] > peak ? psf[k] : peak;
        psf_stats(psf, S, &cy, &cx, &r50);
        fprintf(f, "  %6d %8.4f %4.1f,%4.1f %9.1f\n", l, peak, cy, cx, r50);
    }
    free(psf);
    return st;
}

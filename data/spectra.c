/* spectra.c — CSV spectral tables, bin integration, 31 -> 41 mirroring, 33-channel target.
 * What it is: small host-side helpers, double precision, no threads (tables are a few hundred
 * rows; cubes are copied band by band). What it is not: a CSV library (no quoting, no escapes). */
#include "data/spectra.h"
#include <ctype.h>
#include <errno.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#define CSV_MAX_BYTES (64L << 20)

/* ---- CSV loading ----------------------------------------------------------------------- */
static char *read_all(const char *path, long *len, lm_err *err)
{
    if (lm_file_check(path, "a spectra file (.csv)", err)) return NULL;
    FILE *f = fopen(path, "rb");
    if (!f) {
        lm_err_set(err, LM_ERR_IO, "spectra file '%s': cannot open (%s)", path, strerror(errno));
        return NULL;
    }
    char *buf = NULL;
    long n = -1;
    if (fseek(f, 0, SEEK_END) == 0) n = ftell(f);
    if (n < 0 || n > CSV_MAX_BYTES || fseek(f, 0, SEEK_SET) != 0) {
        lm_err_set(err, LM_ERR_IO, "spectra file '%s': cannot read (not a regular file or "
                   "larger than %ld bytes)", path, CSV_MAX_BYTES);
        fclose(f);
        return NULL;
    }
    buf = malloc((size_t)n + 1);
    if (!buf || fread(buf, 1, (size_t)n, f) != (size_t)n) {
        lm_err_set(err, buf ? LM_ERR_IO : LM_ERR_NOMEM, "spectra file '%s': cannot read", path);
        free(buf);
        fclose(f);
        return NULL;
    }
    fclose(f);
    buf[n] = 0;
    *len = n;
    return buf;
}

/* Trim spaces (and one pair of surrounding double quotes) in place; returns the start. */
static char *trim(char *s)
{
    while (*s && isspace((unsigned char)*s)) s++;
    char *e = s + strlen(s);
    while (e > s && isspace((unsigned char)e[-1])) *--e = 0;
    if (e - s >= 2 && s[0] == '"' && e[-1] == '"') {
        e[-1] = 0;
        s++;
    }
    return s;
}

/* Split line (modified in place) at commas into at most max cells; returns the cell count
 * (which may exceed max: the extra cells are counted but not stored). */
static int split_cells(char *line, char **cells, int max)
{
    int n = 0;
    char *p = line;
    for (;;) {
        char *comma = strchr(p, ',');
        if (comma) *comma = 0;
        if (n < max) cells[n] = trim(p);
        n++;
        if (!comma) return n;
        p = comma + 1;
    }
}

static int blank_or_comment(const char *s)
{
    while (*s && isspace((unsigned char)*s)) s++;
    return *s == 0 || *s == '#';
}

static lm_status parse_header(lm_csv_table *t, char *line, int lineno, lm_err *err)
{
    int n = 1;
    for (const char *q = line; *q; q++) n += *q == ',';
    if (n < 2)
        return lm_err_set(err, LM_ERR_FORMAT, "spectra file '%s', line %d: header has %d column; "
                          "need wavelength and at least one value column", t->path, lineno, n);
    t->names = calloc((size_t)n, sizeof *t->names);
    char **cells = malloc((size_t)n * sizeof *cells);
    if (!t->names || !cells) {
        free(cells);
        return lm_err_set(err, LM_ERR_NOMEM, "spectra file '%s': out of memory", t->path);
    }
    split_cells(line, cells, n);
    t->cols = n;
    lm_status s = LM_OK;
    for (int i = 0; i < n && s == LM_OK; i++) {
        t->names[i] = strdup(cells[i]);
        if (!t->names[i]) s = lm_err_set(err, LM_ERR_NOMEM, "spectra file '%s': out of memory",
                                         t->path);
    }
    free(cells);
    return s;
}

static lm_status parse_row(lm_csv_table *t, char *line, int lineno, char **cells, lm_err *err)
{
    int n = split_cells(line, cells, t->cols);
    if (n != t->cols)
        return lm_err_set(err, LM_ERR_FORMAT, "spectra file '%s', line %d: %d cells, the header "
                          "has %d (ragged row)", t->path, lineno, n, t->cols);
    double *row = t->data + (size_t)t->rows * t->cols;
    for (int c = 0; c < n; c++) {
        char *end = NULL;
        errno = 0;
        double v = strtod(cells[c], &end);
        if (!cells[c][0] || *end || !isfinite(v))
            return lm_err_set(err, LM_ERR_FORMAT, "spectra file '%s', line %d, column %d ('%s'): "
                              "'%s' is not a finite number", t->path, lineno, c + 1,
                              t->names[c], cells[c]);
        row[c] = v;
    }
    if (t->rows > 0 && !(row[0] > row[-t->cols]))
        return lm_err_set(err, LM_ERR_FORMAT, "spectra file '%s', line %d: wavelength %g is not "
                          "greater than the previous row's %g (wavelengths must increase)",
                          t->path, lineno, row[0], row[-t->cols]);
    t->rows++;
    return LM_OK;
}

static lm_status parse_table(lm_csv_table *t, char *buf, long len, lm_err *err)
{
    long nlines = 1;
    for (long i = 0; i < len; i++) nlines += buf[i] == '\n';
    char *line = buf, *next;
    int lineno = 0;
    lm_status s = LM_OK;
    char **cells = NULL;
    for (; line && s == LM_OK; line = next) {
        next = strchr(line, '\n');
        if (next) *next++ = 0;
        lineno++;
        if (blank_or_comment(line)) continue;
        if (!t->names) {
            s = parse_header(t, line, lineno, err);
            if (s != LM_OK) break;
            t->data = malloc((size_t)nlines * t->cols * sizeof(double));
            cells = malloc((size_t)t->cols * sizeof *cells);
            if (!t->data || !cells)
                s = lm_err_set(err, LM_ERR_NOMEM, "spectra file '%s': out of memory", t->path);
            continue;
        }
        s = parse_row(t, line, lineno, cells, err);
    }
    free(cells);
    if (s == LM_OK && !t->names)
        s = lm_err_set(err, LM_ERR_FORMAT, "spectra file '%s': empty (no header row)", t->path);
    if (s == LM_OK && t->rows < 2)
        s = lm_err_set(err, LM_ERR_FORMAT, "spectra file '%s': %d data row(s); need at least 2",
                       t->path, t->rows);
    return s;
}

lm_status lm_csv_table_load(const char *path, lm_csv_table *t, lm_err *err)
{
    memset(t, 0, sizeof *t);
    snprintf(t->path, sizeof t->path, "%s", path);
    long len = 0;
    char *buf = read_all(path, &len, err);
    if (!buf) return err ? err->status : LM_ERR_IO;
    for (long i = 0; i < len; i++)
        if (buf[i] == '\r') buf[i] = ' ';
    lm_status s = parse_table(t, buf, len, err);
    free(buf);
    if (s != LM_OK) lm_csv_table_free(t);
    return s;
}

void lm_csv_table_free(lm_csv_table *t)
{
    if (t->names)
        for (int i = 0; i < t->cols; i++) free(t->names[i]);
    free(t->names);
    free(t->data);
    memset(t, 0, sizeof *t);
}

int lm_csv_table_find(const lm_csv_table *t, const char *name)
{
    for (int i = 1; i < t->cols; i++)
        if (strcmp(t->names[i], name) == 0) return i;
    return -1;
}

/* ---- spectra --------------------------------------------------------------------------- */
lm_status lm_spectrum_from_arrays(const double *wl, const double *val, int n, lm_spectrum *s,
                                  lm_err *err)
{
    memset(s, 0, sizeof *s);
    if (n < 2) return lm_err_set(err, LM_ERR_ARG, "spectrum: %d samples; need at least 2", n);
    for (int i = 1; i < n; i++)
        if (!(wl[i] > wl[i - 1]))
            return lm_err_set(err, LM_ERR_ARG, "spectrum: wavelength[%d] = %g not greater than "
                              "wavelength[%d] = %g", i, wl[i], i - 1, wl[i - 1]);
    s->wl = malloc((size_t)n * sizeof(double));
    s->val = malloc((size_t)n * sizeof(double));
    if (!s->wl || !s->val) {
        lm_spectrum_free(s);
        return lm_err_set(err, LM_ERR_NOMEM, "spectrum: out of memory");
    }
    memcpy(s->wl, wl, (size_t)n * sizeof(double));
    memcpy(s->val, val, (size_t)n * sizeof(double));
    s->n = n;
    return LM_OK;
}

lm_status lm_spectrum_from_table(const lm_csv_table *t, int col, lm_spectrum *s, lm_err *err)
{
    memset(s, 0, sizeof *s);
    if (col < 1 || col >= t->cols)
        return lm_err_set(err, LM_ERR_ARG, "spectra file '%s': column %d does not exist "
                          "(value columns are 1..%d)", t->path, col, t->cols - 1);
    double *wl = malloc((size_t)t->rows * sizeof(double));
    double *v = malloc((size_t)t->rows * sizeof(double));
    lm_status st = LM_ERR_NOMEM;
    if (wl && v) {
        for (int r = 0; r < t->rows; r++) {
            wl[r] = t->data[(size_t)r * t->cols];
            v[r] = t->data[(size_t)r * t->cols + col];
        }
        st = lm_spectrum_from_arrays(wl, v, t->rows, s, err);
    } else {
        lm_err_set(err, st, "spectra file '%s': out of memory", t->path);
    }
    free(wl);
    free(v);
    return st;
}

static void list_columns(const lm_csv_table *t, char *out, size_t n)
{
    size_t used = 0;
    out[0] = 0;
    for (int i = 1; i < t->cols && used + 1 < n; i++) {
        int k = snprintf(out + used, n - used, "%s'%s'", i > 1 ? ", " : "", t->names[i]);
        if (k < 0) break;
        used += (size_t)k;
    }
}

lm_status lm_spectrum_load(const char *path, const char *column, int index, lm_spectrum *s,
                           lm_err *err)
{
    memset(s, 0, sizeof *s);
    lm_csv_table t;
    lm_status st = lm_csv_table_load(path, &t, err);
    if (st != LM_OK) return st;
    int col = column ? lm_csv_table_find(&t, column) : index;
    if (col < 1 || col >= t.cols) {
        char names[256];
        list_columns(&t, names, sizeof names);
        if (column)
            st = lm_err_set(err, LM_ERR_FORMAT, "spectra file '%s': no column '%s' (columns: %s)",
                            path, column, names);
        else
            st = lm_err_set(err, LM_ERR_FORMAT, "spectra file '%s': no value column %d (value "
                            "columns are 1..%d: %s)", path, index, t.cols - 1, names);
    } else {
        st = lm_spectrum_from_table(&t, col, s, err);
    }
    lm_csv_table_free(&t);
    return st;
}

void lm_spectrum_free(lm_spectrum *s)
{
    free(s->wl);
    free(s->val);
    memset(s, 0, sizeof *s);
}

/* Index i of the segment [wl[i], wl[i+1]] containing x (clamped to 0 .. n-2). */
static int segment_of(const lm_spectrum *s, double x)
{
    int lo = 0, hi = s->n - 2;
    while (lo < hi) {
        int mid = (lo + hi + 1) / 2;
        if (s->wl[mid] <= x) lo = mid;
        else hi = mid - 1;
    }
    return lo;
}

static double lerp_in(const lm_spectrum *s, int i, double x)
{
    double t = (x - s->wl[i]) / (s->wl[i + 1] - s->wl[i]);
    return s->val[i] + t * (s->val[i + 1] - s->val[i]);
}

double lm_spectrum_eval(const lm_spectrum *s, double wl)
{
    if (s->n < 2 || wl < s->wl[0] || wl > s->wl[s->n - 1]) return 0.0;
    return lerp_in(s, segment_of(s, wl), wl);
}

double lm_spectrum_integrate(const lm_spectrum *s, double lo, double hi)
{
    if (s->n < 2) return 0.0;
    if (lo < s->wl[0]) lo = s->wl[0];
    if (hi > s->wl[s->n - 1]) hi = s->wl[s->n - 1];
    if (!(hi > lo)) return 0.0;
    double sum = 0.0;
    for (int i = segment_of(s, lo); i < s->n - 1 && s->wl[i] < hi; i++) {
        double a = s->wl[i] > lo ? s->wl[i] : lo;
        double b = s->wl[i + 1] < hi ? s->wl[i + 1] : hi;
        if (b > a) sum += 0.5 * (b - a) * (lerp_in(s, i, a) + lerp_in(s, i, b));
    }
    return sum;
}

double lm_spectrum_peak(const lm_spectrum *s)
{
    int best = 0;
    for (int i = 1; i < s->n; i++)
        if (s->val[i] > s->val[best]) best = i;
    return s->n > 0 ? s->wl[best] : 0.0;
}

lm_status lm_spectrum_bin(const lm_spectrum *s, double start, double step, int count,
                          double *out, lm_err *err)
{
    if (count < 1 || !(step > 0.0))
        return lm_err_set(err, LM_ERR_ARG, "spectrum bin: need count >= 1 and step > 0 (got %d, "
                          "%g)", count, step);
    for (int i = 0; i < count; i++) {
        double c = start + step * i;
        out[i] = lm_spectrum_integrate(s, c - 0.5 * step, c + 0.5 * step);
    }
    return LM_OK;
}

/* ---- mirroring and the 33-channel target ------------------------------------------------ */
int lm_mirror_source_band(int bin41)
{
    if (bin41 < 0 || bin41 >= LM_GRID41_COUNT) return -1;
    int k = bin41 - 2; /* index on the 400..700 grid, -2 .. 38 */
    if (k < 0) return -k;                                  /* 380 <- 420, 390 <- 410 */
    if (k > LM_GRID31_COUNT - 1) return 2 * (LM_GRID31_COUNT - 1) - k; /* 710 <- 690 ... */
    return k;
}

void lm_spectrum_mirror41(const float *in31, float *out41)
{
    for (int b = 0; b < LM_GRID41_COUNT; b++) out41[b] = in31[lm_mirror_source_band(b)];
}

/* 1 if the cube's bands sit at start + i*10 nm (within 0.01 nm). */
static int on_grid(const lm_cube *c, int bands, float start)
{
    if (c->bands != bands || !c->data) return 0;
    for (int i = 0; i < bands; i++)
        if (fabsf(c->wavelength[i] - (start + LM_GRID41_STEP * (float)i)) > 0.01f) return 0;
    return 1;
}

lm_status lm_cube_mirror41(const lm_cube *in, lm_cube *out, lm_err *err)
{
    memset(out, 0, sizeof *out);
    if (!on_grid(in, LM_GRID31_COUNT, LM_GRID31_START))
        return lm_err_set(err, LM_ERR_SHAPE, "mirror: need a 31-band cube at 400..700 nm in 10 nm "
                          "steps; got %d bands starting at %g nm", in->bands,
                          in->bands > 0 ? in->wavelength[0] : 0.0);
    lm_status s = lm_cube_alloc(out, LM_GRID41_COUNT, in->height, in->width, LM_GRID41_START,
                                LM_GRID41_STEP);
    if (s != LM_OK) return lm_err_set(err, s, "mirror: cannot allocate a %d x %d cube",
                                      in->height, in->width);
    size_t plane = (size_t)in->height * in->width;
    for (int b = 0; b < LM_GRID41_COUNT; b++)
        memcpy(lm_cube_band(out, b), lm_cube_band(in, lm_mirror_source_band(b)),
               plane * sizeof(float));
    return LM_OK;
}

/* dst = mean of bands [b0, b1] of src */
static void mean_bands(const lm_cube *src, int b0, int b1, float *dst)
{
    size_t plane = (size_t)src->height * src->width;
    float inv = 1.0f / (float)(b1 - b0 + 1);
    for (size_t i = 0; i < plane; i++) {
        float acc = 0.0f;
        for (int b = b0; b <= b1; b++) acc += lm_cube_band(src, b)[i];
        dst[i] = acc * inv;
    }
}

lm_status lm_cube_target33(const lm_cube *in, lm_cube *out, lm_err *err)
{
    memset(out, 0, sizeof *out);
    if (!on_grid(in, LM_GRID41_COUNT, LM_GRID41_START))
        return lm_err_set(err, LM_ERR_SHAPE, "target33: need a 41-band cube at 380..780 nm in "
                          "10 nm steps; got %d bands starting at %g nm", in->bands,
                          in->bands > 0 ? in->wavelength[0] : 0.0);
    lm_status s = lm_cube_alloc(out, LM_TARGET_CHANNELS, in->height, in->width,
                                LM_GRID31_START - LM_GRID41_STEP, LM_GRID41_STEP);
    if (s != LM_OK) return lm_err_set(err, s, "target33: cannot allocate a %d x %d cube",
                                      in->height, in->width);
    size_t plane = (size_t)in->height * in->width;
    mean_bands(in, 0, 1, lm_cube_band(out, 0));
    memcpy(lm_cube_band(out, 1), lm_cube_band(in, 2), LM_GRID31_COUNT * plane * sizeof(float));
    mean_bands(in, 2 + LM_GRID31_COUNT, LM_GRID41_COUNT - 1,
               lm_cube_band(out, LM_TARGET_CHANNELS - 1));
    out->wavelength[0] = 385.0f;
    out->wavelength[LM_TARGET_CHANNELS - 1] = 745.0f;
    return LM_OK;
}

/* ---- bundled data ------------------------------------------------------------------------ */
const char *lm_data_dir(void)
{
    const char *env = getenv("LM_DATA_DIR");
    if (env && env[0]) return env;
#ifdef LM_SOURCE_DIR
    return LM_SOURCE_DIR "/data";
#else
    return "data";
#endif
}

lm_status lm_data_path(const char *rel, char *out, size_t n, lm_err *err)
{
    int k = snprintf(out, n, "%s/%s", lm_data_dir(), rel);
    if (k < 0 || (size_t)k >= n)
        return lm_err_set(err, LM_ERR_ARG, "data path '%s/%s' is too long", lm_data_dir(), rel);
    return LM_OK;
}

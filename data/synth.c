/* synth.c — narrowband Gaussian spectra, the rainbow scene and procedural scenes (synth.h).
 * What it is: plain host loops writing 31-band 400..700 nm cubes; every random choice comes
 * from an lm_rng (per-pixel noise textures from a hash of the scene seed and the pixel, so they
 * do not depend on loop order).
 * What it is not: the dataset sampler (dataset.c) or the forward model. */
#include "data/synth.h"
#include "data/spectra.h"
#include <math.h>
#include <pthread.h>
#include <stdlib.h>
#include <string.h>

const int lm_synth_fwhm_nm[LM_SYNTH_NFWHM] = {10, 20, 30, 40, 50};
const int lm_synth_sep_nm[LM_SYNTH_NSEP] = {10, 20, 30, 40, 60, 80};

#define SAMPLE_START 380.0   /* 1 nm samples cover every bin [395, 705] with margin */
#define SAMPLE_COUNT 341     /* 380..720 nm */
#define LN2 0.69314718055994530942

/* ---- narrowband spectra ----------------------------------------------------------------- */
void lm_synth_gauss_draw(lm_rng *r, lm_synth_gauss *g)
{
    memset(g, 0, sizeof *g);
    g->npeaks = 1 + (int)lm_rng_below(r, 2);
    g->fwhm = lm_synth_fwhm_nm[lm_rng_below(r, LM_SYNTH_NFWHM)];
    if (g->npeaks == 1) {
        g->centre[0] = 400.0 + lm_rng_below(r, 301);
    } else {
        int sep = lm_synth_sep_nm[lm_rng_below(r, LM_SYNTH_NSEP)];
        g->centre[0] = 400.0 + lm_rng_below(r, (uint32_t)(301 - sep));
        g->centre[1] = g->centre[0] + sep;
    }
}

double lm_synth_gauss_eval(const lm_synth_gauss *g, double wl)
{
    double v = 0.0, k = 4.0 * LN2 / (g->fwhm * g->fwhm);
    for (int p = 0; p < g->npeaks; p++) {
        double d = wl - g->centre[p];
        v += exp(-k * d * d);
    }
    return v;
}

void lm_synth_gauss_sample(const lm_synth_gauss *g, double wl0, int n, double *out)
{
    for (int i = 0; i < n; i++) out[i] = lm_synth_gauss_eval(g, wl0 + i);
}

lm_status lm_synth_gauss_bins(const lm_synth_gauss *g, float out31[LM_SYNTH_BANDS], lm_err *err)
{
    if ((g->npeaks != 1 && g->npeaks != 2) || !(g->fwhm > 0.0))
        return lm_err_set(err, LM_ERR_ARG, "synth gauss: need 1 or 2 peaks and fwhm > 0 (got %d, "
                          "%g)", g->npeaks, g->fwhm);
    double wl[SAMPLE_COUNT], val[SAMPLE_COUNT], bins[LM_SYNTH_BANDS];
    for (int i = 0; i < SAMPLE_COUNT; i++) wl[i] = SAMPLE_START + i;
    lm_synth_gauss_sample(g, SAMPLE_START, SAMPLE_COUNT, val);
    lm_spectrum s;
    lm_status st = lm_spectrum_from_arrays(wl, val, SAMPLE_COUNT, &s, err);
    if (st == LM_OK)
        st = lm_spectrum_bin(&s, LM_GRID31_START, 10.0, LM_SYNTH_BANDS, bins, err);
    lm_spectrum_free(&s);
    if (st != LM_OK) return st;
    double mx = 0.0;
    for (int b = 0; b < LM_SYNTH_BANDS; b++) mx = bins[b] > mx ? bins[b] : mx;
    if (!(mx > 0.0))
        return lm_err_set(err, LM_ERR_NUMERIC, "synth gauss: spectrum (centre %g nm, fwhm %g nm) "
                          "is 0 over 400..700 nm", g->centre[0], g->fwhm);
    for (int b = 0; b < LM_SYNTH_BANDS; b++) out31[b] = (float)(bins[b] / mx);
    return LM_OK;
}

lm_status lm_synth_uniform_cube(const float spec31[LM_SYNTH_BANDS], int h, int w, lm_cube *cube,
                                lm_err *err)
{
    lm_status st = lm_cube_alloc(cube, LM_SYNTH_BANDS, h, w, LM_GRID31_START, 10.0f);
    if (st != LM_OK) return lm_err_set(err, st, "synth: cannot allocate a %d x %d cube", h, w);
    size_t plane = (size_t)h * w;
    for (int b = 0; b < LM_SYNTH_BANDS; b++) {
        float *p = lm_cube_band(cube, b);
        for (size_t i = 0; i < plane; i++) p[i] = spec31[b];
    }
    return LM_OK;
}

lm_status lm_synth_gauss_patch(lm_rng *r, int h, int w, lm_cube *cube, lm_synth_gauss *g,
                               lm_err *err)
{
    memset(cube, 0, sizeof *cube);
    lm_synth_gauss tmp;
    lm_synth_gauss_draw(r, &tmp);
    if (g) *g = tmp;
    float spec[LM_SYNTH_BANDS];
    lm_status st = lm_synth_gauss_bins(&tmp, spec, err);
    return st != LM_OK ? st : lm_synth_uniform_cube(spec, h, w, cube, err);
}

/* ---- rainbow ---------------------------------------------------------------------------- */
double lm_synth_rainbow_peak(int y, int h)
{
    return 400.0 + 300.0 * (double)(h - 1 - y) / (double)(h - 1);
}

lm_status lm_synth_rainbow(int h, int w, lm_cube *cube, lm_err *err)
{
    memset(cube, 0, sizeof *cube);
    if (h < 2 || w < 1)
        return lm_err_set(err, LM_ERR_ARG, "synth rainbow: need at least 2 rows and 1 column "
                          "(got %d x %d)", h, w);
    lm_status st = lm_cube_alloc(cube, LM_SYNTH_BANDS, h, w, LM_GRID31_START, 10.0f);
    if (st != LM_OK) return lm_err_set(err, st, "synth rainbow: cannot allocate %d x %d", h, w);
    for (int y = 0; y < h && st == LM_OK; y++) {
        lm_synth_gauss g = {1, {lm_synth_rainbow_peak(y, h), 0.0}, 20.0};
        float spec[LM_SYNTH_BANDS];
        st = lm_synth_gauss_bins(&g, spec, err);
        for (int b = 0; b < LM_SYNTH_BANDS && st == LM_OK; b++) {
            float *row = lm_cube_band(cube, b) + (size_t)y * w;
            for (int x = 0; x < w; x++) row[x] = spec[b];
        }
    }
    if (st != LM_OK) lm_cube_free(cube);
    return st;
}

/* ---- ColorChecker palette --------------------------------------------------------------- */
lm_status lm_synth_palette_load(lm_synth_palette *p, lm_err *err)
{
    memset(p, 0, sizeof *p);
    char path[1024];
    lm_status st = lm_data_path(LM_SYNTH_CC_FILE, path, sizeof path, err);
    lm_csv_table t;
    if (st == LM_OK) st = lm_csv_table_load(path, &t, err);
    if (st != LM_OK) return st;
    if (t.cols - 1 != LM_SYNTH_CC_PATCHES || t.data[0] > 400.0 ||
        t.data[(size_t)(t.rows - 1) * t.cols] < 700.0) {
        st = lm_err_set(err, LM_ERR_FORMAT, "%s: expected %d ColorChecker columns covering "
                        "400..700 nm, found %d columns over %g..%g nm", path, LM_SYNTH_CC_PATCHES,
                        t.cols - 1, t.data[0], t.data[(size_t)(t.rows - 1) * t.cols]);
    }
    for (int c = 1; c < t.cols && st == LM_OK; c++) {
        lm_spectrum s;
        st = lm_spectrum_from_table(&t, c, &s, err);
        for (int b = 0; b < LM_SYNTH_BANDS && st == LM_OK; b++)
            p->refl[c - 1][b] = (float)lm_spectrum_eval(&s, LM_GRID31_START + 10.0 * b);
        lm_spectrum_free(&s);
    }
    if (st == LM_OK) p->count = LM_SYNTH_CC_PATCHES;
    lm_csv_table_free(&t);
    return st;
}

/* ---- procedural scenes ------------------------------------------------------------------ */
#define MAX_SITES 12
#define MAX_ELLIPSES 4
#define MAX_TRIS 3
#define MAX_REGIONS (MAX_SITES + MAX_ELLIPSES + MAX_TRIS)
#define NWAVES 3

enum { TEX_FLAT, TEX_GRADIENT, TEX_STRIPES, TEX_NOISE };

typedef struct material {
    float a[LM_SYNTH_BANDS], b[LM_SYNTH_BANDS]; /* reflectance; second one for blends */
    int texture;
    float dc, ds;        /* unit direction of gradient / stripes */
    float scale, phase;  /* gradient length or stripe period (px); stripe phase */
    float amp;           /* noise amplitude */
    int sharp;           /* square-wave stripes */
} material;

typedef struct ellipse { float cy, cx, ry, rx, c, s; } ellipse;
typedef struct tri { float y[3], x[3]; } tri;

typedef struct scene_plan {
    int nsites, nell, ntri;
    float sy[MAX_SITES], sx[MAX_SITES];
    ellipse ell[MAX_ELLIPSES];
    tri tr[MAX_TRIS];
    material mat[MAX_REGIONS];
    float light_lo, wave_fy[NWAVES], wave_fx[NWAVES], wave_ph[NWAVES], wave_c[NWAVES];
    uint64_t noise_key;
} scene_plan;

/* A smooth spectrum: base + a few broad Gaussians, scaled to a random maximum in [0.3, 1]. */
static void smooth_spectrum(lm_rng *r, float *out)
{
    double v[LM_SYNTH_BANDS], base = lm_rng_uniform_range(r, 0.0f, 0.3f), mx = 0.0;
    for (int b = 0; b < LM_SYNTH_BANDS; b++) v[b] = base;
    int n = 1 + (int)lm_rng_below(r, 3);
    for (int k = 0; k < n; k++) {
        lm_synth_gauss g = {1, {lm_rng_uniform_range(r, 350.0f, 750.0f), 0.0},
                            lm_rng_uniform_range(r, 60.0f, 250.0f)};
        double a = lm_rng_uniform_range(r, 0.2f, 1.0f);
        for (int b = 0; b < LM_SYNTH_BANDS; b++)
            v[b] += a * lm_synth_gauss_eval(&g, LM_GRID31_START + 10.0 * b);
    }
    for (int b = 0; b < LM_SYNTH_BANDS; b++) mx = v[b] > mx ? v[b] : mx;
    double top = lm_rng_uniform_range(r, 0.3f, 1.0f);
    for (int b = 0; b < LM_SYNTH_BANDS; b++) out[b] = (float)(v[b] / mx * top);
}

static void pick_spectrum(lm_rng *r, const lm_synth_palette *pal, float *out)
{
    if (pal && pal->count > 0 && lm_rng_uniform(r) < 0.5f)
        memcpy(out, pal->refl[lm_rng_below(r, (uint32_t)pal->count)],
               LM_SYNTH_BANDS * sizeof(float));
    else
        smooth_spectrum(r, out);
}

static void plan_material(lm_rng *r, const lm_synth_palette *pal, int h, int w, material *m)
{
    memset(m, 0, sizeof *m);
    pick_spectrum(r, pal, m->a);
    pick_spectrum(r, pal, m->b);
    float u = lm_rng_uniform(r), th = lm_rng_uniform_range(r, 0.0f, 6.2831853f);
    m->dc = cosf(th);
    m->ds = sinf(th);
    m->texture = u < 0.35f ? TEX_FLAT : u < 0.6f ? TEX_GRADIENT : u < 0.8f ? TEX_STRIPES
                                                                            : TEX_NOISE;
    float size = (float)(h > w ? h : w);
    m->scale = m->texture == TEX_GRADIENT ? lm_rng_uniform_range(r, 0.3f, 1.5f) * size
                                          : lm_rng_uniform_range(r, 2.0f, 12.0f);
    m->phase = lm_rng_uniform_range(r, 0.0f, 6.2831853f);
    m->amp = lm_rng_uniform_range(r, 0.1f, 0.5f);
    m->sharp = (int)lm_rng_below(r, 2);
}

static void plan_shapes(lm_rng *r, int h, int w, scene_plan *p)
{
    float mn = (float)(h < w ? h : w);
    p->nsites = 2 + (int)lm_rng_below(r, MAX_SITES - 1);
    for (int k = 0; k < p->nsites; k++) {
        p->sy[k] = lm_rng_uniform_range(r, 0.0f, (float)h);
        p->sx[k] = lm_rng_uniform_range(r, 0.0f, (float)w);
    }
    p->nell = (int)lm_rng_below(r, MAX_ELLIPSES + 1);
    for (int k = 0; k < p->nell; k++) {
        ellipse *e = &p->ell[k];
        float th = lm_rng_uniform_range(r, 0.0f, 3.1415927f);
        e->cy = lm_rng_uniform_range(r, 0.0f, (float)h);
        e->cx = lm_rng_uniform_range(r, 0.0f, (float)w);
        e->ry = lm_rng_uniform_range(r, 0.05f, 0.4f) * mn + 1.0f;
        e->rx = lm_rng_uniform_range(r, 0.05f, 0.4f) * mn + 1.0f;
        e->c = cosf(th);
        e->s = sinf(th);
    }
    p->ntri = (int)lm_rng_below(r, MAX_TRIS + 1);
    for (int k = 0; k < p->ntri; k++)
        for (int v = 0; v < 3; v++) {
            p->tr[k].y[v] = lm_rng_uniform_range(r, -0.2f, 1.2f) * (float)h;
            p->tr[k].x[v] = lm_rng_uniform_range(r, -0.2f, 1.2f) * (float)w;
        }
}

static void plan_scene(uint64_t seed, int h, int w, const lm_synth_palette *pal, scene_plan *p)
{
    lm_rng r;
    lm_rng_seed(&r, seed);
    memset(p, 0, sizeof *p);
    plan_shapes(&r, h, w, p);
    for (int k = 0; k < MAX_REGIONS; k++) plan_material(&r, pal, h, w, &p->mat[k]);
    p->light_lo = lm_rng_uniform_range(&r, 0.3f, 0.9f);
    float size = (float)(h > w ? h : w);
    for (int k = 0; k < NWAVES; k++) {
        p->wave_fy[k] = lm_rng_uniform_range(&r, -1.5f, 1.5f) / size;
        p->wave_fx[k] = lm_rng_uniform_range(&r, -1.5f, 1.5f) / size;
        p->wave_ph[k] = lm_rng_uniform_range(&r, 0.0f, 6.2831853f);
        p->wave_c[k] = lm_rng_uniform_range(&r, 0.2f, 1.0f);
    }
    p->noise_key = lm_rng_u64(&r);
}

static int in_triangle(const tri *t, float y, float x)
{
    float d[3];
    for (int i = 0; i < 3; i++) {
        int j = (i + 1) % 3;
        d[i] = (t->x[j] - t->x[i]) * (y - t->y[i]) - (t->y[j] - t->y[i]) * (x - t->x[i]);
    }
    return (d[0] >= 0 && d[1] >= 0 && d[2] >= 0) || (d[0] <= 0 && d[1] <= 0 && d[2] <= 0);
}

/* Region of pixel centre (y, x): the last shape containing it, else the nearest Voronoi site. */
static int region_of(const scene_plan *p, float y, float x)
{
    for (int k = p->ntri - 1; k >= 0; k--)
        if (in_triangle(&p->tr[k], y, x)) return MAX_SITES + MAX_ELLIPSES + k;
    for (int k = p->nell - 1; k >= 0; k--) {
        const ellipse *e = &p->ell[k];
        float dy = y - e->cy, dx = x - e->cx;
        float u = (dx * e->c + dy * e->s) / e->rx, v = (-dx * e->s + dy * e->c) / e->ry;
        if (u * u + v * v <= 1.0f) return MAX_SITES + k;
    }
    int best = 0;
    float bd = INFINITY;
    for (int k = 0; k < p->nsites; k++) {
        float dy = y - p->sy[k], dx = x - p->sx[k], d = dy * dy + dx * dx;
        if (d < bd) bd = d, best = k;
    }
    return best;
}

static float hash_unit(uint64_t key, uint64_t i)
{
    uint64_t z = key ^ (i * 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    return (float)((z ^ (z >> 31)) >> 40) * (1.0f / 16777216.0f);
}

static float shading(const scene_plan *p, float y, float x)
{
    float s = 0.0f, norm = 0.0f;
    for (int k = 0; k < NWAVES; k++) {
        s += p->wave_c[k] * cosf(6.2831853f * (p->wave_fy[k] * y + p->wave_fx[k] * x) +
                                 p->wave_ph[k]);
        norm += p->wave_c[k];
    }
    return p->light_lo + (1.0f - p->light_lo) * (0.5f + 0.5f * s / norm);
}

/* Fill one pixel's 31 values (before shading): blend weight t between spectra a and b, and a
 * multiplicative texture factor. */
static void pixel_spectrum(const scene_plan *p, const material *m, int y, int x, int w,
                           float *out)
{
    float proj = m->dc * (float)x + m->ds * (float)y, t = 0.0f, f = 1.0f;
    if (m->texture == TEX_GRADIENT) {
        t = 0.5f + proj / m->scale;
        t = t < 0.0f ? 0.0f : t > 1.0f ? 1.0f : t;
    } else if (m->texture == TEX_STRIPES) {
        float s = 0.5f + 0.5f * sinf(6.2831853f * proj / m->scale + m->phase);
        t = m->sharp ? (s > 0.5f ? 1.0f : 0.0f) : s;
    } else if (m->texture == TEX_NOISE) {
        f = 1.0f - m->amp * hash_unit(p->noise_key, (uint64_t)y * (uint64_t)w + (uint64_t)x);
    }
    for (int b = 0; b < LM_SYNTH_BANDS; b++) out[b] = f * ((1.0f - t) * m->a[b] + t * m->b[b]);
}

lm_status lm_synth_scene(uint64_t seed, int h, int w, const lm_synth_palette *pal,
                         lm_cube *cube, lm_err *err)
{
    memset(cube, 0, sizeof *cube);
    if (h < 1 || w < 1)
        return lm_err_set(err, LM_ERR_ARG, "synth scene: bad size %d x %d", h, w);
    lm_status st = lm_cube_alloc(cube, LM_SYNTH_BANDS, h, w, LM_GRID31_START, 10.0f);
    if (st != LM_OK) return lm_err_set(err, st, "synth scene: cannot allocate %d x %d", h, w);
    scene_plan *p = malloc(sizeof *p);
    if (!p) {
        lm_cube_free(cube);
        return lm_err_set(err, LM_ERR_NOMEM, "synth scene: out of memory");
    }
    plan_scene(seed, h, w, pal, p);
    size_t plane = (size_t)h * w;
    for (int y = 0; y < h; y++)
        for (int x = 0; x < w; x++) {
            float fy = (float)y + 0.5f, fx = (float)x + 0.5f, v[LM_SYNTH_BANDS];
            const material *m = &p->mat[region_of(p, fy, fx)];
            pixel_spectrum(p, m, y, x, w, v);
            float light = shading(p, fy, fx);
            for (int b = 0; b < LM_SYNTH_BANDS; b++) {
                float val = v[b] * light;
                cube->data[b * plane + (size_t)y * w + x] = val < 0.0f ? 0.0f
                                                            : val > 1.0f ? 1.0f : val;
            }
        }
    free(p);
    return LM_OK;
}

/* ---- fine narrowband detail ------------------------------------------------------------ */
/* Binned narrowband spectra for FWHM 10, 15, ..., 40 nm (7) and peaks at 400, 401, ..., 700 nm
 * (301): 7 x 301 x 31 values, made once per process (they depend on nothing else). */
#define FINE_WIDTHS 7
static float fine_tab[FINE_WIDTHS * 301 * LM_SYNTH_BANDS];
static lm_status fine_tab_status = LM_OK;
static pthread_once_t fine_tab_once = PTHREAD_ONCE_INIT;

static void fine_tab_make(void)
{
    lm_err e = {0};
    for (int f = 0; f < FINE_WIDTHS && !fine_tab_status; f++)
        for (int k = 0; k <= 300 && !fine_tab_status; k++) {
            lm_synth_gauss g = {1, {400.0 + k, 0.0}, 10.0 + 5.0 * f};
            fine_tab_status = lm_synth_gauss_bins(
                &g, fine_tab + ((size_t)f * 301 + (size_t)k) * LM_SYNTH_BANDS, &e);
        }
}

static const float *narrow_at(const float *tab, double peak)
{
    int k = (int)lround(peak - 400.0);
    return tab + (size_t)(k < 0 ? 0 : k > 300 ? 300 : k) * LM_SYNTH_BANDS;
}

/* Blend spectrum s (times a) into pixel (y, x) with weight al. */
static void blend_px(lm_cube *c, int y, int x, float al, float a, const float *s)
{
    const size_t plane = (size_t)c->height * c->width, o = (size_t)y * c->width + x;
    for (int b = 0; b < LM_SYNTH_BANDS; b++) {
        float *v = c->data + b * plane + o;
        *v = (1.0f - al) * *v + al * a * s[b];
    }
}

lm_status lm_synth_fine(uint64_t seed, int h, int w, const lm_synth_palette *pal,
                        lm_cube *cube, lm_err *err)
{
    lm_status st = lm_synth_scene(seed, h, w, pal, cube, err);
    if (st) return st;
    pthread_once(&fine_tab_once, fine_tab_make);
    if (fine_tab_status) {
        lm_cube_free(cube);
        return lm_err_set(err, fine_tab_status, "synth fine: cannot make the narrowband spectra");
    }
    const float *tab = NULL;
    lm_rng r;
    lm_rng_seed(&r, seed ^ 0xF1E5EEDull);
    if (lm_rng_below(&r, 2)) { /* the iridescent sheet */
        const float th = lm_rng_uniform_range(&r, 0.0f, 6.2831853f), ny = sinf(th),
                    nx = cosf(th), py = lm_rng_uniform(&r) * (float)h,
                    px = lm_rng_uniform(&r) * (float)w;
        const float period = lm_rng_uniform_range(&r, 4.0f, 32.0f),
                    ph = lm_rng_uniform(&r), a = lm_rng_uniform_range(&r, 0.5f, 1.0f),
                    cover = lm_rng_uniform_range(&r, 0.5f, 1.0f);
        const float ga = lm_rng_uniform_range(&r, 0.0f, 6.2831853f); /* grating direction */
        tab = fine_tab + (size_t)(1 + lm_rng_below(&r, 6)) * 301 * LM_SYNTH_BANDS;
        for (int y = 0; y < h && !st; y++)
            for (int x = 0; x < w; x++) {
                const float fy = (float)y + 0.5f, fx = (float)x + 0.5f;
                float al = 0.5f + nx * (fx - px) + ny * (fy - py);
                al = al < 0.0f ? 0.0f : al > 1.0f ? 1.0f : al;
                if (al == 0.0f) continue;
                float u = (cosf(ga) * fx + sinf(ga) * fy) / period + ph;
                u -= floorf(u);
                const double peak = 400.0 + 300.0 * (u < 0.5f ? 2.0f * u : 2.0f - 2.0f * u);
                blend_px(cube, y, x, al * cover, a, narrow_at(tab, peak));
            }
    }
    const int strokes = 4 + (int)lm_rng_below(&r, 21);
    for (int k = 0; k < strokes && !st; k++) {
        const float cy = lm_rng_uniform(&r) * (float)h, cx = lm_rng_uniform(&r) * (float)w,
                    th = lm_rng_uniform_range(&r, 0.0f, 3.1415927f),
                    len = lm_rng_uniform_range(&r, 4.0f, 64.0f),
                    wd = lm_rng_uniform_range(&r, 0.6f, 2.5f),
                    p0 = lm_rng_uniform_range(&r, 400.0f, 700.0f),
                    drift = lm_rng_uniform_range(&r, -60.0f, 60.0f),
                    a = lm_rng_uniform_range(&r, 0.4f, 1.0f);
        tab = fine_tab + (size_t)lm_rng_below(&r, FINE_WIDTHS) * 301 * LM_SYNTH_BANDS;
        const float dy = sinf(th), dx = cosf(th), reach = 0.5f * len + wd + 1.0f;
        const int y0 = (int)floorf(cy - reach), y1 = (int)ceilf(cy + reach),
                  x0 = (int)floorf(cx - reach), x1 = (int)ceilf(cx + reach);
        for (int y = y0 < 0 ? 0 : y0; y <= y1 && y < h && !st; y++)
            for (int x = x0 < 0 ? 0 : x0; x <= x1 && x < w; x++) {
                const float ry = (float)y + 0.5f - cy, rx = (float)x + 0.5f - cx;
                float t = rx * dx + ry * dy; /* along the stroke */
                t = t < -0.5f * len ? -0.5f * len : t > 0.5f * len ? 0.5f * len : t;
                const float ey = ry - t * dy, ex = rx - t * dx, d = sqrtf(ey * ey + ex * ex);
                float al = 0.5f * wd + 0.5f - d;
                al = al < 0.0f ? 0.0f : al > 1.0f ? 1.0f : al;
                if (al == 0.0f) continue;
                blend_px(cube, y, x, al, a, narrow_at(tab, p0 + drift * t / len));
            }
    }
    return st;
}

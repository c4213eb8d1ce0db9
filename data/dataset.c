/* dataset.c — scene listing, split by scene group (quotas by hash rank) and sample synthesis
 * (dataset.h); the cube cache is dataset_cache.c, the worker pool dataset_workers.c.
 * What it is: a sample is a pure function of (seed, split, index): every random choice is
 * drawn from lm_rng_split(split generator, index) in a fixed order (sample_plan), so worker
 * threads, the cache state and the order of preparation never change the numbers.
 * What it is not: a file reader (cube_io.h), the forward model (forward.h) or the synthetic
 * generators (synth.h). */
#include "data/dataset_internal.h"
#include "data/cube_io.h"
#include "data/forward.h"
#include "data/image.h"
#include "data/spectra.h"
#include "data/synth.h"
#include "data/util.h"
#include "data/system.h"
#include <dirent.h>
#include <inttypes.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>

void lm_dataset_default_cfg(lm_dataset_cfg *cfg)
{
    *cfg = (lm_dataset_cfg){.patch_h = 66, .patch_w = 64, .synth_fraction = 0.33f,
                            .noise_min = 0.0f, .noise_max = 0.15f, .flips = 1, .seed = 1,
                            .workers = 2, .cache_scenes = 0, .val_patches = 64,
                            .val_noise = 0.0f, .procedural_fraction = 0.0f, .buckets = 1};
}

/* ---- split: group keys and the hash ---------------------------------------------------- */
/* FNV-1a, then a splitmix finaliser. */
static uint64_t split_hash(const char *s)
{
    uint64_t h = lm_fnv1a_str(LM_FNV1A_BASIS, s);
    h = (h ^ (h >> 30)) * 0xBF58476D1CE4E5B9ull;
    h = (h ^ (h >> 27)) * 0x94D049BB133111EBull;
    return h ^ (h >> 31);
}

/* Where name's trailing "<digits>" starts (len if none); *value its number (-1 if it has more
 * than 9 digits). */
static size_t trailing_digits(const char *name, size_t len, long *value)
{
    size_t p = len;
    while (p > 0 && name[p - 1] >= '0' && name[p - 1] <= '9') p--;
    *value = len - p <= 9 && p < len ? strtol(name + p, NULL, 10) : -1;
    return p;
}

int lm_dataset_group_key(const char *name, int height, int width, char *out, size_t n)
{
    size_t len = strlen(name), keep = len;
    long v;
    size_t p = trailing_digits(name, len, &v);
    if (p < len && p >= 5 && !strncmp(name + p - 5, "_crop", 5)) keep = p - 5;
    else if (p < len && p >= 1 && name[p - 1] == '_' && v >= 0 && (v == height || v == width))
        keep = p - 1;
    if (keep == 0) keep = len; /* "_256" alone: no stem to keep */
    return snprintf(out, n, "%.*s", (int)keep, name);
}

/* ---- scene discovery -------------------------------------------------------------------- */
static const char *base_name(const char *p) { return strrchr(p, '/') ? strrchr(p, '/') + 1 : p; }

/* Number of CAVE band images `*_ms_NN.png|tif|tiff` directly in dir; first receives band 01. */
static int cave_bands_in(const char *dir, char *first, size_t n)
{
    DIR *d = opendir(dir);
    if (!d) return 0;
    int count = 0;
    struct dirent *de;
    while ((de = readdir(d)) != NULL) {
        const char *dot = strrchr(de->d_name, '.');
        if (de->d_name[0] == '.' || !dot || (strcasecmp(dot, ".png") && strcasecmp(dot, ".tif")
                                             && strcasecmp(dot, ".tiff")))
            continue;
        const char *p = dot;
        while (p > de->d_name && p[-1] >= '0' && p[-1] <= '9') p--;
        if (p == dot || p - de->d_name < 4 || strncasecmp(p - 4, "_ms_", 4)) continue;
        count++;
        if (atoi(p) == 1 && first) snprintf(first, n, "%s/%s", dir, de->d_name);
    }
    closedir(d);
    return count;
}

static int is_cube_file(const char *name)
{
    const char *dot = strrchr(name, '.');
    return dot && (!strcasecmp(dot, ".mat") || !strcasecmp(dot, ".exr"));
}

/* The folder holding a CAVE scene's bands: dir itself, or its single sub-folder with bands
 * when dir holds nothing else that is a scene (scene/scene/ layout). Empty if dir is not a
 * CAVE scene. */
static void cave_band_dir(const char *dir, char *out, size_t n)
{
    out[0] = 0;
    if (cave_bands_in(dir, NULL, 0) > 0) {
        snprintf(out, n, "%s", dir);
        return;
    }
    DIR *d = opendir(dir);
    if (!d) return;
    int found = 0, other = 0;
    struct dirent *de;
    while ((de = readdir(d)) != NULL) {
        char sub[DS_PATH_MAX];
        if (de->d_name[0] == '.') continue;
        snprintf(sub, sizeof sub, "%s/%s", dir, de->d_name);
        if (lm_is_dir(sub) && cave_bands_in(sub, NULL, 0) > 0) {
            if (found++ == 0) snprintf(out, n, "%s", sub);
        } else if (is_cube_file(de->d_name)) {
            other++;
        }
    }
    closedir(d);
    if (found != 1 || other) out[0] = 0;
}

static lm_status add_scene(lm_dataset *d, const char *path, const char *name, lm_err *err)
{
    scene *s = realloc(d->scenes, (size_t)(d->nscenes + 1) * sizeof *s);
    if (!s) return lm_err_set(err, LM_ERR_NOMEM, "dataset: out of memory");
    d->scenes = s;
    s += d->nscenes;
    memset(s, 0, sizeof *s);
    s->path = strdup(path);
    s->name = strdup(name);
    d->nscenes++; /* freed by lm_dataset_close even when incomplete */
    if (!s->path || !s->name) return lm_err_set(err, LM_ERR_NOMEM, "dataset: out of memory");
    char *dot = strrchr(s->name, '.');
    if (dot && is_cube_file(s->name)) *dot = 0;
    return LM_OK;
}

/* A folder of scenes: .mat / .exr files and CAVE scene folders, in name order. */
static lm_status scan_folder(lm_dataset *d, const char *dir, lm_err *err)
{
    struct dirent **ents;
    int n = scandir(dir, &ents, NULL, alphasort);
    if (n < 0) return lm_err_set(err, LM_ERR_IO, "%s: cannot open folder", dir);
    lm_status st = LM_OK;
    int before = d->nscenes;
    for (int i = 0; i < n; i++) {
        char sub[DS_PATH_MAX], bands[DS_PATH_MAX];
        const char *nm = ents[i]->d_name;
        snprintf(sub, sizeof sub, "%s/%s", dir, nm);
        if (st == LM_OK && nm[0] != '.') {
            if (lm_is_dir(sub)) {
                cave_band_dir(sub, bands, sizeof bands);
                if (bands[0]) st = add_scene(d, bands, base_name(bands), err);
            } else if (is_cube_file(nm)) {
                st = add_scene(d, sub, nm, err);
            }
        }
        free(ents[i]);
    }
    free(ents);
    if (st == LM_OK && d->nscenes == before)
        st = lm_err_set(err, LM_ERR_FORMAT, "%s: no scenes in this folder (expected CAVE scene "
                        "folders, .mat or .exr files)", dir);
    return st;
}

static lm_status add_path(lm_dataset *d, const char *path, lm_err *err)
{
    struct stat st;
    if (stat(path, &st) != 0)
        return lm_err_set(err, LM_ERR_IO, "%s: no such file or folder", path);
    if (S_ISDIR(st.st_mode)) {
        char bands[DS_PATH_MAX];
        cave_band_dir(path, bands, sizeof bands);
        return bands[0] ? add_scene(d, bands, base_name(bands), err) : scan_folder(d, path, err);
    }
    if (!is_cube_file(path))
        return lm_err_set(err, LM_ERR_UNSUPPORTED, "%s: not a scene (expected a CAVE folder, "
                          ".mat or .exr)", path);
    return add_scene(d, path, base_name(path), err);
}

/* ---- scene headers ---------------------------------------------------------------------- */
/* 31 spectral channels (T., else S0.) at 400..700 nm in an EXR header? Returns their count. */
static int exr_bands_ok(const lm_image *im, int *ok)
{
    const char *prefix[2] = {"T.", "S0."};
    int nb = 0;
    *ok = 1;
    for (int p = 0; p < 2 && nb == 0; p++)
        for (int c = 0; c < im->channels; c++) {
            double nm;
            if (!lm_spectral_channel_parse(im->names[c], prefix[p], &nm)) continue;
            *ok &= fabs(fmod(nm - 400.0, 10.0)) < 0.5 && nm > 399.5 && nm < 700.5;
            nb++;
        }
    *ok &= nb == LM_GRID31_COUNT;
    return nb;
}

/* How scenes are read: onto 31 bands 400-700 nm (no other grid kept), the .mat key. */
void lm_dataset_read_opts(const lm_dataset *d, lm_cube_read_opts *o)
{
    lm_cube_read_opts_default(o);
    o->keep.count = 0;
    o->mat_key = d->mat_key;
}

/* 1 if a sidecar wavelength list goes with the scene (its bands are then resampled). */
static int has_sidecar(const char *path)
{
    double wl[LM_RESAMPLE_MAX_BANDS];
    int n = 0;
    return lm_wavelengths_sidecar(path, wl, &n, NULL) != LM_OK || n > 0;
}

/* Sizes from headers (CAVE band 01, EXR); a .mat, an EXR off the 31-band grid and a scene
 * with a wavelength sidecar are read whole (resampled, or refused with the reason). */
static lm_status probe_scene(const lm_dataset *d, scene *s, lm_err *err)
{
    lm_cube_format f = lm_cube_detect(s->path);
    char hdr[DS_PATH_MAX] = "";
    if (f == LM_CUBE_FMT_MAT || has_sidecar(s->path)) {
        lm_cube c;
        lm_cube_read_opts o;
        lm_dataset_read_opts(d, &o);
        lm_status st = lm_cube_read_with(s->path, &o, &c, err);
        s->height = c.height;
        s->width = c.width;
        lm_cube_free(&c);
        return st;
    }
    int n = f == LM_CUBE_FMT_CAVE ? cave_bands_in(s->path, hdr, sizeof hdr) : 0;
    if (f == LM_CUBE_FMT_CAVE && (n != LM_CAVE_BANDS || !hdr[0]))
        return lm_err_set(err, LM_ERR_FORMAT, "%s: CAVE scene with %d band images%s; expected "
                          "%d (_ms_01 .. _ms_31)", s->path, n, hdr[0] ? "" : " and no band 01",
                          LM_CAVE_BANDS);
    lm_image im;
    lm_status st = lm_image_info(f == LM_CUBE_FMT_CAVE ? hdr : s->path, NULL, &im, err);
    int ok = 1;
    if (st == LM_OK && f == LM_CUBE_FMT_EXR) exr_bands_ok(&im, &ok);
    s->height = im.height;
    s->width = im.width;
    lm_image_free(&im);
    if (st == LM_OK && !ok) {
        lm_cube c;
        lm_cube_read_opts o;
        lm_dataset_read_opts(d, &o);
        st = lm_cube_read_with(s->path, &o, &c, err); /* resampled, or the reason it cannot be */
        s->height = c.height;
        s->width = c.width;
        lm_cube_free(&c);
    }
    return st;
}

/* ---- splits ----------------------------------------------------------------------------- */
static int fits(const lm_dataset *d, const scene *s)
{
    return s->height >= d->cfg.patch_h && s->width >= d->cfg.patch_w;
}

/* A scene's place in the group order: by group hash, ties by group key. */
typedef struct group_rank {
    uint64_t hash;
    const char *group;
    int scene;
} group_rank;

static int cmp_group(const void *pa, const void *pb)
{
    const group_rank *a = pa, *b = pb;
    return a->hash != b->hash ? (a->hash < b->hash ? -1 : 1) : strcmp(a->group, b->group);
}

/* Each scene's group key and hash, then the split by group rank: with G groups, the first
 * (G + 5) / 10 = floor(0.1 G + 0.5) groups (smallest hash) are test, as many next are val, the
 * rest train. Scenes smaller than the patch count too, so the split depends on the scene set
 * alone, not on the patch size. */
static lm_status assign_splits(lm_dataset *d, lm_err *err)
{
    group_rank *o = malloc((size_t)(d->nscenes + 1) * sizeof *o);
    if (!o) return lm_err_set(err, LM_ERR_NOMEM, "dataset: out of memory");
    for (int i = 0; i < d->nscenes; i++) {
        scene *s = &d->scenes[i];
        size_t n = (size_t)lm_dataset_group_key(s->name, s->height, s->width, NULL, 0) + 1;
        s->group = malloc(n);
        if (!s->group) return free(o), lm_err_set(err, LM_ERR_NOMEM, "dataset: out of memory");
        lm_dataset_group_key(s->name, s->height, s->width, s->group, n);
        s->hash = split_hash(s->group);
        o[i] = (group_rank){s->hash, s->group, i};
    }
    qsort(o, (size_t)d->nscenes, sizeof *o, cmp_group);
    d->ngroups = 0;
    for (int i = 0; i < d->nscenes; i++) d->ngroups += i == 0 || cmp_group(&o[i - 1], &o[i]) != 0;
    int n_test = (d->ngroups + 5) / 10, n_val = (d->ngroups + 5) / 10, rank = -1;
    for (int i = 0; i < d->nscenes; i++) {
        rank += i == 0 || cmp_group(&o[i - 1], &o[i]) != 0;
        d->scenes[o[i].scene].split = rank < n_test ? LM_SPLIT_TEST
                                    : rank < n_test + n_val ? LM_SPLIT_VAL : LM_SPLIT_TRAIN;
    }
    free(o);
    return LM_OK;
}

static lm_status build_splits(lm_dataset *d, lm_err *err)
{
    for (int k = 0; k < 3; k++) {
        d->list[k] = malloc((size_t)(d->nscenes + 1) * sizeof(int));
        if (!d->list[k]) return lm_err_set(err, LM_ERR_NOMEM, "dataset: out of memory");
    }
    lm_status st = assign_splits(d, err);
    if (st != LM_OK) return st;
    for (int i = 0; i < d->nscenes; i++) {
        if (!fits(d, &d->scenes[i])) d->too_small++;
        else d->list[d->scenes[i].split][d->count[d->scenes[i].split]++] = i;
    }
    int usable = d->nscenes - d->too_small;
    if (d->nscenes > 0 && usable == 0) {
        const scene *big = &d->scenes[0];
        for (int i = 1; i < d->nscenes; i++)
            if ((long)d->scenes[i].height * d->scenes[i].width > (long)big->height * big->width)
                big = &d->scenes[i];
        return lm_err_set(err, LM_ERR_SHAPE, "dataset: patch %d x %d is larger than every scene "
                          "(largest: %s, %d x %d)", d->cfg.patch_h, d->cfg.patch_w, big->path,
                          big->height, big->width);
    }
    for (int k = 0; k < 3 && d->nscenes < 3; k++) {
        if (d->count[k] > 0) continue;
        d->borrowed[k] = 1;
        for (int i = 0; i < d->nscenes; i++)
            if (fits(d, &d->scenes[i])) d->list[k][d->count[k]++] = i;
    }
    return LM_OK;
}

/* ---- one sample ------------------------------------------------------------------------- */
typedef struct sample_plan {
    lm_dataset_sample_info info;
    uint64_t synth_seed;
    lm_rng synth_rng, noise_rng;
} sample_plan;

/* Every draw in a fixed order, whatever the sample turns out to be. */
static lm_status plan_sample(const lm_dataset *d, lm_data_split split, long i, sample_plan *p,
                             lm_err *err)
{
    const lm_dataset_cfg *c = &d->cfg;
    lm_rng r = lm_rng_split(&d->rng[split], (uint64_t)i);
    memset(p, 0, sizeof *p);
    float u_synth = lm_rng_uniform(&r), u_kind = lm_rng_uniform(&r);
    float k = lm_rng_uniform_range(&r, c->noise_min, c->noise_max);
    uint32_t pick = lm_rng_u32(&r), py = lm_rng_u32(&r), px = lm_rng_u32(&r);
    int fh = (int)lm_rng_below(&r, 2), fv = (int)lm_rng_below(&r, 2);
    p->synth_seed = lm_rng_u64(&r);
    p->synth_rng = lm_rng_split(&r, 1);
    p->noise_rng = lm_rng_split(&r, 2);
    int train = split == LM_SPLIT_TRAIN;
    lm_dataset_sample_info *in = &p->info;
    in->scene = -1;
    in->noise_k = train ? k : c->val_noise;
    (void)u_kind; /* drawn still: the other draws of a sample keep their place in the stream */
    if (train && u_synth < c->synth_fraction) {
        in->kind = LM_SAMPLE_NARROWBAND;
    } else if (train && u_synth < c->synth_fraction + c->procedural_fraction) {
        in->kind = LM_SAMPLE_PROCEDURAL;
    } else if (train && u_synth < c->synth_fraction + c->procedural_fraction + c->fine_fraction) {
        in->kind = LM_SAMPLE_FINE;
    } else {
        int n = d->count[split];
        if (n == 0)
            return lm_err_set(err, LM_ERR_ARG, "dataset: the %s split has no scene (%d scenes "
                              "listed, %d smaller than the %d x %d patch)", train ? "training"
                              : split == LM_SPLIT_VAL ? "validation" : "test", d->nscenes,
                              d->too_small, c->patch_h, c->patch_w);
        in->kind = LM_SAMPLE_SCENE;
        in->scene = train ? (int)(pick % (uint32_t)n) : (int)(i % n);
        const scene *s = &d->scenes[d->list[split][in->scene]];
        int tr = c->sys->tile_rows, tc = c->sys->tile_cols;
        in->y0 = tr * (int)(py % (uint32_t)((s->height - c->patch_h) / tr + 1));
        in->x0 = tc * (int)(px % (uint32_t)((s->width - c->patch_w) / tc + 1));
    }
    in->flip_h = train && c->flips ? fh : 0;
    in->flip_v = train && c->flips ? fv : 0;
    /* spectral augmentation from a stream of its own (the draws above keep their values) */
    lm_rng ra = lm_rng_split(&r, 3);
    const float tilt = lm_rng_uniform_range(&ra, -1.0f, 1.0f);
    in->illum_tilt = train ? tilt * c->illum_jitter : 0.0f;
    const int jitter = train && c->gain_jitter > 0.0f;
    for (int l = 0; l < c->sys->nleds && l < LM_SYSTEM_MAX_LEDS; l++) {
        const float g = jitter ? 1.0f + c->gain_jitter * lm_rng_normal(&ra) : 1.0f;
        in->led_gain[l] = g > 0.1f ? g : 0.1f;
    }
    /* geometric augmentation, from a stream of its own too */
    lm_rng rg = lm_rng_split(&r, 4);
    const float uz = lm_rng_uniform_range(&rg, -1.0f, 1.0f), uy = lm_rng_uniform(&rg),
                ux = lm_rng_uniform(&rg);
    const int turn = (int)lm_rng_below(&rg, 2);
    in->zoom = 1.0f, in->transpose = 0;
    in->sy0 = (float)in->y0, in->sx0 = (float)in->x0;
    if (train && in->kind == LM_SAMPLE_SCENE && (c->scale_jitter > 0.0f || c->transpose)) {
        const scene *s = &d->scenes[d->list[split][in->scene]];
        int t = c->transpose && turn && s->height >= c->patch_w && s->width >= c->patch_h;
        const int rh = t ? c->patch_w : c->patch_h, rw = t ? c->patch_h : c->patch_w;
        float z = c->scale_jitter > 0.0f ? powf(1.0f + c->scale_jitter, uz) : 1.0f;
        z = fminf(z, fminf((float)s->height / (float)rh, (float)s->width / (float)rw));
        in->zoom = z, in->transpose = t;
        if (z == 1.0f && t) { /* whole pixels */
            in->sy0 = fminf(floorf(uy * (float)(s->height - rh + 1)), (float)(s->height - rh));
            in->sx0 = fminf(floorf(ux * (float)(s->width - rw + 1)), (float)(s->width - rw));
        } else if (z != 1.0f) {
            in->sy0 = uy * fmaxf((float)s->height - (float)rh * z, 0.0f);
            in->sx0 = ux * fmaxf((float)s->width - (float)rw * z, 0.0f);
        } /* else the plain patch, on the tile grid */
    }
    /* collage: a second scene patch across an edge, from a stream of its own as well */
    lm_rng rc = lm_rng_split(&r, 5);
    const float u_col = lm_rng_uniform(&rc);
    const uint32_t pick2 = lm_rng_u32(&rc), py2 = lm_rng_u32(&rc), px2 = lm_rng_u32(&rc);
    const int fh2 = (int)lm_rng_below(&rc, 2), fv2 = (int)lm_rng_below(&rc, 2);
    const float th = lm_rng_uniform_range(&rc, 0.0f, 6.2831853f), ey = lm_rng_uniform(&rc),
                ex = lm_rng_uniform(&rc);
    in->mix_scene = -1;
    /* clipping as a 16-bit PNG frame holds values, from a stream of its own */
    lm_rng rk = lm_rng_split(&r, 6);
    const float u_clip = lm_rng_uniform(&rk);
    in->clip = c->sensor_clip || (train && u_clip < c->clip_fraction);
    /* a noiseless training sample, from a stream of its own */
    lm_rng rn = lm_rng_split(&r, 7);
    in->clean = train && lm_rng_uniform(&rn) < c->clean_fraction;
    if (in->clean) in->noise_k = 0.0f;
    if (train && in->kind == LM_SAMPLE_SCENE && u_col < c->collage) {
        const int n = d->count[split];
        const scene *s2 = &d->scenes[d->list[split][(int)(pick2 % (uint32_t)n)]];
        in->collage = 1;
        in->mix_scene = (int)(pick2 % (uint32_t)n);
        in->mix_y0 = (int)(py2 % (uint32_t)(s2->height - c->patch_h + 1));
        in->mix_x0 = (int)(px2 % (uint32_t)(s2->width - c->patch_w + 1));
        in->mix_flip_h = c->flips ? fh2 : 0, in->mix_flip_v = c->flips ? fv2 : 0;
        in->edge_nx = cosf(th), in->edge_ny = sinf(th);
        const float cy = (float)c->patch_h * (0.25f + 0.5f * ey),
                    cx = (float)c->patch_w * (0.25f + 0.5f * ex);
        in->edge_c = in->edge_nx * cx + in->edge_ny * cy;
    }
    return LM_OK;
}

/* Blend the collage's second patch into out (the first), as lm_dataset_sample_info says. */
static lm_status paste_collage(lm_dataset *d, const lm_dataset_sample_info *in,
                               lm_data_split split, lm_cube *out, lm_err *err)
{
    scene_ref ref = {-1, {0}, NULL};
    lm_status st = lm_ds_scene_acquire(d, d->list[split][in->mix_scene], &ref, err);
    if (st) return st;
    const lm_cube *src = ref.cube;
    const int ph = out->height, pw = out->width;
    for (int y = 0; y < ph; y++)
        for (int x = 0; x < pw; x++) {
            float w = 0.5f + in->edge_nx * ((float)x + 0.5f) + in->edge_ny * ((float)y + 0.5f) -
                      in->edge_c;
            w = w < 0.0f ? 0.0f : w > 1.0f ? 1.0f : w;
            if (w == 0.0f) continue;
            const int sy = in->mix_y0 + (in->mix_flip_v ? ph - 1 - y : y),
                      sx = in->mix_x0 + (in->mix_flip_h ? pw - 1 - x : x);
            for (int b = 0; b < LM_GRID31_COUNT; b++) {
                float *o = lm_cube_band(out, b) + (size_t)y * pw + x;
                const float v = lm_cube_band(src, b)[(size_t)sy * src->width + sx];
                *o = w == 1.0f ? v : (1.0f - w) * *o + w * v;
            }
        }
    lm_ds_scene_release(d, &ref);
    return LM_OK;
}

/* The source pixels and weights of n patch pixels along one axis of a region starting at s0,
 * z source pixels per patch pixel, in a source of len pixels: taps per pixel (idx, w: n x
 * taps). z >= 1: the area average over [s0 + i z, s0 + (i + 1) z); z < 1: linear
 * interpolation at the pixel's centre s0 + (i + 0.5) z - 0.5. Indices clamped to the source. */
static void axis_taps(int n, float s0, float z, int len, int taps, int *idx, float *w)
{
    for (int i = 0; i < n; i++) {
        int *ix = idx + (size_t)i * taps;
        float *wi = w + (size_t)i * taps;
        for (int k = 0; k < taps; k++) ix[k] = 0, wi[k] = 0.0f;
        if (z >= 1.0f) {
            const double a = (double)s0 + (double)i * z, b = a + z;
            int k = 0;
            for (long p = (long)floor(a); p < (long)ceil(b) && k < taps; p++) {
                const double lo = fmax(a, (double)p), hi = fmin(b, (double)(p + 1));
                if (hi <= lo) continue;
                ix[k] = (int)(p < 0 ? 0 : p >= len ? len - 1 : p);
                wi[k++] = (float)((hi - lo) / z);
            }
            for (; k < taps; k++) ix[k] = ix[0]; /* unused: weight 0, inside the span */
        } else {
            const double c = (double)s0 + (i + 0.5) * z - 0.5;
            const long p = (long)floor(c);
            const float f = (float)(c - (double)p);
            ix[0] = (int)(p < 0 ? 0 : p >= len ? len - 1 : p);
            ix[1] = (int)(p + 1 < 0 ? 0 : p + 1 >= len ? len - 1 : p + 1);
            wi[0] = 1.0f - f, wi[1] = f;
            for (int k = 2; k < taps; k++) ix[k] = ix[0];
        }
    }
}

/* The 31-band patch of a zoomed or transposed sample (flips applied to the patch), in two
 * passes: the region's rows from the scene's (over the columns the taps reach), then each
 * patch pixel from its region row. */
static lm_status resample_patch(const lm_cube *src, const lm_dataset_sample_info *in, int ph,
                                int pw, lm_cube *out, lm_err *err)
{
    const int rh = in->transpose ? pw : ph, rw = in->transpose ? ph : pw;
    const int taps = (int)ceilf(in->zoom) + 2;
    int *iy = malloc(sizeof(int) * (size_t)rh * taps), *ix = malloc(sizeof(int) * (size_t)rw * taps);
    float *wy = malloc(sizeof(float) * (size_t)rh * taps);
    float *wx = malloc(sizeof(float) * (size_t)rw * taps);
    float *rows = NULL;
    int c0 = 0, span = 0;
    if (iy && ix && wy && wx) {
        axis_taps(rh, in->sy0, in->zoom, src->height, taps, iy, wy);
        axis_taps(rw, in->sx0, in->zoom, src->width, taps, ix, wx);
        int c1 = ix[0];
        c0 = ix[0];
        for (int k = 1; k < rw * taps; k++) c0 = ix[k] < c0 ? ix[k] : c0, c1 = ix[k] > c1 ? ix[k] : c1;
        span = c1 - c0 + 1;
        rows = malloc(sizeof(float) * (size_t)rh * span);
    }
    if (!rows) {
        free(iy), free(ix), free(wy), free(wx);
        return lm_err_set(err, LM_ERR_NOMEM, "dataset: out of memory resampling a patch");
    }
    for (int b = 0; b < LM_GRID31_COUNT; b++) {
        const float *sb = lm_cube_band(src, b) + c0;
        float *db = lm_cube_band(out, b);
        for (int a = 0; a < rh; a++) { /* region row a over the columns c0 .. c0 + span - 1 */
            float *r = rows + (size_t)a * span;
            for (int c = 0; c < span; c++) r[c] = 0.0f;
            for (int i = 0; i < taps; i++) {
                const float w = wy[(size_t)a * taps + i];
                if (w == 0.0f) continue;
                const float *srow = sb + (size_t)iy[(size_t)a * taps + i] * src->width;
                for (int c = 0; c < span; c++) r[c] += w * srow[c];
            }
        }
        for (int y = 0; y < ph; y++)
            for (int x = 0; x < pw; x++) {
                const int yy = in->flip_v ? ph - 1 - y : y, xx = in->flip_h ? pw - 1 - x : x;
                const int ra = in->transpose ? xx : yy, rb = in->transpose ? yy : xx;
                const float *r = rows + (size_t)ra * span;
                const int *px = ix + (size_t)rb * taps;
                const float *qx = wx + (size_t)rb * taps;
                float acc = 0.0f;
                for (int j = 0; j < taps; j++) acc += qx[j] * r[px[j] - c0];
                db[(size_t)y * pw + x] = acc;
            }
    }
    free(iy), free(ix), free(wy), free(wx), free(rows);
    return LM_OK;
}

lm_status lm_dataset_sample_info_get(const lm_dataset *d, lm_data_split split, long i,
                                     lm_dataset_sample_info *info, lm_err *err)
{
    if ((int)split < 0 || split > LM_SPLIT_TEST || i < 0)
        return lm_err_set(err, LM_ERR_ARG, "dataset: bad split %d or sample %ld", (int)split, i);
    sample_plan p;
    lm_status st = plan_sample(d, split, i, &p, err);
    if (st == LM_OK) *info = p.info;
    return st;
}

/* The 31-band patch of a sample, flips, zoom and transposition applied. */
static lm_status sample_cube(lm_dataset *d, sample_plan *p, lm_data_split split, lm_cube *out,
                             lm_err *err)
{
    int ph = d->cfg.patch_h, pw = d->cfg.patch_w;
    const lm_dataset_sample_info *in = &p->info;
    if (in->kind == LM_SAMPLE_NARROWBAND) return lm_synth_gauss_patch(&p->synth_rng, ph, pw, out,
                                                                       NULL, err);
    lm_cube src = {0};
    scene_ref ref = {-1, {0}, NULL};
    lm_status st;
    if (in->kind == LM_SAMPLE_PROCEDURAL) {
        st = lm_synth_scene(p->synth_seed, ph, pw, &d->pal, &src, err);
    } else if (in->kind == LM_SAMPLE_FINE) {
        st = lm_synth_fine(p->synth_seed, ph, pw, &d->pal, &src, err);
    } else {
        st = lm_ds_scene_acquire(d, d->list[split][in->scene], &ref, err);
        if (st == LM_OK) src = *ref.cube;
    }
    if (st == LM_OK) st = lm_cube_alloc(out, LM_GRID31_COUNT, ph, pw, LM_GRID31_START, 10.0f);
    if (st == LM_OK && (in->zoom != 1.0f || in->transpose)) {
        st = resample_patch(&src, in, ph, pw, out, err);
    } else if (st == LM_OK) {
        int y0 = in->y0, x0 = in->x0; /* 0, 0 for synthetic patches */
        for (int b = 0; b < LM_GRID31_COUNT; b++)
            for (int y = 0; y < ph; y++) {
                int sy = y0 + (in->flip_v ? ph - 1 - y : y);
                const float *srow = lm_cube_band(&src, b) + (size_t)sy * src.width + x0;
                float *drow = lm_cube_band(out, b) + (size_t)y * pw;
                for (int x = 0; x < pw; x++) drow[x] = srow[in->flip_h ? pw - 1 - x : x];
            }
    }
    if (in->kind == LM_SAMPLE_PROCEDURAL || in->kind == LM_SAMPLE_FINE) lm_cube_free(&src);
    else if (ref.cube) lm_ds_scene_release(d, &ref);
    if (st == LM_OK && in->collage) st = paste_collage(d, in, split, out, err);
    return st;
}

/* The sample's photo-electrons at full scale: photons, or for a training sample with a
 * photons_min, log-uniform in [photons_min, photons] (from a stream of its own, so the other
 * noise numbers of the sample stay those of a fixed count). */
static double sample_photons(const lm_dataset_cfg *c, lm_data_split split, const lm_rng *noise)
{
    if (!(c->photons_min > 0.0 && c->photons > c->photons_min) || split != LM_SPLIT_TRAIN)
        return c->photons;
    lm_rng r = lm_rng_split(noise, 7);
    double u = lm_rng_uniform(&r);
    return exp(log(c->photons_min) + u * (log(c->photons) - log(c->photons_min)));
}

/* The illumination tilt of a sample on its 31-band cube (400..700 nm), in place. */
static void apply_tilt(lm_cube *c31, float t)
{
    if (t == 0.0f) return;
    double f[LM_GRID31_COUNT], mx = 0.0;
    for (int b = 0; b < LM_GRID31_COUNT; b++) {
        f[b] = exp(t * (LM_GRID31_START + 10.0 * b - 550.0) / 150.0);
        if (f[b] > mx) mx = f[b];
    }
    const size_t np = (size_t)c31->height * c31->width;
    for (int b = 0; b < LM_GRID31_COUNT; b++) {
        float *p = lm_cube_band(c31, b);
        const float s = (float)(f[b] / mx);
        for (size_t i = 0; i < np; i++) p[i] *= s;
    }
}

/* The noise-free buckets of a sample: the system's, or with the sample's LED gain factors a
 * copy of it whose responses are scaled (the tile map and everything else shared). */
static lm_status clean_frame(const lm_system *sys, const lm_dataset_sample_info *in,
                             const lm_cube *c41, float *b1, float *b0, lm_err *err)
{
    int jitter = 0;
    for (int l = 0; l < sys->nleds; l++) jitter |= in->led_gain[l] != 1.0f;
    if (!jitter) return lm_forward_clean(sys, c41, 0, 0, b1, b0, 1, err);
    lm_system js = *sys;
    lm_led leds[LM_SYSTEM_MAX_LEDS];
    float *resp = malloc(sizeof(float) * (size_t)sys->nleds * sys->nbins);
    if (!resp) return lm_err_set(err, LM_ERR_NOMEM, "dataset: out of memory");
    for (int l = 0; l < sys->nleds; l++) {
        leds[l] = sys->leds[l];
        leds[l].response = resp + (size_t)l * sys->nbins;
        for (int b = 0; b < sys->nbins; b++)
            leds[l].response[b] = sys->leds[l].response[b] * in->led_gain[l];
    }
    js.leds = leds;
    lm_status st = lm_forward_clean(&js, c41, 0, 0, b1, b0, 1, err);
    free(resp);
    return st;
}

/* Sample i of a split; noisy 0: the clean frame (no noise, clipping or quantisation). */
static lm_status make_sample(lm_dataset *d, lm_data_split split, long i, int noisy, float *raw,
                             float *target, lm_err *err)
{
    sample_plan p;
    lm_status st = plan_sample(d, split, i, &p, err);
    lm_cube c31 = {0}, c41 = {0}, t33 = {0};
    if (st == LM_OK) st = sample_cube(d, &p, split, &c31, err);
    if (st == LM_OK) apply_tilt(&c31, p.info.illum_tilt);
    if (st == LM_OK) st = lm_cube_mirror41(&c31, &c41, err);
    const int ph = d->cfg.patch_h, pw = d->cfg.patch_w, two = d->cfg.buckets == 2;
    float *b0 = two ? raw + (size_t)ph * pw : NULL; /* raw bucket 0 until scaled below */
    if (st == LM_OK) st = clean_frame(d->cfg.sys, &p.info, &c41, raw, b0, err);
    const int shot = !p.info.clean && (d->cfg.photons > 0 || d->cfg.read_noise > 0.0f);
    if (st == LM_OK && noisy && (p.info.noise_k > 0.0f || p.info.clip || d->cfg.sensor_bits ||
                                 shot)) {
        lm_noise_opts no = {0};
        no.gauss_k = p.info.noise_k;
        no.clip = p.info.clip;
        no.bits = d->cfg.sensor_bits;
        no.photons = sample_photons(&d->cfg, split, &p.noise_rng); /* shot and read noise */
        no.read_noise = d->cfg.read_noise;
        if (p.info.clean) no.photons = 0.0, no.read_noise = 0.0f;
        st = lm_forward_noise(raw, ph, pw, &no, &p.noise_rng, 1, err);
        /* bucket 0 next from the same generator (lm_forward_noise advanced it), as
         * lm_forward_simulate does: bucket 1's numbers are those of a one-bucket sample */
        lm_noise_opts n0 = lm_forward_bucket0_noise(&no, d->cfg.sys->nleds);
        if (st == LM_OK && two) st = lm_forward_noise(b0, ph, pw, &n0, &p.noise_rng, 1, err);
    }
    if (st == LM_OK && two) {
        const int nl = d->cfg.sys->nleds;
        const float f = nl > 1 ? 1.0f / (float)(nl - 1) : 1.0f; /* as simulate --bucket0 */
        for (size_t k = 0; k < (size_t)ph * pw; k++) b0[k] *= f;
    }
    if (st == LM_OK) st = lm_cube_target33(&c41, &t33, err);
    if (st == LM_OK)
        memcpy(target, t33.data, (size_t)LM_TARGET_CHANNELS * t33.height * t33.width *
               sizeof(float));
    lm_cube_free(&c31);
    lm_cube_free(&c41);
    lm_cube_free(&t33);
    return st;
}

lm_status lm_ds_make_sample(lm_dataset *d, lm_data_split split, long i, float *raw,
                            float *target, lm_err *err)
{
    return make_sample(d, split, i, 1, raw, target, err);
}

lm_status lm_dataset_sample_clean(lm_dataset *d, long i, float *raw, float *target, lm_err *err)
{
    if (i < 0) return lm_err_set(err, LM_ERR_ARG, "dataset: bad sample %ld", i);
    return make_sample(d, LM_SPLIT_TRAIN, i, 0, raw, target, err);
}

/* ---- evaluation samples, accessors ------------------------------------------------------ */
int lm_dataset_eval_count(const lm_dataset *d, lm_data_split split)
{
    if (split != LM_SPLIT_VAL && split != LM_SPLIT_TEST) return 0;
    return d->count[split] > 0 ? d->cfg.val_patches : 0;
}

lm_status lm_dataset_eval_sample(lm_dataset *d, lm_data_split split, int i, float *raw,
                                 float *target, lm_err *err)
{
    if (split != LM_SPLIT_VAL && split != LM_SPLIT_TEST)
        return lm_err_set(err, LM_ERR_ARG, "dataset eval sample: split must be validation or "
                          "test");
    if (i < 0 || i >= lm_dataset_eval_count(d, split))
        return lm_err_set(err, LM_ERR_ARG, "dataset eval sample: index %d outside 0..%d", i,
                          lm_dataset_eval_count(d, split) - 1);
    return lm_ds_make_sample(d, split, i, raw, target, err);
}

int lm_dataset_buckets(const lm_dataset *d) { return d->cfg.buckets == 2 ? 2 : 1; }

int lm_dataset_num_scenes(const lm_dataset *d, lm_data_split split)
{
    return (int)split >= 0 && split <= LM_SPLIT_TEST ? d->count[split] : 0;
}

const char *lm_dataset_scene_name(const lm_dataset *d, lm_data_split split, int i)
{
    return i < 0 || i >= lm_dataset_num_scenes(d, split) ? NULL : d->scenes[d->list[split][i]].name;
}

const char *lm_dataset_scene_path(const lm_dataset *d, lm_data_split split, int i)
{
    return i < 0 || i >= lm_dataset_num_scenes(d, split) ? NULL : d->scenes[d->list[split][i]].path;
}

int lm_dataset_split_borrowed(const lm_dataset *d, lm_data_split split)
{
    return (int)split >= 0 && split <= LM_SPLIT_TEST ? d->borrowed[split] : 0;
}

static int listed(const lm_dataset_scene *s, int n, const char *path)
{
    for (int i = 0; i < n; i++)
        if (!strcmp(s[i].path, path)) return 1;
    return 0;
}

lm_status lm_dataset_list_scenes(const char *const *paths, int npaths, const lm_system *sys,
                                 const char *mat_key, int split, lm_dataset_scene **out, int *n,
                                 lm_err *err)
{
    *out = NULL;
    *n = 0;
    lm_dataset_cfg cfg;
    lm_dataset_default_cfg(&cfg);
    cfg.paths = paths;
    cfg.npaths = npaths;
    cfg.sys = sys;
    cfg.workers = 0;
    cfg.synth_fraction = 0.0f;
    cfg.mat_key = mat_key;
    lm_dataset *d = lm_dataset_open(&cfg, err);
    if (!d) return err->status;
    int total = 0;
    for (int k = 0; k < 3; k++) total += d->count[k];
    lm_dataset_scene *s = calloc((size_t)total + 1, sizeof *s);
    if (!s) {
        lm_dataset_close(d);
        return lm_err_set(err, LM_ERR_NOMEM, "out of memory");
    }
    for (int k = 0; k < 3; k++) {
        if ((split >= 0 && k != split) || d->borrowed[k]) continue;
        for (int i = 0; i < d->count[k]; i++) {
            const scene *sc = &d->scenes[d->list[k][i]];
            if (listed(s, *n, sc->path)) continue;
            snprintf(s[*n].name, sizeof s->name, "%s", sc->name);
            snprintf(s[*n].path, sizeof s->path, "%s", sc->path);
            s[(*n)++].split = (lm_data_split)k;
        }
    }
    lm_dataset_close(d);
    *out = s;
    return LM_OK;
}

int lm_dataset_split_of_scene(const lm_dataset *d, const char *name_or_path)
{
    for (int pass = 0; pass < 2; pass++)
        for (int i = 0; i < d->nscenes; i++)
            if (!strcmp(pass ? d->scenes[i].name : d->scenes[i].path, name_or_path))
                return (int)d->scenes[i].split;
    return -1;
}

/* ": a, b, c" — the scene names of split k's list. */
static void describe_names(const lm_dataset *d, int k, FILE *f)
{
    for (int i = 0; i < d->count[k]; i++)
        fprintf(f, "%s%s", i ? ", " : ": ", d->scenes[d->list[k][i]].name);
}

void lm_dataset_describe(const lm_dataset *d, FILE *f)
{
    static const char *names[3] = {"train", "val", "test"};
    const lm_dataset_cfg *c = &d->cfg;
    char noise[64]; /* the training noise level k (docs/system.md, Noise) */
    if (c->noise_max <= 0) snprintf(noise, sizeof noise, "noise: none");
    else if (c->noise_min == c->noise_max)
        snprintf(noise, sizeof noise, "noise k = %g", c->noise_min);
    else snprintf(noise, sizeof noise, "noise k ~ U[%g, %g]", c->noise_min, c->noise_max);
    char shot[256] = ""; /* shot and read noise, drawn before k; augmentation */
    if (c->photons > 0 && c->photons_min > 0)
        snprintf(shot, sizeof shot, "; shot noise %g..%g e- at full scale (log-uniform; "
                 "validation %g)", c->photons_min, c->photons, c->photons);
    else if (c->photons > 0)
        snprintf(shot, sizeof shot, "; shot noise %g e- at full scale", c->photons);
    if (c->read_noise > 0)
        snprintf(shot + strlen(shot), sizeof shot - strlen(shot), "; read noise %g %s",
                 (double)c->read_noise, c->photons > 0 ? "e-" : "of full scale");
    if (c->illum_jitter > 0)
        snprintf(shot + strlen(shot), sizeof shot - strlen(shot), "; illumination tilt t ~ "
                 "U[-%g, %g]", (double)c->illum_jitter, (double)c->illum_jitter);
    if (c->gain_jitter > 0)
        snprintf(shot + strlen(shot), sizeof shot - strlen(shot), "; LED gain error sd %g",
                 (double)c->gain_jitter);
    if (c->scale_jitter > 0)
        snprintf(shot + strlen(shot), sizeof shot - strlen(shot), "; zoom %.3g..%.3g",
                 1.0 / (1.0 + c->scale_jitter), 1.0 + c->scale_jitter);
    if (c->transpose)
        snprintf(shot + strlen(shot), sizeof shot - strlen(shot), "; transposes");
    if (c->clip_fraction > 0 && !c->sensor_clip)
        snprintf(shot + strlen(shot), sizeof shot - strlen(shot), "; clipped to [0, 1] %.0f%%",
                 100.0 * c->clip_fraction);
    if (c->clean_fraction > 0)
        snprintf(shot + strlen(shot), sizeof shot - strlen(shot), "; without noise %.0f%%",
                 100.0 * c->clean_fraction);
    if (c->collage > 0)
        snprintf(shot + strlen(shot), sizeof shot - strlen(shot), "; collage %.0f%%",
                 100.0 * c->collage);
    if (c->fine_fraction > 0)
        snprintf(shot + strlen(shot), sizeof shot - strlen(shot), "; fine narrowband synthetic "
                 "%.0f%%", 100.0 * c->fine_fraction);
    fprintf(f, "dataset: %d scenes in %d groups; patch %d x %d; narrowband synthetic %.0f%%, "
            "procedural %.0f%%; %s%s; flips %s; seed %llu; %d "
            "workers; cache %d scenes%s\n", d->nscenes, d->ngroups, c->patch_h, c->patch_w,
            100.0 * c->synth_fraction, 100.0 * c->procedural_fraction, noise, shot,
            c->flips ? "on" : "off", (unsigned long long)c->seed, d->nthreads, d->cache_cap,
            c->buckets == 2 ? "; both buckets (bucket 1, bucket 0 / (LEDs - 1))" : "");
    fprintf(f, "  split by scene group (name without a _crop<N> or _<height|width> tag): test "
            "and val take %d of the %d groups each (a tenth, rounded), by hash rank\n",
            (d->ngroups + 5) / 10, d->ngroups);
    for (int k = 0; k < 3; k++) {
        fprintf(f, "  %-5s %d scenes%s", names[k], d->count[k],
                d->borrowed[k] ? " (borrowed: fewer than 3 scenes, this split reuses all of "
                                 "them)" : "");
        if (k > 0) fprintf(f, ", %d fixed samples (noise k = %g)", lm_dataset_eval_count(d, k),
                           c->val_noise);
        if (d->count[k] == 0) fprintf(f, " (no scene here: %s)", k ? "not evaluated"
                                      : "synthetic samples only");
        if (k > 0 && !d->borrowed[k]) describe_names(d, k, f);
        fputc('\n', f);
    }
    if (d->too_small)
        fprintf(f, "  %d scenes smaller than the patch are not used\n", d->too_small);
}

/* ---- open / close ----------------------------------------------------------------------- */
static lm_status check_cfg(const lm_dataset_cfg *c, lm_err *err)
{
    const lm_system *s = c->sys;
    if (!s) return lm_err_set(err, LM_ERR_ARG, "dataset: no system description");
    if (s->nbins != LM_GRID41_COUNT || fabsf(s->grid_start - LM_GRID41_START) > 0.01f ||
        fabsf(s->grid_step - LM_GRID41_STEP) > 0.01f)
        return lm_err_set(err, LM_ERR_ARG, "dataset: the system '%s' must use the 380..780 nm "
                          "grid of 41 bins (has %d bins from %g nm)", s->name, s->nbins,
                          s->grid_start);
    if (c->patch_h < 1 || c->patch_w < 1 || c->patch_h % s->tile_rows ||
        c->patch_w % s->tile_cols)
        return lm_err_set(err, LM_ERR_SHAPE, "dataset: patch %d x %d is not a positive multiple "
                          "of the %d x %d tile", c->patch_h, c->patch_w, s->tile_rows,
                          s->tile_cols);
    if (!(c->synth_fraction >= 0.0f && c->procedural_fraction >= 0.0f &&
          c->fine_fraction >= 0.0f &&
          c->synth_fraction + c->procedural_fraction + c->fine_fraction <= 1.0f))
        return lm_err_set(err, LM_ERR_ARG, "dataset: synth_fraction, procedural_fraction and "
                          "fine_fraction must be >= 0 with a sum <= 1 (got %g, %g, %g)",
                          c->synth_fraction, c->procedural_fraction, c->fine_fraction);
    if (!(c->noise_min >= 0.0f && c->noise_max >= c->noise_min && isfinite(c->noise_max)) ||
        !(c->val_noise >= 0.0f && isfinite(c->val_noise)))
        return lm_err_set(err, LM_ERR_ARG, "dataset: need 0 <= noise_min <= noise_max and "
                          "val_noise >= 0 (got %g, %g, %g)", c->noise_min, c->noise_max,
                          c->val_noise);
    if (c->workers < 0 || c->workers > DS_MAX_WORKERS || c->cache_scenes < 0 ||
        c->val_patches < 0 || c->npaths < 0 || (c->npaths > 0 && !c->paths))
        return lm_err_set(err, LM_ERR_ARG, "dataset: need 0 <= workers <= %d, cache_scenes >= 0, "
                          "val_patches >= 0 and a path list", DS_MAX_WORKERS);
    if (c->mat_key && strlen(c->mat_key) >= LM_DATASET_KEY_LEN)
        return lm_err_set(err, LM_ERR_ARG, "dataset: .mat key longer than %d characters",
                          LM_DATASET_KEY_LEN - 1);
    if (!(c->photons_min >= 0 && c->photons_min <= c->photons) && c->photons_min != 0)
        return lm_err_set(err, LM_ERR_ARG, "dataset: photons_min %g must be in [0, photons %g]",
                          c->photons_min, c->photons);
    if (!(c->photons >= 0 && c->photons <= 1e12) || !(c->read_noise >= 0 && c->read_noise <= 1e6))
        return lm_err_set(err, LM_ERR_ARG, "dataset: photons %g (0..1e12) or read noise %g "
                          "(0..1e6) out of range", c->photons, (double)c->read_noise);
    if (!(c->illum_jitter >= 0.0f && c->illum_jitter <= 2.0f) ||
        !(c->gain_jitter >= 0.0f && c->gain_jitter <= 0.5f))
        return lm_err_set(err, LM_ERR_ARG, "dataset: illumination jitter %g (0..2) or LED gain "
                          "jitter %g (0..0.5) out of range", (double)c->illum_jitter,
                          (double)c->gain_jitter);
    if (!(c->scale_jitter >= 0.0f && c->scale_jitter <= 1.0f) || c->transpose < 0 ||
        c->transpose > 1)
        return lm_err_set(err, LM_ERR_ARG, "dataset: scale jitter %g (0..1) or transpose %d "
                          "(0|1) out of range", (double)c->scale_jitter, c->transpose);
    if (!(c->clip_fraction >= 0.0f && c->clip_fraction <= 1.0f))
        return lm_err_set(err, LM_ERR_ARG, "dataset: clip share %g out of range (0..1)",
                          (double)c->clip_fraction);
    if (!(c->clean_fraction >= 0.0f && c->clean_fraction <= 1.0f))
        return lm_err_set(err, LM_ERR_ARG, "dataset: noiseless share %g out of range (0..1)",
                          (double)c->clean_fraction);
    if (!(c->collage >= 0.0f && c->collage <= 1.0f))
        return lm_err_set(err, LM_ERR_ARG, "dataset: collage share %g out of range (0..1)",
                          (double)c->collage);
    if (c->buckets < 0 || c->buckets > 2)
        return lm_err_set(err, LM_ERR_ARG, "dataset: buckets %d (1: bucket 1 only, 2: both)",
                          c->buckets);
    if (c->npaths == 0 && c->synth_fraction + c->procedural_fraction + c->fine_fraction < 1.0f)
        return lm_err_set(err, LM_ERR_ARG, "dataset: no scene paths given (only a fully "
                          "synthetic dataset, synth_fraction + procedural_fraction = 1, needs "
                          "none)");
    return LM_OK;
}

static lm_status open_scenes(lm_dataset *d, lm_err *err)
{
    lm_status st = LM_OK;
    for (int p = 0; p < d->cfg.npaths && st == LM_OK; p++) st = add_path(d, d->cfg.paths[p], err);
    for (int i = 0; i < d->nscenes && st == LM_OK; i++) st = probe_scene(d, &d->scenes[i], err);
    if (st == LM_OK) st = build_splits(d, err);
    return st != LM_OK ? st : lm_ds_cache_init(d, err);
}

lm_dataset *lm_dataset_open(const lm_dataset_cfg *cfg, lm_err *err)
{
    if (check_cfg(cfg, err) != LM_OK) return NULL;
    lm_dataset *d = calloc(1, sizeof *d);
    if (!d) return lm_err_set(err, LM_ERR_NOMEM, "dataset: out of memory"), NULL;
    d->cfg = *cfg;
    snprintf(d->mat_key, sizeof d->mat_key, "%s", cfg->mat_key ? cfg->mat_key : "");
    d->cfg.mat_key = NULL; /* copied */
    pthread_mutex_init(&d->mu, NULL);
    pthread_cond_init(&d->work_cv, NULL);
    pthread_cond_init(&d->done_cv, NULL);
    lm_status st = open_scenes(d, err);
    d->cfg.paths = NULL; /* the caller's list is only read during open */
    if (st == LM_OK && cfg->synth_fraction + cfg->procedural_fraction + cfg->fine_fraction > 0.0f)
        st = lm_synth_palette_load(&d->pal, err);
    lm_rng base;
    lm_rng_seed(&base, cfg->seed);
    for (int k = 0; k < 3; k++) d->rng[k] = lm_rng_split(&base, 0x5EED0000u + (uint64_t)k);
    if (st == LM_OK) st = lm_ds_workers_start(d, err);
    if (st != LM_OK) {
        lm_dataset_close(d);
        return NULL;
    }
    return d;
}

void lm_dataset_close(lm_dataset *d)
{
    if (!d) return;
    lm_ds_workers_stop(d);
    lm_ds_cache_free(d);
    for (int i = 0; i < d->nscenes; i++)
        free(d->scenes[i].path), free(d->scenes[i].name), free(d->scenes[i].group);
    free(d->scenes);
    for (int k = 0; k < 3; k++) free(d->list[k]);
    pthread_cond_destroy(&d->work_cv);
    pthread_cond_destroy(&d->done_cv);
    pthread_mutex_destroy(&d->mu);
    free(d);
}

static int visible(const struct dirent *e) { return e->d_name[0] != '.'; }

uint64_t lm_scene_content_hash(const char *path)
{
    if (!lm_is_dir(path)) return lm_file_hash(path);
    struct dirent **list;
    int n = scandir(path, &list, visible, alphasort);
    if (n < 0) return 0;
    uint64_t h = LM_FNV1A_BASIS_SHORT;
    int any = 0;
    for (int i = 0; i < n; i++) {
        char f[DS_PATH_MAX];
        snprintf(f, sizeof f, "%s/%s", path, list[i]->d_name);
        struct stat st;
        if (stat(f, &st) == 0 && S_ISREG(st.st_mode)) {
            uint64_t fh = lm_file_hash(f);
            h = lm_fnv1a(h, &fh, sizeof fh);
            any = 1;
        }
        free(list[i]);
    }
    free(list);
    return any ? h : 0;
}

char *lm_dataset_split_hashes(const lm_dataset *d, lm_data_split split)
{
    int n = lm_dataset_num_scenes(d, split);
    char *out = malloc((size_t)n * 17 + 1);
    if (!out) return NULL;
    char *p = out;
    *p = 0;
    for (int i = 0; i < n; i++)
        p += sprintf(p, "%s%016" PRIx64, i ? "," : "",
                     lm_scene_content_hash(lm_dataset_scene_path(d, split, i)));
    return out;
}

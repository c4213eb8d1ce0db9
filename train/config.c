/* config.c — the training run configuration: defaults, JSON files, CLI flags, validation.
 * One table describes every field (JSON name, type, help); the JSON loader and the flag setter
 * both go through it, so every field is settable both ways and errors name the field.
 * Paths of "data" and "system" in a config file are relative to that file's folder.
 * What it is not: the loop (train.c). */
#include "train/train.h"
#include <errno.h>
#include <jansson.h>
#include <limits.h>
#include <math.h>
#include <stddef.h>
#include <stdlib.h>
#include <string.h>
#include <unistd.h>
#include "data/dataset.h"
#include "data/util.h"

typedef enum ftype { F_INT, F_LONG, F_U64, F_FLOAT, F_STR, F_LIST, F_PATCH, F_NOISE } ftype;

typedef struct field {
    const char *name;
    ftype type;
    size_t off;
    size_t size;      /* strings: buffer size */
    const char *arg, *help;
    double lo, hi;    /* numbers (each of a pair): the allowed range, checked before any
                       * conversion (a value that does not fit is an error, never wrapped) */
} field;

/* Upper bounds: what a run on one machine can use; far above any real run, low enough that
 * nothing downstream overflows (sizes multiply up to batch x 41 x patch_h x patch_w) or runs
 * for ever (every validation evaluates val_patches samples). */
#define MAX_COUNT 1e9      /* iterations and intervals */
#define MAX_PATCH 4096     /* each side of a patch */
#define MAX_BATCH 4096     /* as infer/eval --batch */
#define MAX_VAL_PATCHES 100000

#define FLD(n, t, m, a, h, lo, hi)                                                            \
    {n, t, offsetof(lm_train_cfg, m), sizeof(((lm_train_cfg *)0)->m), a, h, lo, hi}
static const field fields[] = {
    FLD("version", F_INT, version, "N", "config format version (1)", 1, 1),
    FLD("model", F_STR, model, "NAME", "model preset (lumosaic info --list)", 0, 0),
    FLD("system", F_STR, system, "FILE", "system description (default: bundled)", 0, 0),
    FLD("data", F_LIST, data, "PATH", "scene file or folder (repeatable)", 0, 0),
    FLD("mat_key", F_STR, mat_key, "NAME", ".mat scenes: the cube variable (default: the first "
        "of cube, hsi, rad, ref, ...)", 0, 0),
    FLD("synth_fraction", F_FLOAT, synth_fraction, "F", "share of the paper's synthetic samples "
        "(textureless narrowband spectra)", 0, 1),
    FLD("procedural_fraction", F_FLOAT, procedural_fraction, "F", "share of procedural scenes "
        "(textured, varied spectra; not in the paper; -1: 0.2, at most 1 - synth_fraction)", -1,
        1),
    FLD("fine_fraction", F_FLOAT, fine_fraction, "F", "share of procedural scenes with fine, "
        "saturated narrowband detail on top (thin strokes, iridescent sheets: where a mosaic "
        "aliases; not in the paper; 0 = none)", 0, 1),
    FLD("motion_fraction", F_FLOAT, motion_fraction, "F", "share of real-scene samples seen "
        "moving during the exposure (0)", 0, 1),
    FLD("motion_speed", F_FLOAT, motion_speed, "PX_S", "moving samples: translation speed "
        "uniform in [0, this] px/s (240)", 0, 1e5),
    FLD("motion_rotation", F_FLOAT, motion_rotation, "DEG_S", "moving samples: rotation uniform "
        "in [-this, this] deg/s about the patch centre (0)", 0, 1e5),
    FLD("motion_samples", F_INT, motion_samples, "N", "moving samples: instants per LED window "
        "(2)", 1, 64),
    FLD("patch", F_PATCH, patch_h, "HxW", "patch size, multiples of the tile (66x64)", 1,
        MAX_PATCH),
    FLD("batch", F_INT, batch, "N", "samples per forward pass (the preset's recipe; else 14)", 1, MAX_BATCH),
    FLD("accum_steps", F_INT, accum_steps, "N", "batches accumulated per update (recipe; else 2)", 1, 1024),
    FLD("iterations", F_LONG, iterations, "N", "optimizer updates (50000)", 1, MAX_COUNT),
    FLD("lr", F_FLOAT, lr, "F", "learning rate (recipe; else 1e-4)", 0, 10),
    FLD("schedule", F_STR, schedule, "S", "constant | cosine | step (recipe; else constant)", 0, 0),
    FLD("lr_min", F_FLOAT, lr_min, "F", "cosine: final learning rate (recipe; else 0)", 0, 10),
    FLD("warmup", F_LONG, warmup, "N", "linear warm-up updates (recipe; else 0)", 0, MAX_COUNT),
    FLD("step_every", F_LONG, step_every, "N", "step schedule: decay period", 0, MAX_COUNT),
    FLD("step_gamma", F_FLOAT, step_gamma, "F", "step schedule: decay factor", 0, 1),
    FLD("weight_decay", F_FLOAT, weight_decay, "F", "Adam L2 weight decay", 0, 10),
    FLD("ema", F_FLOAT, ema, "D", "decay of a moving average of the weights, which validation, "
        "snapshots and the checkpoint's model use (0 = none; e.g. 0.999; switched on by --fork "
        "or --resume it starts at the checkpoint's weights)", 0, 0.999999),
    FLD("noise", F_NOISE, noise_min, "MIN,MAX", "noise level range k (0,0.15)", 0, 1),
    FLD("val_noise", F_FLOAT, val_noise, "F", "noise level of validation samples", 0, 1),
    FLD("seed", F_U64, seed, "N", "random seed (init, data)", 0, 0),
    FLD("threads", F_INT, threads, "N", "compute threads (0 = all cores)", 0, LM_MAX_THREADS),
    FLD("device", F_STR, device, "NAME", "cpu | opencl (default: $LM_DEVICE, else cpu)", 0, 0),
    FLD("workers", F_INT, workers, "N", "data preparation threads", 0, LM_DATASET_MAX_WORKERS),
    FLD("val_interval", F_LONG, val_interval, "N", "updates between validations (0 = end)", 0,
        MAX_COUNT),
    FLD("val_patches", F_INT, val_patches, "N", "fixed validation samples", 0, MAX_VAL_PATCHES),
    FLD("checkpoint_interval", F_LONG, checkpoint_interval, "N", "updates between checkpoints",
        0, MAX_COUNT),
    FLD("log_interval", F_LONG, log_interval, "N", "updates between progress lines (no tty)", 1,
        MAX_COUNT),
    FLD("output", F_STR, output, "DIR", "run folder (checkpoints, log.csv)", 0, 0),
    FLD("fit", F_STR, fit, "M", "auto | closed | sgd (auto: closed form for lmmse presets)", 0,
        0),
    FLD("fit_patches", F_LONG, fit_patches, "N", "closed form: training patches (4096)", 1, 1e6),
    FLD("fit_synth", F_FLOAT, fit_synth, "F", "closed form: synthetic share of the statistics, "
        "0..1 (-1: chosen on the validation split)", -1, 1),
    FLD("fit_b0_noise", F_FLOAT, fit_b0_noise, "R", "closed form, two buckets: bucket 0's "
        "noise sd as a fraction of bucket 1's in the fit (0 = the same, the relative-Gaussian "
        "convention; about 0.3 for shot noise, where bucket 0 collects eleven LEDs' light)", 0,
        10),
    FLD("base", F_STR, base, "RUN", "train as a residual on this run's model (e.g. an lmmse "
        "fit)", 0, 0),
    FLD("base_trainable", F_INT, base_trainable, "0|1", "fine-tune the base with the net (0)", 0,
        1),
    FLD("res_init", F_FLOAT, res_init, "F", "residual: initial gates on the net's output (1; "
        "the net's output layers start at 0)", -1000, 1000),
    FLD("sensor_clip", F_INT, sensor_clip, "0|1", "clip noisy samples to [0, 1] as a 16-bit "
        "PNG frame holds them (0)", 0, 1),
    FLD("clip_fraction", F_FLOAT, clip_fraction, "F", "share of noisy training samples clipped "
        "to [0, 1] as a 16-bit PNG frame holds them, the rest keeping their negatives: a model "
        "for both kinds of frame (0; sensor_clip 1 clips them all)", 0, 1),
    FLD("clean_fraction", F_FLOAT, clean_fraction, "F", "share of training samples without "
        "noise (no Gaussian, shot or read noise), the rest drawn as noise / photons say: a model "
        "that denoises without losing its clean accuracy (0)", 0, 1),
    FLD("photons", F_FLOAT, photons, "P", "shot noise: photo-electrons at full scale (the "
        "brightest LED's white response; 0 = off), as simulate --poisson", 0, 1e12),
    FLD("photons_min", F_FLOAT, photons_min, "P", "shot noise over a range of light: each "
        "training sample's photo-electrons at full scale drawn log-uniformly in [this, photons] "
        "(0 = every sample at photons; validation samples: photons)", 0, 1e12),
    FLD("read_noise", F_FLOAT, read_noise, "E", "read noise: electrons with photons, else a "
        "fraction of full scale (0 = off), as simulate --read-noise", 0, 1e6),
    FLD("illum_jitter", F_FLOAT, illum_jitter, "A", "augmentation: each training sample's "
        "spectra tilted by exp(t (wavelength - 550 nm) / 150 nm), t ~ U[-A, A] (an illuminant of "
        "another colour; target and frame alike; 0 = off)", 0, 2),
    FLD("gain_jitter", F_FLOAT, gain_jitter, "S", "augmentation: each training sample's frame "
        "simulated with every LED's gain off by a factor 1 + S x N(0, 1) (a calibration error; "
        "the target is the scene's; 0 = off)", 0, 0.5),
    FLD("scale_jitter", F_FLOAT, scale_jitter, "S", "augmentation: each training scene patch "
        "resampled from a region z times its size, z = (1 + S)^u, u ~ U[-1, 1] (area average "
        "where z > 1, bilinear where z < 1; scenes seen at other scales; 0 = off)", 0, 1),
    FLD("transpose", F_INT, transpose, "0|1", "augmentation: training scene patches transposed "
        "half of the time (with the flips: every quarter turn and mirror; 0 = off)", 0, 1),
    FLD("collage", F_FLOAT, collage, "F", "augmentation: share of training scene patches with "
        "a patch of another training scene pasted in across a straight edge of random direction "
        "(more material boundaries than the scenes hold; 0 = off)", 0, 1),
    FLD("sensor_bits", F_INT, sensor_bits, "N", "quantise samples to N bits (0 = off; 16 = PNG)",
        0, 24),
    FLD("buckets", F_INT, buckets, "1|2", "coded-frame buckets the model reads: 1 (bucket 1, the "
        "paper) or 2 (bucket 1 and bucket 0 / (LEDs - 1); the model's \"-b2\" preset; a -b2 "
        "preset sets 2)", 1, 2),
    FLD("frames", F_INT, frames, "1|3", "coded frames per sample: 1, or 3 (frames i-1, i, i+1 "
        "aligned onto frame i: the model's \"-mf3\" preset; a -mf3 preset sets 3)", 1, 3),
    FLD("snapshots", F_STR, snapshots, "M,M,...", "weights at these minutes of training into "
        "<output>/snapshots/<M>min/", 0, 0),
    FLD("minutes", F_FLOAT, minutes, "M", "time budget in minutes (0 = none; the schedule "
        "spans it; a closed-form fit reads training patches until then and solves from them)",
        0, 1e6),
    FLD("clock", F_STR, clock, "C", "what minutes and snapshots count: wall | cpu (CPU time of "
        "the process, all threads; not shrunk by a busy machine)", 0, 0),
    FLD("precision", F_STR, precision, "P", "fp32 | bf16: bf16 operands (fp32 sums, master "
        "weights, Adam, loss) for the 3x3 convolutions' Winograd products, forward and input "
        "gradient; AMX tiles or AVX-512-BF16 where the CPU has them, else the same arithmetic "
        "slower", 0, 0),
    FLD("doe", F_STR, doe, "FILE", "qdo presets: DOE description (default: bundled; a run's "
        "doe.json)", 0, 0),
    FLD("doe_optimise", F_INT, doe_optimise, "0|1", "qdo presets: train the DOE's height map "
        "with the network (--optimise-doe: 1)", 0, 1),
    FLD("doe_lr", F_FLOAT, doe_lr, "F", "DOE optimisation: Adam learning rate of the heights "
        "(fractions of the maximum height; 0.01)", 0, 10),
    FLD("doe_quantise", F_STR, doe_quantise, "Q", "DOE optimisation: progressive | ste | none "
        "(quantisation to the DOE's levels in training)", 0, 0),
    FLD("doe_bands", F_INT, doe_bands, "N", "DOE optimisation: wavelengths whose PSFs get a "
        "gradient per update (4)", 1, 31),
    FLD("recipe", F_STR, recipe, "R", "preset | paper: what lr, batch, accum_steps, schedule, "
        "lr_min, warmup and synth_fraction default to: the model preset's measured recipe "
        "(docs/guide/training.md \"Training recipes\"; presets without one: the paper's values shown here) or "
        "the paper's protocol", 0, 0),
};
#define NFIELDS (int)(sizeof fields / sizeof fields[0])
_Static_assert(sizeof fields / sizeof fields[0] <= 64 * 2, "lm_train_cfg.given holds 128 bits");

float lm_train_procedural_share(const lm_train_cfg *c)
{
    if (c->procedural_fraction >= 0.0f) return c->procedural_fraction;
    float rest = 1.0f - c->synth_fraction;
    return rest < LM_TRAIN_PROCEDURAL_DEFAULT ? (rest > 0.0f ? rest : 0.0f)
                                              : LM_TRAIN_PROCEDURAL_DEFAULT;
}

void lm_train_cfg_default(lm_train_cfg *c)
{
    memset(c, 0, sizeof *c);
    c->version = LM_TRAIN_CFG_VERSION;
    snprintf(c->model, sizeof c->model, "han-paper");
    c->synth_fraction = 0.33f;
    c->procedural_fraction = -1.0f; /* lm_train_procedural_share: 0.2 (docs/guide/training.md) */
    c->motion_speed = 240.0f, c->motion_samples = 2;
    c->patch_h = 66, c->patch_w = 64;
    c->batch = 14, c->accum_steps = 2;
    c->iterations = 50000;
    c->lr = 1e-4f;
    snprintf(c->schedule, sizeof c->schedule, "constant");
    c->step_gamma = 0.5f;
    c->noise_min = 0.0f, c->noise_max = 0.15f;
    c->seed = 1;
    c->workers = 2;
    const char *dev = getenv("LM_DEVICE");
    snprintf(c->device, sizeof c->device, "%s", dev && *dev ? dev : "cpu"); /* checked later */
    c->val_interval = 1000;
    c->val_patches = 64;
    c->checkpoint_interval = 1000;
    c->log_interval = 100;
    c->buckets = 1;
    c->frames = 1;
    snprintf(c->output, sizeof c->output, "runs/train");
    snprintf(c->fit, sizeof c->fit, "auto");
    c->fit_patches = 4096;
    c->fit_synth = -1.0f;
    c->res_init = 1.0f;
    snprintf(c->clock, sizeof c->clock, "wall");
    snprintf(c->precision, sizeof c->precision, "fp32");
    c->doe_lr = 0.01f;
    snprintf(c->doe_quantise, sizeof c->doe_quantise, "progressive");
    c->doe_bands = 4;
    snprintf(c->recipe, sizeof c->recipe, "preset");
}

static const field *find_field(const char *key)
{
    char k[64];
    snprintf(k, sizeof k, "%s", key);
    for (char *p = k; *p; p++)
        if (*p == '-') *p = '_';
    for (int i = 0; i < NFIELDS; i++)
        if (!strcmp(fields[i].name, k)) return &fields[i];
    return NULL;
}

int lm_train_cfg_has(const char *key) { return find_field(key) != NULL; }

int lm_train_cfg_given(const lm_train_cfg *c, const char *key)
{
    const field *f = find_field(key);
    if (!f) return 0;
    int idx = (int)(f - fields);
    return (int)(c->given[idx / 64] >> (idx % 64) & 1);
}

static int parse_long(const char *s, long long *v) { return lm_parse_int(s, v) == 0; }

static int parse_double(const char *s, double *v) { return lm_parse_real(s, v) == 0; }

/* "lo..hi" of a field. */
static const char *range_text(const field *f, char *buf, size_t n)
{
    snprintf(buf, n, "%.15g..%.15g", f->lo, f->hi);
    return buf;
}

static int is_integer(const field *f) { return f->type != F_FLOAT && f->type != F_NOISE; }

/* "<where>: field '<name>': <v> is out of range (lo..hi)"; integers as given (`text`, or v). */
static lm_status out_of_range(const field *f, double v, const char *text, const char *where,
                              lm_err *err)
{
    char r[64], num[64];
    if (is_integer(f) && text) snprintf(num, sizeof num, "%s", text);
    else snprintf(num, sizeof num, is_integer(f) ? "%.0f" : "%.9g", v);
    return lm_err_set(err, LM_ERR_ARG, "%s: field '%s': %s is out of range (%s)", where,
                      f->name, num, range_text(f, r, sizeof r));
}

/* One number of field f from text, range-checked before it is converted: 1, or 0 if the text
 * is not a number of the field's kind (error set: out of range). */
static int number(const field *f, const char *s, double *v, const char *where, lm_err *err)
{
    long long l;
    int integer = is_integer(f);
    if (integer ? !parse_long(s, &l) : !parse_double(s, v)) return 0;
    if (integer) *v = (double)l;
    if (integer ? l < f->lo || l > f->hi : !(*v >= f->lo && *v <= f->hi))
        return out_of_range(f, *v, s, where, err), -1;
    return 1;
}

static lm_status put_string(lm_train_cfg *c, const field *f, const char *v, const char *where,
                            lm_err *err)
{
    char *dst = (char *)c + f->off;
    if (f->type == F_LIST) {
        if (c->ndata >= LM_TRAIN_MAX_PATHS)
            return lm_err_set(err, LM_ERR_ARG, "%s: field '%s': at most %d paths", where,
                              f->name, LM_TRAIN_MAX_PATHS);
        dst = c->data[c->ndata];
        if (strlen(v) >= LM_TRAIN_PATH_LEN)
            return lm_err_set(err, LM_ERR_ARG, "%s: field '%s': path too long", where, f->name);
        strcpy(dst, v);
        c->ndata++;
        return LM_OK;
    }
    if (strlen(v) >= f->size)
        return lm_err_set(err, LM_ERR_ARG, "%s: field '%s': value too long (at most %zu "
                          "characters)", where, f->name, f->size - 1);
    strcpy(dst, v);
    return LM_OK;
}

/* Set a field from text; `where` names the source in messages. */
static lm_status set_text(lm_train_cfg *c, const field *f, const char *v, const char *where,
                          lm_err *err)
{
    void *dst = (char *)c + f->off;
    int idx = (int)(f - fields);
    c->given[idx / 64] |= 1ull << (idx % 64);
    double a = 0, b = 0;
    int ok = 0;
    switch (f->type) {
    case F_INT:
    case F_LONG:
    case F_FLOAT:
        ok = number(f, v, &a, where, err);
        if (ok == 1 && f->type == F_INT) *(int *)dst = (int)a;
        else if (ok == 1 && f->type == F_LONG) *(long *)dst = (long)a;
        else if (ok == 1) *(float *)dst = (float)a;
        break;
    case F_U64: {
        char *end;
        errno = 0;
        unsigned long long u = strtoull(v, &end, 10);
        ok = !errno && end != v && !*end && v[0] != '-';
        if (ok) *(uint64_t *)dst = u;
        break;
    }
    case F_STR:
    case F_LIST: return put_string(c, f, v, where, err);
    case F_PATCH:
    case F_NOISE: {
        char buf[64], *sep;
        snprintf(buf, sizeof buf, "%s", v);
        if (!(sep = strchr(buf, f->type == F_PATCH ? 'x' : ','))) break;
        *sep = 0;
        ok = number(f, buf, &a, where, err);
        if (ok == 1) ok = number(f, sep + 1, &b, where, err);
        if (ok == 1 && f->type == F_PATCH) c->patch_h = (int)a, c->patch_w = (int)b;
        else if (ok == 1) c->noise_min = (float)a, c->noise_max = (float)b;
        break;
    }
    }
    if (ok == 1) return LM_OK;
    if (ok < 0) return err->status;
    static const char *what[] = {"an integer", "an integer", "a non-negative integer",
                                 "a finite number", "a string", "a path",
                                 "HxW (integers, e.g. 66x64)", "MIN,MAX (numbers, e.g. 0,0.15)"};
    char r[64] = "";
    if (f->type != F_U64) snprintf(r, sizeof r, " in %.15g..%.15g", f->lo, f->hi);
    return lm_err_set(err, LM_ERR_ARG, "%s: field '%s': must be %s%s (got '%s')", where, f->name,
                      what[f->type], r, v);
}

lm_status lm_train_cfg_set(lm_train_cfg *c, const char *key, const char *value, lm_err *err)
{
    const field *f = find_field(key);
    if (!f) return lm_err_set(err, LM_ERR_ARG, "config: unknown field '%s'", key);
    char where[96];
    snprintf(where, sizeof where, "option --%s", key);
    return set_text(c, f, value, where, err);
}

/* A path from a config file, relative to the file's folder unless absolute. */
static void resolve_path(const char *base_dir, const char *p, char *out, size_t n)
{
    if (p[0] == '/' || !base_dir || !base_dir[0]) snprintf(out, n, "%s", p);
    else snprintf(out, n, "%s/%s", base_dir, p);
}

/* JSON value -> text for set_text, with the JSON type checked first. */
static lm_status set_json(lm_train_cfg *c, const field *f, json_t *v, const char *where,
                          const char *base_dir, lm_err *err)
{
    char buf[LM_TRAIN_PATH_LEN + 8];
    int ok = 1;
    switch (f->type) {
    case F_INT:
    case F_LONG:
    case F_U64:
        ok = json_is_integer(v);
        if (ok) snprintf(buf, sizeof buf, "%" JSON_INTEGER_FORMAT, json_integer_value(v));
        break;
    case F_FLOAT:
        ok = json_is_number(v);
        if (ok) snprintf(buf, sizeof buf, "%.9g", json_number_value(v));
        break;
    case F_STR:
        ok = json_is_string(v);
        if (ok && (!strcmp(f->name, "system") || !strcmp(f->name, "base") ||
                   (!strcmp(f->name, "doe") && strcmp(json_string_value(v), "default"))) &&
            json_string_length(v))
            resolve_path(base_dir, json_string_value(v), buf, sizeof buf);
        else if (ok) snprintf(buf, sizeof buf, "%s", json_string_value(v));
        break;
    case F_LIST: {
        if (json_is_string(v)) v = json_pack("[O]", v);
        else if (json_is_array(v)) json_incref(v);
        else return lm_err_set(err, LM_ERR_ARG, "%s: field '%s': must be a path or a list of "
                               "paths", where, f->name);
        c->ndata = 0;
        size_t i;
        json_t *e;
        lm_status st = LM_OK;
        json_array_foreach(v, i, e) {
            if (!json_is_string(e)) {
                st = lm_err_set(err, LM_ERR_ARG, "%s: field 'data[%zu]': must be a path", where, i);
                break;
            }
            resolve_path(base_dir, json_string_value(e), buf, sizeof buf);
            if ((st = put_string(c, f, buf, where, err))) break;
        }
        json_decref(v);
        return st;
    }
    case F_PATCH:
    case F_NOISE: {
        int patch = f->type == F_PATCH;
        ok = json_is_array(v) && json_array_size(v) == 2;
        for (size_t i = 0; ok && i < 2; i++)
            ok = patch ? json_is_integer(json_array_get(v, i)) : json_is_number(json_array_get(v, i));
        if (ok && patch) /* the full values: set_text checks the range */
            snprintf(buf, sizeof buf, "%" JSON_INTEGER_FORMAT "x%" JSON_INTEGER_FORMAT,
                     json_integer_value(json_array_get(v, 0)),
                     json_integer_value(json_array_get(v, 1)));
        else if (ok)
            snprintf(buf, sizeof buf, "%.9g,%.9g", json_number_value(json_array_get(v, 0)),
                     json_number_value(json_array_get(v, 1)));
        if (!ok)
            return lm_err_set(err, LM_ERR_ARG, "%s: field '%s': must be %s", where, f->name,
                              patch ? "[height, width] (integers)" : "[min, max] (numbers)");
        break;
    }
    }
    if (!ok) {
        static const char *what[] = {"an integer", "an integer", "an integer", "a number",
                                     "a string"};
        return lm_err_set(err, LM_ERR_ARG, "%s: field '%s': must be %s", where, f->name,
                          what[f->type]);
    }
    return set_text(c, f, buf, where, err);
}

static lm_status parse_root(lm_train_cfg *c, json_t *root, const char *label, const char *base,
                            lm_err *err)
{
    char where[600];
    snprintf(where, sizeof where, "config %s", label);
    if (!json_is_object(root))
        return lm_err_set(err, LM_ERR_FORMAT, "%s: must be a JSON object", where);
    json_t *ver = json_object_get(root, "version");
    if (!json_is_integer(ver) || json_integer_value(ver) != LM_TRAIN_CFG_VERSION)
        return lm_err_set(err, LM_ERR_FORMAT, "%s: field 'version': must be %d (this program's "
                          "config format)", where, LM_TRAIN_CFG_VERSION);
    const char *key;
    json_t *v;
    json_t *doe = json_object_get(root, "doe");
    if (json_is_object(doe)) { /* "doe": {"file", "optimise", "lr", "quantise", "bands"} */
        static const char *const sub[][2] = {{"file", "doe"}, {"optimise", "doe_optimise"},
                                             {"lr", "doe_lr"}, {"quantise", "doe_quantise"},
                                             {"bands", "doe_bands"}};
        json_object_foreach(doe, key, v) {
            int k = 0;
            while (k < 5 && strcmp(sub[k][0], key)) k++;
            if (k == 5)
                return lm_err_set(err, LM_ERR_FORMAT, "%s: unknown field 'doe.%s' (file, "
                                  "optimise, lr, quantise, bands)", where, key);
            json_t *val = json_is_boolean(v) ? json_integer(json_is_true(v)) : json_incref(v);
            const field *f = find_field(sub[k][1]);
            lm_status st = set_json(c, f, val, where, base, err);
            json_decref(val);
            if (st) return st;
        }
    }
    json_object_foreach(root, key, v) {
        if (!strcmp(key, "doe") && json_is_object(v)) continue;
        const field *f = NULL;
        for (int i = 0; i < NFIELDS && !f; i++)
            if (!strcmp(fields[i].name, key)) f = &fields[i];
        if (!f) return lm_err_set(err, LM_ERR_FORMAT, "%s: unknown field '%s'", where, key);
        lm_status st = set_json(c, f, v, where, base, err);
        if (st) return st;
    }
    return LM_OK;
}

lm_status lm_train_cfg_parse(lm_train_cfg *c, const char *text, const char *label, lm_err *err)
{
    json_error_t je;
    json_t *root = json_loads(text, JSON_REJECT_DUPLICATES, &je);
    if (!root)
        return lm_err_set(err, LM_ERR_FORMAT, "config %s: line %d: %s", label, je.line, je.text);
    lm_status st = parse_root(c, root, label, NULL, err);
    json_decref(root);
    return st;
}

lm_status lm_train_cfg_load(lm_train_cfg *c, const char *path, lm_err *err)
{
    lm_status fchk = lm_file_check(path, "a run config (.json)", err);
    if (fchk) return fchk;
    json_error_t je;
    json_t *root = json_load_file(path, JSON_REJECT_DUPLICATES, &je);
    if (!root) {
        FILE *f = fopen(path, "rb");
        if (!f) return lm_err_set(err, LM_ERR_IO, "config %s: cannot open: %s", path,
                                  strerror(errno));
        fclose(f);
        return lm_err_set(err, LM_ERR_FORMAT, "config %s: line %d: %s", path, je.line, je.text);
    }
    char base[LM_TRAIN_PATH_LEN];
    snprintf(base, sizeof base, "%s", path);
    char *slash = strrchr(base, '/');
    if (slash) *slash = 0;
    else base[0] = 0;
    lm_status st = parse_root(c, root, path, base, err);
    json_decref(root);
    return st;
}

/* The numbers of field f in cfg (0, 1 or 2 of them). */
static int field_values(const lm_train_cfg *c, const field *f, double v[2])
{
    const void *src = (const char *)c + f->off;
    switch (f->type) {
    case F_INT: v[0] = *(const int *)src; return 1;
    case F_LONG: v[0] = (double)*(const long *)src; return 1;
    case F_FLOAT: v[0] = *(const float *)src; return 1;
    case F_PATCH: v[0] = c->patch_h, v[1] = c->patch_w; return 2;
    case F_NOISE: v[0] = c->noise_min, v[1] = c->noise_max; return 2;
    default: return 0;
    }
}

#define BAD(fmt, ...) return lm_err_set(err, LM_ERR_ARG, "config: field " fmt, __VA_ARGS__)
lm_status lm_train_cfg_validate(const lm_train_cfg *c, lm_err *err)
{
    char net[64], base[64];
    if (lm_model_name_split(c->model, net, base, sizeof net))
        BAD("'model': %s is %s trained as a residual on a fitted %s: train %s first, then "
            "--model %s --base RUN (RUN: that %s run)", c->model, net, base, base, net, base);
    if (!lm_model_preset_known(c->model) && lm_model_preset_why(c->model))
        BAD("'model': unknown preset '%s': %s", c->model, lm_model_preset_why(c->model));
    if (!lm_model_preset_known(c->model)) BAD("'model': unknown preset '%s' (see lumosaic info --list)", c->model);
    for (int i = 0; i < NFIELDS; i++) { /* every number in its field's range (NaN is not) */
        double v[2];
        int n = field_values(c, &fields[i], v);
        for (int k = 0; k < n; k++)
            if (!(v[k] >= fields[i].lo && v[k] <= fields[i].hi))
                return out_of_range(&fields[i], v[k], NULL, "config", err);
    }
    if (!(c->lr > 0)) BAD("'lr': must be > 0 (got %g)", c->lr);
    if (c->lr_min > c->lr) BAD("'lr_min': must be in [0, lr] (got %g)", c->lr_min);
    if (strcmp(c->schedule, "constant") && strcmp(c->schedule, "cosine") &&
        strcmp(c->schedule, "step"))
        BAD("'schedule': must be constant, cosine or step (got '%s')", c->schedule);
    if (!strcmp(c->schedule, "step") && c->step_every < 1)
        BAD("'step_every': must be >= 1 with the step schedule (got %ld)", c->step_every);
    if (!(c->step_gamma > 0)) BAD("'step_gamma': must be in (0, 1] (got %g)", c->step_gamma);
    if (c->noise_min > c->noise_max)
        BAD("'noise': need 0 <= min <= max <= 1 (got %g,%g)", c->noise_min, c->noise_max);
    if (c->photons_min > 0.0f && !(c->photons > c->photons_min))
        BAD("'photons_min': must be below 'photons' (got %g, photons %g)", (double)c->photons_min,
            (double)c->photons);
    if (strcmp(c->device, "cpu") && strcmp(c->device, "opencl"))
        BAD("'device': must be cpu or opencl (got '%s'; --device, the config or $LM_DEVICE)",
            c->device);
    if (!c->output[0]) BAD("'output': must name a folder%s", "");
    if (strcmp(c->fit, "auto") && strcmp(c->fit, "closed") && strcmp(c->fit, "sgd"))
        BAD("'fit': must be auto, closed or sgd (got '%s')", c->fit);
    if (strcmp(c->clock, "wall") && strcmp(c->clock, "cpu"))
        BAD("'clock': must be wall or cpu (got '%s')", c->clock);
    if (strcmp(c->precision, "fp32") && strcmp(c->precision, "bf16"))
        BAD("'precision': must be fp32 or bf16 (got '%s')", c->precision);
    if (strcmp(c->recipe, "preset") && strcmp(c->recipe, "paper"))
        BAD("'recipe': must be preset or paper (got '%s')", c->recipe);
    if (!(c->fit_synth == -1.0f || (c->fit_synth >= 0.0f && c->fit_synth <= 1.0f)))
        BAD("'fit_synth': must be -1 (chosen on validation) or in [0, 1] (got %g)",
            (double)c->fit_synth);
    double marks[64];
    char why[128];
    if (c->snapshots[0] && lm_parse_list(c->snapshots, 0, 1e6, marks, 64, why, sizeof why) < 0)
        BAD("'snapshots': must be minutes separated by commas (got '%s': %s)", c->snapshots, why);
    if (strcmp(c->doe_quantise, "progressive") && strcmp(c->doe_quantise, "ste") &&
        strcmp(c->doe_quantise, "none"))
        BAD("'doe_quantise': must be progressive, ste or none (got '%s')", c->doe_quantise);
    if (!(c->doe_lr > 0)) BAD("'doe_lr': must be > 0 (got %g)", (double)c->doe_lr);
    if (!(c->procedural_fraction == -1.0f || c->procedural_fraction >= 0.0f))
        BAD("'procedural_fraction': must be -1 (default share) or in [0, 1] (got %g)",
            (double)c->procedural_fraction);
    if (c->procedural_fraction >= 0.0f && c->synth_fraction + c->procedural_fraction > 1.0f)
        BAD("'procedural_fraction': synth_fraction + procedural_fraction must be <= 1 (got %g)",
            (double)(c->synth_fraction + c->procedural_fraction));
    if (c->synth_fraction + lm_train_procedural_share(c) + c->fine_fraction > 1.0f)
        BAD("'fine_fraction': synth_fraction + procedural_fraction + fine_fraction must be <= 1 "
            "(got %g)", (double)(c->synth_fraction + lm_train_procedural_share(c) +
                                 c->fine_fraction));
    if (c->ndata == 0 && c->synth_fraction + lm_train_procedural_share(c) + c->fine_fraction < 1)
        BAD("'data': no scenes given (add --data PATH, or make synth_fraction + "
            "procedural_fraction 1)%s", "");
    return LM_OK;
}
#undef BAD

/* The run's paths (data, system, base, DOE) made relative to `dir` where they resolve, so that
 * a run folder moved or cloned with its data beside it keeps working. */
int lm_train_cfg_paths(lm_train_cfg *c, char **paths)
{
    int n = 0;
    for (int i = 0; i < c->ndata; i++) paths[n++] = c->data[i];
    paths[n++] = c->system;
    paths[n++] = c->base;
    if (strcmp(c->doe, "default")) paths[n++] = c->doe;
    return n;
}

static void paths_relative_to(lm_train_cfg *c, const char *dir)
{
    char *paths[LM_TRAIN_MAX_PATHS + 3];
    const int n = lm_train_cfg_paths(c, paths);
    for (int i = 0; i < n; i++) {
        char rel[LM_TRAIN_PATH_LEN];
        if (paths[i][0] && !lm_path_relative(dir, paths[i], rel, sizeof rel)) strcpy(paths[i], rel);
    }
}

static lm_status cfg_save(const lm_train_cfg *c, const char *path, lm_err *err);

lm_status lm_train_cfg_save(const lm_train_cfg *cfg, const char *path, lm_err *err)
{
    lm_train_cfg *c = malloc(sizeof *c);
    if (!c) return lm_err_set(err, LM_ERR_NOMEM, "%s: out of memory", path);
    *c = *cfg;
    char dir[LM_TRAIN_PATH_LEN];
    const char *slash = strrchr(path, '/');
    if (!slash) snprintf(dir, sizeof dir, ".");
    else snprintf(dir, sizeof dir, "%.*s", slash == path ? 1 : (int)(slash - path), path);
    paths_relative_to(c, dir);
    lm_status st = cfg_save(c, path, err);
    free(c);
    return st;
}

static lm_status cfg_save(const lm_train_cfg *c, const char *path, lm_err *err)
{
    json_t *data = json_array();
    for (int i = 0; i < c->ndata; i++) json_array_append_new(data, json_string(c->data[i]));
    json_t *root = json_pack(
        "{s:i, s:s, s:s, s:o, s:f, s:[i,i], s:i, s:i, s:I, s:f, s:s, s:f, s:I, s:I, s:f, s:f, "
        "s:[f,f], s:f, s:I, s:i, s:s, s:i, s:I, s:i, s:I, s:I, s:s}",
        "version", c->version, "model", c->model, "system", c->system, "data", data,
        "synth_fraction", (double)c->synth_fraction, "patch", c->patch_h, c->patch_w,
        "batch", c->batch, "accum_steps", c->accum_steps, "iterations", (json_int_t)c->iterations,
        "lr", (double)c->lr, "schedule", c->schedule, "lr_min", (double)c->lr_min,
        "warmup", (json_int_t)c->warmup, "step_every", (json_int_t)c->step_every,
        "step_gamma", (double)c->step_gamma, "weight_decay", (double)c->weight_decay,
        "noise", (double)c->noise_min, (double)c->noise_max, "val_noise", (double)c->val_noise,
        "seed", (json_int_t)c->seed, "threads", c->threads, "device", c->device,
        "workers", c->workers,
        "val_interval", (json_int_t)c->val_interval, "val_patches", c->val_patches,
        "checkpoint_interval", (json_int_t)c->checkpoint_interval,
        "log_interval", (json_int_t)c->log_interval, "output", c->output);
    if (root)
        json_object_update_new(root, json_pack("{s:s, s:I, s:f, s:s, s:i, s:f, s:f, s:s, s:i, s:i, s:s, s:f}", "fit", c->fit,
                               "fit_patches", (json_int_t)c->fit_patches,
                               "fit_synth", (double)c->fit_synth, "base", c->base,
                               "base_trainable", c->base_trainable,
                               "res_init", (double)c->res_init, "minutes", (double)c->minutes,
                               "snapshots", c->snapshots, "sensor_clip", c->sensor_clip,
                               "sensor_bits", c->sensor_bits, "clock", c->clock,
                               "procedural_fraction", (double)c->procedural_fraction));
    if (root) json_object_set_new(root, "mat_key", json_string(c->mat_key));
    if (root)
        json_object_set_new(root, "doe", json_pack("{s:s, s:b, s:f, s:s, s:i}", "file", c->doe,
                                                   "optimise", c->doe_optimise, "lr",
                                                   (double)c->doe_lr, "quantise",
                                                   c->doe_quantise, "bands", c->doe_bands));
    if (root) /* moving samples */
        json_object_update_new(root, json_pack("{s:f, s:f, s:f, s:i}", "motion_fraction",
                               (double)c->motion_fraction, "motion_speed", (double)c->motion_speed,
                               "motion_rotation", (double)c->motion_rotation, "motion_samples",
                               c->motion_samples));
    if (root) json_object_set_new(root, "buckets", json_integer(c->buckets));
    if (root) json_object_set_new(root, "frames", json_integer(c->frames));
    if (root) json_object_set_new(root, "recipe", json_string(c->recipe));
    if (root) json_object_set_new(root, "photons", json_real(c->photons));
    if (root) json_object_set_new(root, "photons_min", json_real(c->photons_min));
    if (root) json_object_set_new(root, "read_noise", json_real(c->read_noise));
    if (root) json_object_set_new(root, "fit_b0_noise", json_real(c->fit_b0_noise));
    if (root) json_object_set_new(root, "illum_jitter", json_real(c->illum_jitter));
    if (root) json_object_set_new(root, "gain_jitter", json_real(c->gain_jitter));
    if (root) json_object_set_new(root, "scale_jitter", json_real(c->scale_jitter));
    if (root) json_object_set_new(root, "transpose", json_integer(c->transpose));
    if (root) json_object_set_new(root, "collage", json_real(c->collage));
    if (root) json_object_set_new(root, "clip_fraction", json_real(c->clip_fraction));
    if (root) json_object_set_new(root, "clean_fraction", json_real(c->clean_fraction));
    if (root) json_object_set_new(root, "fine_fraction", json_real(c->fine_fraction));
    if (root) json_object_set_new(root, "ema", json_real(c->ema));
    if (root) json_object_set_new(root, "precision", json_string(c->precision));
    if (!root) return lm_err_set(err, LM_ERR_NOMEM, "%s: cannot build the config JSON", path);
    char tmp[LM_TRAIN_PATH_LEN + 32];
    snprintf(tmp, sizeof tmp, "%s.tmp.%ld", path, (long)getpid());
    int rc = json_dump_file(root, tmp, JSON_INDENT(2) | JSON_PRESERVE_ORDER | JSON_REAL_PRECISION(9));
    json_decref(root);
    if (rc != 0 || rename(tmp, path) != 0) {
        int e = errno;
        remove(tmp);
        return lm_err_set(err, LM_ERR_WRITE, "%s: cannot write the config: %s", path,
                          strerror(e));
    }
    return LM_OK;
}

void lm_train_cfg_print_help(FILE *f)
{
    for (int i = 0; i < NFIELDS; i++) {
        char flag[64], opt[96];
        snprintf(flag, sizeof flag, "%s", fields[i].name);
        for (char *p = flag; *p; p++)
            if (*p == '_') *p = '-';
        snprintf(opt, sizeof opt, "--%s %s", flag, fields[i].arg);
        char r[64] = "";
        if (fields[i].type != F_STR && fields[i].type != F_LIST && fields[i].type != F_U64)
            snprintf(r, sizeof r, " [%.15g..%.15g]", fields[i].lo, fields[i].hi);
        fprintf(f, "  %-30s %s%s\n", opt, fields[i].help, r);
    }
}

void lm_train_cfg_adam(const lm_train_cfg *c, lm_adam_cfg *o)
{
    lm_adam_default_cfg(o);
    o->lr = c->lr;
    o->lr_min = c->lr_min;
    o->weight_decay = c->weight_decay;
    o->ema = c->ema;
    o->schedule = !strcmp(c->schedule, "cosine") ? LM_LR_COSINE
                  : !strcmp(c->schedule, "step") ? LM_LR_STEP : LM_LR_CONSTANT;
    o->total_steps = c->iterations;
    o->warmup_steps = c->warmup;
    o->step_every = c->step_every;
    o->step_gamma = c->step_gamma;
}

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

typedef enum ftype { F_INT, F_LONG, F_U64, F_FLOAT, F_STR, F_LIST, F_PATCH, F_NOISE } ftype;

typedef struct field {
    const char *name;
    ftype type;
    size_t off;
    size_t size;      /* strings: buffer size */
    const char *arg, *help;
} field;

#define FLD(n, t, m, a, h) {n, t, offsetof(lm_train_cfg, m), sizeof(((lm_train_cfg *)0)->m), a, h}
static const field fields[] = {
    FLD("version", F_INT, version, "N", "config format version (1)"),
    FLD("model", F_STR, model, "NAME", "model preset (lumosaic info --list)"),
    FLD("system", F_STR, system, "FILE", "system description (default: bundled)"),
    FLD("data", F_LIST, data, "PATH", "scene file or folder (repeatable)"),
    FLD("synth_fraction", F_FLOAT, synth_fraction, "F", "share of synthetic samples [0,1]"),
    FLD("patch", F_PATCH, patch_h, "HxW", "patch size, multiples of the tile (66x64)"),
    FLD("batch", F_INT, batch, "N", "samples per forward pass (14)"),
    FLD("accum_steps", F_INT, accum_steps, "N", "batches accumulated per update (2)"),
    FLD("iterations", F_LONG, iterations, "N", "optimizer updates (50000)"),
    FLD("lr", F_FLOAT, lr, "F", "learning rate (1e-4)"),
    FLD("schedule", F_STR, schedule, "S", "constant | cosine | step"),
    FLD("lr_min", F_FLOAT, lr_min, "F", "cosine: final learning rate"),
    FLD("warmup", F_LONG, warmup, "N", "linear warm-up updates"),
    FLD("step_every", F_LONG, step_every, "N", "step schedule: decay period"),
    FLD("step_gamma", F_FLOAT, step_gamma, "F", "step schedule: decay factor"),
    FLD("weight_decay", F_FLOAT, weight_decay, "F", "Adam L2 weight decay"),
    FLD("noise", F_NOISE, noise_min, "MIN,MAX", "noise level range k (0,0.15)"),
    FLD("val_noise", F_FLOAT, val_noise, "F", "noise level of validation samples"),
    FLD("seed", F_U64, seed, "N", "random seed (init, data)"),
    FLD("threads", F_INT, threads, "N", "compute threads (0 = all cores)"),
    FLD("device", F_STR, device, "NAME", "cpu | opencl (default: $LM_DEVICE, else cpu)"),
    FLD("workers", F_INT, workers, "N", "data preparation threads"),
    FLD("val_interval", F_LONG, val_interval, "N", "updates between validations (0 = end)"),
    FLD("val_patches", F_INT, val_patches, "N", "fixed validation samples"),
    FLD("checkpoint_interval", F_LONG, checkpoint_interval, "N", "updates between checkpoints"),
    FLD("log_interval", F_LONG, log_interval, "N", "updates between progress lines (no tty)"),
    FLD("output", F_STR, output, "DIR", "run folder (checkpoints, log.csv)"),
    FLD("fit", F_STR, fit, "M", "auto | closed | sgd (auto: closed form for lmmse presets)"),
    FLD("fit_patches", F_LONG, fit_patches, "N", "closed form: training patches (4096)"),
    FLD("base", F_STR, base, "RUN", "train as a residual on this run's model (e.g. an lmmse fit)"),
    FLD("base_trainable", F_INT, base_trainable, "0|1", "fine-tune the base with the net (0)"),
    FLD("res_init", F_FLOAT, res_init, "F", "residual: initial gates on the net's output (1; the net's output layers start at 0)"),
    FLD("sensor_clip", F_INT, sensor_clip, "0|1", "clip noisy samples to [0, 1] as a 16-bit "
        "PNG frame holds them (0)"),
    FLD("sensor_bits", F_INT, sensor_bits, "N", "quantise samples to N bits (0 = off; 16 = PNG)"),
    FLD("snapshots", F_STR, snapshots, "M,M,...", "weights at these minutes of training into "
        "<output>/snapshots/<M>min/"),
    FLD("minutes", F_FLOAT, minutes, "M", "time budget in minutes (0 = none; the schedule "
        "spans it)"),
};
#define NFIELDS (int)(sizeof fields / sizeof fields[0])

void lm_train_cfg_default(lm_train_cfg *c)
{
    memset(c, 0, sizeof *c);
    c->version = LM_TRAIN_CFG_VERSION;
    snprintf(c->model, sizeof c->model, "han-paper");
    c->synth_fraction = 0.33f;
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
    snprintf(c->output, sizeof c->output, "runs/train");
    snprintf(c->fit, sizeof c->fit, "auto");
    c->fit_patches = 4096;
    c->res_init = 1.0f;
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

static int parse_long(const char *s, long long *v)
{
    char *end;
    errno = 0;
    *v = strtoll(s, &end, 10);
    return errno == 0 && end != s && *end == 0;
}

static int parse_float(const char *s, float *v)
{
    char *end;
    double d = strtod(s, &end);
    *v = (float)d;
    return end != s && *end == 0 && isfinite(d);
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
    long long l;
    float a, b;
    switch (f->type) {
    case F_INT:
        if (!parse_long(v, &l) || l < INT_MIN || l > INT_MAX) break;
        *(int *)dst = (int)l;
        return LM_OK;
    case F_LONG:
        if (!parse_long(v, &l)) break;
        *(long *)dst = (long)l;
        return LM_OK;
    case F_U64: {
        char *end;
        errno = 0;
        unsigned long long u = strtoull(v, &end, 10);
        if (errno || end == v || *end || v[0] == '-') break;
        *(uint64_t *)dst = u;
        return LM_OK;
    }
    case F_FLOAT:
        if (!parse_float(v, &a)) break;
        *(float *)dst = a;
        return LM_OK;
    case F_STR:
    case F_LIST: return put_string(c, f, v, where, err);
    case F_PATCH: {
        int h, w;
        char extra;
        if (sscanf(v, "%dx%d%c", &h, &w, &extra) != 2) break;
        c->patch_h = h, c->patch_w = w;
        return LM_OK;
    }
    case F_NOISE: {
        char buf[64], *comma;
        snprintf(buf, sizeof buf, "%s", v);
        if (!(comma = strchr(buf, ','))) break;
        *comma = 0;
        if (!parse_float(buf, &a) || !parse_float(comma + 1, &b)) break;
        c->noise_min = a, c->noise_max = b;
        return LM_OK;
    }
    }
    static const char *what[] = {"an integer", "an integer", "a non-negative integer", "a number",
                                 "a string", "a path", "HxW (e.g. 66x64)", "MIN,MAX (e.g. 0,0.15)"};
    return lm_err_set(err, LM_ERR_ARG, "%s: field '%s': must be %s (got '%s')", where, f->name,
                      what[f->type], v);
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
        if (ok && (!strcmp(f->name, "system") || !strcmp(f->name, "base")) &&
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
        if (ok && patch)
            snprintf(buf, sizeof buf, "%dx%d", (int)json_integer_value(json_array_get(v, 0)),
                     (int)json_integer_value(json_array_get(v, 1)));
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
    json_object_foreach(root, key, v) {
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
    json_t *root = json_loads(text, 0, &je);
    if (!root)
        return lm_err_set(err, LM_ERR_FORMAT, "config %s: line %d: %s", label, je.line, je.text);
    lm_status st = parse_root(c, root, label, NULL, err);
    json_decref(root);
    return st;
}

lm_status lm_train_cfg_load(lm_train_cfg *c, const char *path, lm_err *err)
{
    json_error_t je;
    json_t *root = json_load_file(path, 0, &je);
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

#define BAD(fmt, ...) return lm_err_set(err, LM_ERR_ARG, "config: field " fmt, __VA_ARGS__)
lm_status lm_train_cfg_validate(const lm_train_cfg *c, lm_err *err)
{
    if (!lm_model_preset_known(c->model)) BAD("'model': unknown preset '%s' (see lumosaic info --list)", c->model);
    if (c->version != LM_TRAIN_CFG_VERSION) BAD("'version': must be %d", LM_TRAIN_CFG_VERSION);
    if (c->batch < 1) BAD("'batch': must be >= 1 (got %d)", c->batch);
    if (c->accum_steps < 1) BAD("'accum_steps': must be >= 1 (got %d)", c->accum_steps);
    if (c->iterations < 1) BAD("'iterations': must be >= 1 (got %ld)", c->iterations);
    if (c->patch_h < 1 || c->patch_w < 1)
        BAD("'patch': must be positive (got %dx%d)", c->patch_h, c->patch_w);
    if (!(c->lr > 0)) BAD("'lr': must be > 0 (got %g)", c->lr);
    if (c->lr_min < 0 || c->lr_min > c->lr) BAD("'lr_min': must be in [0, lr] (got %g)", c->lr_min);
    if (strcmp(c->schedule, "constant") && strcmp(c->schedule, "cosine") &&
        strcmp(c->schedule, "step"))
        BAD("'schedule': must be constant, cosine or step (got '%s')", c->schedule);
    if (c->warmup < 0) BAD("'warmup': must be >= 0 (got %ld)", c->warmup);
    if (!strcmp(c->schedule, "step") && c->step_every < 1)
        BAD("'step_every': must be >= 1 with the step schedule (got %ld)", c->step_every);
    if (!(c->step_gamma > 0 && c->step_gamma <= 1))
        BAD("'step_gamma': must be in (0, 1] (got %g)", c->step_gamma);
    if (c->weight_decay < 0) BAD("'weight_decay': must be >= 0 (got %g)", c->weight_decay);
    if (!(c->synth_fraction >= 0 && c->synth_fraction <= 1))
        BAD("'synth_fraction': must be in [0, 1] (got %g)", c->synth_fraction);
    if (!(c->noise_min >= 0 && c->noise_min <= c->noise_max && c->noise_max <= 1))
        BAD("'noise': need 0 <= min <= max <= 1 (got %g,%g)", c->noise_min, c->noise_max);
    if (!(c->val_noise >= 0 && c->val_noise <= 1))
        BAD("'val_noise': must be in [0, 1] (got %g)", c->val_noise);
    if (c->threads < 0 || c->threads > LM_MAX_THREADS)
        BAD("'threads': %d is out of range (0..%d)", c->threads, LM_MAX_THREADS);
    if (strcmp(c->device, "cpu") && strcmp(c->device, "opencl"))
        BAD("'device': must be cpu or opencl (got '%s'; --device, the config or $LM_DEVICE)",
            c->device);
    if (c->workers < 0) BAD("'workers': must be >= 0 (got %d)", c->workers);
    if (c->val_interval < 0) BAD("'val_interval': must be >= 0 (got %ld)", c->val_interval);
    if (c->val_patches < 0) BAD("'val_patches': must be >= 0 (got %d)", c->val_patches);
    if (c->checkpoint_interval < 0)
        BAD("'checkpoint_interval': must be >= 0 (got %ld)", c->checkpoint_interval);
    if (c->log_interval < 1) BAD("'log_interval': must be >= 1 (got %ld)", c->log_interval);
    if (!c->output[0]) BAD("'output': must name a folder%s", "");
    if (strcmp(c->fit, "auto") && strcmp(c->fit, "closed") && strcmp(c->fit, "sgd"))
        BAD("'fit': must be auto, closed or sgd (got '%s')", c->fit);
    if (c->fit_patches < 1) BAD("'fit_patches': must be >= 1 (got %ld)", c->fit_patches);
    if (c->base_trainable != 0 && c->base_trainable != 1)
        BAD("'base_trainable': must be 0 or 1 (got %d)", c->base_trainable);
    if (!(c->minutes >= 0 && c->minutes <= 1e6))
        BAD("'minutes': must be in [0, 1e6] (got %g)", c->minutes);
    for (const char *p = c->snapshots; *p; p++)
        if (!strchr("0123456789.,", *p))
            BAD("'snapshots': must be minutes separated by commas (got '%s')", c->snapshots);
    if (c->sensor_clip != 0 && c->sensor_clip != 1)
        BAD("'sensor_clip': must be 0 or 1 (got %d)", c->sensor_clip);
    if (c->sensor_bits < 0 || c->sensor_bits > 24)
        BAD("'sensor_bits': must be 0..24 (got %d)", c->sensor_bits);
    if (!isfinite(c->res_init)) BAD("'res_init': must be finite (got %g)", c->res_init);
    if (c->ndata == 0 && c->synth_fraction < 1)
        BAD("'data': no scenes given (add --data PATH, or set synth_fraction to 1)%s", "");
    return LM_OK;
}
#undef BAD

lm_status lm_train_cfg_save(const lm_train_cfg *c, const char *path, lm_err *err)
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
        json_object_update_new(root, json_pack("{s:s, s:I, s:s, s:i, s:f, s:f, s:s, s:i, s:i}", "fit", c->fit,
                               "fit_patches", (json_int_t)c->fit_patches, "base", c->base,
                               "base_trainable", c->base_trainable,
                               "res_init", (double)c->res_init, "minutes", (double)c->minutes,
                               "snapshots", c->snapshots, "sensor_clip", c->sensor_clip,
                               "sensor_bits", c->sensor_bits));
    if (!root) return lm_err_set(err, LM_ERR_NOMEM, "%s: cannot build the config JSON", path);
    char tmp[LM_TRAIN_PATH_LEN + 32];
    snprintf(tmp, sizeof tmp, "%s.tmp.%ld", path, (long)getpid());
    int rc = json_dump_file(root, tmp, JSON_INDENT(2) | JSON_PRESERVE_ORDER | JSON_REAL_PRECISION(9));
    json_decref(root);
    if (rc != 0 || rename(tmp, path) != 0) {
        remove(tmp);
        return lm_err_set(err, LM_ERR_IO, "%s: cannot write the config", path);
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
        fprintf(f, "  %-30s %s\n", opt, fields[i].help);
    }
}

void lm_train_cfg_adam(const lm_train_cfg *c, lm_adam_cfg *o)
{
    lm_adam_default_cfg(o);
    o->lr = c->lr;
    o->lr_min = c->lr_min;
    o->weight_decay = c->weight_decay;
    o->schedule = !strcmp(c->schedule, "cosine") ? LM_LR_COSINE
                  : !strcmp(c->schedule, "step") ? LM_LR_STEP : LM_LR_CONSTANT;
    o->total_steps = c->iterations;
    o->warmup_steps = c->warmup;
    o->step_every = c->step_every;
    o->step_gamma = c->step_gamma;
}

/* config.c — the study configuration (study.h): defaults and the JSON loader. Training fields
 * are handed to the training config's own parser (train/train.h), so they are checked exactly
 * as `lumosaic train --config` checks them; study fields are checked here. Errors are one line
 * "config <file>: field '<name>': <problem>".
 * What it is not: the study run (study.c). */
#include <jansson.h>
#include <math.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "study/study.h"

void lm_study_cfg_default(lm_study_cfg *cfg)
{
    memset(cfg, 0, sizeof *cfg);
    cfg->version = LM_STUDY_CFG_VERSION;
    lm_train_cfg_default(&cfg->train);
    cfg->train.iterations = 2000;
    static const float k[] = {0.0f, 0.05f, 0.10f, 0.15f, 0.20f};
    cfg->nnoise = 5;
    memcpy(cfg->noise, k, sizeof k);
    cfg->eval_scenes = 8;
    cfg->eval_h = 132, cfg->eval_w = 128;
    cfg->rainbow = 256;
    cfg->frame_h = 480, cfg->frame_w = 640;
    cfg->timing_repeats = 3;
}

/* Study fields, then those passed on to the training config. */
static const char *const study_fields[] = {"version", "presets", "data", "system", "train",
    "noise", "eval_scenes", "eval_size", "rainbow", "frame", "timing_repeats", "output",
    "conditions", "condition_scenes", "narrowband_sweep", "preset_train", "drop", NULL};
static const char *const train_fields[] = {"iterations", "seed", "patch", "synth_fraction",
                                           NULL};

static int in_list(const char *const *l, const char *s)
{
    for (; *l; l++)
        if (!strcmp(*l, s)) return 1;
    return 0;
}

/* A path relative to the config file's folder (absolute paths unchanged). */
static void resolve(const char *cfgpath, const char *p, char *out, size_t n)
{
    const char *slash = strrchr(cfgpath, '/');
    if (p[0] == '/' || !slash) snprintf(out, n, "%s", p);
    else snprintf(out, n, "%.*s/%s", (int)(slash - cfgpath), cfgpath, p);
}

#define BAD(...) return lm_err_set(err, LM_ERR_ARG, __VA_ARGS__)

static lm_status int_field(json_t *root, const char *where, const char *name, long lo, long hi,
                           int *out, lm_err *err)
{
    json_t *v = json_object_get(root, name);
    if (!v) return LM_OK;
    if (!json_is_integer(v) || json_integer_value(v) < lo || json_integer_value(v) > hi)
        BAD("%s: field '%s': must be an integer in %ld..%ld", where, name, lo, hi);
    *out = (int)json_integer_value(v);
    return LM_OK;
}

/* "HxW" or [H, W], each in 1..8192. */
static lm_status size_field(json_t *root, const char *where, const char *name, int *h, int *w,
                            lm_err *err)
{
    json_t *v = json_object_get(root, name);
    if (!v) return LM_OK;
    long long a = 0, b = 0; /* range-checked below, before they become ints */
    char tail = 0;
    if (json_is_string(v)) {
        if (sscanf(json_string_value(v), "%6lldx%6lld%c", &a, &b, &tail) != 2) a = 0;
    } else if (json_is_array(v) && json_array_size(v) == 2 &&
               json_is_integer(json_array_get(v, 0)) && json_is_integer(json_array_get(v, 1))) {
        a = json_integer_value(json_array_get(v, 0));
        b = json_integer_value(json_array_get(v, 1));
    }
    if (a < 1 || b < 1 || a > 8192 || b > 8192)
        BAD("%s: field '%s': must be \"HxW\" or [H, W] (1..8192)", where, name);
    *h = (int)a, *w = (int)b;
    return LM_OK;
}

static lm_status presets_field(lm_study_cfg *cfg, json_t *root, const char *where, lm_err *err)
{
    json_t *v = json_object_get(root, "presets");
    if (!json_is_array(v) || !json_array_size(v) || json_array_size(v) > LM_STUDY_MAX_PRESETS)
        BAD("%s: field 'presets': must be a list of 1..%d model presets (lumosaic info --list)",
            where, LM_STUDY_MAX_PRESETS);
    for (size_t i = 0; i < json_array_size(v); i++) {
        const char *s = json_string_value(json_array_get(v, i));
        char net[64] = "";
        const char *plus = s ? strchr(s, '+') : NULL;
        snprintf(net, sizeof net, "%.*s", plus ? (int)(plus - s) : 63, s ? s : "");
        int known = s && strlen(s) < sizeof cfg->presets[0] && lm_model_preset_known(net);
        for (int j = 0; plus && known && j <= cfg->npresets; j++)
            if (j == cfg->npresets)
                BAD("%s: field 'presets[%zu]': the base '%s' of '%s' must be listed before it",
                    where, i, plus + 1, s);
            else if (!strcmp(cfg->presets[j], plus + 1)) break;
        if (!known)
            BAD("%s: field 'presets[%zu]': %s%s%s is not a model preset (lumosaic info --list)",
                where, i, s ? "'" : "", s ? s : "not a string", s ? "'" : "");
        for (int j = 0; j < cfg->npresets; j++)
            if (!strcmp(cfg->presets[j], s)) BAD("%s: field 'presets': '%s' twice", where, s);
        snprintf(cfg->presets[cfg->npresets++], sizeof cfg->presets[0], "%s", s);
    }
    return LM_OK;
}

static lm_status noise_field(lm_study_cfg *cfg, json_t *root, const char *where, lm_err *err)
{
    json_t *v = json_object_get(root, "noise");
    if (!v) return LM_OK;
    size_t n = json_is_array(v) ? json_array_size(v) : 0;
    if (n < 1 || n > LM_EVAL_MAX_NOISE)
        BAD("%s: field 'noise': must be a list of 1..%d levels in %% (0..100)", where,
            LM_EVAL_MAX_NOISE);
    for (size_t i = 0; i < n; i++) {
        json_t *e = json_array_get(v, i);
        double p = json_is_number(e) ? json_number_value(e) : -1;
        if (!(p >= 0 && p <= 100))
            BAD("%s: field 'noise[%zu]': must be a level in %% (0..100)", where, i);
        for (size_t j = 0; j < i; j++)
            if (cfg->noise[j] == (float)(p / 100.0))
                BAD("%s: field 'noise': level %g twice", where, p);
        cfg->noise[i] = (float)(p / 100.0);
    }
    cfg->nnoise = (int)n;
    return LM_OK;
}

/* levels of condition i: a list of valid levels, or the family's default sweep. */
static lm_status cond_levels(lm_study_cond *sc, json_t *lv, const char *w, size_t i, lm_err *err)
{
    if (!lv) {
        sc->nlevels = lm_cond_default_levels(sc->family, sc->levels);
        return LM_OK;
    }
    size_t n = json_is_array(lv) ? json_array_size(lv) : 0;
    if (n < 1 || n > LM_COND_MAX_LEVELS)
        BAD("%s: field 'conditions[%zu].levels': must be a list of 1..%d levels", w, i,
            LM_COND_MAX_LEVELS);
    double lo = 0, hi = 0;
    lm_cond_range(sc->family, &lo, &hi);
    for (size_t k = 0; k < n; k++) {
        json_t *e = json_array_get(lv, k);
        double v = json_is_number(e) ? json_number_value(e) : NAN;
        if (!lm_cond_level_ok(sc->family, v))
            BAD("%s: field 'conditions[%zu].levels[%zu]': not a valid %s level (%s, %g..%g)", w,
                i, k, lm_cond_name(sc->family), lm_cond_unit(sc->family), lo, hi);
        sc->levels[k] = v;
    }
    sc->nlevels = (int)n;
    return LM_OK;
}

/* "conditions": [{"family": name, "levels": [...]}, ...] */
static lm_status cond_field(lm_study_cfg *cfg, json_t *root, const char *w, lm_err *err)
{
    json_t *v = json_object_get(root, "conditions");
    if (!v) return LM_OK;
    size_t n = json_is_array(v) ? json_array_size(v) : 0;
    if (!json_is_array(v) || n > LM_COND_NFAMILIES)
        BAD("%s: field 'conditions': must be a list of at most %d {\"family\", \"levels\"}",
            w, LM_COND_NFAMILIES);
    for (size_t i = 0; i < n; i++) {
        json_t *o = json_array_get(v, i), *lv = json_object_get(o, "levels");
        int f = lm_cond_parse(json_string_value(json_object_get(o, "family")));
        if (!json_is_object(o) || f < 0 || json_object_size(o) != 1u + (lv != NULL))
            BAD("%s: field 'conditions[%zu]': must be {\"family\": photons | saturation | "
                "led_gain | dead_pixels | motion, \"levels\": [...]}", w, i);
        for (int j = 0; j < cfg->ncond; j++)
            if ((int)cfg->cond[j].family == f)
                BAD("%s: field 'conditions': family '%s' twice", w, lm_cond_name(f));
        lm_study_cond *sc = &cfg->cond[cfg->ncond++];
        sc->family = (lm_cond_family)f;
        if (cond_levels(sc, lv, w, i, err)) return err->status;
    }
    return LM_OK;
}

/* "narrowband_sweep": {"preset": name, "fractions": [0..1, ...]} */
static lm_status nb_field(lm_study_cfg *cfg, json_t *root, const char *w, lm_err *err)
{
    json_t *v = json_object_get(root, "narrowband_sweep");
    if (!v) return LM_OK;
    json_t *p = json_object_get(v, "preset"), *fr = json_object_get(v, "fractions");
    const char *s = json_string_value(p);
    int known = 0;
    for (const char *const *q = lm_model_presets(); s && *q; q++) known |= !strcmp(*q, s);
    size_t n = json_is_array(fr) ? json_array_size(fr) : 0;
    if (!json_is_object(v) || json_object_size(v) != 2 || !known || n < 1 ||
        n > LM_STUDY_MAX_FRACTIONS)
        BAD("%s: field 'narrowband_sweep': must be {\"preset\": a model preset, \"fractions\": "
            "[1..%d synthetic shares in 0..1]}", w, LM_STUDY_MAX_FRACTIONS);
    for (size_t i = 0; i < n; i++) {
        json_t *e = json_array_get(fr, i);
        double f = json_is_number(e) ? json_number_value(e) : -1;
        if (!(f >= 0 && f <= 1))
            BAD("%s: field 'narrowband_sweep.fractions[%zu]': must be in 0..1", w, i);
        cfg->nb_fraction[i] = (float)f;
    }
    cfg->nnb = (int)n;
    snprintf(cfg->nb_preset, sizeof cfg->nb_preset, "%s", s);
    return LM_OK;
}

/* data (list or one path) and system, relative to the config file. */
static lm_status path_fields(lm_study_cfg *cfg, json_t *root, const char *where, lm_err *err)
{
    char buf[LM_TRAIN_PATH_LEN];
    json_t *d = json_object_get(root, "data");
    if (json_is_string(d)) d = json_pack("[O]", d);
    else json_incref(d);
    size_t n = json_is_array(d) ? json_array_size(d) : 0;
    lm_status st = LM_OK;
    if (!n) st = lm_err_set(err, LM_ERR_ARG, "%s: field 'data': must be a path or a list of "
                            "paths (scenes or folders of scenes)", where);
    cfg->train.ndata = 0;
    for (size_t i = 0; !st && i < n; i++) {
        const char *s = json_string_value(json_array_get(d, i));
        if (!s) st = lm_err_set(err, LM_ERR_ARG, "%s: field 'data[%zu]': must be a path", where, i);
        else resolve(cfg->path, s, buf, sizeof buf);
        if (!st) st = lm_train_cfg_set(&cfg->train, "data", buf, err);
    }
    json_decref(d);
    json_t *s = json_object_get(root, "system");
    if (!st && s && !json_is_string(s))
        st = lm_err_set(err, LM_ERR_ARG, "%s: field 'system': must be a path", where);
    if (!st && s) {
        resolve(cfg->path, json_string_value(s), buf, sizeof buf);
        st = lm_train_cfg_set(&cfg->train, "system", buf, err);
    }
    return st;
}

/* iterations / seed / patch / synth_fraction and the "train" object, through the training
 * config's parser. */
static lm_status train_fields_parse(lm_study_cfg *cfg, json_t *root, const char *where,
                                    lm_err *err)
{
    json_t *t = json_object_get(root, "train");
    if (t && !json_is_object(t)) BAD("%s: field 'train': must be an object", where);
    json_t *tj = t ? json_deep_copy(t) : json_object();
    const char *key;
    json_t *v;
    lm_status st = LM_OK;
    json_object_foreach(tj, key, v) {
        if (!st && (in_list(train_fields, key) || !strcmp(key, "model") ||
                    !strcmp(key, "data") || !strcmp(key, "output") || !strcmp(key, "system")))
            st = lm_err_set(err, LM_ERR_ARG, "%s: field 'train.%s': set by the study (use the "
                            "top-level field%s)", where, key,
                            strcmp(key, "model") ? "" : " 'presets'");
    }
    for (int i = 0; train_fields[i]; i++)
        if ((v = json_object_get(root, train_fields[i])))
            json_object_set(tj, train_fields[i], v);
    json_object_set_new(tj, "version", json_integer(LM_TRAIN_CFG_VERSION));
    char *text = st ? NULL : json_dumps(tj, 0);
    json_decref(tj);
    if (st) return st;
    if (!text) return lm_err_set(err, LM_ERR_NOMEM, "%s: out of memory", where);
    char label[LM_TRAIN_PATH_LEN + 32];
    snprintf(label, sizeof label, "%s (training fields)", cfg->path);
    st = lm_train_cfg_parse(&cfg->train, text, label, err);
    free(text);
    return st;
}

/* preset_train {"name": {...}} (names of the presets list) and drop {after_minutes, behind_db}. */
static lm_status extra_fields(lm_study_cfg *cfg, json_t *root, const char *w, lm_err *err)
{
    json_t *pt = json_object_get(root, "preset_train"), *v;
    const char *key;
    if (pt && !json_is_object(pt)) BAD("%s: field 'preset_train': must be an object", w);
    json_object_foreach(pt, key, v) {
        int listed = 0;
        for (int j = 0; j < cfg->npresets; j++) listed |= !strcmp(cfg->presets[j], key);
        if (!listed || !json_is_object(v))
            BAD("%s: field 'preset_train.%s': must be an object for a listed preset", w, key);
        lm_train_cfg probe = cfg->train;
        json_t *t = json_deep_copy(v);
        json_object_set_new(t, "version", json_integer(LM_TRAIN_CFG_VERSION));
        char *text = json_dumps(t, 0);
        json_decref(t);
        lm_status st = text ? lm_train_cfg_parse(&probe, text, w, err) : LM_ERR_NOMEM;
        free(text);
        if (st) return st;
    }
    if (pt) cfg->preset_train = json_incref(pt);
    json_t *d = json_object_get(root, "drop");
    if (!d) return LM_OK;
    json_t *a = json_object_get(d, "after_minutes"), *b = json_object_get(d, "behind_db");
    if (!json_is_object(d) || !json_is_number(a) || !json_is_number(b) ||
        !(json_number_value(a) > 0 && json_number_value(a) <= 1e6) ||
        !(json_number_value(b) >= 0 && json_number_value(b) <= 1000))
        BAD("%s: field 'drop': must be {\"after_minutes\": M in (0, 1e6], \"behind_db\": D in "
            "[0, 1000]}", w);
    cfg->drop_minutes = (float)json_number_value(a);
    cfg->drop_db = (float)json_number_value(b);
    return LM_OK;
}

void lm_study_cfg_free(lm_study_cfg *cfg)
{
    json_decref(cfg->preset_train);
    cfg->preset_train = NULL;
}

static lm_status study_fields_parse(lm_study_cfg *cfg, json_t *root, const char *w, lm_err *err)
{
    lm_status st;
    if ((st = presets_field(cfg, root, w, err)) || (st = noise_field(cfg, root, w, err)) ||
        (st = int_field(root, w, "eval_scenes", 1, 1000, &cfg->eval_scenes, err)) ||
        (st = size_field(root, w, "eval_size", &cfg->eval_h, &cfg->eval_w, err)) ||
        (st = int_field(root, w, "rainbow", 0, 4096, &cfg->rainbow, err)) ||
        (st = size_field(root, w, "frame", &cfg->frame_h, &cfg->frame_w, err)) ||
        (st = int_field(root, w, "timing_repeats", 1, 100, &cfg->timing_repeats, err)) ||
        (st = int_field(root, w, "condition_scenes", 0, 1000, &cfg->cond_scenes, err)) ||
        (st = cond_field(cfg, root, w, err)) || (st = nb_field(cfg, root, w, err)) ||
        (st = extra_fields(cfg, root, w, err)))
        return st;
    if (cfg->rainbow > 0 && cfg->rainbow < 66)
        BAD("%s: field 'rainbow': need 0 (skip) or at least 66 (the window)", w);
    json_t *o = json_object_get(root, "output");
    if (o && !json_is_string(o)) BAD("%s: field 'output': must be a path", w);
    if (o) snprintf(cfg->output, sizeof cfg->output, "%s", json_string_value(o));
    return LM_OK;
}

lm_status lm_study_cfg_load(lm_study_cfg *cfg, const char *path, lm_err *err)
{
    lm_study_cfg_default(cfg);
    snprintf(cfg->path, sizeof cfg->path, "%s", path);
    char w[LM_TRAIN_PATH_LEN + 16];
    snprintf(w, sizeof w, "config %s", path);
    json_error_t je;
    lm_status fchk = lm_file_check(path, "a study config (.json)", err);
    if (fchk) return fchk;
    json_t *root = json_load_file(path, JSON_REJECT_DUPLICATES, &je);
    if (!root) {
        FILE *f = fopen(path, "r");
        if (!f) return lm_err_set(err, LM_ERR_IO, "%s: cannot open", w);
        fclose(f);
        return lm_err_set(err, LM_ERR_FORMAT, "%s: line %d: %s", w, je.line, je.text);
    }
    lm_status st = LM_OK;
    json_t *ver = json_object_get(root, "version");
    if (!json_is_object(root)) st = lm_err_set(err, LM_ERR_FORMAT, "%s: must be an object", w);
    else if (!json_is_integer(ver) || json_integer_value(ver) != LM_STUDY_CFG_VERSION)
        st = lm_err_set(err, LM_ERR_FORMAT, "%s: field 'version': must be %d", w,
                        LM_STUDY_CFG_VERSION);
    const char *key;
    json_t *v;
    if (!st) json_object_foreach(root, key, v) {
        if (!st && !in_list(study_fields, key) && !in_list(train_fields, key))
            st = lm_err_set(err, LM_ERR_FORMAT, "%s: unknown field '%s'", w, key);
    }
    if (!st) st = study_fields_parse(cfg, root, w, err);
    if (!st) st = path_fields(cfg, root, w, err);
    if (!st) st = train_fields_parse(cfg, root, w, err);
    if (!st) st = lm_train_cfg_validate(&cfg->train, err);
    json_decref(root);
    return st;
}

int lm_study_noise_index(const lm_study_cfg *cfg, double pct)
{
    int best = 0;
    for (int i = 1; i < cfg->nnoise; i++)
        if (fabs(100.0 * cfg->noise[i] - pct) < fabs(100.0 * cfg->noise[best] - pct)) best = i;
    return best;
}

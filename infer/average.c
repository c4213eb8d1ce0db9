/* average.c — the weight average of trained models of one preset (see average.h). */
#include "infer/average.h"
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "data/util.h"
#include "infer/model_io.h"
#include "models/params.h"

/* A metadata value of the weights file, "" when absent (freed by the caller). */
static char *meta_or_empty(const char *file, const char *key)
{
    lm_err e = {0};
    char *s = lm_safetensors_meta(file, key, &e);
    return s ? s : calloc(1, 1);
}

/* Append the comma-separated 16-hex scene hashes of `add` not yet in *set. 0, or -1. */
static int union_scenes(char **set, const char *add)
{
    for (const char *p = add; *p;) {
        const char *q = strchr(p, ',');
        size_t len = q ? (size_t)(q - p) : strlen(p);
        int have = 0;
        for (const char *s = *set; len && *s && !have;) {
            const char *t = strchr(s, ',');
            size_t l2 = t ? (size_t)(t - s) : strlen(s);
            have = l2 == len && !memcmp(s, p, len);
            s = t ? t + 1 : s + l2;
        }
        if (len && !have) {
            size_t old = strlen(*set);
            char *n = realloc(*set, old + len + 2);
            if (!n) return -1;
            if (old) n[old++] = ',';
            memcpy(n + old, p, len);
            n[old + len] = 0;
            *set = n;
        }
        p = q ? q + 1 : p + len;
    }
    return 0;
}

lm_status lm_model_average(const char *const *paths, int n, const char *out_path, lm_err *err)
{
    if (n < 2 || n > LM_AVERAGE_MAX)
        return lm_err_set(err, LM_ERR_ARG, "%d model(s) to average: give 2 to %d", n,
                          LM_AVERAGE_MAX);
    lm_infer_model first, im;
    memset(&im, 0, sizeof im);
    lm_status st = lm_infer_model_load(paths[0], NULL, &first, err);
    if (st) return st;
    char *f_base = meta_or_empty(first.weights, "base_preset");
    char *f_hash = meta_or_empty(first.weights, "system_hash");
    char *f_sys = meta_or_empty(first.weights, "system");
    char *scenes = meta_or_empty(first.weights, "train_scenes");
    /* the share of clipped training samples: the smallest of the models' ("" when one of
     * them does not record it) */
    char *f_clip = meta_or_empty(first.weights, "clipped");
    double clip = f_clip && f_clip[0] ? atof(f_clip) : -1.0;
    free(f_clip);
    size_t total = first.model->params.total, list_len = 1;
    double *sum = calloc(total ? total : 1, sizeof *sum);
    unsigned char *differs = calloc(total ? total : 1, 1);
    char *list = calloc(1, 1);
    if (!f_base || !f_hash || !f_sys || !scenes || !sum || !differs || !list)
        st = lm_err_set(err, LM_ERR_NOMEM, "average: out of memory (%zu parameters)", total);
    const float *ref = first.model->params.data;
    for (size_t j = 0; !st && j < total; j++) sum[j] = ref[j];
    for (int i = 0; !st && i < n; i++) {
        const lm_infer_model *cur = &first;
        if (i > 0) {
            st = lm_infer_model_load(paths[i], NULL, &im, err);
            if (st) break;
            cur = &im;
            char *b = meta_or_empty(im.weights, "base_preset");
            char *h = meta_or_empty(im.weights, "system_hash");
            char *sc = meta_or_empty(im.weights, "train_scenes");
            char *cl = meta_or_empty(im.weights, "clipped");
            const double c = cl && cl[0] ? atof(cl) : -1.0;
            free(cl);
            if (clip >= 0.0 && (c < 0.0 || c < clip)) clip = c;
            if (!b || !h || !sc)
                st = lm_err_set(err, LM_ERR_NOMEM, "average: out of memory");
            else if (strcmp(im.model->preset, first.model->preset) || strcmp(b, f_base))
                st = lm_err_set(err, LM_ERR_ARG, "%s is %s%s%s, %s is %s%s%s: only "
                                "models of one preset (and base) can be averaged", im.weights,
                                im.model->preset, b[0] ? " on " : "", b, first.weights,
                                first.model->preset, f_base[0] ? " on " : "", f_base);
            else if (strcmp(h, f_hash))
                st = lm_err_set(err, LM_ERR_ARG, "%s and %s were trained with other "
                                "system descriptions (hash %s, %s)", im.weights, first.weights,
                                h[0] ? h : "none", f_hash[0] ? f_hash : "none");
            else if (lm_model_buckets(im.model) != lm_model_buckets(first.model) ||
                     lm_model_frames(im.model) != lm_model_frames(first.model) ||
                     im.model->params.total != total)
                st = lm_err_set(err, LM_ERR_ARG, "%s and %s read other inputs or have "
                                "other shapes", im.weights, first.weights);
            else if (union_scenes(&scenes, sc))
                st = lm_err_set(err, LM_ERR_NOMEM, "average: out of memory");
            free(b), free(h), free(sc);
            const float *d = im.model->params.data;
            for (size_t j = 0; !st && j < total; j++) {
                sum[j] += d[j];
                differs[j] |= d[j] != ref[j];
            }
        }
        if (!st) { /* "file@iteration" for the record */
            char *it = meta_or_empty(cur->weights, "iteration"), item[1200];
            snprintf(item, sizeof item, "%s%s%s%s", i ? "," : "", cur->weights,
                     it && it[0] ? "@" : "", it ? it : "");
            free(it);
            size_t l = strlen(item);
            char *nl = realloc(list, list_len + l);
            if (!nl) st = lm_err_set(err, LM_ERR_NOMEM, "average: out of memory");
            else memcpy(nl + list_len - 1, item, l + 1), list = nl, list_len += l;
        }
        if (i > 0) lm_infer_model_free(&im);
    }
    if (!st) {
        float *out = first.model->params.data;
        for (size_t j = 0; j < total; j++)
            if (differs[j]) out[j] = (float)(sum[j] / n);
        char sys[PATH_MAX + 8], bk[8], fr[8], cnt[16], cs[32] = "";
        if (clip >= 0.0) snprintf(cs, sizeof cs, "%.6g", clip);
        lm_infer_system_relative(first.weights, f_sys, out_path, sys, sizeof sys);
        snprintf(bk, sizeof bk, "%d", lm_model_buckets(first.model));
        snprintf(fr, sizeof fr, "%d", lm_model_frames(first.model));
        snprintf(cnt, sizeof cnt, "%d", n);
        const char *meta[] = {"format", "lumosaic-checkpoint-1", "preset", first.model->preset,
                              "system", sys, "system_hash", f_hash, "buckets", bk,
                              "frames", fr, "train_scenes", scenes, "average_count", cnt,
                              "average_of", list, "clipped", cs, "base_preset", f_base};
        st = lm_params_save(&first.model->params, out_path, meta, f_base[0] ? 11 : 10, err);
    }
    free(sum), free(differs), free(list);
    free(f_base), free(f_hash), free(f_sys), free(scenes);
    lm_infer_model_free(&first);
    return st;
}

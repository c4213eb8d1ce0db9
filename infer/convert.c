/* convert.c — a trained model rewritten with another storage type (see convert.h). */
#include "infer/convert.h"
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include "infer/model_io.h"

lm_status lm_model_convert(const char *in_path, const char *out_path, lm_store_dtype dt,
                           lm_store_report *rep, lm_err *err)
{
    lm_infer_model im;
    lm_status st = lm_infer_model_load(in_path, NULL, &im, err);
    if (st) return st;
    struct stat a, b;
    if (stat(im.weights, &a) == 0 && stat(out_path, &b) == 0 && a.st_dev == b.st_dev &&
        a.st_ino == b.st_ino) {
        st = lm_err_set(err, LM_ERR_ARG, "%s is the model being converted: write another file",
                        out_path);
        lm_infer_model_free(&im);
        return st;
    }
    char **kv = NULL;
    int n = lm_safetensors_meta_all(im.weights, &kv, err);
    const char **meta = n >= 0 ? calloc(2 * (size_t)n + 1, sizeof *meta) : NULL;
    char sys[PATH_MAX + 8];
    if (n < 0) st = err->status;
    else if (!meta) st = lm_err_set(err, LM_ERR_NOMEM, "convert: out of memory");
    for (int i = 0; !st && i < n; i++) {
        meta[2 * i] = kv[2 * i];
        meta[2 * i + 1] = kv[2 * i + 1];
        if (!strcmp(kv[2 * i], "system")) { /* relative to the weights' folder: rebased */
            lm_infer_system_relative(im.weights, kv[2 * i + 1], out_path, sys, sizeof sys);
            meta[2 * i + 1] = sys;
        }
    }
    if (!st) st = lm_params_save_as(&im.model->params, out_path, meta, n, dt, rep, err);
    free(meta);
    lm_safetensors_meta_free(kv, n > 0 ? n : 0);
    lm_infer_model_free(&im);
    return st;
}

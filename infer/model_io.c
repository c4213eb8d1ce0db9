/* model_io.c — load a trained model for inference (see model_io.h).
 * What it is not: a checkpoint resumer (no optimizer state is read). */
#include "infer/model_io.h"
#include "data/noise_est.h"
#include <inttypes.h>
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include "data/spectra.h"
#include "data/mosaic.h"
#include "data/util.h"

static int is_file(const char *p)
{
    struct stat st;
    return stat(p, &st) == 0 && S_ISREG(st.st_mode);
}

/* Resolve the weights file and read its metadata: preset, system path, system hash. */
static lm_status read_meta(const char *path, lm_infer_model *im, char *preset, size_t np,
                           uint64_t *hash, lm_err *err)
{
    if (lm_is_dir(path)) snprintf(im->weights, sizeof im->weights, "%s/model.safetensors", path);
    else snprintf(im->weights, sizeof im->weights, "%s", path);
    lm_status fchk = lm_file_check(im->weights, "a .safetensors file", err);
    if (fchk) return fchk;
    if (!is_file(im->weights))
        return lm_err_set(err, LM_ERR_IO, "%s: no such model (a run folder with "
                          "model.safetensors, or a .safetensors file)", im->weights);
    lm_err e2;
    lm_err_clear(&e2);
    char *p = lm_safetensors_meta(im->weights, "preset", &e2);
    if (!p && e2.status) return lm_err_set(err, e2.status, "%s", e2.msg);
    if (!p)
        return lm_err_set(err, LM_ERR_FORMAT, "%s: not a Lumosaic model (no 'preset' metadata)",
                          im->weights);
    snprintf(preset, np, "%s", p);
    free(p);
    char *s = lm_safetensors_meta(im->weights, "system", &e2);
    const char *slash = strrchr(im->weights, '/');
    if (s && s[0] && s[0] != '/' && slash) /* recorded relative to the weights' folder */
        snprintf(im->system_path, sizeof im->system_path, "%.*s/%s",
                 (int)(slash - im->weights), im->weights, s);
    else
        snprintf(im->system_path, sizeof im->system_path, "%s", s ? s : "");
    free(s);
    char *h = lm_safetensors_meta(im->weights, "system_hash", &e2);
    *hash = h ? strtoull(h, NULL, 16) : 0;
    free(h);
    return LM_OK;
}

/* The file of the recorded system on this machine: the recorded path, else the bundled default
 * when it has the recorded hash (recorded on another machine or checkout). "" if neither. */
static void recorded_system(const char *recorded, uint64_t hash, char *out, size_t n)
{
    snprintf(out, n, "%s", recorded);
    lm_err e2 = {0};
    if (!out[0] && lm_data_path("systems/default.json", out, n, &e2)) out[0] = 0;
    if (!is_file(out) && hash) {
        char def[1024];
        if (lm_data_path("systems/default.json", def, sizeof def, &e2) == LM_OK && is_file(def) &&
            lm_file_hash(def) == hash)
            snprintf(out, n, "%s", def);
    }
    if (!is_file(out)) out[0] = 0;
}

/* An override of another hash: the recorded system's file, loaded into *msys, with the remap
 * from the override's frames to it (im->remap); LM_ERR_ARG "model/system mismatch" with the
 * reason when it cannot be mapped. */
static lm_status load_remap(lm_infer_model *im, const char *recorded, uint64_t hash,
                            uint64_t got, lm_system *msys, lm_err *err)
{
    char path[1024];
    recorded_system(recorded, hash, path, sizeof path);
    if (!path[0] || lm_file_hash(path) != hash)
        return lm_err_set(err, LM_ERR_ARG, "model/system mismatch: %s was trained with a system "
                          "description of hash %016" PRIx64 " (not found here), %s has hash "
                          "%016" PRIx64, im->weights, hash, im->system_path, got);
    lm_err e2 = {0};
    if (lm_system_load(path, msys, &e2))
        return lm_err_set(err, e2.status, "%s: the model's system: %s", im->weights, e2.msg);
    if (lm_gain_remap_init(msys, &im->sys, &im->remap, &e2))
        return lm_err_set(err, LM_ERR_ARG, "model/system mismatch: %s cannot be mapped onto the "
                          "system %s was trained with (%s): %s", im->system_path, im->weights,
                          path, e2.msg);
    snprintf(im->model_system, sizeof im->model_system, "%s", path);
    return LM_OK;
}

/* Load the system (override or recorded; "" = bundled default) and check its hash. An override
 * of another hash that differs from the recorded system in gains only is kept with a remap
 * (infer/raw.h); *msys then holds the recorded system (else it stays zeroed). */
static lm_status load_system(lm_infer_model *im, const char *override, uint64_t hash,
                             lm_system *msys, lm_err *err)
{
    char recorded[sizeof im->system_path];
    snprintf(recorded, sizeof recorded, "%s", im->system_path);
    if (override && override[0])
        snprintf(im->system_path, sizeof im->system_path, "%s", override);
    else
        recorded_system(recorded, hash, im->system_path, sizeof im->system_path);
    if (!im->system_path[0] && !recorded[0] &&
        lm_data_path("systems/default.json", im->system_path, sizeof im->system_path, err))
        return err->status;
    if (!im->system_path[0]) snprintf(im->system_path, sizeof im->system_path, "%s", recorded);
    if (!is_file(im->system_path))
        return lm_err_set(err, LM_ERR_IO, "%s: system description '%s' not found (give the "
                          "system description it was trained with: --system FILE, or a system "
                          "when loading the model)", im->weights, im->system_path);
    uint64_t got = lm_file_hash(im->system_path);
    const int other = hash && got != hash;
    if (other && !(override && override[0]))
        return lm_err_set(err, LM_ERR_ARG, "model/system mismatch: %s was trained with a system "
                          "description of hash %016" PRIx64 ", %s has hash %016" PRIx64,
                          im->weights, hash, im->system_path, got);
    lm_status st = lm_system_load(im->system_path, &im->sys, err);
    if (!st && other) st = load_remap(im, recorded, hash, got, msys, err);
    return st;
}

lm_status lm_infer_model_load(const char *path, const char *system_override, lm_infer_model *im,
                              lm_err *err)
{
    memset(im, 0, sizeof *im);
    char preset[64];
    uint64_t hash = 0;
    lm_mosaic mo;
    lm_system msys; /* with a remap: the model's own system, whose front the network keeps */
    memset(&msys, 0, sizeof msys);
    lm_status st = read_meta(path, im, preset, sizeof preset, &hash, err);
    if (!st) st = load_system(im, system_override, hash, &msys, err);
    if (!st) st = lm_mosaic_from_system(im->remap.active ? &msys : &im->sys, &mo, err);
    lm_system_free(&msys);
    lm_err e3 = {0};
    char *base = st ? NULL : lm_safetensors_meta(im->weights, "base_preset", &e3);
    if (!st && base && base[0])
        im->model = lm_model_create_residual(preset, base, &mo, 0, 0, 0.0f, err);
    else if (!st)
        im->model = lm_model_create(preset, &mo, 0, err);
    free(base);
    if (!st && !im->model) st = err->status;
    if (!st) {
        lm_err e2;
        lm_err_clear(&e2);
        if (lm_params_load(&im->model->params, im->weights, 0, &e2))
            st = lm_err_set(err, e2.status, "model/system mismatch or bad weights: %s", e2.msg);
    }
    if (st) {
        lm_infer_model_free(im);
        return st;
    }
    im->train_scenes = lm_safetensors_meta(im->weights, "train_scenes", &e3);
    char *cl = lm_safetensors_meta(im->weights, "clipped", &e3); /* older files: none */
    im->clipped = cl && cl[0] ? atof(cl) : -1.0;
    free(cl);
    char *bk = lm_safetensors_meta(im->weights, "buckets", &e3); /* older files: none */
    if (bk && bk[0] && atoi(bk) != lm_model_buckets(im->model))
        st = lm_err_set(err, LM_ERR_FORMAT, "%s: records %s bucket(s), its preset %s reads %d",
                        im->weights, bk, preset, lm_model_buckets(im->model));
    free(bk);
    char *fr = st ? NULL : lm_safetensors_meta(im->weights, "frames", &e3); /* older: none */
    if (fr && fr[0] && atoi(fr) != lm_model_frames(im->model))
        st = lm_err_set(err, LM_ERR_FORMAT, "%s: records %s frame(s), its preset %s reads %d",
                        im->weights, fr, preset, lm_model_frames(im->model));
    free(fr);
    if (st) {
        lm_infer_model_free(im);
        return st;
    }
    if (im->remap.active && lm_model_buckets(im->model) == 0)
        im->remap.active = 0; /* an RGB camera's image: no LED gains in it */
    if (im->remap.active && lm_model_buckets(im->model) == 2) {
        st = lm_err_set(err, LM_ERR_ARG, "model/system mismatch: %s has other LED gains than "
                        "%s was trained with, and the two-bucket model %s reads bucket 0, which "
                        "sums every other LED: it cannot be rescaled per tile phase",
                        im->system_path, im->weights, preset);
        lm_infer_model_free(im);
        return st;
    }
    lm_params_set_requires_grad(&im->model->params, 0);
    if (lm_model_has(im->model, LM_CAP_QDO_OPTICS))
        st = lm_infer_qdocam(im->weights, &im->qdo, err);
    if (st) lm_infer_model_free(im);
    return st;
}

lm_status lm_infer_qdocam(const char *weights, lm_qdocam **out, lm_err *err)
{
    lm_doe doe;
    lm_qdocam *q = calloc(1, sizeof *q);
    *out = NULL;
    if (!q) return lm_err_set(err, LM_ERR_NOMEM, "qdo camera: out of memory");
    char run_doe[1100] = "";
    const char *slash = weights ? strrchr(weights, '/') : NULL;
    if (weights)
        snprintf(run_doe, sizeof run_doe, "%.*s%sdoe.json", slash ? (int)(slash - weights) : 0,
                 weights, slash ? "/" : "");
    lm_status st = run_doe[0] && is_file(run_doe) ? lm_doe_load(run_doe, &doe, err)
                                                  : lm_doe_default(&doe, err);
    if (!st) {
        st = lm_qdocam_init(q, &doe, LM_RGBCAM_D65, err);
        lm_doe_free(&doe);
    }
    if (st) free(q);
    else *out = q;
    return st;
}

void lm_infer_set_noise(lm_model *m, const float *frame, int height, int width)
{
    if (!m || !m->noise_input) return;
    m->noise_sigma_items = NULL;
    if (m->noise_given >= 0.0f) {
        float mx = 0.0f;
        for (size_t i = 0; i < (size_t)height * width; i++) mx = frame[i] > mx ? frame[i] : mx;
        m->noise_sigma = m->noise_given * mx;
        return;
    }
    float s = lm_noise_estimate(frame, height, width, m->mosaic.ty, m->mosaic.tx);
    m->noise_sigma = s > 0.0f ? s : 0.0f;
}

void lm_infer_model_free(lm_infer_model *im)
{
    lm_model_free(im->model);
    lm_system_free(&im->sys);
    if (im->qdo) lm_qdocam_free(im->qdo);
    free(im->qdo);
    free(im->train_scenes);
    memset(im, 0, sizeof *im);
}

lm_status lm_infer_bundled_model(int buckets, char *out, size_t n, lm_err *err)
{
    const char *dir = getenv("LM_MODELS_DIR");
#ifdef LM_SOURCE_DIR
    if (!dir || !dir[0]) dir = LM_SOURCE_DIR "/models/demo";
#endif
    if (!dir || !dir[0])
        return lm_err_set(err, LM_ERR_IO, "no bundled models: set LM_MODELS_DIR to the folder "
                          "holding %s", LM_BUNDLED_MODEL_1);
    const char *file = buckets == 2 ? LM_BUNDLED_MODEL_2 : LM_BUNDLED_MODEL_1;
    int k = snprintf(out, n, "%s/%s", dir, file);
    if (k < 0 || (size_t)k >= n) return lm_err_set(err, LM_ERR_ARG, "%s: path too long", dir);
    if (!is_file(out))
        return lm_err_set(err, LM_ERR_IO, "%s: the bundled %s model is missing (set "
                          "LM_MODELS_DIR to the folder holding it)", out,
                          buckets == 2 ? "two-bucket" : "single-bucket");
    return LM_OK;
}

lm_status lm_infer_auto_load(const char *file, const char *system_override, lm_auto_calib *a,
                             lm_infer_model *im0, lm_infer_model *more, lm_model **models,
                             lm_err *e)
{
    if (lm_auto_load(file, a, e)) return e->status;
    for (int m = 0; m < a->nmodels; m++) {
        lm_infer_model *im = m ? &more[m] : im0;
        const char *path = a->models[m].path;
        lm_status st = lm_infer_model_load(path, system_override, im, e);
        if (st) {
            char msg[sizeof e->msg];
            snprintf(msg, sizeof msg, "%s", e->msg);
            lm_err_clear(e);
            return lm_err_set(e, st, "%s: model %d: %s", file, m, msg);
        }
        const lm_model *x = im->model, *x0 = im0->model;
        models[m] = im->model;
        if (im->remap.active)
            return lm_err_set(e, LM_ERR_ARG, "%s: %s has other LED gains than model '%s' was "
                              "trained with, and a calibrated auto model does not rescale "
                              "frames: reconstruct with that model alone (its frames are "
                              "rescaled to its gains)", file, im->system_path, path);
        if (lm_model_buckets(x) != lm_model_buckets(x0))
            return lm_err_set(e, LM_ERR_ARG, "%s: model '%s' reads %s, model '%s' %s: the "
                              "models of a calibration read the same buckets", file, path,
                              lm_model_buckets(x) == 2 ? "both buckets" : "bucket 1",
                              a->models[0].path,
                              lm_model_buckets(x0) == 2 ? "both" : "bucket 1");
        if (lm_model_frames(x) != 1)
            return lm_err_set(e, LM_ERR_ARG, "%s: model '%s' reads three frames: a calibrated "
                              "auto model takes one-frame models only", file, path);
        if (x->mosaic.ty != x0->mosaic.ty || x->mosaic.tx != x0->mosaic.tx ||
            x->out_channels != LM_MODEL_OUT_CHANNELS || lm_model_has(x, LM_CAP_WHOLE_FRAME) ||
            lm_model_has(x, LM_CAP_QDO_OPTICS))
            return lm_err_set(e, LM_ERR_ARG, "%s: models '%s' and '%s' do not fit the same "
                              "system", file, a->models[0].path, path);
    }
    return LM_OK;
}

/* See model_io.h: the recorded system, rebased from the weights' folder to out_path's. */
void lm_infer_system_relative(const char *weights, const char *recorded, const char *out_path,
                              char *out, size_t n)
{
    snprintf(out, n, "%s", recorded);
    if (!recorded[0]) return;
    char abs[PATH_MAX + 8], odir[PATH_MAX];
    const char *slash = strrchr(weights, '/');
    if (recorded[0] != '/' && slash)
        snprintf(abs, sizeof abs, "%.*s/%s", (int)(slash - weights), weights, recorded);
    else
        snprintf(abs, sizeof abs, "%s", recorded);
    const char *os = strrchr(out_path, '/');
    snprintf(odir, sizeof odir, "%.*s", os ? (int)(os - out_path) : 1, os ? out_path : ".");
    if (os == out_path) snprintf(odir, sizeof odir, "/");
    if (lm_path_relative(odir, abs, out, n)) snprintf(out, n, "%s", abs);
}

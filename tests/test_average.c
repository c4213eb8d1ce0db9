/* test_average.c — lm_model_average (infer/average.h): the mean of every parameter, elements
 * equal in all inputs kept bit for bit, the record of the inputs and of their training scenes,
 * the system path rewritten for the output's folder, and the refusals. */
#include "data/spectra.h"
#include "data/system.h"
#include "tensor/rng.h"
#include "data/util.h"
#include "infer/average.h"
#include "infer/model_io.h"
#include "models/params.h"
#include "tests/check.h"
#include <limits.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

static char hash_[32], def_[1024];

/* A model of preset (on base, or "") with seed's weights; the first `same` parameters set to
 * 1/3 (equal in every input), saved as a trained model with the given metadata. */
static lm_model *save(const char *path, const char *preset, const char *base, uint64_t seed,
                      const char *sys, const char *it, const char *scenes, const char *clip)
{
    lm_err e = {0};
    lm_model *m = base[0] ? lm_model_create_residual(preset, base, NULL, seed, 0, 1.0f, &e)
                          : lm_model_create(preset, NULL, seed, &e);
    CHECK_MSG(m != NULL, "%s", e.msg);
    if (!m) return NULL;
    lm_rng r;
    lm_rng_seed(&r, seed * 7919u + 1u);
    for (size_t j = 0; j < m->params.total; j++) /* no init leaves zeros that inputs share */
        m->params.data[j] = lm_rng_uniform(&r) - 0.5f;
    for (int i = 0; i < m->params.n; i++) /* the base (frozen): equal in every input */
        if (!strncmp(m->params.items[i]->name, "base.", 5)) {
            const lm_param *p = m->params.items[i];
            for (size_t j = 0; j < (size_t)lm_tensor_numel(&p->t); j++)
                p->t.data[j] = 1.0f / 3.0f + (float)j * 1e-3f;
        }
    const char *meta[] = {"format", "lumosaic-checkpoint-1", "preset", preset, "system", sys,
                          "system_hash", hash_, "iteration", it, "train_scenes", scenes,
                          "clipped", clip, "base_preset", base};
    CHECK(lm_params_save(&m->params, path, meta, base[0] ? 8 : 7, &e) == LM_OK);
    return m;
}

static void test_mean_and_record(void)
{
    char dir[] = "/tmp/lm_test_average_XXXXXX", p[3][300], out[340], sub[300];
    CHECK(mkdtemp(dir) != NULL);
    snprintf(sub, sizeof sub, "%s/out", dir);
    CHECK(mkdir(sub, 0755) == 0);
    const char *sc[3] = {"aaaaaaaaaaaaaaaa,bbbbbbbbbbbbbbbb", "bbbbbbbbbbbbbbbb,cccccccccccccccc",
                         ""};
    lm_model *m[3];
    const char *clip[3] = {"0.5", "0.25", "1"}; /* the average records the smallest */
    for (int i = 0; i < 3; i++) {
        snprintf(p[i], sizeof p[i], "%s/m%d.safetensors", dir, i);
        char it[8];
        snprintf(it, sizeof it, "%d", 100 * (i + 1));
        m[i] = save(p[i], "rt-8-nc", "lmmse", 11u + (uint64_t)i, "", it, sc[i], clip[i]);
    }
    snprintf(out, sizeof out, "%s/avg.safetensors", sub);
    lm_err e = {0};
    const char *paths[3] = {p[0], p[1], p[2]};
    CHECK_MSG(lm_model_average(paths, 3, out, &e) == LM_OK, "%s", e.msg);
    lm_infer_model im;
    CHECK_MSG(lm_infer_model_load(out, NULL, &im, &e) == LM_OK, "%s", e.msg);
    if (im.model && m[0] && m[1] && m[2]) {
        CHECK(!strcmp(im.model->preset, "rt-8-nc") && im.model->base);
        CHECK(im.model->params.total == m[0]->params.total);
        size_t bad = 0, base_n = 0, net_n = 0;
        for (int i = 0; i < im.model->params.n; i++) {
            const lm_param *q = im.model->params.items[i];
            int is_base = !strncmp(q->name, "base.", 5);
            for (size_t j = 0; j < (size_t)lm_tensor_numel(&q->t); j++) {
                size_t k = q->offset + j;
                double mean = ((double)m[0]->params.data[k] + m[1]->params.data[k] +
                               m[2]->params.data[k]) / 3.0;
                float want = is_base ? m[0]->params.data[k] : (float)mean;
                bad += memcmp(&q->t.data[j], &want, sizeof want) != 0;
                base_n += is_base, net_n += !is_base;
            }
        }
        CHECK(base_n > 0 && net_n > 0);
        CHECK_MSG(bad == 0, "%zu elements differ from the mean", bad);
        /* the training scenes of all three, each once */
        CHECK(im.train_scenes && !strcmp(im.train_scenes, "aaaaaaaaaaaaaaaa,bbbbbbbbbbbbbbbb,"
                                         "cccccccccccccccc"));
    }
    lm_infer_model_free(&im);
    char *of = lm_safetensors_meta(out, "average_of", &e);
    CHECK(of && strstr(of, "m0.safetensors@100,") && strstr(of, "m2.safetensors@300"));
    free(of);
    char *cnt = lm_safetensors_meta(out, "average_count", &e);
    CHECK(cnt && !strcmp(cnt, "3"));
    free(cnt);
    char *cl = lm_safetensors_meta(out, "clipped", &e);
    CHECK_MSG(cl && !strcmp(cl, "0.25"), "clipped share %s", cl ? cl : "(none)");
    free(cl);
    /* two of them: a plain mean, rounded once */
    CHECK(lm_model_average(paths, 2, out, &e) == LM_OK);
    CHECK(lm_infer_model_load(out, NULL, &im, &e) == LM_OK);
    if (im.model && m[0] && m[1]) {
        size_t bad = 0;
        for (int i = 0; i < im.model->params.n; i++) { /* (the block pads between tensors) */
            const lm_param *q = im.model->params.items[i];
            for (size_t j = 0, k = q->offset; j < (size_t)lm_tensor_numel(&q->t); j++, k++) {
                float a = m[0]->params.data[k], b = m[1]->params.data[k];
                float want = a == b ? a : (float)(((double)a + b) / 2.0);
                bad += memcmp(&q->t.data[j], &want, sizeof want) != 0;
            }
        }
        CHECK_MSG(bad == 0, "%zu elements differ from the mean of two", bad);
    }
    lm_infer_model_free(&im);
    for (int i = 0; i < 3; i++) {
        lm_model_free(m[i]);
        unlink(p[i]);
    }
    unlink(out);
    rmdir(sub);
    rmdir(dir);
}

/* A model that records its system by a path relative to its folder: the output in another
 * folder still finds it (the path rewritten relative to the output's folder). */
static void test_system_path(void)
{
    char dir[] = "/tmp/lm_test_average_XXXXXX", rel[1024], p[2][300], sub[300], out[340];
    CHECK(mkdtemp(dir) != NULL);
    CHECK(lm_path_relative(dir, def_, rel, sizeof rel) == 0);
    for (int i = 0; i < 2; i++) {
        snprintf(p[i], sizeof p[i], "%s/m%d.safetensors", dir, i);
        lm_model_free(save(p[i], "linear", "", 3u + (uint64_t)i, rel, "5", "", ""));
    }
    snprintf(sub, sizeof sub, "%s/deeper/out", dir);
    char mid[300];
    snprintf(mid, sizeof mid, "%s/deeper", dir);
    CHECK(mkdir(mid, 0755) == 0 && mkdir(sub, 0755) == 0);
    snprintf(out, sizeof out, "%s/avg.safetensors", sub);
    lm_err e = {0};
    const char *paths[2] = {p[0], p[1]};
    CHECK_MSG(lm_model_average(paths, 2, out, &e) == LM_OK, "%s", e.msg);
    char *rec = lm_safetensors_meta(out, "system", &e), want[1100];
    snprintf(want, sizeof want, "../../%s", rel);
    CHECK_MSG(rec && !strcmp(rec, want), "%s", rec ? rec : "(none)");
    free(rec);
    lm_infer_model im;
    CHECK_MSG(lm_infer_model_load(out, NULL, &im, &e) == LM_OK, "%s", e.msg);
    char a[PATH_MAX], b[PATH_MAX];
    CHECK(realpath(im.system_path, a) && realpath(def_, b) && !strcmp(a, b));
    lm_infer_model_free(&im);
    unlink(out), unlink(p[0]), unlink(p[1]);
    rmdir(sub), rmdir(mid), rmdir(dir);
}

static void test_refusals(void)
{
    char dir[] = "/tmp/lm_test_average_XXXXXX", a[300], b[300], c[300], out[300];
    CHECK(mkdtemp(dir) != NULL);
    snprintf(a, sizeof a, "%s/a.safetensors", dir);
    snprintf(b, sizeof b, "%s/b.safetensors", dir);
    snprintf(c, sizeof c, "%s/c.safetensors", dir);
    snprintf(out, sizeof out, "%s/out.safetensors", dir);
    lm_model_free(save(a, "rt-8-nc", "lmmse", 1, "", "1", "", ""));
    lm_model_free(save(b, "rt-8-nc", "", 2, "", "1", "", ""));   /* no base */
    lm_model_free(save(c, "rt-16-nc", "lmmse", 3, "", "1", "", "")); /* another preset */
    lm_err e = {0};
    const char *one[1] = {a}, *nobase[2] = {a, b}, *other[2] = {a, c}, *missing[2] = {a, "/nonexistent/run"};
    CHECK(lm_model_average(one, 1, out, &e) == LM_ERR_ARG);
    lm_err_clear(&e);
    CHECK(lm_model_average(nobase, 2, out, &e) == LM_ERR_ARG && strstr(e.msg, "one preset"));
    lm_err_clear(&e);
    CHECK(lm_model_average(other, 2, out, &e) == LM_ERR_ARG && strstr(e.msg, "rt-16-nc on lmmse"));
    lm_err_clear(&e);
    CHECK(lm_model_average(missing, 2, out, &e) == LM_ERR_IO);
    CHECK(access(out, F_OK) != 0); /* nothing written */
    unlink(a), unlink(b), unlink(c);
    rmdir(dir);
}

int main(void)
{
    lm_err e = {0};
    if (lm_data_path("systems/default.json", def_, sizeof def_, &e) != LM_OK) {
        fprintf(stderr, "%s\n", e.msg);
        return 1;
    }
    snprintf(hash_, sizeof hash_, "%016llx", (unsigned long long)lm_file_hash(def_));
    RUN(test_mean_and_record);
    RUN(test_system_path);
    RUN(test_refusals);
    return check_summary();
}

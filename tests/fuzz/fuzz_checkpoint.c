/* fuzz_checkpoint.c — resuming a training checkpoint (train/checkpoint.c over the safetensors
 * reader): a run folder of the `linear` model holds a valid model.safetensors and
 * optimizer.safetensors; the input's first byte picks which one it replaces (even: the
 * weights, odd: the optimizer state), the rest is that file. lm_train_load_checkpoint must
 * fail with one line naming the folder's file, or load. */
#include "tests/fuzz/fuzz_util.h"
#include "data/system.h"
#include "models/model.h"
#include "train/adam.h"
#include "data/mosaic.h"
#include "train/train.h"

static lm_model *model;
static lm_adam opt;
static char run[512], saved[2][512];

static void die(const lm_err *e)
{
    fprintf(stderr, "fuzz_checkpoint: %s\n", e->msg);
    abort();
}

/* The model, its optimizer and a valid checkpoint, made once; the two files are kept aside. */
static void make_run(void)
{
    lm_err e = {LM_OK, ""};
    lm_system sys;
    lm_mosaic mo;
    if (lm_system_default(&sys, &e) || lm_mosaic_from_system(&sys, &mo, &e)) die(&e);
    lm_system_free(&sys);
    if (!(model = lm_model_create("linear", &mo, 1, &e))) die(&e);
    lm_adam_cfg cfg;
    lm_adam_default_cfg(&cfg);
    if (lm_adam_init(&opt, &model->params, &cfg, &e)) die(&e);
    lm_train_cfg tc;
    lm_train_cfg_default(&tc);
    mkdir(fz_path(run, "run"), 0755);
    if (lm_train_save_checkpoint(run, model, &opt, 7, 9, NULL, &tc, &e)) die(&e);
    const char *names[2] = {"model.safetensors", "optimizer.safetensors"};
    for (int k = 0; k < 2; k++) {
        char p[600], q[32];
        snprintf(p, sizeof p, "%s/%s", run, names[k]);
        snprintf(q, sizeof q, "saved%d", k);
        if (rename(p, fz_path(saved[k], q)) != 0) abort();
    }
}

static void put(const char *src, const char *dst, const uint8_t *d, size_t n)
{
    FILE *f = fopen(dst, "wb"), *g = src ? fopen(src, "rb") : NULL;
    char buf[65536];
    size_t k;
    if (!f) abort();
    if (g) {
        while ((k = fread(buf, 1, sizeof buf, g)) > 0) fwrite(buf, 1, k, f);
        fclose(g);
    } else if (n) {
        fwrite(d, 1, n, f);
    }
    if (fclose(f) != 0) abort();
}

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size)
{
    if (!model) make_run();
    if (size < 1) return 0;
    int which = data[0] & 1;
    char p[2][600];
    snprintf(p[0], sizeof p[0], "%s/model.safetensors", run);
    snprintf(p[1], sizeof p[1], "%s/optimizer.safetensors", run);
    put(saved[!which], p[!which], NULL, 0);
    put(NULL, p[which], data + 1, size - 1);
    long it = 0, nb = 0;
    uint64_t seed = 0;
    lm_err e = {LM_OK, ""};
    lm_status s = lm_train_load_checkpoint(run, model, &opt, &it, &nb, &seed, &e);
    fz_check(s, &e, run);
    return 0;
}

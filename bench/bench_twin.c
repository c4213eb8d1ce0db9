/* bench_twin.c — the Lumosaic side of the side-by-side benchmark against the PyTorch twin
 * (bench/torch_twin.py, driven by bench/vs_torch.py). One preset, one mode per process, so the
 * driver can read each side's peak resident memory from its own child process:
 *   step     training steps (forward, L1 loss, backward, Adam) at batch B of 66 x 64 patches;
 *   forward  no-grad forward at batch B of 66 x 64 (the paper-size HAN);
 *   frame    reconstruction of one H x W frame with the window scheme of system.md §8
 *            (lm_tile_fold: 66 x 64 windows, stride 30 x 32, flush edge windows, raised-cosine
 *            kernel of infer/tile.h, --batch windows per network call);
 *   dump     the agreement file (safetensors): the mosaic (phases, responses), every parameter
 *            ("param.<name>"), a raw batch and target, the forward output, the L1 loss, every
 *            trainable parameter's gradient ("grad.<name>") and, with --frame-h/--frame-w, one
 *            small frame folded as in `frame` mode ("frame.raw", "frame.out").
 * Times are per repetition after --warmup untimed ones; output is one JSON object on stdout.
 * Inputs are uniform random (seed 7); the model is initialised from --seed (default 1); the
 * network front comes from the bundled default system, as in bench_train.
 *
 * Usage: bench_twin --preset P [--threads T] [--mode step|forward|frame|dump] [--reps N]
 *        [--warmup W] [--batch B] [--height H] [--width W] [--out file] [--seed S]
 *        [--frame-h H --frame-w W] [--no-grad-dump] [--gamma g]
 * --gamma sets every parameter named "*gamma" (HAN's LAM / CSAM scales, initialised 0) to g
 * after the seeded init, so the agreement check exercises those branches too.
 * Not a test: prints figures. */
#include "autograd/autograd.h"
#include "infer/tile.h"
#include "models/model.h"
#include "train/adam.h"
#include "data/mosaic.h"
#include "data/system.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include "bench/bench_util.h"

#define PH 66
#define PW 64
#define MAXREP 256

typedef struct args {
    const char *preset, *mode, *out;
    int threads, reps, warmup, batch, height, width, frame_h, frame_w, grads, set_gamma;
    unsigned long seed;
    float gamma;
} args;

static int parse_args(int argc, char **argv, args *a)
{
    *a = (args){.mode = "step", .threads = 2, .reps = 5, .warmup = 1, .batch = 0, .height = 480,
                .width = 640, .seed = 1, .grads = 1};
    for (int i = 1; i < argc; i++) {
        const char *k = argv[i], *v = i + 1 < argc ? argv[i + 1] : NULL;
        if (!strcmp(k, "--no-grad-dump")) { a->grads = 0; continue; }
        if (!v) { fprintf(stderr, "bench_twin: %s needs a value\n", k); return -1; }
        i++;
        if (!strcmp(k, "--preset")) a->preset = v;
        else if (!strcmp(k, "--mode")) a->mode = v;
        else if (!strcmp(k, "--out")) a->out = v;
        else if (!strcmp(k, "--threads")) a->threads = atoi(v);
        else if (!strcmp(k, "--reps")) a->reps = atoi(v);
        else if (!strcmp(k, "--warmup")) a->warmup = atoi(v);
        else if (!strcmp(k, "--batch")) a->batch = atoi(v);
        else if (!strcmp(k, "--height")) a->height = atoi(v);
        else if (!strcmp(k, "--width")) a->width = atoi(v);
        else if (!strcmp(k, "--frame-h")) a->frame_h = atoi(v);
        else if (!strcmp(k, "--frame-w")) a->frame_w = atoi(v);
        else if (!strcmp(k, "--seed")) a->seed = strtoul(v, NULL, 10);
        else if (!strcmp(k, "--gamma")) a->gamma = (float)atof(v), a->set_gamma = 1;
        else { fprintf(stderr, "bench_twin: unknown option %s\n", k); return -1; }
    }
    if (!a->preset) { fprintf(stderr, "bench_twin: --preset is required\n"); return -1; }
    if (a->batch <= 0) a->batch = !strcmp(a->mode, "frame") ? 8 : 4;
    if (a->reps < 1) a->reps = 1;
    if (a->reps > MAXREP) a->reps = MAXREP;
    if (a->threads < 1) a->threads = 1;
    return 0;
}

/* Forward + L1 (+ backward + Adam when train). Returns 0 or prints the ctx error. */
static int step(lm_ctx *c, lm_model *m, lm_adam *o, const float *raw, const float *tgt, int B,
                int train)
{
    lm_ctx_reset(c);
    lm_ctx_set_grad(c, train);
    lm_tensor *x = lm_tensor_from(c, 4, (int[]){B, 1, PH, PW}, raw);
    lm_tensor *y = lm_tensor_from(c, 4, (int[]){B, LM_MODEL_OUT_CHANNELS, PH, PW}, tgt);
    lm_tensor *loss = lm_l1_loss(c, lm_model_forward(c, m, x), y);
    if (train && loss) {
        lm_params_zero_grad(&m->params);
        lm_backward(c, loss, NULL);
        if (!lm_ctx_status(c)) lm_adam_step(o, &m->params, lm_nthreads(c));
    }
    if (lm_ctx_status(c)) {
        fprintf(stderr, "%s: %s\n", m->preset, lm_ctx_message(c));
        return -1;
    }
    return 0;
}

static lm_tensor *model_fn(lm_ctx *c, lm_tensor *raw, void *user)
{
    return lm_model_forward(c, (lm_model *)user, raw);
}

static int fold_frame(lm_ctx *c, lm_model *m, const float *frame, int H, int W, int batch,
                      float *out)
{
    lm_tile_opts o;
    lm_tile_default_opts(&o);
    o.batch = batch;
    lm_err e = {0};
    if (lm_tile_fold(c, frame, H, W, m->mosaic.ty, m->mosaic.tx, &o, model_fn, m,
                     m->out_channels, out, &e)) {
        fprintf(stderr, "%s: %s\n", m->preset, e.msg);
        return -1;
    }
    return 0;
}

static float *random_buf(lm_rng *r, size_t n)
{
    float *p = malloc(sizeof(float) * n);
    if (p) lm_rng_fill_uniform(r, p, (long)n, 0.0f, 1.0f);
    return p;
}

static void print_times(const args *a, const lm_model *m, const double *t, int n, const char *x)
{
    printf("{\"side\": \"lumosaic\", \"preset\": \"%s\", \"mode\": \"%s\", \"threads\": %d, "
           "\"batch\": %d, \"params\": %ld%s, \"times_ms\": [", a->preset, a->mode, a->threads,
           a->batch, lm_params_count(&m->params, 1), x);
    for (int i = 0; i < n; i++) printf("%s%.3f", i ? ", " : "", 1e3 * t[i]);
    printf("], \"min_ms\": %.3f, \"median_ms\": %.3f}\n", 1e3 * bench_min(t, n),
           1e3 * bench_median(t, n));
}

/* step / forward / frame timing. */
static int run_timed(const args *a, lm_model *m, lm_ctx *c)
{
    int frame = !strcmp(a->mode, "frame"), train = !strcmp(a->mode, "step");
    lm_adam o = {0};
    lm_adam_cfg ac;
    lm_adam_default_cfg(&ac);
    lm_err e = {0};
    if (train && lm_adam_init(&o, &m->params, &ac, &e)) {
        fprintf(stderr, "%s\n", e.msg);
        return 1;
    }
    if (!train) lm_params_set_requires_grad(&m->params, 0);
    lm_rng r;
    lm_rng_seed(&r, 7);
    size_t nin = frame ? (size_t)a->height * a->width : (size_t)a->batch * PH * PW;
    size_t nout = frame ? (size_t)LM_MODEL_OUT_CHANNELS * a->height * a->width
                        : (size_t)a->batch * LM_MODEL_OUT_CHANNELS * PH * PW;
    float *raw = random_buf(&r, nin), *tgt = random_buf(&r, nout);
    double t[MAXREP];
    int ok = raw && tgt;
    for (int i = 0; ok && i < a->warmup + a->reps; i++) {
        double t0 = bench_now();
        ok = frame ? fold_frame(c, m, raw, a->height, a->width, a->batch, tgt) == 0
                   : step(c, m, &o, raw, tgt, a->batch, train) == 0;
        if (i >= a->warmup) t[i - a->warmup] = bench_now() - t0;
    }
    if (ok) {
        char extra[96] = "";
        if (frame) snprintf(extra, sizeof extra, ", \"height\": %d, \"width\": %d", a->height,
                            a->width);
        print_times(a, m, t, a->reps, extra);
    }
    free(raw), free(tgt);
    if (train) lm_adam_free(&o);
    return ok ? 0 : 1;
}

/* ---- dump ------------------------------------------------------------------------------- */
typedef struct entry { char name[LM_PARAM_NAME_MAX]; int ndim, shape[5]; const float *src; } entry;
typedef struct dumpset { entry *e; int n, cap; } dumpset;

static int dump_add(dumpset *d, const char *name, int ndim, const int *shape, const float *src)
{
    if (d->n == d->cap) {
        int cap = d->cap ? 2 * d->cap : 64;
        entry *ne = realloc(d->e, sizeof *ne * (size_t)cap);
        if (!ne) return -1;
        d->e = ne, d->cap = cap;
    }
    entry *x = &d->e[d->n++];
    snprintf(x->name, sizeof x->name, "%s", name);
    x->ndim = ndim;
    memcpy(x->shape, shape, sizeof(int) * (size_t)ndim);
    x->src = src;
    return 0;
}

/* Write the entries as one safetensors file through an lm_params (copies the data). */
static int dump_write(const dumpset *d, const char *path, const char *preset)
{
    lm_params p;
    lm_params_init(&p);
    lm_err e = {0};
    int ok = 1;
    for (int i = 0; ok && i < d->n; i++)
        ok = lm_params_add(&p, d->e[i].name, d->e[i].ndim, d->e[i].shape, 0, &e) != NULL;
    ok = ok && lm_params_finalize(&p, &e) == LM_OK;
    for (int i = 0; ok && i < d->n; i++)
        memcpy(p.items[i]->t.data, d->e[i].src,
               sizeof(float) * (size_t)lm_tensor_numel(&p.items[i]->t));
    const char *meta[] = {"preset", preset, "format", "lumosaic-twin-dump-1"};
    ok = ok && lm_params_save(&p, path, meta, 2, &e) == LM_OK;
    if (!ok) fprintf(stderr, "dump: %s\n", e.msg);
    lm_params_free(&p);
    return ok ? 0 : -1;
}

static int dump_params(dumpset *d, const lm_model *m, int grads)
{
    char nm[LM_PARAM_NAME_MAX + 8];
    for (int i = 0; i < m->params.n; i++) {
        const lm_param *q = m->params.items[i];
        snprintf(nm, sizeof nm, "%s.%s", grads ? "grad" : "param", q->name);
        if (grads && !q->trainable) continue;
        if (dump_add(d, nm, q->t.ndim, q->t.shape, grads ? q->g.data : q->t.data)) return -1;
    }
    return 0;
}

/* Forward + L1 (+ backward: gradients land in m->params' grad block) on one batch. */
static int dump_forward(const args *a, lm_model *m, lm_ctx *c, const float *raw, const float *tgt,
                        float *out, float *loss)
{
    const int B = a->batch, O = LM_MODEL_OUT_CHANNELS;
    lm_ctx_reset(c);
    lm_ctx_set_grad(c, a->grads);
    lm_params_zero_grad(&m->params);
    lm_tensor *x = lm_tensor_from(c, 4, (int[]){B, 1, PH, PW}, raw);
    lm_tensor *y = lm_tensor_from(c, 4, (int[]){B, O, PH, PW}, tgt);
    lm_tensor *pred = lm_model_forward(c, m, x), *l = lm_l1_loss(c, pred, y);
    if (a->grads && l) lm_backward(c, l, NULL);
    int ok = !lm_ctx_status(c);
    if (ok) {
        lm_tensor_read(c, lm_contiguous(c, pred), out);
        lm_tensor_read(c, l, loss);
    } else fprintf(stderr, "%s: %s\n", m->preset, lm_ctx_message(c));
    lm_ctx_reset(c);
    return ok ? 0 : -1;
}

/* The mosaic, the parameters, one batch with its output, loss and gradients, then the optional
 * frame; everything into one file. */
static int run_dump(const args *a, lm_model *m, lm_ctx *c)
{
    if (!a->out) { fprintf(stderr, "bench_twin: dump needs --out\n"); return 1; }
    const int B = a->batch, P = m->mosaic.nch, O = LM_MODEL_OUT_CHANNELS;
    const int FH = a->frame_h, FW = a->frame_w;
    lm_rng r;
    lm_rng_seed(&r, 7);
    float *raw = random_buf(&r, (size_t)B * PH * PW);
    float *tgt = random_buf(&r, (size_t)B * O * PH * PW);
    float *out = malloc(sizeof(float) * B * O * PH * PW), *fr = NULL, *fout = NULL, loss = 0;
    float mos[LM_MOSAIC_MAX_CH * 2], tile[2] = {(float)m->mosaic.ty, (float)m->mosaic.tx};
    for (int k = 0; k < P; k++)
        mos[2 * k] = (float)m->mosaic.phase_y[k], mos[2 * k + 1] = (float)m->mosaic.phase_x[k];
    dumpset d = {0};
    int ok = raw && tgt && out && !dump_add(&d, "mosaic.tile", 1, (int[]){2}, tile) &&
             !dump_add(&d, "mosaic.phase", 2, (int[]){P, 2}, mos) &&
             !dump_add(&d, "mosaic.response", 2, (int[]){P, LM_MOSAIC_RESP_CH},
                       &m->mosaic.response[0][0]) &&
             !dump_params(&d, m, 0) && !dump_forward(a, m, c, raw, tgt, out, &loss) &&
             !dump_add(&d, "raw", 4, (int[]){B, 1, PH, PW}, raw) &&
             !dump_add(&d, "target", 4, (int[]){B, O, PH, PW}, tgt) &&
             !dump_add(&d, "out", 4, (int[]){B, O, PH, PW}, out) &&
             !dump_add(&d, "loss", 1, (int[]){1}, &loss) && (!a->grads || !dump_params(&d, m, 1));
    if (ok && FH > 0 && FW > 0) {
        fr = random_buf(&r, (size_t)FH * FW);
        fout = malloc(sizeof(float) * O * FH * FW);
        lm_params_set_requires_grad(&m->params, 0);
        ok = fr && fout && fold_frame(c, m, fr, FH, FW, 8, fout) == 0 &&
             !dump_add(&d, "frame.raw", 4, (int[]){1, 1, FH, FW}, fr) &&
             !dump_add(&d, "frame.out", 4, (int[]){1, O, FH, FW}, fout);
    }
    ok = ok && dump_write(&d, a->out, a->preset) == 0;
    if (ok)
        printf("{\"side\": \"lumosaic\", \"preset\": \"%s\", \"mode\": \"dump\", "
               "\"file\": \"%s\", \"loss\": %.9g, \"tensors\": %d}\n", a->preset, a->out, loss,
               d.n);
    free(d.e), free(raw), free(tgt), free(out), free(fr), free(fout);
    return ok ? 0 : 1;
}

int main(int argc, char **argv)
{
    args a;
    if (parse_args(argc, argv, &a)) return 2;
    lm_system sys;
    lm_mosaic mo;
    lm_err e = {0};
    if (lm_system_default(&sys, &e) || lm_mosaic_from_system(&sys, &mo, &e)) {
        fprintf(stderr, "%s\n", e.msg);
        return 1;
    }
    lm_system_free(&sys);
    lm_model *m = lm_model_create(a.preset, &mo, a.seed, &e);
    if (!m) {
        fprintf(stderr, "%s\n", e.msg);
        return 1;
    }
    for (int i = 0; a.set_gamma && i < m->params.n; i++) {
        const char *nm = m->params.items[i]->name;
        size_t l = strlen(nm);
        if (l >= 5 && !strcmp(nm + l - 5, "gamma")) lm_init_const(&m->params.items[i]->t, a.gamma);
    }
    lm_ctx c;
    lm_ctx_init(&c, a.threads);
    int rc;
    if (!strcmp(a.mode, "dump")) rc = run_dump(&a, m, &c);
    else if (!strcmp(a.mode, "step") || !strcmp(a.mode, "forward") || !strcmp(a.mode, "frame"))
        rc = run_timed(&a, m, &c);
    else {
        fprintf(stderr, "bench_twin: unknown mode '%s' (step, forward, frame, dump)\n", a.mode);
        rc = 2;
    }
    lm_ctx_free(&c);
    lm_model_free(m);
    return rc;
}

/* test_mst.c — MST++ (models/mst.c): exact parameter counts of models.md §5, official names and
 * initialisation, shapes with sizes not multiple of 8 (reflect pad inside, crop back, checked
 * against padding done by hand), determinism, whole-model finite-difference gradient check of
 * mst-tiny, the no-grad whole-frame path against the grad-mode forward, and the RGB training
 * source (train/source_rgb.c) with a few training iterations of mst-tiny. */
#include "models/model.h"
#include "data/dataset.h"
#include "data/rgbcam.h"
#include "train/train.h"
#include "tests/check.h"
#include <math.h>
#include <stdlib.h>
#include <unistd.h>

static lm_model *make(const char *preset, uint64_t seed)
{
    lm_err e = {0};
    lm_model *m = lm_model_create(preset, NULL, seed, &e);
    CHECK_MSG(m != NULL, "%s: %s", preset, e.msg);
    return m;
}

static long prefix_count(const lm_params *p, const char *prefix)
{
    long n = 0;
    for (int i = 0; i < p->n; i++)
        if (!strncmp(p->items[i]->name, prefix, strlen(prefix)))
            n += lm_tensor_numel(&p->items[i]->t);
    return n;
}

static void test_parameter_counts(void)
{
    static const struct { const char *name; long n; int in; } want[] = {
        {"mst", 1619625, 3}, {"mst-coded", 1622136, 1}, {"mst-tiny", 837 + 536713 + 8649, 3}};
    for (int i = 0; i < 3; i++) {
        lm_model *m = make(want[i].name, 1);
        if (!m) continue;
        CHECK_MSG(lm_params_count(&m->params, 0) == want[i].n, "%s: %ld parameters, expected %ld",
                  want[i].name, lm_params_count(&m->params, 0), want[i].n);
        CHECK(lm_params_count(&m->params, 1) == want[i].n);
        CHECK(m->in_channels == want[i].in && m->out_channels == 31);
        lm_model_free(m);
    }
    /* the parts quoted in models.md: conv_in 837, one MST 536,713, conv_out 8,649;
     * MSAB(c, h) = 12 c^2 + 57 c + h */
    lm_model *m = make("mst", 1);
    if (!m) return;
    CHECK(prefix_count(&m->params, "conv_in.") == 837);
    CHECK(prefix_count(&m->params, "conv_out.") == 8649);
    for (int s = 0; s < 3; s++) {
        char pre[32];
        snprintf(pre, sizeof pre, "body.%d.", s);
        CHECK_MSG(prefix_count(&m->params, pre) == 536713, "%s %ld", pre,
                  prefix_count(&m->params, pre));
    }
    long c = 124;
    CHECK(prefix_count(&m->params, "body.1.bottleneck.") == 12 * c * c + 57 * c + 4);
    lm_param *r = lm_params_find(&m->params, "body.2.encoder_layers.1.0.blocks.0.0.rescale");
    CHECK(r && r->t.ndim == 3 && r->t.shape[0] == 2);
    lm_param *up = lm_params_find(&m->params, "body.0.decoder_layers.0.0.weight");
    CHECK(up && up->t.shape[0] == 124 && up->t.shape[1] == 62 && up->t.shape[2] == 2);
    CHECK(lm_params_find(&m->params, "body.0.decoder_layers.0.0.bias") != NULL);
    CHECK(lm_params_find(&m->params, "body.0.decoder_layers.1.bias") == NULL);
    lm_param *pr = lm_params_find(&m->params, "body.0.decoder_layers.1.2.blocks.0.0.proj.bias");
    CHECK(pr && pr->t.shape[0] == 31);
    CHECK(lm_params_find(&m->params, "body.0.encoder_layers.0.0.blocks.0.1.fn.net.2.weight"));
    lm_model_free(m);
}

static void test_init(void)
{
    lm_model *a = make("mst-tiny", 7), *b = make("mst-tiny", 7), *d = make("mst-tiny", 8);
    if (!a || !b || !d) return;
    CHECK(!memcmp(a->params.data, b->params.data, a->params.total * sizeof(float)));
    CHECK(memcmp(a->params.data, d->params.data, a->params.total * sizeof(float)) != 0);
    const lm_params *p = &a->params;
    lm_tensor *q = &lm_params_find(p, "body.0.bottleneck.blocks.0.0.to_q.weight")->t;
    double s2 = 0;
    for (long i = 0; i < lm_tensor_numel(q); i++) s2 += (double)q->data[i] * q->data[i];
    double sd = sqrt(s2 / lm_tensor_numel(q)); /* 124 x 124: Linear trunc-normal std 0.02 */
    CHECK_MSG(fabs(sd - 0.02) < 0.002, "to_q std %g", sd);
    CHECK(lm_params_find(p, "body.0.bottleneck.blocks.0.0.rescale")->t.data[3] == 1.0f);
    CHECK(lm_params_find(p, "body.0.bottleneck.blocks.0.0.proj.bias")->t.data[5] == 0.0f);
    CHECK(lm_params_find(p, "body.0.bottleneck.blocks.0.1.norm.weight")->t.data[9] == 1.0f);
    CHECK(lm_params_find(p, "body.0.bottleneck.blocks.0.1.norm.bias")->t.data[9] == 0.0f);
    /* conv_in: PyTorch default U(+-1/sqrt(27)) */
    lm_tensor *w = &lm_params_find(p, "conv_in.weight")->t;
    float mx = 0;
    for (long i = 0; i < lm_tensor_numel(w); i++) mx = fmaxf(mx, fabsf(w->data[i]));
    CHECK(mx <= 1.0f / sqrtf(27.0f) && mx > 0.9f / sqrtf(27.0f));
    lm_model_free(a), lm_model_free(b), lm_model_free(d);
}

/* Reflect index (PyTorch 'reflect', edge excluded). */
static int refl(int i, int n) { return i < n ? i : 2 * (n - 1) - i; }

static void test_shapes_and_crop(void)
{
    lm_model *m = make("mst-tiny", 3);
    if (!m) return;
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 1);
    int B = 2, H = 13, W = 10, HP = 16, WP = 16;
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){B, 3, H, W}, &r, 0, 1);
    lm_tensor *y = lm_model_forward(&c, m, x);
    CHECK_CTX_OK(&c);
    CHECK(y && y->shape[0] == B && y->shape[1] == 31 && y->shape[2] == H && y->shape[3] == W);
    /* same as padding by hand to 16 x 16 and cropping the output */
    lm_tensor *xp = lm_tensor_new4(&c, B, 3, HP, WP);
    for (int b = 0; b < B; b++)
        for (int k = 0; k < 3; k++)
            for (int i = 0; i < HP; i++)
                for (int j = 0; j < WP; j++)
                    *lm_at4(xp, b, k, i, j) = *lm_at4(x, b, k, refl(i, H), refl(j, W));
    lm_tensor *yp = lm_model_forward(&c, m, xp);
    CHECK_CTX_OK(&c);
    double maxd = 0;
    for (int b = 0; y && yp && b < B; b++)
        for (int k = 0; k < 31; k++)
            for (int i = 0; i < H; i++)
                for (int j = 0; j < W; j++)
                    maxd = fmax(maxd, fabs(*lm_at4(y, b, k, i, j) - *lm_at4(yp, b, k, i, j)));
    CHECK_MSG(maxd < 1e-5, "crop differs by %g", maxd);
    int finite = 1;
    for (long i = 0; y && i < lm_tensor_numel(y); i++) finite &= isfinite(y->data[i]);
    CHECK(finite);
    /* bad inputs: an error naming the preset, never a crash */
    CHECK(lm_model_forward(&c, m, lm_tensor_zeros(&c, 4, (int[]){1, 1, 8, 8})) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_model_forward(&c, m, lm_tensor_zeros(&c, 4, (int[]){1, 3, 2, 8})) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    CHECK(lm_model_forward(&c, m, lm_tensor_zeros(&c, 3, (int[]){3, 8, 8})) == NULL);
    CHECK(strstr(c.msg, "mst-tiny") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    lm_ctx_free(&c);
    lm_model_free(m);
    /* the coded variant takes the raw mosaic */
    m = make("mst-coded", 3);
    if (!m) return;
    lm_ctx_init(&c, 2);
    x = lm_tensor_uniform(&c, 4, (int[]){1, 1, 12, 12}, &r, 0, 1);
    y = lm_model_forward(&c, m, x);
    CHECK_CTX_OK(&c);
    CHECK(y && y->shape[1] == 31 && y->shape[2] == 12 && y->shape[3] == 12);
    CHECK(lm_model_forward(&c, m, lm_tensor_zeros(&c, 4, (int[]){1, 3, 12, 12})) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_SHAPE);
    lm_ctx_free(&c);
    lm_model_free(m);
}

static void test_deterministic(void)
{
    lm_model *m = make("mst-tiny", 4);
    if (!m) return;
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 9);
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){2, 3, 24, 20}, &r, 0, 1);
    lm_tensor *y1 = lm_model_forward(&c, m, x), *y2 = lm_model_forward(&c, m, x);
    CHECK_CTX_OK(&c);
    CHECK(y1 && y2 && !memcmp(y1->data, y2->data, lm_tensor_numel(y1) * sizeof(float)));
    lm_ctx_free(&c);
    lm_model_free(m);
}

/* Whole frame without gradients (scopes free intermediates) = the grad-mode forward. */
static void test_reconstruct_frame(void)
{
    lm_model *m = make("mst-tiny", 5);
    if (!m) return;
    int H = 21, W = 30;
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_rng r;
    lm_rng_seed(&r, 3);
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){1, 3, H, W}, &r, 0, 1);
    lm_tensor *y = lm_model_forward(&c, m, x); /* parameters require grad: full tape */
    CHECK_CTX_OK(&c);
    float *out = malloc(sizeof(float) * 31 * H * W);
    lm_err e = {0};
    CHECK(lm_mst_reconstruct(m, x->data, H, W, out, 2, &e) == LM_OK);
    if (y) CHECK_ARRAY_CLOSE(out, y->data, 31L * H * W, 1e-5, 1e-5);
    lm_model *h = make("han-tiny", 1);
    CHECK(lm_mst_reconstruct(h, x->data, H, W, out, 2, &e) == LM_ERR_ARG);
    lm_model_free(h);
    free(out);
    lm_ctx_free(&c);
    lm_model_free(m);
}

typedef struct gc_user { lm_model *m; } gc_user;

static lm_tensor *model_fn(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin;
    return lm_model_forward(c, ((gc_user *)u)->m, in[0]);
}

/* Gradient of a weighted sum of the output w.r.t. the RGB input and samples of every
 * parameter; 6 x 7 exercises the reflect pad and the crop. MST++ has no kinks (GELU). */
static void test_gradcheck(void)
{
    lm_model *m = make("mst-tiny", 11);
    if (!m) return;
    /* larger Linear weights than the 0.02 init so the attention is far from uniform */
    lm_rng r;
    lm_rng_seed(&r, 21);
    for (int i = 0; i < m->params.n; i++) {
        lm_param *p = m->params.items[i];
        if (strstr(p->name, "to_") || strstr(p->name, "proj.weight"))
            lm_init_normal(&p->t, &r, 0.3f);
        if (strstr(p->name, "rescale")) lm_init_uniform(&p->t, &r, 2.0f);
    }
    lm_ctx c;
    lm_ctx_init(&c, 2);
    lm_tensor *x = lm_tensor_uniform(&c, 4, (int[]){1, 3, 6, 7}, &r, 0.1f, 1.0f);
    lm_tensor_set_requires_grad(x, 1);
    int np = m->params.n;
    lm_tensor **in = malloc((size_t)(np + 1) * sizeof *in);
    in[0] = x;
    for (int i = 0; i < np; i++) in[i + 1] = &m->params.items[i]->t;
    lm_gradcheck_opts o;
    lm_gradcheck_default_opts(&o);
    o.eps = 1e-2;
    o.max_checks = 2;
    o.atol = 2e-3;
    o.rtol = 2e-2;
    gc_user u = {m};
    lm_params_zero_grad(&m->params);
    lm_gradcheck_result res;
    lm_status st = lm_gradcheck(&c, model_fn, in, np + 1, &u, &o, &res);
    CHECK_MSG(st == LM_OK, "mst-tiny: %ld of %ld off: %s", res.failed, res.checked, c.msg);
    long expect = 2;
    for (int i = 0; i < np; i++) expect += lm_tensor_numel(in[i + 1]) < 2 ? lm_tensor_numel(in[i + 1]) : 2;
    CHECK_MSG(res.checked == expect, "%ld checked, expected %ld", res.checked, expect);
    if (st) printf("     worst: %s\n", res.worst_input ? m->params.items[res.worst_input - 1]->name : "input");
    printf("     mst-tiny gradient check: %ld elements, worst abs err %.3g\n", res.checked,
           res.max_abs_err);
    lm_ctx_clear_error(&c);
    free(in);
    lm_ctx_free(&c);
    lm_model_free(m);
}

/* ---- the RGB training source on the shared CAVE samples --------------------------------- */
static lm_system g_sys;

static lm_dataset *open_cave(float noise, lm_err *e)
{
    static char dir[1024];
    const char *sd = getenv("LM_SHARED_DIR");
    snprintf(dir, sizeof dir, "%s/data/cave", sd ? sd : "/work/shared");
    static const char *paths[1];
    paths[0] = dir;
    if (lm_system_default(&g_sys, e)) return NULL;
    lm_dataset_cfg cfg;
    lm_dataset_default_cfg(&cfg);
    cfg.paths = paths, cfg.npaths = 1, cfg.sys = &g_sys;
    cfg.patch_h = 12, cfg.patch_w = 12;
    cfg.noise_min = noise, cfg.noise_max = noise;
    cfg.workers = 0, cfg.seed = 3, cfg.val_patches = 4;
    return lm_dataset_open(&cfg, e);
}

/* Noise-free: the input is the camera image of the target's channels 1..31, same samples as
 * the coded dataset; with noise: the dataset's k per sample, deterministic per index. */
static void test_source_rgb(void)
{
    lm_err e = {0};
    lm_dataset *d = open_cave(0.0f, &e);
    CHECK_MSG(d != NULL, "%s", e.msg);
    if (!d) return;
    lm_train_source src;
    CHECK(lm_train_source_rgb_open(&src, d, NULL, LM_RGBCAM_D65, NULL, 12, 12, 3, &e) == LM_OK);
    enum { B = 2, P = 12 * 12 };
    static float rgb[B * 3 * P], tgt[B * 33 * P], raw[B * P], tgt2[B * 33 * P], ref[3 * P];
    CHECK(src.batch(src.user, 5, B, rgb, tgt, &e) == LM_OK);
    CHECK(lm_dataset_batch(d, 5, B, raw, tgt2, &e) == LM_OK);
    CHECK(!memcmp(tgt, tgt2, sizeof tgt)); /* same samples as the coded pipeline */
    lm_rgbcam cam;
    lm_rgbcam_load(&cam, NULL, LM_RGBCAM_D65, &e);
    for (int j = 0; j < B; j++) {
        lm_rgbcam_render(&cam, tgt + (j * 33 + 1) * P, 12, 12, ref, 1);
        CHECK_ARRAY_CLOSE(rgb + j * 3 * P, ref, 3 * P, 1e-6, 0);
    }
    CHECK(src.eval_count(src.user) == lm_dataset_eval_count(d, LM_SPLIT_VAL));
    if (src.eval_count(src.user) > 0) {
        CHECK(src.eval_sample(src.user, 0, rgb, tgt, &e) == LM_OK);
        lm_rgbcam_render(&cam, tgt + P, 12, 12, ref, 1);
        CHECK_ARRAY_CLOSE(rgb, ref, 3 * P, 1e-6, 0);
    }
    lm_train_source_rgb_close(&src);
    lm_dataset_close(d);
    lm_system_free(&g_sys);
    d = open_cave(0.1f, &e);
    if (!d) return;
    CHECK(lm_train_source_rgb_open(&src, d, NULL, LM_RGBCAM_D65, NULL, 12, 12, 3, &e) == LM_OK);
    static float rgb2[B * 3 * P];
    CHECK(src.batch(src.user, 2, B, rgb, tgt, &e) == LM_OK);
    CHECK(src.batch(src.user, 2, B, rgb2, tgt, &e) == LM_OK);
    CHECK(!memcmp(rgb, rgb2, sizeof rgb));
    double s2 = 0, mx = 0;
    lm_rgbcam_render(&cam, tgt + P, 12, 12, ref, 1);
    for (int i = 0; i < 3 * P; i++) s2 += (rgb[i] - ref[i]) * (rgb[i] - ref[i]), mx = fmax(mx, ref[i]);
    CHECK_MSG(fabs(sqrt(s2 / (3 * P)) - 0.1 * mx) < 0.02 * mx, "noise sd %g, k x max %g",
              sqrt(s2 / (3 * P)), 0.1 * mx);
    lm_train_source_rgb_close(&src);
    lm_dataset_close(d);
    lm_system_free(&g_sys);
}

/* Always batch 0 (overfitting one batch shows the loop learns), validation as the source's. */
static lm_train_source *g_inner;
static lm_status fixed_batch(void *u, long index, int B, float *raw, float *target, lm_err *err)
{
    (void)index;
    return g_inner->batch(u, 0, B, raw, target, err);
}

static int fixed_count(void *u) { (void)u; return 2; }
static lm_status fixed_eval(void *u, int i, float *raw, float *target, lm_err *err)
{
    static float r[2 * 3 * 144], t[2 * 33 * 144];
    if (g_inner->batch(u, 0, 2, r, t, err)) return err->status;
    memcpy(raw, r + i * 3 * 144, sizeof r / 2);
    memcpy(target, t + i * 33 * 144, sizeof t / 2);
    return LM_OK;
}

static void test_train_mst_tiny(void)
{
    lm_err e = {0};
    lm_dataset *d = open_cave(0.0f, &e);
    CHECK_MSG(d != NULL, "%s", e.msg);
    if (!d) return;
    lm_train_source src, fixed;
    CHECK(lm_train_source_rgb_open(&src, d, NULL, LM_RGBCAM_D65, NULL, 12, 12, 3, &e) == LM_OK);
    g_inner = &src;
    fixed = src;
    fixed.batch = fixed_batch;
    fixed.eval_count = fixed_count, fixed.eval_sample = fixed_eval; /* 31 -> 33 widening */
    lm_model *m = make("mst-tiny", 2);
    lm_train_cfg cfg;
    lm_train_cfg_default(&cfg);
    snprintf(cfg.model, sizeof cfg.model, "mst-tiny");
    snprintf(cfg.output, sizeof cfg.output, "/tmp/lm_test_mst_%ld", (long)getpid());
    snprintf(cfg.data[0], sizeof cfg.data[0], "%s", lm_dataset_scene_path(d, LM_SPLIT_TRAIN, 0));
    cfg.ndata = 1; /* recorded only: the batches come from `fixed` */
    cfg.patch_h = cfg.patch_w = 12;
    cfg.batch = 2, cfg.accum_steps = 1, cfg.iterations = 8;
    cfg.lr = 2e-3f, cfg.threads = 2;
    cfg.val_interval = 0, cfg.checkpoint_interval = 0;
    lm_train_result res;
    lm_status st = lm_train_run(&cfg, m, &fixed, NULL, &res, &e);
    CHECK_MSG(st == LM_OK, "%s", e.msg);
    CHECK_MSG(res.last_loss < 0.75 * res.first_loss, "loss %g -> %g", res.first_loss,
              res.last_loss);
    CHECK(res.validated);
    /* validated on the training batch: L1 over bands 1..31 is the loss just reached */
    CHECK_MSG(res.val.psnr > 15 && res.val.psnr < 100 && res.val.sam > 0 &&
              res.val.mae < 1.5 * res.last_loss, "val PSNR %g MAE %g", res.val.psnr, res.val.mae);
    printf("     mst-tiny, 8 iterations on one RGB batch: L1 %.4f -> %.4f, val PSNR %.2f dB\n",
           res.first_loss, res.last_loss, res.val.psnr);
    char cmd[600];
    snprintf(cmd, sizeof cmd, "rm -rf '%s'", cfg.output);
    CHECK(system(cmd) == 0);
    lm_model_free(m);
    lm_train_source_rgb_close(&src);
    lm_dataset_close(d);
    lm_system_free(&g_sys);
}

int main(void)
{
    RUN(test_parameter_counts);
    RUN(test_init);
    RUN(test_shapes_and_crop);
    RUN(test_deterministic);
    RUN(test_reconstruct_frame);
    RUN(test_gradcheck);
    RUN(test_source_rgb);
    RUN(test_train_mst_tiny);
    return check_summary();
}

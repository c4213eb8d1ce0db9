/* model.c — the preset table (each row: builder and capability flags) and the common model
 * life cycle. What it is not: the families' layers (models/<family>.c). */
#include "models/model.h"
#include "tensor/device.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

typedef struct preset preset;
struct preset {
    const char *name;
    lm_status (*build)(lm_model *m, const preset *ps, lm_err *err); /* declares the family */
    unsigned caps;   /* lm_model_cap flags, copied to lm_model.caps */
    lm_han_cfg han;  /* han */
    int width;       /* mcan: feats; srnet: dim; rt: width; mst: stages; lmmse: features;
                      * lmmse-guide: the guide's window; lmmse-gri: the interpolation's */
    int depth;       /* tn: residual blocks (0: 2) */
};

/* The families' builders, called with their preset row. */
static lm_status build_linear(lm_model *m, const preset *ps, lm_err *err)
{
    (void)ps;
    return lm_linear_build(m, err);
}
static lm_status build_lmmse(lm_model *m, const preset *ps, lm_err *err)
{
    return lm_lmmse_build(m, 11, ps->width, err);
}
static lm_status build_lmmse_guide(lm_model *m, const preset *ps, lm_err *err)
{
    return lm_lmmse_guide_build(m, 11, ps->width, err);
}
static lm_status build_lmmse_gri(lm_model *m, const preset *ps, lm_err *err)
{
    return lm_lmmse_gri_build(m, 11, ps->width, err); /* 15: ~19 samples of each LED */
}
static lm_status build_han(lm_model *m, const preset *ps, lm_err *err)
{
    return lm_han_build(m, ps->han, err);
}
static lm_status build_mcan(lm_model *m, const preset *ps, lm_err *err)
{
    return lm_mcan_build(m, ps->width, err);
}
static lm_status build_srnet(lm_model *m, const preset *ps, lm_err *err)
{
    return lm_srnet_build(m, ps->width, err);
}
static lm_status build_mst(lm_model *m, const preset *ps, lm_err *err)
{
    return lm_mst_build(m, ps->width, !(ps->caps & LM_CAP_RGB_INPUT), err);
}
static lm_status build_rt(lm_model *m, const preset *ps, lm_err *err)
{
    return lm_rt_build(m, ps->width, 0, err);
}
static lm_status build_rt_nc(lm_model *m, const preset *ps, lm_err *err)
{
    return lm_rt_build(m, ps->width, 1, err);
}

static lm_status build_tile(lm_model *m, const preset *ps, lm_err *err)
{
    return lm_tile_build(m, ps->width, ps->depth ? ps->depth : 2, 1, err);
}

#define CL LM_CAP_OPENCL
#define FIT LM_CAP_CLOSED_FORM
#define RGB LM_CAP_RGB_INPUT
#define WHOLE LM_CAP_WHOLE_FRAME
#define QDO LM_CAP_QDO_OPTICS
#define B2 LM_CAP_TWO_BUCKETS
static const preset presets[] = { /* the first lmmse row also gives "lmmse-K[-rfD]" its flags,
                                   * "lmmse-b2" those of "lmmse-K-b2" */
    {"linear", build_linear, CL, {0, 0, 0, 0, 0}, 0, 0},
    {"lmmse", build_lmmse, CL | FIT, {0, 0, 0, 0, 0}, 0, 0},
    {"lmmse-rf", build_lmmse, CL | FIT, {0, 0, 0, 0, 0}, 256, 0},
    {"han-tiny", build_han, CL, {2, 2, 16, 4, 0}, 0, 0},
    {"han-tiny-nc", build_han, CL, {2, 2, 16, 4, 1}, 0, 0}, /* noise-conditioned, as rt-N-nc */
    {"han-g3b2c32", build_han, CL, {3, 2, 32, 8, 0}, 0, 0},
    {"han-g3b2c32-nc", build_han, CL, {3, 2, 32, 8, 1}, 0, 0},
    {"han-small", build_han, CL, {4, 6, 64, 16, 0}, 0, 0},
    {"han-paper", build_han, CL, {10, 18, 128, 16, 0}, 0, 0},
    {"mcan-tiny", build_mcan, CL, {0, 0, 0, 0, 0}, 16, 0},
    {"mcan", build_mcan, CL, {0, 0, 0, 0, 0}, 64, 0},
    {"srnet-tiny", build_srnet, CL, {0, 0, 0, 0, 0}, 8, 0},
    {"srnet", build_srnet, CL, {0, 0, 0, 0, 0}, 32, 0},
    {"mst-tiny", build_mst, RGB | WHOLE, {0, 0, 0, 0, 0}, 1, 0},
    {"mst", build_mst, RGB | WHOLE, {0, 0, 0, 0, 0}, 3, 0},
    {"mst-coded", build_mst, WHOLE, {0, 0, 0, 0, 0}, 3, 0},
    {"qdo-mst", build_mst, RGB | WHOLE | QDO, {0, 0, 0, 0, 0}, 1, 0}, /* MST++-tiny behind a DOE */
    /* the same with the DOE learned end to end (QDO proper; train/doe_opt.c) */
    {"qdo-mst-doe", build_mst, RGB | WHOLE | QDO | LM_CAP_DOE_LEARNED, {0, 0, 0, 0, 0}, 1, 0},
    {"rt-8", build_rt, CL, {0, 0, 0, 0, 0}, 8, 0},
    {"rt-16", build_rt, CL, {0, 0, 0, 0, 0}, 16, 0},
    /* both buckets: the same families reading bucket 1 and bucket 0 (2 input planes) */
    {"lmmse-b2", build_lmmse, CL | FIT | B2, {0, 0, 0, 0, 0}, 0, 0},
    /* lmmse-b2 plus the panchromatic guide's ratio features (host features; on a device the
     * frames go to the host and the maps back) */
    {"lmmse-guide-b2", build_lmmse_guide, CL | FIT | B2, {0, 0, 0, 0, 0}, 7, 0},
    /* lmmse-b2 plus each LED's plane interpolated by a guided filter on g (host features) */
    {"lmmse-gri-b2", build_lmmse_gri, CL | FIT | B2, {0, 0, 0, 0, 0}, 15, 0},
    {"rt-8-b2", build_rt, CL | B2, {0, 0, 0, 0, 0}, 8, 0},
    {"rt-16-b2", build_rt, CL | B2, {0, 0, 0, 0, 0}, 16, 0},
    /* multi-frame: the current frame and its two neighbours aligned to it (3 input planes) */
    {"rt-8-mf3", build_rt, CL | LM_CAP_MULTI_FRAME, {0, 0, 0, 0, 0}, 8, 0},
    {"rt-16-mf3", build_rt, CL | LM_CAP_MULTI_FRAME, {0, 0, 0, 0, 0}, 16, 0},
    /* noise-conditioned: the branch also sees the input's estimated noise level */
    {"rt-8-nc", build_rt_nc, CL, {0, 0, 0, 0, 0}, 8, 0},
    {"rt-16-nc", build_rt_nc, CL, {0, 0, 0, 0, 0}, 16, 0},
    /* tile resolution, noise-conditioned: the phase planes of each tile, `width` channels */
    {"tn-64-nc", build_tile, CL, {0, 0, 0, 0, 0}, 64, 0},
    {"tn-96-nc", build_tile, CL, {0, 0, 0, 0, 0}, 96, 0},
    {"tn-160-nc", build_tile, CL, {0, 0, 0, 0, 0}, 160, 0},
    {"tn-96-nc-b2", build_tile, CL | B2, {0, 0, 0, 0, 0}, 96, 0},
    {"tn-160-nc-b2", build_tile, CL | B2, {0, 0, 0, 0, 0}, 160, 0},
    /* deeper: four residual blocks (each 3x3 layer reaches one tile further) */
    {"tn-64-d4-nc", build_tile, CL, {0, 0, 0, 0, 0}, 64, 4},
    {"tn-96-d4-nc", build_tile, CL, {0, 0, 0, 0, 0}, 96, 4},
};
#undef B2
#undef CL
#undef FIT
#undef RGB
#undef WHOLE
#undef QDO
#define NPRESETS (int)(sizeof presets / sizeof presets[0])

lm_tensor *lm_model_noise_bias(lm_ctx *c, const lm_model *m, lm_tensor *weights, int B)
{
    const float *items = m->noise_sigma_items;
    if (!items && !(m->noise_sigma >= 0.0f)) {
        lm_ctx_fail(c, LM_ERR_ARG, "%s: the input's noise level is not set (noise_sigma; the "
                    "caller estimates it, data/noise_est.h)", m->preset);
        return NULL;
    }
    lm_tensor *s = lm_tensor_new_on(c, LM_DEVICE_CPU, 4, (int[]){B, 1, 1, 1});
    if (!s) return NULL;
    for (int b = 0; b < B; b++)
        s->data[b] = LM_NOISE_BIAS_SCALE * (items ? items[b] : m->noise_sigma);
    if (c->backend->device != LM_DEVICE_CPU) s = lm_tensor_to_device(c, s);
    int w = weights->shape[0];
    return lm_mul(c, s, lm_reshape(c, weights, 4, (int[]){1, w, 1, 1}));
}

const char *const *lm_model_presets(void)
{
    static const char *names[NPRESETS + 1];
    for (int i = 0; i < NPRESETS; i++) names[i] = presets[i].name;
    names[NPRESETS] = NULL;
    return names;
}

/* One line per preset: what it is for (lumosaic info --list). */
static const struct { const char *name, *purpose; } purposes[] = {
    {"linear", "one learned linear filter per tile phase: the simplest baseline"},
    {"lmmse", "closed-form floor: noise-aware linear filters fitted in seconds (base of residuals)"},
    {"lmmse-rf", "the floor on random ReLU features: a little above lmmse, slow to fit"},
    {"han-tiny", "HAN, 2 groups x 2 blocks, 16 channels: small attention network"},
    {"han-tiny-nc", "han-tiny that also sees the frame's noise level: best residual on lmmse"},
    {"han-g3b2c32", "HAN, 3 groups x 2 blocks, 32 channels: 5x han-tiny's cost"},
    {"han-g3b2c32-nc", "han-g3b2c32 that also sees the noise level: the larger residual"},
    {"han-small", "HAN, 4 x 6, 64 channels: too slow to train well on a CPU"},
    {"han-paper", "the paper's HAN (57 M parameters): for GPUs"},
    {"mcan-tiny", "MCAN with 16 features: mosaic attention, small"},
    {"mcan", "the paper's MCAN (64 features)"},
    {"srnet-tiny", "SRNet with 8 channels: transformer-style baseline, small"},
    {"srnet", "the paper's SRNet (32 channels)"},
    {"mst-tiny", "MST++ (1 stage) from an RGB image: the RGB-camera baseline"},
    {"mst", "MST++ (3 stages) from an RGB image"},
    {"mst-coded", "MST++ (3 stages) on the coded frame"},
    {"qdo-mst", "QDO baseline: MST++-tiny behind a fixed diffractive optic and RGB sensor"},
    {"qdo-mst-doe", "QDO with the optic's height map learned end to end"},
    {"rt-8", "real-time residual network, 8 channels (~30-45 fps at 640 x 480, 2 cores)"},
    {"rt-16", "real-time residual network, 16 channels"},
    {"lmmse-b2", "closed-form floor reading both buckets (bucket 1 and bucket 0)"},
    {"lmmse-guide-b2", "lmmse-b2 plus each LED's share of the panchromatic image (closed form)"},
    {"lmmse-gri-b2", "lmmse-b2 plus each LED's plane guided-filtered on the panchromatic image, "
                     "15 x 15 (closed form)"},
    {"rt-8-b2", "rt-8 reading both buckets"},
    {"rt-16-b2", "rt-16 reading both buckets"},
    {"rt-8-mf3", "rt-8 reading three aligned frames (video)"},
    {"rt-16-mf3", "rt-16 reading three aligned frames (video)"},
    {"rt-8-nc", "rt-8 that also sees the noise level"},
    {"rt-16-nc", "rt-16 that also sees the noise level: the bundled real-time residual on lmmse"},
    {"tn-64-nc", "tile-resolution residual, 64 channels, sees the noise level (1/3 han-tiny's cost)"},
    {"tn-96-nc", "tile-resolution residual, 96 channels, sees the noise level: best residual on lmmse"},
    {"tn-160-nc", "tile-resolution residual, 160 channels, sees the noise level (2x han-tiny's cost)"},
    {"tn-96-nc-b2", "tn-96-nc reading both buckets: the residual on lmmse-b2"},
    {"tn-160-nc-b2", "tn-160-nc reading both buckets (2.6x tn-96-nc-b2's cost)"},
    {"tn-64-d4-nc", "tn-64-nc with four residual blocks: tn-96-nc's cost, 9 tiles' reach"},
    {"tn-96-d4-nc", "tn-96-nc with four residual blocks (1.9x its cost)"},
};

const char *lm_model_preset_purpose(const char *name)
{
    for (size_t i = 0; i < sizeof purposes / sizeof purposes[0]; i++)
        if (!strcmp(purposes[i].name, name)) return purposes[i].purpose;
    return "";
}

const char *lm_model_name(const lm_model *m, char *out, size_t n)
{
    if (m->base) snprintf(out, n, "%s+%s", m->preset, m->base->preset);
    else snprintf(out, n, "%s", m->preset);
    return out;
}

int lm_model_name_split(const char *name, char *net, char *base, size_t n)
{
    const char *plus = strchr(name, '+');
    if (!plus || strchr(plus + 1, '+') || (size_t)(plus - name) >= n || strlen(plus + 1) >= n)
        return 0;
    snprintf(net, n, "%.*s", (int)(plus - name), name);
    snprintf(base, n, "%s", plus + 1);
    return lm_model_preset_known(net) && lm_model_preset_known(base);
}

static const preset *find_preset(const char *name)
{
    for (int i = 0; i < NPRESETS; i++)
        if (!strcmp(presets[i].name, name)) return &presets[i];
    return NULL;
}

/* "lmmse-K" or "lmmse-K-rfD": the lmmse window K (odd, 1..31), else 0; *D the random
 * features (0..4096). */
static int lmmse_k_plain(const char *name, int *D)
{
    *D = 0;
    if (strncmp(name, "lmmse-", 6)) return 0;
    char *end;
    long k = strtol(name + 6, &end, 10), d = 0;
    if (end != name + 6 && !strncmp(end, "-rf", 3)) {
        char *e2;
        d = strtol(end + 3, &e2, 10);
        if (e2 == end + 3 || d < 1 || d > 4096) return 0;
        end = e2;
    }
    *D = (int)d;
    return *end || end == name + 6 || k < 1 || k > 31 || k % 2 == 0 ? 0 : (int)k;
}

/* The lmmse name forms beyond lmmse_k_plain's: "lmmse-K-b2" (two buckets), "lmmse-K-gG-b2"
 * (the panchromatic guide's window G, odd, at most K), "lmmse-K-riN-b2" (the guided
 * interpolation's window N, odd, LM_LMMSE_GRI_MIN..LM_LMMSE_GRI_MAX). */
typedef struct lmmse_name {
    int K, D, b2, G, RI;
    const char *why; /* the reason an "lmmse-K-..." name is refused, else NULL */
} lmmse_name;

static int lmmse_parse(const char *name, lmmse_name *o)
{
    memset(o, 0, sizeof *o);
    if (strncmp(name, "lmmse-", 6)) return 0;
    char *end, *e2;
    long k = strtol(name + 6, &end, 10), w = 0;
    if (end == name + 6) return 0;
    const int ri = !strncmp(end, "-ri", 3), g = !ri && !strncmp(end, "-g", 2);
    if (ri || g) {
        const char *p = end + (ri ? 3 : 2);
        w = strtol(p, &e2, 10);
        if (e2 == p || strcmp(e2, "-b2")) return 0;
        if (w % 2 == 0 || (g && (w < 1 || w > k)) ||
            (ri && (w < LM_LMMSE_GRI_MIN || w > LM_LMMSE_GRI_MAX))) {
            o->why = ri ? "the guided interpolation's window N must be odd, 3..31"
                        : "the guide's window G must be odd and at most K";
            return 0;
        }
        end = e2;
    }
    if (!strcmp(end, "-b2")) {
        if (k < 1 || k > 31 || k % 2 == 0) {
            o->why = "the window K must be odd, 1..31";
            return 0;
        }
        o->b2 = 1, o->G = g ? (int)w : 0, o->RI = ri ? (int)w : 0;
        return o->K = (int)k;
    }
    return o->K = lmmse_k_plain(name, &o->D);
}

static void unknown_preset(const char *name, lm_err *err)
{
    lmmse_name ln;
    lmmse_parse(name, &ln);
    if (ln.why) {
        lm_err_set(err, LM_ERR_ARG, "unknown model '%s': %s", name, ln.why);
        return;
    }
    char list[512] = "";
    for (int i = 0; i < NPRESETS; i++) {
        strncat(list, presets[i].name, sizeof list - strlen(list) - 3);
        if (i + 1 < NPRESETS) strcat(list, ", ");
    }
    lm_err_set(err, LM_ERR_ARG, "unknown model '%s' (presets: %s, lmmse-K, lmmse-K-rfD, "
               "lmmse-K-b2, lmmse-K-gG-b2, lmmse-K-riN-b2)", name, list);
}

const char *lm_model_preset_why(const char *name)
{
    lmmse_name ln;
    return find_preset(name) || lmmse_parse(name, &ln) ? NULL : ln.why;
}

int lm_model_preset_known(const char *name)
{
    lmmse_name ln;
    return find_preset(name) || lmmse_parse(name, &ln);
}

/* Declare the preset's parameters into m (not finalized, not initialised). */
static lm_status build(lm_model *m, const char *name, lm_err *err)
{
    const preset *ps = find_preset(name);
    lmmse_name ln = {0};
    if (!ps && !lmmse_parse(name, &ln)) return unknown_preset(name, err), err->status;
    snprintf(m->preset, sizeof m->preset, "%s", name);
    m->out_channels = LM_MODEL_OUT_CHANNELS;
    m->in_channels = 1;
    m->conv_rows = -1;
    m->noise_sigma = -1.0f;
    m->noise_given = -1.0f;
    if (!ps) {
        m->caps = find_preset(ln.G ? "lmmse-guide-b2" : ln.RI ? "lmmse-gri-b2"
                              : ln.b2 ? "lmmse-b2" : "lmmse")->caps;
        m->in_channels = lm_model_buckets(m);
        return ln.G ? lm_lmmse_guide_build(m, ln.K, ln.G, err)
               : ln.RI ? lm_lmmse_gri_build(m, ln.K, ln.RI, err)
               : lm_lmmse_build(m, ln.K, ln.D, err);
    }
    m->caps = ps->caps;
    if (m->caps & LM_CAP_TWO_BUCKETS) m->in_channels = 2; /* builders may set it otherwise */
    if (m->caps & LM_CAP_MULTI_FRAME) m->in_channels = lm_model_coded_planes(m);
    return ps->build(m, ps, err);
}

static lm_model *model_new(const lm_mosaic *mosaic, lm_err *err)
{
    lm_model *m = calloc(1, sizeof *m);
    if (!m) {
        lm_err_set(err, LM_ERR_NOMEM, "out of memory creating a model");
        return NULL;
    }
    lm_params_init(&m->params);
    if (mosaic) m->mosaic = *mosaic;
    else lm_mosaic_default(&m->mosaic);
    return m;
}

lm_model *lm_model_create(const char *name, const lm_mosaic *mosaic, uint64_t seed, lm_err *err)
{
    lm_model *m = model_new(mosaic, err);
    if (!m) return NULL;
    lm_status st = build(m, name, err);
    if (st == LM_OK) st = lm_params_finalize(&m->params, err);
    if (st != LM_OK) {
        lm_model_free(m);
        return NULL;
    }
    lm_rng r;
    lm_rng_seed(&r, seed);
    m->init(m, &r);
    return m;
}

lm_model *lm_model_create_residual(const char *preset, const char *base_preset,
                                   const lm_mosaic *mosaic, uint64_t seed, int train_base,
                                   float res_init, lm_err *err)
{
    lm_model *m = model_new(mosaic, err), *b = m ? model_new(mosaic, err) : NULL;
    if (!b) return lm_model_free(m), NULL;
    m->base = b;
    lm_status st = build(m, preset, err);
    if (st == LM_OK) { /* the base declares into m's block: "base.*", frozen unless trained */
        b->params = m->params;
        snprintf(b->params.prefix, sizeof b->params.prefix, "base.");
        b->params.frozen = !train_base;
        st = build(b, base_preset, err);
        m->params = b->params;
        m->params.prefix[0] = 0;
        m->params.frozen = 0;
        lm_params_init(&b->params);
    }
    if (st == LM_OK && ((m->caps | b->caps) & LM_CAP_RGB_INPUT ||
                        b->out_channels != m->out_channels))
        st = lm_err_set(err, LM_ERR_ARG, "residual %s on %s: both must map the raw mosaic to %d "
                        "channels", preset, base_preset, m->out_channels);
    if (st == LM_OK && lm_model_buckets(m) != lm_model_buckets(b))
        st = lm_err_set(err, LM_ERR_ARG, "residual %s on %s: the net reads %d bucket(s), the "
                        "base %d; use both of one kind (\"-b2\" presets read both buckets)",
                        preset, base_preset, lm_model_buckets(m), lm_model_buckets(b));
    if (st == LM_OK && lm_model_frames(b) != 1 && lm_model_frames(b) != lm_model_frames(m))
        st = lm_err_set(err, LM_ERR_ARG, "residual %s on %s: the base reads %d frames, the net "
                        "%d; a multi-frame net takes a one-frame base (it sees the current "
                        "frame) or one of its own kind", preset, base_preset, lm_model_frames(b),
                        lm_model_frames(m));
    int gs[1] = {m->out_channels};
    lm_tensor *g = st == LM_OK ? lm_params_add(&m->params, "res_scale", 1, gs, 1, err) : NULL;
    if (st == LM_OK && !g) st = err->status;
    if (st == LM_OK) st = lm_params_finalize(&m->params, err);
    if (st != LM_OK) return lm_model_free(m), NULL;
    lm_rng r;
    lm_rng_seed(&r, seed);
    m->init(m, &r);
    lm_rng_seed(&r, seed ^ 0x9E3779B97F4A7C15ull);
    b->init(b, &r);
    lm_init_const(g, res_init);
    for (int i = 0; i < m->n_out_layers; i++) { /* the net starts at 0: the model is its base */
        lm_init_const(m->out_layers[i]->w, 0.0f);
        if (m->out_layers[i]->b) lm_init_const(m->out_layers[i]->b, 0.0f);
    }
    m->conv_rows = m->conv_rows < 0 || b->conv_rows < 0 ? -1
                   : m->conv_rows > b->conv_rows ? m->conv_rows : b->conv_rows;
    m->noise_input |= b->noise_input;
    /* a residual is trained by gradient descent; on OpenCL only if both parts run there */
    m->caps = ((m->caps | b->caps) & LM_CAP_WHOLE_FRAME) | (m->caps & b->caps & LM_CAP_OPENCL) |
              (m->caps & (LM_CAP_TWO_BUCKETS | LM_CAP_MULTI_FRAME));
    m->res_scale = g;
    return m;
}

void lm_model_free(lm_model *m)
{
    if (!m) return;
    lm_model_free(m->base);
    if (m->free_impl) m->free_impl(m);
    lm_params_free(&m->params);
    free(m);
}

lm_tensor *lm_model_forward(lm_ctx *c, lm_model *m, lm_tensor *raw)
{
    if (!lm_check_inputs(c, m->preset, 1, raw)) return NULL;
    char sb[64];
    const int nb = lm_model_buckets(m), nf = lm_model_frames(m), np = nb * nf;
    if (nb == 0) {
        if (raw->ndim == 4 && raw->shape[1] == m->in_channels) return m->forward(c, m, raw);
        lm_ctx_fail(c, LM_ERR_SHAPE, "%s: input %s must be B x %d x H x W", m->preset,
                    lm_shape_str(raw, sb, sizeof sb), m->in_channels);
        return NULL;
    }
    if (raw->ndim != 4 || raw->shape[1] != np || raw->shape[2] % m->mosaic.ty ||
        raw->shape[3] % m->mosaic.tx) {
        lm_ctx_fail(c, LM_ERR_SHAPE, "%s: input %s must be B x %d x H x W (%s) with H %% %d == 0 "
                    "and W %% %d == 0", m->preset, lm_shape_str(raw, sb, sizeof sb), np,
                    nf > 1 ? "frame i aligned, frames i-1 and i+1 moved onto it"
                    : nb == 2 ? "bucket 1, bucket 0" : "bucket 1", m->mosaic.ty, m->mosaic.tx);
        return NULL;
    }
    if (!m->base) return m->forward(c, m, raw);
    lm_model *b = m->base;
    b->noise_sigma = m->noise_sigma;
    b->noise_sigma_items = m->noise_sigma_items;
    lm_tensor *y = m->forward(c, m, raw);
    int gs[4] = {1, m->out_channels, 1, 1};
    y = lm_mul(c, y, lm_reshape(c, m->res_scale, 4, gs));
    /* a one-frame base under a multi-frame net sees the current frame (plane 0) */
    lm_tensor *braw = lm_model_coded_planes(b) == np ? raw
                      : lm_contiguous(c, lm_slice(c, raw, 1, 0, lm_model_coded_planes(b)));
    return lm_add(c, y, b->forward(c, b, braw));
}

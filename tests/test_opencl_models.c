/* test_opencl_models.c — CPU vs OpenCL agreement of whole models: for linear, han-tiny (LAM and
 * CSAM scales set non-zero), mcan-tiny and srnet-tiny (with a response map), rt-8, rt-16, lmmse,
 * lmmse-5-rf6, residuals rt-8, rt-8-nc, han-tiny-nc and tn-64-nc on lmmse-5, the two-bucket
 * lmmse-5-b2 and rt-8-b2 on it, the host-feature floors lmmse-5-g3-b2 and lmmse-5-ri5-b2 (rt-8-b2
 * on the latter), and
 * the RGB baseline mst-tiny (3 channels in, 31 out; attention over the whole input), the same
 * weights
 * and input run forward + L1 loss + backward on a CPU ctx and on an OpenCL ctx (parameters
 * swapped onto the device for the step, lm_tensors_swap_to_device); the outputs, the loss, the
 * input gradient and every parameter gradient are compared, and the worst absolute and relative
 * differences printed.
 *
 * Tolerance, per compared tensor with reference r: |cl - cpu| <= 1e-4 max|r| + 1e-3 |cpu|.
 * The scale-relative absolute term is there because a model is a chain of dozens of float ops
 * whose sums run in a different order on the two backends (OpenBLAS vs our tiled GEMM,
 * per-chunk reductions); errors grow with the magnitude of the tensor, not of each element,
 * and elements near 0 would otherwise fail on relative error alone. A wrong kernel (a missing
 * +=, a transposed operand) gives errors of the order of max|r| itself, far above 1e-4.
 * Exit 77 only when no OpenCL platform exists. */
#include "tests/test_opencl_util.h"
#include "models/model.h"
#include "autograd/autograd.h"
#include "tests/model_fixture.h"

#define ATOL_SCALE 1e-4 /* absolute term, times max |reference| */
#define RTOL 1e-3


/* Worst differences of one compared tensor, and the number of elements out of tolerance. */
typedef struct diff {
    double abs, rel, scale;
    long bad, n, first;
} diff;

static diff compare(const float *cl, const float *cpu, long n)
{
    diff d = {0, 0, 0, 0, n, -1};
    for (long i = 0; i < n; i++) d.scale = fmax(d.scale, fabs((double)cpu[i]));
    double atol = ATOL_SCALE * d.scale + 1e-30;
    for (long i = 0; i < n; i++) {
        double e = fabs((double)cl[i] - (double)cpu[i]), ref = fabs((double)cpu[i]);
        double r = e / (ref > 1e-6 ? ref : 1e-6);
        if (!(e <= atol + RTOL * ref)) {
            if (d.first < 0) d.first = i;
            d.bad++;
        }
        if (e > d.abs || e != e) d.abs = e;
        if (ref > 1e-3 * d.scale && r > d.rel) d.rel = r; /* rel. error of non-tiny elements */
    }
    return d;
}

static void report(const char *model, const char *what, diff d, const float *cl, const float *cpu)
{
    printf("  %-10s %-22s worst abs %.2e (max|ref| %.2e)  worst rel %.2e  n=%ld\n", model, what,
           d.abs, d.scale, d.rel, d.n);
    if (d.bad) {
        fprintf(stderr, "%s %s: %ld of %ld out of tolerance; first [%ld] opencl %.8g cpu %.8g\n",
                model, what, d.bad, d.n, d.first, cl[d.first], cpu[d.first]);
        check_failures_++;
    }
}

/* One side's results: output, loss, input gradient, parameter gradient block (malloc'd). */
typedef struct run_out {
    float *y, *gx, *gp;
    float loss;
} run_out;

static float *copy_out(lm_ctx *c, lm_tensor *t)
{
    return t ? opencl_fetch(c, lm_contiguous(c, t)) : NULL;
}

/* Forward + L1 loss against target + backward on ctx c (CPU or OpenCL). */
static run_out run_model(lm_ctx *c, lm_model *m, const float *x, const float *target,
                         const int *shape)
{
    run_out o = {NULL, NULL, NULL, NAN};
    lm_params_zero_grad(&m->params);
    int np = m->params.n;
    lm_tensor **ps = malloc((size_t)np * sizeof *ps);
    lm_tensor *saved = malloc((size_t)np * sizeof *saved);
    for (int i = 0; i < np; i++) ps[i] = &m->params.items[i]->t;
    lm_tensor *xt = lm_tensor_from(c, 4, shape, x);
    lm_tensor *tt = lm_tensor_from(c, 4, (int[]){shape[0], m->out_channels, shape[2], shape[3]},
                                   target);
    lm_tensor_set_requires_grad(xt, 1);
    lm_tensors_swap_to_device(c, ps, np, saved);
    lm_tensor *y = lm_model_forward(c, m, xt);
    lm_tensor *loss = lm_l1_loss(c, y, tt);
    lm_backward(c, loss, NULL);
    CHECK_CTX_OK(c);
    o.y = copy_out(c, y);
    o.gx = xt && xt->grad ? copy_out(c, xt->grad) : NULL;
    float *l = copy_out(c, loss);
    if (l) o.loss = l[0];
    free(l);
    lm_tensors_swap_back(c, ps, np, saved);
    CHECK_CTX_OK(c);
    o.gp = malloc(m->params.total * sizeof(float));
    memcpy(o.gp, m->params.grad, m->params.total * sizeof(float));
    free(ps);
    free(saved);
    return o;
}

/* Every parameter gradient compared; one line with the worst parameter (by abs / scale). */
static void compare_params(const lm_model *m, const run_out *g, const run_out *cpu)
{
    diff worst = {0}, all = {0};
    const char *wname = "";
    for (int i = 0; i < m->params.n; i++) {
        const lm_param *p = m->params.items[i];
        if (!p->trainable) continue;
        long n = lm_tensor_numel(&p->t);
        diff d = compare(g->gp + p->offset, cpu->gp + p->offset, n);
        if (d.bad) {
            char what[128];
            snprintf(what, sizeof what, "grad %s", p->name);
            report(m->preset, what, d, g->gp + p->offset, cpu->gp + p->offset);
        }
        if (d.abs / (d.scale + 1e-30) >= worst.abs / (worst.scale + 1e-30)) worst = d, wname = p->name;
        all.rel = fmax(all.rel, d.rel);
        all.n += n;
    }
    printf("  %-10s %-22s worst rel %.2e over %ld elements; worst parameter %s: abs %.2e "
           "(max|ref| %.2e)\n", m->preset, "param grads", all.rel, all.n, wname, worst.abs,
           worst.scale);
    CHECK(all.n > 0);
}

/* base: NULL, or a residual of preset on this base; models that read the noise level get
 * sigma (between two of lmmse's levels, so the filters blend). */
static void check_model_on(const char *preset, const char *base, int B, int H, int W)
{
    lm_mosaic mo;
    test_mosaic(&mo);
    lm_err e = {0};
    lm_model *m = base ? lm_model_create_residual(preset, base, &mo, 7, 0, 1.0f, &e)
                       : lm_model_create(preset, &mo, 7, &e);
    CHECK_MSG(m != NULL, "%s: %s", preset, e.msg);
    if (!m) return;
    m->noise_sigma = 0.03f;
    lm_param *g1 = lm_params_find(&m->params, "la.gamma");
    lm_param *g2 = lm_params_find(&m->params, "csa.gamma");
    if (g1) g1->t.data[0] = 0.3f;
    if (g2) g2->t.data[0] = 0.7f;
    lm_param *nz = lm_params_find(&m->params, "body.0.noise"); /* "-nc": the noise bias acts */
    if (!nz) nz = lm_params_find(&m->params, "head.0.noise");
    for (int i = 0; nz && i < nz->t.shape[0]; i++) nz->t.data[i] = 0.4f - 0.1f * (float)(i % 9);
    /* the closed-form floors' feature readout (zero until fitted): every feature map acts */
    lm_param *ro = lm_params_find(&m->params, base ? "base.readout.weight" : "readout.weight");
    for (long i = 0; ro && i < lm_tensor_numel(&ro->t); i++)
        ro->t.data[i] = 0.05f * (float)((i * 7) % 13) - 0.3f;
    int shape[4] = {B, m->in_channels, H, W}; /* 3 for the RGB baseline (MST++) */
    long nx = (long)B * m->in_channels * H * W, ny = (long)B * H * W * m->out_channels;
    float *x = malloc((size_t)nx * sizeof(float)), *target = malloc((size_t)ny * sizeof(float));
    lm_rng r;
    lm_rng_seed(&r, 11);
    lm_rng_fill_uniform(&r, x, nx, 0.05f, 1.0f);
    lm_rng_fill_uniform(&r, target, ny, 0.0f, 1.0f);
    lm_ctx cc, gc;
    lm_ctx_init(&cc, 2);
    opencl_ctx(&gc);
    run_out cpu = run_model(&cc, m, x, target, shape);
    run_out cl = run_model(&gc, m, x, target, shape);
    if (cpu.y && cl.y && cpu.gx && cl.gx) {
        report(preset, "output", compare(cl.y, cpu.y, ny), cl.y, cpu.y);
        report(preset, "loss", compare(&cl.loss, &cpu.loss, 1), &cl.loss, &cpu.loss);
        report(preset, "input grad", compare(cl.gx, cpu.gx, nx), cl.gx, cpu.gx);
        compare_params(m, &cl, &cpu);
    } else {
        CHECK_MSG(0, "%s: a run produced no result", preset);
    }
    free(cpu.y), free(cpu.gx), free(cpu.gp), free(cl.y), free(cl.gx), free(cl.gp);
    free(x), free(target);
    lm_ctx_free(&cc);
    lm_ctx_free(&gc);
    lm_model_free(m);
}

static void check_model(const char *preset, int B, int H, int W)
{
    check_model_on(preset, NULL, B, H, W);
}

static void test_models(void)
{
    check_model("rt-8", 2, 12, 16);
    check_model("rt-16", 2, 12, 16);
    check_model("lmmse", 2, 18, 24);
    check_model("lmmse-5-rf6", 2, 12, 16);
    check_model_on("rt-8", "lmmse-5", 2, 12, 16);
    check_model("lmmse-5-b2", 2, 12, 16); /* both buckets: two input planes */
    check_model_on("rt-8-b2", "lmmse-5-b2", 2, 12, 16);
    /* host features (the panchromatic guide, the guided interpolation): read to the host, the
     * maps written back to the device */
    check_model("lmmse-5-g3-b2", 2, 12, 16);
    check_model("lmmse-5-ri5-b2", 2, 24, 32);
    check_model_on("rt-8-b2", "lmmse-5-ri5-b2", 2, 24, 32);
    check_model_on("rt-8-nc", "lmmse-5", 2, 12, 16); /* the noise level as a bias */
    check_model_on("han-tiny-nc", "lmmse-5", 2, 12, 16);
    check_model_on("tn-64-nc", "lmmse-5", 2, 12, 16);
    check_model("linear", 2, 12, 16);
    check_model("han-tiny", 2, 12, 16);
    check_model("mcan-tiny", 2, 12, 16);
    check_model("srnet-tiny", 2, 24, 20);
    check_model("mst-tiny", 1, 16, 16); /* RGB input; attention across the whole frame */
}

/* A host parameter in a device op without the swap is an error naming the kernel, not a
 * crash; the swap restores the host structs exactly. */
static void test_swap_errors(void)
{
    lm_err e = {0};
    lm_model *m = lm_model_create("linear", NULL, 1, &e);
    CHECK(m != NULL);
    if (!m) return;
    lm_ctx gc;
    opencl_ctx(&gc);
    lm_tensor *x = lm_tensor_zeros(&gc, 4, (int[]){1, 1, 3, 4});
    CHECK(lm_model_forward(&gc, m, x) == NULL);
    CHECK_MSG(strstr(lm_ctx_message(&gc), "host") != NULL, "message: %s", lm_ctx_message(&gc));
    CHECK_CTX_FAILED(&gc, LM_ERR_BACKEND);
    lm_tensor *ps[1] = {&m->params.items[0]->t}, saved[1];
    lm_tensor before = *ps[0];
    CHECK(lm_tensors_swap_to_device(&gc, ps, 1, saved) == LM_OK);
    CHECK(ps[0]->device == LM_DEVICE_OPENCL && ps[0]->data == NULL);
    CHECK(lm_tensors_swap_back(&gc, ps, 1, saved) == LM_OK);
    CHECK(!memcmp(&before, ps[0], sizeof before));
    lm_ctx_free(&gc);
    lm_model_free(m);
}

int main(void)
{
    int s = opencl_setup();
    if (s) return s;
    RUN(test_models);
    RUN(test_swap_errors);
    lm_cl_backend_free(clb_);
    return check_summary();
}

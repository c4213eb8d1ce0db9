/* test_opencl_core.c — the OpenCL backend itself: creation and selection, device tensors and
 * their arena, host<->device copies and the recorded transfers (gradients across), the view
 * kernels (fill, flat_add, strided_copy, strided_add) against plain-loop references, the
 * backward seed on the device, and the error paths (unknown kernel, host/device mix, build log).
 * Exit 77 only when no OpenCL platform exists. */
#include "tests/test_opencl_util.h"

static void test_backend_selection(void)
{
    lm_err e = {0};
    CHECK(lm_backend_open("cpu", &e) == lm_backend_cpu());
    CHECK(lm_backend_open("tpu", &e) == NULL && e.status == LM_ERR_ARG && strstr(e.msg, "tpu"));
    lm_err_clear(&e);
    setenv("LM_DEVICE", "cpu", 1);
    CHECK(lm_backend_open(NULL, &e) == lm_backend_cpu());
    setenv("LM_OPENCL_DEVICE", "99", 1);
    CHECK(lm_backend_open("opencl", &e) == NULL && e.status == LM_ERR_ARG &&
          strstr(e.msg, "LM_OPENCL_DEVICE"));
    unsetenv("LM_OPENCL_DEVICE");
    lm_err_clear(&e);
    setenv("LM_DEVICE", "opencl", 1);
    lm_backend *b = lm_backend_open(NULL, &e);
    CHECK_MSG(b && b->device == LM_DEVICE_OPENCL, "%s", e.msg);
    CHECK(b && strlen(lm_cl_backend_device_name(b)) > 0);
    lm_backend_close(b);
    unsetenv("LM_DEVICE");
}

static void test_device_tensors_roundtrip(void)
{
    lm_ctx c, h;
    opencl_ctx(&c);
    lm_ctx_init(&h, 1);
    float v[60];
    for (int i = 0; i < 60; i++) v[i] = (float)i * 0.5f - 7.0f;
    lm_tensor *x = lm_tensor_from(&c, 3, (int[]){3, 4, 5}, v);
    CHECK(x && x->device == LM_DEVICE_OPENCL && x->data == NULL && x->dev != NULL);
    float back[60] = {0};
    CHECK(lm_tensor_read(&c, x, back) == 0);
    CHECK_ARRAY_CLOSE(back, v, 60, 0, 0);
    lm_tensor *f = lm_tensor_full(&c, 2, (int[]){7, 9}, 2.5f); /* fill kernel */
    float *fh = opencl_fetch(&c, f);
    for (int i = 0; fh && i < 63; i++) CHECK(fh[i] == 2.5f);
    free(fh);
    /* the same RNG stream gives the same values on both devices */
    lm_rng r1, r2;
    lm_rng_seed(&r1, 5);
    lm_rng_seed(&r2, 5);
    lm_tensor *u = lm_tensor_normal(&c, 1, (int[]){100}, &r1, 1.0f, 2.0f);
    lm_tensor *uh = lm_tensor_normal(&h, 1, (int[]){100}, &r2, 1.0f, 2.0f);
    float *ud = opencl_fetch(&c, u);
    if (ud && uh) CHECK_ARRAY_CLOSE(ud, uh->data, 100, 0, 0);
    free(ud);
    /* a host tensor in the device ctx */
    lm_tensor *ht = lm_tensor_new_on(&c, LM_DEVICE_CPU, 1, (int[]){4});
    CHECK(ht && ht->data && ht->device == LM_DEVICE_CPU);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
    lm_ctx_free(&h);
}

/* Steps of identical allocations land at identical device places once the arena settled,
 * also when the first step needed several blocks (> 16 MB). */
static void test_device_arena_reuse(void)
{
    lm_ctx c;
    opencl_ctx(&c);
    void *dev[3][6];
    size_t off[3][6];
    for (int step = 0; step < 3; step++) {
        for (int i = 0; i < 6; i++) {
            lm_tensor *t = lm_tensor_new(&c, 1, (int[]){1500000 + 1000 * i}); /* ~6 MB each */
            dev[step][i] = t ? t->dev : NULL;
            off[step][i] = t ? t->dev_off : 0;
        }
        CHECK_CTX_OK(&c);
        lm_ctx_reset(&c);
    }
    for (int i = 0; i < 6; i++) CHECK(dev[2][i] == dev[1][i] && off[2][i] == off[1][i]);
    CHECK(dev[1][0] == dev[1][5]); /* coalesced into one block */
    CHECK(off[1][1] >= 1500000 && off[1][1] % 64 == 0);
    lm_ctx_free(&c);
}

/* reshape on the device (no copy) and its flat_add backward, across to_host. */
static void test_reshape_and_flat_add(void)
{
    lm_ctx c;
    opencl_ctx(&c);
    lm_rng r;
    lm_rng_seed(&r, 1);
    lm_tensor *x = lm_tensor_uniform(&c, 2, (int[]){6, 5}, &r, -1, 1);
    lm_tensor_set_requires_grad(x, 1);
    lm_tensor *y = lm_reshape(&c, x, 3, (int[]){3, 2, 5});
    CHECK(y && y->dev == x->dev && y->dev_off == x->dev_off);
    lm_tensor *yh = lm_tensor_to_host(&c, y);
    lm_tensor *w = lm_tensor_new_on(&c, LM_DEVICE_CPU, 3, (int[]){3, 2, 5});
    for (int i = 0; w && i < 30; i++) w->data[i] = (float)i - 10.0f;
    CHECK(lm_backward(&c, yh, w) == LM_OK);
    CHECK(x->grad && x->grad->device == LM_DEVICE_OPENCL);
    float *g = opencl_fetch(&c, x->grad);
    if (g && w) CHECK_ARRAY_CLOSE(g, w->data, 30, 0, 0);
    free(g);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* A strided view of a device tensor: x[:, :, 1:3] of 2x3x4 (hand-made, as slice would). */
static lm_tensor view_of(const lm_tensor *x)
{
    lm_tensor v = *x;
    v.shape[2] = 2;
    v.dev_off += 1;
    v.grad = NULL;
    v.flags = LM_VIEW;
    return v;
}

static void test_strided_copy(void)
{
    lm_ctx c;
    opencl_ctx(&c);
    float h[24];
    for (int i = 0; i < 24; i++) h[i] = (float)(i * i % 17) - 3.0f;
    lm_tensor *x = lm_tensor_from(&c, 3, (int[]){2, 3, 4}, h);
    lm_tensor v = view_of(x);
    CHECK(!lm_tensor_is_contiguous(&v));
    lm_tensor *y = lm_contiguous(&c, &v);
    CHECK(y && y != &v && y->device == LM_DEVICE_OPENCL);
    float expect[12];
    int k = 0;
    for (int a = 0; a < 2; a++)
        for (int b = 0; b < 3; b++)
            for (int d = 1; d < 3; d++) expect[k++] = h[(a * 3 + b) * 4 + d];
    float *yh = opencl_fetch(&c, y);
    if (yh) CHECK_ARRAY_CLOSE(yh, expect, 12, 0, 0);
    free(yh);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* strided_add through lm_kernel_run by name (the op using it, slice, is host-only so far). */
static void test_strided_add(void)
{
    lm_ctx c;
    opencl_ctx(&c);
    float h[24], s[12];
    for (int i = 0; i < 24; i++) h[i] = (float)i;
    for (int i = 0; i < 12; i++) s[i] = 100.0f + (float)i;
    lm_tensor *x = lm_tensor_from(&c, 3, (int[]){2, 3, 4}, h);
    lm_tensor *src = lm_tensor_from(&c, 3, (int[]){2, 3, 2}, s);
    lm_tensor v = view_of(x);
    lm_kernel k = {"strided_add", NULL}; /* never run on the CPU: both tensors on the device */
    lm_tensor *t[2] = {&v, src};
    CHECK(lm_kernel_run(&c, &k, t, 2, NULL) == 0);
    CHECK(lm_kernel_run(&c, &k, t, 2, NULL) == 0); /* += twice */
    float expect[24];
    for (int i = 0; i < 24; i++) expect[i] = h[i];
    for (int a = 0, j = 0; a < 2; a++)
        for (int b = 0; b < 3; b++)
            for (int d = 1; d < 3; d++) expect[(a * 3 + b) * 4 + d] += 2 * s[j++];
    float *xh = opencl_fetch(&c, x);
    if (xh) CHECK_ARRAY_CLOSE(xh, expect, 24, 0, 0);
    free(xh);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* A recorded device slice (what lm_slice would do on the device): forward is a view, backward
 * adds the view's gradient into the strided part of x's gradient with strided_add. */
static void devslice_backward(lm_ctx *c, lm_node *n)
{
    lm_tensor *x = n->in[0];
    if (!lm_requires_grad(x)) return;
    lm_tensor *gx = lm_grad(c, x);
    if (!gx) return;
    lm_tensor v = view_of(gx);
    lm_tensor *t[2] = {&v, n->out->grad};
    static const lm_kernel k = {"strided_add", NULL};
    lm_kernel_run(c, &k, t, 2, NULL);
}

static lm_tensor *devslice(lm_ctx *c, lm_tensor *x)
{
    lm_tensor *v = x ? lm_ctx_alloc(c, sizeof *v) : NULL;
    if (!v) return NULL;
    *v = view_of(x);
    lm_record(c, "devslice", devslice_backward, v, &x, 1, NULL, 0);
    return v;
}

/* Finite differences through host -> device -> strided view -> copy -> host: exercises
 * to_device / to_host backward, strided_copy, flat_add (contiguous backward), strided_add. */
static lm_tensor *fn_transfer(lm_ctx *c, lm_tensor *const *in, int nin, void *u)
{
    (void)nin, (void)u;
    lm_tensor *d = lm_tensor_to_device(c, in[0]);
    return lm_tensor_to_host(c, lm_contiguous(c, devslice(c, d)));
}

static void test_transfer_gradients(void)
{
    lm_ctx c;
    opencl_ctx(&c);
    lm_rng r;
    lm_rng_seed(&r, 9);
    /* y = contiguous(x[:, :, 1:3]) through the device: grad x = w scattered, 0 elsewhere */
    lm_tensor *x = lm_tensor_new_on(&c, LM_DEVICE_CPU, 3, (int[]){2, 3, 4});
    lm_tensor *w = lm_tensor_new_on(&c, LM_DEVICE_CPU, 3, (int[]){2, 3, 2});
    if (x && w) {
        lm_rng_fill_uniform(&r, x->data, 24, -1, 1);
        lm_rng_fill_uniform(&r, w->data, 12, -1, 1);
    }
    lm_tensor_set_requires_grad(x, 1);
    lm_tensor *y = fn_transfer(&c, &x, 1, NULL);
    CHECK(y && y->device == LM_DEVICE_CPU && lm_backward(&c, y, w) == LM_OK);
    float ey[12], eg[24] = {0};
    for (int a = 0, j = 0; a < 2; a++)
        for (int b = 0; b < 3; b++)
            for (int d = 1; d < 3; d++, j++) {
                ey[j] = x->data[(a * 3 + b) * 4 + d];
                eg[(a * 3 + b) * 4 + d] = w->data[j];
            }
    if (y && x->grad) {
        CHECK_ARRAY_CLOSE(y->data, ey, 12, 0, 0);
        CHECK_ARRAY_CLOSE(x->grad->data, eg, 24, 0, 0);
    }
    CHECK_CTX_OK(&c);
    /* exact: to_device then to_host is the identity, so the gradient is the seed */
    lm_ctx_reset(&c);
    x = lm_tensor_new_on(&c, LM_DEVICE_CPU, 2, (int[]){3, 4});
    w = lm_tensor_new_on(&c, LM_DEVICE_CPU, 2, (int[]){3, 4});
    for (int i = 0; x && w && i < 12; i++) x->data[i] = (float)i, w->data[i] = 1.0f - (float)i;
    lm_tensor_set_requires_grad(x, 1);
    lm_tensor *d = lm_tensor_to_device(&c, x);
    CHECK(d && d->device == LM_DEVICE_OPENCL && lm_tensor_to_device(&c, d) == d);
    y = lm_tensor_to_host(&c, d);
    CHECK(y && y->device == LM_DEVICE_CPU && lm_tensor_to_host(&c, y) == y);
    CHECK(lm_backward(&c, y, w) == LM_OK);
    if (x && x->grad && y) {
        CHECK_ARRAY_CLOSE(y->data, x->data, 12, 0, 0);
        CHECK_ARRAY_CLOSE(x->grad->data, w->data, 12, 0, 0);
    }
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

/* to_device of a strided host view packs it. */
static void test_to_device_strided(void)
{
    lm_ctx c;
    opencl_ctx(&c);
    lm_tensor *x = lm_tensor_new_on(&c, LM_DEVICE_CPU, 2, (int[]){4, 6});
    for (int i = 0; x && i < 24; i++) x->data[i] = (float)i;
    lm_tensor *s = lm_slice(&c, x, 1, 2, 3); /* 4x3, rows of 6 */
    lm_tensor *d = lm_tensor_to_device(&c, s);
    float *h = opencl_fetch(&c, d);
    float expect[12];
    for (int i = 0; i < 4; i++)
        for (int j = 0; j < 3; j++) expect[i * 3 + j] = (float)(i * 6 + j + 2);
    if (h) CHECK_ARRAY_CLOSE(h, expect, 12, 0, 0);
    free(h);
    CHECK_CTX_OK(&c);
    lm_ctx_free(&c);
}

static void test_grad_seed_on_device(void)
{
    lm_ctx c;
    opencl_ctx(&c);
    lm_tensor *y = lm_tensor_zeros(&c, 1, (int[]){5});
    float wv[5] = {1, -2, 3, -4, 5};
    lm_tensor *wh = lm_tensor_new_on(&c, LM_DEVICE_CPU, 1, (int[]){5});
    lm_tensor *wd = lm_tensor_from(&c, 1, (int[]){5}, wv);
    if (wh) memcpy(wh->data, wv, sizeof wv);
    CHECK(lm_grad_seed(&c, y, NULL) == LM_OK);
    CHECK(lm_grad_seed(&c, y, wh) == LM_OK);
    CHECK(lm_grad_seed(&c, y, wd) == LM_OK);
    float *g = y ? opencl_fetch(&c, y->grad) : NULL;
    for (int i = 0; g && i < 5; i++) CHECK(g[i] == 1.0f + 2.0f * wv[i]);
    free(g);
    lm_tensor *yh = lm_tensor_new_on(&c, LM_DEVICE_CPU, 1, (int[]){5});
    CHECK(lm_grad_seed(&c, yh, wd) == LM_ERR_ARG);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    lm_ctx_free(&c);
}

static void test_errors(void)
{
    lm_ctx c, h;
    opencl_ctx(&c);
    lm_ctx_init(&h, 1);
    lm_tensor *x = lm_tensor_zeros(&c, 1, (int[]){8});
    lm_kernel unknown = {"no_such_kernel_xyz", NULL};
    CHECK(lm_kernel_run(&c, &unknown, &x, 1, NULL) == LM_ERR_UNSUPPORTED);
    CHECK(strstr(c.msg, "no_such_kernel_xyz") != NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_UNSUPPORTED);
    lm_tensor *hx = lm_tensor_new_on(&c, LM_DEVICE_CPU, 1, (int[]){8});
    lm_kernel fa = {"flat_add", NULL};
    lm_tensor *mix[2] = {x, hx};
    CHECK(lm_kernel_run(&c, &fa, mix, 2, NULL) == LM_ERR_BACKEND);
    CHECK(strstr(c.msg, "flat_add") && strstr(c.msg, "host"));
    CHECK_CTX_FAILED(&c, LM_ERR_BACKEND);
    lm_tensor *hh = lm_tensor_zeros(&h, 1, (int[]){3});
    CHECK(lm_tensor_to_device(&h, hh) == NULL);
    CHECK(strstr(h.msg, "to_device") != NULL);
    CHECK_CTX_FAILED(&h, LM_ERR_ARG);
    CHECK(lm_tensor_to_device(&c, NULL) == NULL);
    CHECK_CTX_FAILED(&c, LM_ERR_ARG);
    CHECK(lm_tensor_read(&h, x, hh->data) == LM_ERR_ARG); /* device tensor, CPU ctx */
    CHECK_CTX_FAILED(&h, LM_ERR_ARG);
    CHECK(lm_tensor_new_on(&h, LM_DEVICE_OPENCL, 1, (int[]){2}) == NULL);
    CHECK_CTX_FAILED(&h, LM_ERR_UNSUPPORTED);
    lm_ctx_free(&c);
    lm_ctx_free(&h);
}

static void test_build_failure_prints_log(void)
{
    lm_err e = {0};
    CHECK(lm_cl_compile_check(clb_, "__kernel void ok(__global float *x) { x[0] = 1.0f; }",
                              &e) == LM_OK);
    fprintf(stderr, "(a build log is expected below)\n");
    CHECK(lm_cl_compile_check(clb_, "__kernel void bad(__global float *x) { x[0] = nope; }",
                              &e) == LM_ERR_BACKEND);
    CHECK_MSG(strstr(e.msg, "nope") != NULL, "message: %s", e.msg);
}

/* Two ctxs share one backend; each has its own device memory. */
static void test_two_contexts(void)
{
    lm_ctx a, b;
    opencl_ctx(&a);
    opencl_ctx(&b);
    lm_tensor *x = lm_tensor_full(&a, 1, (int[]){10}, 1.0f);
    lm_tensor *y = lm_tensor_full(&b, 1, (int[]){10}, 2.0f);
    lm_ctx_reset(&b);
    lm_tensor_full(&b, 1, (int[]){10}, 3.0f);
    float *xh = opencl_fetch(&a, x);
    for (int i = 0; xh && i < 10; i++) CHECK(xh[i] == 1.0f);
    free(xh);
    CHECK(y != NULL);
    CHECK_CTX_OK(&a);
    CHECK_CTX_OK(&b);
    lm_ctx_free(&a);
    lm_ctx_free(&b);
}

int main(void)
{
    int s = opencl_setup();
    if (s) return s;
    RUN(test_backend_selection);
    RUN(test_device_tensors_roundtrip);
    RUN(test_device_arena_reuse);
    RUN(test_reshape_and_flat_add);
    RUN(test_strided_copy);
    RUN(test_strided_add);
    RUN(test_transfer_gradients);
    RUN(test_to_device_strided);
    RUN(test_grad_seed_on_device);
    RUN(test_errors);
    RUN(test_build_failure_prints_log);
    RUN(test_two_contexts);
    lm_cl_backend_free(clb_);
    return check_summary();
}

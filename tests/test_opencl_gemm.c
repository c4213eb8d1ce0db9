/* test_opencl_gemm.c — CPU vs OpenCL agreement, forward and every input gradient, of the
 * products: matmul (transposes, batched, broadcast batch), linear (with/without bias),
 * conv2d (padding, stride, dilation, groups, depthwise, bias; chunked im2col), conv_transpose2d
 * (stride, output padding, groups, dilation, bias) and conv3d.
 * Tolerance atol 1e-4, rtol 1e-4: float products summed in a different order than OpenBLAS
 * (sums of at most a few hundred terms of magnitude <= 1 here). Exit 77 only when no OpenCL
 * platform exists. */
#include "tests/test_opencl_util.h"

#define SHAPE(...) {__VA_ARGS__}
#define TOL .atol = 1e-4, .rtol = 1e-4

typedef struct mm_sel { int ta, tb; } mm_sel;
static lm_tensor *f_matmul(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)n;
    const mm_sel *m = u;
    return lm_matmul(c, in[0], in[1], m->ta, m->tb);
}
static lm_tensor *f_linear(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    (void)u;
    return lm_linear(c, in[0], in[1], n > 2 ? in[2] : NULL);
}
static lm_tensor *f_conv2d(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    return lm_conv2d(c, in[0], in[1], n > 2 ? in[2] : NULL, u);
}
typedef struct convt_sel { lm_conv2d_opts o; int oph, opw; } convt_sel;
static lm_tensor *f_convt(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    const convt_sel *s = u;
    return lm_conv_transpose2d(c, in[0], in[1], n > 2 ? in[2] : NULL, &s->o, s->oph, s->opw);
}
typedef struct c3_sel { int pd, ph, pw; } c3_sel;
static lm_tensor *f_conv3d(lm_ctx *c, lm_tensor *const *in, int n, void *u)
{
    const c3_sel *s = u;
    return lm_conv3d(c, in[0], in[1], n > 2 ? in[2] : NULL, s->pd, s->ph, s->pw);
}

static void test_matmul(void)
{
    mm_sel nn = {0, 0}, tn = {1, 0}, nt = {0, 1}, tt = {1, 1};
    agree_case cases[] = {
        {"matmul 2d", f_matmul, &nn, 2, {2, 2}, {SHAPE(37, 29), SHAPE(29, 70)}, TOL},
        {"matmul 2d a^T", f_matmul, &tn, 2, {2, 2}, {SHAPE(29, 37), SHAPE(29, 70)}, TOL},
        {"matmul 2d b^T", f_matmul, &nt, 2, {2, 2}, {SHAPE(37, 29), SHAPE(70, 29)}, TOL},
        {"matmul 2d a^T b^T", f_matmul, &tt, 2, {2, 2}, {SHAPE(29, 37), SHAPE(70, 29)}, TOL},
        {"matmul 3d x 3d", f_matmul, &nt, 2, {3, 3}, {SHAPE(3, 20, 16), SHAPE(3, 24, 16)}, TOL},
        {"matmul 3d x 2d (fold)", f_matmul, &nn, 2, {3, 2}, {SHAPE(4, 9, 13), SHAPE(13, 5)}, TOL},
        {"matmul 3d^T x 2d", f_matmul, &tn, 2, {3, 2}, {SHAPE(4, 13, 9), SHAPE(13, 5)}, TOL},
        {"matmul 2d x 3d^T", f_matmul, &nt, 2, {2, 3}, {SHAPE(9, 13), SHAPE(4, 5, 13)}, TOL},
        {"matmul 1x1", f_matmul, &nn, 2, {2, 2}, {SHAPE(1, 1), SHAPE(1, 1)}, TOL},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) check_agree(&cases[i], 100 + i);
}

static void test_linear(void)
{
    agree_case k1 = {"linear bias", f_linear, NULL, 3, {3, 2, 1},
                     {SHAPE(2, 7, 33), SHAPE(20, 33), SHAPE(20)}, TOL};
    agree_case k2 = {"linear no bias", f_linear, NULL, 2, {2, 2}, {SHAPE(70, 12), SHAPE(65, 12)},
                     TOL};
    check_agree(&k1, 1);
    check_agree(&k2, 2);
}

static void test_conv2d(void)
{
    lm_conv2d_opts p1 = {.pad_h = 1, .pad_w = 1}, s2 = {.stride_h = 2, .stride_w = 2, .pad_h = 1,
                                                       .pad_w = 0},
                   dil = {.dil_h = 2, .dil_w = 3, .pad_h = 2, .pad_w = 3},
                   grp = {.groups = 2, .pad_h = 1, .pad_w = 1},
                   dw = {.groups = 6, .pad_h = 1, .pad_w = 1}, one = {0};
    agree_case cases[] = {
        {"conv2d 3x3 pad1 bias", f_conv2d, &p1, 3, {4, 4, 1},
         {SHAPE(2, 5, 9, 11), SHAPE(7, 5, 3, 3), SHAPE(7)}, TOL},
        {"conv2d stride 2", f_conv2d, &s2, 2, {4, 4}, {SHAPE(2, 3, 10, 9), SHAPE(4, 3, 3, 2)},
         TOL},
        {"conv2d dilation", f_conv2d, &dil, 3, {4, 4, 1},
         {SHAPE(1, 4, 12, 13), SHAPE(5, 4, 3, 3), SHAPE(5)}, TOL},
        {"conv2d groups 2", f_conv2d, &grp, 3, {4, 4, 1},
         {SHAPE(2, 6, 7, 8), SHAPE(4, 3, 3, 3), SHAPE(4)}, TOL},
        {"conv2d depthwise", f_conv2d, &dw, 2, {4, 4}, {SHAPE(2, 6, 8, 7), SHAPE(6, 1, 3, 3)},
         TOL},
        {"conv2d 1x1", f_conv2d, &one, 3, {4, 4, 1},
         {SHAPE(3, 8, 5, 6), SHAPE(16, 8, 1, 1), SHAPE(16)}, TOL},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) check_agree(&cases[i], 200 + i);
}

/* The stride-1 kernels without im2col (conv_fwd_implicit, conv_bwd_w_implicit, the flipped
 * input gradient) on rows wider than their 16-pixel blocks: Wo 37 (blocks of 16, 16, 5),
 * 33 with a 3x5 dilated kernel and unequal pads, 9 output channels (a partial block of 8) and
 * 2 groups of 5; bias gradients over 185 positions per image (more than a work-group).
 * Padding beyond the kernel reach (1x1, pad 1) sends the input gradient to col2im. */
static void test_conv2d_implicit(void)
{
    lm_conv2d_opts p1 = {.pad_h = 1, .pad_w = 1}, asym = {.pad_h = 2, .pad_w = 1, .dil_h = 2},
                   g2 = {.pad_h = 1, .pad_w = 2, .groups = 2};
    agree_case cases[] = {
        {"conv2d implicit Wo 37 bias", f_conv2d, &p1, 3, {4, 4, 1},
         {SHAPE(2, 3, 5, 37), SHAPE(9, 3, 3, 3), SHAPE(9)}, TOL},
        {"conv2d implicit 3x5 dil pads", f_conv2d, &asym, 3, {4, 4, 1},
         {SHAPE(2, 4, 6, 35), SHAPE(5, 4, 3, 5), SHAPE(5)}, TOL},
        {"conv2d implicit groups", f_conv2d, &g2, 3, {4, 4, 1},
         {SHAPE(3, 4, 4, 20), SHAPE(10, 2, 3, 5), SHAPE(10)}, TOL},
        {"conv2d 1x1 pad 1", f_conv2d, &p1, 3, {4, 4, 1},
         {SHAPE(2, 3, 4, 20), SHAPE(5, 3, 1, 1), SHAPE(5)}, TOL},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) check_agree(&cases[i], 250 + i);
}

/* A scratch budget far below one image forces several images per chunk and split columns;
 * LM_OPENCL_CONV_IM2COL sends stride-1 convs through im2col too. */
static void test_conv2d_chunked(void)
{
    lm_err e = {0};
    setenv("LM_OPENCL_CONV_SCRATCH", "3000", 1);
    setenv("LM_OPENCL_CONV_IM2COL", "1", 1);
    lm_backend *saved = clb_;
    clb_ = lm_cl_backend_create(&e);
    unsetenv("LM_OPENCL_CONV_SCRATCH");
    unsetenv("LM_OPENCL_CONV_IM2COL");
    CHECK_MSG(clb_ != NULL, "%s", e.msg);
    if (!clb_) {
        clb_ = saved;
        return;
    }
    lm_conv2d_opts p1 = {.pad_h = 1, .pad_w = 1, .groups = 2};
    /* per image: 2 groups x 27 x 130 = 7020 floats > 3000: columns split (P = 3000/54/64*64
     * rounds to the 64 minimum) */
    agree_case big = {"conv2d chunked columns", f_conv2d, &p1, 3, {4, 4, 1},
                      {SHAPE(2, 6, 10, 13), SHAPE(4, 3, 3, 3), SHAPE(4)}, TOL};
    check_agree(&big, 300);
    /* per image 2 x 27 x 12 = 648 floats: 4 images per chunk, 3 chunks for 9 images */
    agree_case many = {"conv2d chunked images", f_conv2d, &p1, 2, {4, 4},
                       {SHAPE(9, 6, 3, 4), SHAPE(4, 3, 3, 3)}, TOL};
    check_agree(&many, 301);
    convt_sel ts = {{.stride_h = 2, .stride_w = 2, .pad_h = 1, .pad_w = 1}, 1, 1};
    agree_case ct = {"conv_transpose2d chunked", f_convt, &ts, 2, {4, 4},
                     {SHAPE(3, 4, 6, 7), SHAPE(4, 5, 3, 3)}, TOL};
    check_agree(&ct, 302);
    lm_cl_backend_free(clb_);
    clb_ = saved;
}

static void test_conv_transpose2d(void)
{
    convt_sel s2 = {{.stride_h = 2, .stride_w = 2, .pad_h = 1, .pad_w = 1}, 1, 1};
    convt_sel g2 = {{.groups = 2, .pad_h = 1, .pad_w = 0}, 0, 0};
    convt_sel dl = {{.stride_h = 2, .stride_w = 3, .dil_h = 2, .dil_w = 1}, 1, 2};
    agree_case cases[] = {
        {"conv_transpose2d s2 op1 bias", f_convt, &s2, 3, {4, 4, 1},
         {SHAPE(2, 4, 5, 6), SHAPE(4, 3, 3, 3), SHAPE(3)}, TOL},
        {"conv_transpose2d groups", f_convt, &g2, 2, {4, 4},
         {SHAPE(2, 4, 6, 5), SHAPE(4, 3, 3, 2)}, TOL},
        {"conv_transpose2d dilated", f_convt, &dl, 3, {4, 4, 1},
         {SHAPE(1, 3, 4, 5), SHAPE(3, 2, 2, 3), SHAPE(2)}, TOL},
    };
    for (size_t i = 0; i < sizeof cases / sizeof cases[0]; i++) check_agree(&cases[i], 400 + i);
}

static void test_conv3d(void)
{
    c3_sel p1 = {1, 1, 1}, mixed = {1, 0, 2};
    agree_case k1 = {"conv3d csam 1->1 3x3x3", f_conv3d, &p1, 3, {5, 5, 1},
                     {SHAPE(2, 1, 6, 7, 8), SHAPE(1, 1, 3, 3, 3), SHAPE(1)}, TOL};
    agree_case k2 = {"conv3d 2->3 mixed pads", f_conv3d, &mixed, 2, {5, 5},
                     {SHAPE(1, 2, 5, 6, 4), SHAPE(3, 2, 2, 3, 3)}, TOL};
    /* rows wider than the kernels' 16-wide segments: W = Wo = 37 (16, 16, 5) */
    agree_case k3 = {"conv3d 2->2 wide rows", f_conv3d, &mixed, 3, {5, 5, 1},
                     {SHAPE(2, 2, 3, 4, 37), SHAPE(2, 2, 3, 3, 5), SHAPE(2)}, TOL};
    check_agree(&k1, 500);
    check_agree(&k2, 501);
    check_agree(&k3, 502);
}

int main(void)
{
    int s = opencl_setup();
    if (s) return s;
    RUN(test_matmul);
    RUN(test_linear);
    RUN(test_conv2d);
    RUN(test_conv2d_implicit);
    RUN(test_conv2d_chunked);
    RUN(test_conv_transpose2d);
    RUN(test_conv3d);
    lm_cl_backend_free(clb_);
    return check_summary();
}

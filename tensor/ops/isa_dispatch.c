/* isa_dispatch.c — the entry points of the kernels built once per instruction set
 * (cmake/isa.cmake): each calls the variant of the level lm_isa_active() chose.
 * What it is: one switch per kernel; the level is read with one atomic load.
 * What it is not: a kernel. The variants are the same source files compiled with other flags
 * (conv2d_winograd.c, sgemm_panel.c, conv2d_direct.c, conv2d_depthwise.c, gelu_fast.c). */
#include "tensor/isa.h"
#include "tensor/ops/gemm_internal.h"
#include "tensor/ops/gelu_fast.h"

/* The prototypes of one level's variants. */
#define LM_DECLARE_LEVEL(L)                                                                   \
    int lm_conv2d_winograd_applies_##L(const lm_conv_geom *g);                                \
    int lm_conv2d_winograd_fwd_##L(lm_ctx *c, const lm_conv_geom *g, const float *x,          \
                                   const float *w, const float *bias, float *y);              \
    int lm_conv2d_winograd_bwd_x_##L(lm_ctx *c, const lm_conv_geom *g, const float *dy,       \
                                     const float *w, float *dx);                              \
    int lm_conv2d_winograd_bwd_w_##L(lm_ctx *c, const lm_conv_geom *g, const float *dy,       \
                                     const float *x, float *dw);                              \
    void lm_panel_pack_##L(int M, int K, const float *A, long lda, float *Ap);                \
    void lm_sgemm_panel_##L(int M, int n, int K, const float *Ap, const float *B, long ldb,   \
                            const float *bias, int accumulate, float *C, long ldc);           \
    int lm_conv2d_direct_applies_##L(const lm_conv_geom *g);                                  \
    int lm_conv2d_direct_fwd_##L(lm_ctx *c, const lm_conv_geom *g, const float *x,            \
                                 const float *w, const float *bias, float *y);                \
    int lm_conv2d_dw_fwd_##L(lm_ctx *c, const lm_conv_geom *g, const float *x,                \
                             const float *w, const float *bias, float *y);                    \
    int lm_conv2d_dw_bwd_x_##L(lm_ctx *c, const lm_conv_geom *g, const float *dy,             \
                               const float *w, float *dx);                                    \
    int lm_conv2d_dw_bwd_w_##L(lm_ctx *c, const lm_conv_geom *g, const float *dy,             \
                               const float *x, float *dw);                                    \
    void lm_gelu_fwd_fast_##L(const float *x, float *y, long n, int nthr);                    \
    void lm_gelu_bwd_fast_##L(const float *x, const float *gy, float *gx, long n, int nthr);

LM_DECLARE_LEVEL(generic)
#ifdef LM_ISA_X86_VARIANTS
LM_DECLARE_LEVEL(avx2)
LM_DECLARE_LEVEL(avx512)
/* The best variant for the active level (AMX: the AVX-512 variants; the tile kernels are
 * chosen where bf16 operands are used). */
#define DISPATCH(name, args)                                                                  \
    do {                                                                                      \
        lm_isa a_ = lm_isa_active();                                                          \
        if (a_ >= LM_ISA_AVX512) return name##_avx512 args;                                   \
        if (a_ == LM_ISA_AVX2) return name##_avx2 args;                                       \
        return name##_generic args;                                                           \
    } while (0)
/* The same for kernels that return nothing. */
#define DISPATCH_V(name, args)                                                                \
    do {                                                                                      \
        lm_isa a_ = lm_isa_active();                                                          \
        if (a_ >= LM_ISA_AVX512) name##_avx512 args;                                          \
        else if (a_ == LM_ISA_AVX2) name##_avx2 args;                                         \
        else name##_generic args;                                                             \
    } while (0)
#else
#define DISPATCH(name, args) return name##_generic args
#define DISPATCH_V(name, args) name##_generic args
#endif

int lm_conv2d_winograd_applies(const lm_conv_geom *g)
{
    DISPATCH(lm_conv2d_winograd_applies, (g));
}

int lm_conv2d_winograd_fwd(lm_ctx *c, const lm_conv_geom *g, const float *x, const float *w,
                           const float *bias, float *y)
{
    DISPATCH(lm_conv2d_winograd_fwd, (c, g, x, w, bias, y));
}

int lm_conv2d_winograd_bwd_x(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *w,
                             float *dx)
{
    DISPATCH(lm_conv2d_winograd_bwd_x, (c, g, dy, w, dx));
}

int lm_conv2d_winograd_bwd_w(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *x,
                             float *dw)
{
    DISPATCH(lm_conv2d_winograd_bwd_w, (c, g, dy, x, dw));
}

void lm_panel_pack(int M, int K, const float *A, long lda, float *Ap)
{
    DISPATCH_V(lm_panel_pack, (M, K, A, lda, Ap));
}

void lm_sgemm_panel(int M, int n, int K, const float *Ap, const float *B, long ldb,
                    const float *bias, int accumulate, float *C, long ldc)
{
    DISPATCH_V(lm_sgemm_panel, (M, n, K, Ap, B, ldb, bias, accumulate, C, ldc));
}

int lm_conv2d_direct_applies(const lm_conv_geom *g)
{
    DISPATCH(lm_conv2d_direct_applies, (g));
}

int lm_conv2d_direct_fwd(lm_ctx *c, const lm_conv_geom *g, const float *x, const float *w,
                         const float *bias, float *y)
{
    DISPATCH(lm_conv2d_direct_fwd, (c, g, x, w, bias, y));
}

int lm_conv2d_dw_fwd(lm_ctx *c, const lm_conv_geom *g, const float *x, const float *w,
                     const float *bias, float *y)
{
    DISPATCH(lm_conv2d_dw_fwd, (c, g, x, w, bias, y));
}

int lm_conv2d_dw_bwd_x(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *w,
                       float *dx)
{
    DISPATCH(lm_conv2d_dw_bwd_x, (c, g, dy, w, dx));
}

int lm_conv2d_dw_bwd_w(lm_ctx *c, const lm_conv_geom *g, const float *dy, const float *x,
                       float *dw)
{
    DISPATCH(lm_conv2d_dw_bwd_w, (c, g, dy, x, dw));
}

void lm_gelu_fwd_fast(const float *x, float *y, long n, int nthr)
{
    DISPATCH_V(lm_gelu_fwd_fast, (x, y, n, nthr));
}

void lm_gelu_bwd_fast(const float *x, const float *gy, float *gx, long n, int nthr)
{
    DISPATCH_V(lm_gelu_bwd_fast, (x, gy, gx, n, nthr));
}

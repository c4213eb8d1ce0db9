/* isa.h — the instruction set the CPU kernels run with, chosen once per process.
 * What it is: the hot kernels (Winograd convolution, the panel and blocked SGEMMs, the direct
 * and depthwise convolutions) are compiled once per instruction set — generic (the build's
 * baseline), AVX2 + FMA, AVX-512 (F, VL, BW, DQ) — and every call goes to the best variant the
 * CPU and the operating system support (CPUID + XGETBV), or to a lower one named by the
 * environment variable LM_ISA=generic|avx2|avx512|amx. A level the CPU lacks is refused with
 * one line (lm_isa_init), never run. The matrix units are reported too: AVX-512-BF16 and AMX
 * tiles (AMX-BF16), and whether the kernel grants the AMX tile state to this process.
 * What it is not: a per-call choice (the level is fixed after the first kernel call) or a
 * list of every CPU feature. On non-x86 builds only the generic level exists. */
#ifndef LM_ISA_H
#define LM_ISA_H
#include "tensor/status.h"

#ifdef __cplusplus
extern "C" {
#endif

typedef enum lm_isa {
    LM_ISA_GENERIC = 0, /* the build's baseline (x86-64 SSE2 on Debian) */
    LM_ISA_AVX2 = 1,    /* AVX2 + FMA (x86-64-v3) */
    LM_ISA_AVX512 = 2,  /* AVX-512 F/VL/BW/DQ (x86-64-v4) */
    LM_ISA_AMX = 3      /* AVX-512 plus AMX-BF16 tiles */
} lm_isa;

/* What this CPU and operating system offer (each 0 or 1). */
typedef struct lm_cpu_features {
    int x86;          /* built for x86-64 */
    int avx2_fma;     /* AVX2 and FMA, with the YMM state enabled by the OS */
    int avx512;       /* AVX-512 F, VL, BW, DQ, with the ZMM state enabled */
    int avx512_bf16;  /* vdpbf16ps */
    int amx_bf16;     /* AMX-TILE and AMX-BF16, with the tile state enabled in XCR0 */
    char vendor[13];  /* "GenuineIntel", "AuthenticAMD", ... ("" off x86) */
    char brand[49];   /* the processor's brand string ("" if unknown) */
} lm_cpu_features;

/* The features of this machine (computed once). */
const lm_cpu_features *lm_cpu_features_get(void);

/* Choose the level once: the best the CPU supports, or LM_ISA from the environment.
 * Returns LM_OK, or LM_ERR_UNSUPPORTED / LM_ERR_ARG with a one-line message in msg (size n)
 * when LM_ISA names a level the CPU lacks or is not a level name; the level is then the
 * best supported one. Safe to call more than once and from several threads. */
lm_status lm_isa_init(char *msg, int n);

/* The level every kernel call uses (calls lm_isa_init on first use). */
lm_isa lm_isa_active(void);

/* The best level the CPU supports (ignoring LM_ISA). */
lm_isa lm_isa_best(void);

/* 1 when the operating system lets this process use the AMX tile data (Linux: requested once
 * per process with arch_prctl(ARCH_REQ_XCOMP_PERM, XFEATURE_XTILEDATA), the first time this is
 * called); 0 when refused, or when the CPU has no AMX-BF16. The level stays amx when refused:
 * the bf16 product then runs AVX-512-BF16 (tensor/ops/gemm_bf16.h). */
int lm_amx_tile_granted(void);

/* "generic", "avx2", "avx512", "amx". */
const char *lm_isa_name(lm_isa isa);

/* One line saying which level is active and why (e.g. "avx512: the CPU has AVX-512 F/VL/BW/DQ;
 * no AMX tiles" or "avx2: forced by LM_ISA (the CPU supports avx512)"), into buf. */
void lm_isa_describe(char *buf, int n);

/* One line for users: which path a precision takes on this CPU, e.g. "bf16 (AMX tiles, fp32
 * sums)", "bf16 (AVX-512-BF16 products, fp32 sums)" or "bf16 (operands rounded to bf16, products
 * in fp32: this CPU has no AVX-512-BF16)"; "fp32" for LM_PRECISION_FP32 (tensor.h); defined
 * beside the bf16 product, tensor/ops/gemm_bf16.c. */
const char *lm_precision_describe(int precision);

#ifdef __cplusplus
}
#endif
#endif

/* isa.c — CPU feature detection and the process-wide kernel level (isa.h). */
#include "tensor/isa.h"
#include <pthread.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#if defined(__x86_64__) && defined(__linux__)
#include <sys/syscall.h>
#include <unistd.h>
#define LM_AMX_PRCTL 1
#else
#define LM_AMX_PRCTL 0
#endif

#if defined(__x86_64__) || defined(__i386__)
#include <cpuid.h>
#define LM_X86 1
#else
#define LM_X86 0
#endif

static lm_cpu_features feat;
static pthread_once_t feat_once = PTHREAD_ONCE_INIT;

#if LM_X86
/* XCR0: which register states the operating system saves (and so lets programs use). */
static unsigned long long xgetbv0(void)
{
    unsigned int lo, hi;
    __asm__ volatile("xgetbv" : "=a"(lo), "=d"(hi) : "c"(0));
    return ((unsigned long long)hi << 32) | lo;
}
#endif

static void detect(void)
{
    memset(&feat, 0, sizeof feat);
#if LM_X86
    feat.x86 = 1;
    unsigned int a, b, c, d;
    if (!__get_cpuid(0, &a, &b, &c, &d)) return;
    unsigned int maxleaf = a;
    memcpy(feat.vendor, &b, 4);
    memcpy(feat.vendor + 4, &d, 4);
    memcpy(feat.vendor + 8, &c, 4);
    feat.vendor[12] = 0;
    if (__get_cpuid(0x80000000u, &a, &b, &c, &d) && a >= 0x80000004u) {
        unsigned int r[12];
        for (unsigned int i = 0; i < 3; i++)
            __get_cpuid(0x80000002u + i, &r[4 * i], &r[4 * i + 1], &r[4 * i + 2], &r[4 * i + 3]);
        memcpy(feat.brand, r, 48);
        feat.brand[48] = 0;
        char *s = feat.brand; /* some CPUs pad the brand on the left */
        while (*s == ' ') s++;
        memmove(feat.brand, s, strlen(s) + 1);
    }
    __get_cpuid(1, &a, &b, &c, &d);
    int fma = (c >> 12) & 1, osxsave = (c >> 27) & 1, avx = (c >> 28) & 1;
    if (!osxsave || !avx || maxleaf < 7) return;
    unsigned long long xcr0 = xgetbv0();
    int ymm_os = (xcr0 & 0x6) == 0x6;              /* SSE + AVX state */
    int zmm_os = ymm_os && (xcr0 & 0xe0) == 0xe0;  /* opmask, ZMM0-15 upper, ZMM16-31 */
    int tile_os = (xcr0 & 0x60000) == 0x60000;     /* XTILECFG + XTILEDATA */
    unsigned int b7, c7, d7, a7;
    __cpuid_count(7, 0, a7, b7, c7, d7);
    unsigned int sub1_a = 0, t1, t2, t3;
    if (a7 >= 1) __cpuid_count(7, 1, sub1_a, t1, t2, t3);
    int avx2 = (b7 >> 5) & 1;
    int f = (b7 >> 16) & 1, dq = (b7 >> 17) & 1, bw = (b7 >> 30) & 1, vl = (b7 >> 31) & 1;
    feat.avx2_fma = ymm_os && avx2 && fma;
    feat.avx512 = feat.avx2_fma && zmm_os && f && dq && bw && vl;
    feat.avx512_bf16 = feat.avx512 && ((sub1_a >> 5) & 1);
    int amx_bf16 = (d7 >> 22) & 1, amx_tile = (d7 >> 24) & 1;
    feat.amx_bf16 = feat.avx512 && tile_os && amx_tile && amx_bf16;
#endif
}

const lm_cpu_features *lm_cpu_features_get(void)
{
    pthread_once(&feat_once, detect);
    return &feat;
}

static int amx_granted;
static pthread_once_t amx_once = PTHREAD_ONCE_INIT;

/* Linux keeps the tile data (8 KiB of state per thread) off until a process asks for it;
 * the permission then holds for every thread of the process, present and future. */
static void amx_request(void)
{
#if LM_AMX_PRCTL
    enum { ARCH_GET_XCOMP_PERM = 0x1022, ARCH_REQ_XCOMP_PERM = 0x1023, XFEATURE_XTILEDATA = 18 };
    if (!lm_cpu_features_get()->amx_bf16) return;
    if (syscall(SYS_arch_prctl, ARCH_REQ_XCOMP_PERM, XFEATURE_XTILEDATA) != 0) return;
    unsigned long perm = 0;
    if (syscall(SYS_arch_prctl, ARCH_GET_XCOMP_PERM, &perm) != 0) return;
    amx_granted = (perm >> XFEATURE_XTILEDATA) & 1;
#endif
}

int lm_amx_tile_granted(void)
{
    pthread_once(&amx_once, amx_request);
    return amx_granted;
}

lm_isa lm_isa_best(void)
{
    const lm_cpu_features *f = lm_cpu_features_get();
    return f->amx_bf16 ? LM_ISA_AMX : f->avx512 ? LM_ISA_AVX512 : f->avx2_fma ? LM_ISA_AVX2
                                                                                : LM_ISA_GENERIC;
}

const char *lm_isa_name(lm_isa isa)
{
    switch (isa) {
    case LM_ISA_GENERIC: return "generic";
    case LM_ISA_AVX2: return "avx2";
    case LM_ISA_AVX512: return "avx512";
    case LM_ISA_AMX: return "amx";
    }
    return "?";
}

static pthread_mutex_t init_mu = PTHREAD_MUTEX_INITIALIZER;
static int isa_level = -1;   /* chosen level, -1 before lm_isa_init */
static int isa_forced = 0;   /* LM_ISA set and honoured */
static lm_status isa_status; /* result of the first init */
static char isa_msg[160];

lm_status lm_isa_init(char *msg, int n)
{
    pthread_mutex_lock(&init_mu);
    if (isa_level < 0) {
        lm_isa best = lm_isa_best();
        int level = (int)best;
        const char *e = getenv("LM_ISA");
        isa_status = LM_OK;
        isa_msg[0] = 0;
        if (e && *e) {
            int want = -1;
            for (int i = LM_ISA_GENERIC; i <= LM_ISA_AMX; i++)
                if (!strcmp(e, lm_isa_name((lm_isa)i))) want = i;
            if (want < 0) {
                isa_status = LM_ERR_ARG;
                snprintf(isa_msg, sizeof isa_msg, "LM_ISA=%s: not a level (generic, avx2, "
                         "avx512, amx)", e);
            } else if (want > (int)best) {
                isa_status = LM_ERR_UNSUPPORTED;
                snprintf(isa_msg, sizeof isa_msg, "LM_ISA=%s: this CPU supports at most %s",
                         e, lm_isa_name(best));
            } else {
                level = want;
                isa_forced = 1;
            }
        }
        __atomic_store_n(&isa_level, level, __ATOMIC_RELEASE);
    }
    lm_status st = isa_status;
    if (msg && n > 0) snprintf(msg, (size_t)n, "%s", isa_msg);
    pthread_mutex_unlock(&init_mu);
    return st;
}

lm_isa lm_isa_active(void)
{
    int l = __atomic_load_n(&isa_level, __ATOMIC_ACQUIRE);
    if (l < 0) {
        lm_isa_init(NULL, 0);
        l = __atomic_load_n(&isa_level, __ATOMIC_ACQUIRE);
    }
    return (lm_isa)l;
}

void lm_isa_describe(char *buf, int n)
{
    const lm_cpu_features *f = lm_cpu_features_get();
    lm_isa a = lm_isa_active(), best = lm_isa_best();
    char why[200];
    if (!f->x86)
        snprintf(why, sizeof why, "not an x86-64 build: portable C kernels");
    else if (isa_forced)
        snprintf(why, sizeof why, "set by LM_ISA (the CPU supports %s)", lm_isa_name(best));
    else if (best == LM_ISA_AMX)
        snprintf(why, sizeof why, "the CPU has AMX-BF16 tiles and AVX-512; %s",
                 lm_amx_tile_granted() ? "tile state granted by the kernel"
                                       : "the kernel refuses the tile state (no tile kernels)");
    else if (best == LM_ISA_AVX512)
        snprintf(why, sizeof why, "the CPU has AVX-512 F/VL/BW/DQ%s; no AMX tiles",
                 f->avx512_bf16 ? " and AVX-512-BF16" : "");
    else if (best == LM_ISA_AVX2)
        snprintf(why, sizeof why, "the CPU has AVX2 + FMA; no AVX-512");
    else
        snprintf(why, sizeof why, "the CPU has no AVX2 + FMA (or the OS does not enable it)");
    snprintf(buf, (size_t)n, "%s: %s", lm_isa_name(a), why);
}

/* test_amx_refused.c — a process whose operating system refuses the AMX tile state (a container
 * whose seccomp profile denies arch_prctl(ARCH_REQ_XCOMP_PERM), an old kernel) must not run a
 * tile instruction: without the permission the first one kills the process (SIGILL). Here the
 * refusal is real: the test installs a seccomp filter that makes that request fail with EPERM,
 * before anything asks for the tile state, then checks
 *   - lm_amx_tile_granted() is 0 and lm_isa_describe says the kernel refuses the tile state
 *     (on a CPU with AMX);
 *   - the process's bf16 kernel is AVX-512-BF16 where the CPU has it, else the fp32 twin, and
 *     lm_bf16_kernel_runs(AMX) is 0;
 *   - bf16 products with the process's kernel and with the AMX layout named (lm_*_for, which
 *     must then multiply by the fp32 twin) run and equal the fp32 twin's sums within fp32
 *     summation error.
 * On a CPU without AMX (or not x86-64 Linux) the refusal cannot be reached; the kernel choice
 * and the products are still checked, and the test says so. */
#include "tests/check.h"
#include "tensor/isa.h"
#include "tensor/ops/gemm_bf16.h"
#include <errno.h>
#include <math.h>
#include <stdlib.h>
#include <string.h>
#if defined(__linux__) && defined(__x86_64__)
#include <linux/audit.h>
#include <linux/filter.h>
#include <linux/seccomp.h>
#include <stddef.h>
#include <sys/prctl.h>
#include <sys/syscall.h>
#include <unistd.h>
#define LM_TEST_SECCOMP 1
#else
#define LM_TEST_SECCOMP 0
#endif

/* arch_prctl(ARCH_REQ_XCOMP_PERM, ...) fails with EPERM; every other call is allowed. */
static int deny_tile_request(void)
{
#if LM_TEST_SECCOMP
    struct sock_filter f[] = {
        BPF_STMT(BPF_LD | BPF_W | BPF_ABS, offsetof(struct seccomp_data, arch)),
        BPF_JUMP(BPF_JMP | BPF_JEQ | BPF_K, AUDIT_ARCH_X86_64, 1, 0),
        BPF_STMT(BPF_RET | BPF_K, SECCOMP_RET_ALLOW),
        BPF_STMT(BPF_LD | BPF_W | BPF_ABS, offsetof(struct seccomp_data, nr)),
        BPF_JUMP(BPF_JMP | BPF_JEQ | BPF_K, SYS_arch_prctl, 1, 0),
        BPF_STMT(BPF_RET | BPF_K, SECCOMP_RET_ALLOW),
        BPF_STMT(BPF_LD | BPF_W | BPF_ABS, offsetof(struct seccomp_data, args[0])),
        BPF_JUMP(BPF_JMP | BPF_JEQ | BPF_K, 0x1023 /* ARCH_REQ_XCOMP_PERM */, 0, 1),
        BPF_STMT(BPF_RET | BPF_K, SECCOMP_RET_ERRNO | (EPERM & SECCOMP_RET_DATA)),
        BPF_STMT(BPF_RET | BPF_K, SECCOMP_RET_ALLOW),
    };
    struct sock_fprog prog = {(unsigned short)(sizeof f / sizeof f[0]), f};
    if (prctl(PR_SET_NO_NEW_PRIVS, 1, 0, 0, 0) != 0) return -1;
    if (prctl(PR_SET_SECCOMP, SECCOMP_MODE_FILTER, &prog) != 0) return -1;
    /* the filter holds: the request itself now fails */
    if (syscall(SYS_arch_prctl, 0x1023, 18) == 0 || errno != EPERM) return -1;
    return 0;
#else
    return -1;
#endif
}

/* C = A B with kernel k's layout and lm_gemm_bf16_panel_for, against the fp32 twin from the
 * same bf16 operands: within fp32 summation error (tests/test_gemm_bf16.c derives the bound). */
static void check_product(lm_bf16_kernel k, int M, int n, int K, lm_rng *r)
{
    float *A = malloc(sizeof(float) * (size_t)M * K), *B = malloc(sizeof(float) * (size_t)K * n);
    float *C = calloc((size_t)M * n, sizeof(float));
    lm_bf16 *Ap = malloc(sizeof(lm_bf16) * lm_bf16_pack_a_size_for(k, M, K));
    lm_bf16 *Bp = malloc(sizeof(lm_bf16) * lm_bf16_pack_b_size_for(k, K, n));
    for (long i = 0; i < (long)M * K; i++) A[i] = lm_rng_uniform(r) * 2 - 1;
    for (long i = 0; i < (long)K * n; i++) B[i] = lm_rng_uniform(r) * 2 - 1;
    lm_bf16_pack_a_for(k, M, K, A, K, Ap);
    lm_bf16_pack_b_for(k, K, n, B, n, Bp);
    lm_gemm_bf16_panel_for(k, M, n, K, Ap, Bp, NULL, 0, C, n);
    double worst = 0;
    int bad = 0;
    for (int i = 0; i < M; i++)
        for (int j = 0; j < n; j++) {
            double s = 0, mag = 0;
            for (int p = 0; p < K; p++) {
                double t = (double)lm_bf16_to_f32(lm_bf16_round(A[(long)i * K + p])) *
                           lm_bf16_to_f32(lm_bf16_round(B[(long)p * n + j]));
                s += t, mag += fabs(t);
            }
            double err = fabs(C[(long)i * n + j] - s), tol = 1.01 * (K + 1) * ldexp(mag, -24);
            if (err > tol) bad++;
            if (err > worst) worst = err;
        }
    CHECK_MSG(bad == 0, "%s layout, %d x %d x %d: %d of %d values off (worst %.3g)",
              lm_bf16_kernel_name(k), M, n, K, bad, M * n, worst);
    free(A), free(B), free(C), free(Ap), free(Bp);
}

static void test_refused(void)
{
    const lm_cpu_features *f = lm_cpu_features_get();
    int denied = deny_tile_request() == 0;
    if (!denied)
        printf("     note: no seccomp filter here (not x86-64 Linux, or refused): the tile "
               "state is not denied\n");
    if (denied && f->amx_bf16) {
        CHECK_MSG(lm_amx_tile_granted() == 0, "the tile state was granted through the filter");
        char d[300];
        lm_isa_describe(d, sizeof d);
        printf("     %s\n", d);
        if (lm_isa_active() == LM_ISA_AMX)
            CHECK_MSG(strstr(d, "refuses the tile state") != NULL, "lm_isa_describe: %s", d);
    } else if (denied) {
        printf("     note: this CPU has no AMX tiles: the refusal path is not reachable; the "
               "kernel choice and products are checked\n");
    }
    lm_bf16_kernel k = lm_bf16_kernel_active();
    printf("     process kernel: %s\n", lm_bf16_kernel_name(k));
    if (denied || !f->amx_bf16) {
        CHECK_MSG(k != LM_BF16_AMX, "the tile kernel was chosen without the tile state");
        CHECK(lm_bf16_kernel_runs(LM_BF16_AMX) == 0);
        if (f->avx512_bf16 && lm_isa_active() >= LM_ISA_AVX512)
            CHECK_MSG(k == LM_BF16_DPBF16, "expected AVX-512-BF16, got %s",
                      lm_bf16_kernel_name(k));
    }
    lm_rng r;
    lm_rng_seed(&r, 7);
    const int shapes[][3] = {{32, 64, 64}, {17, 35, 33}, {96, 130, 288}};
    for (int s = 0; s < 3; s++) {
        check_product(k, shapes[s][0], shapes[s][1], shapes[s][2], &r);
        check_product(LM_BF16_AMX, shapes[s][0], shapes[s][1], shapes[s][2], &r);
    }
}

int main(void)
{
    RUN(test_refused);
    return check_summary();
}

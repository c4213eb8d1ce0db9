/* test_op_table.c — the one kernel list (tensor/op_list.h) against its two tables: every kernel
 * of LM_OP_LIST is in the CPU kernel set (tensor/op_table.c) and in the OpenCL launcher table
 * (kernels-opencl/cl_backend.c) under its name, every CPU kernel has an OpenCL launcher, every
 * launcher a CPU twin, and no name appears twice. Needs no OpenCL device (the tables are data). */
#include "tests/check.h"
#include "tensor/op_list.h"
#include "kernels-opencl/cl_impl.h"

/* Walk the X-macro list: each name, looked up by name on both sides, is that name's kernel
 * object and launcher function. */
static void test_list_has_both_sides(void)
{
    int n = 0;
#define CHECK_BOTH(name)                                                                      \
    do {                                                                                      \
        const lm_kernel *k = lm_kernel_find(#name);                                           \
        const lm_cl_entry *e = lm_cl_find_launcher(#name);                                    \
        CHECK_MSG(k == &lm_kernel_##name && k->cpu, "kernel '%s': no CPU kernel", #name);     \
        CHECK_MSG(e && e->fn == lm_cl_launch_##name, "kernel '%s': no OpenCL launcher", #name); \
        n++;                                                                                  \
    } while (0);
    LM_OP_LIST(CHECK_BOTH)
#undef CHECK_BOTH
    CHECK(n == LM_OP_COUNT);
}

/* Every kernel of the CPU set has a launcher of the same name, and every launcher a CPU twin. */
static void test_tables_cover_each_other(void)
{
    for (int i = 0; i < LM_OP_COUNT; i++) {
        const lm_kernel *k = lm_kernel_at(i);
        const lm_cl_entry *e = lm_cl_launcher_at(i);
        CHECK_MSG(k && k->name && k->cpu, "CPU kernel %d missing", i);
        CHECK_MSG(e && e->name && e->fn, "OpenCL launcher %d missing", i);
        if (!k || !e || !k->name || !e->name) continue;
        CHECK_MSG(lm_cl_find_launcher(k->name) != NULL, "CPU kernel '%s' has no OpenCL launcher",
                  k->name);
        CHECK_MSG(lm_kernel_find(e->name) != NULL, "OpenCL launcher '%s' has no CPU twin",
                  e->name);
        CHECK_MSG(!strcmp(k->name, e->name), "row %d: CPU '%s', OpenCL '%s'", i, k->name,
                  e->name);
    }
    CHECK(lm_kernel_at(-1) == NULL && lm_kernel_at(LM_OP_COUNT) == NULL);
    CHECK(lm_cl_launcher_at(LM_OP_COUNT) == NULL);
    CHECK(lm_kernel_find("no_such_kernel") == NULL);
    CHECK(lm_cl_find_launcher("no_such_kernel") == NULL);
}

/* Dispatch is by name: two kernels of one name would run each other's launcher. */
static void test_names_unique(void)
{
    for (int i = 0; i < LM_OP_COUNT; i++)
        for (int j = i + 1; j < LM_OP_COUNT; j++) {
            const lm_kernel *a = lm_kernel_at(i), *b = lm_kernel_at(j);
            if (a && b)
                CHECK_MSG(strcmp(a->name, b->name) != 0, "kernel name '%s' listed twice",
                          a->name);
        }
}

int main(void)
{
    RUN(test_list_has_both_sides);
    RUN(test_tables_cover_each_other);
    RUN(test_names_unique);
    return check_summary();
}

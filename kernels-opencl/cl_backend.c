/* cl_backend.c — OpenCL backend lifetime: device choice, the program (every embedded .cl file)
 * built once with its kernels cached by name, the launcher table, and dispatch by kernel name.
 * Not here: device memory (cl_memory.c), argument helpers (cl_launch.c), the launchers
 * themselves (cl_ops_*.c); the recorded transfers and parameter swaps are the backend-blind
 * tensor/transfer.c and tensor/mirror.c (tensor/device.h). */
#include "kernels-opencl/cl_backend.h"
#include "kernels-opencl/cl_impl.h"
#include "tensor/op_params.h"
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

/* The launcher table, generated from LM_OP_LIST (tensor/op_list.h): row i is the launcher of
 * the list's kernel i, under the same name as its CPU twin lm_kernel_<name>. */
#define LM_CL_ENTRY(name) {#name, lm_cl_launch_##name},
static const lm_cl_entry launchers[LM_OP_COUNT] = {LM_OP_LIST(LM_CL_ENTRY)};
#undef LM_CL_ENTRY

const lm_cl_entry *lm_cl_launcher_at(int id)
{
    return id >= 0 && id < LM_OP_COUNT ? &launchers[id] : NULL;
}

const lm_cl_entry *lm_cl_find_launcher(const char *name)
{
    for (int i = 0; name && i < LM_OP_COUNT; i++)
        if (launchers[i].name && !strcmp(launchers[i].name, name)) return &launchers[i];
    return NULL;
}

int lm_cl_platform_count(void)
{
    cl_uint n = 0;
    if (clGetPlatformIDs(0, NULL, &n) != CL_SUCCESS) return 0;
    return (int)n;
}

const char *lm_cl_backend_device_name(const lm_backend *b)
{
    return b && b->device == LM_DEVICE_OPENCL ? ((const lm_cl *)b->impl)->device_name : "";
}

/* ---- device choice ------------------------------------------------------------------------ */
#define MAX_DEVICES 64
typedef struct dev_list {
    cl_platform_id plat[MAX_DEVICES];
    cl_device_id dev[MAX_DEVICES];
    int n;
} dev_list;

static lm_status list_devices(dev_list *l, lm_err *e)
{
    cl_platform_id plats[16];
    cl_uint np = 0;
    cl_int err = clGetPlatformIDs(16, plats, &np);
    l->n = 0;
    if (err != CL_SUCCESS || np == 0)
        return lm_err_set(e, LM_ERR_UNSUPPORTED, "opencl: no OpenCL platform found (%s)",
                          lm_cl_error_str(err));
    for (cl_uint p = 0; p < np && p < 16; p++) {
        cl_device_id ds[MAX_DEVICES];
        cl_uint nd = 0;
        if (clGetDeviceIDs(plats[p], CL_DEVICE_TYPE_ALL, MAX_DEVICES, ds, &nd) != CL_SUCCESS)
            continue;
        for (cl_uint d = 0; d < nd && l->n < MAX_DEVICES; d++) {
            l->plat[l->n] = plats[p];
            l->dev[l->n++] = ds[d];
        }
    }
    if (l->n == 0) return lm_err_set(e, LM_ERR_BACKEND, "opencl: platforms without devices");
    return LM_OK;
}

/* LM_OPENCL_DEVICE index, else the first GPU, else device 0. */
static int choose_device(const dev_list *l, lm_err *e)
{
    const char *env = getenv("LM_OPENCL_DEVICE");
    if (env && *env) {
        char *end = NULL;
        long i = strtol(env, &end, 10);
        if (*end || i < 0 || i >= l->n) {
            lm_err_set(e, LM_ERR_ARG, "opencl: LM_OPENCL_DEVICE=%s is not a device index "
                       "(0..%d)", env, l->n - 1);
            return -1;
        }
        return (int)i;
    }
    for (int i = 0; i < l->n; i++) {
        cl_device_type t = 0;
        clGetDeviceInfo(l->dev[i], CL_DEVICE_TYPE, sizeof t, &t, NULL);
        if (t & CL_DEVICE_TYPE_GPU) return i;
    }
    return 0;
}

/* ---- program and kernels ------------------------------------------------------------------ */
static void print_build_log(lm_cl *b, cl_program prog, lm_err *e)
{
    size_t len = 0;
    clGetProgramBuildInfo(prog, b->device, CL_PROGRAM_BUILD_LOG, 0, NULL, &len);
    char *log = malloc(len + 1);
    if (!log) return;
    log[0] = 0;
    clGetProgramBuildInfo(prog, b->device, CL_PROGRAM_BUILD_LOG, len, log, NULL);
    log[len] = 0;
    fprintf(stderr, "opencl: program build failed on %s; build log:\n%s\n", b->device_name, log);
    lm_err_set(e, LM_ERR_BACKEND, "opencl: program build failed on %s: %.400s", b->device_name,
               log);
    free(log);
}

static int cmp_kernel(const void *a, const void *b)
{
    return strcmp(((const lm_cl_kernel *)a)->name, ((const lm_cl_kernel *)b)->name);
}

/* The build options: the OpenCL C version, then every size and enum value the .cl sources
 * name, as -D NAME=value from their C definitions (cl_impl.h, LM_OP_ENUMS of op_params.h). */
static void build_options(char *buf, size_t n)
{
    size_t len = (size_t)snprintf(buf, n, "-cl-std=CL1.2 -DWG=%d -DCHUNK=%d -DLM_CL_SUM_PLAIN=%d",
                                  LM_CL_WG, LM_CL_CHUNK, (int)LM_CL_SUM_PLAIN);
#define LM_DEFINE_OPTION(name)                                                                \
    if (len < n) len += (size_t)snprintf(buf + len, n - len, " -D" #name "=%d", (int)(name));
    LM_OP_ENUMS(LM_DEFINE_OPTION)
#undef LM_DEFINE_OPTION
}

/* Compile sources into *prog for the backend's device; prints the build log on failure. */
static lm_status compile(lm_cl *b, int n, const char *const *src, cl_program *prog, lm_err *e)
{
    cl_int err;
    char options[1024];
    build_options(options, sizeof options);
    *prog = clCreateProgramWithSource(b->context, (cl_uint)n, (const char **)src, NULL, &err);
    if (err != CL_SUCCESS)
        return lm_err_set(e, LM_ERR_BACKEND, "opencl: clCreateProgramWithSource: %s",
                          lm_cl_error_str(err));
    err = clBuildProgram(*prog, 1, &b->device, options, NULL, NULL);
    if (err != CL_SUCCESS) {
        print_build_log(b, *prog, e);
        return lm_err_set(e, LM_ERR_BACKEND, "opencl: clBuildProgram: %s", lm_cl_error_str(err));
    }
    return LM_OK;
}

lm_status lm_cl_compile_check(lm_backend *bb, const char *src, lm_err *e)
{
    lm_cl *b = bb->impl;
    cl_program prog = NULL;
    lm_status s = compile(b, 1, &src, &prog, e);
    if (prog) clReleaseProgram(prog);
    return s;
}

static lm_status build_program(lm_cl *b, lm_err *e)
{
    lm_status s = compile(b, lm_cl_nsources, lm_cl_sources, &b->program, e);
    if (s != LM_OK) return s;
    cl_uint nk = 0;
    clCreateKernelsInProgram(b->program, 0, NULL, &nk);
    cl_kernel *ks = calloc(nk ? nk : 1, sizeof *ks);
    b->kernels = calloc(nk ? nk : 1, sizeof *b->kernels);
    if (!ks || !b->kernels) {
        free(ks);
        return lm_err_set(e, LM_ERR_NOMEM, "opencl: out of memory");
    }
    cl_int err = clCreateKernelsInProgram(b->program, nk, ks, NULL);
    for (cl_uint i = 0; err == CL_SUCCESS && i < nk; i++) {
        b->kernels[i].k = ks[i];
        clGetKernelInfo(ks[i], CL_KERNEL_FUNCTION_NAME, sizeof b->kernels[i].name,
                        b->kernels[i].name, NULL);
        b->nkernels++;
    }
    free(ks);
    if (err != CL_SUCCESS)
        return lm_err_set(e, LM_ERR_BACKEND, "opencl: clCreateKernelsInProgram: %s",
                          lm_cl_error_str(err));
    qsort(b->kernels, (size_t)b->nkernels, sizeof *b->kernels, cmp_kernel);
    return LM_OK;
}

lm_cl_kernel *lm_cl_find_kernel(lm_cl *b, const char *name)
{
    lm_cl_kernel key;
    snprintf(key.name, sizeof key.name, "%s", name);
    return bsearch(&key, b->kernels, (size_t)b->nkernels, sizeof key, cmp_kernel);
}

/* ---- launcher table ----------------------------------------------------------------------- */
static int cmp_entry(const void *a, const void *b)
{
    return strcmp((*(const lm_cl_entry *const *)a)->name, (*(const lm_cl_entry *const *)b)->name);
}

/* The launcher table sorted by name; a name listed twice is a programming error reported at
 * creation. */
static lm_status build_table(lm_cl *b, lm_err *e)
{
    int n = LM_OP_COUNT;
    b->entries = malloc((size_t)n * sizeof *b->entries);
    if (!b->entries) return lm_err_set(e, LM_ERR_NOMEM, "opencl: out of memory");
    for (int i = 0; i < n; i++) b->entries[b->nentries++] = &launchers[i];
    qsort(b->entries, (size_t)n, sizeof *b->entries, cmp_entry);
    for (int i = 1; i < n; i++)
        if (!strcmp(b->entries[i]->name, b->entries[i - 1]->name))
            return lm_err_set(e, LM_ERR_BACKEND, "opencl: launcher '%s' registered twice",
                              b->entries[i]->name);
    return LM_OK;
}

static const lm_cl_entry *find_entry(const lm_cl *b, const char *name)
{
    lm_cl_entry key = {name, NULL};
    const lm_cl_entry *kp = &key;
    const lm_cl_entry *const *r =
        bsearch(&kp, b->entries, (size_t)b->nentries, sizeof kp, cmp_entry);
    return r ? *r : NULL;
}

/* ---- dispatch ----------------------------------------------------------------------------- */
/* Largest element index a device tensor touches must fit the kernels' int indexing. */
static int fits_int(const lm_tensor *t)
{
    long long last = (long long)t->dev_off;
    for (int i = 0; i < t->ndim; i++) last += (long long)(t->shape[i] - 1) * t->stride[i];
    return last < 2147483647LL && lm_tensor_numel(t) < 2147483647L;
}

int lm_cl_launch(lm_cl *b, lm_ctx *c, const char *name, lm_tensor *const *t, int nt,
                 const void *params)
{
    if (c->status) return c->status;
    const lm_cl_entry *e = find_entry(b, name);
    if (!e)
        return lm_ctx_fail(c, LM_ERR_UNSUPPORTED, "opencl: kernel '%s' has no OpenCL "
                           "implementation yet", name);
    for (int i = 0; i < nt; i++)
        if (t[i] && !fits_int(t[i]))
            return lm_ctx_fail(c, LM_ERR_UNSUPPORTED, "opencl: kernel '%s': tensor %d is too "
                               "large for 32-bit indexing", name, i);
    return e->fn(b, c, t, nt, params);
}

/* Host-only kernels run on the CPU; device-only kernels on the device; a mix is an error. */
static int cl_run(lm_backend *bb, lm_ctx *c, const lm_kernel *k, lm_tensor *const *t, int nt,
                  const void *params)
{
    lm_cl *b = bb->impl;
    int ndev = 0, host = -1;
    for (int i = 0; i < nt; i++) {
        if (!t[i]) continue;
        if (t[i]->device == LM_DEVICE_OPENCL) ndev++;
        else if (host < 0) host = i;
    }
    if (ndev == 0) return k->cpu(c, t, nt, params);
    if (host >= 0)
        return lm_ctx_fail(c, LM_ERR_BACKEND, "opencl: kernel '%s': tensor %d is on the host "
                           "while others are on the device (use lm_tensor_to_device)", k->name,
                           host);
    return lm_cl_launch(b, c, k->name, t, nt, params);
}

/* ---- create / free ------------------------------------------------------------------------ */
static lm_status open_device(lm_cl *b, const dev_list *l, int i, lm_err *e)
{
    cl_int err;
    b->platform = l->plat[i];
    b->device = l->dev[i];
    clGetPlatformInfo(b->platform, CL_PLATFORM_NAME, sizeof b->platform_name, b->platform_name,
                      NULL);
    clGetDeviceInfo(b->device, CL_DEVICE_NAME, sizeof b->device_name, b->device_name, NULL);
    clGetDeviceInfo(b->device, CL_DEVICE_MAX_WORK_GROUP_SIZE, sizeof b->max_wg, &b->max_wg,
                    NULL);
    clGetDeviceInfo(b->device, CL_DEVICE_LOCAL_MEM_SIZE, sizeof b->local_mem, &b->local_mem,
                    NULL);
    cl_context_properties props[] = {CL_CONTEXT_PLATFORM, (cl_context_properties)b->platform, 0};
    b->context = clCreateContext(props, 1, &b->device, NULL, NULL, &err);
    if (err != CL_SUCCESS)
        return lm_err_set(e, LM_ERR_BACKEND, "opencl: clCreateContext on %s: %s",
                          b->device_name, lm_cl_error_str(err));
    b->queue = clCreateCommandQueue(b->context, b->device, 0, &err);
    if (err != CL_SUCCESS)
        return lm_err_set(e, LM_ERR_BACKEND, "opencl: clCreateCommandQueue on %s: %s",
                          b->device_name, lm_cl_error_str(err));
    return LM_OK;
}

lm_backend *lm_cl_backend_create(lm_err *e)
{
    dev_list l;
    if (list_devices(&l, e) != LM_OK) return NULL;
    int i = choose_device(&l, e);
    if (i < 0) return NULL;
    lm_cl *b = calloc(1, sizeof *b);
    if (!b) {
        lm_err_set(e, LM_ERR_NOMEM, "opencl: out of memory");
        return NULL;
    }
    b->base.name = "opencl";
    b->base.device = LM_DEVICE_OPENCL;
    b->base.run = cl_run;
    b->base.impl = b;
    b->base.close = lm_cl_backend_free;
    b->base.device_name = b->device_name;
    b->conv_scratch = 1L << 22;
    const char *cs = getenv("LM_OPENCL_CONV_SCRATCH");
    if (cs && atol(cs) > 0) b->conv_scratch = atol(cs);
    const char *ci = getenv("LM_OPENCL_CONV_IM2COL");
    b->conv_im2col = ci && *ci && *ci != '0';
    lm_cl_memory_install(&b->base);
    if (open_device(b, &l, i, e) != LM_OK || build_program(b, e) != LM_OK ||
        build_table(b, e) != LM_OK) {
        lm_cl_backend_free(&b->base);
        return NULL;
    }
    return &b->base;
}

void lm_cl_backend_free(lm_backend *bb)
{
    if (!bb) return;
    lm_cl *b = bb->impl;
    if (b->queue) clFinish(b->queue);
    for (int i = 0; i < b->nkernels; i++) clReleaseKernel(b->kernels[i].k);
    if (b->program) clReleaseProgram(b->program);
    if (b->queue) clReleaseCommandQueue(b->queue);
    if (b->context) clReleaseContext(b->context);
    free(b->kernels);
    free(b->entries);
    free(b);
}

void lm_cl_backend_finish(lm_backend *bb)
{
    if (bb && bb->device == LM_DEVICE_OPENCL) clFinish(((lm_cl *)bb->impl)->queue);
}

/* The backend registers itself as "opencl" (lm_backend_open, tensor/device.h) when the program
 * starts; kernels-opencl/opencl.cmake makes every program that links the library link this
 * file. */
__attribute__((constructor)) static void register_opencl(void)
{
    lm_backend_register("opencl", lm_cl_backend_create);
}

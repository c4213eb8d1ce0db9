/* replay_main.c — runs a fuzz harness on files instead of under libFuzzer: the CTest form of
 * every harness (fuzz_<name>_replay CORPUS_DIR REGRESS_DIR ...), built by the normal gcc build
 * in Release and with ASan/UBSan. Each file (a directory: each regular file in it, sorted) is
 * fed once to LLVMFuzzerTestOneInput; a crash, a sanitizer report or a harness check fails the
 * test. Like libFuzzer's -malloc_limit_mb, a single allocation over 1 GiB is fatal: a tiny
 * hostile file must not make a reader (or a library under it) ask for a gigabyte. Without
 * ASan this is a malloc/calloc/realloc/memalign interposer over glibc's; with ASan,
 * max_allocation_size_mb.
 * What it is not: a fuzzer (no mutation, no coverage). */
#define _GNU_SOURCE
#include <dirent.h>
#include <errno.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/stat.h>
#include <unistd.h>

int LLVMFuzzerTestOneInput(const uint8_t *data, size_t size);

#define REPLAY_MALLOC_LIMIT ((size_t)1 << 30)
#define REPLAY_MAX_INPUT (64u << 20)

#if defined(__SANITIZE_ADDRESS__)
#define REPLAY_ASAN 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define REPLAY_ASAN 1
#endif
#endif

#ifdef REPLAY_ASAN
const char *__asan_default_options(void);
const char *__asan_default_options(void) { return "max_allocation_size_mb=1024"; }
#else
extern void *__libc_malloc(size_t n);
extern void *__libc_calloc(size_t a, size_t b);
extern void *__libc_realloc(void *p, size_t n);
extern void *__libc_memalign(size_t align, size_t n);

static void over_limit(const char *fn, size_t n)
{
    char msg[160];
    int k = snprintf(msg, sizeof msg, "replay: %s(%zu): over the %zu-byte allocation limit\n",
                     fn, n, REPLAY_MALLOC_LIMIT);
    if (write(STDERR_FILENO, msg, (size_t)k) < 0) abort();
    abort();
}

void *malloc(size_t n)
{
    if (n > REPLAY_MALLOC_LIMIT) over_limit("malloc", n);
    return __libc_malloc(n);
}

void *calloc(size_t a, size_t b)
{
    if (b && a > REPLAY_MALLOC_LIMIT / b) over_limit("calloc", a * b);
    return __libc_calloc(a, b);
}

void *realloc(void *p, size_t n)
{
    if (n > REPLAY_MALLOC_LIMIT) over_limit("realloc", n);
    return __libc_realloc(p, n);
}

void *memalign(size_t align, size_t n)
{
    if (n > REPLAY_MALLOC_LIMIT) over_limit("memalign", n);
    return __libc_memalign(align, n);
}

void *aligned_alloc(size_t align, size_t n) { return memalign(align, n); }

int posix_memalign(void **out, size_t align, size_t n)
{
    if (n > REPLAY_MALLOC_LIMIT) over_limit("posix_memalign", n);
    void *p = __libc_memalign(align, n);
    if (!p) return ENOMEM;
    *out = p;
    return 0;
}
#endif

static int replay_file(const char *path)
{
    FILE *f = fopen(path, "rb");
    if (!f) {
        perror(path);
        return -1;
    }
    uint8_t *buf = malloc(REPLAY_MAX_INPUT);
    size_t n = buf ? fread(buf, 1, REPLAY_MAX_INPUT, f) : 0;
    fclose(f);
    if (!buf) return -1;
    uint8_t *copy = malloc(n ? n : 1); /* exactly n bytes, so ASan sees overreads */
    memcpy(copy, buf, n);
    free(buf);
    fprintf(stderr, "replay: %s (%zu bytes)\n", path, n);
    LLVMFuzzerTestOneInput(copy, n);
    free(copy);
    return 0;
}

static int cmp_str(const void *a, const void *b)
{
    return strcmp(*(char *const *)a, *(char *const *)b);
}

/* Every regular file of dir, sorted by name. Returns the count replayed or -1. */
static int replay_dir(const char *dir)
{
    DIR *d = opendir(dir);
    if (!d) {
        perror(dir);
        return -1;
    }
    char **names = NULL;
    int n = 0, cap = 0, done = 0;
    struct dirent *de;
    while ((de = readdir(d)) != NULL) {
        if (de->d_name[0] == '.') continue;
        if (n == cap) names = realloc(names, sizeof *names * (size_t)(cap = cap ? 2 * cap : 64));
        names[n++] = strdup(de->d_name);
    }
    closedir(d);
    qsort(names, (size_t)n, sizeof *names, cmp_str);
    for (int i = 0; i < n; i++) {
        char p[4096];
        struct stat st;
        snprintf(p, sizeof p, "%s/%s", dir, names[i]);
        if (stat(p, &st) == 0 && S_ISREG(st.st_mode) && replay_file(p) == 0) done++;
        free(names[i]);
    }
    free(names);
    return done;
}

int main(int argc, char **argv)
{
    int total = 0;
    for (int i = 1; i < argc; i++) {
        struct stat st;
        int k = stat(argv[i], &st) == 0 && S_ISDIR(st.st_mode) ? replay_dir(argv[i])
                                                                 : replay_file(argv[i]) + 1;
        if (k < 0) return 1;
        total += k;
    }
    printf("replayed %d inputs\n", total);
    return total > 0 ? 0 : 1;
}

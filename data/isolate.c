/* isolate.c — a library call in a child process (see isolate.h).
 * What it is: fork, then exec of the entry's helper beside the running program or beside the
 * shared library holding this code, or failing that of /proc/self/exe, with the entry in the
 * environment (LM_ISOLATE_ENTRY, _FD, _MEM, _ARG in hex); between the two the child makes only
 * system calls (no allocation, no lock: any lock may be held by a thread that no longer
 * exists). The new image's constructor (lm_isolate_serve) sets the limits that need a look at
 * its own address space, default fault handlers (so a fault ends the child, whatever handlers
 * a sanitizer or fuzzer installed), and runs the entry. The parent bounds each read of the
 * reply by the wall clock (a child that never answers is killed) and turns the child's end into
 * a status and a message.
 * What it is not: a general process API (no stdin/stdout plumbing). */
#define _GNU_SOURCE
#include "data/isolate.h"
#include <dlfcn.h>
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdint.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

extern char **environ;

#if defined(__SANITIZE_ADDRESS__)
#define LM_ISOLATE_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define LM_ISOLATE_SANITIZED 1
#endif
#endif

#define ENV_ENTRY "LM_ISOLATE_ENTRY="
#define ENV_FD "LM_ISOLATE_FD="
#define ENV_MEM "LM_ISOLATE_MEM="
#define ENV_ARG "LM_ISOLATE_ARG="
#define EXIT_BAD_START 97 /* the exec'd child could not read what it was given */

/* The wall-clock time the parent waits for each piece of the reply: generous, for loaded
 * machines; the CPU limit ends a busy child long before. */
#define WALL_SECONDS_PER_CPU_SECOND 4
#define WALL_SECONDS_MIN 60

static size_t vm_bytes(void)
{
    unsigned long pages = 0;
    FILE *f = fopen("/proc/self/statm", "r");
    if (f) {
        if (fscanf(f, "%lu", &pages) != 1) pages = 0;
        fclose(f);
    }
    return (size_t)pages * (size_t)sysconf(_SC_PAGESIZE);
}

/* Fault signals to their default action (a fault ends the child). */
static void default_faults(void)
{
    const int faults[] = {SIGSEGV, SIGBUS, SIGILL, SIGFPE, SIGABRT, SIGPIPE, SIGXCPU};
    for (size_t i = 0; i < sizeof faults / sizeof faults[0]; i++) signal(faults[i], SIG_DFL);
}

static void limit_as(size_t bytes)
{
    if (bytes == 0) return;
    struct rlimit r;
    r.rlim_cur = r.rlim_max = (rlim_t)bytes;
    setrlimit(RLIMIT_AS, &r);
}

/* The forked child, before exec: system calls only. */
static void child_prepare(int fd, const lm_isolate_limits *lim)
{
    sigset_t none;
    sigemptyset(&none);
    sigprocmask(SIG_SETMASK, &none, NULL); /* the forking thread's mask is inherited */
    fcntl(fd, F_SETFD, 0);                 /* the reply pipe survives exec */
    if (lim->cpu_seconds > 0) {
        struct rlimit r;
        r.rlim_cur = (rlim_t)lim->cpu_seconds;
        r.rlim_max = (rlim_t)lim->cpu_seconds + 2;
        setrlimit(RLIMIT_CPU, &r);
    }
#ifndef LM_ISOLATE_SANITIZED
    /* the libraries' own diagnostics are not ours to print (a sanitizer's report is kept) */
    int null = open("/dev/null", O_WRONLY);
    if (null >= 0) {
        dup2(null, STDERR_FILENO);
        dup2(null, STDOUT_FILENO);
        close(null);
    }
#endif
}

/* The child's environment: the caller's without LM_ISOLATE_*, then the entry's four. NULL if
 * out of memory. */
static char **child_env(const lm_isolate_entry *en, int fd, size_t mem, const void *arg,
                        size_t n, char **own)
{
    size_t k = 0;
    for (char **v = environ; v && *v; v++) k++;
    char **env = malloc(sizeof(char *) * (k + 5));
    size_t len = strlen(ENV_ENTRY) + strlen(en->name) + 1;
    char *s = malloc(len + 128 + strlen(ENV_ARG) + 2 * n + 1);
    if (!env || !s) {
        free(env);
        free(s);
        return NULL;
    }
    size_t m = 0;
    for (char **v = environ; v && *v; v++)
        if (strncmp(*v, "LM_ISOLATE_", 11) != 0) env[m++] = *v;
    char *w = s;
    env[m++] = w, w += sprintf(w, "%s%s", ENV_ENTRY, en->name) + 1;
    env[m++] = w, w += sprintf(w, "%s%d", ENV_FD, fd) + 1;
    env[m++] = w, w += sprintf(w, "%s%zu", ENV_MEM, mem) + 1;
    env[m++] = w, w += sprintf(w, "%s", ENV_ARG);
    static const char hex[] = "0123456789abcdef";
    const unsigned char *a = arg;
    for (size_t i = 0; i < n; i++) *w++ = hex[a[i] >> 4], *w++ = hex[a[i] & 15];
    *w = 0;
    env[m] = NULL;
    *own = s;
    return env;
}

/* dir(file)/name if it is an executable file; "" otherwise. */
static void beside(const char *file, const char *name, char *out, size_t cap)
{
    out[0] = 0;
    const char *slash = strrchr(file, '/');
    if (!slash) return;
    if ((size_t)snprintf(out, cap, "%.*s/%s", (int)(slash - file), file, name) >= cap ||
        access(out, X_OK) != 0)
        out[0] = 0;
}

/* The helper: beside the running program (/proc/self/exe), else beside the shared object
 * holding this code (liblumosaic.so in a program that loads it, e.g. Python); "" if neither
 * has it. */
static void helper_path(const char *name, char *out, size_t cap)
{
    static const char here = 0;
    out[0] = 0;
    char self[4096];
    ssize_t k = readlink("/proc/self/exe", self, sizeof self - 1);
    if (k > 0) {
        self[k] = 0;
        beside(self, name, out, cap);
    }
    Dl_info info;
    if (!out[0] && dladdr(&here, &info) && info.dli_fname && info.dli_fname[0])
        beside(info.dli_fname, name, out, cap);
}

lm_status lm_isolate_start(lm_isolate *c, const lm_isolate_entry *entry, const void *arg,
                           size_t n, const lm_isolate_limits *lim, const char *what, lm_err *e)
{
    c->pid = -1;
    c->fd = -1;
    c->timed_out = 0;
    if (n > LM_ISOLATE_MAX_ARG)
        return lm_err_set(e, LM_ERR_ARG, "%s: the reader's argument is too long (%zu bytes)",
                          what, n);
    int p[2];
    if (pipe2(p, O_CLOEXEC) != 0)
        return lm_err_set(e, LM_ERR_IO, "%s: cannot create a pipe: %s", what, strerror(errno));
    char *strings = NULL;
    char **env = lim->fork_only ? NULL : child_env(entry, p[1], lim->mem_bytes, arg, n, &strings);
    if (!lim->fork_only && !env) {
        close(p[0]), close(p[1]);
        return lm_err_set(e, LM_ERR_NOMEM, "%s: out of memory", what);
    }
    size_t as_fallback = lim->mem_bytes ? vm_bytes() + lim->mem_bytes : 0;
    char helper[4096] = "";
    if (env && entry->helper) helper_path(entry->helper, helper, sizeof helper);
    char *argv[] = {(char *)"lumosaic-reader", (char *)entry->name, NULL};
    fflush(NULL); /* nothing buffered may be written twice */
    pid_t pid = fork();
    if (pid < 0) {
        int err = errno;
        close(p[0]), close(p[1]);
        free(env), free(strings);
        return lm_err_set(e, LM_ERR_IO, "%s: cannot start a reader process: %s", what,
                          strerror(err));
    }
    if (pid == 0) {
        close(p[0]);
        child_prepare(p[1], lim);
        if (env && helper[0]) execve(helper, argv, env);
        if (env) execve("/proc/self/exe", argv, env);
        /* no exec: the entry runs in the forked image (see isolate.h) */
        default_faults();
        limit_as(as_fallback);
        entry->run(p[1], arg, n);
        close(p[1]);
        _exit(0);
    }
    close(p[1]);
    free(env), free(strings);
    c->pid = pid;
    c->fd = p[0];
    c->wall_ms = 1000L * (lim->cpu_seconds > 0
                              ? WALL_SECONDS_PER_CPU_SECOND * lim->cpu_seconds + WALL_SECONDS_MIN
                              : 24 * 3600);
    return LM_OK;
}

static int hex_digit(char ch)
{
    if (ch >= '0' && ch <= '9') return ch - '0';
    if (ch >= 'a' && ch <= 'f') return ch - 'a' + 10;
    return -1;
}

void lm_isolate_serve(const lm_isolate_entry *entry)
{
    const char *name = getenv("LM_ISOLATE_ENTRY");
    if (!name || strcmp(name, entry->name) != 0) return;
    const char *fds = getenv("LM_ISOLATE_FD"), *mems = getenv("LM_ISOLATE_MEM");
    const char *hexarg = getenv("LM_ISOLATE_ARG");
    char *end = NULL;
    long fd = fds ? strtol(fds, &end, 10) : -1;
    if (fd < 0 || !end || *end || !mems || !hexarg) _exit(EXIT_BAD_START);
    unsigned long long mem = strtoull(mems, &end, 10);
    size_t len = strlen(hexarg);
    if (*end || len % 2 || len / 2 > LM_ISOLATE_MAX_ARG) _exit(EXIT_BAD_START);
    unsigned char *arg = malloc(len / 2 + 1);
    if (!arg) _exit(EXIT_BAD_START);
    for (size_t i = 0; i < len / 2; i++) {
        int hi = hex_digit(hexarg[2 * i]), lo = hex_digit(hexarg[2 * i + 1]);
        if (hi < 0 || lo < 0) _exit(EXIT_BAD_START);
        arg[i] = (unsigned char)(hi << 4 | lo);
    }
    arg[len / 2] = 0;
    default_faults();
    if (mem) limit_as(vm_bytes() + (size_t)mem);
    entry->run((int)fd, arg, len / 2);
    close((int)fd);
    _exit(0);
}

int lm_isolate_read(lm_isolate *c, void *buf, size_t n)
{
    char *p = buf;
    while (n > 0) {
        struct pollfd pf = {c->fd, POLLIN, 0};
        int r = poll(&pf, 1, (int)(c->wall_ms > 0x7fffffffL ? 0x7fffffffL : c->wall_ms));
        if (r < 0 && errno == EINTR) continue;
        if (r <= 0) {
            c->timed_out = r == 0;
            return -1;
        }
        ssize_t k = read(c->fd, p, n);
        if (k < 0 && errno == EINTR) continue;
        if (k <= 0) return -1;
        p += k;
        n -= (size_t)k;
    }
    return 0;
}

int lm_isolate_write(int fd, const void *buf, size_t n)
{
    const char *p = buf;
    while (n > 0) {
        ssize_t k = write(fd, p, n);
        if (k < 0 && errno == EINTR) continue;
        if (k <= 0) return -1;
        p += k;
        n -= (size_t)k;
    }
    return 0;
}

lm_status lm_isolate_finish(lm_isolate *c, const char *what, const char *doing, lm_err *e)
{
    if (c->pid <= 0) return LM_OK;
    if (c->fd >= 0) close(c->fd); /* a child still writing gets SIGPIPE */
    c->fd = -1;
    if (c->timed_out) kill(c->pid, SIGKILL);
    int st = 0;
    while (waitpid(c->pid, &st, 0) < 0 && errno == EINTR) {
    }
    c->pid = -1;
    if (c->timed_out)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: %s failed: the reader did not finish in %ld s "
                          "(corrupt file?)", what, doing, c->wall_ms / 1000);
    if (WIFEXITED(st) && WEXITSTATUS(st) == 0) return LM_OK;
    if (WIFSIGNALED(st) && WTERMSIG(st) == SIGXCPU)
        return lm_err_set(e, LM_ERR_FORMAT, "%s: %s failed: the reader ran out of its CPU time "
                          "(corrupt file?)", what, doing);
    if (WIFSIGNALED(st))
        return lm_err_set(e, LM_ERR_FORMAT, "%s: %s failed: the library crashed on this file "
                          "(signal %d, %s): corrupt file", what, doing, WTERMSIG(st),
                          strsignal(WTERMSIG(st)));
    return lm_err_set(e, LM_ERR_FORMAT, "%s: %s failed: the reader exited with status %d "
                      "(out of memory on a corrupt file?)", what, doing, WEXITSTATUS(st));
}

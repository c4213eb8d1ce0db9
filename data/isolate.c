/* isolate.c — a library call in a child process (see isolate.h).
 * What it is: fork + pipe, rlimits (address space, CPU) in the child, default fault handlers there
 * (so a fault ends the child, whatever handlers a sanitizer or fuzzer installed), a wall-clock
 * bound on the parent's reads (a child stuck on a lock it inherited is killed), and the child's
 * end turned into a status and a message.
 * What it is not: a general process API (no exec, no stdin/stdout plumbing). */
#include "data/isolate.h"
#include <errno.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <stdio.h>
#include <string.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

#if defined(__SANITIZE_ADDRESS__)
#define LM_ISOLATE_SANITIZED 1
#elif defined(__has_feature)
#if __has_feature(address_sanitizer)
#define LM_ISOLATE_SANITIZED 1
#endif
#endif

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

static void child_setup(const lm_isolate_limits *lim)
{
    const int faults[] = {SIGSEGV, SIGBUS, SIGILL, SIGFPE, SIGABRT, SIGPIPE, SIGXCPU};
    for (size_t i = 0; i < sizeof faults / sizeof faults[0]; i++) signal(faults[i], SIG_DFL);
    struct rlimit r;
    if (lim->mem_bytes > 0) {
        r.rlim_cur = r.rlim_max = (rlim_t)(vm_bytes() + lim->mem_bytes);
        setrlimit(RLIMIT_AS, &r);
    }
    if (lim->cpu_seconds > 0) {
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

lm_status lm_isolate_start(lm_isolate *c, lm_isolate_fn fn, void *arg,
                           const lm_isolate_limits *lim, const char *what, lm_err *e)
{
    c->pid = -1;
    c->fd = -1;
    c->timed_out = 0;
    int p[2];
    if (pipe(p) != 0)
        return lm_err_set(e, LM_ERR_IO, "%s: cannot create a pipe: %s", what, strerror(errno));
    fflush(NULL); /* nothing buffered may be written twice */
    pid_t pid = fork();
    if (pid < 0) {
        close(p[0]);
        close(p[1]);
        return lm_err_set(e, LM_ERR_IO, "%s: cannot start a reader process: %s", what,
                          strerror(errno));
    }
    if (pid == 0) {
        close(p[0]);
        child_setup(lim);
        fn(p[1], arg);
        close(p[1]);
        _exit(0);
    }
    close(p[1]);
    c->pid = pid;
    c->fd = p[0];
    c->wall_ms = 1000L * (lim->cpu_seconds > 0
                              ? WALL_SECONDS_PER_CPU_SECOND * lim->cpu_seconds + WALL_SECONDS_MIN
                              : 24 * 3600);
    return LM_OK;
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

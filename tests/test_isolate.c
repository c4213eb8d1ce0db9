/* test_isolate.c — a library call in a child process (data/isolate.h): a reply comes through,
 * and a crash, an abort, a non-zero exit, a runaway allocation and a busy loop each end as an
 * error naming the input, with the parent alive; both in the exec'd child and in the forked
 * fallback. The exec'd child is a fresh image: a lock the parent holds does not hold it. */
#define _GNU_SOURCE
#include "tests/check.h"
#include "tests/fixture.h"
#include "data/isolate.h"
#include <pthread.h>
#include <signal.h>
#include <stdlib.h>
#include <unistd.h>

#if !defined(__SANITIZE_ADDRESS__) /* ASan's allocator aborts instead of returning NULL */
/* Touches 4 GB if it can: the address-space cap makes malloc fail first. */
static void hog(int fd, const void *arg, size_t n)
{
    (void)arg;
    n = (size_t)4 << 30;
    char *p = malloc(n);
    char ok = p == NULL;
    for (size_t i = 0; p && i < n; i += 4096) p[i] = 1;
    lm_isolate_write(fd, &ok, 1);
}

#endif

static void reply_ok(int fd, const void *arg, size_t n)
{
    lm_isolate_write(fd, arg, n);
}

static void crash(int fd, const void *arg, size_t n)
{
    (void)fd;
    (void)arg;
    (void)n;
    raise(SIGSEGV);
}

static void give_up(int fd, const void *arg, size_t n)
{
    (void)fd;
    (void)arg;
    (void)n;
    abort();
}

static void exit_3(int fd, const void *arg, size_t n)
{
    (void)fd;
    (void)arg;
    (void)n;
    _exit(3);
}

static void spin(int fd, const void *arg, size_t n)
{
    (void)fd;
    (void)arg;
    (void)n;
    for (volatile unsigned long i = 0;; i++) {
    }
}

/* The parent holds it while the child tries to take it. */
static pthread_mutex_t held = PTHREAD_MUTEX_INITIALIZER;

static void take_lock(int fd, const void *arg, size_t n)
{
    (void)arg;
    (void)n;
    pthread_mutex_lock(&held);
    char ok = 1;
    lm_isolate_write(fd, &ok, 1);
}

LM_ISOLATE_ENTRY(e_reply, "test.reply", NULL, reply_ok)
LM_ISOLATE_ENTRY(e_crash, "test.crash", NULL, crash)
LM_ISOLATE_ENTRY(e_abort, "test.abort", NULL, give_up)
LM_ISOLATE_ENTRY(e_exit3, "test.exit3", NULL, exit_3)
LM_ISOLATE_ENTRY(e_spin, "test.spin", NULL, spin)
LM_ISOLATE_ENTRY(e_lock, "test.lock", NULL, take_lock)
#if !defined(__SANITIZE_ADDRESS__)
LM_ISOLATE_ENTRY(e_hog, "test.hog", NULL, hog)
#endif

static void test_reply(void)
{
    for (int fork_only = 0; fork_only < 2; fork_only++) {
        lm_isolate c;
        lm_err e = {0};
        lm_isolate_limits lim = {64u << 20, 10, fork_only};
        /* every byte value, a NUL inside: the argument is bytes, not a string */
        unsigned char arg[300], buf[300];
        for (int i = 0; i < 300; i++) arg[i] = (unsigned char)(i * 7);
        CHECK(lm_isolate_start(&c, &e_reply, arg, sizeof arg, &lim, "in.dat", &e) == LM_OK);
        CHECK(lm_isolate_read(&c, buf, sizeof buf) == 0 && memcmp(buf, arg, sizeof buf) == 0);
        CHECK(lm_isolate_read(&c, buf, 1) == -1); /* the reply is over */
        CHECK(lm_isolate_finish(&c, "in.dat", "reading", &e) == LM_OK);
    }
    lm_isolate c;
    lm_err e = {0};
    lm_isolate_limits lim = {64u << 20, 10, 0};
    static unsigned char big[LM_ISOLATE_MAX_ARG + 1];
    CHECK(lm_isolate_start(&c, &e_reply, big, sizeof big, &lim, "in.dat", &e) == LM_ERR_ARG);
    CHECK_ERR(e, LM_ERR_ARG, "in.dat", "too long");
}

static void test_failures(void)
{
    const lm_isolate_entry *ens[4] = {&e_crash, &e_abort, &e_exit3, &e_spin};
    const char *why[4] = {"signal 11", "signal 6", "status 3", "CPU time"};
    for (int fork_only = 0; fork_only < 2; fork_only++)
        for (int i = 0; i < 4; i++) {
            lm_isolate c;
            lm_err e = {0};
            lm_isolate_limits lim = {64u << 20, 1, fork_only};
            char b;
            CHECK(lm_isolate_start(&c, ens[i], NULL, 0, &lim, "bad.dat", &e) == LM_OK);
            CHECK(lm_isolate_read(&c, &b, 1) == -1);
            CHECK(lm_isolate_finish(&c, "bad.dat", "reading", &e) == LM_ERR_FORMAT);
            CHECK_ERR(e, LM_ERR_FORMAT, "bad.dat: reading failed", why[i]);
        }
}

/* A child made by fork alone would wait for ever on the lock (until the wall-clock bound). */
static void test_fresh_image(void)
{
    pthread_mutex_lock(&held);
    lm_isolate c;
    lm_err e = {0};
    lm_isolate_limits lim = {64u << 20, 2, 0};
    char ok = 0;
    CHECK(lm_isolate_start(&c, &e_lock, NULL, 0, &lim, "lock", &e) == LM_OK);
    CHECK(lm_isolate_read(&c, &ok, 1) == 0 && ok == 1);
    CHECK_MSG(lm_isolate_finish(&c, "lock", "locking", &e) == LM_OK, "%s", e.msg);
    pthread_mutex_unlock(&held);
}

static void test_memory_cap(void)
{
#if !defined(__SANITIZE_ADDRESS__)
    for (int fork_only = 0; fork_only < 2; fork_only++) {
        lm_isolate c;
        lm_err e = {0};
        lm_isolate_limits lim = {256u << 20, 10, fork_only};
        char refused = 0;
        CHECK(lm_isolate_start(&c, &e_hog, NULL, 0, &lim, "big.dat", &e) == LM_OK);
        CHECK(lm_isolate_read(&c, &refused, 1) == 0 && refused == 1);
        CHECK(lm_isolate_finish(&c, "big.dat", "reading", &e) == LM_OK);
    }
#endif
}

int main(void)
{
    RUN(test_reply);
    RUN(test_failures);
    RUN(test_fresh_image);
    RUN(test_memory_cap);
    return check_summary();
}

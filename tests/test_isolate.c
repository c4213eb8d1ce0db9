/* test_isolate.c — a library call in a child process (data/isolate.h): a reply comes through,
 * and a crash, an abort, a non-zero exit, a runaway allocation and a busy loop each end as an
 * error naming the input, with the parent alive. */
#define _GNU_SOURCE
#include "tests/check.h"
#include "tests/fixture.h"
#include "data/isolate.h"
#include <signal.h>
#include <stdlib.h>
#include <unistd.h>

static void reply_ok(int fd, void *arg)
{
    const char *s = arg;
    lm_isolate_write(fd, s, strlen(s) + 1);
}

static void crash(int fd, void *arg)
{
    (void)fd;
    (void)arg;
    raise(SIGSEGV);
}

static void give_up(int fd, void *arg)
{
    (void)fd;
    (void)arg;
    abort();
}

static void exit_3(int fd, void *arg)
{
    (void)fd;
    (void)arg;
    _exit(3);
}

static void spin(int fd, void *arg)
{
    (void)fd;
    (void)arg;
    for (volatile unsigned long i = 0;; i++) {
    }
}

static void test_reply(void)
{
    lm_isolate c;
    lm_err e = {0};
    lm_isolate_limits lim = {64u << 20, 10};
    char buf[6] = "";
    CHECK(lm_isolate_start(&c, reply_ok, "hello", &lim, "in.dat", &e) == LM_OK);
    CHECK(lm_isolate_read(&c, buf, 6) == 0 && strcmp(buf, "hello") == 0);
    CHECK(lm_isolate_read(&c, buf, 1) == -1); /* the reply is over */
    CHECK(lm_isolate_finish(&c, "in.dat", "reading", &e) == LM_OK);
}

static void test_failures(void)
{
    lm_isolate_fn fns[4] = {crash, give_up, exit_3, spin};
    const char *why[4] = {"signal 11", "signal 6", "status 3", "CPU time"};
    for (int i = 0; i < 4; i++) {
        lm_isolate c;
        lm_err e = {0};
        lm_isolate_limits lim = {64u << 20, 1};
        char b;
        CHECK(lm_isolate_start(&c, fns[i], NULL, &lim, "bad.dat", &e) == LM_OK);
        CHECK(lm_isolate_read(&c, &b, 1) == -1);
        CHECK(lm_isolate_finish(&c, "bad.dat", "reading", &e) == LM_ERR_FORMAT);
        CHECK_ERR(e, LM_ERR_FORMAT, "bad.dat: reading failed", why[i]);
    }
}

#if !defined(__SANITIZE_ADDRESS__) /* ASan's allocator aborts instead of returning NULL */
/* Touches 4 GB if it can: the address-space cap makes malloc fail first. */
static void hog(int fd, void *arg)
{
    (void)arg;
    size_t n = (size_t)4 << 30;
    char *p = malloc(n);
    char ok = p == NULL;
    for (size_t i = 0; p && i < n; i += 4096) p[i] = 1;
    lm_isolate_write(fd, &ok, 1);
}

#endif

static void test_memory_cap(void)
{
#if !defined(__SANITIZE_ADDRESS__)
    lm_isolate c;
    lm_err e = {0};
    lm_isolate_limits lim = {256u << 20, 10};
    char refused = 0;
    CHECK(lm_isolate_start(&c, hog, NULL, &lim, "big.dat", &e) == LM_OK);
    CHECK(lm_isolate_read(&c, &refused, 1) == 0 && refused == 1);
    CHECK(lm_isolate_finish(&c, "big.dat", "reading", &e) == LM_OK);
#endif
}

int main(void)
{
    RUN(test_reply);
    RUN(test_failures);
    RUN(test_memory_cap);
    return check_summary();
}

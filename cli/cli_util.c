/* cli_util.c — option parsing and staging folders for the cli/cmd_*.c commands (see
 * cli_util.h). */
#define _GNU_SOURCE /* nftw flags */
#include "cli/cli_util.h"
#include "tensor/tensor.h"
#include "data/util.h"
#include <dirent.h>
#include <errno.h>
#include <ftw.h>
#include <math.h>
#include <omp.h>
#include <pthread.h>
#include <semaphore.h>
#include <signal.h>
#include <stdarg.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <strings.h>
#include <sys/stat.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>

void lm_cli_init(lm_cli *c, const char *prog, int argc, char **argv)
{
    c->prog = prog;
    c->argc = argc;
    c->argv = argv;
    c->i = 1;
}

int lm_cli_done(const lm_cli *c) { return c->i >= c->argc; }

int lm_cli_is_help(const lm_cli *c)
{
    const char *a = c->argv[c->i];
    return !strcmp(a, "--help") || !strcmp(a, "-h");
}

static void yield_to_signal(void);

int lm_cli_error(const lm_cli *c, const char *fmt, ...)
{
    yield_to_signal();
    char msg[1024];
    va_list ap;
    va_start(ap, fmt);
    vsnprintf(msg, sizeof msg, fmt, ap);
    va_end(ap);
    for (char *p = msg; *p; p++) /* one line, whatever the message holds */
        if (*p == '\n' || *p == '\r') *p = ' ';
    fprintf(stderr, "%s: %s\n", c->prog, msg);
    return 2;
}

int lm_cli_exit_status(int status)
{
    switch (status) {
    case LM_OK: return LM_EXIT_OK;
    case LM_ERR_WRITE:
    case LM_ERR_NOMEM:
    case LM_ERR_BACKEND: return LM_EXIT_FAILED;
    default: return LM_EXIT_USAGE; /* arguments, shapes, formats, reads, NaN in the input,
                                    * unsupported input */
    }
}

int lm_cli_unknown(const lm_cli *c)
{
    return lm_cli_error(c, "unknown option '%s' (see '%s --help')", c->argv[c->i], c->prog);
}

int lm_cli_value(lm_cli *c, const char *name, const char **value)
{
    const char *a = c->argv[c->i];
    size_t n = strlen(name);
    if (strncmp(a, name, n) != 0) return 0;
    if (a[n] == '=') {
        *value = a + n + 1;
        c->i++;
        return 1;
    }
    if (a[n] != 0) return 0;
    if (c->i + 1 >= c->argc) {
        lm_cli_error(c, "%s needs a value", name);
        return -1;
    }
    *value = c->argv[c->i + 1];
    c->i += 2;
    return 1;
}

int lm_cli_flag(lm_cli *c, const char *name, int *flag)
{
    const char *a = c->argv[c->i];
    size_t n = strlen(name);
    if (strncmp(a, name, n) != 0 || (a[n] != 0 && a[n] != '=')) return 0;
    if (a[n] == '=') {
        lm_cli_error(c, "%s takes no value", name);
        return -1;
    }
    *flag = 1;
    c->i++;
    return 1;
}

int lm_cli_parse_ll(const char *s, long long *out) { return lm_parse_int(s, out); }

int lm_cli_parse_real(const char *s, double *out) { return lm_parse_real(s, out); }

int lm_cli_int(lm_cli *c, const char *name, long long lo, long long hi, long long *out)
{
    const char *s;
    int r = lm_cli_value(c, name, &s);
    if (r <= 0) return r;
    long long v;
    if (lm_cli_parse_ll(s, &v) != 0) {
        lm_cli_error(c, "%s: '%s' is not an integer in %lld..%lld", name, s, lo, hi);
        return -1;
    }
    if (v < lo || v > hi) {
        lm_cli_error(c, "%s: %lld is out of range (%lld..%lld)", name, v, lo, hi);
        return -1;
    }
    *out = v;
    return 1;
}

int lm_cli_real(lm_cli *c, const char *name, double lo, double hi, double *out)
{
    const char *s;
    int r = lm_cli_value(c, name, &s);
    if (r <= 0) return r;
    double v;
    if (lm_cli_parse_real(s, &v) != 0) {
        lm_cli_error(c, "%s: '%s' is not a finite number in %g..%g", name, s, lo, hi);
        return -1;
    }
    if (v < lo || v > hi) {
        lm_cli_error(c, "%s: %g is out of range (%g..%g)", name, v, lo, hi);
        return -1;
    }
    *out = v;
    return 1;
}

int lm_cli_common_opt(lm_cli *c, unsigned which, long long seed_max, lm_cli_common *o)
{
    int r = 0;
    if ((which & LM_CLI_THREADS) && /* the same bound for every command */
        (r = lm_cli_int(c, "--threads", 1, LM_MAX_THREADS, &o->threads)))
        return r;
    if ((which & LM_CLI_DEVICE) && (r = lm_cli_value(c, "--device", &o->device))) return r;
    if ((which & LM_CLI_SEED) && (r = lm_cli_int(c, "--seed", 0, seed_max, &o->seed))) return r;
    if ((which & LM_CLI_QUIET) && (r = lm_cli_flag(c, "--quiet", &o->quiet))) return r;
    if (which & LM_CLI_PRECISION) {
        static const char *const names[] = {"fp32", "bf16", NULL};
        int k = 0;
        if ((r = lm_cli_choice(c, "--precision", names, &k)) != 0) {
            if (r > 0) o->precision = k ? LM_PRECISION_BF16 : LM_PRECISION_FP32;
            return r;
        }
    }
    return 0;
}

void lm_cli_common_apply(const lm_cli_common *o)
{
    if (o->threads > 0) omp_set_num_threads((int)o->threads);
}

int lm_cli_choice(lm_cli *c, const char *name, const char *const *choices, int *out)
{
    const char *s;
    int r = lm_cli_value(c, name, &s);
    if (r <= 0) return r;
    char list[256] = "";
    for (int k = 0; choices[k]; k++) {
        if (!strcmp(s, choices[k])) {
            *out = k;
            return 1;
        }
        size_t used = strlen(list);
        snprintf(list + used, sizeof list - used, "%s%s", k ? ", " : "", choices[k]);
    }
    lm_cli_error(c, "%s: unknown value '%s' (one of: %s)", name, s, list);
    return -1;
}

int lm_cli_parse_size(const char *s, long long lo, long long hi, int *h, int *w)
{
    char buf[64], *x;
    long long a, b;
    if (snprintf(buf, sizeof buf, "%s", s) >= (int)sizeof buf || !(x = strchr(buf, 'x')))
        return -1;
    *x = 0;
    if (lm_cli_parse_ll(buf, &a) || lm_cli_parse_ll(x + 1, &b) || a < lo || a > hi || b < lo ||
        b > hi)
        return -1;
    *h = (int)a, *w = (int)b;
    return 0;
}

int lm_cli_has_ext(const char *path, const char *ext)
{
    size_t n = strlen(path), m = strlen(ext);
    return n >= m && strcasecmp(path + n - m, ext) == 0;
}

/* 1 if dir is a folder with no entries but . and .. */
static int dir_is_empty(const char *dir)
{
    DIR *d = opendir(dir);
    if (!d) return 0;
    struct dirent *e;
    int empty = 1;
    while (empty && (e = readdir(d)))
        if (strcmp(e->d_name, ".") && strcmp(e->d_name, "..")) empty = 0;
    closedir(d);
    return empty;
}

/* ---- signals ------------------------------------------------------------------------ */
/* The handler only counts and records (async-signal-safe); a waiting thread does the rest
 * (removing files, printing) in an ordinary thread context. The staging folder in use is
 * guarded by `mu`: committing it (a rename) and removing it on a signal never interleave. A
 * hold (lm_cli_signals_hold) makes the waiter wait before it ends the program; the children
 * tracked receive the signal that ends it and are waited for. */
#define SIG_MAX_CHILDREN 64
static struct {
    const char *prog;
    int graceful;
    atomic_int count, first, last;
    sem_t wake;
    pthread_mutex_t mu;
    pthread_cond_t released;
    int hold;                          /* lm_cli_signals_hold depth */
    long child[SIG_MAX_CHILDREN];      /* tracked child processes (0 = free slot) */
    void (*note)(char *buf, size_t n); /* graceful: what a stop at once leaves */
    char stage[1200];                  /* staging folder in use ("" = none) */
} sig = {.mu = PTHREAD_MUTEX_INITIALIZER, .released = PTHREAD_COND_INITIALIZER};

/* A command that stops at once on a signal (not graceful): once a signal has arrived, an
 * error of the main thread is most likely the teardown itself (the staging folder removed
 * under a write), so it is not reported: the calling thread waits while the signal's thread
 * removes what was staged, says so in its one line and ends the program. */
static void yield_to_signal(void)
{
    if (!sig.prog || sig.graceful || atomic_load(&sig.count) == 0) return;
    for (;;) pause();
}

void lm_cli_signals_hold(int on)
{
    pthread_mutex_lock(&sig.mu);
    sig.hold += on ? 1 : -1;
    if (sig.hold <= 0) {
        sig.hold = 0;
        pthread_cond_broadcast(&sig.released);
    }
    pthread_mutex_unlock(&sig.mu);
}

void lm_cli_signals_track(long pid, int on)
{
    pthread_mutex_lock(&sig.mu);
    for (int i = 0; i < SIG_MAX_CHILDREN; i++)
        if (on ? sig.child[i] == 0 : sig.child[i] == pid) {
            sig.child[i] = on ? pid : 0;
            break;
        }
    pthread_mutex_unlock(&sig.mu);
}

void lm_cli_signals_note(void (*note)(char *buf, size_t n))
{
    pthread_mutex_lock(&sig.mu);
    sig.note = note;
    pthread_mutex_unlock(&sig.mu);
}

static void set_stage(const char *tmp)
{
    pthread_mutex_lock(&sig.mu);
    snprintf(sig.stage, sizeof sig.stage, "%s", tmp ? tmp : "");
    pthread_mutex_unlock(&sig.mu);
}

int lm_cli_stage_dir(const lm_cli *c, const char *dir, char *tmp, size_t n)
{
    struct stat st;
    if (stat(dir, &st) == 0 && !(S_ISDIR(st.st_mode) && dir_is_empty(dir))) {
        return lm_cli_error(c, "%s: output already exists and is not an empty folder", dir);
    }
    int k = snprintf(tmp, n, "%s.tmp.%ld", dir, (long)getpid());
    if (k < 0 || (size_t)k >= n) return lm_cli_error(c, "%s: output path is too long", dir);
    if (mkdir(tmp, 0777) != 0) {
        lm_cli_error(c, "%s: cannot create a folder: %s", tmp, strerror(errno));
        return LM_EXIT_FAILED;
    }
    set_stage(tmp);
    return 0;
}

static int rm_entry(const char *p, const struct stat *st, int flag, struct FTW *f)
{
    (void)st, (void)flag, (void)f;
    return remove(p);
}

void lm_cli_remove_tree(const char *dir)
{
    pthread_mutex_lock(&sig.mu);
    if (!strcmp(sig.stage, dir)) sig.stage[0] = 0;
    pthread_mutex_unlock(&sig.mu);
    nftw(dir, rm_entry, 16, FTW_DEPTH | FTW_PHYS);
}

int lm_cli_commit_dir(const lm_cli *c, const char *tmp, const char *dir)
{
    pthread_mutex_lock(&sig.mu);
    int bad = rename(tmp, dir) != 0, e = errno;
    if (!bad && !strcmp(sig.stage, tmp)) sig.stage[0] = 0;
    pthread_mutex_unlock(&sig.mu);
    if (bad) {
        lm_cli_error(c, "%s: cannot move the output into place: %s", dir, strerror(e));
        lm_cli_remove_tree(tmp);
        return -1;
    }
    return 0;
}

const char *lm_cli_signal_name(int s)
{
    static char buf[32];
    if (s == SIGINT) return "SIGINT";
    if (s == SIGTERM) return "SIGTERM";
    snprintf(buf, sizeof buf, "signal %d", s);
    return buf;
}

const atomic_int *lm_cli_signal_flag(void) { return &sig.first; }

static void on_signal(int s)
{
    int n = atomic_fetch_add(&sig.count, 1);
    if (n == 0) atomic_store(&sig.first, s);
    atomic_store(&sig.last, s);
    if (!sig.graceful || n > 0) sem_post(&sig.wake);
}

/* The tracked children get signal s and are waited for (up to 60 s; then SIGKILL). */
static void stop_children(int s)
{
    for (int i = 0; i < SIG_MAX_CHILDREN; i++)
        if (sig.child[i] > 0) kill((pid_t)sig.child[i], s);
    for (int i = 0; i < SIG_MAX_CHILDREN; i++) {
        pid_t p = (pid_t)sig.child[i];
        if (p <= 0) continue;
        int k = 0;
        while (waitpid(p, NULL, WNOHANG) == 0 && k++ < 1200)
            nanosleep(&(struct timespec){0, 50000000}, NULL);
        if (k > 1200) kill(p, SIGKILL), waitpid(p, NULL, 0);
    }
}

/* Woken by a signal that ends the program: the staging folder goes (moved aside first, so the
 * command's own threads cannot add files to it while it is removed), one line, exit. */
static void *sig_waiter(void *arg)
{
    (void)arg;
    while (sem_wait(&sig.wake) != 0) continue;
    int s = atomic_load(&sig.first), s2 = atomic_load(&sig.last);
    pthread_mutex_lock(&sig.mu); /* held until _exit: no commit can start */
    while (sig.hold > 0) pthread_cond_wait(&sig.released, &sig.mu);
    stop_children(sig.graceful ? s2 : s);
    int staged = sig.stage[0] != 0;
    if (staged) {
        char trash[1300];
        snprintf(trash, sizeof trash, "%s.removing", sig.stage);
        const char *dir = rename(sig.stage, trash) == 0 ? trash : sig.stage;
        for (int k = 0; k < 5 && access(dir, F_OK) == 0; k++)
            nftw(dir, rm_entry, 16, FTW_DEPTH | FTW_PHYS);
    }
    char note[1400] = "";
    if (!staged && sig.graceful && sig.note) sig.note(note, sizeof note);
    if (staged)
        fprintf(stderr, "%s: interrupted (%s): partial output removed\n", sig.prog,
                lm_cli_signal_name(s));
    else if (sig.graceful && s2 != s)
        fprintf(stderr, "%s: interrupted (%s after %s): stopped at once%s%s\n", sig.prog,
                lm_cli_signal_name(s2), lm_cli_signal_name(s), note[0] ? ": " : "", note);
    else if (sig.graceful)
        fprintf(stderr, "%s: interrupted (%s) again: stopped at once%s%s\n", sig.prog,
                lm_cli_signal_name(s), note[0] ? ": " : "", note);
    else
        fprintf(stderr, "%s: interrupted (%s)\n", sig.prog, lm_cli_signal_name(s));
    fflush(stderr);
    _exit(128 + (sig.graceful ? s2 : s));
}

int lm_cli_signals_init(const lm_cli *c, int graceful)
{
    sig.prog = c->prog;
    sig.graceful = graceful;
    pthread_t t;
    if (sem_init(&sig.wake, 0, 0) != 0 || pthread_create(&t, NULL, sig_waiter, NULL) != 0)
        return -1;
    pthread_detach(t);
    struct sigaction sa;
    memset(&sa, 0, sizeof sa);
    sa.sa_handler = on_signal;
    sa.sa_flags = SA_RESTART; /* reads and writes in progress go on */
    sigemptyset(&sa.sa_mask);
    return sigaction(SIGINT, &sa, NULL) || sigaction(SIGTERM, &sa, NULL) ? -1 : 0;
}

int lm_cli_positional(lm_cli *c, const char **out, int *n)
{
    const char *a = c->argv[c->i];
    if (a[0] == '-' && a[1] == '-') return lm_cli_unknown(c);
    out[(*n)++] = a;
    c->i++;
    return 0;
}

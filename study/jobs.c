/* jobs.c — `lumosaic study --jobs J`: the presets still to train are trained side by side, J at
 * a time, each in a child process (`lumosaic study --worker NAME`, the same program and
 * config) that trains that one preset and exits. Training time is then best counted on the CPU
 * clock (the config's "clock": "cpu"), which runs that share the machine do not shrink.
 * What it is not: which presets train when (study.c), evaluation or timing (serial, after). */
#include <errno.h>
#include <signal.h>
#include <spawn.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>
#include <sys/wait.h>
#include <time.h>
#include <unistd.h>
#include <omp.h>
#include "study/study.h"

extern char **environ;

static lm_status spawn_one(const char *exe, const lm_study_cfg *cfg, const char *dir,
                           const char *name, double stop_s, const lm_study_opts *o, pid_t *pid,
                           lm_err *err)
{
    char thr[16], stop[32];
    int t = o->threads > 0 ? o->threads : omp_get_num_procs() / (o->jobs > 0 ? o->jobs : 1);
    snprintf(thr, sizeof thr, "%d", t > 0 ? t : 1);
    snprintf(stop, sizeof stop, "%.3f", stop_s > 0 ? stop_s : 0.0);
    char *argv[] = {(char *)exe, "study", "--config", (char *)cfg->path, "--output", (char *)dir,
                    "--threads", thr, "--worker", (char *)name, "--stop-seconds", stop,
                    "--no-charts", o->progress ? NULL : "--quiet", NULL};
    /* its own process group: a terminal's Ctrl-C reaches the study alone, which forwards it
     * once (twice would stop a worker at once) */
    posix_spawnattr_t at;
    int rc = posix_spawnattr_init(&at);
    if (!rc) rc = posix_spawnattr_setflags(&at, POSIX_SPAWN_SETPGROUP);
    if (!rc) rc = posix_spawnattr_setpgroup(&at, 0);
    if (!rc) rc = posix_spawn(pid, exe, NULL, &at, argv, environ);
    posix_spawnattr_destroy(&at);
    if (rc != 0)
        return lm_err_set(err, LM_ERR_IO, "study: cannot start a worker for %s (%s): %s", name,
                          exe, strerror(rc));
    fprintf(o->log, "study: %s: worker %ld started (%s threads)\n", name, (long)*pid, thr);
    return LM_OK;
}

lm_status lm_study_spawn(const lm_study_cfg *cfg, const char *dir, const char *const *names,
                         int n, double stop_s, const lm_study_opts *o, lm_err *err)
{
    char self[4096];
    const char *exe = o->exe;
    if (!exe) {
        ssize_t len = readlink("/proc/self/exe", self, sizeof self - 1);
        if (len <= 0)
            return lm_err_set(err, LM_ERR_IO, "study --jobs: cannot find this program (%s)",
                              strerror(errno));
        self[len] = 0;
        exe = self;
    }
    pid_t *pid = calloc((size_t)n, sizeof *pid);
    if (!pid) return lm_err_set(err, LM_ERR_NOMEM, "study: out of memory");
    int next = 0, running = 0, bad = -1, bad_status = 0, forwarded = 0;
    lm_status st = LM_OK;
    while (running > 0 || (next < n && !st && bad < 0 && !forwarded)) {
        while (!st && bad < 0 && !forwarded && running < o->jobs && next < n) {
            st = spawn_one(exe, cfg, dir, names[next], stop_s, o, &pid[next], err);
            if (!st && o->track) o->track((long)pid[next], 1);
            if (!st) next++, running++;
        }
        if (running == 0) break;
        /* a signal: every running worker gets it (each finishes its iteration, checkpoints
         * and exits), no other starts */
        int sig = o->interrupt ? atomic_load(o->interrupt) : 0;
        if (sig && !forwarded) {
            for (int i = 0; i < next; i++)
                if (pid[i] > 0) kill(pid[i], sig);
            forwarded = sig;
        }
        int status = 0;
        pid_t w = waitpid(-1, &status, WNOHANG); /* polled: the flag is read between waits */
        if (w == 0) {
            nanosleep(&(struct timespec){0, 50000000}, NULL);
            continue;
        }
        if (w < 0 && errno == EINTR) continue;
        if (w < 0) break;
        for (int i = 0; i < next; i++) {
            if (pid[i] != w) continue;
            running--;
            pid[i] = 0;
            if (o->track) o->track((long)w, 0);
            int stopped = forwarded && WIFEXITED(status) && WEXITSTATUS(status) == 128 + forwarded;
            if ((!WIFEXITED(status) || WEXITSTATUS(status) != 0) && !stopped && bad < 0)
                bad = i, bad_status = status;
        }
    }
    /* a failed run exits 1 (cmd_study maps LM_ERR_NUMERIC, a failed run, to 1); bad input 2 */
    if (!st && bad >= 0)
        st = WIFSIGNALED(bad_status)
             ? lm_err_set(err, LM_ERR_NUMERIC, "study: the worker training %s was stopped by "
                          "signal %d (the study resumes from its checkpoint)", names[bad],
                          WTERMSIG(bad_status))
             : lm_err_set(err, WEXITSTATUS(bad_status) == 2 ? LM_ERR_ARG : LM_ERR_NUMERIC,
                          "study: the worker training %s failed (exit %d; its message is "
                          "above)", names[bad], WEXITSTATUS(bad_status));
    if (!st && forwarded)
        st = lm_err_set(err, LM_ERR_INTERRUPTED, "the workers checkpointed their runs in %s/runs "
                        "and exited", dir);
    free(pid);
    return st;
}

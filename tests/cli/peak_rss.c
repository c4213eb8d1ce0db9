/* peak_rss.c — run a command and record its peak resident memory, for the memory-bound tests
 * (tests/cli/hostile.sh). What it is: `cli_peak_rss OUT.kb COMMAND ARGS...` runs COMMAND, writes
 * the largest resident set size of it and of any child it waited for (wait4's ru_maxrss, in KB)
 * to OUT.kb, and exits with COMMAND's status (128 + the signal if it was killed). Works the same
 * in sanitizer builds, where a virtual-memory limit (ulimit -v) cannot be used.
 * What it is not: a test by itself, or a limit (the script compares the figures). */
#include <stdio.h>
#include <sys/resource.h>
#include <sys/wait.h>
#include <unistd.h>

int main(int argc, char **argv)
{
    if (argc < 3) {
        fprintf(stderr, "usage: cli_peak_rss OUT.kb COMMAND [ARGS...]\n");
        return 2;
    }
    pid_t pid = fork();
    if (pid < 0) {
        perror("cli_peak_rss: fork");
        return 2;
    }
    if (pid == 0) {
        execvp(argv[2], argv + 2);
        perror("cli_peak_rss: exec");
        _exit(127);
    }
    int st = 0;
    struct rusage ru;
    if (wait4(pid, &st, 0, &ru) != pid) {
        perror("cli_peak_rss: wait4");
        return 2;
    }
    FILE *f = fopen(argv[1], "w");
    if (!f) {
        perror(argv[1]);
        return 2;
    }
    fprintf(f, "%ld\n", ru.ru_maxrss);
    fclose(f);
    return WIFSIGNALED(st) ? 128 + WTERMSIG(st) : WEXITSTATUS(st);
}

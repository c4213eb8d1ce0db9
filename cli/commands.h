/* commands.h — the subcommands of the `lumosaic` program. Each lives in its own cli/cmd_*.c,
 * parses its own options (every option has --help text), prints one-line errors to stderr and
 * returns the process exit status (cli_util.h: 0 ok, 1 the work failed, e.g. an output that
 * cannot be written, 2 bad usage or input, 128 + N on signal N). */
#ifndef LM_CLI_COMMANDS_H
#define LM_CLI_COMMANDS_H

typedef int (*lm_cmd_fn)(int argc, char **argv); /* argv[0] is the subcommand name */

typedef struct lm_command {
    const char *name;
    lm_cmd_fn run;
    const char *summary;
} lm_command;

int lm_cmd_version(int argc, char **argv);
/* Declarations of the other commands go here, one line each (alphabetical). */
int lm_cmd_average(int argc, char **argv);
int lm_cmd_bound(int argc, char **argv);
int lm_cmd_calibrate(int argc, char **argv);
int lm_cmd_coding(int argc, char **argv);
int lm_cmd_convert(int argc, char **argv);
int lm_cmd_eval(int argc, char **argv);
int lm_cmd_fit_auto(int argc, char **argv);
int lm_cmd_infer(int argc, char **argv);
int lm_cmd_info(int argc, char **argv);
int lm_cmd_render(int argc, char **argv);
int lm_cmd_report(int argc, char **argv);
int lm_cmd_simulate(int argc, char **argv);
int lm_cmd_study(int argc, char **argv);
int lm_cmd_train(int argc, char **argv);

#endif

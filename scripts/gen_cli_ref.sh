#!/usr/bin/env bash
# gen_cli_ref.sh — writes docs/reference/cli.md from the program's own help: `lumosaic --help`,
# every command's `--help` (the command list is read from `lumosaic --help`, so a new command
# appears by itself) and `lumosaic info --list`.
#
#   scripts/gen_cli_ref.sh [LUMOSAIC]            regenerate docs/reference/cli.md
#                                                (default LUMOSAIC: build/lumosaic)
#   scripts/gen_cli_ref.sh --check LUMOSAIC      exit 1, printing the difference and the command
#                                                that regenerates it, if the file is out of date
set -euo pipefail
root=$(cd "$(dirname "$0")/.." && pwd)
check=0
if [ "${1:-}" = "--check" ]; then check=1; shift; fi
lm=${1:-$root/build/lumosaic}
out=$root/docs/reference/cli.md

generate() {
  local cmds c
  cmds=$("$lm" --help | sed -n 's/^  \([a-z][a-z0-9-]*\) .*/\1/p' | grep -vx help)
  echo "# Command-line reference"
  echo
  echo "Generated from the program's own help by \`scripts/gen_cli_ref.sh\`; do not edit by hand"
  echo "(the CTest test \`docs_cli_reference\` fails when this page and the help differ). The guide"
  echo "explains the commands task by task: [docs/guide/](../guide/README.md)."
  echo
  echo "Exit status, the same for every command: 0 done; 1 the work failed (an output that cannot be"
  echo "written, out of memory, a NaN loss); 2 bad usage or input; 130 / 143 interrupted by SIGINT /"
  echo "SIGTERM. What each means and what to do: [troubleshooting](../guide/troubleshooting.md)."
  echo
  echo "Commands:"
  echo
  for c in $cmds; do echo "- [\`lumosaic $c\`](#lumosaic-$c)"; done
  echo "- [Presets: \`lumosaic info --list\`](#presets-lumosaic-info---list)"
  echo
  echo "## lumosaic"
  echo
  echo '```text'
  "$lm" --help
  echo '```'
  for c in $cmds; do
    echo
    echo "## lumosaic $c"
    echo
    echo '```text'
    "$lm" "$c" --help
    echo '```'
  done
  echo
  echo "## Presets: lumosaic info --list"
  echo
  echo '```text'
  "$lm" info --list
  echo '```'
}

tmp=$(mktemp)
trap 'rm -f "$tmp"' EXIT
generate > "$tmp"
if [ "$check" = 1 ]; then
  if ! diff -u "$out" "$tmp"; then
    echo "docs/reference/cli.md differs from the program's --help; regenerate it with:" >&2
    echo "  scripts/gen_cli_ref.sh build/lumosaic" >&2
    exit 1
  fi
  echo "docs/reference/cli.md matches the --help of $(grep -c '^## lumosaic ' "$out") commands"
else
  mkdir -p "$(dirname "$out")"
  cp "$tmp" "$out"
  echo "wrote $out"
fi

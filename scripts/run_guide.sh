#!/usr/bin/env bash
# run_guide.sh — runs the commands of the guide, so that it cannot rot.
#
#   scripts/run_guide.sh BUILD_DIR [PAGE.md ...]     (default: README.md and docs/guide/*.md)
#
# Every fenced block tagged ```sh in a page is run, in the page's order, with bash -euo pipefail,
# in a fresh folder laid out like a checkout: build/ (BUILD_DIR), models/, data/, study/,
# scripts/, examples/ and include/ of this repository, and ../shared (LM_SHARED_DIR, default
# the folder beside the checkout), so a block reads exactly as a user types it at the top of
# the repository. Blocks of one page share that folder (a later block may use an earlier
# block's output); each page gets its own.
# Blocks tagged ```sh norun (installing packages, hours of training) are not run; they are
# checked instead: bash -n, every `lumosaic COMMAND --option` names an option that
# `lumosaic COMMAND --help` lists, and every scripts/... or study/... path exists.
# Prints one line per block; exits 1 if any block failed.
set -u
root=$(cd "$(dirname "$0")/.." && pwd)
build=$(cd "$1" && pwd)
shift
shared=${LM_SHARED_DIR:-$root/../shared}
shared=$(cd "$shared" && pwd)
lm=$build/lumosaic
if [ $# -eq 0 ]; then set -- "$root"/README.md "$root"/docs/guide/*.md; fi
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
fails=0 blocks=0 checked=0

# extract PAGE OUTDIR: OUTDIR/NNN.{run,norun} (block text) and OUTDIR/NNN.line (its line)
extract() {
  awk -v out="$2" '
    /^```sh( norun)?[ \t]*$/ && !inb { inb = 1; n++; kind = ($0 ~ /norun/) ? "norun" : "run"
                                      f = sprintf("%s/%03d.%s", out, n, kind)
                                      printf "" > f; print NR + 1 > sprintf("%s/%03d.line", out, n)
                                      next }
    /^```/ && inb { inb = 0; close(f); next }
    inb { print >> f }
  ' "$1"
}

# check_norun FILE: the options of every lumosaic command in it exist; paths exist
check_norun() {
  local f=$1 ok=0 line cmd opt p
  bash -n "$f" 2>&1 || ok=1
  # join continuation lines, then look at each lumosaic invocation
  while IFS= read -r line; do
    [[ $line =~ (^|[[:space:]/])lumosaic[[:space:]]+([a-z][a-z0-9-]*)(.*)$ ]] || continue
    cmd=${BASH_REMATCH[2]} rest=${BASH_REMATCH[3]}
    help=$("$lm" "$cmd" --help 2>&1) || { echo "  'lumosaic $cmd' is not a command"; ok=1; continue; }
    for opt in $(grep -oE -- '(^|[[:space:]])--[a-z][a-z0-9-]*' <<< "$rest" | tr -d ' \t'); do
      grep -qE -- "(^|[^a-z0-9-])$opt([^a-z0-9-]|$)" <<< "$help" ||
        { echo "  lumosaic $cmd: no option $opt in its --help"; ok=1; }
    done
  done < <(sed -e ':a' -e '/\\$/N; s/\\\n//; ta' "$f")
  for p in $(grep -oE '(^|[[:space:]])(scripts|study|examples|models)/[A-Za-z0-9_./+-]+' "$f" | tr -d ' \t'); do
    [ -e "$root/$p" ] || { echo "  $p does not exist"; ok=1; }
  done
  return $ok
}

i=0
for page in "$@"; do
  i=$((i + 1))
  name=$(basename "$page" .md)
  w=$T/$i-$name
  mkdir -p "$w/blocks" "$w/repo"
  ln -s "$shared" "$w/shared"
  ln -s "$build" "$w/repo/build"
  for d in models data study scripts examples include; do ln -s "$root/$d" "$w/repo/$d"; done
  extract "$page" "$w/blocks"
  for b in "$w"/blocks/*.run "$w"/blocks/*.norun; do
    [ -e "$b" ] || continue
    n=${b%.*}
    at="${page#"$root"/}:$(cat "$n.line")"
    if [ "${b##*.}" = norun ]; then
      checked=$((checked + 1))
      if msg=$(check_norun "$b"); then echo "ok      $at (not run: options checked)"
      else echo "FAIL    $at (not run)"; echo "$msg"; fails=$((fails + 1)); fi
    fi
  done
  for b in "$w"/blocks/*.run; do
    [ -e "$b" ] || continue
    n=${b%.*}
    at="${page#"$root"/}:$(cat "$n.line")"
    blocks=$((blocks + 1))
    start=$(date +%s)
    if (cd "$w/repo" && bash -euo pipefail "$b") > "$n.log" 2>&1; then
      echo "ok      $at ($(( $(date +%s) - start )) s)"
    else
      echo "FAIL    $at: the block exited with an error; its last output:"
      tail -15 "$n.log" | sed 's/^/    /'
      fails=$((fails + 1))
    fi
  done
done
echo "run_guide: $blocks blocks run, $checked checked without running, $fails failed"
[ "$fails" -eq 0 ]

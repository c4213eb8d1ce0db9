#!/usr/bin/env bash
# run_guide_selftest.sh BUILD_DIR — scripts/run_guide.sh finds what is wrong on a page:
# a block that fails, an option a command does not have, a script that does not exist; and
# passes the good blocks of the same page.
root=$(cd "$(dirname "$0")/../.." && pwd)
out=$("$root/scripts/run_guide.sh" "$1" "$root/tests/docs/broken_page.md" 2>&1)
rc=$?
fails=0
expect() { grep -qF -- "$1" <<< "$out" || { echo "FAIL: output lacks: $1"; fails=$((fails + 1)); }; }
[ "$rc" -eq 1 ] || { echo "FAIL: exit status $rc, want 1"; fails=$((fails + 1)); }
expect "FAIL    tests/docs/broken_page.md:4: the block exited with an error"
expect "lumosaic infer: no option --no-such-option in its --help"
expect "scripts/no_such_script.sh does not exist"
expect "ok      tests/docs/broken_page.md:17"
expect "run_guide: 2 blocks run, 2 checked without running, 3 failed"
[ "$fails" -eq 0 ] || { echo "$out"; exit 1; }
echo "run_guide self-test: 6 checks passed"

# lib.sh — helpers for the end-to-end CLI tests (sourced by tests/cli/*.sh).
# Each script gets LUMOSAIC and MAKE_CUBE as $1 $2, works in a fresh temporary folder $T
# (removed at exit) and exits 1 if any check failed.
set -u
LM=$1
MK=$2
SHARED=${LM_SHARED_DIR:-$(cd "$(dirname "$0")/../../.." && pwd)/shared}
CAVE=$SHARED/data/cave/balloons_crop100
T=$(mktemp -d)
trap 'rm -rf "$T"' EXIT
fails=0
checks=0

fail() { echo "FAIL: $*" >&2; fails=$((fails + 1)); }
ok() { checks=$((checks + 1)); }

# check NAME CONDITION...: run the condition (a command), fail with NAME if it is false.
check() {
  local name=$1; shift
  if "$@"; then ok; else fail "$name"; fi
}

# check_not NAME CONDITION...: fail with NAME if the condition holds.
check_not() {
  local name=$1; shift
  if "$@"; then fail "$name"; else ok; fi
}

# no_output PATH: PATH is missing or an empty folder, and no "PATH.tmp.*" staging file is left.
no_output() {
  local p=$1
  if [ -e "$p" ] && { [ ! -d "$p" ] || [ -n "$(ls -A "$p")" ]; }; then return 1; fi
  ! ls -d "$p".tmp.* >/dev/null 2>&1
}

# expect_error NAME STATUS PATTERN OUTPUT -- COMMAND...: the command exits with STATUS, prints
# exactly one line on stderr that contains PATTERN, and leaves no partial OUTPUT. Cases run in
# the background, three at a time (start-up dominates their cost); finish waits for them and
# counts their results from $T/results.
mkdir -p "$T/results"
expect_error() {
  while [ "$(jobs -rp | wc -l)" -ge 3 ]; do wait -n; done
  expect_error_run "$@" &
}

expect_error_run() {
  local name=$1 want=$2 pat=$3 out=$4; shift 5
  local log
  log=$(mktemp "$T/results/case.XXXXXX")
  "$@" > "$log.out" 2> "$log.err"
  local rc=$? lines msg
  lines=$(wc -l < "$log.err")
  msg=$(cat "$log.err")
  if [ "$rc" -ne "$want" ]; then echo "FAIL: $name: exit status $rc, want $want ($msg)" > "$log"
  elif [ "$lines" -ne 1 ]; then echo "FAIL: $name: $lines lines on stderr: $msg" > "$log"
  elif ! grep -qF -- "$pat" "$log.err"; then echo "FAIL: $name: '$msg' lacks '$pat'" > "$log"
  elif ! no_output "$out"; then echo "FAIL: $name: partial output left at $out" > "$log"
  else echo ok > "$log"; fi
}

# eval_row DIR K: the mean PSNR row of DIR/eval.csv at noise level K (%).
eval_row() { awk -F, -v k="$2" '$1 == "mean" && $2 == k { print $3 }' "$1/eval.csv"; }

# check_auto_split AUTO A NAME_A B NAME_B: the eval folders AUTO (eval --model auto of a
# calibration forced to model A on clean frames and B at 10 %), A and B (each model alone, the
# same scenes and noise): AUTO's clean row is A's, its 10 % row B's, and A and B differ at 10 %.
check_auto_split() {
  local a=$1 m0=$2 n0=$3 m1=$4 n1=$5
  check "eval auto clean = $n0 ($(eval_row "$a" 0) vs $(eval_row "$m0" 0))" \
    [ "$(eval_row "$a" 0)" = "$(eval_row "$m0" 0)" -a -n "$(eval_row "$m0" 0)" ]
  check "eval auto 10 % = $n1 ($(eval_row "$a" 10) vs $(eval_row "$m1" 10))" \
    [ "$(eval_row "$a" 10)" = "$(eval_row "$m1" 10)" -a -n "$(eval_row "$m1" 10)" ]
  check_not "the two models score apart at 10 %" \
    [ "$(eval_row "$m0" 10)" = "$(eval_row "$m1" 10)" ]
}

finish() {
  wait
  local f
  for f in "$T"/results/case.??????; do
    [ -e "$f" ] || continue
    if [ "$(cat "$f")" = ok ]; then ok; else fail "$(sed 's/^FAIL: //' "$f")"; fi
  done
  echo "$checks passed, $fails failed"
  [ "$fails" -eq 0 ]
  exit $?
}

#!/usr/bin/env bash
# omp_wait.sh — how OpenMP threads wait (issue 16, item 9; cli/main.c omp_wait_policy): a
# computing command started without a policy runs with GOMP_SPINCOUNT=1000 (it re-executes
# itself once, same process id), a policy the user set (OMP_WAIT_POLICY or GOMP_SPINCOUNT) or
# LM_KEEP_OMP_WAIT=1 is left alone, and a command that does not compute (version) is not
# re-executed. Read from /proc/<pid>/environ of a running `train`.
# usage: omp_wait.sh LUMOSAIC MAKE_CUBE
source "$(dirname "$0")/lib.sh"
spin_of() { # spin_of NAME ENV...: GOMP_SPINCOUNT of a running train started with ENV
  local name=$1; shift
  env -u OMP_WAIT_POLICY -u GOMP_SPINCOUNT "$@" "$LM" train --model linear --data "$CAVE" \
    --iterations 1000000 --batch 2 --accum-steps 1 --val-interval 0 --threads 1 --quiet \
    --output "$T/$name" > /dev/null 2>&1 &
  local pid=$! v=""
  for i in $(seq 1 100); do
    [ -s "$T/$name/log.csv" ] && break
    sleep 0.1
  done
  v=$(tr '\0' '\n' < /proc/$pid/environ 2> /dev/null | sed -n 's/^GOMP_SPINCOUNT=//p')
  kill -9 $pid 2> /dev/null
  wait $pid 2> /dev/null
  echo "${v:-unset}"
}
check "no policy: spin 1000" [ "$(spin_of a)" = 1000 ]
check "OMP_WAIT_POLICY=passive: left alone" [ "$(spin_of b OMP_WAIT_POLICY=passive)" = unset ]
check "GOMP_SPINCOUNT=5: left alone" [ "$(spin_of c GOMP_SPINCOUNT=5)" = 5 ]
check "LM_KEEP_OMP_WAIT=1: left alone" [ "$(spin_of d LM_KEEP_OMP_WAIT=1)" = unset ]
n=$(env -u OMP_WAIT_POLICY -u GOMP_SPINCOUNT "$LM" version | grep -c lumosaic)
check "version runs (no re-execution needed)" [ "$n" -ge 1 ]
finish

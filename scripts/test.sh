#!/usr/bin/env bash
# test.sh — the whole test suite: set-up and build (scripts/setup.sh), every CTest test in the
# Release build (portable, warnings as errors; the numerical tests also at each lower
# instruction-set level this CPU runs, label "isa"), the Python package installed with pip in a virtual
# environment and its pytest tests (scripts/test_python.sh), then the same suite built with
# AddressSanitizer + UndefinedBehaviorSanitizer (every test but labels "isa", "slow" and "guide":
# the reruns per instruction set, the long training anchor and the guide's commands, whose code
# the unit and CLI tests already run there; they would cost a third of its time), then the core
# library compiled (not run) for other CPU targets and with clang, warnings as errors
# (scripts/check_targets.sh).
# Exits non-zero on any failure. A skipped OpenCL test fails the run when CI=true (CI installs
# PoCL, so a skip there means the set-up is broken).
set -euo pipefail
cd "$(dirname "$0")/.."
LM_WERROR=ON scripts/setup.sh

jobs=$(nproc)
echo "== tests (Release) =="
ctest --test-dir build --output-on-failure -j"$jobs" | tee build/ctest.log

echo "== Python package (pip install ./python in build/venv, pytest) =="
scripts/test_python.sh

echo "== tests (AddressSanitizer + UndefinedBehaviorSanitizer) =="
cmake -S . -B build-asan -DLM_SANITIZE=ON -DCMAKE_BUILD_TYPE=RelWithDebInfo -DLM_WERROR=ON > /dev/null
cmake --build build-asan -j"$jobs"
ASAN_OPTIONS=${ASAN_OPTIONS:-abort_on_error=0:detect_leaks=1} \
UBSAN_OPTIONS=${UBSAN_OPTIONS:-print_stacktrace=1:halt_on_error=1} \
  ctest --test-dir build-asan --output-on-failure -j"$jobs" -LE "isa|slow|guide" \
  | tee build-asan/ctest.log

echo "== compile for other targets (warnings as errors) =="
# clang and its OpenMP runtime, the ARM cross compiler: only this check needs them
for p in clang libomp-dev gcc-aarch64-linux-gnu; do
  if ! dpkg-query -W -f='${Status}' "$p" 2>/dev/null | grep -q "install ok installed"; then
    sudo=""; [ "$(id -u)" -ne 0 ] && sudo="sudo"
    $sudo apt-get update -q && DEBIAN_FRONTEND=noninteractive $sudo apt-get install -y -q \
      --no-install-recommends clang libomp-dev gcc-aarch64-linux-gnu libc6-dev-arm64-cross
    break
  fi
done
scripts/check_targets.sh

if [ "${CI:-}" = "true" ] && grep -q "\*\*\*Skipped\|Not Run" build/ctest.log build-asan/ctest.log; then
  echo "test.sh: tests were skipped in CI (OpenCL platform missing?): failing" >&2
  exit 1
fi

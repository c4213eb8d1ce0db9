#!/usr/bin/env bash
# check_targets.sh — compile the core library (no tests, nothing run) for other CPU targets and
# with clang, warnings as errors, so that a warning that only one target's code generation
# shows (GCC's flow warnings depend on the target it tunes for) fails here, not in a user's
# build. Targets: x86-64-v3 (AVX2), icelake-server and sapphirerapids (AVX-512, AMX), Zen 4
# (GCC 12 has no -march=znver4: znver3 with Zen 4's AVX-512 extensions), and the portable
# build with clang (its advisory "loop not vectorized" left out), and every library source for
# 64-bit ARM (aarch64-linux-gnu-gcc: no x86 intrinsics anywhere but in code guarded for x86;
# the Debian headers of the libraries stand in for ARM's, compile only). Build folders:
# build-targets/<name>.
# Usage: scripts/check_targets.sh [NAME ...]   (default: all)
set -euo pipefail
cd "$(dirname "$0")/.."

znver4="znver3 -mavx512f -mavx512cd -mavx512dq -mavx512bw -mavx512vl -mavx512ifma \
-mavx512vbmi -mavx512vbmi2 -mavx512bitalg -mavx512vpopcntdq -mavx512vnni -mavx512bf16 -mgfni \
-mvaes -mvpclmulqdq"
names=("$@")
[ ${#names[@]} -gt 0 ] || names=(x86-64-v3 icelake-server sapphirerapids znver4 clang aarch64)
jobs=$(nproc)
for name in "${names[@]}"; do
  dir=build-targets/$name
  start=$(date +%s)
  case $name in
    aarch64)
      command -v aarch64-linux-gnu-gcc >/dev/null ||
        { echo "check_targets: aarch64-linux-gnu-gcc not installed" >&2; exit 1; }
      mkdir -p "$dir"
      : > "$dir/build.log"
      for f in tensor/*.c tensor/ops/*.c autograd/*.c models/*.c train/*.c infer/*.c data/*.c \
               kernels-opencl/*.c; do
        aarch64-linux-gnu-gcc -std=gnu11 -O2 -Wall -Wextra -Werror -Wno-psabi -fopenmp -I. \
          -DLM_SOURCE_DIR='"."' -DLM_VERSION='"check"' -DCL_TARGET_OPENCL_VERSION=120 \
          -idirafter /usr/include -idirafter /usr/include/x86_64-linux-gnu/openblas-pthread \
          -idirafter /usr/include/OpenEXR -idirafter /usr/include/hdf5/serial \
          -c "$f" -o "$dir/object.o" >> "$dir/build.log" 2>&1 &
        [ "$(jobs -rp | wc -l)" -lt "$jobs" ] || wait -n || true
      done
      wait
      if grep -qE "error|warning" "$dir/build.log"; then
        grep -E "error|warning" "$dir/build.log" | head -20 >&2
        echo "check_targets: aarch64: the library does not compile warning-free" >&2
        exit 1
      fi
      echo "check_targets: aarch64: every library source compiled warning-free ($(( $(date +%s) - start )) s)"
      continue ;;
    clang)
      command -v clang >/dev/null || { echo "check_targets: clang not installed" >&2; exit 1; }
      # -Wno-pass-failed: clang reports an `omp simd` loop it leaves scalar at the baseline
      # instruction set (a float min/max reduction, a loop with a call) as a warning; that is
      # a missed optimisation of one target, not a defect, and GCC vectorises those loops
      CC=clang CXX=clang++ CFLAGS=-Wno-pass-failed cmake -S . -B "$dir" \
          -DCMAKE_BUILD_TYPE=Release -DLM_WERROR=ON -DLM_NATIVE=OFF -DLM_MARCH= > /dev/null ;;
    znver4)
      cmake -S . -B "$dir" -DCMAKE_BUILD_TYPE=Release -DLM_WERROR=ON -DLM_MARCH="$znver4" \
          > /dev/null ;;
    *)
      cmake -S . -B "$dir" -DCMAKE_BUILD_TYPE=Release -DLM_WERROR=ON -DLM_MARCH="$name" \
          > /dev/null ;;
  esac
  if ! cmake --build "$dir" -j"$jobs" --target lumosaic_core > "$dir/build.log" 2>&1; then
    grep -E "error|warning" "$dir/build.log" | head -20 >&2
    echo "check_targets: $name: the core library does not compile warning-free" >&2
    exit 1
  fi
  echo "check_targets: $name: core library compiled warning-free ($(( $(date +%s) - start )) s)"
done
